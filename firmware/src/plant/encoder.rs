//! The Canon R-ISO on the base table as TIM2 sees it in encoder mode: x4 quadrature decoding,
//! 324 000 counts/rev, a 32-bit counter that wraps.

use core::f64::consts::TAU;
use libm::floor;
use protocol::ENCODER_COUNTS_PER_REV;

/// Encoder and counter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Encoder {
    /// Counter value at θ1 = 0 (the counter starts wherever it was).
    pub offset_counts: u32,
    /// A and B swapped in the wiring: the count runs backwards.
    pub reversed: bool,
}

impl Encoder {
    /// Counter value at base-table angle `theta1_rad`: the count of the last quadrature edge
    /// passed.
    pub fn count(&self, theta1_rad: f64) -> u32 {
        let counts = floor(theta1_rad / TAU * f64::from(ENCODER_COUNTS_PER_REV)) as i64;
        let signed = if self.reversed { -counts } else { counts };
        self.offset_counts.wrapping_add(signed as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_turn_is_324000_counts_and_the_counter_wraps() {
        let e = Encoder { offset_counts: u32::MAX - 10, reversed: false };
        assert_eq!(e.count(0.0), u32::MAX - 10);
        assert_eq!(e.count(TAU).wrapping_sub(e.count(0.0)), 324_000);
        assert_eq!(e.count(-TAU / 324_000.0 * 0.5), u32::MAX - 11);
        let r = Encoder { reversed: true, ..e };
        assert_eq!(r.count(TAU).wrapping_sub(r.count(0.0)) as i32, -324_000);
    }
}
