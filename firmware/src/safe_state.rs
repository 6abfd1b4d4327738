//! The one action that makes the motor safe, whatever went wrong: bridge enable low first (the
//! H-bridge's outputs float at once and the motor coasts, even if the PWM write that follows
//! never happens), then PWM compare 0 (so a bridge re-enabled by anything short of a reset
//! drives nothing). Written against the embedded-hal traits so the order and the "both, even
//! if one fails" rule are tested on the host (below, against mocks); `main.rs` calls it from the
//! panic handler and the HardFault handler through `board::force_motor_safe`, which implements
//! the traits on the bare registers (no peripheral ownership is needed from a fault context).

use embedded_hal::digital::OutputPin;
use embedded_hal::pwm::SetDutyCycle;

/// Drops `enable` and zeroes `pwm`, in that order; both are attempted whatever the other
/// returned. Returns whether both succeeded (a fault handler has no one to tell, and the
/// watchdog resets the MCU regardless).
pub fn make_motor_safe<E: OutputPin, P: SetDutyCycle>(enable: &mut E, pwm: &mut P) -> bool {
    let enable_low = enable.set_low().is_ok();
    let duty_zero = pwm.set_duty_cycle_fully_off().is_ok();
    enable_low && duty_zero
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::digital::{Mock as Pin, State, Transaction as PinTx};
    use embedded_hal_mock::eh1::pwm::{Mock as Pwm, Transaction as PwmTx};
    use embedded_hal_mock::eh1::MockError;
    use std::io::ErrorKind;

    #[test]
    fn enable_goes_low_and_the_duty_to_zero() {
        let mut en = Pin::new(&[PinTx::set(State::Low)]);
        let mut pwm = Pwm::new(&[PwmTx::set_duty_cycle(0)]);
        assert!(make_motor_safe(&mut en, &mut pwm));
        en.done();
        pwm.done();
    }

    /// A failed enable write must not skip the PWM (and the other way round).
    #[test]
    fn a_failing_write_does_not_skip_the_other() {
        let mut en = Pin::new(&[PinTx::set(State::Low).with_error(MockError::Io(ErrorKind::Other))]);
        let mut pwm = Pwm::new(&[PwmTx::set_duty_cycle(0)]);
        assert!(!make_motor_safe(&mut en, &mut pwm));
        en.done();
        pwm.done();

        let mut en = Pin::new(&[PinTx::set(State::Low)]);
        let mut pwm = Pwm::new(&[PwmTx::set_duty_cycle(0).with_error(MockError::Io(ErrorKind::Other))]);
        assert!(!make_motor_safe(&mut en, &mut pwm));
        en.done();
        pwm.done();
    }

    /// The enable drops before the PWM is touched: one pin and the PWM share a mock log here,
    /// recording the order in which they were written.
    #[test]
    fn the_enable_drops_first() {
        use std::cell::RefCell;
        struct Logged<'a>(&'a RefCell<Vec<&'static str>>);
        impl embedded_hal::digital::ErrorType for Logged<'_> {
            type Error = core::convert::Infallible;
        }
        impl OutputPin for Logged<'_> {
            fn set_low(&mut self) -> Result<(), Self::Error> {
                self.0.borrow_mut().push("enable low");
                Ok(())
            }
            fn set_high(&mut self) -> Result<(), Self::Error> {
                self.0.borrow_mut().push("enable high");
                Ok(())
            }
        }
        impl embedded_hal::pwm::ErrorType for Logged<'_> {
            type Error = core::convert::Infallible;
        }
        impl SetDutyCycle for Logged<'_> {
            fn max_duty_cycle(&self) -> u16 {
                crate::pwm::PWM_PERIOD_TICKS
            }
            fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Self::Error> {
                self.0.borrow_mut().push(if duty == 0 { "duty 0" } else { "duty >0" });
                Ok(())
            }
        }
        let log = RefCell::new(Vec::new());
        assert!(make_motor_safe(&mut Logged(&log), &mut Logged(&log)));
        assert_eq!(log.into_inner(), ["enable low", "duty 0"]);
    }
}
