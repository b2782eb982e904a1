//! The axis model: servo, homing and trapezoidal moves in virtual time.
//!
//! Eight axes, all connected, servo off and not homed at start, at 0.
//! - 232H switches the servo; switching it off stops a move.
//! - 233H homes: the axis travels to 0 at the end-search speed, then creeps
//!   for [`HOME_CREEP_MS`]; bits 1-2 of the 212H status read 1 meanwhile,
//!   2 after.
//! - 234H / 235H / 237H / 26BH move to a coordinate, 236H jogs (to the soft
//!   limit [`SOFT_LIMIT`]) or inches. A move follows a trapezoidal speed
//!   profile from its acceleration, speed and deceleration (0 G = 9,806.65
//!   mm/s² × the value / 100); zero values take the record's values (237H),
//!   then the simulator's parameters [`DEFAULT_SPEED`], [`DEFAULT_ACC`].
//! - 238H stops the axes at their current position.
//! - 212H reports bit 0 (in use) while an axis moves or homes, bits 1-2
//!   (homing), bit 3 (servo), bit 4 (last operation completed normally),
//!   and the position at the time of the query. 215H reports AUTO mode,
//!   no system error, "operating in AUTO" and "system ready"; it has no
//!   field for motion.

use super::HOME_CREEP_MS;

/// Homing state (212H status bits 1-2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Home {
    /// Not homed since power-on.
    #[default]
    NotDone,
    /// Homing now.
    Returning,
    /// Homed.
    Done,
}

/// What an axis is doing while it is in use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Kind {
    /// A move, jog or inching.
    Move,
    /// A homing: travel to 0, then the creep.
    Home,
}

/// A trapezoidal (or triangular) move, in 0.001 mm and ms: 1 mm/s is
/// 1 unit/ms, 0.01 G is 0.0980665 units/ms².
#[derive(Debug, Clone, Copy, PartialEq)]
struct Motion {
    kind: Kind,
    from: f64,
    to: f64,
    start: u32,
    acc: f64,
    dec: f64,
    peak: f64,
    t_acc: f64,
    t_cruise: f64,
    t_dec: f64,
}

fn units_per_ms2(centi_g: u16) -> f64 {
    f64::from(centi_g.max(1)) * 0.098_066_5
}

impl Motion {
    fn new(kind: Kind, from: i32, to: i32, start: u32, acc: u16, dec: u16, speed: u16) -> Self {
        let (a, d, v) = (
            units_per_ms2(acc),
            units_per_ms2(dec),
            f64::from(speed.max(1)),
        );
        let dist = (f64::from(to) - f64::from(from)).abs();
        let (d_a, d_d) = (v * v / (2.0 * a), v * v / (2.0 * d));
        let (peak, t_cruise) = if d_a + d_d <= dist {
            (v, (dist - d_a - d_d) / v)
        } else {
            ((2.0 * dist * a * d / (a + d)).sqrt(), 0.0)
        };
        Motion {
            kind,
            from: f64::from(from),
            to: f64::from(to),
            start,
            acc: a,
            dec: d,
            peak,
            t_acc: peak / a,
            t_cruise,
            t_dec: peak / d,
        }
    }

    /// Milliseconds the travel takes.
    fn duration(&self) -> f64 {
        self.t_acc + self.t_cruise + self.t_dec
    }

    /// Whole ms after which the axis is at rest (a homing adds its creep).
    fn end_ms(&self) -> u32 {
        let creep = if self.kind == Kind::Home {
            HOME_CREEP_MS
        } else {
            0
        };
        self.duration().ceil() as u32 + creep
    }

    /// Position at tick `now`.
    fn position(&self, now: u32) -> i32 {
        let t = f64::from(now.wrapping_sub(self.start));
        let s = if t >= self.duration() {
            (self.to - self.from).abs()
        } else if t < self.t_acc {
            0.5 * self.acc * t * t
        } else if t < self.t_acc + self.t_cruise {
            0.5 * self.peak * self.t_acc + self.peak * (t - self.t_acc)
        } else {
            let u = t - self.t_acc - self.t_cruise;
            0.5 * self.peak * self.t_acc + self.peak * self.t_cruise + self.peak * u
                - 0.5 * self.dec * u * u
        };
        let dir = if self.to >= self.from { 1.0 } else { -1.0 };
        (self.from + dir * s).round() as i32
    }
}

/// One simulated axis.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Axis {
    /// Servo on.
    pub servo: bool,
    /// Homing state.
    pub home: Home,
    /// The last operation ended normally (212H bit 4).
    pub completed: bool,
    pos: i32,
    motion: Option<Motion>,
}

impl Axis {
    /// Brings the state up to tick `now`: a move whose time has passed ends.
    pub(super) fn settle(&mut self, now: u32) {
        if let Some(m) = self.motion {
            if now.wrapping_sub(m.start) >= m.end_ms() {
                self.pos = m.to as i32;
                self.motion = None;
                self.completed = true;
                if m.kind == Kind::Home {
                    self.home = Home::Done;
                }
            }
        }
    }

    /// Position at tick `now` (0.001 mm).
    pub fn position(&self, now: u32) -> i32 {
        self.motion.map_or(self.pos, |m| m.position(now))
    }

    /// Moving or homing at the last settle.
    pub fn in_use(&self) -> bool {
        self.motion.is_some()
    }

    /// The 212H status byte.
    pub fn status_byte(&self) -> u8 {
        let home = match self.home {
            Home::NotDone => 0,
            Home::Returning => 1,
            Home::Done => 2,
        };
        u8::from(self.in_use())
            | home << 1
            | u8::from(self.servo) << 3
            | u8::from(self.completed) << 4
    }

    /// Starts a move (or homing) to `to` at tick `now` with these
    /// acceleration, deceleration (0.01 G) and speed (mm/s). A move under
    /// way is taken over from where the axis is (refusals, when on, are
    /// the caller's).
    pub(super) fn begin(
        &mut self,
        kind: Kind,
        to: i32,
        now: u32,
        (acc, dec, speed): (u16, u16, u16),
    ) {
        self.pos = self.position(now);
        self.completed = false;
        if kind == Kind::Home {
            self.home = Home::Returning;
        }
        self.motion = Some(Motion::new(kind, self.pos, to, now, acc, dec, speed));
    }

    /// Stops at the current position; the operation did not complete.
    pub(super) fn stop(&mut self, now: u32) {
        if let Some(m) = self.motion.take() {
            self.pos = m.position(now);
            self.completed = false;
            if m.kind == Kind::Home {
                self.home = Home::NotDone;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_move_ends_at_its_target_after_its_profile_time() {
        // 50 mm at 100 mm/s, 0.3 G both ways: 34 ms ramps, about 534 ms in all.
        let mut a = Axis::default();
        a.begin(Kind::Move, 50_000, 1_000, (30, 30, 100));
        assert!(a.in_use());
        assert_eq!(a.status_byte() & 1, 1);
        a.settle(1_533);
        assert!(a.in_use(), "still moving at 533 ms");
        a.settle(1_535);
        assert!(!a.in_use());
        assert_eq!((a.position(2_000), a.completed), (50_000, true));
    }

    #[test]
    fn a_stopped_homing_leaves_the_axis_not_homed() {
        let mut a = Axis {
            pos: 10_000,
            ..Axis::default()
        };
        a.begin(Kind::Home, 0, 0, (30, 30, 100));
        assert_eq!(a.home, Home::Returning);
        assert_eq!(a.status_byte() & 0b111, 0b011);
        a.stop(50);
        assert_eq!(
            (a.home, a.completed, a.in_use()),
            (Home::NotDone, false, false)
        );
        assert!((0..10_000).contains(&a.position(60)));
    }
}
