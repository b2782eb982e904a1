//! The gateway (`tools/gateway.sh`'s binary) as a process and the real
//! `iai` tool run against it, for the end-to-end tests that use both
//! (`iai_bridge.rs`, `readme_try_it.rs`).

pub use host_tests::qemu::iai_binary;

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::Duration;

/// The gateway; SIGTERM (then SIGKILL) when dropped.
pub struct Gateway {
    child: Child,
    /// Where its host side listens, `127.0.0.1:PORT`.
    pub addr: String,
    log: Receiver<String>,
}

impl Gateway {
    /// Starts the gateway on the bridge firmware `elf`, with `args` after
    /// `--elf`; returns once it printed its ready line.
    pub fn start(elf: &Path, args: &[String]) -> Gateway {
        let mut child = Command::new(env!("CARGO_BIN_EXE_gateway"))
            .arg("--elf")
            .arg(elf)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start the gateway");
        let lines = |pipe: Box<dyn Read + Send>| {
            let (tx, rx) = channel();
            std::thread::spawn(move || {
                for l in BufReader::new(pipe).lines() {
                    let Ok(l) = l else { break };
                    if tx.send(l).is_err() {
                        break;
                    }
                }
            });
            rx
        };
        let stdout = lines(Box::new(child.stdout.take().expect("stdout")));
        let log = lines(Box::new(child.stderr.take().expect("stderr")));
        let first = stdout
            .recv_timeout(Duration::from_secs(60))
            .unwrap_or_else(|_| {
                panic!(
                    "no ready line: {}",
                    log.try_iter().collect::<Vec<_>>().join("\n")
                )
            });
        let addr = first
            .strip_prefix("protocol-b ")
            .unwrap_or_else(|| panic!("first line {first:?}"))
            .to_owned();
        Gateway { child, addr, log }
    }

    /// `iai ARGS` in the directory `dir`, which must succeed.
    pub fn run<S: AsRef<std::ffi::OsStr> + std::fmt::Debug>(
        &self,
        iai: &Path,
        args: &[S],
        dir: &Path,
    ) -> Output {
        let out = Command::new(iai)
            .args(args)
            .current_dir(dir)
            .stdin(Stdio::null())
            .output()
            .expect("run iai");
        assert!(
            out.status.success(),
            "iai {args:?}: {}\n{}\n{}\ngateway:\n{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
            self.log.try_iter().collect::<Vec<_>>().join("\n")
        );
        out
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .arg("-TERM")
            .arg(self.child.id().to_string())
            .status();
        for _ in 0..100 {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// What `o` printed on stdout.
pub fn text(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// What `o` printed on stderr.
pub fn err(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
