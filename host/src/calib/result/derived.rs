//! What engineers read off M = K S: sensitivities, axis directions, their tilts from the package
//! axes and the angles between them, each with a 1-σ from the covariance of M by the delta
//! method (first-order propagation through a numerical Jacobian).

use crate::calib::result::axes::AXES;
use crate::calib::result::estimate::Estimate;
use crate::calib::result::estimate::{estimates, sigmas, values};
use nalgebra::{DMatrix, DVector, Vector3};
use serde::{Deserialize, Serialize};

/// Central-difference step, in units of each input's σ: small enough that the curvature of the
/// functions here (angles, norms, of relative scale ≫ σ) adds < 1e-8 relative error, large
/// enough to stay clear of rounding.
const STEP_SIGMAS: f64 = 1e-3;

/// First-order propagation of `cov` through `f` at `x`: returns f(x) and J·cov·Jᵀ.
pub fn delta_method(f: impl Fn(&[f64]) -> Vec<f64>, x: &[f64], cov: &DMatrix<f64>) -> (Vec<f64>, DMatrix<f64>) {
    let y = f(x);
    let mut jac = DMatrix::zeros(y.len(), x.len());
    let mut xp = x.to_vec();
    for j in 0..x.len() {
        let sd = cov[(j, j)].max(0.0).sqrt();
        if sd == 0.0 {
            continue;
        }
        let h = STEP_SIGMAS * sd;
        xp[j] = x[j] + h;
        let up = f(&xp);
        xp[j] = x[j] - h;
        let down = f(&xp);
        xp[j] = x[j];
        for i in 0..y.len() {
            jac[(i, j)] = (up[i] - down[i]) / (2.0 * h);
        }
    }
    let out = &jac * cov * jac.transpose();
    (y, out)
}

/// How closely the rig's pose fixtures hold the package, degrees (± bound): a machined 90° angle
/// block holds it to ~0.1°, the size issue 10 gives for the fixtures of such a rig (and the
/// simulator's `pose_fixture` default). The runs see the package only through the fixture, so a
/// rotation of it common to both poses turns all three axes alike and no run reveals it: it
/// limits the tilts from the package axes (extrinsic), not the angles between the real axes
/// (intrinsic).
pub const MOUNT_TOLERANCE_DEG: f64 = 0.1;

/// 1-σ of one tilt component from the mount alone: [`MOUNT_TOLERANCE_DEG`] as a uniform bound
/// (GUM 4.3.7, Type B: bound/√3). A small rotation φ of the package moves each tilt component by
/// one component of φ.
pub fn mount_sigma_deg() -> f64 {
    MOUNT_TOLERANCE_DEG / 3f64.sqrt()
}

/// One axis's calibration, from row i of M and offset i.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(into = "AxisEstimateJson", from = "AxisEstimateJson")]
pub struct AxisEstimate {
    /// Axis name.
    pub axis: char,
    /// Sensitivity k_i = |m_i|, counts per °/s.
    pub k_counts_per_dps: Estimate,
    /// k relative to the datasheet sensitivity of the full scale in use, percent.
    pub k_vs_nominal_percent: f64,
    /// Direction s_i (unit vector, package frame), per component.
    pub s: [Estimate; 3],
    /// Offset, counts.
    pub offset_counts: Estimate,
    /// Angle between s_i and the package axis e_i, degrees, with the runs' σ alone
    /// ([`Self::tilt_extrinsic_deg`] adds the mount's). Its σ is first-order, valid for tilts
    /// well above it; `tilt_components_deg` are well-behaved at any size.
    pub tilt_deg: Estimate,
    /// The package axes toward which the two tilt components lean.
    pub tilt_component_axes: [char; 2],
    /// Tilt of s_i toward each of those axes, atan2(s_j, s_i), degrees.
    pub tilt_components_deg: [f64; 2],
    /// 2×2 covariance of the tilt components, degrees², from the runs (intrinsic to the fit).
    pub tilt_components_cov_deg2: [[f64; 2]; 2],
    /// 1-σ the mount adds to the tilt and to each tilt component ([`mount_sigma_deg`]): the
    /// extrinsic angles' uncertainty is this and the runs' σ together.
    pub tilt_mount_sigma_deg: f64,
}

impl AxisEstimate {
    /// The tilt from the package axis with the runs' and the mount's σ together.
    pub fn tilt_extrinsic_deg(&self) -> Estimate {
        self.tilt_deg.widened(self.tilt_mount_sigma_deg)
    }
}

/// The angle between two real axes (intrinsic: the mount does not limit it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(into = "InterAxisAngleJson", from = "InterAxisAngleJson")]
pub struct InterAxisAngle {
    /// The two axes, e.g. ['x', 'y'].
    pub axes: [char; 2],
    /// Angle between s_a and s_b, degrees.
    pub angle_deg: Estimate,
    /// angle − 90°, degrees (σ as the angle's).
    pub non_orthogonality_deg: f64,
}

/// Axis pairs in report order.
const PAIRS: [(usize, usize); 3] = [(0, 1), (1, 2), (0, 2)];

/// Derived values from the 12 parameters [m_x, b_x, m_y, b_y, m_z, b_z] (axis-major, each m a
/// row of M): per axis k, s (3), offset, tilt, two tilt components (8); then 3 inter-axis angles.
fn derived_vector(p: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(27);
    let rows: Vec<Vector3<f64>> = (0..3).map(|i| Vector3::new(p[4 * i], p[4 * i + 1], p[4 * i + 2])).collect();
    for (i, m) in rows.iter().enumerate() {
        let k = m.norm();
        let s = m / k;
        let (j, l) = ((i + 1) % 3, (i + 2) % 3);
        let perp = (s[j] * s[j] + s[l] * s[l]).sqrt();
        out.extend_from_slice(&[k, s.x, s.y, s.z, p[4 * i + 3]]);
        out.push(perp.atan2(s[i]).to_degrees());
        out.push(s[j].atan2(s[i]).to_degrees());
        out.push(s[l].atan2(s[i]).to_degrees());
    }
    for (a, b) in PAIRS {
        let c = rows[a].dot(&rows[b]) / (rows[a].norm() * rows[b].norm());
        out.push(c.clamp(-1.0, 1.0).acos().to_degrees());
    }
    out
}

/// Per-axis estimates and inter-axis angles from the parameters and their covariance.
/// `nominal_counts_per_dps` is the datasheet sensitivity.
pub fn derive(
    params: &[f64; 12],
    cov: &DMatrix<f64>,
    nominal_counts_per_dps: f64,
) -> ([AxisEstimate; 3], [InterAxisAngle; 3]) {
    let (y, c) = delta_method(derived_vector, params, cov);
    let est = |i: usize| Estimate::from_variance(y[i], c[(i, i)]);
    let axes = std::array::from_fn(|i| {
        let o = 8 * i;
        AxisEstimate {
            axis: AXES[i],
            k_counts_per_dps: est(o),
            k_vs_nominal_percent: (y[o] / nominal_counts_per_dps - 1.0) * 100.0,
            s: [est(o + 1), est(o + 2), est(o + 3)],
            offset_counts: est(o + 4),
            tilt_deg: est(o + 5),
            tilt_component_axes: [AXES[(i + 1) % 3], AXES[(i + 2) % 3]],
            tilt_components_deg: [y[o + 6], y[o + 7]],
            tilt_components_cov_deg2: [[c[(o + 6, o + 6)], c[(o + 6, o + 7)]], [c[(o + 7, o + 6)], c[(o + 7, o + 7)]]],
            tilt_mount_sigma_deg: mount_sigma_deg(),
        }
    });
    let angles = std::array::from_fn(|n| {
        let (a, b) = PAIRS[n];
        InterAxisAngle { axes: [AXES[a], AXES[b]], angle_deg: est(24 + n), non_orthogonality_deg: y[24 + n] - 90.0 }
    });
    (axes, angles)
}

/// Mahalanobis distance of a 2-vector difference under a 2×2 covariance.
pub fn mahalanobis2(d: [f64; 2], cov: [[f64; 2]; 2]) -> f64 {
    let c = nalgebra::Matrix2::new(cov[0][0], cov[0][1], cov[1][0], cov[1][1]);
    match c.try_inverse() {
        Some(ci) => {
            let v = nalgebra::Vector2::new(d[0], d[1]);
            (v.transpose() * ci * v)[(0, 0)].max(0.0).sqrt()
        }
        None => f64::INFINITY,
    }
}

/// Converts a fixed array to a column vector (helper for callers building covariances).
pub fn dvec(v: &[f64]) -> DVector<f64> {
    DVector::from_column_slice(v)
}

// The JSON layouts of this module's report types (see [`crate::calib::result::estimate::values`] for why).

#[derive(Serialize, Deserialize)]
pub struct AxisEstimateJson {
    axis: char,
    k_counts_per_dps: f64,
    k_sigma: f64,
    k_vs_nominal_percent: f64,
    s: [f64; 3],
    s_sigma: [f64; 3],
    offset_counts: f64,
    offset_sigma_counts: f64,
    tilt_deg: f64,
    tilt_sigma_deg: f64,
    tilt_component_axes: [char; 2],
    tilt_components_deg: [f64; 2],
    tilt_components_cov_deg2: [[f64; 2]; 2],
    /// Absent from files written before the mount's σ was reported.
    #[serde(default)]
    tilt_mount_sigma_deg: f64,
}

impl From<AxisEstimate> for AxisEstimateJson {
    fn from(a: AxisEstimate) -> Self {
        Self {
            axis: a.axis,
            k_counts_per_dps: a.k_counts_per_dps.value,
            k_sigma: a.k_counts_per_dps.sigma,
            k_vs_nominal_percent: a.k_vs_nominal_percent,
            s: values(a.s),
            s_sigma: sigmas(a.s),
            offset_counts: a.offset_counts.value,
            offset_sigma_counts: a.offset_counts.sigma,
            tilt_deg: a.tilt_deg.value,
            tilt_sigma_deg: a.tilt_deg.sigma,
            tilt_component_axes: a.tilt_component_axes,
            tilt_components_deg: a.tilt_components_deg,
            tilt_components_cov_deg2: a.tilt_components_cov_deg2,
            tilt_mount_sigma_deg: a.tilt_mount_sigma_deg,
        }
    }
}

impl From<AxisEstimateJson> for AxisEstimate {
    fn from(a: AxisEstimateJson) -> Self {
        Self {
            axis: a.axis,
            k_counts_per_dps: Estimate::new(a.k_counts_per_dps, a.k_sigma),
            k_vs_nominal_percent: a.k_vs_nominal_percent,
            s: estimates(a.s, a.s_sigma),
            offset_counts: Estimate::new(a.offset_counts, a.offset_sigma_counts),
            tilt_deg: Estimate::new(a.tilt_deg, a.tilt_sigma_deg),
            tilt_component_axes: a.tilt_component_axes,
            tilt_components_deg: a.tilt_components_deg,
            tilt_components_cov_deg2: a.tilt_components_cov_deg2,
            tilt_mount_sigma_deg: a.tilt_mount_sigma_deg,
        }
    }
}

#[derive(Serialize, Deserialize)]
pub struct InterAxisAngleJson {
    axes: [char; 2],
    angle_deg: f64,
    sigma_deg: f64,
    non_orthogonality_deg: f64,
}

impl From<InterAxisAngle> for InterAxisAngleJson {
    fn from(a: InterAxisAngle) -> Self {
        Self {
            axes: a.axes,
            angle_deg: a.angle_deg.value,
            sigma_deg: a.angle_deg.sigma,
            non_orthogonality_deg: a.non_orthogonality_deg,
        }
    }
}

impl From<InterAxisAngleJson> for InterAxisAngle {
    fn from(a: InterAxisAngleJson) -> Self {
        Self {
            axes: a.axes,
            angle_deg: Estimate::new(a.angle_deg, a.sigma_deg),
            non_orthogonality_deg: a.non_orthogonality_deg,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Linear maps propagate exactly: y = A x gives A C Aᵀ.
    #[test]
    fn delta_method_is_exact_for_linear_maps() {
        let a = DMatrix::from_row_slice(2, 3, &[1.0, 2.0, 0.0, -1.0, 0.5, 3.0]);
        let c = DMatrix::from_row_slice(3, 3, &[2.0, 0.3, 0.0, 0.3, 1.0, -0.2, 0.0, -0.2, 0.5]);
        let x = [0.4, -1.0, 2.0];
        let (_, out) = delta_method(|v| (&a * dvec(v)).iter().copied().collect(), &x, &c);
        let expect = &a * &c * a.transpose();
        assert!((out - expect).abs().max() < 1e-9);
    }

    /// A row of M along e_x tilted by 1° toward y: k is the norm and the tilt is 1°.
    #[test]
    fn derived_values_of_a_tilted_row() {
        let t = 1f64.to_radians();
        let mut p = [0.0; 12];
        p[..4].copy_from_slice(&[57.0 * t.cos(), 57.0 * t.sin(), 0.0, 5.0]);
        p[4..8].copy_from_slice(&[0.0, 57.0, 0.0, 0.0]);
        p[8..].copy_from_slice(&[0.0, 0.0, 57.0, 0.0]);
        let cov = DMatrix::identity(12, 12) * 1e-6;
        let (axes, angles) = derive(&p, &cov, 57.142_857);
        assert!((axes[0].k_counts_per_dps.value - 57.0).abs() < 1e-12);
        assert!((axes[0].tilt_deg.value - 1.0).abs() < 1e-9);
        assert!((axes[0].tilt_components_deg[0] - 1.0).abs() < 1e-9);
        assert!((angles[0].angle_deg.value - 89.0).abs() < 1e-9);
        // σ of k for isotropic σ² = 1e-6 on the row: exactly 1e-3.
        assert!((axes[0].k_counts_per_dps.sigma - 1e-3).abs() < 1e-9);
        // σ of a tilt component: σ/k rad.
        assert!((axes[1].tilt_components_deg[0] - 0.0).abs() < 1e-12);
        assert!((axes[1].tilt_components_cov_deg2[0][0].sqrt() - (1e-3 / 57.0f64).to_degrees()).abs() < 1e-9);
    }
}
