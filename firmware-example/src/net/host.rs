//! The protocol-B host on TCP: which connection is the host, and the
//! bridge's upstream [`Port`] on its socket.
//!
//! [`SOCKETS`] TCP sockets listen on the port, so that a connection made
//! while the host is connected, or while its connection is closing, is
//! answered. Each socket has a [`Role`]: the first connection made while
//! nobody is served becomes the **host** (its bytes are the bridge's
//! upstream, the bridge's answers go to it); one made while a host is
//! served is **held**, then admitted or **refused** with `&` B0B; one made
//! while the host is leaving, or while the bridge finishes what the last
//! host started, **waits** unread and becomes the host once the bridge is
//! idle. A client that closes and connects again at once is not refused.
//!
//! **Flow control.** The bridge reads the socket only when it can use the
//! bytes; while it cannot (a 26DH chunk being confirmed and read back), the
//! socket's receive buffer fills, its window closes and TCP stops the host.
//! Nothing is lost on the way in ([`Port::take_overruns`] is 0): TCP's
//! window replaces XON/XOFF.
//!
//! **End of a host.** When the host closes its sending side and the
//! bridge has looked at every byte, or the connection is gone (reset,
//! closed, timed out), the bridge is told ([`Bridge::end_of_input`]): a
//! partial command is dropped, a 26DH being received ends as after a stall
//! (`&` B04, with the same guarantees). A half-closed host still gets the
//! bridge's answers, then its connection is closed once the bridge is
//! idle; a gone host's answers are dropped. The next host finds the bridge
//! idle.
//!
//! **A host that stops reading** is reset after [`HOST_STALL_MS`] without
//! taking a byte while data waits for it; one that vanished without
//! closing is found by keep-alives ([`KEEP_ALIVE_MS`],
//! [`SILENCE_LIMIT_MS`]). Either way the bridge ends its work as above and
//! is then free for a held connection.

use iai_protocol_b::frame::{emit_frame, Header, Station};
use smoltcp::iface::{SocketHandle, SocketSet};
use smoltcp::socket::tcp::{self, State};
use smoltcp::time::Duration;

use crate::bridge::Bridge;
use crate::codes;
use crate::serial::Port;

/// A host that takes none of the bytes waiting for it for this long is
/// reset (the bridge waits while the socket's transmit buffer is full).
pub const HOST_STALL_MS: u32 = 10_000;
/// How long a connection made while a host is served is held before it
/// is refused (the host may be leaving: its close can still be on the
/// way behind the data it sent last).
pub const HOLD_MS: u32 = 1_000;
/// A refused connection still open after this long is reset.
pub const REFUSE_LIMIT_MS: u32 = 2_000;
/// A connection closing (after the host's close) still open after this
/// long is reset.
pub const CLOSE_LIMIT_MS: u32 = 2_000;
/// Keep-alive interval on an idle connection.
pub const KEEP_ALIVE_MS: u64 = 5_000;
/// A connection that hears nothing from its peer for this long (keep-
/// alives unanswered, data unacknowledged) is reset by the stack. A host
/// that vanished with an answer still waiting for it is reset sooner, as
/// one that stops reading ([`HOST_STALL_MS`] after it last took a byte).
pub const SILENCE_LIMIT_MS: u64 = 20_000;
/// Sockets listening on the port: the host's, one for a connection made
/// while it is served (held, then refused or admitted) and one more, so
/// that a client that closes and connects again at once still finds one
/// listening while the last host's socket finishes its close. While all
/// are taken, one more connection is reset by the stack.
pub const SOCKETS: usize = 3;

/// What one socket is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Listening, or connected and waiting, unread, to become the host
    /// once the bridge is idle.
    Listen,
    /// Connected while a host is served, unread; refused if that host is
    /// still served [`HOLD_MS`] after `since`. If the host leaves first,
    /// it waits as [`Role::Listen`] does (a client that closes and
    /// connects again before its close reached the bridge is not refused).
    Held {
        /// Tick when it was first seen connected.
        since: u32,
    },
    /// The host's connection.
    Host,
    /// The host left; closing our side since `since`.
    Closing {
        /// Tick when the close began.
        since: u32,
    },
    /// Answered `&` + the bridge's station + [`codes::HOST_BUSY`] (B0B) +
    /// SC CR LF and closing since `since`: what it sends is read and
    /// dropped; it is reset if not gone within [`REFUSE_LIMIT_MS`].
    Refused {
        /// Tick when the refusal went out.
        since: u32,
    },
    /// Aborted: its reset goes out at the next poll of the interface,
    /// then it listens again.
    Reset,
}

/// Whether the bridge serves anyone.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Session {
    /// Nobody: the next connection becomes the host.
    Vacant,
    /// The host is on socket `n`.
    Host(usize),
    /// The host left; the bridge finishes its work, answers dropped.
    Draining,
}

/// Counters of the TCP side.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HostStats {
    /// Connections that became the host.
    pub hosts: u32,
    /// Connections refused with B0B.
    pub refused: u32,
    /// Hosts whose connection went while the bridge worked for them (a
    /// partial command dropped, a 26DH ended with B04, or answers dropped).
    pub cut_short: u32,
    /// Hosts reset for taking nothing for [`HOST_STALL_MS`].
    pub stalled: u32,
}

/// The sockets on the protocol-B port and who is the host.
#[derive(Debug)]
pub struct Hosts {
    handles: [SocketHandle; SOCKETS],
    roles: [Role; SOCKETS],
    session: Session,
    port: u16,
    /// The host's transmit queue when last looked at, and since when it
    /// has not shrunk.
    tx_queue: usize,
    tx_still_since: u32,
    /// The bridge was told that the host's input ended.
    input_ended: bool,
    /// The host closed its sending side (or its connection is gone).
    leaving: bool,
    stats: HostStats,
}

/// Settings of a socket on the protocol-B port.
pub fn configure(socket: &mut tcp::Socket<'_>) {
    socket.set_nagle_enabled(false);
    socket.set_keep_alive(Some(Duration::from_millis(KEEP_ALIVE_MS)));
    socket.set_timeout(Some(Duration::from_millis(SILENCE_LIMIT_MS)));
}

impl Hosts {
    /// The sockets `handles` (TCP, set up with [`configure`]) on `port`;
    /// they listen from the first [`Hosts::service`].
    pub fn new(handles: [SocketHandle; SOCKETS], port: u16) -> Self {
        Hosts {
            handles,
            roles: [Role::Reset; SOCKETS],
            session: Session::Vacant,
            port,
            tx_queue: 0,
            tx_still_since: 0,
            input_ended: false,
            leaving: false,
            stats: HostStats::default(),
        }
    }

    /// Who is served.
    pub fn session(&self) -> Session {
        self.session
    }

    /// What socket `n` is doing.
    pub fn role(&self, n: usize) -> Option<Role> {
        self.roles.get(n).copied()
    }

    /// Counters.
    pub fn stats(&self) -> HostStats {
        self.stats
    }

    /// The host's socket, if a host is served.
    pub fn host_handle(&self) -> Option<SocketHandle> {
        match self.session {
            Session::Host(n) => self.handles.get(n).copied(),
            _ => None,
        }
    }

    /// The bridge's upstream for this round.
    pub fn port<'a, 's>(&self, sockets: &'a mut SocketSet<'s>) -> HostPort<'a, 's> {
        HostPort {
            sockets,
            host: self.host_handle(),
        }
    }

    /// Looks at every socket after the interface was polled: admits,
    /// refuses, ends and recycles connections, and tells the bridge when
    /// its host's input ended. `station` is the bridge's own (for B0B).
    pub fn service(
        &mut self,
        sockets: &mut SocketSet<'_>,
        bridge: &mut Bridge,
        station: Station,
        now: u32,
    ) {
        if self.session == Session::Draining && bridge.end_of_input() && bridge.host_idle() {
            self.session = Session::Vacant;
        }
        // The host's socket first: a host that left and a connection made
        // just after it seen in the same round, the one leaves before the
        // other is judged (which is then admitted, not refused).
        let first = match self.session {
            Session::Host(h) => h,
            _ => 0,
        };
        for k in 0..SOCKETS {
            let n = (first + k) % SOCKETS;
            let (Some(&handle), Some(role)) = (self.handles.get(n), self.roles.get(n).copied())
            else {
                continue;
            };
            let socket = sockets.get_mut::<tcp::Socket>(handle);
            let next = match role {
                // The reset went out with the last poll.
                Role::Reset => Role::Listen,
                Role::Listen => self.on_listening(socket, n, None, bridge, now),
                Role::Held { since } => self.on_listening(socket, n, Some(since), bridge, now),
                Role::Host => self.on_host(socket, bridge, now),
                Role::Closing { since } => settle(socket, since, CLOSE_LIMIT_MS, now, role),
                Role::Refused { since } => settle(socket, since, REFUSE_LIMIT_MS, now, role),
            };
            if matches!(next, Role::Refused { .. }) && !matches!(role, Role::Refused { .. }) {
                refuse(socket, station);
                self.stats.refused = self.stats.refused.wrapping_add(1);
            }
            if next == Role::Listen && !socket.is_open() {
                // Cannot fail: the socket is closed and the port not 0.
                let _ = socket.listen(self.port);
            }
            if let Some(r) = self.roles.get_mut(n) {
                *r = next;
            }
        }
    }

    /// A listening socket (or one `held` since then): a connection
    /// established on it becomes the host, waits, is held or is refused.
    fn on_listening(
        &mut self,
        socket: &mut tcp::Socket<'_>,
        n: usize,
        held: Option<u32>,
        bridge: &Bridge,
        now: u32,
    ) -> Role {
        match socket.state() {
            State::Established | State::CloseWait => {}
            State::Closed | State::TimeWait => {
                socket.abort();
                return Role::Reset;
            }
            _ => return Role::Listen,
        }
        match self.session {
            Session::Vacant if bridge.host_idle() => {
                self.session = Session::Host(n);
                self.tx_queue = 0;
                self.tx_still_since = now;
                self.input_ended = false;
                self.leaving = false;
                self.stats.hosts = self.stats.hosts.wrapping_add(1);
                Role::Host
            }
            Session::Host(_) if !self.leaving => match held {
                None => Role::Held { since: now },
                Some(since) if now.wrapping_sub(since) >= HOLD_MS => Role::Refused { since: now },
                Some(since) => Role::Held { since },
            },
            // The host is leaving, or the bridge still finishes the last
            // host's work: wait.
            _ => held.map_or(Role::Listen, |since| Role::Held { since }),
        }
    }

    /// The host's socket: its end, or a stall.
    fn on_host(&mut self, socket: &mut tcp::Socket<'_>, bridge: &mut Bridge, now: u32) -> Role {
        let gone = !matches!(socket.state(), State::Established | State::CloseWait);
        self.leaving = gone || !socket.may_recv();
        if gone {
            // Reset by the peer, timed out, or closed under us: the
            // bridge's answers go nowhere.
            self.leave(bridge);
            if socket.state() == State::Closed {
                return Role::Listen;
            }
            socket.abort();
            return Role::Reset;
        }
        let input_done = !socket.may_recv() && !socket.can_recv();
        if input_done && !self.input_ended && bridge.end_of_input() {
            self.input_ended = true;
        }
        let queue = socket.send_queue();
        if queue == 0 || queue < self.tx_queue {
            self.tx_still_since = now;
        }
        self.tx_queue = queue;
        if queue > 0 && now.wrapping_sub(self.tx_still_since) >= HOST_STALL_MS {
            socket.abort();
            self.stats.stalled = self.stats.stalled.wrapping_add(1);
            self.leave(bridge);
            return Role::Reset;
        }
        if self.input_ended && bridge.host_idle() && queue == 0 {
            // Everything answered and sent: close our side too.
            socket.close();
            self.session = Session::Vacant;
            return Role::Closing { since: now };
        }
        Role::Host
    }

    /// The host's connection is gone: the bridge ends what it started;
    /// its answers are dropped until it is idle.
    fn leave(&mut self, bridge: &mut Bridge) {
        let ended = bridge.end_of_input();
        if ended && bridge.host_idle() {
            self.session = Session::Vacant;
        } else {
            self.stats.cut_short = self.stats.cut_short.wrapping_add(1);
            self.session = Session::Draining;
        }
    }
}

/// A socket closing after the host left or after a refusal: listens again
/// once closed, is reset if it lingers past `limit_ms`.
fn settle(socket: &mut tcp::Socket<'_>, since: u32, limit_ms: u32, now: u32, role: Role) -> Role {
    // What the peer still sends is dropped: its window stays open, so it
    // reads our close instead of stalling.
    while socket.can_recv() {
        if socket.recv(|b| (b.len(), ())).is_err() {
            break;
        }
    }
    match socket.state() {
        State::Closed => Role::Listen,
        // Our close went first and the peer's came: nothing more to say.
        State::TimeWait => {
            socket.abort();
            Role::Reset
        }
        _ if now.wrapping_sub(since) >= limit_ms => {
            socket.abort();
            Role::Reset
        }
        _ => role,
    }
}

/// Sends the refusal, `&` + `station` + B0B, and closes.
fn refuse(socket: &mut tcp::Socket<'_>, station: Station) {
    let mut frame = [0u8; 16];
    let len = emit_frame(
        &mut frame,
        Header::Error,
        station,
        codes::HOST_BUSY,
        Default::default(),
        |_| Ok(()),
    )
    .unwrap_or(0);
    let _ = socket.send_slice(frame.get(..len).unwrap_or(&[]));
    socket.close();
}

/// The bridge's upstream on the host's socket: reads what the host sent;
/// writes to it, or drops what is written while no host is served (the
/// answers of a host that left).
pub struct HostPort<'a, 's> {
    sockets: &'a mut SocketSet<'s>,
    host: Option<SocketHandle>,
}

impl embedded_io::ErrorType for HostPort<'_, '_> {
    type Error = core::convert::Infallible;
}

impl embedded_io::ReadReady for HostPort<'_, '_> {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(match self.host {
            Some(h) => self.sockets.get::<tcp::Socket>(h).can_recv(),
            None => false,
        })
    }
}

impl embedded_io::Read for HostPort<'_, '_> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        Ok(match self.host {
            Some(h) => self
                .sockets
                .get_mut::<tcp::Socket>(h)
                .recv_slice(buf)
                .unwrap_or(0),
            None => 0,
        })
    }
}

impl embedded_io::WriteReady for HostPort<'_, '_> {
    fn write_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(match self.host {
            Some(h) => {
                let s = self.sockets.get::<tcp::Socket>(h);
                !s.may_send() || s.can_send()
            }
            None => true,
        })
    }
}

impl embedded_io::Write for HostPort<'_, '_> {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        Ok(match self.host {
            Some(h) => {
                let s = self.sockets.get_mut::<tcp::Socket>(h);
                if s.may_send() {
                    s.send_slice(buf).unwrap_or(buf.len())
                } else {
                    buf.len()
                }
            }
            None => buf.len(),
        })
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// TCP loses no byte: nothing to count.
impl Port for HostPort<'_, '_> {}

#[cfg(test)]
mod tests;
