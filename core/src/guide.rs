//! A guide in three walkthroughs. This module holds no code; every example
//! below is compiled and run by `cargo test --doc`.
//!
//! - [Receiving frames](#1-receiving-frames): bytes from a UART become
//!   checked frames, then typed messages, then named fields.
//! - [Sending a command and reading the reply](#2-sending-a-command-and-reading-the-reply):
//!   the request engine, with the protocol's timeouts and retries.
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
//! use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
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
//!         match step.status {
//!             Status::Partial => {}
//!             Status::Complete(Event::Error(e)) => println!("dropped a broken frame: {e}"),
//!             Status::Complete(Event::Frame(frame)) => {
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
//! A [`Line`](crate::line::Line) is one line to a controller: the command
//! on it, its reply, and what may still arrive (late replies, copies).
//! Every engine borrows it for its calls, so what one engine left in flight
//! is known to the next. [`Client`](crate::client::Client) sends any
//! command and returns its typed reply. The line applies chapter 5 of the
//! X-SEL specification (the TTA's own chapter is lost): the reply must be
//! complete within 3 s after the command was sent, or the command is sent
//! again, up to 3 sends; a reply counts only if its format, checksum,
//! station and message ID are right, and only for the command it answers.
//! Commands that must not run twice (235H relative move, 236H inching,
//! program steps) are sent once unless you opt in: a lost reply then
//! reports [`Failure::OutcomeUnknown`](crate::error::Failure::OutcomeUnknown).
//! An `&` error response is [`Failure::Controller`](crate::error::Failure::Controller)
//! with its code (and, if asked for, the 216H error detail); it is not
//! sent again. A line just opened knows nothing of its past: its first
//! command is preceded by a 200H "fence" whose echo proves that nothing
//! sent before can still be answered.
//!
//! Motion commands are built from `(axis, value)` pairs, so their axis
//! pattern always matches their values. The UART is anything with the
//! `embedded-io` `Read`, `ReadReady` and `Write` traits; the clock any
//! `FnMut() -> u32` in milliseconds. Here a [`Loopback`](crate::io::Loopback)
//! plays the controller:
//!
//! ```
//! use iai_protocol_b::{client::Client, error::Failure, line::Line, line::LineConfig, frame::Station};
//! use iai_protocol_b::message::{AbsoluteMove, AxisStatusQuery};
//! # let mut uart = iai_protocol_b::io::Loopback::default();
//! # let mut ms = 0u32;
//! # let mut now = move || { ms += 1; ms };
//!
//! let mut line = Line::new(LineConfig::new(Station(0x99)), 0x5eed);
//! let mut client: Client = Client::new();
//! // 234H: axis 1 to +100.000 mm, axis 2 to -25.500 mm at 100 mm/s.
//! let go = AbsoluteMove::to(&[(1, 100_000), (2, -25_500)])?.with_speed(100);
//! client.call(&mut line, &mut uart, &mut now, &go)?;
//! // 212H: the typed reply, one status block per axis asked.
//! let status = client.call(&mut line, &mut uart, &mut now, &AxisStatusQuery::of(&[1, 2])?)?;
//! assert_eq!(status.axes.len(), 2);
//! # Ok::<(), Failure<core::convert::Infallible>>(())
//! ```
//!
//! Without blocking, drive the same engine yourself (every engine has this
//! shape, [`crate::engine`]): [`Client::start`](crate::client::Client::start),
//! then [`Client::poll`](crate::client::Client::poll) tells you to transmit
//! bytes (report [`Client::sent`](crate::client::Client::sent) when the
//! last one left), to wait until a tick (feeding received bytes to
//! [`Client::received`](crate::client::Client::received) meanwhile), or
//! that the request is done; [`Client::response`](crate::client::Client::response)
//! then parses the reply. [`Client::poll_nb`](crate::client::Client::poll_nb)
//! and, with the `async` feature, `Client::call_async` wrap that loop.
//!
//! To build frames by hand, every message emits itself with
//! [`Message::emit`](crate::message::Message::emit) into a buffer of
//! [`Message::emit_len`](crate::message::Message::emit_len) bytes.
//!
//! # 3. Streaming a position table
//!
//! A position table can hold 20,000 records of 8 axes: far more than one
//! command frame may carry. [`Transfer`](crate::transfer::Transfer) pulls
//! records from any source (an iterator here, a
//! [`RecordBuffer`](crate::transfer::RecordBuffer) when they arrive over
//! another link), packs as many as the controller accepts into each 26DH
//! command, waits for the reply that confirms that count (sending again
//! after a timeout), then reads the positions back with 21FH and compares
//! them with what it sent ([`Verify::Full`](crate::transfer::Verify), the
//! default). The caller moves bytes and time, as for every engine:
//!
//! - [`Step::Transmit`](crate::engine::Step::Transmit): send these bytes,
//!   then call [`Transfer::sent`](crate::transfer::Transfer::sent);
//! - [`Step::WaitUntil`](crate::engine::Step::WaitUntil): feed received
//!   bytes to [`Transfer::received`](crate::transfer::Transfer::received)
//!   ([`engine::feed`](crate::engine::feed) loops over them) and poll
//!   again by that tick;
//! - [`Step::Done`](crate::engine::Step::Done): the
//!   [`Guarantee`](crate::transfer::Guarantee) the run carries, or why it
//!   stopped (a failed transfer can be resumed).
//!
//! The controller of this example is a map in memory: it reads each 26DH
//! record by record with the [`PositionStreamDecoder`](crate::table::PositionStreamDecoder)
//! and stores the records; it answers 21FH from the map and echoes 200H.
//!
//! ```
//! use std::collections::BTreeMap;
//! use iai_protocol_b::checksum::BypassPolicy;
//! use iai_protocol_b::decoder::{Event, FrameDecoder};
//! use iai_protocol_b::engine::{feed, Step};
//! use iai_protocol_b::message::*;
//! use iai_protocol_b::position::PositionRecord;
//! use iai_protocol_b::table::{PositionStreamDecoder, StreamEvent};
//! use iai_protocol_b::transfer::Guarantee;
//! use iai_protocol_b::{line::Line, line::LineConfig, profile::Profile, frame::Station, transfer::Transfer, transfer::TransferConfig};
//!
//! let station = Station(0x99);
//! // 500 records of 3 axes: more than one 2,051-byte frame holds.
//! let table: Vec<_> = (1..=500u16)
//!     .map(|n| {
//!         let x = i32::from(n) * 100;
//!         PositionRecord::new(n, 30, 30, 200, &[(1, x), (2, -x), (3, 5_000)]).unwrap()
//!     })
//!     .collect();
//!
//! /// The controller: stores 26DH records, answers 21FH windows and 200H.
//! fn controller(map: &mut BTreeMap<u16, PositionRecord>, command: &[u8], st: Station) -> Vec<u8> {
//!     let mut out = vec![0u8; 2048];
//!     let n = if command.starts_with(b"!9926D") {
//!         let mut dec = PositionStreamDecoder::new(BypassPolicy::default());
//!         let (mut input, mut written) = (command, 0);
//!         loop {
//!             let r = dec.decode(input);
//!             input = &input[r.consumed..];
//!             match r.status.complete() {
//!                 Some(StreamEvent::Record(rec)) => { map.insert(rec.number, rec); written += 1 }
//!                 Some(StreamEvent::End { .. }) => break,
//!                 Some(StreamEvent::Error { error, .. }) => panic!("{error}"),
//!                 _ => {}
//!             }
//!         }
//!         let reply = ChangePositionData2Response { number_of_changed_positions: written };
//!         reply.emit(st, &mut out).unwrap()
//!     } else {
//!         let mut dec: FrameDecoder = FrameDecoder::new();
//!         let Some(Event::Frame(frame)) = dec.decode(command).status.complete() else { panic!() };
//!         if let Ok(q) = TestCall::parse(&frame) {
//!             TestCallResponse { test_string: q.test_string }.emit(st, &mut out).unwrap()
//!         } else {
//!             let q = EffectivePositionQuery2::parse(&frame).unwrap();
//!             let head = q.query_head_position_number;
//!             let window = head..head + q.number_of_query_records;
//!             let found: Vec<_> = map.range(window).map(|(_, r)| r.clone()).collect();
//!             let reply = EffectivePositionResponse2 { records: Repeated::from_slice(&found) };
//!             reply.emit(st, &mut out).unwrap()
//!         }
//!     };
//!     out.truncate(n);
//!     out
//! }
//!
//! let mut line = Line::new(LineConfig::new(station), 42);
//! let cfg = TransferConfig::new(Profile::TTA);
//! let mut transfer: Transfer<_> = Transfer::new(cfg, table.clone().into_iter());
//! let mut map = BTreeMap::new();
//! let mut wire = Vec::new();
//! let mut now = 0u32;
//! let guarantee = loop {
//!     match transfer.poll(&mut line, now) {
//!         Step::Transmit(bytes) => {
//!             wire = controller(&mut map, bytes, station);
//!             transfer.sent(&mut line, now);
//!         }
//!         Step::WaitUntil(deadline) => {
//!             if wire.is_empty() {
//!                 now = deadline; // nothing on the line: let time pass
//!             } else {
//!                 feed(&mut transfer, &mut line, &wire, now);
//!                 wire.clear();
//!             }
//!         }
//!         Step::Done(result) => break result.expect("the transfer completes"),
//!         Step::Idle => unreachable!("an iterator is never pending"),
//!     }
//!     now += 1;
//! };
//! assert_eq!(guarantee, Guarantee::Verified);
//! assert_eq!(transfer.stats().records_verified, 500);
//! assert_eq!(map.values().cloned().collect::<Vec<_>>(), table);
//! ```
//!
//! Over a real UART, [`Transfer::run_blocking`](crate::transfer::Transfer::run_blocking)
//! (`embedded-io`), [`Transfer::poll_nb`](crate::transfer::Transfer::poll_nb)
//! (a non-blocking main loop) and, with the `async` feature, the async
//! flavour run the same loop. To write the table by hand instead,
//! [`PositionStreamEncoder`](crate::table::PositionStreamEncoder) produces
//! one frame of any size chunk by chunk.
