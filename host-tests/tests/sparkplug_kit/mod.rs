//! What the Sparkplug end-to-end tests share (`qemu_sparkplug.rs`,
//! `qemu_sparkplug_fleet.rs`): Mosquitto on a free port with a password
//! file, and the Python Sparkplug host
//! (`host-tests/sparkplug/sparkplug_host.py`) as a process whose JSON
//! lines are read here.
#![allow(dead_code)]

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

pub const GROUP: &str = "Plant";
pub const HOST_ID: &str = "scada";

pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Mosquitto on a free port of 127.0.0.1 with a password file; killed
/// when dropped.
pub struct Broker {
    child: Child,
    conf: PathBuf,
    /// Its port on 127.0.0.1.
    pub port: u16,
    _dir: PathBuf,
}

impl Broker {
    pub fn start() -> Broker {
        let port = free_port();
        let dir = host_tests::qemu::target_dir().join(format!("mosquitto-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let passwd = dir.join("passwd");
        for (i, (user, pass)) in [("gw", "gw-secret"), ("host", "host-secret")]
            .iter()
            .enumerate()
        {
            let mut cmd = Command::new("mosquitto_passwd");
            cmd.arg("-b");
            if i == 0 {
                cmd.arg("-c");
            }
            let st = cmd.arg(&passwd).args([user, pass]).status();
            assert!(
                st.is_ok_and(|s| s.success()),
                "mosquitto_passwd (tools/setup.sh)"
            );
        }
        let conf = dir.join("mosquitto.conf");
        std::fs::write(
            &conf,
            format!(
                "listener {port} 127.0.0.1\nallow_anonymous false\npassword_file {}\n",
                passwd.display()
            ),
        )
        .unwrap();
        let child = spawn(&conf, port);
        Broker {
            child,
            conf,
            port,
            _dir: dir,
        }
    }

    /// Stops the broker (as a crash does: no Will is sent for anyone)
    /// and starts it again on the same port.
    pub fn restart(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        self.child = spawn(&self.conf, self.port);
    }
}

/// Mosquitto on `conf`, once it listens on `port`.
fn spawn(conf: &std::path::Path, port: u16) -> Child {
    let child = Command::new("mosquitto")
        .arg("-c")
        .arg(conf)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("mosquitto (tools/setup.sh installs it)");
    let end = Instant::now() + Duration::from_secs(10);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < end, "mosquitto did not listen on {port}");
        std::thread::sleep(Duration::from_millis(50));
    }
    child
}

impl Drop for Broker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The Python host: its messages, and the values of the controller's
/// metrics as its BIRTH and DATA left them.
pub struct Host {
    child: Child,
    stdin: ChildStdin,
    /// Its messages not taken yet.
    pub lines: Receiver<Value>,
    /// Its messages taken so far.
    pub log: Vec<Value>,
    /// The controller's metrics as the last BIRTH and DATA left them.
    pub device: HashMap<String, Value>,
}

impl Host {
    pub fn start(port: u16) -> Host {
        let py = host_tests::qemu::workspace_root().join(".venv/bin/python");
        let script =
            host_tests::qemu::workspace_root().join("host-tests/sparkplug/sparkplug_host.py");
        let mut child = Command::new(py)
            .arg(script)
            .args([
                "--port",
                &port.to_string(),
                "--group",
                GROUP,
                "--host-id",
                HOST_ID,
            ])
            .args(["--username", "host", "--password", "host-secret"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("the venv's python (tools/setup.sh)");
        let stdin = child.stdin.take().unwrap();
        let stdout = child.stdout.take().unwrap();
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for l in BufReader::new(stdout).lines() {
                let Ok(l) = l else { break };
                if let Ok(v) = serde_json::from_str::<Value>(&l) {
                    if tx.send(v).is_err() {
                        break;
                    }
                }
            }
        });
        let mut h = Host {
            child,
            stdin,
            lines,
            log: Vec::new(),
            device: HashMap::new(),
        };
        h.wait_for("the host ready", 20, |m| m["ready"] == true);
        h
    }

    pub fn send(&mut self, cmd: Value) {
        writeln!(self.stdin, "{cmd}").unwrap();
        self.stdin.flush().unwrap();
        self.wait_for("the host's command done", 10, |m| m.get("done").is_some());
    }

    /// Takes the host's lines until `pred` holds for one (the first
    /// such), at most `secs`; every message's own checks must pass.
    pub fn wait_for(&mut self, what: &str, secs: u64, pred: impl Fn(&Value) -> bool) -> Value {
        let end = Instant::now() + Duration::from_secs(secs);
        loop {
            let left = end.saturating_duration_since(Instant::now());
            let m = self.lines.recv_timeout(left).unwrap_or_else(|_| {
                panic!(
                    "no {what} within {secs} s; the host saw:\n{}\nthe controller's metrics: {:?}",
                    self.tail(),
                    self.device
                )
            });
            let errors = m["errors"].as_array().cloned().unwrap_or_default();
            assert!(errors.is_empty(), "the host found {errors:?} in {m}");
            if m["device"] == "controller" {
                if m["kind"] == "DBIRTH" {
                    self.device.clear();
                }
                for metric in m["metrics"].as_array().into_iter().flatten() {
                    let name = metric["name"].as_str().unwrap_or_default().to_owned();
                    self.device.insert(name, metric["value"].clone());
                }
            }
            self.log.push(m.clone());
            if pred(&m) {
                return m;
            }
        }
    }

    /// Waits until the controller's metrics satisfy `pred`.
    pub fn wait_device(
        &mut self,
        what: &str,
        secs: u64,
        pred: impl Fn(&HashMap<String, Value>) -> bool,
    ) {
        if pred(&self.device) {
            return;
        }
        let end = Instant::now() + Duration::from_secs(secs);
        while !pred(&self.device) {
            let left = end
                .saturating_duration_since(Instant::now())
                .as_secs()
                .max(1);
            assert!(Instant::now() < end, "{what}: {:?}", self.device);
            self.wait_for(what, left, |m| {
                m["kind"] == "DDATA" || m["kind"] == "DBIRTH"
            });
        }
    }

    /// Takes the host's lines for `d` (each one's checks must pass).
    pub fn collect(&mut self, d: Duration) {
        let end = Instant::now() + d;
        while let Ok(m) = self
            .lines
            .recv_timeout(end.saturating_duration_since(Instant::now()))
        {
            let errors = m["errors"].as_array().cloned().unwrap_or_default();
            assert!(errors.is_empty(), "the host found {errors:?} in {m}");
            self.log.push(m);
        }
    }

    pub fn tail(&self) -> String {
        let n = self.log.len().saturating_sub(8);
        self.log[n..]
            .iter()
            .map(|m| {
                format!("{} {}", m["topic"], m["metrics"])
                    .chars()
                    .take(300)
                    .collect::<String>()
            })
            .collect::<Vec<_>>()
            .join("\n")
    }

    pub fn seen(&self, kind: &str) -> usize {
        self.log.iter().filter(|m| m["kind"] == kind).count()
    }

    /// A DCMD to the controller with one metric; waits until its command
    /// is done (or `expect` other than done).
    pub fn dcmd(&mut self, node: &str, name: &str, ty: &str, value: Value) {
        let metrics = json!([{ "name": name, "type": ty, "value": value }]);
        self.send(json!({ "dcmd": node, "metrics": metrics }));
    }
}

impl Drop for Host {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
