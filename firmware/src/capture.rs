//! The two 32-bit timers that make every timestamp and every encoder count hardware-exact.
//!
//! TIM2 counts the encoder in x4 quadrature mode (324 000 counts/rev) and, on its spare
//! channels, latches the count at the index (CH3) and data-ready (CH4) edges. TIM5 runs at
//! 1 MHz and latches the time of the same two edges (CH3, CH4). Each signal is wired to one pin
//! of each timer, because a pin reaches only one timer. The capture interrupt of TIM5 is the
//! only interrupt these signals raise; interrupt latency affects neither value.

use crate::board::{CAPTURE_FILTER, INDEX_FILTER};

// The filter durations of `firmware::input_filter` assume the CKD this module writes.
const _: () = assert!(firmware::input_filter::CKD_DIVIDER == 4, "capture.rs writes CR1.CKD = ÷4");
use stm32f4xx_hal::pac::{TIM2, TIM5};

/// One captured edge.
#[derive(Clone, Copy)]
pub struct Capture {
    /// TIM5 at the edge, µs.
    pub t_us: u32,
    /// TIM2 at the edge, encoder counts.
    pub encoder: u32,
    /// The capture register was overwritten before this read (CCxOF).
    pub overcaptured: bool,
}

/// Owner of TIM2 and TIM5 after setup.
pub struct Captures {
    tim2: TIM2,
    tim5: TIM5,
}

/// Read-only view of the free-running counters, for the control loop.
#[derive(Clone, Copy)]
pub struct Counters(());

impl Counters {
    /// TIM5 now, µs.
    pub fn now_us(&self) -> u32 {
        // SAFETY: CNT reads have no side effects; after `Captures::new` nothing writes CNT.
        unsafe { (*TIM5::ptr()).cnt().read().bits() }
    }

    /// TIM2 now, encoder counts.
    pub fn encoder(&self) -> u32 {
        // SAFETY: as above.
        unsafe { (*TIM2::ptr()).cnt().read().bits() }
    }
}

impl Captures {
    /// Configures and starts both timers (clocks must be enabled); `timclk1_hz` is the APB1
    /// timer clock.
    pub fn new(tim2: TIM2, tim5: TIM5, timclk1_hz: u32) -> (Self, Counters) {
        // TIM2: encoder mode 3 (count on both edges of both inputs), TI1/TI2 filtered.
        tim2.ccmr1_input().write(|w| {
            w.cc1s().ti1();
            w.cc2s().ti2();
            w.ic1f().set(CAPTURE_FILTER);
            w.ic2f().set(CAPTURE_FILTER)
        });
        tim2.smcr().write(|w| w.sms().encoder_mode_3());
        tim2.ccmr2_input().write(|w| {
            w.cc3s().ti3();
            w.cc4s().ti4();
            w.ic3f().set(INDEX_FILTER);
            w.ic4f().set(CAPTURE_FILTER)
        });
        // CH3 both edges (CC3P = CC3NP = 1), CH4 rising.
        tim2.ccer().write(|w| {
            w.cc3e().set_bit();
            w.cc3p().set_bit();
            w.cc3np().set_bit();
            w.cc4e().set_bit()
        });
        tim2.arr().write(|w| w.arr().set(u32::MAX));
        // CKD ÷4: f_DTS = 21 MHz for the index filter (board::INDEX_FILTER), as on TIM5
        // (input_filter::CKD_DIVIDER, asserted below).
        tim2.cr1().write(|w| {
            w.ckd().div4();
            w.cen().set_bit()
        });

        // TIM5: 1 MHz free-running, the same captures for time.
        tim5.psc().write(|w| w.psc().set((timclk1_hz / protocol::TIMESTAMP_HZ - 1) as u16));
        tim5.arr().write(|w| w.arr().set(u32::MAX));
        tim5.egr().write(|w| w.ug().set_bit()); // load the prescaler now
        tim5.sr().write(|w| w.uif().clear_bit());
        tim5.ccmr2_input().write(|w| {
            w.cc3s().ti3();
            w.cc4s().ti4();
            w.ic3f().set(INDEX_FILTER);
            w.ic4f().set(CAPTURE_FILTER)
        });
        tim5.ccer().write(|w| {
            w.cc3e().set_bit();
            w.cc3p().set_bit();
            w.cc3np().set_bit();
            w.cc4e().set_bit()
        });
        tim5.dier().write(|w| {
            w.cc3ie().set_bit();
            w.cc4ie().set_bit()
        });
        tim5.cr1().write(|w| {
            w.ckd().div4();
            w.cen().set_bit()
        });
        (Self { tim2, tim5 }, Counters(()))
    }

    /// A pending data-ready capture (reading CCR4 clears CC4IF).
    pub fn data_ready(&mut self) -> Option<Capture> {
        let sr = self.tim5.sr().read();
        if !sr.cc4if().bit_is_set() {
            return None;
        }
        let overcaptured = sr.cc4of().bit_is_set();
        if overcaptured {
            self.tim5.sr().write(|w| unsafe { w.bits(!0) }.cc4of().clear_bit());
        }
        Some(Capture { t_us: self.tim5.ccr4().read().bits(), encoder: self.tim2.ccr4().read().bits(), overcaptured })
    }

    /// A pending index capture (reading CCR3 clears CC3IF).
    pub fn index(&mut self) -> Option<Capture> {
        let sr = self.tim5.sr().read();
        if !sr.cc3if().bit_is_set() {
            return None;
        }
        let overcaptured = sr.cc3of().bit_is_set();
        if overcaptured {
            self.tim5.sr().write(|w| unsafe { w.bits(!0) }.cc3of().clear_bit());
        }
        Some(Capture { t_us: self.tim5.ccr3().read().bits(), encoder: self.tim2.ccr3().read().bits(), overcaptured })
    }
}
