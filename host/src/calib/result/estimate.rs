//! An estimated quantity with its uncertainty, so that every reported estimate carries its 1-σ
//! in one value rather than in a second field beside it. The unit stays in the name of the field
//! that holds it (`tilt_deg: Estimate`); how an estimate is printed is [`crate::calib::present`]'s.

use serde::{Deserialize, Serialize};

/// A value and its 1-σ standard uncertainty, both in the same unit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// The estimate.
    pub value: f64,
    /// Its 1-σ.
    pub sigma: f64,
}

impl Estimate {
    /// `value ± sigma`.
    pub const fn new(value: f64, sigma: f64) -> Self {
        Self { value, sigma }
    }

    /// `value` with σ = √variance (a variance rounded below 0 counts as 0).
    pub fn from_variance(value: f64, variance: f64) -> Self {
        Self::new(value, variance.max(0.0).sqrt())
    }

    /// In another unit, `factor` of it per unit of this one (3600 from °/s to °/h); σ scales
    /// by |factor|.
    pub fn scaled(self, factor: f64) -> Self {
        Self::new(self.value * factor, self.sigma * factor.abs())
    }

    /// With an independent uncertainty `sigma` added in quadrature (GUM 5.1.2, uncorrelated
    /// inputs): e.g. a Type B bound the fit knows nothing of.
    pub fn widened(self, sigma: f64) -> Self {
        Self::new(self.value, self.sigma.hypot(sigma))
    }

    /// How many σ the value lies above `reference`, (value − reference)/σ.
    pub fn z(self, reference: f64) -> f64 {
        (self.value - reference) / self.sigma
    }
}

/// The flat JSON form of estimates: calibration.json and loop.json are read by programs outside
/// the crate (`validation/check.py` reads `axes[i].s`, `k_counts_per_dps` and `k_sigma`; the
/// all-effects bench also `tilt_mount_sigma_deg`), so each report type that holds [`Estimate`]s
/// converts to and from a layout beside it (`#[serde(into, from)]`) that writes each estimate's
/// value and σ as two fields side by side, as they were before the type existed. The values.
pub(crate) fn values<const N: usize>(e: [Estimate; N]) -> [f64; N] {
    e.map(|e| e.value)
}

/// The σs of the flat JSON form ([`values`]).
pub(crate) fn sigmas<const N: usize>(e: [Estimate; N]) -> [f64; N] {
    e.map(|e| e.sigma)
}

/// Estimates from the flat JSON form's values and σs ([`values`]).
pub(crate) fn estimates<const N: usize>(value: [f64; N], sigma: [f64; N]) -> [Estimate; N] {
    std::array::from_fn(|i| Estimate::new(value[i], sigma[i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaling_widening_and_z() {
        let e = Estimate::new(2.0, 0.5);
        assert_eq!(e.scaled(-3.0), Estimate::new(-6.0, 1.5));
        assert!((e.widened(1.2).sigma - 1.3).abs() < 1e-15);
        assert_eq!(e.z(1.0), 2.0);
        assert_eq!(Estimate::from_variance(1.0, -1e-30).sigma, 0.0);
    }
}
