//! On simulated data: how far a calibration lies from the truth, in degrees and ppm and in units
//! of its own reported uncertainty.

use super::derived::{mahalanobis2, AxisEstimate};
use crate::sim::Truth;
use serde::{Deserialize, Serialize};

/// Errors of one calibration against the simulated truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthErrors {
    /// Angle between estimated and true axis direction, degrees.
    pub direction_error_deg: [f64; 3],
    /// Mahalanobis distance of the two tilt components from the truth (the 2-D "σ").
    pub direction_z: [f64; 3],
    /// (k − k_true)/k_true, ppm.
    pub sensitivity_error_ppm: [f64; 3],
    /// (k − k_true)/σ_k.
    pub sensitivity_z: [f64; 3],
}

impl TruthErrors {
    /// Compares per-axis estimates with the truth.
    pub fn of(axes: &[AxisEstimate; 3], truth: &Truth) -> Self {
        let mut out = Self {
            direction_error_deg: [0.0; 3],
            direction_z: [0.0; 3],
            sensitivity_error_ppm: [0.0; 3],
            sensitivity_z: [0.0; 3],
        };
        for (i, a) in axes.iter().enumerate() {
            let s = truth.s[i];
            let dot: f64 = (0..3).map(|j| a.s[j] * s[j]).sum();
            out.direction_error_deg[i] = dot.clamp(-1.0, 1.0).acos().to_degrees();
            let (j, l) = ((i + 1) % 3, (i + 2) % 3);
            let truth_tilt = [s[j].atan2(s[i]).to_degrees(), s[l].atan2(s[i]).to_degrees()];
            let d = [a.tilt_components_deg[0] - truth_tilt[0], a.tilt_components_deg[1] - truth_tilt[1]];
            out.direction_z[i] = mahalanobis2(d, a.tilt_components_cov_deg2);
            let k = truth.k_counts_per_dps[i];
            out.sensitivity_error_ppm[i] = (a.k_counts_per_dps / k - 1.0) * 1e6;
            out.sensitivity_z[i] = (a.k_counts_per_dps - k) / a.k_sigma;
        }
        out
    }

    /// Largest direction error, degrees.
    pub fn max_direction_deg(&self) -> f64 {
        self.direction_error_deg.iter().fold(0.0, |m, &v| m.max(v))
    }

    /// Largest |sensitivity error|, ppm.
    pub fn max_sensitivity_ppm(&self) -> f64 {
        self.sensitivity_error_ppm.iter().fold(0.0, |m, &v| m.max(v.abs()))
    }

    /// Largest |z| of directions (2-D) and sensitivities.
    pub fn max_z(&self) -> f64 {
        self.direction_z.iter().chain(self.sensitivity_z.iter()).fold(0.0, |m, &v| m.max(v.abs()))
    }
}
