//! The bridge firmware under QEMU with the controller simulator behind it
//! and its host side on a TCP port of 127.0.0.1, relayed like a serial
//! cable at the line rate with XON/XOFF (see [`host_tests::gateway`]).
//!
//! Prints `protocol-b 127.0.0.1:PORT` on stdout once the bridge answers
//! through the relay and, on a board with the gateway's Modbus RTU port
//! (`lm3s6965`), `modbus-rtu 127.0.0.1:PORT` after it (with `--ethernet`:
//! `protocol-b-tcp 127.0.0.1:PORT` once the Ethernet build answers over
//! TCP, QEMU's user network forwarding that port to the firmware's, then
//! `modbus-tcp 127.0.0.1:PORT`, forwarded to the firmware's Modbus TCP
//! port 502, then `http 127.0.0.1:PORT`, forwarded to its web page on port
//! 80);
//! nothing else goes to stdout.
//! Runs until SIGINT, SIGTERM or SIGHUP (Ctrl-C), then stops QEMU and the
//! simulator. Exit code 0 after such a stop, 1 if anything failed (QEMU
//! exiting on its own included), 2 for bad arguments.
//!
//! Run through `./tools/gateway.sh`. Options: `--port P` (default: a free
//! port), `--baud B` (9600, 19200, 38400, 57600 or 115200, default
//! 115200), `--modbus-port P`, `--modbus-baud B` (the Modbus RTU port,
//! default 115200, even parity, unit 1; with `--ethernet`, `--modbus-port`
//! is the host port forwarded to Modbus TCP), `--board lm3s6965|mps2-an386|b-l475e-iot01a`, `--reply-delay-ms MS` (the
//! simulated controller's time per command, default 2), `--faults SPEC`
//! (as `iai simulate --faults`), `--seed S`, `--elf PATH`,
//! `--stack-report` (at the stop, end the firmware with the quit sequence
//! and log its stack peak: for the size report; a client's bytes could
//! end the firmware too; with `--ethernet` the sequence goes over the
//! protocol-B port), `--ethernet` (protocol B over TCP: the
//! `lm3s6965-eth` build, lm3s6965 only), `--broker 127.0.0.1:PORT` (with
//! `--ethernet`: the firmware's Sparkplug B edge node on the MQTT broker
//! at that port of this machine, group `IAI`, the node ID made from the
//! MAC address, DCMD commands off; prints `sparkplug
//! spBv1.0/IAI/NBIRTH/NODE` once NBIRTH is out), `--http-port P` (with
//! `--ethernet`: the host port of the web page), `--config-image FILE`
//! (boot with this image of the configuration page's slots, as `iai bridge
//! config block` or `iai bridge config get --image` writes it),
//! `--blank-config` (boot with no page loaded: every default).

use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use firmware_example::net::sparkplug::config::SparkplugConfig;
use host_tests::gateway::{self, Options, PageSource, Ready};
use host_tests::qemu::Board;

const USAGE: &str = "usage: gateway [--port P] [--baud B] [--modbus-port P] [--modbus-baud B] \
                     [--board lm3s6965|mps2-an386|b-l475e-iot01a] \
                     [--reply-delay-ms MS] [--faults SPEC] [--seed S] [--elf PATH] \
                     [--stack-report] [--ethernet] [--broker 127.0.0.1:PORT] [--http-port P] \
                     [--config-image FILE | --blank-config]";

fn parse_args() -> Result<Options, String> {
    let mut o = Options::default();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--port" => {
                o.port = value()?
                    .parse()
                    .map_err(|_| "--port takes 0..=65535 (0: a free port)".to_owned())?;
            }
            "--stack-report" => o.stack_report = true,
            "--modbus-port" => {
                o.modbus_port = value()?
                    .parse()
                    .map_err(|_| "--modbus-port takes 0..=65535 (0: a free port)".to_owned())?;
            }
            "--modbus-baud" => {
                o.modbus_baud = value()?
                    .parse()
                    .ok()
                    .filter(|b| firmware_example::config::BAUD_RATES.contains(b))
                    .ok_or("--modbus-baud takes 9600, 19200, 38400, 57600 or 115200")?;
            }
            "--baud" => {
                o.baud = value()?
                    .parse()
                    .ok()
                    .filter(|b| firmware_example::config::BAUD_RATES.contains(b))
                    .ok_or("--baud takes 9600, 19200, 38400, 57600 or 115200")?;
            }
            "--board" => {
                let v = value()?;
                o.board = Board::named(&v)
                    .ok_or(format!("--board takes {}, not {v:?}", Board::names()))?;
            }
            "--reply-delay-ms" => {
                o.reply_delay_ms = value()?
                    .parse()
                    .map_err(|_| "--reply-delay-ms takes milliseconds".to_owned())?;
            }
            "--faults" => o.faults = iai_simulator::server::parse_faults(&value()?)?,
            "--seed" => {
                o.seed = value()?
                    .parse()
                    .map_err(|_| "--seed takes a number".to_owned())?;
            }
            "--elf" => o.elf = Some(PathBuf::from(value()?)),
            "--ethernet" => o.ethernet = true,
            "--broker" => {
                let v = value()?;
                let port = v
                    .strip_prefix("127.0.0.1:")
                    .or_else(|| v.strip_prefix("localhost:"))
                    .and_then(|p| p.parse::<u16>().ok())
                    .filter(|p| *p != 0)
                    .ok_or(format!(
                        "--broker takes 127.0.0.1:PORT (a broker on this machine, which the \
                         guest reaches as 10.0.2.2), not {v:?}"
                    ))?;
                o.sparkplug = Some(SparkplugConfig {
                    enabled: true,
                    broker: gateway::QEMU_HOST,
                    port,
                    ..SparkplugConfig::default()
                });
            }
            "--http-port" => {
                o.http_port = value()?
                    .parse()
                    .map_err(|_| "--http-port takes 0..=65535 (0: a free port)".to_owned())?;
            }
            "--config-image" => o.page = PageSource::Image(PathBuf::from(value()?)),
            "--blank-config" => o.page = PageSource::Blank,
            "-h" | "--help" => return Err(USAGE.to_owned()),
            other => return Err(format!("unknown argument {other:?}\n{USAGE}")),
        }
    }
    Ok(o)
}

fn main() -> ExitCode {
    let opts = match parse_args() {
        Ok(o) if o.sparkplug.is_some() && !o.ethernet => {
            eprintln!(
                "gateway: --broker needs --ethernet (the edge node is in the Ethernet build)"
            );
            return ExitCode::from(2);
        }
        Ok(o) => o,
        Err(e) => {
            eprintln!("gateway: {e}");
            return ExitCode::from(2);
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    if let Err(e) = ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed)) {
        eprintln!("gateway: cannot handle signals: {e}");
        return ExitCode::FAILURE;
    }
    let ready = |at: Ready| {
        let mut out = io::stdout().lock();
        let prefix = if at.over_ethernet {
            "protocol-b-tcp"
        } else {
            "protocol-b"
        };
        let _ = writeln!(out, "{prefix} {}", at.protocol_b);
        if let Some(m) = at.modbus_rtu {
            let _ = writeln!(out, "modbus-rtu {m}");
        }
        if let Some(m) = at.modbus_tcp {
            let _ = writeln!(out, "modbus-tcp {m}");
        }
        if let Some(h) = at.http {
            let _ = writeln!(out, "http {h}");
        }
        if let Some(topic) = &at.sparkplug {
            let _ = writeln!(out, "sparkplug {topic}");
        }
        let _ = out.flush();
    };
    match gateway::run(&opts, &stop, ready) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("gateway: FAILED: {e}");
            ExitCode::FAILURE
        }
    }
}
