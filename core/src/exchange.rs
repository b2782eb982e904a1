//! One command and its reply: when to (re)send, when to give up.
//!
//! Shared by the [transfer engine](crate::transfer) and the
//! [read-back engine](crate::readback). The rules are those of the
//! 2003 X-SEL specification, chapter 5 (p. 62; the TTA's own chapter is
//! lost and the same rules are assumed): a reply must arrive within the
//! timeout after the command was completely sent, otherwise the command is
//! sent again, up to a limit of sends.

/// `now` is at or after `at` on a wrapping millisecond clock.
pub(crate) fn reached(now: u32, at: u32) -> bool {
    now.wrapping_sub(at) < 0x8000_0000
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum Phase {
    Idle,
    Send { not_before: u32 },
    Sending,
    Await { deadline: u32 },
}

/// What the exchange needs now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Due {
    /// Nothing outstanding.
    Idle,
    /// Transmit the command; `fresh` on the first poll of each send.
    Transmit { fresh: bool },
    /// Nothing to do before this tick.
    WaitUntil(u32),
    /// The reply did not come in time; the exchange is idle.
    TimedOut,
}

/// State of one command/reply exchange.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Exchange {
    phase: Phase,
    tries: u8,
}

impl Exchange {
    pub(crate) const fn new() -> Self {
        Exchange {
            phase: Phase::Idle,
            tries: 0,
        }
    }

    /// A new command is ready: send it from tick `not_before` on.
    pub(crate) fn start(&mut self, not_before: u32) {
        self.tries = 0;
        self.phase = Phase::Send { not_before };
    }

    pub(crate) fn poll(&mut self, now: u32) -> Due {
        match self.phase {
            Phase::Idle => Due::Idle,
            Phase::Send { not_before } if !reached(now, not_before) => Due::WaitUntil(not_before),
            Phase::Send { .. } => {
                self.tries = self.tries.saturating_add(1);
                self.phase = Phase::Sending;
                Due::Transmit { fresh: true }
            }
            Phase::Sending => Due::Transmit { fresh: false },
            Phase::Await { deadline } if !reached(now, deadline) => Due::WaitUntil(deadline),
            Phase::Await { .. } => {
                self.phase = Phase::Idle;
                Due::TimedOut
            }
        }
    }

    /// The command was completely transmitted at `now`.
    pub(crate) fn sent(&mut self, now: u32, timeout_ms: u32) {
        if self.phase == Phase::Sending {
            self.phase = Phase::Await {
                deadline: now.wrapping_add(timeout_ms),
            };
        }
    }

    /// Whether a reply is awaited.
    pub(crate) fn awaiting(&self) -> bool {
        matches!(self.phase, Phase::Await { .. })
    }

    /// Sends again from `at` if fewer than `max_tries` sends were made;
    /// `false` (and idle) otherwise.
    pub(crate) fn retry(&mut self, at: u32, max_tries: u8) -> bool {
        if self.tries < max_tries {
            self.phase = Phase::Send { not_before: at };
            true
        } else {
            self.phase = Phase::Idle;
            false
        }
    }

    /// The reply came: the exchange is over.
    pub(crate) fn finish(&mut self) {
        self.phase = Phase::Idle;
        self.tries = 0;
    }
}
