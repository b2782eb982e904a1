//! Hosts that come and go: for an upstream that is a connection rather
//! than a cable (protocol B over TCP, [`crate::net`]). A serial host never
//! leaves; a TCP host may close or drop its connection anywhere, and the
//! next host must find the bridge as if nobody had been there before.
//!
//! [`Bridge::end_of_input`] is how the owner of the upstream says that no
//! more bytes will come from the current host. What that host started is
//! then ended the way a host that stops would end it, only without
//! waiting for the silence: a partial command is dropped (never
//! forwarded), and a 26DH still being received stops as after
//! [`UPSTREAM_STALL_MS`](super::UPSTREAM_STALL_MS), answered `&`
//! [`codes::UPSTREAM_STALLED`] (B04) with the same guarantee: the chunks
//! already written hold only records of that message, each confirmed and
//! read back; the record being received is never written. Work that needs
//! nothing more from the host (a forwarded command waiting for its reply,
//! a 26DH received whole and still being written) runs to its end; where
//! its answer goes is the upstream's business.

use super::upstream::Upstream;
use super::{Bridge, Mode};
use crate::codes;

impl Bridge {
    /// Whether the bridge is idle and holds no byte of the host's that it
    /// has not looked at: a new host may be served from here.
    pub fn host_idle(&self) -> bool {
        self.mode == Mode::Idle && self.up.staged() == 0
    }

    /// No more bytes will come from the current host (see the module
    /// docs). Returns `false`, changing nothing, while bytes the bridge
    /// already read from the port wait to be looked at (they may complete
    /// what the host started): call again after the next
    /// [`Bridge::poll`]. Calling it again once it returned `true` is
    /// harmless.
    pub fn end_of_input(&mut self) -> bool {
        if self.up.staged() > 0 {
            return false;
        }
        match self.mode {
            Mode::Head | Mode::Command | Mode::Skip { .. } => {
                self.stats.rejected += 1;
                self.go_idle();
            }
            Mode::Stream {
                station,
                upstream_done: false,
                abort: None,
                waiting_since,
            } => {
                self.mode = Mode::Stream {
                    station,
                    upstream_done: false,
                    abort: Some(codes::UPSTREAM_STALLED),
                    waiting_since,
                };
            }
            _ => {}
        }
        // The envelope, the skipper and the quit detector start afresh.
        self.up = Upstream::new();
        true
    }
}
