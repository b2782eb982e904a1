//! `iai simulate`: the controller simulator on TCP, a pty or a dialled port.

use std::io::{self, Write};
use std::process::ExitCode;

use iai_cli::csvtable;
use iai_cli::simulate;
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_simulator::server::{self, ServeOptions, Shared};
use iai_simulator::Controller;

use super::{Failure, Run};
use crate::{ProfileArg, SimArgs};

pub(crate) fn simulate_cmd(args: &SimArgs) -> Run {
    let station = Station(args.station);
    let mut ctl = match args.profile {
        ProfileArg::Tta => Controller::tta(station),
        ProfileArg::Xsel2003 => Controller::xsel_2003(station),
    };
    ctl.response_delay_ms = args.reply_delay_ms;
    ctl.refuse = !args.accept_all;
    let shared = Shared::new(ctl).with_frame_log(simulate::inspector_log());
    let opts = ServeOptions {
        faults: args.faults.clone().unwrap_or_default(),
        seed: args.seed,
        log_frames: !args.quiet,
    };
    // Signals: write the table if asked, then exit.
    let (tx, rx) = std::sync::mpsc::channel::<()>();
    let done = tx.clone();
    ctrlc::set_handler(move || {
        let _ = tx.send(());
    })
    .map_err(|e| format!("cannot handle signals: {e}"))?;
    let mut connected = None;
    let listening = if args.pty {
        start_pty(&shared, &opts)?
    } else if let Some(addr) = &args.connect {
        let wait = args.connect_wait_ms.map_or(server::CONNECT_PATIENCE, |ms| {
            std::time::Duration::from_millis(ms)
        });
        let conn = server::connect(addr, wait)?;
        let peer = conn
            .peer_addr()
            .map_or_else(|_| addr.clone(), |a| a.to_string());
        connected = Some(conn);
        format!("connected tcp {peer}")
    } else {
        let addr = args.tcp.clone().unwrap_or_default();
        let listener = std::net::TcpListener::bind(addr.as_str()).map_err(|e| {
            format!("--tcp {addr:?}: cannot listen there ({e}); give 127.0.0.1:PORT")
        })?;
        let local = listener
            .local_addr()
            .map_err(|e| format!("--tcp {addr:?}: {e}"))?;
        let (s, o) = (shared.clone(), opts.clone());
        std::thread::spawn(move || server::serve_tcp(listener, s, o));
        format!("listening tcp {local}")
    };
    {
        let mut out = io::stdout().lock();
        let ctl = shared.ctl.lock().unwrap_or_else(|p| p.into_inner());
        let _ = writeln!(out, "{listening}");
        let _ = writeln!(
            out,
            "simulating a {} controller, station {:02X} (receive buffer {} bytes, transmit {} bytes); Ctrl-C stops",
            args.profile.profile().name(),
            args.station,
            ctl.max_receive,
            ctl.max_transmit
        );
        let _ = out.flush();
    }
    // The one connection of --connect: its end ends the run, as a signal does.
    if let Some(conn) = connected {
        let (s, o) = (shared.clone(), opts.clone());
        std::thread::spawn(move || {
            server::serve_connected(conn, &s, &o);
            let _ = done.send(());
        });
    }
    let _ = rx.recv();
    if let Some(path) = &args.dump {
        let ctl = shared.ctl.lock().unwrap_or_else(|p| p.into_inner());
        let recs: Vec<&PositionRecord> = ctl.table.values().collect();
        let axes = csvtable::axes_used(recs.iter().copied());
        let written = std::fs::File::create(path).and_then(|f| {
            let mut w = io::BufWriter::new(f);
            csvtable::write_header(&mut w, axes)?;
            for r in &recs {
                csvtable::write_row(&mut w, r, axes)?;
            }
            w.flush()
        });
        written.map_err(|e| format!("--dump {}: {e}", path.display()))?;
        let mut out = io::stdout().lock();
        let _ = writeln!(
            out,
            "dumped {} position(s) to {}",
            recs.len(),
            path.display()
        );
        let _ = out.flush();
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(unix)]
fn start_pty(shared: &Shared, opts: &ServeOptions) -> Result<String, Failure> {
    let pty = server::pty::Pty::open().map_err(|e| format!("--pty: {e}"))?;
    let line = format!("listening pty {}", pty.path);
    let (s, o) = (shared.clone(), opts.clone());
    std::thread::spawn(move || server::pty::serve_pty(pty, s, o));
    Ok(line)
}

#[cfg(not(unix))]
fn start_pty(_: &Shared, _: &ServeOptions) -> Result<String, Failure> {
    Err(Failure::Failed(
        "--pty needs a Unix system; use --tcp 127.0.0.1:PORT".into(),
    ))
}
