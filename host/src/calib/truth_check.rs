//! On simulated data: how far a calibration lies from the truth, in degrees and ppm and in units
//! of its own reported uncertainty.

use super::derived::{mahalanobis2, AxisEstimate};
use super::report::CalReport;
use crate::sim::Truth;
use nalgebra::{Matrix3, Vector3};
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
    /// Direction errors after removing the rotation common to all three axes that best maps the
    /// true axes onto the estimated ones (Kabsch): the intrinsic part, which the runs determine.
    #[serde(default)]
    pub intrinsic_direction_error_deg: [f64; 3],
    /// That common rotation, degrees: the extrinsic part, which only the mount bounds (a turn of
    /// the package in its fixture common to both poses moves all three axes alike, unseen).
    #[serde(default)]
    pub common_rotation_deg: f64,
}

/// The rotation R (as a matrix) minimising Σ|est_i − R·truth_i|² over the three axes (Kabsch,
/// Acta Cryst. A32, 922, 1976): from the SVD of Σ est_i·truth_iᵀ, with the sign fixed so R is
/// proper.
fn common_rotation(est: &[[f64; 3]; 3], truth: &[[f64; 3]; 3]) -> Matrix3<f64> {
    let h = (0..3).fold(Matrix3::zeros(), |acc, i| acc + Vector3::from(est[i]) * Vector3::from(truth[i]).transpose());
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let d = (u * v_t).determinant().signum();
    u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t
}

impl TruthErrors {
    /// Compares per-axis estimates with the truth.
    pub fn of(axes: &[AxisEstimate; 3], truth: &Truth) -> Self {
        let mut out = Self {
            direction_error_deg: [0.0; 3],
            direction_z: [0.0; 3],
            sensitivity_error_ppm: [0.0; 3],
            sensitivity_z: [0.0; 3],
            intrinsic_direction_error_deg: [0.0; 3],
            common_rotation_deg: 0.0,
        };
        let est: [[f64; 3]; 3] = std::array::from_fn(|i| axes[i].s.map(|c| c.value));
        let r = common_rotation(&est, &truth.s);
        out.common_rotation_deg = ((r.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees();
        for ((err, e), t) in out.intrinsic_direction_error_deg.iter_mut().zip(&est).zip(&truth.s) {
            let cos = Vector3::from(*e).normalize().dot(&(r * Vector3::from(*t)).normalize());
            *err = cos.clamp(-1.0, 1.0).acos().to_degrees();
        }
        for (i, a) in axes.iter().enumerate() {
            let s = truth.s[i];
            let dot: f64 = (0..3).map(|j| a.s[j].value * s[j]).sum();
            out.direction_error_deg[i] = dot.clamp(-1.0, 1.0).acos().to_degrees();
            let (j, l) = ((i + 1) % 3, (i + 2) % 3);
            let truth_tilt = [s[j].atan2(s[i]).to_degrees(), s[l].atan2(s[i]).to_degrees()];
            let d = [a.tilt_components_deg[0] - truth_tilt[0], a.tilt_components_deg[1] - truth_tilt[1]];
            out.direction_z[i] = mahalanobis2(d, a.tilt_components_cov_deg2);
            let k = truth.k_counts_per_dps[i];
            out.sensitivity_error_ppm[i] = (a.k_counts_per_dps.value / k - 1.0) * 1e6;
            out.sensitivity_z[i] = a.k_counts_per_dps.z(k);
        }
        out
    }

    /// Largest direction error, degrees.
    pub fn max_direction_deg(&self) -> f64 {
        self.direction_error_deg.iter().fold(0.0, |m, &v| m.max(v))
    }

    /// Largest direction error after removing the common rotation, degrees.
    pub fn max_intrinsic_direction_deg(&self) -> f64 {
        self.intrinsic_direction_error_deg.iter().fold(0.0, |m, &v| m.max(v))
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

/// Every |z| of a calibration against a true M (counts per °/s, rows = axes), as
/// `../shared/validation/check.py` reckons them: per axis, the sensitivity against its σ, each
/// element of its row of M against √ of its variance in `cov`, and its direction as a 2-dof
/// distance (the tilt components' Mahalanobis distance, as in [`TruthErrors`]): 21 values, axis
/// by axis. A value that is not a number (a σ of 0 or NaN, a covariance that is not one) is +∞:
/// a calibration that cannot say how far off it is, is off.
pub fn z_against_m(report: &CalReport, m_true: &[[f64; 3]; 3]) -> Vec<f64> {
    let mut z = Vec::with_capacity(21);
    for (i, a) in report.axes.iter().enumerate() {
        let row = m_true[i];
        let k = row.iter().map(|v| v * v).sum::<f64>().sqrt();
        let s = row.map(|v| v / k);
        z.push(a.k_counts_per_dps.z(k).abs());
        for (j, &t) in row.iter().enumerate() {
            let p = 4 * i + j;
            z.push(((report.m_counts_per_dps[i][j] - t) / report.cov[p][p].sqrt()).abs());
        }
        let (j, l) = ((i + 1) % 3, (i + 2) % 3);
        let truth_tilt = [s[j].atan2(s[i]).to_degrees(), s[l].atan2(s[i]).to_degrees()];
        let d = [a.tilt_components_deg[0] - truth_tilt[0], a.tilt_components_deg[1] - truth_tilt[1]];
        let c = a.tilt_components_cov_deg2;
        // A 2×2 covariance that is not positive definite gives no distance (check.py's too).
        let pd = c[0][0] > 0.0 && c[0][0] * c[1][1] - c[0][1] * c[1][0] > 0.0;
        let finite = d.iter().chain(c.iter().flatten()).all(|v| v.is_finite());
        z.push(if pd && finite { mahalanobis2(d, c) } else { f64::INFINITY });
    }
    z.into_iter().map(|v| if v.is_nan() { f64::INFINITY } else { v }).collect()
}

/// The largest of [`z_against_m`].
pub fn max_z_against_m(report: &CalReport, m_true: &[[f64; 3]; 3]) -> f64 {
    z_against_m(report, m_true).into_iter().fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};

    /// Axes turned together by 0.05° about a skew axis, and one of them alone by 0.001° more:
    /// the common rotation is the 0.05° (to the 0.001°'s share), the intrinsic error is left on
    /// the axis that moved alone, and neither depends on which frame the truth is in.
    #[test]
    fn common_rotation_separates_the_mount_from_the_axes() {
        let truth = [[0.9998, 0.017, 0.009], [-0.015, 0.9999, -0.004], [-0.009, -0.03, 0.9995]]
            .map(|r| Vector3::from(r).normalize().into());
        let turn = Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::new(1.0, 2.0, -0.5)), 0.05f64.to_radians());
        let nudge = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.001f64.to_radians());
        let est: [[f64; 3]; 3] = std::array::from_fn(|i| {
            let v = turn * Vector3::from(truth[i]);
            (if i == 0 { nudge * v } else { v }).into()
        });
        let r = common_rotation(&est, &truth);
        let angle = ((r.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees();
        assert!((angle - 0.05).abs() < 0.001, "{angle}");
        let raw: f64 = Vector3::from(est[1]).dot(&Vector3::from(truth[1])).clamp(-1.0, 1.0).acos().to_degrees();
        assert!(raw > 0.02, "the raw error holds the turn: {raw}");
        for i in 1..3 {
            let left = Vector3::from(est[i]).dot(&(r * Vector3::from(truth[i]))).clamp(-1.0, 1.0).acos().to_degrees();
            assert!(left < 0.001, "axis {i}: {left}");
        }
        assert!((common_rotation(&truth, &truth) - Matrix3::identity()).abs().max() < 1e-12);
    }
}
