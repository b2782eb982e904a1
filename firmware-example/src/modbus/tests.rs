//! The Modbus side, frame by frame: recorded requests (with their CRC)
//! and what the gateway answers.

extern crate std;
use std::vec::Vec;

use super::*;
use crate::config::ModbusConfig;
use crate::modbus::map::{CMD_BUSY, CMD_DONE, HEND, MOVE, PEND, PWR, SV};

/// A Modbus port over byte vectors.
#[derive(Default)]
struct Fake {
    input: Vec<u8>,
    output: Vec<u8>,
}

impl embedded_io::ErrorType for Fake {
    type Error = core::convert::Infallible;
}
impl embedded_io::ReadReady for Fake {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(!self.input.is_empty())
    }
}
impl embedded_io::Read for Fake {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let n = buf.len().min(self.input.len());
        buf[..n].copy_from_slice(&self.input[..n]);
        self.input.drain(..n);
        Ok(n)
    }
}
impl embedded_io::WriteReady for Fake {
    fn write_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(true)
    }
}
impl embedded_io::Write for Fake {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        self.output.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}
impl Port for Fake {}

fn gateway(policy: Policy) -> Gateway {
    Gateway::new(ModbusConfig::DEFAULT, policy)
}

/// `request` arrives at once; the answer after the silence.
fn ask(gw: &mut Gateway, request: &[u8]) -> Vec<u8> {
    let mut port = Fake {
        input: request.to_vec(),
        ..Fake::default()
    };
    gw.serve(&mut port, 0, 1_000).unwrap();
    gw.serve(&mut port, 2, 2_750).unwrap();
    port.output
}

/// `body` with its CRC (for requests built in the test).
fn rtu(body: &[u8]) -> Vec<u8> {
    let mut v = body.to_vec();
    v.extend_from_slice(&rtu::crc16(body).to_le_bytes());
    v
}

const READ_PNOW_1: [u8; 8] = [0x01, 0x03, 0x90, 0x00, 0x00, 0x02, 0xE9, 0x0B];
/// -25.500 mm.
const PNOW_1: [u8; 9] = [0x01, 0x03, 0x04, 0xFF, 0xFF, 0x9C, 0x64, 0x92, 0xFC];
const READ_9006: [u8; 8] = [0x01, 0x03, 0x90, 0x06, 0x00, 0x01, 0x49, 0x0B];
const EXCEPTION_03_02: [u8; 5] = [0x01, 0x83, 0x02, 0xC0, 0xF1];
/// Function 2BH, MEI type 14: read device identification, basic stream
/// from object 0.
const FUNCTION_2B: [u8; 7] = [0x01, 0x2B, 0x0E, 0x01, 0x00, 0x70, 0x77];
/// Function 11H (report server ID): not served.
const FUNCTION_11: [u8; 4] = [0x01, 0x11, 0xC0, 0x2C];
const EXCEPTION_11_01: [u8; 5] = [0x01, 0x91, 0x01, 0x8C, 0x50];
/// DRG1 of axis 1 := SON.
const SERVO_ON_1: [u8; 8] = [0x01, 0x06, 0x0D, 0x00, 0x10, 0x00, 0x86, 0xA6];
/// DRG1 of axis 1 := SON | HOME.
const HOME_1: [u8; 8] = [0x01, 0x06, 0x0D, 0x00, 0x10, 0x10, 0x87, 0x6A];
const EXCEPTION_06_06: [u8; 5] = [0x01, 0x86, 0x06, 0xC2, 0x62];
const EXCEPTION_06_01: [u8; 5] = [0x01, 0x86, 0x01, 0x83, 0xA0];
/// CMDST, function 04.
const READ_CMDST: [u8; 8] = [0x01, 0x04, 0xB1, 0x00, 0x00, 0x03, 0x97, 0x37];

#[test]
fn a_read_is_answered_from_the_cache() {
    let mut gw = gateway(Policy::ForwardAll);
    gw.regs.cache.axes[0].current_position = -25_500;
    assert_eq!(ask(&mut gw, &READ_PNOW_1), PNOW_1);
    // Function 04 reads the same read-only registers.
    let mut fc4 = READ_PNOW_1;
    fc4[1] = 4;
    let fc4 = rtu(&fc4[..6]);
    let answer = ask(&mut gw, &fc4);
    assert_eq!(answer[..7], [1, 4, 4, 0xFF, 0xFF, 0x9C, 0x64]);
}

#[test]
fn dss1_waits_for_a_poll_after_a_confirmed_motion_command() {
    let mut gw = gateway(Policy::ForwardAll);
    let c = &mut gw.regs.cache;
    c.link_up = true;
    // Servo on, homed, last operation completed, at rest.
    c.axes[0].axis_status = 0b1_1100;
    assert_eq!(c.dss1(0), PWR | SV | HEND | PEND);
    // A push error is not a completion (the core's MoveOutcome).
    c.axes[0].axis_status = 0b11_1100;
    assert_eq!(c.dss1(0), PWR | SV | HEND);
    c.axes[0].axis_status = 0b1_1100;
    c.stale = 1;
    assert_eq!(c.dss1(0), PWR | SV | MOVE);
    // Moving (212H bit 0): MOVE, no PEND.
    c.stale = 0;
    c.axes[0].axis_status = 0b1_1101;
    assert_eq!(c.dss1(0), PWR | SV | HEND | MOVE);
    // At rest after a stop: neither MOVE nor PEND (bit 4 clear).
    c.axes[0].axis_status = 0b0_1100;
    assert_eq!(c.dss1(0), PWR | SV | HEND);
}

#[test]
fn refusals_by_exception_code() {
    let mut gw = gateway(Policy::ForwardAll);
    // An address outside the map: 02.
    assert_eq!(ask(&mut gw, &READ_9006), EXCEPTION_03_02);
    // A function the gateway does not serve: 01.
    assert_eq!(rtu(&FUNCTION_11[..2]), FUNCTION_11);
    assert_eq!(ask(&mut gw, &FUNCTION_11), EXCEPTION_11_01);
    // A read of no registers: 03.
    assert_eq!(
        ask(&mut gw, &rtu(&[1, 3, 0x90, 0, 0, 0]))[..3],
        [1, 0x83, 3]
    );
    // A writable register through function 04: 02.
    assert_eq!(
        ask(&mut gw, &rtu(&[1, 4, 0x0D, 0, 0, 1]))[..3],
        [1, 0x84, 2]
    );
    // A write to a read-only register: 02.
    assert_eq!(
        ask(&mut gw, &rtu(&[1, 6, 0x90, 0, 0, 1]))[..3],
        [1, 0x86, 2]
    );
    // Two commands in one DRG1 write: 03.
    assert_eq!(ask(&mut gw, &HOME_1)[..3], [1, 0x86, 3]);
    // A numeric move that asks for a push: 03.
    let push = rtu(&[
        1, 16, 0x99, 0, 0, 9, 18, 0, 0, 0x27, 0x10, 0, 0, 0, 0, 0, 0, 0, 100, 0, 30, 0, 1, 0, 0,
    ]);
    assert_eq!(ask(&mut gw, &push)[..3], [1, 0x90, 3]);
}

#[test]
fn a_command_is_accepted_at_once_and_the_next_one_is_busy() {
    let mut gw = gateway(Policy::ForwardAll);
    assert_eq!(ask(&mut gw, &SERVO_ON_1), SERVO_ON_1, "echoed: accepted");
    let cmdst = ask(&mut gw, &READ_CMDST);
    assert_eq!(
        cmdst[3..9],
        [0x40, 0x01, 0, 0, 0x02, 0x32],
        "busy, seq 1, 232H"
    );
    assert_eq!(gw.regs.hs.words()[0], CMD_BUSY | 1);
    // HOME's rising edge while the servo command is busy: 06, not kept.
    assert_eq!(ask(&mut gw, &HOME_1), EXCEPTION_06_06);
    assert_eq!(gw.regs.drg1[0], 0x1000);
}

#[test]
fn a_write_the_policy_refuses_is_exception_01_and_counted() {
    let mut gw = gateway(Policy::ReadOnly);
    assert_eq!(ask(&mut gw, &SERVO_ON_1), EXCEPTION_06_01);
    assert_eq!(gw.regs.cache.refused, 1);
    assert_eq!(gw.regs.drg1[0], 0);
    // The health block counts it (register 8).
    let health = ask(&mut gw, &rtu(&[1, 4, 0xB0, 8, 0, 1]));
    assert_eq!(health[3..5], [0, 1]);
}

#[test]
fn silence_for_broadcasts_other_units_and_broken_frames() {
    let mut gw = gateway(Policy::ForwardAll);
    // Broadcast: POSR of axis 1 := 7 is done, not answered.
    assert_eq!(ask(&mut gw, &rtu(&[0, 6, 0x0D, 3, 0, 7])), []);
    assert_eq!(gw.regs.posr[0], 7);
    // A broadcast read: not answered.
    assert_eq!(ask(&mut gw, &rtu(&[0, 3, 0x90, 0, 0, 2])), []);
    // Another unit.
    assert_eq!(ask(&mut gw, &rtu(&[2, 3, 0x90, 0, 0, 2])), []);
    // A wrong CRC, even with a function the gateway would refuse.
    let mut bad = FUNCTION_11;
    bad[3] ^= 0x80;
    assert_eq!(ask(&mut gw, &bad), []);
    // Function 16 whose byte count disagrees with its length.
    assert_eq!(ask(&mut gw, &rtu(&[1, 16, 0x0D, 3, 0, 1, 4, 0, 9])), []);
    // Noise longer than a frame.
    assert_eq!(ask(&mut gw, &[0x55; 300]), []);
    assert_eq!(gw.stats().dropped, 3);
    // The bus goes on.
    gw.regs.cache.axes[0].current_position = -25_500;
    assert_eq!(ask(&mut gw, &READ_PNOW_1), PNOW_1);
}

#[test]
fn window_records_are_written_whole() {
    let mut gw = gateway(Policy::ForwardAll);
    // Half a record: 03.
    let mut half = std::vec![1, 16, 0x22, 0x00, 0, 10, 20];
    half.extend([0u8; 20]);
    assert_eq!(ask(&mut gw, &rtu(&half))[..3], [1, 0x90, 3]);
    // One record: position 3, axis 1 at 1.000 mm, 100 mm/s.
    let mut one = std::vec![1, 16, 0x22, 0x00, 0, 21, 42];
    let words: [u16; 21] = [
        3, 1, 30, 30, 100, 0, 1000, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    ];
    for w in words {
        one.extend(w.to_be_bytes());
    }
    assert_eq!(ask(&mut gw, &rtu(&one))[..6], [1, 16, 0x22, 0, 0, 21]);
    assert_eq!(gw.regs.hs.words()[2], 0x26D);
    assert_eq!(gw.regs.window[..21], words);
}

/// `pdu` (unit ID first) behind an MBAP header with transaction ID `tid`.
fn mbap(tid: u16, pdu: &[u8]) -> Vec<u8> {
    let mut v = tid.to_be_bytes().to_vec();
    v.extend_from_slice(&[0, 0]);
    v.extend_from_slice(&(pdu.len() as u16).to_be_bytes());
    v.extend_from_slice(pdu);
    v
}

fn ask_tcp(gw: &mut Gateway, adu: &[u8]) -> Vec<u8> {
    let mut resp = tcp::Response::new();
    gw.serve_tcp(adu, &mut resp, 0);
    resp.to_vec()
}

#[test]
fn tcp_reads_the_same_cache_and_echoes_the_transaction_id() {
    let mut gw = gateway(Policy::ForwardAll);
    gw.regs.cache.axes[0].current_position = -25_500;
    let read = mbap(0xBEEF, &READ_PNOW_1[..6]);
    assert_eq!(tcp::adu_len(&read[..5]), None);
    assert_eq!(tcp::adu_len(&read), Some(Ok(12)));
    // Transaction ID, protocol 0, length 7, unit, function, 4 bytes.
    assert_eq!(
        ask_tcp(&mut gw, &read),
        [0xBE, 0xEF, 0, 0, 0, 7, 1, 3, 4, 0xFF, 0xFF, 0x9C, 0x64]
    );
    // Another transaction ID, the same registers and the same answer.
    let answer = ask_tcp(&mut gw, &mbap(7, &READ_PNOW_1[..6]));
    assert_eq!(answer[..2], [0, 7]);
    assert_eq!(answer[2..], [0, 0, 0, 7, 1, 3, 4, 0xFF, 0xFF, 0x9C, 0x64]);
    assert_eq!(gw.stats().answered, 2);
    // A refusal is an exception, as on RTU: 9006H is not mapped.
    assert_eq!(
        ask_tcp(&mut gw, &mbap(9, &READ_9006[..6])),
        [0, 9, 0, 0, 0, 3, 1, 0x83, 2]
    );
    assert_eq!(gw.stats().exceptions, 1);
}

#[test]
fn tcp_writes_go_through_the_same_handshake() {
    let mut gw = gateway(Policy::ForwardAll);
    gw.regs.cache.link_up = true;
    let servo = mbap(0x0102, &SERVO_ON_1[..6]);
    // The echo of a write: header with length 6, then the request's PDU.
    assert_eq!(ask_tcp(&mut gw, &servo), servo);
    // The RTU side sees the same command queued: a second write waits for
    // it (exception 06, server busy), on either transport.
    assert_eq!(ask(&mut gw, &HOME_1), EXCEPTION_06_06);
    assert_eq!(
        ask_tcp(&mut gw, &mbap(3, &HOME_1[..6])),
        [0, 3, 0, 0, 0, 3, 1, 0x86, 6]
    );
    let cmdst = ask_tcp(&mut gw, &mbap(4, &READ_CMDST[..6]));
    assert_eq!(cmdst[..9], [0, 4, 0, 0, 0, 9, 1, 4, 6]);
    assert_eq!(
        u16::from_be_bytes([cmdst[9], cmdst[10]]) & CMD_BUSY,
        CMD_BUSY
    );
}

#[test]
fn malformed_tcp_requests_are_dropped_or_end_the_connection() {
    let mut gw = gateway(Policy::ForwardAll);
    let good = mbap(1, &READ_PNOW_1[..6]);
    // A protocol ID other than 0: not Modbus, dropped unanswered.
    let mut other = good.clone();
    other[3] = 1;
    assert_eq!(tcp::check(&other), Err(tcp::Dropped::Protocol));
    assert_eq!(ask_tcp(&mut gw, &other), []);
    // A length field that disagrees with the ADU, or with the function.
    let mut long = good.clone();
    long[5] = 7;
    assert_eq!(tcp::check(&long), Err(tcp::Dropped::Length));
    assert_eq!(ask_tcp(&mut gw, &long), []);
    let short = mbap(1, &READ_PNOW_1[..5]);
    assert_eq!(tcp::check(&short), Err(tcp::Dropped::Length));
    assert_eq!(ask_tcp(&mut gw, &short), []);
    let bulk = mbap(1, &[1, 16, 0, 0, 0, 1, 2, 0, 5, 0]);
    assert_eq!(ask_tcp(&mut gw, &bulk), []);
    assert_eq!(gw.stats().dropped, 4);
    // A length field no ADU has: the stream cannot be followed.
    assert_eq!(
        tcp::adu_len(&[0, 1, 0, 0, 0, 1]),
        Some(Err(tcp::Dropped::Framing))
    );
    assert_eq!(
        tcp::adu_len(&[0, 1, 0, 0, 1, 0]),
        Some(Err(tcp::Dropped::Framing))
    );
    assert_eq!(tcp::adu_len(&[0, 1, 0, 0, 0, 254]), Some(Ok(260)));
    // Another unit: not answered; unit 0 (broadcast) reads: not answered.
    let mut unit2 = good.clone();
    unit2[6] = 2;
    assert_eq!(ask_tcp(&mut gw, &unit2), []);
    let mut unit0 = good.clone();
    unit0[6] = 0;
    assert_eq!(ask_tcp(&mut gw, &unit0), []);
    // An unknown function: exception 01, with the transaction ID, whatever
    // its length.
    assert_eq!(
        ask_tcp(&mut gw, &mbap(0x55AA, &[1, 0x11])),
        [0x55, 0xAA, 0, 0, 0, 3, 1, 0x91, 1]
    );
    assert_eq!(
        ask_tcp(&mut gw, &mbap(0x55AB, &[1, 0x41, 0, 0, 0, 0, 0, 0])),
        [0x55, 0xAB, 0, 0, 0, 3, 1, 0xC1, 1]
    );
    // The good request still answers.
    assert_eq!(ask_tcp(&mut gw, &good)[..9], [0, 1, 0, 0, 0, 7, 1, 3, 4]);
    // Every byte pattern of a short ADU is handled without a panic.
    for a in 0..=255u8 {
        for len in 0..12 {
            let adu: Vec<u8> = (0..len).map(|i| a.wrapping_mul(i as u8 + 1)).collect();
            let _ = ask_tcp(&mut gw, &adu);
            let _ = tcp::adu_len(&adu);
        }
    }
}

/// The controller's port of [`one_upstream`]: takes what is written and
/// is unplugged after `reads_left` readiness checks, which ends the loop.
struct Unplugging {
    reads_left: u32,
}

/// The error of an unplugged port.
const UNPLUGGED: embedded_io::ErrorKind = embedded_io::ErrorKind::BrokenPipe;

impl embedded_io::ErrorType for Unplugging {
    type Error = embedded_io::ErrorKind;
}
impl embedded_io::ReadReady for Unplugging {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        self.reads_left = self.reads_left.checked_sub(1).ok_or(UNPLUGGED)?;
        Ok(false)
    }
}
impl embedded_io::Read for Unplugging {
    fn read(&mut self, _buf: &mut [u8]) -> Result<usize, Self::Error> {
        Ok(0)
    }
}
impl embedded_io::WriteReady for Unplugging {
    fn write_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(true)
    }
}
impl embedded_io::Write for Unplugging {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}
impl Port for Unplugging {}

/// A two-UART board's loop with `input` on its one upstream port, which
/// speaks `speaks`, until the controller's port is unplugged (each sleep
/// is a millisecond): what the upstream port was sent.
fn one_upstream(speaks: UpstreamProtocol, input: &[u8]) -> Vec<u8> {
    let cfg = crate::config::Config::DEFAULT;
    let mut bridge = Bridge::new(cfg, crate::config::Source::Default, 0);
    let mut gw = gateway(Policy::ForwardAll);
    let mut up = Fake {
        input: input.to_vec(),
        ..Fake::default()
    };
    let mut down = Unplugging { reads_left: 2_000 };
    let ms = core::cell::Cell::new(0u32);
    let result = run_one_upstream(
        speaks,
        &mut bridge,
        &mut gw,
        &mut up,
        &mut down,
        || ms.get(),
        || ms.get() * 1_000,
        |_| ms.set(ms.get() + 1),
        || {},
    );
    assert!(matches!(result, Err(Error::Downstream(UNPLUGGED))));
    up.output
}

#[test]
fn one_upstream_port_speaks_what_the_block_chooses() {
    use iai_protocol_b::checksum::ChecksumMode;
    use iai_protocol_b::frame::{emit_frame, Header, Station};
    // The bridge's status query (B00H to its own station BB).
    let mut status = [0u8; 16];
    let n = emit_frame(
        &mut status,
        Header::Command,
        Station(0xBB),
        crate::codes::STATUS_QUERY,
        ChecksumMode::Compute,
        |_| Ok(()),
    )
    .unwrap();
    let status = &status[..n];

    // Modbus RTU: the request answered (an address outside the map),
    // a protocol-B frame met with silence.
    assert_eq!(
        one_upstream(UpstreamProtocol::ModbusRtu, &READ_9006),
        EXCEPTION_03_02
    );
    assert!(one_upstream(UpstreamProtocol::ModbusRtu, status).is_empty());

    // Protocol B: the bridge answers its status query with `#`; the Modbus
    // request (no `!`, not a frame) gets nothing.
    let reply = one_upstream(UpstreamProtocol::ProtocolB, status);
    assert!(reply.starts_with(b"#BBB00"), "{reply:?}");
    assert!(one_upstream(UpstreamProtocol::ProtocolB, &READ_9006).is_empty());
}

/// `pdu` (unit ID first) asked over RTU and over TCP: the two answers'
/// unit and PDU, which must be the same (`None`: no answer on either). A
/// command the RTU request started is taken as confirmed before the TCP
/// one, which then starts it again.
fn both(gw: &mut Gateway, pdu: &[u8]) -> Option<Vec<u8>> {
    let on_rtu = ask(gw, &rtu(pdu));
    if gw.regs.hs.take().is_some() {
        gw.regs.hs.finish(Ok(()));
    }
    let on_tcp = ask_tcp(gw, &mbap(0x0A0B, pdu));
    if on_rtu.is_empty() {
        assert_eq!(on_tcp, [], "answered over TCP only: {pdu:02X?}");
        return None;
    }
    assert_eq!(rtu::crc16(&on_rtu), 0, "the RTU answer's CRC");
    let rtu_pdu = on_rtu[..on_rtu.len() - 2].to_vec();
    assert_eq!(
        on_tcp[..4],
        [0x0A, 0x0B, 0, 0],
        "transaction and protocol IDs"
    );
    assert_eq!(
        usize::from(u16::from_be_bytes([on_tcp[4], on_tcp[5]])),
        on_tcp.len() - 6,
        "the MBAP length"
    );
    assert_eq!(
        on_tcp[6..],
        rtu_pdu[..],
        "RTU and TCP answer alike: {pdu:02X?}"
    );
    Some(rtu_pdu)
}

#[test]
fn fc15_and_fc16_check_the_byte_count_against_the_quantity() {
    let mut gw = gateway(Policy::ForwardAll);
    // Coil 300 (output port 300), quantity 1: one byte of coils.
    assert_eq!(
        both(&mut gw, &[1, 15, 0x01, 0x2C, 0, 1, 1, 1]),
        Some(std::vec![1, 15, 0x01, 0x2C, 0, 1])
    );
    assert_eq!(gw.regs.hs.words()[2], 0x24A);
    let seq = gw.regs.hs.words()[0] & 0xFF;
    // Quantity 1 with two bytes, quantity 9 with one, quantity 0: 03, and
    // nothing carried out (the sequence number stays).
    for pdu in [
        &[1, 15, 0x01, 0x2C, 0, 1, 2, 1, 0][..],
        &[1, 15, 0x01, 0x2C, 0, 9, 1, 0xFF],
        &[1, 15, 0x01, 0x2C, 0, 0, 0],
        &[1, 15, 0x01, 0x2C, 0x07, 0xB1, 0],
    ] {
        assert_eq!(
            both(&mut gw, pdu),
            Some(std::vec![1, 0x8F, 3]),
            "{pdu:02X?}"
        );
    }
    // POSR of axis 1: quantity 1 with four bytes, quantity 2 with two.
    for pdu in [
        &[1, 16, 0x0D, 3, 0, 1, 4, 0, 9, 0, 9][..],
        &[1, 16, 0x0D, 3, 0, 2, 2, 0, 9],
        &[1, 16, 0x0D, 3, 0, 0x7C, 0],
    ] {
        assert_eq!(
            both(&mut gw, pdu),
            Some(std::vec![1, 0x90, 3]),
            "{pdu:02X?}"
        );
    }
    assert_eq!(gw.regs.posr[0], 0);
    assert_eq!(gw.regs.hs.words()[0] & 0xFF, seq, "no command started");
    // The same write with its byte count right.
    assert_eq!(
        both(&mut gw, &[1, 16, 0x0D, 3, 0, 1, 2, 0, 9]),
        Some(std::vec![1, 16, 0x0D, 3, 0, 1])
    );
    assert_eq!(gw.regs.posr[0], 9);
}

#[test]
fn device_identification_is_answered_alike_on_rtu_and_tcp() {
    use crate::modbus::ident::{FIRMWARE, PRODUCT, VENDOR};
    let mut gw = gateway(Policy::ForwardAll);
    // The recorded request of a common meter's manual: basic, stream.
    assert_eq!(rtu(&FUNCTION_2B[..5]), FUNCTION_2B);
    let mut want = std::vec![1, 0x2B, 0x0E, 1, 0x81, 0, 0, 3];
    for (id, text) in [(0u8, VENDOR), (1, PRODUCT), (2, FIRMWARE)] {
        want.extend([id, text.len() as u8]);
        want.extend(text.as_bytes());
    }
    assert_eq!(both(&mut gw, &FUNCTION_2B[..5]), Some(want));
    // Once the controller's 201H reply is in, object 2 carries it too.
    gw.regs.cache.version = Some(iai_protocol_b::message::VersionResponse {
        version_number: 0x0107,
        ..Default::default()
    });
    let one = both(&mut gw, &[1, 0x2B, 0x0E, 4, 2]).unwrap();
    let text = std::str::from_utf8(&one[10..]).unwrap();
    assert!(
        text.starts_with(&std::format!("{FIRMWARE}; controller 0107 ")),
        "{text}"
    );
    // What is not served: 01 on both, alike; a misused 43/14: 02 or 03.
    for (pdu, code) in [
        (&[1, 0x2B, 0x0D, 1, 0][..], 1),
        (&[1, 0x2B][..], 1),
        (&[1, 0x2B, 0x0E, 4, 9][..], 2),
        (&[1, 0x2B, 0x0E, 7, 0][..], 3),
        (&[1, 0x11][..], 1),
        (&[1, 0x08, 0, 0, 0x12, 0x34][..], 1),
        (&[1, 0x17, 0, 0, 0, 1, 0, 0, 0, 1, 2, 0, 0][..], 1),
    ] {
        assert_eq!(
            both(&mut gw, pdu),
            Some(std::vec![1, pdu[1] | 0x80, code]),
            "{pdu:02X?}"
        );
    }
    // Broadcast or another unit: no answer on either.
    assert_eq!(both(&mut gw, &[0, 0x2B, 0x0E, 1, 0]), None);
    assert_eq!(both(&mut gw, &[2, 0x11]), None);
}

#[test]
fn unit_255_over_tcp_is_the_gateway_itself() {
    let mut gw = gateway(Policy::ForwardAll);
    gw.regs.cache.axes[0].current_position = -25_500;
    // Over TCP, 255 reads what the configured unit (1) reads, and the
    // answer carries 255.
    assert_eq!(
        ask_tcp(&mut gw, &mbap(5, &[0xFF, 3, 0x90, 0, 0, 2])),
        [0, 5, 0, 0, 0, 7, 0xFF, 3, 4, 0xFF, 0xFF, 0x9C, 0x64]
    );
    assert_eq!(
        ask_tcp(&mut gw, &mbap(6, &[0xFF, 0x2B, 0x0E, 4, 0]))[6..9],
        [0xFF, 0x2B, 0x0E]
    );
    assert_eq!(
        ask_tcp(&mut gw, &mbap(7, &[0xFF, 0x11])),
        [0, 7, 0, 0, 0, 3, 0xFF, 0x91, 1]
    );
    // A write through 255: the same handshake, echoed with 255.
    let servo = mbap(8, &[0xFF, 6, 0x0D, 0, 0x10, 0]);
    assert_eq!(ask_tcp(&mut gw, &servo), servo);
    assert_eq!(gw.regs.hs.words()[2], 0x232);
    // On an RTU line 255 is nobody's unit here: no answer.
    assert_eq!(ask(&mut gw, &rtu(&[0xFF, 3, 0x90, 0, 0, 2])), []);
}

#[test]
fn cmdst_counts_accepted_commands_only() {
    let mut gw = gateway(Policy::ForwardAll);
    let seq = |gw: &Gateway| gw.regs.hs.words()[0] & 0xFF;
    assert_eq!(ask(&mut gw, &SERVO_ON_1), SERVO_ON_1);
    assert_eq!(seq(&gw), 1);
    // Busy (06), two commands in one write (03), a policy refusal (01
    // elsewhere): the sequence number stays.
    assert_eq!(ask(&mut gw, &HOME_1), EXCEPTION_06_06);
    assert_eq!(seq(&gw), 1);
    gw.regs.hs.take();
    gw.regs.hs.finish(Ok(()));
    assert_eq!(gw.regs.hs.words()[0], CMD_DONE | 1);
    assert_eq!(
        ask(&mut gw, &rtu(&[1, 6, 0x0D, 0, 0x01, 0x18]))[..3],
        [1, 0x86, 3]
    );
    assert_eq!(seq(&gw), 1);
    // A setting is no command: POSR and PRGNO leave it.
    assert_eq!(ask(&mut gw, &rtu(&[1, 6, 0x0D, 3, 0, 4])).len(), 8);
    assert_eq!(seq(&gw), 1);
    // The next accepted command: 2.
    assert_eq!(ask(&mut gw, &HOME_1), HOME_1);
    assert_eq!(seq(&gw), 2);
}

#[test]
fn window_misuses_by_exception_code() {
    let mut gw = gateway(Policy::ForwardAll);
    // A first position above 65531 (the window would pass 65535): 03.
    assert_eq!(
        ask(&mut gw, &rtu(&[1, 6, 0x21, 0xF0, 0xFF, 0xFC]))[..3],
        [1, 0x86, 3]
    );
    assert_eq!(ask(&mut gw, &rtu(&[1, 6, 0x21, 0xF0, 0xFF, 0xFB])).len(), 8);
    gw.regs.hs.take();
    gw.regs.hs.finish(Ok(()));
    // A record with axis pattern 0 (no meaning in 26DH; read back it means
    // "not defined") or above FFH: 03, nothing staged.
    for pattern in [0u16, 0x100] {
        let mut one = std::vec![1, 16, 0x22, 0x00, 0, 21, 42];
        let words: [u16; 21] = [
            3, pattern, 30, 30, 100, 0, 1000, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
        ];
        for w in words {
            one.extend(w.to_be_bytes());
        }
        assert_eq!(
            ask(&mut gw, &rtu(&one))[..3],
            [1, 0x90, 3],
            "pattern {pattern}"
        );
    }
    assert_eq!(gw.regs.window[0], 0);
    // Gaps inside an axis block (9006H..900FH) and FC 04 on a holding
    // register: 02.
    for addr in [0x9006u16, 0x900F, 0x9906] {
        let [a, b] = addr.to_be_bytes();
        let r = ask(&mut gw, &rtu(&[1, 4, a, b, 0, 1]));
        assert_eq!(r[..3], [1, 0x84, 2], "{addr:04X}");
    }
    assert_eq!(
        ask(&mut gw, &rtu(&[1, 4, 0x21, 0xF0, 0, 1]))[..3],
        [1, 0x84, 2]
    );
    // A read that runs from a block into its gap: 02.
    assert_eq!(
        ask(&mut gw, &rtu(&[1, 3, 0x90, 0x05, 0, 2]))[..3],
        [1, 0x83, 2]
    );
}
