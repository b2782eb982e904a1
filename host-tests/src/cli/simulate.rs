//! `iai simulate`: the controller simulator on a TCP port of this machine,
//! printing every frame it receives and sends.

use std::io::Write;
use std::net::{TcpListener, TcpStream};

use iai_protocol_b::frame::Station;

use super::inspect::{text_entry, Inspector, Item, Origin};
use crate::sim::{serve_tcp_observed, Simulator, Traffic};

/// Which controller the simulator behaves like.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimProfile {
    /// TTA buffers (2,051 / 2,048 bytes).
    Tta,
    /// 2003-generation X-SEL (1,023 / 1,024 bytes).
    Xsel2003,
}

/// Options of `iai simulate`.
#[derive(Debug, Clone)]
pub struct SimulateOptions {
    /// TCP port on 127.0.0.1 (0: any free port).
    pub port: u16,
    /// Controller kind.
    pub profile: SimProfile,
    /// Station code.
    pub station: u8,
    /// Stop after this many connections (`None`: serve forever).
    pub connections: Option<usize>,
}

fn log(out: &mut impl Write, arrow: &str, items: Vec<Item>) -> std::io::Result<()> {
    for item in items {
        for (i, line) in text_entry(&item).into_iter().enumerate() {
            // Position-stream fields would flood the log: the header line
            // and a few field lines per frame are enough.
            if i > 6 {
                writeln!(out, "  {arrow}     …")?;
                break;
            }
            writeln!(out, "  {arrow} {line}")?;
        }
    }
    out.flush()
}

/// Serves one connection until the peer closes it, logging both directions.
pub fn serve_logged(
    sim: &mut Simulator,
    stream: TcpStream,
    out: &mut impl Write,
) -> std::io::Result<()> {
    let (mut rx, mut tx) = (Inspector::new(), Inspector::new());
    rx.set_origin(Origin {
        line: None,
        dir: Some("rx"),
    });
    tx.set_origin(Origin {
        line: None,
        dir: Some("tx"),
    });
    serve_tcp_observed(sim, stream, |traffic| match traffic {
        Traffic::Received(bytes) => {
            rx.feed(bytes);
            log(out, "<", rx.take_items())
        }
        Traffic::Sent(bytes) => {
            tx.feed(bytes);
            log(out, ">", tx.take_items())
        }
        Traffic::Closed => {
            rx.finish();
            log(out, "<", rx.take_items())
        }
    })
}

/// Runs the simulator: prints `listening on 127.0.0.1:PORT`, then serves
/// connections one after the other.
pub fn command(opts: &SimulateOptions, out: &mut impl Write) -> std::io::Result<()> {
    let listener = TcpListener::bind(("127.0.0.1", opts.port))?;
    let addr = listener.local_addr()?;
    let station = Station(opts.station);
    let (name, make): (&str, fn(Station) -> Simulator) = match opts.profile {
        SimProfile::Tta => ("TTA", Simulator::tta),
        SimProfile::Xsel2003 => ("X-SEL 2003", Simulator::xsel_2003),
    };
    let mut sim = make(station);
    writeln!(out, "listening on {addr}")?;
    writeln!(
        out,
        "simulating a {name} controller, station {:02X} (receive buffer {} bytes, transmit {} bytes); Ctrl-C stops",
        opts.station, sim.max_receive, sim.max_transmit
    )?;
    out.flush()?;
    for (served, conn) in listener.incoming().enumerate() {
        let conn = conn?;
        let peer = conn.peer_addr()?;
        writeln!(out, "connection from {peer}")?;
        out.flush()?;
        if let Err(e) = serve_logged(&mut sim, conn, out) {
            writeln!(out, "connection from {peer} failed: {e}")?;
        }
        let s = sim.stats();
        writeln!(
            out,
            "connection from {peer} closed: {} command(s), {} reply(ies), {} broken frame(s), {} position record(s) written, table holds {}",
            s.commands, s.replies, s.broken_frames, s.records_written, sim.table.len()
        )?;
        out.flush()?;
        if opts.connections.is_some_and(|n| served + 1 >= n) {
            break;
        }
    }
    Ok(())
}
