//! Running the example firmware under QEMU (`qemu-system-arm`).
//!
//! [`build_firmware`] builds a [`Board`]'s binary of `firmware-example`
//! with the `firmware` profile, the one `tools/size-report.sh` builds, so
//! that the test command builds each board once (building inside a test
//! made the first test of a board pay for the whole optimised build: the
//! mps2-an386 pass-through test took about 9 s, nearly all of it cargo).
//! [`QemuSession::start`] boots an ELF with its serial ports wired to Unix
//! sockets: [`QemuSession::upstream`] is the host side of the bridge,
//! [`QemuSession::downstream`] the controller side (which of QEMU's
//! `-serial` ports each is: [`Board::serials`]), and a configuration page (see
//! `firmware_example::config`) loaded into the flash slots at the ELF's
//! `_bridge_config` symbol. The firmware ends the run through semihosting
//! `exit`, which becomes QEMU's exit code (0 on success).
//!
//! The host side listens and QEMU connects as a client, so nothing the
//! firmware sends is lost before the test is ready. The session only ever
//! kills the QEMU process it spawned, through its own [`Child`] handle.
//!
//! Std only; needs `qemu-system-arm` on `PATH` and the board's rustup target.

use std::fmt;
use std::io::{self, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread;
use std::time::{Duration, Instant};

use firmware_example::config::page::{BRIDGE_AT, NET_AT, PAGE_LEN, SPARKPLUG_AT};
use firmware_example::config::store::image;
use firmware_example::config::Config;
use firmware_example::net::config::NetConfig;
use firmware_example::net::sparkplug::config::SparkplugConfig;

/// Name of the firmware package.
pub const FIRMWARE_PACKAGE: &str = "firmware-example";

/// The cargo profile the QEMU tests, the demo and the size report share.
pub const FIRMWARE_PROFILE: &str = "firmware";

/// The QEMU program.
pub const QEMU: &str = "qemu-system-arm";

/// Upstream bytes that make the firmware end the run successfully, when
/// its configuration allows it.
pub use firmware_example::codes::QUIT as QUIT_SEQUENCE;

/// Silence kept on the upstream before [`QUIT_SEQUENCE`]: the firmware's
/// guard plus a margin.
pub const QUIT_GUARD: Duration =
    Duration::from_millis(firmware_example::bridge::QUIT_GUARD_MS as u64 + 30);

/// Text the firmware prints through semihosting once its serial ports are
/// set up. [`QemuSession::start`] waits for it before returning, because
/// bytes sent to a UART before the firmware configures it may be lost.
pub const READY_MARKER: &str = "bridge up";

/// How long to wait for QEMU's output pipes to close after it exited.
const OUTPUT_GRACE: Duration = Duration::from_secs(2);

/// A QEMU machine the firmware supports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Board {
    /// `lm3s6965evb`: Cortex-M3, PL011 UARTs with FIFOs. Fastest serial
    /// throughput; use it for data tests.
    Lm3s6965,
    /// `mps2-an386`: Cortex-M4F, CMSDK UARTs. Use it for instruction counts.
    Mps2An386,
    /// `b-l475e-iot01a` (QEMU 9 and later): the STM32L475, Cortex-M4F, the
    /// USART design of the STM32G0 boards, running their embassy tasks.
    BL475eIot01a,
}

/// What a board's serial port (QEMU's `-serial`, in order) carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Serial {
    /// The host side of the bridge ([`QemuSession::upstream`]).
    Host,
    /// The controller side ([`QemuSession::downstream`]).
    Controller,
    /// The gateway's Modbus RTU port ([`QemuSession::modbus`]).
    Modbus,
    /// Nothing the firmware uses (`-serial null`).
    Unused,
}

impl Board {
    /// Every supported board.
    pub const ALL: [Board; 3] = [Board::Lm3s6965, Board::Mps2An386, Board::BL475eIot01a];

    /// QEMU `-machine` name.
    pub fn machine(self) -> &'static str {
        match self {
            Board::Lm3s6965 => "lm3s6965evb",
            Board::Mps2An386 => "mps2-an386",
            Board::BL475eIot01a => "b-l475e-iot01a",
        }
    }

    /// A slot of the board's configuration page: its flash erase page
    /// (`memory-qemu.x`: 1 KiB, as the LM3S6965's; `memory-stm32l475.x`:
    /// 2 KiB).
    pub fn config_slot_len(self) -> usize {
        match self {
            Board::Lm3s6965 | Board::Mps2An386 => 1024,
            Board::BL475eIot01a => 2048,
        }
    }

    /// Rust target triple the firmware is built for.
    pub fn target(self) -> &'static str {
        match self {
            Board::Lm3s6965 => "thumbv7m-none-eabi",
            Board::Mps2An386 | Board::BL475eIot01a => "thumbv7em-none-eabihf",
        }
    }

    /// The board's binary in `firmware-example`.
    pub fn bin(self) -> &'static str {
        match self {
            Board::Lm3s6965 => "lm3s6965",
            Board::Mps2An386 => "mps2-an386",
            Board::BL475eIot01a => "b-l475e-iot01a",
        }
    }

    /// What each of its serial ports carries, in QEMU's `-serial` order
    /// (the order the machine wires its UARTs: on `b-l475e-iot01a`
    /// USART1, USART2, USART3, UART4).
    pub fn serials(self) -> &'static [Serial] {
        match self {
            Board::Lm3s6965 => &[Serial::Host, Serial::Controller, Serial::Modbus],
            Board::Mps2An386 => &[Serial::Host, Serial::Controller],
            Board::BL475eIot01a => &[
                Serial::Host,
                Serial::Modbus,
                Serial::Unused,
                Serial::Controller,
            ],
        }
    }

    /// Whether the board's firmware has the gateway's Modbus RTU port (a
    /// third UART).
    pub fn has_modbus(self) -> bool {
        self.serials().contains(&Serial::Modbus)
    }

    /// Whether QEMU models the board's watchdog, so that a stalled loop
    /// resets it (QEMU 10 leaves the STM32L475's IWDG unimplemented).
    pub fn watchdog_modelled(self) -> bool {
        self != Board::BL475eIot01a
    }

    /// Cargo feature of `firmware-example` that selects this board.
    pub fn feature(self) -> &'static str {
        match self {
            Board::Lm3s6965 => "board-lm3s6965",
            Board::Mps2An386 => "board-mps2-an386",
            Board::BL475eIot01a => "board-b-l475e-iot01a",
        }
    }

    /// The board named `name` (its binary or its QEMU machine).
    pub fn named(name: &str) -> Option<Board> {
        Board::ALL
            .into_iter()
            .find(|b| b.bin() == name || b.machine() == name)
    }

    /// The boards' names, for a usage text: `lm3s6965, mps2-an386, ...`.
    pub fn names() -> String {
        Board::ALL.map(Board::bin).join(", ")
    }

    /// Cargo arguments that select this board's features.
    pub fn cargo_feature_args(self) -> Vec<String> {
        vec![
            "--no-default-features".to_owned(),
            "--features".to_owned(),
            self.feature().to_owned(),
        ]
    }
}

impl fmt::Display for Board {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.machine())
    }
}

/// The workspace root (the parent of this crate's folder).
pub fn workspace_root() -> PathBuf {
    let manifest_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest_dir.parent().unwrap_or(manifest_dir).to_path_buf()
}

/// The workspace target directory: `$CARGO_TARGET_DIR` if set (relative to
/// the workspace root), else `<root>/target`.
pub fn target_dir() -> PathBuf {
    let root = workspace_root();
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) if !dir.is_empty() => root.join(dir),
        _ => root.join("target"),
    }
}

/// Build the firmware for `board` with [`FIRMWARE_PROFILE`] and return
/// the ELF path (a no-op when `tools/test.sh` built it already).
pub fn build_firmware(board: Board) -> io::Result<PathBuf> {
    build_firmware_with_profile(board, FIRMWARE_PROFILE)
}

/// Build the firmware for `board` with a cargo profile (`release`,
/// `firmware`, `dev`...) and return the ELF path.
pub fn build_firmware_with_profile(board: Board, profile: &str) -> io::Result<PathBuf> {
    build_firmware_with(board, profile, &[], None)
}

/// Build the firmware for `board` with a cargo profile, extra cargo
/// features (e.g. `bench`) and, if given, its own target directory (so
/// that a variant does not overwrite the ELF other tests use); return the
/// ELF path.
pub fn build_firmware_with(
    board: Board,
    profile: &str,
    features: &[&str],
    target_dir_override: Option<&Path>,
) -> io::Result<PathBuf> {
    build_bin(board, board.bin(), profile, features, target_dir_override)
}

/// Builds the `iai` tool in the calling test's cargo profile (a no-op when
/// the test command built it) and returns its path, beside the test
/// executable's `target/<profile>/`.
pub fn iai_binary() -> io::Result<PathBuf> {
    let exe = std::env::current_exe()?;
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .ok_or_else(|| io::Error::other(format!("no target/<profile> above {}", exe.display())))?
        .to_path_buf();
    let profile = match dir.file_name().and_then(|n| n.to_str()) {
        Some("debug") => "dev".to_owned(),
        Some(other) => other.to_owned(),
        None => return Err(io::Error::other(format!("no profile in {}", dir.display()))),
    };
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(workspace_root())
        .args([
            "build",
            "--quiet",
            "-p",
            "iai-cli",
            "--bin",
            "iai",
            "--profile",
        ])
        .arg(&profile)
        .stdin(Stdio::null())
        .output()?;
    if !out.status.success() {
        return Err(io::Error::other(format!(
            "building iai failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        )));
    }
    let iai = dir.join("iai");
    if !iai.is_file() {
        return Err(io::Error::other(format!("{} missing", iai.display())));
    }
    Ok(iai)
}

/// The Ethernet board's binary (protocol B over TCP on `lm3s6965evb`).
pub const ETHERNET_BIN: &str = "lm3s6965-eth";

/// Build the bridge with its host side on Ethernet ([`ETHERNET_BIN`],
/// features `board-lm3s6965` and `ethernet`) with [`FIRMWARE_PROFILE`];
/// the ELF path. It runs on [`Board::Lm3s6965`].
pub fn build_ethernet_firmware() -> io::Result<PathBuf> {
    build_bin(
        Board::Lm3s6965,
        ETHERNET_BIN,
        FIRMWARE_PROFILE,
        &["ethernet"],
        None,
    )
}

/// Build `firmware-example`'s example `name` for `board` with
/// [`FIRMWARE_PROFILE`]; the ELF path.
pub fn build_example(board: Board, name: &str) -> io::Result<PathBuf> {
    build_target(board, ("--example", name), FIRMWARE_PROFILE, &[], None)
}

fn build_bin(
    board: Board,
    bin: &str,
    profile: &str,
    features: &[&str],
    target_dir_override: Option<&Path>,
) -> io::Result<PathBuf> {
    build_target(
        board,
        ("--bin", bin),
        profile,
        features,
        target_dir_override,
    )
}

/// Builds one of `firmware-example`'s programs (`("--bin", name)` or
/// `("--example", name)`) for `board`; the ELF path.
fn build_target(
    board: Board,
    (kind, name): (&str, &str),
    profile: &str,
    features: &[&str],
    target_dir_override: Option<&Path>,
) -> io::Result<PathBuf> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut feature_list = vec![board.feature()];
    feature_list.extend_from_slice(features);
    let mut command = Command::new(&cargo);
    command
        .current_dir(workspace_root())
        .args(["build", "--quiet", "-p", FIRMWARE_PACKAGE, kind, name])
        .args(["--profile", profile])
        .args(["--target", board.target()])
        .args(["--no-default-features", "--features"])
        .arg(feature_list.join(","));
    if let Some(dir) = target_dir_override {
        command.arg("--target-dir").arg(dir);
    }
    let output = command
        .stdin(Stdio::null())
        .output()
        .map_err(|e| io::Error::new(e.kind(), format!("running {cargo:?}: {e}")))?;
    if !output.status.success() {
        return Err(io::Error::other(format!(
            "building {FIRMWARE_PACKAGE} for {board} ({}) failed with {}:\n{}",
            board.target(),
            output.status,
            String::from_utf8_lossy(&output.stderr)
        )));
    }
    let profile_dir = match profile {
        "dev" | "test" => "debug",
        "bench" => "release",
        other => other,
    };
    let dir = target_dir_override
        .map_or_else(target_dir, Path::to_path_buf)
        .join(board.target())
        .join(profile_dir);
    let elf = if kind == "--example" {
        dir.join("examples").join(name)
    } else {
        dir.join(name)
    };
    if elf.is_file() {
        Ok(elf)
    } else {
        Err(io::Error::new(
            io::ErrorKind::NotFound,
            format!("cargo succeeded but {} is missing", elf.display()),
        ))
    }
}

/// How a QEMU run ended.
#[derive(Debug)]
pub struct ExitOutcome {
    /// QEMU's exit status.
    pub status: ExitStatus,
    /// QEMU's exit code (`None` if killed by a signal): the firmware's
    /// semihosting exit status, 0 for success.
    pub code: Option<i32>,
    /// What QEMU wrote on stdout (semihosting output of the firmware).
    pub stdout: String,
    /// What QEMU wrote on stderr.
    pub stderr: String,
}

impl ExitOutcome {
    /// Whether the firmware exited with success.
    pub fn success(&self) -> bool {
        self.code == Some(0)
    }
}

/// A running QEMU with both serial ports connected.
pub struct QemuSession {
    /// First serial port: the host side of the bridge.
    pub upstream: UnixStream,
    /// Second serial port: the controller side of the bridge.
    pub downstream: UnixStream,
    /// The gateway's Modbus RTU port, when asked for
    /// ([`QemuSession::start_tied`]) on a board that has one.
    pub modbus: Option<UnixStream>,
    board: Board,
    child: Child,
    stdout: Capture,
    stderr: Capture,
}

impl fmt::Debug for QemuSession {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("QemuSession")
            .field("board", &self.board)
            .field("pid", &self.child.id())
            .finish_non_exhaustive()
    }
}

/// Output of one QEMU pipe, collected by a background thread.
#[derive(Clone, Default)]
struct Capture(Arc<(Mutex<CaptureState>, Condvar)>);

#[derive(Default)]
struct CaptureState {
    data: Vec<u8>,
    closed: bool,
}

impl Capture {
    /// Start collecting everything `pipe` produces until it closes.
    fn spawn<R: Read + Send + 'static>(mut pipe: R) -> Self {
        let capture = Capture::default();
        let shared = capture.clone();
        thread::spawn(move || {
            let mut buf = [0; 4096];
            loop {
                let n = pipe.read(&mut buf).unwrap_or(0);
                let (state, changed) = &*shared.0;
                let mut state = state.lock().unwrap_or_else(PoisonError::into_inner);
                if n == 0 {
                    state.closed = true;
                } else {
                    state.data.extend_from_slice(&buf[..n]);
                }
                changed.notify_all();
                if n == 0 {
                    break;
                }
            }
        });
        capture
    }

    /// Everything collected so far, as (lossy) UTF-8.
    fn text(&self) -> String {
        let state = self.0 .0.lock().unwrap_or_else(PoisonError::into_inner);
        String::from_utf8_lossy(&state.data).into_owned()
    }

    /// Wait until the output contains `needle` (`true`), or the pipe closes
    /// or `deadline` passes (`false`).
    fn wait_for(&self, needle: &str, deadline: Instant) -> bool {
        let (state, changed) = &*self.0;
        let mut state = state.lock().unwrap_or_else(PoisonError::into_inner);
        loop {
            if contains(&state.data, needle.as_bytes()) {
                return true;
            }
            let now = Instant::now();
            if state.closed || now >= deadline {
                return false;
            }
            state = changed
                .wait_timeout(state, deadline - now)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// Wait (up to `limit`) for the pipe to close, then return the text.
    fn finish(&self, limit: Duration) -> String {
        let deadline = Instant::now() + limit;
        let (state, changed) = &*self.0;
        let mut guard = state.lock().unwrap_or_else(PoisonError::into_inner);
        while !guard.closed {
            let now = Instant::now();
            if now >= deadline {
                break;
            }
            guard = changed
                .wait_timeout(guard, deadline - now)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
        String::from_utf8_lossy(&guard.data).into_owned()
    }
}

fn contains(haystack: &[u8], needle: &[u8]) -> bool {
    needle.is_empty() || haystack.windows(needle.len()).any(|w| w == needle)
}

impl QemuSession {
    /// Boot `elf` on `board`, connect both serial ports and wait until the
    /// firmware prints [`READY_MARKER`].
    ///
    /// `timeout` bounds the start-up and is also set as the read and write
    /// timeout of both sockets (change it with `set_read_timeout` /
    /// `set_write_timeout` on the streams).
    pub fn start(board: Board, elf: &Path, timeout: Duration) -> io::Result<Self> {
        Self::start_with_marker(board, elf, timeout, Some(READY_MARKER))
    }

    /// Like [`QemuSession::start`], waiting for `ready_marker` on QEMU's
    /// stdout instead, or for nothing (`None`: only the connections) for
    /// firmware that prints no marker.
    pub fn start_with_marker(
        board: Board,
        elf: &Path,
        timeout: Duration,
        ready_marker: Option<&str>,
    ) -> io::Result<Self> {
        Self::start_with_args(board, elf, timeout, ready_marker, &[])
    }

    /// Like [`QemuSession::start_with_marker`], with extra QEMU arguments
    /// (e.g. `-icount shift=5,sleep=off`) and [`test_config`].
    pub fn start_with_args(
        board: Board,
        elf: &Path,
        timeout: Duration,
        ready_marker: Option<&str>,
        extra_args: &[&str],
    ) -> io::Result<Self> {
        Self::start_configured(
            board,
            elf,
            timeout,
            ready_marker,
            extra_args,
            Some(&test_config()),
        )
    }

    /// Like [`QemuSession::start_with_args`], with the configuration block
    /// `config` in flash (`None`: flash left blank, the firmware's
    /// defaults).
    pub fn start_configured(
        board: Board,
        elf: &Path,
        timeout: Duration,
        ready_marker: Option<&str>,
        extra_args: &[&str],
        config: Option<&Config>,
    ) -> io::Result<Self> {
        Self::start_inner(
            board,
            elf,
            timeout,
            ready_marker,
            extra_args,
            config,
            false,
            false,
        )
    }

    /// Like [`QemuSession::start_configured`], and QEMU is also killed
    /// when the thread that calls this ends, even if this process is
    /// killed with SIGKILL (Linux `PR_SET_PDEATHSIG`): for a long-running
    /// program whose main thread starts QEMU, such as the gateway. Not for
    /// tests, whose sessions may outlive the thread that started them
    /// (a test that runs the gateway runs it in a thread that lives as long
    /// as the session). With `modbus`, the board's Modbus RTU port is
    /// connected too ([`QemuSession::modbus`]).
    #[allow(clippy::too_many_arguments)]
    pub fn start_tied(
        board: Board,
        elf: &Path,
        timeout: Duration,
        ready_marker: Option<&str>,
        extra_args: &[&str],
        config: Option<&Config>,
        modbus: bool,
    ) -> io::Result<Self> {
        Self::start_inner(
            board,
            elf,
            timeout,
            ready_marker,
            extra_args,
            config,
            true,
            modbus,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn start_inner(
        board: Board,
        elf: &Path,
        timeout: Duration,
        ready_marker: Option<&str>,
        extra_args: &[&str],
        config: Option<&Config>,
        tied: bool,
        modbus: bool,
    ) -> io::Result<Self> {
        let loader = match config {
            Some(cfg) => Some(config_loader_arg(board, elf, cfg)?),
            None => None,
        };
        // Both lines are Unix sockets: their senders can tell how much QEMU
        // has not read yet (see `HostLink` and the simulator's pacing).
        static SOCKETS: AtomicU32 = AtomicU32::new(0);
        let sock_dir = target_dir().join("qemu-sockets");
        std::fs::create_dir_all(&sock_dir)?;
        let n = SOCKETS.fetch_add(1, Ordering::Relaxed);
        let sock = sock_dir.join(format!("up-{}-{n}.sock", std::process::id()));
        let down_sock = sock_dir.join(format!("down-{}-{n}.sock", std::process::id()));
        let _ = std::fs::remove_file(&sock);
        let _ = std::fs::remove_file(&down_sock);
        let upstream_listener = UnixListener::bind(&sock)?;
        let downstream_listener = UnixListener::bind(&down_sock)?;
        let modbus_sock = sock_dir.join(format!("modbus-{}-{n}.sock", std::process::id()));
        let modbus_listener = if modbus {
            let _ = std::fs::remove_file(&modbus_sock);
            Some(UnixListener::bind(&modbus_sock)?)
        } else {
            None
        };

        let mut command = Command::new(QEMU);
        command
            .args(["-machine", board.machine()])
            .args(["-nographic", "-monitor", "none"])
            .args(["-semihosting-config", "enable=on,target=native"]);
        for serial in board.serials() {
            let (id, path) = match serial {
                Serial::Host => ("u0", &sock),
                Serial::Controller => ("u1", &down_sock),
                Serial::Modbus if modbus => ("u2", &modbus_sock),
                Serial::Modbus | Serial::Unused => {
                    command.args(["-serial", "null"]);
                    continue;
                }
            };
            command
                .arg("-chardev")
                .arg(format!("socket,id={id},path={}", path.display()))
                .args(["-serial", &format!("chardev:{id}")]);
        }
        command.args(extra_args);
        if let Some(loader) = &loader {
            command.arg("-device").arg(loader);
        }
        command
            .arg("-kernel")
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        if tied {
            use std::os::unix::process::CommandExt;
            let die_with_parent = || {
                // SAFETY: PR_SET_PDEATHSIG takes one int argument; prctl is
                // async-signal-safe and touches no memory.
                if unsafe { prctl(PR_SET_PDEATHSIG, SIGKILL) } != 0 {
                    return Err(io::Error::last_os_error());
                }
                Ok(())
            };
            // SAFETY: between fork and exec the closure only calls prctl.
            unsafe {
                command.pre_exec(die_with_parent);
            }
        }
        let mut child = command.spawn().map_err(|e| {
            io::Error::new(
                e.kind(),
                format!("starting {QEMU} (is it installed? apt-get install qemu-system-arm): {e}"),
            )
        })?;
        let stdout = child.stdout.take().map(Capture::spawn).unwrap_or_default();
        let stderr = child.stderr.take().map(Capture::spawn).unwrap_or_default();

        let deadline = Instant::now() + timeout;
        let accepted = accept_unix_until(&upstream_listener, &mut child, deadline)
            .and_then(|up| {
                let down = accept_unix_until(&downstream_listener, &mut child, deadline)?;
                let third = match &modbus_listener {
                    Some(l) => Some(accept_unix_until(l, &mut child, deadline)?),
                    None => None,
                };
                Ok((up, down, third))
            })
            .and_then(|streams| match ready_marker {
                Some(marker) if !stdout.wait_for(marker, deadline) => Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!("the firmware did not print {marker:?}"),
                )),
                _ => Ok(streams),
            });
        let _ = std::fs::remove_file(&sock);
        let _ = std::fs::remove_file(&down_sock);
        if modbus {
            let _ = std::fs::remove_file(&modbus_sock);
        }
        let (upstream, downstream, modbus) = match accepted {
            Ok(streams) => streams,
            Err(e) => {
                if let Ok(None) = child.try_wait() {
                    let _ = child.kill();
                }
                let _ = child.wait();
                return Err(io::Error::new(
                    e.kind(),
                    format!(
                        "{QEMU} -machine {} did not start: {e}\nstdout:\n{}\nstderr:\n{}",
                        board.machine(),
                        stdout.finish(OUTPUT_GRACE),
                        stderr.finish(OUTPUT_GRACE)
                    ),
                ));
            }
        };
        // From here on, dropping `session` on an error kills QEMU.
        let session = Self {
            upstream,
            downstream,
            modbus,
            board,
            child,
            stdout,
            stderr,
        };
        session.upstream.set_nonblocking(false)?;
        session.upstream.set_read_timeout(Some(timeout))?;
        session.upstream.set_write_timeout(Some(timeout))?;
        let down = &session.downstream;
        down.set_nonblocking(false)?;
        down.set_read_timeout(Some(timeout))?;
        down.set_write_timeout(Some(timeout))?;
        if let Some(m) = &session.modbus {
            m.set_nonblocking(false)?;
            m.set_read_timeout(Some(timeout))?;
            m.set_write_timeout(Some(timeout))?;
        }
        Ok(session)
    }

    /// The board this session runs.
    pub fn board(&self) -> Board {
        self.board
    }

    /// QEMU's stdout so far (the firmware's semihosting output).
    pub fn stdout_so_far(&self) -> String {
        self.stdout.text()
    }

    /// Waits until QEMU's stdout holds `needle` (true) or `deadline`
    /// passes (false).
    pub fn wait_for_stdout(&self, needle: &str, deadline: Instant) -> bool {
        self.stdout.wait_for(needle, deadline)
    }

    /// QEMU's stderr so far.
    pub fn stderr_so_far(&self) -> String {
        self.stderr.text()
    }

    /// Process id of the QEMU this session spawned.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// QEMU's exit status once it has exited (and is reaped), `None`
    /// while it runs.
    pub fn try_wait(&mut self) -> io::Result<Option<ExitStatus>> {
        self.child.try_wait()
    }

    /// Ask the firmware to end the run: keep the upstream silent for
    /// [`QUIT_GUARD`], then send [`QUIT_SEQUENCE`].
    pub fn quit(&mut self) -> io::Result<()> {
        thread::sleep(QUIT_GUARD);
        self.upstream.write_all(&QUIT_SEQUENCE)?;
        self.upstream.flush()
    }

    /// Wait up to `timeout` for QEMU to exit and return its exit code and
    /// output. On timeout QEMU is killed and a `TimedOut` error carrying
    /// the output so far is returned.
    pub fn wait(mut self, timeout: Duration) -> io::Result<ExitOutcome> {
        let deadline = Instant::now() + timeout;
        let status = loop {
            if let Some(status) = self.child.try_wait()? {
                break Some(status);
            }
            if Instant::now() >= deadline {
                break None;
            }
            thread::sleep(Duration::from_millis(10));
        };
        let status = match status {
            Some(status) => status,
            None => {
                self.kill_child();
                let stdout = self.stdout.finish(OUTPUT_GRACE);
                let stderr = self.stderr.finish(OUTPUT_GRACE);
                return Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!(
                        "{QEMU} -machine {} still running after {timeout:?}; killed it\nstdout:\n{stdout}\nstderr:\n{stderr}",
                        self.board.machine()
                    ),
                ));
            }
        };
        Ok(ExitOutcome {
            status,
            code: status.code(),
            stdout: self.stdout.finish(OUTPUT_GRACE),
            stderr: self.stderr.finish(OUTPUT_GRACE),
        })
    }

    /// Kill our QEMU (by its own handle) if it is still running, and reap it.
    fn kill_child(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

impl Drop for QemuSession {
    fn drop(&mut self) {
        // `try_wait` reports a child already reaped by `wait` without
        // touching its (possibly reused) PID, so this never hits another
        // process.
        self.kill_child();
    }
}

/// `prctl` option: the signal the process gets when its parent thread ends.
const PR_SET_PDEATHSIG: i32 = 1;
/// Signal number of SIGKILL.
const SIGKILL: i32 = 9;

extern "C" {
    fn prctl(option: i32, ...) -> i32;
}

/// Boot `elf` on `board` with no serial port connected (all to `null`) and
/// extra QEMU arguments, and wait up to `timeout` for it to exit (killing
/// our QEMU, and only it, on timeout). For firmware that only talks through
/// semihosting, such as the `bench` build.
pub fn run_to_exit(
    board: Board,
    elf: &Path,
    extra_args: &[&str],
    timeout: Duration,
) -> io::Result<ExitOutcome> {
    let mut child = Command::new(QEMU)
        .args(["-machine", board.machine()])
        .args(["-nographic", "-monitor", "none", "-serial", "null"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(extra_args)
        .arg("-kernel")
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| io::Error::new(e.kind(), format!("starting {QEMU}: {e}")))?;
    let stdout = child.stdout.take().map(Capture::spawn).unwrap_or_default();
    let stderr = child.stderr.take().map(Capture::spawn).unwrap_or_default();
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(ExitOutcome {
                status,
                code: status.code(),
                stdout: stdout.finish(OUTPUT_GRACE),
                stderr: stderr.finish(OUTPUT_GRACE),
            });
        }
        if Instant::now() >= deadline {
            let _ = child.kill();
            let _ = child.wait();
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                format!(
                    "{QEMU} -machine {} still running after {timeout:?}; killed it\nstdout:\n{}",
                    board.machine(),
                    stdout.finish(OUTPUT_GRACE)
                ),
            ));
        }
        thread::sleep(Duration::from_millis(10));
    }
}

/// The configuration the QEMU tests run with: the defaults (XON/XOFF,
/// forward all, controller station 99, bridge station BB) plus the quit
/// sequence.
pub fn test_config() -> Config {
    Config {
        quit_sequence: true,
        ..Config::DEFAULT
    }
}

/// Address of `symbol` in `elf` (read with `arm-none-eabi-nm`).
pub fn symbol_address(elf: &Path, symbol: &str) -> io::Result<u64> {
    let out = Command::new("arm-none-eabi-nm")
        .arg(elf)
        .output()
        .map_err(|e| io::Error::new(e.kind(), format!("running arm-none-eabi-nm: {e}")))?;
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| {
            let mut f = l.split_whitespace();
            let addr = f.next()?;
            let _kind = f.next()?;
            (f.next()? == symbol).then(|| u64::from_str_radix(addr, 16).ok())?
        })
        .ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::NotFound,
                format!("{symbol} not in {}", elf.display()),
            )
        })
}

/// The configuration page holding `cfg`'s block and, if given, the
/// network block `net` and the Sparkplug block `sparkplug`, as a
/// programmer writes it to a board's two slots of `slot_len` bytes
/// (`firmware_example::config::store::image`; [`Board::config_slot_len`]):
/// the page in slot A as sequence 1, slot B erased.
pub fn page_image(
    slot_len: usize,
    cfg: &Config,
    net: Option<&NetConfig>,
    sparkplug: Option<&SparkplugConfig>,
) -> Vec<u8> {
    let mut page = [0xFFu8; PAGE_LEN];
    page[BRIDGE_AT..BRIDGE_AT + firmware_example::config::BLOCK_LEN]
        .copy_from_slice(&cfg.to_block());
    if let Some(net) = net {
        page[NET_AT..NET_AT + firmware_example::net::config::BLOCK_LEN]
            .copy_from_slice(&net.to_block());
    }
    if let Some(sp) = sparkplug {
        page[SPARKPLUG_AT..SPARKPLUG_AT + firmware_example::net::sparkplug::config::BLOCK_LEN]
            .copy_from_slice(&sp.to_block());
    }
    let mut out = vec![0u8; 2 * slot_len];
    image(&page, slot_len, &mut out);
    out
}

/// The `-device loader,...` argument that puts `cfg`'s configuration page
/// ([`page_image`]) at the ELF's `_bridge_config` on `board`.
pub fn config_loader_arg(board: Board, elf: &Path, cfg: &Config) -> io::Result<String> {
    image_loader_arg(elf, &page_image(board.config_slot_len(), cfg, None, None))
}

/// The `-device loader,...` argument that puts `image` (both slots of the
/// configuration page) at the ELF's `_bridge_config`.
pub fn image_loader_arg(elf: &Path, image: &[u8]) -> io::Result<String> {
    let addr = symbol_address(elf, "_bridge_config")?;
    loader_arg("config", addr, image)
}

/// The `-device loader,...` argument that puts `bytes` at `addr`: written
/// to an Intel HEX file in the target directory (`name-<pid>-<n>.hex`),
/// which QEMU's loader places by the addresses it holds. (A raw file is
/// loaded with the machine's RAM size as its limit, and the
/// `b-l475e-iot01a` machine has none set, so QEMU refuses it there.)
pub fn loader_arg(name: &str, addr: u64, bytes: &[u8]) -> io::Result<String> {
    static SERIAL: AtomicU32 = AtomicU32::new(0);
    let dir = target_dir().join("qemu-config");
    std::fs::create_dir_all(&dir)?;
    let file = dir.join(format!(
        "{name}-{}-{}.hex",
        std::process::id(),
        SERIAL.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::write(&file, intel_hex(addr, bytes)?)?;
    Ok(format!("loader,file={}", file.display()))
}

/// `bytes` at `addr` as Intel HEX: an extended linear address record for
/// each 64 KiB, data records of up to 16 bytes, the end-of-file record.
fn intel_hex(addr: u64, bytes: &[u8]) -> io::Result<String> {
    fn record(out: &mut String, kind: u8, offset: u16, data: &[u8]) {
        let mut sum = data.len() as u8;
        sum = sum
            .wrapping_add((offset >> 8) as u8)
            .wrapping_add(offset as u8);
        sum = sum.wrapping_add(kind);
        out.push_str(&format!(":{:02X}{offset:04X}{kind:02X}", data.len()));
        for b in data {
            sum = sum.wrapping_add(*b);
            out.push_str(&format!("{b:02X}"));
        }
        out.push_str(&format!("{:02X}\n", sum.wrapping_neg()));
    }
    let end = addr + bytes.len() as u64;
    if end > 1 << 32 {
        return Err(io::Error::other(format!("{addr:#x}: past 4 GiB")));
    }
    let mut out = String::new();
    let mut high = None;
    let mut at = addr;
    for chunk in bytes.chunks(16) {
        // A chunk never crosses a 64 KiB boundary unless `addr` is odd.
        let mut rest = chunk;
        while !rest.is_empty() {
            if high != Some(at >> 16) {
                high = Some(at >> 16);
                record(&mut out, 4, 0, &((at >> 16) as u16).to_be_bytes());
            }
            let room = (0x1_0000 - (at & 0xFFFF)) as usize;
            let (now, later) = rest.split_at(rest.len().min(room));
            record(&mut out, 0, at as u16, now);
            at += now.len() as u64;
            rest = later;
        }
    }
    record(&mut out, 1, 0, &[]);
    Ok(out)
}

/// Accept one connection on `listener` before `deadline`, giving up early
/// if `child` exits.
fn accept_unix_until(
    listener: &UnixListener,
    child: &mut Child,
    deadline: Instant,
) -> io::Result<UnixStream> {
    listener.set_nonblocking(true)?;
    accept_with(|| listener.accept().map(|(s, _)| s), child, deadline)
}

/// Polls the non-blocking `accept` until it gives a connection, `child`
/// exits or `deadline` passes.
fn accept_with<S>(
    mut accept: impl FnMut() -> io::Result<S>,
    child: &mut Child,
    deadline: Instant,
) -> io::Result<S> {
    loop {
        match accept() {
            Ok(stream) => return Ok(stream),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
            Err(e) => return Err(e),
        }
        if let Some(status) = child.try_wait()? {
            return Err(io::Error::other(format!("QEMU exited early with {status}")));
        }
        if Instant::now() >= deadline {
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "timed out waiting for QEMU to connect",
            ));
        }
        thread::sleep(Duration::from_millis(5));
    }
}
