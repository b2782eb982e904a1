//! The polling schedule: every period the gateway asks the controller, one
//! query at a time, for what the map shows (212H for the axes, 215H, 213H,
//! 216H, the ports and flags, the integer variables). A round that takes
//! longer than the period (a controller that stops answering: 3 s per
//! query) is followed by the next at once. After a motion command the
//! axes are asked first, so that PEND and HEND catch up soon. The
//! controller's version (201H, for the device identification) is asked
//! once each time the line comes up, before the rest of the round.

use iai_protocol_b::catalogue::{self, MessageInfo};

/// One query of a round, in the order asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Query {
    /// 212H of the mapped axes.
    Axes,
    /// 215H.
    System,
    /// 213H of the program in PRGNO.
    Program,
    /// 216H, the latest system error.
    ErrorDetail,
    /// 20BH, the mapped input ports.
    Inputs,
    /// 20CH, the mapped output ports.
    Outputs,
    /// 20DH, the mapped global flags.
    Flags,
    /// 20EH, the mapped global integer variables.
    Integers,
    /// 201H, the controller's version (asked out of turn, once the line
    /// is up).
    Version,
}

impl Query {
    /// A round, in order.
    pub const ROUND: [Query; 8] = [
        Query::Axes,
        Query::System,
        Query::Program,
        Query::ErrorDetail,
        Query::Inputs,
        Query::Outputs,
        Query::Flags,
        Query::Integers,
    ];

    /// Its message.
    pub const fn message(self) -> &'static MessageInfo {
        match self {
            Query::Axes => &catalogue::AXIS_STATUS_QUERY,
            Query::System => &catalogue::SYSTEM_STATUS_QUERY,
            Query::Program => &catalogue::PROGRAM_STATUS_QUERY,
            Query::ErrorDetail => &catalogue::ERROR_DETAIL_QUERY,
            Query::Inputs => &catalogue::INPUT_PORT_QUERY,
            Query::Outputs => &catalogue::OUTPUT_PORT_QUERY,
            Query::Flags => &catalogue::FLAG_QUERY,
            Query::Integers => &catalogue::INTEGER_VARIABLE_QUERY,
            Query::Version => &catalogue::VERSION_QUERY,
        }
    }
}

/// Where the schedule is.
#[derive(Debug, Clone, Copy)]
pub struct Schedule {
    period_ms: u32,
    /// Next query of the round (`ROUND.len()`: the round is over).
    next: usize,
    /// When the current round started.
    started: Option<u32>,
    /// Ask the axes next, out of turn.
    axes_first: bool,
    /// Ask the version next, out of turn (after the axes).
    version_first: bool,
}

impl Schedule {
    /// A schedule with this period; the first round is due at once.
    pub const fn new(period_ms: u16) -> Self {
        Schedule {
            period_ms: period_ms as u32,
            next: 0,
            started: None,
            axes_first: false,
            version_first: false,
        }
    }

    /// The polling period, ms.
    pub const fn period_ms(&self) -> u32 {
        self.period_ms
    }

    /// Ask the axes before anything else.
    pub fn axes_soon(&mut self) {
        self.axes_first = true;
    }

    /// Ask the controller's version before the rest of the round (the
    /// line came up).
    pub fn version_soon(&mut self) {
        self.version_first = true;
    }

    /// The next query due at `now` that `allowed` permits, and marks it
    /// asked; `None` until the next round is due ([`Schedule::due_at`]).
    pub fn next(&mut self, now: u32, allowed: impl Fn(Query) -> bool) -> Option<Query> {
        if self.axes_first {
            self.axes_first = false;
            if allowed(Query::Axes) {
                return Some(Query::Axes);
            }
        }
        if self.version_first {
            self.version_first = false;
            if allowed(Query::Version) {
                return Some(Query::Version);
            }
        }
        loop {
            if self.next >= Query::ROUND.len() {
                let start = self.started?;
                if now.wrapping_sub(start) < self.period_ms {
                    return None;
                }
                self.next = 0;
                self.started = None;
            }
            if self.next == 0 && self.started.is_none() {
                self.started = Some(now);
            }
            let q = Query::ROUND.get(self.next).copied()?;
            self.next += 1;
            if allowed(q) {
                return Some(q);
            }
        }
    }

    /// When the next query is due (`None`: now).
    pub fn due_at(&self) -> Option<u32> {
        if self.axes_first || self.version_first || self.next < Query::ROUND.len() {
            return None;
        }
        self.started.map(|s| s.wrapping_add(self.period_ms))
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    #[test]
    fn a_round_every_period_axes_first_after_a_command() {
        let mut s = Schedule::new(100);
        let all = |_| true;
        let round: Vec<_> = (0..8).map_while(|_| s.next(0, all)).collect();
        assert_eq!(round, Query::ROUND);
        assert_eq!(s.next(50, all), None);
        assert_eq!(s.due_at(), Some(100));
        s.axes_soon();
        assert_eq!(s.next(60, all), Some(Query::Axes));
        assert_eq!(s.next(100, all), Some(Query::Axes));
        // A policy that refuses 20EH: the round skips it.
        let no_ints = |q| q != Query::Integers;
        let rest: Vec<_> = (0..8).map_while(|_| s.next(100, no_ints)).collect();
        assert_eq!(rest.len(), 6);
        // A round longer than the period: the next starts at once.
        assert_eq!(s.next(5_000, all), Some(Query::Axes));
        // The line came up: the version once, then the round goes on.
        s.version_soon();
        assert_eq!(s.due_at(), None);
        assert_eq!(s.next(5_001, all), Some(Query::Version));
        assert_eq!(s.next(5_002, all), Some(Query::System));
        // A policy that refuses 201H: not asked.
        s.version_soon();
        let no_version = |q| q != Query::Version;
        assert_eq!(s.next(5_003, no_version), Some(Query::Program));
    }
}
