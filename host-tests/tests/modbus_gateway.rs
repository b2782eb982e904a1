//! The Modbus gateway against the simulator in virtual time: cached
//! reads, every command through the handshake, the polling and its ages,
//! the policy, a controller that stops answering, and the protocol-B host
//! on the same line. Latencies are printed (`--nocapture`), not asserted
//! against wall time.

use firmware_example::codes;
use firmware_example::config::{Config, Policy};
use firmware_example::modbus::ident::FIRMWARE;
use firmware_example::modbus::map::{CMD_BUSY, CMD_DONE, CMD_ERROR, HEND, MOVE, PEND, PWR, SV};
use host_tests::modbus_model::{read_request, registers, rtu_frame, write_request, Rig};

/// Reads `count` registers from `addr` (function 03).
fn read(rig: &mut Rig, addr: u16, count: u16) -> Vec<u16> {
    let (r, _) = rig
        .request(&read_request(3, addr, count))
        .expect("answered");
    registers(&r).expect("no exception")
}

/// Writes registers; the exception code if refused.
fn write(rig: &mut Rig, addr: u16, values: &[u16]) -> Result<(), u8> {
    let req = write_request(addr, values);
    let (r, _) = rig.request(&req).expect("answered");
    match r.get(1) {
        Some(f) if f & 0x80 != 0 => Err(r[2]),
        _ => Ok(()),
    }
}

/// Polls CMDST every 10 ms, as a PLC would, until the command is no
/// longer busy: `(status word, error code, ms from the write)`.
fn handshake(rig: &mut Rig, since_ms: u64) -> (u16, u16, u64) {
    loop {
        let w = read(rig, 0xB100, 3);
        if w[0] & CMD_BUSY == 0 {
            return (w[0], w[1], rig.now_ms() - since_ms);
        }
        assert!(rig.now_ms() - since_ms < 30_000, "still busy");
        rig.run_for(10);
    }
}

/// Writes and waits for the handshake; prints its latency.
fn command(rig: &mut Rig, what: &str, addr: u16, values: &[u16]) -> (u16, u16) {
    let t0 = rig.now_ms();
    write(rig, addr, values).expect("accepted");
    let (st, code, ms) = handshake(rig, t0);
    println!("handshake {what}: {ms} ms (status {st:04X}, code {code:03X})");
    (st, code)
}

/// Waits until DSS1 of axis 1 has `bits`.
fn wait_dss1(rig: &mut Rig, bits: u16) -> u64 {
    let t0 = rig.now_ms();
    loop {
        if read(rig, 0x9005, 1)[0] & bits == bits {
            return rig.now_ms() - t0;
        }
        assert!(rig.now_ms() - t0 < 30_000, "DSS1 never had {bits:04X}");
        rig.run_for(10);
    }
}

fn rig() -> Rig {
    start(Config::DEFAULT)
}

/// A rig whose gateway was addressed (it polls from then on) and has
/// polled a round.
fn start(cfg: Config) -> Rig {
    let mut rig = Rig::new(cfg);
    rig.run_for(300);
    assert_eq!(
        rig.sim.stats().commands,
        0,
        "no polls before a master speaks"
    );
    let (r, _) = rig.request(&read_request(4, 0xB000, 1)).unwrap();
    assert_eq!(registers(&r).unwrap(), [0], "link not up yet");
    rig.run_for(300);
    rig
}

#[test]
fn a_plc_homes_moves_and_reads_the_position_back() {
    let mut rig = rig();
    let (r, ns) = rig.request(&read_request(4, 0x9000, 6)).unwrap();
    println!(
        "cached read of PNOW..DSS1 (6 registers): {} us after the request's last byte",
        ns / 1_000
    );
    assert_eq!(registers(&r).unwrap()[5], PWR, "link up, servo off");
    assert_eq!(read(&mut rig, 0xB000, 1), [1], "health: link up");

    let (st, _) = command(&mut rig, "servo on (DRG1 SON, 232H)", 0x0D00, &[0x1000]);
    assert_eq!(st & CMD_DONE, CMD_DONE);
    wait_dss1(&mut rig, SV);
    let (st, _) = command(&mut rig, "home (DRG1 HOME, 233H)", 0x0D00, &[0x1010]);
    assert_eq!(st & CMD_DONE, CMD_DONE);
    // Homing takes its time: HEND only from a poll after the command.
    println!("home end after {} ms more", wait_dss1(&mut rig, HEND));
    // The numeric move: 25.5 mm at 200 mm/s, 0.3 G.
    let target: i32 = 25_500;
    let [hi, lo] = [(target >> 16) as u16, target as u16];
    let (st, _) = command(
        &mut rig,
        "numeric move (9900H, 234H)",
        0x9900,
        &[hi, lo, 0, 0, 0, 200, 30, 0, 0],
    );
    assert_eq!(st & CMD_DONE, CMD_DONE);
    println!("position end after {} ms more", wait_dss1(&mut rig, PEND));
    let pnow = read(&mut rig, 0x9000, 2);
    let pnow = (u32::from(pnow[0]) << 16 | u32::from(pnow[1])) as i32;
    assert_eq!(pnow, target);
    assert_eq!(pnow, rig.sim.axes[0].position(rig.now_ms() as u32));
    // A move to a position number: POSR, then CSTR's rising edge (26BH).
    // Position 9 is not defined: the controller refuses, the handshake
    // says error with the controller's code.
    write(&mut rig, 0x0D03, &[9]).unwrap();
    let (st, code) = command(
        &mut rig,
        "move to POSR (DRG1 CSTR, 26BH)",
        0x0D00,
        &[0x1018],
    );
    assert_eq!((st & CMD_ERROR, code), (CMD_ERROR, 0x0E7));
    let (st, _) = command(&mut rig, "stop (DRG1 STP, 238H)", 0x0D00, &[0x1030]);
    assert_eq!(st & CMD_DONE, CMD_DONE);
    let (st, _) = command(&mut rig, "alarm reset (DRG1 ALRS, 252H)", 0x0D00, &[0x1130]);
    assert_eq!(st & CMD_DONE, CMD_DONE);
}

#[test]
fn ports_flags_and_variables_through_the_handshake() {
    let mut rig = rig();
    // Coil 300 (output port 300) on: the simulator wires it to input 0.
    let t0 = rig.now_ms();
    let (r, _) = rig
        .request(&rtu_frame(&[1, 5, 0x01, 0x2C, 0xFF, 0x00]))
        .unwrap();
    assert_eq!(r[..6], [1, 5, 0x01, 0x2C, 0xFF, 0x00]);
    let (st, _, ms) = handshake(&mut rig, t0);
    println!("handshake output port (coil, 24AH): {ms} ms");
    assert_eq!(st & CMD_DONE, CMD_DONE);
    // Flag 600 on.
    let t0 = rig.now_ms();
    rig.request(&rtu_frame(&[1, 5, 0x02, 0x58, 0xFF, 0x00]))
        .unwrap();
    let (st, _, ms) = handshake(&mut rig, t0);
    println!("handshake flag (coil, 24BH): {ms} ms");
    assert_eq!(st & CMD_DONE, CMD_DONE);
    let (st, _) = command(
        &mut rig,
        "integer variables (24CH)",
        0x20E0,
        &[0, 100, 0xFFFF, 0xFFFF],
    );
    assert_eq!(st & CMD_DONE, CMD_DONE);
    // The next round shows them.
    rig.run_for(200);
    let (r, _) = rig.request(&rtu_frame(&[1, 2, 0, 0, 0, 8])).unwrap();
    assert_eq!(r[..4], [1, 2, 1, 0x01], "input 0 on");
    let (r, _) = rig.request(&rtu_frame(&[1, 1, 0x02, 0x58, 0, 1])).unwrap();
    assert_eq!(r[..4], [1, 1, 1, 0x01], "flag 600 on");
    assert_eq!(read(&mut rig, 0x20E0, 4), [0, 100, 0xFFFF, 0xFFFF]);
    // Several coils in one write: 03.
    let (r, _) = rig
        .request(&rtu_frame(&[1, 15, 0x01, 0x2C, 0, 2, 1, 3]))
        .unwrap();
    assert_eq!(r[..3], [1, 0x8F, 3]);
}

#[test]
fn the_table_window_writes_read_back_and_reads() {
    let mut rig = rig();
    // Positions 10..14, axis 1 at n mm and axis 2 at -n mm.
    let mut words = Vec::new();
    for n in 10u16..15 {
        let a = i32::from(n) * 1_000;
        words.extend([n, 0b11, 30, 30, 100]);
        for (k, v) in [a, -a].into_iter().enumerate() {
            let _ = k;
            words.extend([(v >> 16) as u16, v as u16]);
        }
        words.extend([0u16; 12]);
    }
    let (st, _) = command(
        &mut rig,
        "table window write (26DH, read back)",
        0x2200,
        &words,
    );
    assert_eq!(st & CMD_DONE, CMD_DONE);
    assert_eq!(rig.sim.table.len(), 5);
    let (st, _) = command(&mut rig, "table window read (21FH)", 0x21F0, &[10]);
    assert_eq!(st & CMD_DONE, CMD_DONE);
    assert_eq!(read(&mut rig, 0x2200, 105), words);
    // Positions the controller does not hold read as their number alone.
    command(&mut rig, "table window read (21FH)", 0x21F0, &[13]);
    let w = read(&mut rig, 0x2200, 105);
    assert_eq!(w[..2], [13, 0b11]);
    assert_eq!(w[42..44], [15, 0]);
}

#[test]
fn the_policy_refuses_with_01_and_counts() {
    let mut cfg = Config::DEFAULT;
    cfg.policy = Policy::ReadOnly;
    let mut rig = start(cfg);
    assert_eq!(write(&mut rig, 0x0D00, &[0x1000]), Err(1));
    assert_eq!(write(&mut rig, 0x21F0, &[1]), Ok(()), "a query is allowed");
    assert_eq!(read(&mut rig, 0xB008, 1), [1], "one refused");
    assert!(!rig.sim.axes[0].servo);
}

#[test]
fn a_controller_that_stops_answering() {
    let mut rig = rig();
    rig.sim.faults.stop_after_commands = Some(rig.sim.stats().commands);
    rig.run_for(4_000);
    let (r, ns) = rig.request(&read_request(4, 0xB000, 5)).unwrap();
    let h = registers(&r).unwrap();
    println!(
        "cached read while the controller is silent: {} us; axis data {} ms old",
        ns / 1_000,
        h[1]
    );
    assert_eq!(h[0], 0, "link down");
    assert!(h[1] >= 3_000, "the axis data ages: {}", h[1]);
    assert_eq!(read(&mut rig, 0x9005, 1)[0] & PWR, 0);
    // A command: busy meanwhile (a second one is 06), then error B02.
    let t0 = rig.now_ms();
    write(&mut rig, 0x0D00, &[0x1000]).unwrap();
    assert_eq!(write(&mut rig, 0x0D00, &[0x1010]), Err(6));
    let (st, code, ms) = handshake(&mut rig, t0);
    println!("handshake with a silent controller: {ms} ms");
    assert_eq!(
        (st & CMD_ERROR, code),
        (CMD_ERROR, codes::CONTROLLER_TIMEOUT)
    );
}

#[test]
fn the_protocol_b_host_keeps_its_line_and_gets_only_its_replies() {
    let mut rig = rig();
    // The host's 212H, forty times, while the gateway polls every 100 ms.
    let q = b"!992120189\r\n";
    let mut worst = 0;
    for _ in 0..40 {
        let before = rig.host_replies.len();
        let sent = rig.now_ns() + 12 * 87_000;
        rig.host_send(q);
        while rig.host_replies.len() == before {
            rig.run_for(1);
            assert!(
                rig.now_ns().saturating_sub(sent) < 3_000_000_000,
                "no reply within 3 s"
            );
        }
        let (at, reply) = rig.host_replies.last().unwrap().clone();
        assert!(
            reply.starts_with(b"#99212"),
            "{}",
            String::from_utf8_lossy(&reply)
        );
        worst = worst.max(at.saturating_sub(sent));
        rig.run_for(37);
    }
    println!(
        "host 212H beside the gateway's polls: worst reply {} us",
        worst / 1_000
    );
    assert_eq!(rig.host_replies.len(), 40, "nothing but its own replies");
    assert!(
        read(&mut rig, 0xB005, 1)[0] > 10,
        "the gateway polled meanwhile"
    );
}

/// DSS1 of axis `axis`.
fn dss1(rig: &mut Rig, axis: u16) -> u16 {
    read(rig, 0x9005 + 0x10 * (axis - 1), 1)[0]
}

/// Waits until DSS1 of axis 1 has MOVE clear: `(DSS1 then, ms waited)`.
fn wait_rest(rig: &mut Rig) -> (u16, u64) {
    let t0 = rig.now_ms();
    loop {
        let d = dss1(rig, 1);
        if d & MOVE == 0 {
            return (d, rig.now_ms() - t0);
        }
        assert!(rig.now_ms() - t0 < 30_000, "MOVE never cleared: {d:04X}");
        rig.run_for(10);
    }
}

/// Servo on and home axis 1, waited for as the README says.
fn servo_and_home(rig: &mut Rig) {
    command(rig, "servo on", 0x0D00, &[0x1000]);
    wait_rest(rig);
    command(rig, "home", 0x0D00, &[0x1010]);
    let (d, _) = wait_rest(rig);
    assert_eq!(d & HEND, HEND, "homed once at rest");
}

#[test]
fn after_a_stop_a_plc_waits_for_move_0_and_pend_stays_0() {
    let mut rig = rig();
    servo_and_home(&mut rig);
    // A long move: 200 mm at 10 mm/s.
    let target: i32 = 200_000;
    let mv = [(target >> 16) as u16, target as u16, 0, 0, 0, 10, 30, 0, 0];
    let (st, _) = command(&mut rig, "slow move", 0x9900, &mv);
    assert_eq!(st & CMD_DONE, CMD_DONE);
    // Done (the controller took the move) and on its way: MOVE, no PEND.
    rig.run_for(500);
    let d = dss1(&mut rig, 1);
    assert_eq!(d & (MOVE | PEND), MOVE, "moving: {d:04X}");
    // STP's rising edge (SON kept): done, then MOVE clears; PEND stays 0
    // (the move did not complete), the axis where it stopped.
    let (st, _) = command(&mut rig, "stop (DRG1 STP, 238H)", 0x0D00, &[0x1030]);
    assert_eq!(st & CMD_DONE, CMD_DONE);
    let (d, ms) = wait_rest(&mut rig);
    println!("after STP: MOVE 0 {ms} ms after done, DSS1 {d:04X}");
    assert_eq!(
        d & (MOVE | PEND | HEND | SV),
        HEND | SV,
        "at rest, not completed"
    );
    let pnow = read(&mut rig, 0x9000, 2);
    let pnow = (u32::from(pnow[0]) << 16 | u32::from(pnow[1])) as i32;
    assert!(0 < pnow && pnow < target, "stopped on the way: {pnow}");
    assert_eq!(pnow, rig.sim.axes[0].position(rig.now_ms() as u32));
    // PEND never comes: a PLC that waited for it would wait forever.
    rig.run_for(2_000);
    assert_eq!(dss1(&mut rig, 1) & PEND, 0);
    // An alarm reset: done, then MOVE 0 from a poll after it (held 1 until
    // then, so ALMH read after it is the controller's answer).
    write(&mut rig, 0x0D00, &[0x1000]).unwrap();
    let t0 = rig.now_ms();
    write(&mut rig, 0x0D00, &[0x1100]).unwrap();
    let (st, _, _) = handshake(&mut rig, t0);
    assert_eq!(st & CMD_DONE, CMD_DONE);
    assert_eq!(
        dss1(&mut rig, 1) & MOVE,
        MOVE,
        "not yet polled since the reset"
    );
    let (d, ms) = wait_rest(&mut rig);
    println!("after ALRS: MOVE 0 {ms} ms after done");
    assert_eq!(d & 0x0400, 0, "no alarm");
}

#[test]
fn cstr_moves_its_own_axis_only() {
    let mut rig = rig();
    servo_and_home(&mut rig);
    // Position 7 holds axes 1 and 2.
    let mut rec = vec![7u16, 0b11, 30, 30, 100, 0, 10_000, 0, 20_000];
    rec.extend([0u16; 12]);
    let (st, _) = command(&mut rig, "window write", 0x2200, &rec);
    assert_eq!(st & CMD_DONE, CMD_DONE);
    write(&mut rig, 0x0D03, &[7]).unwrap();
    let (st, _) = command(&mut rig, "CSTR on axis 1's block", 0x0D00, &[0x1008]);
    assert_eq!(st & CMD_DONE, CMD_DONE);
    let (d, _) = wait_rest(&mut rig);
    assert_eq!(d & PEND, PEND);
    let now = rig.now_ms() as u32;
    assert_eq!(rig.sim.axes[0].position(now), 10_000, "axis 1 moved");
    assert_eq!(rig.sim.axes[1].position(now), 0, "axis 2 did not");
}

#[test]
fn the_window_says_what_is_not_defined_and_what_an_axis_lacks() {
    let mut rig = rig();
    // Position 21: axis 2 only.
    let mut rec = vec![21u16, 0b10, 30, 40, 250, 0, 0, 0xFFFF, 0x9C64];
    rec.extend([0u16; 12]);
    command(&mut rig, "window write", 0x2200, &rec);
    command(&mut rig, "window read", 0x21F0, &[20]);
    let w = read(&mut rig, 0x2200, 105);
    // Position 20 is not defined: its number, pattern 0, all else 0.
    assert_eq!(
        w[..21],
        [20, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    );
    // Position 21 as written: acceleration and deceleration in 0.01 G,
    // speed mm/s, axis 1 (not in the pattern) 0, axis 2 -25.500 mm.
    assert_eq!(w[21..42], rec[..]);
    let rec21 = &rig.sim.table[&21];
    assert_eq!(
        (rec21.acceleration, rec21.deceleration, rec21.speed),
        (30, 40, 250)
    );
    assert_eq!(rec21.position(2), Some(-25_500));
}

#[test]
fn device_identification_carries_the_controllers_version_once_the_line_is_up() {
    let mut rig = Rig::new(Config::DEFAULT);
    let revision = |rig: &mut Rig| {
        let req = rtu_frame(&[1, 0x2B, 0x0E, 4, 2]);
        let (r, _) = rig.request(&req).expect("answered");
        assert_eq!(r[..10], [1, 0x2B, 0x0E, 4, 0x81, 0, 0, 1, 2, r[9]]);
        String::from_utf8(r[10..r.len() - 2].to_vec()).unwrap()
    };
    // Before any poll: the firmware's version alone.
    assert_eq!(revision(&mut rig), FIRMWARE);
    rig.run_for(300);
    let with = format!("{FIRMWARE}; controller 0100 model 5A unit 01 2026-12-01");
    assert_eq!(revision(&mut rig), with);
    let asked = |rig: &Rig| rig.sim.stats().commands;
    // The controller goes silent, then answers again: asked once more.
    rig.sim.faults.stop_after_commands = Some(asked(&rig));
    rig.run_for(4_000);
    assert_eq!(read(&mut rig, 0xB000, 1), [0], "link down");
    assert_eq!(revision(&mut rig), FIRMWARE, "forgotten while down");
    // It answers again (a poll on the line meanwhile times out first).
    rig.sim.faults.stop_after_commands = None;
    let t0 = rig.now_ms();
    while revision(&mut rig) != with {
        assert!(rig.now_ms() - t0 < 10_000, "the version never came back");
        rig.run_for(100);
    }
    println!(
        "version known again {} ms after the controller answered again",
        rig.now_ms() - t0
    );
}
