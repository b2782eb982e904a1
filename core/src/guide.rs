//! A guide in three walkthroughs. This module holds no code; every example
//! below is compiled and run by `cargo test --doc`.
//!
//! - [Receiving frames](#1-receiving-frames): bytes from a UART become
//!   checked frames, then typed messages, then named fields.
//! - [Sending a command and reading the reply](#2-sending-a-command-and-reading-the-reply).
//! - [Streaming a position table](#3-streaming-a-position-table): the
//!   transfer engine writes a table of any size in controller-sized,
//!   confirmed commands.
//!
//! # 1. Receiving frames
//!
//! A [`FrameDecoder`](crate::decoder::FrameDecoder) takes bytes in whatever
//! pieces the driver delivers them. Each call consumes input until it has a
//! frame, an error, or nothing more to do; the caller feeds the rest of the
//! input in the next call. Noise before a frame is skipped, a broken frame
//! is reported once and dropped. The frame borrows the decoder's buffer, so
//! use it (or copy it) before pushing more bytes.
//!
//! [`decode_any`](crate::message::decode_any) then gives the typed message,
//! and the [`Fields`](crate::message::Fields) visitor walks its fields with
//! names, units and wire formats, which is what a logger or inspector needs.
//!
//! ```
//! use iai_protocol_b::decoder::{Event, FrameDecoder};
//! use iai_protocol_b::field::FieldSpec;
//! use iai_protocol_b::message::{decode_any, AnyMessage, Fields, Response, Value, Visitor};
//!
//! /// Collects `name=value unit` for every leaf field.
//! struct Show(Vec<String>);
//! impl Visitor for Show {
//!     fn field(&mut self, name: &'static str, unit: &'static str, _: FieldSpec, v: Value<'_>) {
//!         let v = match v {
//!             Value::Unsigned(n) => n.to_string(),
//!             Value::Signed(n) => n.to_string(),
//!             Value::Text(t) => String::from_utf8_lossy(t).into_owned(),
//!         };
//!         let sep = if unit.is_empty() { "" } else { " " };
//!         self.0.push(format!("{name}={v}{sep}{unit}"));
//!     }
//! }
//!
//! // A 212H reply for axis 1 arriving in two pieces, with noise before it.
//! let pieces: [&[u8]; 2] = [b"\x00\x00#992120115", b"00000000001388A5\r\n"];
//! let mut dec: FrameDecoder = FrameDecoder::new();
//! let mut shown = Vec::new();
//! for mut input in pieces {
//!     while !input.is_empty() {
//!         let step = dec.decode(input);
//!         input = &input[step.consumed..];
//!         match step.event {
//!             Event::NeedMore => {}
//!             Event::Error(e) => println!("dropped a broken frame: {e}"),
//!             Event::Frame(frame) => {
//!                 let decoded = decode_any(&frame).unwrap();
//!                 assert!(matches!(
//!                     decoded.message,
//!                     AnyMessage::Response(Response::AxisStatusResponse(_))
//!                 ));
//!                 let mut v = Show(Vec::new());
//!                 decoded.message.fields(&mut v);
//!                 shown = v.0;
//!             }
//!         }
//!     }
//! }
//! assert_eq!(dec.stats().discarded_bytes, 2);
//! assert_eq!(shown.first().map(String::as_str), Some("axis_pattern=1"));
//! assert_eq!(shown.last().map(String::as_str), Some("current_position=5000 0.001mm"));
//! ```
//!
//! On a microcontroller the same loop runs in the UART interrupt or main
//! loop; [`io::receive`](crate::io::receive) and
//! [`io::poll_frame`](crate::io::poll_frame) wrap it for `embedded-io` and
//! `nb` drivers.
//!
//! # 2. Sending a command and reading the reply
//!
//! Every typed message emits itself with [`Message::emit`](crate::message::Message::emit)
//! into a caller's buffer, computing the checksum.
//! [`io::send`](crate::io::send) does that and writes the frame to any
//! `embedded_io::Write`; [`io::receive`](crate::io::receive) reads from an
//! `embedded_io::Read` until a frame is complete, and the response type's
//! [`Message::parse`](crate::message::Message::parse) checks header, ID and
//! every field. An `&` reply is an error response: parse it with
//! [`ErrorResponse::parse`](crate::message::ErrorResponse::parse).
//!
//! Here the "controller" is played by a byte slice holding its reply.
//!
//! ```
//! use iai_protocol_b::axis::{AxisPattern, PerAxis};
//! use iai_protocol_b::decoder::FrameDecoder;
//! use iai_protocol_b::frame::{Header, Station};
//! use iai_protocol_b::io::{receive, send};
//! use iai_protocol_b::message::{
//!     AxisStatus, AxisStatusQuery, AxisStatusResponse, ErrorResponse, Message,
//! };
//!
//! let station = Station(0x99);
//!
//! // Host → controller: 212H for axes 1 and 2.
//! let mut line = [0u8; 64];
//! let query = AxisStatusQuery { query_axis_pattern: AxisPattern::first(2) };
//! let n = send(&mut &mut line[..], &query, station, &mut [0u8; 32]).unwrap();
//! assert_eq!(&line[..n], b"!99212038B\r\n");
//!
//! // Controller → host: what a controller with two homed axes would say.
//! let mut axes = PerAxis::new();
//! for pos in [1_000, -2_500] {
//!     axes.push(AxisStatus { axis_status: 0x15, current_position: pos, ..Default::default() })
//!         .unwrap();
//! }
//! let reply = AxisStatusResponse { axis_pattern: AxisPattern::first(2), axes };
//! let mut wire = [0u8; 64];
//! let len = reply.emit(station, &mut wire).unwrap();
//!
//! // The host reads it back.
//! let mut dec: FrameDecoder = FrameDecoder::new();
//! let frame = receive(&mut &wire[..len], &mut dec).unwrap();
//! match frame.header() {
//!     Header::Response => {
//!         let status = AxisStatusResponse::parse(&frame).unwrap();
//!         let positions: Vec<i32> = status.axes.iter().map(|a| a.current_position).collect();
//!         assert_eq!(positions, [1_000, -2_500]);
//!     }
//!     Header::Error => panic!("controller error {:03X}", ErrorResponse::parse(&frame).unwrap().code),
//!     Header::Command => unreachable!("a controller does not send commands"),
//! }
//! ```
//!
//! A real host also needs a timeout: the X-SEL specification allows the
//! controller a bounded time to answer and asks the host to send the
//! command again after it. The transfer and read-back engines below do
//! this themselves.
//!
//! # 3. Streaming a position table
//!
//! A position table can hold 20,000 records of 8 axes: far more than one
//! command frame may carry. [`Transfer`](crate::transfer::Transfer) is a
//! sans-IO state machine that pulls records from any source (an iterator
//! here, a [`RecordQueue`](crate::transfer::RecordQueue) when they arrive
//! over another link), packs as many as the controller accepts into each
//! 26DH command, and waits for the reply that confirms that count, sending
//! again after a timeout. The caller moves bytes and time:
//!
//! - [`Step::Transmit`](crate::transfer::Step::Transmit): send these bytes,
//!   then call [`Transfer::sent`](crate::transfer::Transfer::sent);
//! - [`Step::WaitUntil`](crate::transfer::Step::WaitUntil): feed received
//!   bytes to [`Transfer::received`](crate::transfer::Transfer::received)
//!   and poll again by that tick;
//! - [`Step::Complete`](crate::transfer::Step::Complete) /
//!   [`Step::Failed`](crate::transfer::Step::Failed): done.
//!
//! The controller side of this example is an in-memory loopback: it reads
//! each command with the [`PositionStreamDecoder`](crate::stream::PositionStreamDecoder)
//! (record by record, as a bridge or a controller with little RAM would)
//! and answers with the 26DH response.
//!
//! ```
//! use iai_protocol_b::checksum::BypassPolicy;
//! use iai_protocol_b::frame::Station;
//! use iai_protocol_b::message::{ChangePositionData2Response, Message};
//! use iai_protocol_b::position::PositionRecord;
//! use iai_protocol_b::stream::{PositionStreamDecoder, StreamEvent};
//! use iai_protocol_b::transfer::{Step, Transfer, TransferConfig};
//!
//! let station = Station(0x99);
//! // 500 records of 3 axes: more than one 2,051-byte frame holds.
//! let table = (1..=500u16).map(|n| {
//!     let x = i32::from(n) * 100;
//!     PositionRecord::new(n, 30, 30, 200, &[(1, x), (2, -x), (3, 5_000)]).unwrap()
//! });
//!
//! let mut transfer: Transfer<_> = Transfer::new(TransferConfig::tta(station), table);
//! let mut controller = PositionStreamDecoder::new(BypassPolicy::default());
//! let mut written = Vec::new();
//! let mut reply = Vec::new();
//! let mut now = 0u32;
//! let stats = loop {
//!     match transfer.poll(now) {
//!         Step::Transmit(bytes) => {
//!             // "Send": the controller reads the command as it arrives.
//!             let command = bytes.to_vec();
//!             transfer.sent(now);
//!             controller.reset();
//!             let mut input = &command[..];
//!             let count = loop {
//!                 let (used, event) = controller.decode(input);
//!                 input = &input[used..];
//!                 match event {
//!                     StreamEvent::Record(rec) => written.push(rec.number),
//!                     StreamEvent::End { records } => break records,
//!                     StreamEvent::Error { error, .. } => panic!("{error}"),
//!                     StreamEvent::NeedMore | StreamEvent::Start { .. } => {}
//!                 }
//!             };
//!             // It answers with the number of positions written.
//!             let mut buf = [0u8; 16];
//!             let resp = ChangePositionData2Response { number_of_changed_positions: count };
//!             let n = resp.emit(station, &mut buf).unwrap();
//!             reply = buf[..n].to_vec();
//!         }
//!         Step::WaitUntil(deadline) => {
//!             if reply.is_empty() {
//!                 now = deadline; // nothing on the line: let time pass
//!             } else {
//!                 transfer.received(&reply, now);
//!                 reply.clear();
//!             }
//!         }
//!         Step::Complete(stats) => break stats,
//!         Step::NeedRecords => unreachable!("an iterator is never pending"),
//!         Step::Failed(e) => panic!("transfer failed: {e:?}"),
//!     }
//!     now += 1;
//! };
//! assert_eq!(stats.records_confirmed, 500);
//! assert!(stats.frames_confirmed > 1);
//! assert_eq!(written, (1..=500).collect::<Vec<u16>>());
//! ```
//!
//! Over a real UART, [`Transfer::run_blocking`](crate::transfer::Transfer::run_blocking)
//! (`embedded-io`), [`Transfer::poll_nb`](crate::transfer::Transfer::poll_nb)
//! (a non-blocking main loop) and, with the `async` feature, the async
//! flavour run the same loop. To write the table by hand instead,
//! [`PositionStreamEncoder`](crate::stream::PositionStreamEncoder) produces
//! one frame of any size chunk by chunk.
