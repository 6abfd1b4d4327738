//! Motor protection that the speed loop cannot give itself: stall and over-speed detection,
//! evaluated every loop period on the same encoder delta.

use crate::speed_loop::{design, LOOP_HZ};

/// The nominal loop period, µs.
pub const NOMINAL_PERIOD_US: u32 = 1_000_000 / LOOP_HZ;
use protocol::Fault;

/// Above this |duty| the table must turn: 10 % of 24 V is ≈ 40 °/s at the table unloaded
/// ([`design::K_CPS_PER_DUTY`]), i.e. ≈ 36 counts per period.
pub const STALL_DUTY: f32 = 0.10;

/// Periods with |duty| ≥ [`STALL_DUTY`] and not one count moved before a stall is declared:
/// 100 ms, ≈ 18 mechanical time constants, and short enough that a blocked RE 30 (39 A stall
/// current at 24 V, limited by the bridge) does not overheat.
pub const STALL_PERIODS: u16 = (LOOP_HZ / 10) as u16;

/// Highest speed the rig may be commanded to ([`protocol::MAX_RATE_MDPS`]).
pub use protocol::MAX_RATE_MDPS;

/// Over-speed limit, counts/s: 125 % of [`MAX_RATE_MDPS`] (450 °/s), beyond any setpoint plus
/// ramp overshoot and, at 1 count per period, far beyond the measurement noise.
pub const OVER_SPEED_CPS: i32 = 405_000;

const _: () = assert!(
    (OVER_SPEED_CPS as f32) < design::K_CPS_PER_DUTY,
    "the drive must be able to exceed the over-speed limit, or a runaway goes undetected"
);

/// Stall and over-speed watch.
#[derive(Debug, Default, Clone)]
pub struct Supervisor {
    still_periods: u16,
}

impl Supervisor {
    /// Nothing seen yet.
    pub const fn new() -> Self {
        Self { still_periods: 0 }
    }

    /// Forget history (motor off).
    pub fn reset(&mut self) {
        self.still_periods = 0;
    }

    /// One period: the duty that was applied during it, how far the encoder moved, and how long
    /// the period was, µs, as measured on TIM5 (nominally 1 000). The speed is the distance over
    /// the measured period: a tick that comes late (delayed by a higher-priority task) carries
    /// more counts, and divided by the nominal period it would read as an over-speed.
    pub fn check(&mut self, applied_duty: f32, delta_counts: i32, period_us: u32) -> Option<Fault> {
        let period_us = i64::from(period_us.max(1));
        if i64::from(delta_counts).abs() * 1_000_000 > i64::from(OVER_SPEED_CPS) * period_us {
            return Some(Fault::OverSpeed);
        }
        if delta_counts == 0 && applied_duty.abs() >= STALL_DUTY {
            self.still_periods = self.still_periods.saturating_add(1);
            if self.still_periods >= STALL_PERIODS {
                return Some(Fault::Stall);
            }
        } else {
            self.still_periods = 0;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stall_needs_the_full_window_of_driven_stillness() {
        let mut s = Supervisor::new();
        for _ in 0..STALL_PERIODS - 1 {
            assert_eq!(s.check(0.5, 0, NOMINAL_PERIOD_US), None);
        }
        // One count of motion restarts the window.
        assert_eq!(s.check(0.5, 1, NOMINAL_PERIOD_US), None);
        for _ in 0..STALL_PERIODS - 1 {
            assert_eq!(s.check(-0.5, 0, NOMINAL_PERIOD_US), None);
        }
        assert_eq!(s.check(-0.5, 0, NOMINAL_PERIOD_US), Some(Fault::Stall));
    }

    #[test]
    fn low_duty_standstill_is_not_a_stall() {
        let mut s = Supervisor::new();
        for _ in 0..10 * STALL_PERIODS {
            assert_eq!(s.check(STALL_DUTY * 0.99, 0, NOMINAL_PERIOD_US), None);
        }
    }

    #[test]
    fn over_speed_in_either_direction() {
        let mut s = Supervisor::new();
        let limit_counts = OVER_SPEED_CPS / LOOP_HZ as i32;
        assert_eq!(s.check(0.9, limit_counts, NOMINAL_PERIOD_US), None);
        assert_eq!(s.check(0.9, limit_counts + 1, NOMINAL_PERIOD_US), Some(Fault::OverSpeed));
        assert_eq!(s.check(-0.9, -limit_counts - 1, NOMINAL_PERIOD_US), Some(Fault::OverSpeed));
    }

    /// Issue 28: a tick 500 µs late at 360 °/s (324 000 cps) carries 486 counts; over the
    /// nominal 1 ms that read as 486 000 cps, beyond the 405 000 cps limit, a false trip. Over
    /// the measured 1.5 ms it is the true 324 000 cps. A true over-speed in a late tick still trips.
    #[test]
    fn a_late_tick_is_not_an_over_speed() {
        let mut s = Supervisor::new();
        assert_eq!(s.check(0.9, 486, 1_500), None);
        // The limit over 1.5 ms is 607.5 counts.
        assert_eq!(s.check(0.9, 607, 1_500), None);
        assert_eq!(s.check(0.9, 608, 1_500), Some(Fault::OverSpeed));
        // An early tick is judged over its own, shorter, period.
        assert_eq!(Supervisor::new().check(0.9, 203, 500), Some(Fault::OverSpeed));
        assert_eq!(Supervisor::new().check(0.9, 202, 500), None);
    }
}
