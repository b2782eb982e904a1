//! Modbus TCP on the Ethernet build: [`CLIENTS`] connections on port
//! [`MODBUS_PORT`], each served by the gateway's one request handler
//! ([`Gateway::serve_tcp`]: the RTU gateway's map, cache and handshake).
//!
//! Each connection is cut into ADUs by their MBAP length
//! ([`crate::modbus::tcp`]); its requests are answered in order, each at
//! once from the gateway's registers (no answer waits for the controller),
//! and a request is taken only when its whole answer fits the socket's
//! transmit buffer, so a client that does not read its answers is held
//! back by TCP and nothing is lost. A length field out of range closes
//! the connection (the stream cannot be followed); an ADU with a protocol
//! ID other than 0 is dropped unanswered.
//!
//! A connection without a request for [`IDLE_MS`] is closed (a client that
//! connects and says nothing); one whose client closed its side (FIN) is
//! closed as soon as its whole requests are answered, a partial request
//! dropped; one the client reset is free at once; one that hears nothing
//! from its peer (keep-
//! alives unanswered: a client that vanished) is reset by the stack as on
//! the protocol-B port, after [`super::host::SILENCE_LIMIT_MS`].
//! While all [`CLIENTS`] sockets are taken, one more connection is reset
//! by the stack.
//!
//! Memory: [`ModbusBuffers`], [`CLIENT_BUFFER`] bytes each way per
//! connection (room for two whole ADUs), 2 × [`CLIENTS`] ×
//! [`CLIENT_BUFFER`] = 4,160 bytes in a static of the board, and one slot
//! per connection in the interface's socket set.

use smoltcp::iface::{SocketHandle, SocketSet};
use smoltcp::socket::tcp::{self, State};

use crate::modbus::tcp::{adu_len, Response, MAX_ADU, UNIT_AT};
use crate::modbus::Gateway;

/// The Modbus TCP port (the standard one).
pub const MODBUS_PORT: u16 = 502;
/// Modbus TCP connections served at once (a PLC, an HMI, a logger and a
/// service tool, say).
pub const CLIENTS: usize = 4;
/// Bytes of each Modbus socket buffer (receive and transmit, per
/// connection): two whole ADUs of the largest size ([`MAX_ADU`]) each way.
/// A request is taken only when a whole answer fits the transmit buffer,
/// so with room for two the next request is answered while the answer
/// before it still waits for its ACK; and the receive buffer (the TCP
/// window) lets a client send its next request, of any size, while the
/// one before it is still being taken. Less than [`MAX_ADU`] would never
/// answer a request; each byte more is 2 × [`CLIENTS`] bytes of RAM.
pub const CLIENT_BUFFER: usize = 2 * MAX_ADU;
/// A connection without a request for this long is closed.
pub const IDLE_MS: u32 = 60_000;
/// A connection closing still open after this long is reset.
pub const CLOSE_LIMIT_MS: u32 = 2_000;
/// Requests answered per connection and round, so that one busy client
/// cannot keep the loop from going round.
pub const REQUESTS_PER_ROUND: usize = 4;

// `serve` takes a request only when a whole answer fits the transmit
// buffer: below one ADU, no request would ever be taken.
const _: () = assert!(CLIENT_BUFFER >= MAX_ADU);

/// The Modbus sockets' buffers, in a static of the board.
pub struct ModbusBuffers {
    rx: [[u8; CLIENT_BUFFER]; CLIENTS],
    tx: [[u8; CLIENT_BUFFER]; CLIENTS],
}

impl ModbusBuffers {
    /// Zeroed buffers (a `static` of them takes no flash).
    pub const fn new() -> Self {
        ModbusBuffers {
            rx: [[0; CLIENT_BUFFER]; CLIENTS],
            tx: [[0; CLIENT_BUFFER]; CLIENTS],
        }
    }

    /// Adds a socket on each of these buffers to `set`; their handles.
    /// One socket at a time: an array of all of them, built on the stack
    /// and moved again by the adding, raised the Ethernet build's stack
    /// peak from 4,512 to 5,416 bytes with four sockets.
    pub(super) fn add_sockets<'a>(
        &'a mut self,
        set: &mut SocketSet<'a>,
    ) -> [SocketHandle; CLIENTS] {
        let ModbusBuffers { rx, tx } = self;
        let mut handles = [SocketHandle::default(); CLIENTS];
        for ((handle, rx), tx) in handles.iter_mut().zip(rx.iter_mut()).zip(tx.iter_mut()) {
            let mut socket = tcp::Socket::new(
                tcp::SocketBuffer::new(rx.as_mut_slice()),
                tcp::SocketBuffer::new(tx.as_mut_slice()),
            );
            super::host::configure(&mut socket);
            *handle = set.add(socket);
        }
        handles
    }
}

impl Default for ModbusBuffers {
    fn default() -> Self {
        Self::new()
    }
}

/// What one Modbus socket is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// Listening.
    Listen,
    /// A client's connection; its last request (or its connection) came
    /// at `last`.
    Open {
        /// Tick of the last request.
        last: u32,
    },
    /// Closing our side since `since`.
    Closing {
        /// Tick when the close began.
        since: u32,
    },
    /// Aborted: its reset goes out at the next poll, then it listens.
    Reset,
}

/// Counters of the Modbus TCP side.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ModbusTcpStats {
    /// Connections accepted.
    pub connections: u32,
    /// Requests taken (answered or dropped by the gateway).
    pub requests: u32,
    /// Connections closed after [`IDLE_MS`] without a request.
    pub idle_closed: u32,
    /// Connections reset for a length field out of range.
    pub framing_reset: u32,
}

/// The Modbus TCP sockets.
#[derive(Debug)]
pub struct ModbusClients {
    handles: [SocketHandle; CLIENTS],
    slots: [Slot; CLIENTS],
    port: u16,
    stats: ModbusTcpStats,
}

impl ModbusClients {
    /// The sockets `handles` (from [`ModbusBuffers`]) on `port`; they
    /// listen from the first [`ModbusClients::service`].
    pub fn new(handles: [SocketHandle; CLIENTS], port: u16) -> Self {
        ModbusClients {
            handles,
            slots: [Slot::Reset; CLIENTS],
            port,
            stats: ModbusTcpStats::default(),
        }
    }

    /// The port.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// What socket `n` is doing.
    pub fn slot(&self, n: usize) -> Option<Slot> {
        self.slots.get(n).copied()
    }

    /// Counters.
    pub fn stats(&self) -> ModbusTcpStats {
        self.stats
    }

    /// Looks at every socket after the interface was polled: answers the
    /// requests that arrived, closes idle and finished connections,
    /// listens again.
    pub fn service(&mut self, sockets: &mut SocketSet<'_>, gateway: &mut Gateway, now: u32) {
        for n in 0..CLIENTS {
            let (Some(&handle), Some(slot)) = (self.handles.get(n), self.slots.get(n).copied())
            else {
                continue;
            };
            let socket = sockets.get_mut::<tcp::Socket>(handle);
            let next = match slot {
                Slot::Reset => Slot::Listen,
                Slot::Listen => match socket.state() {
                    State::Established | State::CloseWait => {
                        self.stats.connections = self.stats.connections.wrapping_add(1);
                        self.serve(socket, gateway, now, now)
                    }
                    State::Closed | State::TimeWait => {
                        socket.abort();
                        Slot::Reset
                    }
                    _ => Slot::Listen,
                },
                Slot::Open { last } => self.serve(socket, gateway, last, now),
                Slot::Closing { since } => settle(socket, since, now),
            };
            if next == Slot::Listen && !socket.is_open() {
                // Cannot fail: the socket is closed and the port not 0.
                let _ = socket.listen(self.port);
            }
            if let Some(s) = self.slots.get_mut(n) {
                *s = next;
            }
        }
    }

    /// An open connection whose last request came at `last`: answers what
    /// arrived, in order.
    fn serve(
        &mut self,
        socket: &mut tcp::Socket<'_>,
        gateway: &mut Gateway,
        mut last: u32,
        now: u32,
    ) -> Slot {
        match socket.state() {
            State::Established | State::CloseWait => {}
            State::Closed => return Slot::Listen,
            _ => {
                socket.abort();
                return Slot::Reset;
            }
        }
        let mut adu = [0u8; MAX_ADU];
        let mut resp = Response::new();
        // Every complete request was taken.
        let mut drained = false;
        for _ in 0..REQUESTS_PER_ROUND {
            // The whole answer must fit: it is never sent in parts.
            if socket.send_capacity().saturating_sub(socket.send_queue()) < MAX_ADU {
                break;
            }
            let got = socket
                .peek_slice(adu.get_mut(..UNIT_AT).unwrap_or(&mut []))
                .unwrap_or(0);
            let len = match adu_len(adu.get(..got).unwrap_or(&[])) {
                None => {
                    drained = true;
                    break;
                }
                Some(Ok(len)) => len,
                Some(Err(_)) => {
                    self.stats.framing_reset = self.stats.framing_reset.wrapping_add(1);
                    socket.abort();
                    return Slot::Reset;
                }
            };
            if socket.recv_queue() < len {
                drained = true;
                break;
            }
            let Some(request) = adu.get_mut(..len) else {
                break;
            };
            if socket.recv_slice(request) != Ok(len) {
                socket.abort();
                return Slot::Reset;
            }
            last = now;
            self.stats.requests = self.stats.requests.wrapping_add(1);
            gateway.serve_tcp(request, &mut resp, now);
            // Fits: checked above.
            let _ = socket.send_slice(&resp);
        }
        // The client closed its side (its FIN came: CLOSE-WAIT; smoltcp's
        // `may_recv` stays true while a partial request is still in the
        // buffer, so it cannot tell): what it sent whole was answered, a
        // partial request is dropped, and our answers go out before our
        // close. The socket is free for the next client at once.
        let peer_closed = !socket.may_recv() || socket.state() == State::CloseWait;
        if peer_closed && drained {
            socket.close();
            return Slot::Closing { since: now };
        }
        if now.wrapping_sub(last) >= IDLE_MS {
            self.stats.idle_closed = self.stats.idle_closed.wrapping_add(1);
            socket.close();
            return Slot::Closing { since: now };
        }
        Slot::Open { last }
    }
}

/// A closing socket: listens again once closed, is reset if it lingers.
fn settle(socket: &mut tcp::Socket<'_>, since: u32, now: u32) -> Slot {
    // What the peer still sends is dropped: it reads our close instead of
    // stalling.
    while socket.can_recv() {
        if socket.recv(|b| (b.len(), ())).is_err() {
            break;
        }
    }
    match socket.state() {
        State::Closed => Slot::Listen,
        State::TimeWait => {
            socket.abort();
            Slot::Reset
        }
        _ if now.wrapping_sub(since) >= CLOSE_LIMIT_MS => {
            socket.abort();
            Slot::Reset
        }
        _ => Slot::Closing { since },
    }
}

#[cfg(test)]
mod tests;
