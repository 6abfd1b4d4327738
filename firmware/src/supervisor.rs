//! Motor protection that the speed loop cannot give itself: stall and over-speed detection,
//! evaluated every loop period on the same encoder delta.

use crate::speed_loop::{design, LOOP_HZ};
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

    /// One period: the duty that was applied during it and how far the encoder moved.
    pub fn check(&mut self, applied_duty: f32, delta_counts: i32) -> Option<Fault> {
        if delta_counts.saturating_mul(LOOP_HZ as i32).saturating_abs() > OVER_SPEED_CPS {
            return Some(Fault::OverSpeed);
        }
        if delta_counts == 0 && applied_duty.abs() >= STALL_DUTY {
            self.still_periods += 1;
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
            assert_eq!(s.check(0.5, 0), None);
        }
        // One count of motion restarts the window.
        assert_eq!(s.check(0.5, 1), None);
        for _ in 0..STALL_PERIODS - 1 {
            assert_eq!(s.check(-0.5, 0), None);
        }
        assert_eq!(s.check(-0.5, 0), Some(Fault::Stall));
    }

    #[test]
    fn low_duty_standstill_is_not_a_stall() {
        let mut s = Supervisor::new();
        for _ in 0..10 * STALL_PERIODS {
            assert_eq!(s.check(STALL_DUTY * 0.99, 0), None);
        }
    }

    #[test]
    fn over_speed_in_either_direction() {
        let mut s = Supervisor::new();
        let limit_counts = OVER_SPEED_CPS / LOOP_HZ as i32;
        assert_eq!(s.check(0.9, limit_counts), None);
        assert_eq!(s.check(0.9, limit_counts + 1), Some(Fault::OverSpeed));
        assert_eq!(s.check(-0.9, -limit_counts - 1), Some(Fault::OverSpeed));
    }
}
