//! Every pin of the rig on the STM32F4DISCOVERY (STM32F407VGT6), and the H-bridge.
//! The wiring table in `firmware/README.md` mirrors this module.
//!
//! | Signal                    | Pin  | Function                  |
//! |---------------------------|------|---------------------------|
//! | Motor PWM                 | PE9  | TIM1_CH1 (AF1), 20 kHz    |
//! | Motor DIR                 | PE10 | GPIO out                  |
//! | Motor EN                  | PE11 | GPIO out, 10 kΩ pull-down |
//! | Encoder A / B             | PA15 / PB3 | TIM2_CH1 / CH2 (AF1), encoder mode |
//! | Index → encoder count     | PB10 | TIM2_CH3 (AF1), both edges, 12 µs filter |
//! | Index → timestamp         | PA2  | TIM5_CH3 (AF2), both edges, 12 µs filter |
//! | DRDY → encoder count      | PB11 | TIM2_CH4 (AF1), rising    |
//! | DRDY → timestamp + IRQ    | PA3  | TIM5_CH4 (AF2), rising    |
//! | Gyro SCK / MISO / MOSI    | PA5 / PA6 / PA7 | SPI1 (AF5), mode 3 |
//! | Gyro CS                   | PE7  | GPIO out                  |
//! | On-board LIS3DSH CS       | PE3  | held high (shares SPI1)   |
//! | USB D− / D+               | PA11 / PA12 | OTG_FS (AF10)      |

use crate::pac;
use firmware::pwm::{MotorCommand, PWM_PERIOD_TICKS};
use stm32f4xx_hal::gpio::{Output, PE10, PE11};
use stm32f4xx_hal::pac::TIM1;
use stm32f4xx_hal::timer::PwmChannel;

/// SPI1 clock for the gyro: 84 MHz APB2 / 16. The L3G4200D allows 10 MHz (datasheet Table 7);
/// the next divider up, /8 = 10.5 MHz, would exceed it.
pub const GYRO_SPI_HZ: u32 = 5_250_000;

/// Input-capture digital filter for the encoder and data-ready channels, CCMRx ICxF: 8 samples
/// at f_CK_INT, 95 ns ([`firmware::input_filter::CAPTURE_ICF`], tested there).
pub const CAPTURE_FILTER: u8 = firmware::input_filter::CAPTURE_ICF;

/// Input-capture filter of the index channels (CH3 of TIM2 and TIM5), CCMR2 IC3F: 8 samples at
/// f_DTS/32 with CR1.CKD = ÷4, 12.2 µs ([`firmware::input_filter::INDEX_ICF`]). CKD only slows
/// the ICxF ≥ 0b0100 filters; the encoder and data-ready channels stay at 95 ns.
pub const INDEX_FILTER: u8 = firmware::input_filter::INDEX_ICF;

/// Level of the data-ready input (PA3): high while the gyro holds an unread sample.
pub fn drdy_level() -> bool {
    // SAFETY: a read of GPIOA.IDR, which has no side effects and is not written by anyone.
    unsafe { (*pac::GPIOA::ptr()).idr().read().idr(3).bit_is_set() }
}

/// Makes the motor safe without owning the peripherals, from any context (the panic handler,
/// HardFault): [`firmware::safe_state::make_motor_safe`] on the bare registers (bridge enable
/// PE11, nSLEEP, low; TIM1 compare 0), then TIM1's main output off. The motor then coasts; the
/// watchdog resets the MCU 34-94 ms later and the EN pull-down holds the bridge off through the
/// reset.
pub fn force_motor_safe() {
    firmware::safe_state::make_motor_safe(&mut RawEnable, &mut RawPwm);
    // SAFETY: TIM1's BDTR is written only by the PWM channel, whose owner is no longer running.
    unsafe { (*pac::TIM1::ptr()).bdtr().modify(|_, w| w.moe().clear_bit()) };
}

/// A trip outside the control task (the data-ready interrupt): the bridge disabled and the duty
/// at 0 now, through the same two writes as [`force_motor_safe`] but with TIM1's main output
/// left on, so the next `Start` drives again. The control task applies the same OFF at its next
/// tick.
pub fn cut_drive() {
    firmware::safe_state::make_motor_safe(&mut RawEnable, &mut RawPwm);
}

/// The bridge enable (PE11) through GPIOE's BSRR, without owning the pin.
struct RawEnable;

impl embedded_hal::digital::ErrorType for RawEnable {
    type Error = core::convert::Infallible;
}

impl embedded_hal::digital::OutputPin for RawEnable {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        // SAFETY: BSRR is a write-only set/reset register: one atomic write touches PE11 only.
        unsafe { (*pac::GPIOE::ptr()).bsrr().write(|w| w.br(11).set_bit()) };
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Self::Error> {
        // SAFETY: as `set_low`.
        unsafe { (*pac::GPIOE::ptr()).bsrr().write(|w| w.bs(11).set_bit()) };
        Ok(())
    }
}

/// TIM1 channel 1's compare register, without owning the timer.
struct RawPwm;

impl embedded_hal::pwm::ErrorType for RawPwm {
    type Error = core::convert::Infallible;
}

impl embedded_hal::pwm::SetDutyCycle for RawPwm {
    fn max_duty_cycle(&self) -> u16 {
        PWM_PERIOD_TICKS
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Self::Error> {
        // SAFETY: CCR1 is written only by the PWM channel, whose owner is no longer running.
        unsafe { (*pac::TIM1::ptr()).ccr1().write(|w| w.ccr().set(duty.min(PWM_PERIOD_TICKS))) };
        Ok(())
    }
}

/// The H-bridge (e.g. TI DRV8874 in PH/EN mode: PWM on EN, DIR on PH, EN on nSLEEP). Its
/// nSLEEP has a pull-down, so the bridge is off from reset until firmware drives it.
pub struct Motor {
    /// PWM output.
    pub pwm: PwmChannel<TIM1, 0>,
    /// Direction.
    pub dir: PE10<Output>,
    /// Enable.
    pub en: PE11<Output>,
}

impl Motor {
    /// Applies one loop period's command.
    pub fn apply(&mut self, cmd: MotorCommand) {
        if cmd.enable {
            self.dir.set_state(cmd.reverse.into());
            self.pwm.set_duty(cmd.compare.min(PWM_PERIOD_TICKS));
            self.en.set_high();
        } else {
            firmware::safe_state::make_motor_safe(&mut self.en, &mut self.pwm);
        }
    }
}

/// Level of the index input (PA2) after an edge: beam blocked = high. Read through IDR, which
/// samples the pin in alternate-function mode too.
pub fn index_level() -> bool {
    // SAFETY: a read of GPIOA.IDR, which has no side effects and is not written by anyone.
    unsafe { (*pac::GPIOA::ptr()).idr().read().idr(2).bit_is_set() }
}
