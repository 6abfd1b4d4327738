//! On simulated data: how far a calibration lies from the truth, in degrees and ppm and in units
//! of its own reported uncertainty.

use crate::calib::result::derived::{mahalanobis2, AxisEstimate};
use crate::calib::result::report::CalReport;
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use serde::{Deserialize, Serialize};
use serde_json::Value;

/// The sensor a calibration is compared with: its true sensitivities and sensing axes (a
/// simulator's truth, `crate::sim::Truth::sensor`, or a reference instrument's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorTruth {
    /// Sensitivities k_i, counts per °/s.
    pub k_counts_per_dps: [f64; 3],
    /// Sensing axes s_i, unit rows in the package frame.
    pub s: [[f64; 3]; 3],
}

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
    pub fn of(axes: &[AxisEstimate; 3], truth: &SensorTruth) -> Self {
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

/// z-values judged per axis: the sensitivity, the three elements of the axis' row of M, and the
/// direction, in the order `../shared/validation/check.py` appends them.
pub const Z_PER_AXIS: usize = 5;

/// z-values judged per calibration. (check.py's docstring says 21; its code appends the
/// [`Z_PER_AXIS`] values above for each of the three axes, and these are those.)
pub const Z_COUNT: usize = 3 * Z_PER_AXIS;

/// One calibration's z-values, axis x first.
pub type Zs = [f64; Z_COUNT];

/// 2-dof Mahalanobis distance of s = m/|m| from `s_true` in the plane normal to s, with `cov3`
/// the covariance of the row m: check.py's `direction_z`, step for step. A covariance that is
/// not positive in that plane (check.py: infinite) or not a number (check.py: NaN) is infinite.
pub fn direction_z(m: [f64; 3], cov3: [[f64; 3]; 3], s_true: [f64; 3]) -> f64 {
    let m = Vector3::from(m);
    let cov = Matrix3::from_fn(|r, c| cov3[r][c]);
    let nm = m.norm();
    let s = m / nm;
    let a = if s.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let u = s.cross(&a).normalize();
    let v = s.cross(&u);
    // ds = (I − s sᵀ) dm / |m|: its components along u and v are u·dm/|m| and v·dm/|m|.
    let basis = [u / nm, v / nm];
    let c = Matrix2::from_fn(|r, q| basis[r].dot(&(cov * basis[q])));
    let d = s - Vector3::from(s_true);
    let e = Vector2::new(u.dot(&d), v.dot(&d));
    let det = c[(0, 0)] * c[(1, 1)] - c[(0, 1)] * c[(1, 0)];
    if det.is_nan() || det <= 0.0 {
        return f64::INFINITY;
    }
    let q = (c[(1, 1)] * e[0] * e[0] - 2.0 * c[(0, 1)] * e[0] * e[1] + c[(0, 0)] * e[1] * e[1]) / det;
    q.max(0.0).sqrt()
}

fn number(v: &Value, what: &str) -> Result<f64, String> {
    v.as_f64().ok_or_else(|| format!("{what} is not a number"))
}

fn triple(v: &Value, what: &str) -> Result<[f64; 3], String> {
    match v.as_array().map(Vec::as_slice) {
        Some([x, y, z]) => Ok([number(x, what)?, number(y, what)?, number(z, what)?]),
        _ => Err(format!("{what} is not 3 numbers")),
    }
}

/// The z-values of a calibration (the JSON of `calibration.json`) against a true M (counts per
/// °/s, rows = axes), computed as `../shared/validation/check.py` does: per axis i,
/// |k − |M_i|| / `k_sigma`; each element j of row i of M, |m_ij − M_ij| / √cov[p][p] with p the
/// index of `m_<i><j>` in `param_names` or else 4i + j; and [`direction_z`] of row i with the
/// rows' 3×3 block of `cov`. A value that is not a number (a σ of 0 or NaN) is +∞: a
/// calibration that cannot say how far off it is, is off. The one place these z-values are
/// computed (the tests, the trust bench and the final step's report all use it).
pub fn z_values(cal: &Value, m_true: &[[f64; 3]; 3]) -> Result<Zs, String> {
    const AXES: [char; 3] = ['x', 'y', 'z'];
    let names: Vec<&str> = cal["param_names"]
        .as_array()
        .ok_or("calibration: param_names is not a list")?
        .iter()
        .map(|n| n.as_str().ok_or("calibration: param_names holds a non-string"))
        .collect::<Result<_, _>>()?;
    let cov_rows = cal["cov"].as_array().ok_or("calibration: cov is not a matrix")?;
    // A null (JSON's NaN) is a number that is not one.
    let cov = |r: usize, q: usize| -> Result<f64, String> {
        let v = cov_rows.get(r).and_then(|row| row.get(q)).ok_or(format!("calibration: no cov[{r}][{q}]"))?;
        Ok(v.as_f64().unwrap_or(f64::NAN))
    };
    let axes = cal["axes"].as_array().filter(|a| a.len() == 3).ok_or("calibration: axes is not 3 axes")?;
    let mut z = [0.0; Z_COUNT];
    for (i, a) in axes.iter().enumerate() {
        let k = number(&a["k_counts_per_dps"], "calibration: axes[i].k_counts_per_dps")?;
        let k_sigma = a["k_sigma"].as_f64().unwrap_or(f64::NAN);
        let m = triple(&cal["m_counts_per_dps"][i], "calibration: m_counts_per_dps[i]")?;
        let row = Vector3::from(m_true[i]);
        let idx: [usize; 3] = std::array::from_fn(|j| {
            let name = format!("m_{}{}", AXES[i], AXES[j]);
            names.iter().position(|n| *n == name).unwrap_or(4 * i + j)
        });
        let zi = &mut z[Z_PER_AXIS * i..Z_PER_AXIS * (i + 1)];
        zi[0] = (k - row.norm()).abs() / k_sigma;
        for (j, &p) in idx.iter().enumerate() {
            zi[1 + j] = (m[j] - row[j]).abs() / cov(p, p)?.sqrt();
        }
        let mut cov3 = [[0.0; 3]; 3];
        for (r, &pr) in idx.iter().enumerate() {
            for (q, &pq) in idx.iter().enumerate() {
                cov3[r][q] = cov(pr, pq)?;
            }
        }
        zi[4] = direction_z(m, cov3, row.normalize().into());
    }
    Ok(z.map(|v| if v.is_nan() { f64::INFINITY } else { v }))
}

/// [`z_values`] of a report (as `calibration.json` holds it).
pub fn z_against_m(report: &CalReport, m_true: &[[f64; 3]; 3]) -> Zs {
    serde_json::to_value(report)
        .map_err(|e| e.to_string())
        .and_then(|v| z_values(&v, m_true))
        .unwrap_or([f64::INFINITY; Z_COUNT])
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
