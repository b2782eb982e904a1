//! A PLC's sequence run by mbpoll (Debian's command-line Modbus master),
//! one process per request, on either of the gateway's Modbus fronts:
//! RTU through a pty that socat bridges to the `modbus-rtu` TCP port, or
//! Modbus TCP (`-m tcp`) on the Ethernet build's `modbus-tcp` port.
//!
//! The sequence: servo on (off first if the PLC before left SON set in
//! DRG1), home, wait for HEND, a numeric move, wait for PEND, PNOW read
//! and compared with the simulator's 212H (asked by the real `iai` tool on
//! the protocol-B port); then a table written through the window (2200H),
//! a whole window of five records per mbpoll write, each write waited for
//! through the handshake (CMDST) by mbpoll reads; read back through the
//! window (a write of its first position to 21F0H, the handshake, one read
//! of the whole window) and compared; then `iai table read` on the
//! protocol-B port must give exactly that table.
//!
//! An mbpoll call takes about 30 ms (20 of them mbpoll's own sleep after
//! it connects), about as long as a command takes to finish, so the
//! first CMDST read after a write waits as long as the last few commands
//! at that address took: about one read per command instead of three.
//!
//! A reply lost on the way (QEMU loses a few under load) is handled as a
//! PLC does, as `host-tests/plc/pymodbus_plc.py` does: a read is asked
//! again; a write whose reply was lost is asked again only if CMDST's
//! sequence number says the gateway did not take it. A Modbus exception
//! fails at once.

use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use iai_protocol_b::position::PositionRecord;

use super::{record_words, run_within};
use crate::gateway_proc::Gateway;

/// Records in the table window.
pub const WINDOW: usize = 5;
pub const DRG1: u16 = 0x0D00;
pub const PNOW: u16 = 0x9000;
pub const DSS1: u16 = 0x9005;
pub const MOVN: u16 = 0x9900;
pub const PWHEAD: u16 = 0x21F0;
pub const PWREC: u16 = 0x2200;
pub const CMDST: u16 = 0xB100;
pub const SON: u16 = 0x1000;
pub const HOME: u16 = 0x1010;
pub const CMD_ERROR: u16 = 1 << 15;
pub const CMD_BUSY: u16 = 1 << 14;
pub const CMD_DONE: u16 = 1 << 13;
pub const SV: u16 = 1 << 12;
pub const HEND: u16 = 1 << 4;
pub const PEND: u16 = 1 << 3;
/// Where the numeric move goes, 0.001 mm (pymodbus_plc.py goes to
/// 25.500 mm, so a PLC after it moves the axis).
pub const MOVE_TO: i32 = 12_000;
/// Attempts at one request whose reply is lost.
const ATTEMPTS: u32 = 5;
/// Handshakes per command address the first CMDST read's delay is taken
/// from.
const SETTLE_SEEN: usize = 5;
/// How much sooner the first CMDST read comes after one that found the
/// command done already.
const SETTLE_PROBE: Duration = Duration::from_millis(5);
/// How long a command or a DSS1 bit may take.
const WAIT: Duration = Duration::from_secs(30);

/// How mbpoll reaches the gateway.
pub enum Link {
    /// RTU on a pty that socat bridges to the gateway's `modbus-rtu` port
    /// (mbpoll's RTU mode opens a serial device); socat is stopped when
    /// the link is dropped.
    Rtu { dev: PathBuf, socat: Child },
    /// Modbus TCP to `127.0.0.1:port`.
    Tcp { port: String },
}

impl Link {
    /// socat bridging a new pty in `dir` to `addr` (`127.0.0.1:PORT`).
    pub fn rtu(addr: &str, dir: &Path) -> Link {
        let dev = dir.join(format!("mbpoll-{}.pty", std::process::id()));
        let _ = std::fs::remove_file(&dev);
        let socat = Command::new("socat")
            .arg(format!("pty,link={},raw,echo=0", dev.display()))
            .arg(format!("tcp:{addr}"))
            .stdin(Stdio::null())
            .spawn()
            .expect("start socat");
        let link = Link::Rtu {
            dev: dev.clone(),
            socat,
        };
        let end = Instant::now() + Duration::from_secs(5);
        while !dev.exists() {
            assert!(Instant::now() < end, "socat made no pty");
            std::thread::sleep(Duration::from_millis(20));
        }
        link
    }

    /// Modbus TCP to `addr` (`127.0.0.1:PORT`).
    pub fn tcp(addr: &str) -> Link {
        let port = addr.trim_start_matches("127.0.0.1:").to_owned();
        Link::Tcp { port }
    }

    fn name(&self) -> &'static str {
        match self {
            Link::Rtu { .. } => "RTU through socat",
            Link::Tcp { .. } => "-m tcp",
        }
    }

    /// mbpoll with this link's options, `args`, the device or host, then
    /// `values` to write (none: a read); unit 1, PDU addresses, once.
    fn command(&self, args: &[String], values: &[u16]) -> Command {
        let mut c = Command::new("mbpoll");
        match self {
            Link::Rtu { .. } => c.args(["-m", "rtu", "-b", "115200", "-P", "even"]),
            Link::Tcp { port } => c.args(["-m", "tcp", "-p", port]),
        };
        c.args(["-a", "1", "-0", "-1", "-q", "-o", "1"]).args(args);
        match self {
            Link::Rtu { dev, .. } => c.arg(dev),
            Link::Tcp { .. } => c.arg("127.0.0.1"),
        };
        if !values.is_empty() {
            c.arg("--").args(values.iter().map(u16::to_string));
        }
        c
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        if let Link::Rtu { dev, socat } = self {
            let _ = socat.kill();
            let _ = socat.wait();
            let _ = std::fs::remove_file(dev);
        }
    }
}

/// What one mbpoll call ended with.
enum Call {
    Done(String),
    /// No reply, or a damaged one: worth asking again.
    Lost(String),
}

/// Calls and their time, for one phase of the sequence.
#[derive(Default, Clone, Copy)]
pub struct Tally {
    pub calls: u32,
    pub time: Duration,
}

impl Tally {
    fn since(&self, before: &Tally) -> Tally {
        Tally {
            calls: self.calls - before.calls,
            time: self.time - before.time,
        }
    }
}

/// mbpoll on a [`Link`], counting its calls.
pub struct Mbpoll {
    link: Link,
    /// Every mbpoll process so far and the wall time they took.
    pub all: Tally,
    /// Of them, the CMDST reads that waited on the handshake.
    pub polls: u32,
    /// Calls whose reply was lost (and asked again).
    pub lost: u32,
    /// CMDST's sequence number as last read, when nothing can have
    /// changed it since (this process is the gateway's only master).
    seq: Option<u16>,
    /// Per command address, the last few handshakes' estimates of how
    /// long after the write's reply a CMDST read finds the command done.
    settle: HashMap<u16, VecDeque<Duration>>,
}

impl Mbpoll {
    pub fn new(link: Link) -> Mbpoll {
        Mbpoll {
            link,
            all: Tally::default(),
            polls: 0,
            lost: 0,
            seq: None,
            settle: HashMap::new(),
        }
    }

    fn call(&mut self, args: &[String], values: &[u16]) -> Call {
        let t0 = Instant::now();
        let out = run_within(
            &mut self.link.command(args, values),
            Duration::from_secs(10),
        );
        self.all.calls += 1;
        self.all.time += t0.elapsed();
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        if out.status.success() && !err.contains("failed") {
            return Call::Done(text);
        }
        // libmodbus's words for a reply that did not come or came damaged;
        // anything else (an exception, a refused option) is a failure.
        let lost = ["timed out", "Invalid CRC", "Invalid data", "reset by peer"];
        assert!(
            lost.iter().any(|l| err.contains(l)),
            "mbpoll {args:?} {values:?}: {}\n{text}\n{err}",
            out.status
        );
        self.lost += 1;
        Call::Lost(err)
    }

    /// `count` values from `addr` of data type `kind` (`3:hex`, `4:hex`,
    /// `3:int`), as mbpoll prints them (`[ref]: value`); asked again when
    /// the reply is lost.
    pub fn read(&mut self, kind: &str, addr: u16, count: usize) -> Vec<i64> {
        let args: Vec<String> = ["-t", kind, "-B", "-r", &addr.to_string()]
            .into_iter()
            .chain(["-c", &count.to_string()])
            .map(str::to_owned)
            .collect();
        let mut why = String::new();
        for _ in 0..ATTEMPTS {
            let text = match self.call(&args, &[]) {
                Call::Done(text) => text,
                Call::Lost(err) => {
                    why = err;
                    continue;
                }
            };
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
            return values;
        }
        panic!("mbpoll read {addr:04X}: no reply in {ATTEMPTS} attempts: {why}");
    }

    /// `count` 16-bit registers from `addr`: input registers (`space` 3)
    /// or holding registers (4).
    pub fn words(&mut self, space: u8, addr: u16, count: usize) -> Vec<u16> {
        self.read(&format!("{space}:hex"), addr, count)
            .into_iter()
            .map(|v| u16::try_from(v).expect("a 16-bit register"))
            .collect()
    }

    /// CMDST's three registers.
    fn cmdst(&mut self) -> [u16; 3] {
        let st = self.words(3, CMDST, 3);
        self.seq = Some(st[0] & 0xFF);
        [st[0], st[1], st[2]]
    }

    /// Writes holding registers (one mbpoll call) and waits through the
    /// handshake for done, reading CMDST with mbpoll until it is not busy.
    pub fn command(&mut self, what: &str, addr: u16, values: &[u16]) {
        let seq = match self.seq {
            Some(s) => s,
            None => self.cmdst()[0] & 0xFF,
        };
        // A command may change what nobody else should assume.
        self.seq = None;
        let args: Vec<String> = ["-t", "4", "-r", &addr.to_string()]
            .into_iter()
            .map(str::to_owned)
            .collect();
        let mut attempts = 0;
        loop {
            attempts += 1;
            match self.call(&args, values) {
                Call::Done(text) => {
                    assert!(
                        text.contains(&format!("Written {} references", values.len())),
                        "{what}: {text}"
                    );
                    break;
                }
                Call::Lost(err) => {
                    if self.cmdst()[0] & 0xFF != seq {
                        break;
                    }
                    assert!(attempts < ATTEMPTS, "{what}: no reply: {err}");
                }
            }
        }
        // A CMDST read before the command can be done is a call for
        // nothing: the first waits as long as the last few commands at
        // this address needed at most (the reads themselves come a call's
        // time, about 30 ms, apart).
        let written = Instant::now();
        let end = written + WAIT;
        if let Some(d) = self.settle.get(&addr).and_then(|d| d.iter().max()) {
            std::thread::sleep(*d);
        }
        let mut busy = None;
        loop {
            self.polls += 1;
            let asked = written.elapsed();
            let st = self.cmdst();
            assert_ne!(st[0] & 0xFF, seq, "{what}: the write started no command");
            if st[0] & CMD_BUSY == 0 {
                assert_eq!(
                    st[0] & (CMD_DONE | CMD_ERROR),
                    CMD_DONE,
                    "{what}: status {:04X}, code {:03X}",
                    st[0],
                    st[1]
                );
                // Done between the last busy read and this one; when the
                // first was done already, a little sooner may do next time.
                let estimate = match busy {
                    Some(b) => (b + asked) / 2,
                    None => asked.saturating_sub(SETTLE_PROBE),
                };
                let seen = self.settle.entry(addr).or_default();
                if seen.len() == SETTLE_SEEN {
                    seen.pop_front();
                }
                seen.push_back(estimate);
                return;
            }
            busy = Some(asked);
            assert!(Instant::now() < end, "{what}: still busy after {WAIT:?}");
        }
    }

    /// Reads DSS1 of axis 1 until `bits` are all set (or all clear with
    /// `set` false).
    pub fn wait_dss1(&mut self, bits: u16, set: bool) {
        let end = Instant::now() + WAIT;
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

/// The PLC's sequence by mbpoll on `link` (see the module's doc), with
/// `records` (numbered from 1, consecutive) as the table; prints what it
/// did, its calls and times, and returns PNOW.
pub fn plc_sequence(gw: &mut Gateway, iai: &Path, link: Link, records: &[PositionRecord]) -> i64 {
    let name = link.name();
    let t0 = Instant::now();
    let mut mb = Mbpoll::new(link);

    // SON is a level against DRG1 as last written: a servo off only when
    // the PLC before left SON set (without one, nobody did, and writing 0
    // over 0 starts no command).
    let servo_off = mb.words(4, DRG1, 1)[0] & SON != 0;
    if servo_off {
        mb.command("servo off", DRG1, &[0]);
        mb.wait_dss1(SV, false);
    }
    mb.command("servo on", DRG1, &[SON]);
    mb.wait_dss1(SV, true);
    mb.command("home", DRG1, &[HOME]);
    mb.wait_dss1(HEND, true);
    let t = MOVE_TO as u32;
    let mv = [(t >> 16) as u16, t as u16, 0, 0, 0, 100, 30, 0, 0];
    mb.command("numeric move", MOVN, &mv);
    mb.wait_dss1(PEND, true);
    let pnow = mb.read("3:int", PNOW, 1)[0];
    assert_eq!(pnow, i64::from(MOVE_TO), "PNOW read by mbpoll ({name})");
    assert_eq!(gw.axis1_position(iai), pnow, "the simulator's 212H");
    let motion = mb.all;
    let motion_wall = t0.elapsed();

    // The table, a whole window per mbpoll write.
    let first = records.first().expect("a table").number;
    for (i, r) in records.iter().enumerate() {
        assert_eq!(usize::from(r.number), usize::from(first) + i, "consecutive");
    }
    let windows: Vec<Vec<u16>> = records
        .chunks(WINDOW)
        .map(|c| c.iter().flat_map(record_words).collect())
        .collect();
    let before = (mb.all, mb.polls, Instant::now());
    for (w, words) in windows.iter().enumerate() {
        let at = usize::from(first) + w * WINDOW;
        mb.command(&format!("window write at {at}"), PWREC, words);
    }
    let write = (
        mb.all.since(&before.0),
        mb.polls - before.1,
        before.2.elapsed(),
    );

    let before = (mb.all, mb.polls, Instant::now());
    for (w, words) in windows.iter().enumerate() {
        let at = u16::try_from(usize::from(first) + w * WINDOW).expect("a position");
        mb.command(&format!("window read at {at}"), PWHEAD, &[at]);
        let back = mb.words(4, PWREC, words.len());
        assert_eq!(
            &back, words,
            "positions {at}.. read back by mbpoll ({name})"
        );
    }
    let read = (
        mb.all.since(&before.0),
        mb.polls - before.1,
        before.2.elapsed(),
    );

    // The controller holds exactly that table: iai reads it back.
    let iai_read = Duration::from_secs_f64(gw.assert_controller_holds(iai, records));

    let s = |d: Duration| d.as_secs_f64();
    println!(
        "mbpoll ({name}), {} calls, {:.1} s in all ({} replies lost and asked again):\n  \
         servo {}on, home, HEND, move, PEND, PNOW {pnow} = the simulator's 212H: \
         {} calls, {:.1} s\n  \
         {} positions written, {} windows: {} calls ({} CMDST polls), {:.1} s \
         ({:.1} s in mbpoll, {:.0} ms a call; the rest waits before a first CMDST read)\n  \
         read back equal: {} calls ({} CMDST polls), {:.1} s ({:.1} s in mbpoll, \
         {:.0} ms a call)\n  \
         iai table read of the {} positions: equal, {:.1} s",
        mb.all.calls,
        s(t0.elapsed()),
        mb.lost,
        if servo_off { "off, " } else { "" },
        motion.calls,
        s(motion_wall),
        records.len(),
        windows.len(),
        write.0.calls,
        write.1,
        s(write.2),
        s(write.0.time),
        s(write.0.time) * 1000.0 / f64::from(write.0.calls),
        read.0.calls,
        read.1,
        s(read.2),
        s(read.0.time),
        s(read.0.time) * 1000.0 / f64::from(read.0.calls),
        records.len(),
        s(iai_read),
    );
    pnow
}
