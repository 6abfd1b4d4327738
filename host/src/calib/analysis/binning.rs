//! Equal-width bins indexed by a multiplication, giving exactly the bin the division gives.
//!
//! The diagnostics put every sample into five kinds of bin (θ2 twice, time, three axis rates):
//! six divisions and a `fmod` per sample, 3 % of a 1-h replay. A multiplication by the
//! reciprocal lands in a different bin than the division only when the quotient is within a few
//! ulp of a bin edge, so [`Binning::index`] multiplies, and divides as before only when the
//! product is within [`EDGE_BINS`] of an edge. The bins, and every sum built on them, are the
//! same bits as with the division.

use std::f64::consts::TAU;

/// How close to a bin edge, in bins, a product must be for the division to decide. The
/// multiplication's quotient and the division's each differ from the exact one by a few ulp of
/// the quotient, ≤ 1e-12 bins for the ≤ 10⁴ bins used here; the angle's reduction by whole turns
/// adds |turns|·2⁻⁵² of a turn, ≤ 2⁻²³ bins for [`MAX_FAST_TURNS`] and 8192 bins a turn.
const EDGE_BINS: f64 = 1e-6;

/// Largest |θ|/2π reduced by the multiplication; beyond, `rem_euclid` reduces it as before.
const MAX_FAST_TURNS: f64 = 65_536.0;

/// Equal bins from 0: x falls in ⌊x/range·n⌋, as `(x / range * n) as usize`, clamped to the last.
#[derive(Debug, Clone, Copy)]
pub struct Binning {
    range: f64,
    n: f64,
    per_unit: f64,
    last: usize,
}

impl Binning {
    /// `n` bins over [0, `range`).
    pub fn new(range: f64, n: usize) -> Self {
        Self { range, n: n as f64, per_unit: n as f64 / range, last: n.saturating_sub(1) }
    }

    /// `count` bins `width` wide from 0: x falls in ⌊x/width⌋, as `(x / width) as usize`.
    pub fn of_width(width: f64, count: usize) -> Self {
        Self { last: count.saturating_sub(1), ..Self::new(width, 1) }
    }

    /// The bin of `x` ≥ 0, `(x / range * n) as usize` clamped to the last bin; NaN is bin 0.
    #[inline]
    pub fn index(&self, x: f64) -> usize {
        self.clear_of_edges(x * self.per_unit).unwrap_or_else(|| self.divided(x))
    }

    /// The bin of θ reduced to [0, 2π), for a binning of [0, 2π): `index(θ.rem_euclid(2π))`
    /// without its `fmod` call.
    #[inline]
    pub fn angle_index(&self, theta_rad: f64) -> usize {
        debug_assert_eq!(self.range, TAU);
        let turns = theta_rad * (1.0 / TAU);
        if turns.abs() < MAX_FAST_TURNS {
            // Exact: |turns| < 2^16, so the integer part takes ≤ 16 of its 53 bits.
            let frac = turns - (turns as i64) as f64;
            let frac = if frac < 0.0 { frac + 1.0 } else { frac };
            if let Some(k) = self.clear_of_edges(frac * self.n) {
                return k;
            }
        }
        self.divided(theta_rad.rem_euclid(TAU))
    }

    /// `(self.angle_index(θ), other.angle_index(θ))`, the turn's fraction taken once for both
    /// (the diagnostics' walk bins every sample's θ2 twice).
    #[inline]
    pub fn angle_indices(&self, other: &Binning, theta_rad: f64) -> (usize, usize) {
        debug_assert!(self.range == TAU && other.range == TAU);
        let turns = theta_rad * (1.0 / TAU);
        if turns.abs() < MAX_FAST_TURNS {
            let frac = turns - (turns as i64) as f64;
            let frac = if frac < 0.0 { frac + 1.0 } else { frac };
            if let (Some(i), Some(j)) = (self.clear_of_edges(frac * self.n), other.clear_of_edges(frac * other.n)) {
                return (i, j);
            }
        }
        (self.angle_index(theta_rad), other.angle_index(theta_rad))
    }

    /// ⌊q⌋ clamped to the last bin, when q is more than [`EDGE_BINS`] from an edge.
    #[inline]
    fn clear_of_edges(&self, q: f64) -> Option<usize> {
        let k = q as i64;
        let frac = q - k as f64;
        (frac > EDGE_BINS && frac < 1.0 - EDGE_BINS).then_some((k as usize).min(self.last))
    }

    #[cold]
    fn divided(&self, x: f64) -> usize {
        ((x / self.range * self.n) as usize).min(self.last)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quotients on and next to every edge, and a spread of values, land where the division
    /// puts them.
    #[test]
    fn agrees_with_the_division_at_and_beside_every_edge() {
        for (range, n) in [(TAU, 360), (TAU, 8192), (1234.567, 8), (0.3, 7)] {
            let b = Binning::new(range, n);
            for k in 0..=n {
                let edge = k as f64 * range / n as f64;
                let mut x = edge;
                for _ in 0..4 {
                    x = x.next_down();
                }
                for _ in 0..9 {
                    if x >= 0.0 {
                        assert_eq!(b.index(x), ((x / range * n as f64) as usize).min(n - 1), "{x} of {range}/{n}");
                    }
                    x = x.next_up();
                }
            }
            for i in 0..100_000 {
                let x = i as f64 * 0.618_033_988_75 * range / 1000.0;
                assert_eq!(b.index(x), ((x / range * n as f64) as usize).min(n - 1), "{x} of {range}/{n}");
            }
            assert_eq!(b.index(f64::NAN), 0);
        }
    }

    /// Bins of a width: those of the division, up to the last.
    #[test]
    fn bins_of_a_width_agree_with_the_division() {
        let b = Binning::of_width(10.0, 1440);
        for k in 0..1500 {
            let mut x = k as f64 * 10.0;
            for _ in 0..4 {
                x = x.next_down();
            }
            for _ in 0..9 {
                if x >= 0.0 {
                    assert_eq!(b.index(x), ((x / 10.0) as usize).min(1439), "{x}");
                }
                x = x.next_up();
            }
        }
        for i in 0..100_000 {
            let x = i as f64 * 0.144_001_7;
            assert_eq!(b.index(x), ((x / 10.0) as usize).min(1439), "{x}");
        }
    }

    /// Two binnings' indices taken together are each one's own.
    #[test]
    fn a_pair_of_angle_binnings_agrees_with_each_alone() {
        let (a, b) = (Binning::new(TAU, 360), Binning::new(TAU, 8192));
        for turns in [-70_000i64, -1, 0, 3, 65_535, 70_000] {
            for k in 0..20_000 {
                let th = (turns as f64 + k as f64 / 20_000.0) * TAU;
                for th in [th.next_down(), th, th.next_up()] {
                    assert_eq!(a.angle_indices(&b, th), (a.angle_index(th), b.angle_index(th)), "{th}");
                }
            }
        }
    }

    /// Angles of many turns, either sign, on and beside every edge of every turn tried, and beyond
    /// the multiplication's range: the bin of `rem_euclid`.
    #[test]
    fn angles_land_in_the_bin_of_their_reduction() {
        for n in [360, 8192] {
            let b = Binning::new(TAU, n);
            let want = |th: f64| ((th.rem_euclid(TAU) / TAU * n as f64) as usize).min(n - 1);
            for turns in [-70_000i64, -3, -1, 0, 1, 2, 1000, 29_000, 65_535, 70_000] {
                for k in (0..n).step_by(97).chain([n - 1]) {
                    let mut th = (turns as f64 + k as f64 / n as f64) * TAU;
                    for _ in 0..4 {
                        th = th.next_down();
                    }
                    for _ in 0..9 {
                        assert_eq!(b.angle_index(th), want(th), "{th} rad, {n} bins");
                        th = th.next_up();
                    }
                }
            }
            for i in 0..200_000 {
                let th = (i as f64 - 50_000.0) * 0.917_356_118_3;
                assert_eq!(b.angle_index(th), want(th), "{th} rad, {n} bins");
            }
        }
    }
}
