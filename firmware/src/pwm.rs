//! Duty to PWM compare value, with error feedback.
//!
//! TIM1 at 168 MHz and 20 kHz resolves duty to 1/8400: 2.9 mV of 24 V, or 86 cps (0.05 % of
//! 0.5 Hz) of steady table speed. Rounding alone would make the loop hunt between two adjacent
//! levels slowly; carrying each period's rounding error into the next makes the mean duty exact
//! and moves the quantisation noise to the loop rate, where the 5.6 ms mechanics filter it out.

/// PWM timer ticks per period: TIM1 at 168 MHz, 20 kHz (above hearing, and 10 periods per
/// electrical time constant of 0.19 ms of the RE 30).
pub const PWM_PERIOD_TICKS: u16 = 8_400;

/// What the H-bridge (PWM + DIR + EN) does until the next loop period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MotorCommand {
    /// EN: bridge enabled; when false the outputs float and the motor coasts.
    pub enable: bool,
    /// DIR: drive towards negative speed.
    pub reverse: bool,
    /// PWM compare value, 0 ..= [`PWM_PERIOD_TICKS`].
    pub compare: u16,
}

impl MotorCommand {
    /// Bridge disabled.
    pub const OFF: MotorCommand = MotorCommand { enable: false, reverse: false, compare: 0 };

    /// Applied duty as a signed fraction of the supply (0 when disabled).
    pub fn duty(&self) -> f32 {
        if !self.enable {
            return 0.0;
        }
        let magnitude = f32::from(self.compare) / f32::from(PWM_PERIOD_TICKS);
        if self.reverse {
            -magnitude
        } else {
            magnitude
        }
    }
}

/// Error-feedback quantiser from duty to [`MotorCommand`].
#[derive(Debug, Default, Clone)]
pub struct PwmModulator {
    residual_ticks: f32,
}

impl PwmModulator {
    /// At rest.
    pub const fn new() -> Self {
        Self { residual_ticks: 0.0 }
    }

    /// Forget the carried error (bridge off).
    pub fn reset(&mut self) {
        self.residual_ticks = 0.0;
    }

    /// Bridge enabled at `duty` (signed fraction, |duty| ≤ 1).
    pub fn drive(&mut self, duty: f32) -> MotorCommand {
        let wanted = duty * f32::from(PWM_PERIOD_TICKS) + self.residual_ticks;
        let period = f32::from(PWM_PERIOD_TICKS);
        let ticks = crate::limit(libm::floorf(wanted + 0.5), period);
        self.residual_ticks = crate::limit(wanted - ticks, 1.0);
        MotorCommand { enable: true, reverse: ticks < 0.0, compare: ticks.abs() as u16 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_duty_is_exact_to_one_tick_over_any_run() {
        let mut m = PwmModulator::new();
        let duty = 0.223_76_f32; // 1879.58 ticks
        let wanted = f64::from(duty) * 8400.0;
        let mut total = 0u64;
        for n in 1..=1000u64 {
            total += u64::from(m.drive(duty).compare);
            // Plain rounding would drift by 0.42 tick per period: 420 ticks after 1000.
            assert!((total as f64 - wanted * n as f64).abs() <= 1.0, "period {n}");
        }
    }

    #[test]
    fn direction_limits_and_off() {
        let mut m = PwmModulator::new();
        let c = m.drive(-0.5);
        assert_eq!((c.enable, c.reverse, c.compare), (true, true, 4200));
        assert_eq!(m.drive(1.5).compare, PWM_PERIOD_TICKS);
        assert_eq!(MotorCommand::OFF.duty(), 0.0);
    }
}
