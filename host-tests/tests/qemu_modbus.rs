//! The Modbus RTU gateway end to end, with third-party Modbus masters:
//! the gateway (`tools/gateway.sh`'s binary) runs the lm3s6965 firmware
//! under QEMU with the simulated controller behind it, and its
//! `modbus-rtu 127.0.0.1:PORT` is worked by
//!
//! 1. **pymodbus** (RTU framer on a TCP client, `host-tests/plc/
//!    pymodbus_plc.py`): servo on, home, wait for HEND, a numeric move to
//!    25.500 mm, wait for PEND, read PNOW; then 500 positions of 8 axes
//!    written through the table window (2200H) and read back through it
//!    (21F0H, 2200H), equal;
//! 2. **mbpoll** (RTU through a pty that socat bridges to the TCP port):
//!    servo on (off first if the PLC before left it on), home, wait for HEND, a numeric move to 12.000 mm,
//!    wait for PEND, read PNOW; read the first five positions back through
//!    the window.
//!
//! After each, PNOW is compared with the simulator's 212H, asked by the
//! real `iai` tool on the protocol-B port; after pymodbus, `iai table
//! read --all` gives exactly the 500 positions the PLC wrote.
//!
//! pymodbus comes from the venv `tools/setup.sh` makes (`.venv`), mbpoll
//! and socat from Debian packages it installs. A client that is absent is
//! skipped with its reason printed; the test fails if both are.

mod plc_gateway;

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use host_tests::qemu::{build_firmware, workspace_root, Board};
use host_tests::table::table;
use iai_protocol_b::position::PositionRecord;
use plc_gateway::{on_path, pymodbus_python, run_within, Gateway};

/// Positions pymodbus writes and reads back.
const POSITIONS: u32 = 500;
/// Registers of one record in the table window.
const RECORD_WORDS: usize = 21;
const DRG1: u16 = 0x0D00;
const PNOW: u16 = 0x9000;
const DSS1: u16 = 0x9005;
const MOVN: u16 = 0x9900;
const PWHEAD: u16 = 0x21F0;
const PWREC: u16 = 0x2200;
const CMDST: u16 = 0xB100;
const SON: u16 = 0x1000;
const HOME: u16 = 0x1010;
const CMD_ERROR: u16 = 1 << 15;
const CMD_BUSY: u16 = 1 << 14;
const CMD_DONE: u16 = 1 << 13;
const SV: u16 = 1 << 12;
const HEND: u16 = 1 << 4;
const PEND: u16 = 1 << 3;

/// A record as its 21 window registers: number, axis pattern,
/// acceleration, deceleration, speed, axes 1 to 8 (high word first).
fn record_words(r: &PositionRecord) -> Vec<u16> {
    let mut w = vec![
        r.number,
        u16::from(r.axes.bits()),
        r.acceleration,
        r.deceleration,
        r.speed,
    ];
    let mut at = r.positions.iter();
    for axis in 0..8 {
        let v = if r.axes.bits() & (1 << axis) != 0 {
            at.next().copied().unwrap_or(0)
        } else {
            0
        };
        let v = v as u32;
        w.extend([(v >> 16) as u16, v as u16]);
    }
    assert_eq!(w.len(), RECORD_WORDS);
    w
}

/// mbpoll on the pty `dev`: RTU, unit 1, 115,200 baud, even parity,
/// PDU addresses, once.
struct Mbpoll {
    dev: PathBuf,
}

impl Mbpoll {
    fn run(&mut self, args: &[&str]) -> String {
        let out = run_within(
            Command::new("mbpoll")
                .args(["-m", "rtu", "-a", "1", "-b", "115200", "-P", "even"])
                .args(["-0", "-1", "-q", "-o", "1"])
                .args(args.iter().take_while(|a| **a != "--"))
                .arg(&self.dev)
                .args(args.iter().skip_while(|a| **a != "--")),
            Duration::from_secs(10),
        );
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "mbpoll {args:?}: {}\n{text}\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
        text
    }

    /// `count` values from `addr` of data type `kind` (`3:hex`, `4:hex`,
    /// `3:int`), as mbpoll prints them (`[ref]: value`).
    fn read(&mut self, kind: &str, addr: u16, count: usize) -> Vec<i64> {
        let text = self.run(&[
            "-t",
            kind,
            "-B",
            "-r",
            &addr.to_string(),
            "-c",
            &count.to_string(),
        ]);
        let values: Vec<i64> = text
            .lines()
            .filter_map(|l| l.trim().strip_prefix('['))
            .filter_map(|l| l.split_once("]:"))
            .map(|(_, v)| {
                let v = v.trim();
                match v.strip_prefix("0x") {
                    Some(h) => i64::from_str_radix(h, 16),
                    None => v.parse(),
                }
                .unwrap_or_else(|_| panic!("mbpoll value {v:?} in:\n{text}"))
            })
            .collect();
        assert_eq!(values.len(), count, "mbpoll read {addr:04X}:\n{text}");
        values
    }

    fn words(&mut self, space: u8, addr: u16, count: usize) -> Vec<u16> {
        let kind = format!("{space}:hex");
        self.read(&kind, addr, count)
            .into_iter()
            .map(|v| u16::try_from(v).expect("a 16-bit register"))
            .collect()
    }

    /// Writes holding registers and waits through the handshake for done.
    fn command(&mut self, what: &str, addr: u16, values: &[u16]) {
        let seq = self.words(3, CMDST, 1)[0] & 0xFF;
        let mut args = vec!["-t".to_owned(), "4".to_owned(), "-r".to_owned()];
        args.push(addr.to_string());
        args.push("--".to_owned());
        args.extend(values.iter().map(u16::to_string));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let text = self.run(&args);
        assert!(
            text.contains(&format!("Written {} references", values.len())),
            "{text}"
        );
        let end = Instant::now() + Duration::from_secs(30);
        loop {
            let st = self.words(3, CMDST, 3);
            assert_ne!(st[0] & 0xFF, seq, "{what}: the write started no command");
            if st[0] & CMD_BUSY == 0 {
                assert_eq!(
                    st[0] & (CMD_DONE | CMD_ERROR),
                    CMD_DONE,
                    "{what}: status {:04X}, code {:03X}",
                    st[0],
                    st[1]
                );
                return;
            }
            assert!(Instant::now() < end, "{what}: still busy after 30 s");
        }
    }

    /// Reads DSS1 until `bits` are all set (or all clear with `set` false).
    fn wait_dss1(&mut self, bits: u16, set: bool) {
        let end = Instant::now() + Duration::from_secs(30);
        loop {
            let d = self.words(3, DSS1, 1)[0];
            let ok = if set { d & bits == bits } else { d & bits == 0 };
            if ok {
                return;
            }
            assert!(
                Instant::now() < end,
                "DSS1 {d:04X}: bits {bits:04X} never {set}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// socat bridging a pty to the Modbus TCP port; killed when dropped.
struct Socat(Child);

impl Drop for Socat {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn pymodbus_and_mbpoll_run_a_plcs_sequence_through_the_gateway() {
    let python = pymodbus_python();
    let mbpoll = if !on_path("mbpoll") {
        Err("mbpoll is not installed".to_owned())
    } else if !on_path("socat") {
        Err("socat is not installed".to_owned())
    } else {
        Ok(())
    };
    if let Err(why) = &python {
        println!("SKIPPED the pymodbus part: {why} (tools/setup.sh installs it)");
    }
    if let Err(why) = &mbpoll {
        println!("SKIPPED the mbpoll part: {why} (tools/setup.sh installs it)");
    }
    assert!(
        python.is_ok() || mbpoll.is_ok(),
        "neither pymodbus nor mbpoll: run tools/setup.sh"
    );

    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let iai = host_tests::qemu::iai_binary().expect("the iai binary");
    let mut gw = Gateway::start(&elf, false);
    let tmp = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let records: Vec<PositionRecord> = table(POSITIONS, 8, 2026).collect();

    if let Ok(py) = &python {
        let file = tmp.join(format!("modbus-table-{}.txt", std::process::id()));
        plc_gateway::write_table_file(&file, &records);
        let t0 = Instant::now();
        let out = run_within(
            Command::new(py)
                .arg(workspace_root().join("host-tests/plc/pymodbus_plc.py"))
                .args(["127.0.0.1", gw.modbus_port()])
                .arg(&file),
            Duration::from_secs(150),
        );
        let _ = std::fs::remove_file(&file);
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        println!("pymodbus ({:.1} s):\n{stdout}", t0.elapsed().as_secs_f64());
        assert!(
            out.status.success(),
            "pymodbus: {}\n{stdout}\n{}\ngateway:\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr),
            gw.log()
        );
        assert!(stdout.lines().any(|l| l == "pnow 25500"), "{stdout}");
        assert!(
            stdout
                .lines()
                .any(|l| l == format!("table {POSITIONS} written, read back equal")),
            "{stdout}"
        );
        assert_eq!(gw.axis1_position(&iai), 25_500, "the simulator's 212H");

        // The controller holds what the PLC wrote: iai reads it back.
        gw.assert_controller_holds(&iai, &records);
    }

    if mbpoll.is_ok() {
        let t0 = Instant::now();
        let dev = tmp.join(format!("mbpoll-{}.pty", std::process::id()));
        let _ = std::fs::remove_file(&dev);
        let socat = Command::new("socat")
            .arg(format!("pty,link={},raw,echo=0", dev.display()))
            .arg(format!("tcp:{}", gw.modbus))
            .stdin(Stdio::null())
            .spawn()
            .expect("start socat");
        let _socat = Socat(socat);
        let end = Instant::now() + Duration::from_secs(5);
        while !dev.exists() {
            assert!(Instant::now() < end, "socat made no pty");
            std::thread::sleep(Duration::from_millis(20));
        }
        let mut mb = Mbpoll { dev: dev.clone() };
        // SON is a level against DRG1 as last written: a servo off only
        // when the PLC before left SON set (without pymodbus, nobody did,
        // and writing 0 over 0 starts no command).
        if mb.words(4, DRG1, 1)[0] & SON != 0 {
            mb.command("servo off", DRG1, &[0]);
            mb.wait_dss1(SV, false);
        }
        mb.command("servo on", DRG1, &[SON]);
        mb.wait_dss1(SV, true);
        mb.command("home", DRG1, &[HOME]);
        mb.wait_dss1(HEND, true);
        let target: i32 = 12_000;
        let t = target as u32;
        let mv = [(t >> 16) as u16, t as u16, 0, 0, 0, 100, 30, 0, 0];
        mb.command("numeric move", MOVN, &mv);
        mb.wait_dss1(PEND, true);
        let pnow = mb.read("3:int", PNOW, 1)[0];
        assert_eq!(pnow, i64::from(target), "PNOW read by mbpoll");
        assert_eq!(gw.axis1_position(&iai), pnow, "the simulator's 212H");
        // Five positions written through the window and read back.
        let five: Vec<u16> = records.iter().take(5).flat_map(record_words).collect();
        mb.command("window write", PWREC, &five);
        mb.command("window read", PWHEAD, &[1]);
        let back = mb.words(4, PWREC, 5 * RECORD_WORDS);
        assert_eq!(back, five, "positions 1 to 5 read back by mbpoll");
        println!(
            "mbpoll through socat: servo on (off first if a PLC left it on), home, move, PNOW {pnow}, \
             5 positions written and read back, {:.1} s",
            t0.elapsed().as_secs_f64()
        );
        let _ = std::fs::remove_file(&dev);
    }

    let status = gw.stop();
    let log = gw.log();
    assert!(status.success(), "{status}\n{log}");
    println!("{log}");
}
