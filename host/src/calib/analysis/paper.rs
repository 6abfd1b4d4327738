//! The paper's identification (EXCITER.md eq. 4-5) as an independent cross-check of the joint
//! fit: per pose and axis a sinusoid in θ2, whose phase gives a plane containing R_q s_i and
//! e_z2; two poses' planes intersect in s_i; the amplitude gives k_i, the baseline the offset.
//!
//! Per pose q the regression `v = a·θ1' sinθ2 + b·θ1' cosθ2 + d·(θ2' − θ̄2') + c` handles a
//! non-constant speed. Its columns are an invertible linear map of the linear model's columns
//! restricted to that pose ([θ1' sinθ2, θ1' cosθ2, θ2'] = R_q ω_s), so its normal equations are
//! that fit's per-run sums transformed, with no further pass over the samples.

use crate::calib::data::kinematics::Kinematics;
use crate::calib::engine::Gram;
use crate::calib::result::axes::AXES;
use crate::calib::result::derived::{delta_method, dvec};
use crate::calib::result::estimate::Estimate;
use crate::calib::result::paper::{PaperAxis, PaperCheck, PoseSinusoid};
use crate::geometry::Pose;
use nalgebra::{DMatrix, Matrix3, Matrix4, Vector3, Vector4};

/// A fitted pose sinusoid with its covariance, for the construction.
struct SinFit {
    sinusoid: PoseSinusoid,
    cov: Matrix4<f64>,
    r: Matrix3<f64>,
}

/// Fits one axis in one pose from the linear model's sums over that pose's runs:
/// columns [ω_s (3), 1] and `sums` holds their products with the raw counts.
fn fit_pose(sums: &Gram, r: Matrix3<f64>, axis: usize, inflation: f64, pose: Pose) -> Option<SinFit> {
    let a = Matrix4::from_row_slice(&sums.xtx[axis]);
    let b = Vector4::from_column_slice(&sums.xte[axis]);
    let n = sums.n[axis];
    let mean_x = Vector3::new(a[(0, 3)], a[(1, 3)], a[(2, 3)]) / a[(3, 3)];
    let theta2_mean = (r * mean_x).z;
    let mut t = Matrix4::zeros();
    t.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    t[(2, 3)] = -theta2_mean;
    t[(3, 3)] = 1.0;
    let ztz = t * a * t.transpose();
    let zty = t * b;
    let inv = ztz.try_inverse()?;
    let g = inv * zty;
    let rss = (sums.ete[axis] - 2.0 * g.dot(&zty) + (g.transpose() * ztz * g)[(0, 0)]).max(0.0);
    let cov = inv * (rss / (n as f64 - 4.0) * inflation);
    let coef: [f64; 4] = g.into();
    Some(SinFit {
        sinusoid: PoseSinusoid {
            pose,
            coef: std::array::from_fn(|i| Estimate::from_variance(coef[i], cov[(i, i)])),
            amplitude_counts_per_dps: coef[0].hypot(coef[1]),
            phase_deg: coef[1].atan2(coef[0]).to_degrees(),
            mean_theta2_rate_dps: theta2_mean,
            n,
        },
        cov,
        r,
    })
}

/// The paper's construction for axis `axis` from the two poses' coefficients
/// p = [a1, b1, d1, c1, a2, b2, d2, c2]: returns [s (3), k, offset].
fn construct(p: &[f64], r: [&Matrix3<f64>; 2], theta2_mean: [f64; 2], axis: usize) -> Vec<f64> {
    // n_iq = R_q s_i × e_z2 ∝ (b, −a, 0), to package frame by R_qᵀ (eq. 4).
    let normal = |q: usize| r[q].transpose() * Vector3::new(p[4 * q + 1], -p[4 * q], 0.0);
    let mut s = normal(0).cross(&normal(1)).normalize();
    if s[axis] < 0.0 {
        s = -s;
    }
    // Amplitude A_q = k·|(R_q s)_xy| = k·√(1 − (R_q s)_z²); least squares over the two poses.
    let (mut num, mut den) = (0.0, 0.0);
    for q in 0..2 {
        let w = (1.0 - (r[q] * s).z.powi(2)).max(0.0).sqrt();
        num += p[4 * q].hypot(p[4 * q + 1]) * w;
        den += w * w;
    }
    let k = num / den;
    // Baseline at θ̄2' = offset + k (R_q s)_z θ̄2': remove the constant θ2' term, average poses.
    let offset = (0..2).map(|q| p[4 * q + 3] - k * (r[q] * s).z * theta2_mean[q]).sum::<f64>() / 2.0;
    vec![s.x, s.y, s.z, k, offset]
}

/// Runs the paper's method on the linear model's per-run sums of [ω_s (3), 1] against the raw
/// counts (`sums`, in the order of `kin.runs`: `Fitted::per_run` of the model fitted from β = 0)
/// and compares it with the joint estimates (`joint[i]` = [s (3), k, offset] of axis i).
/// `inflation[i]` scales each sinusoid's covariance for residual autocorrelation, as measured on
/// the joint fit's residuals (the same noise). None if a pose has no samples or a 4×4 system is
/// singular.
pub fn paper_check(sums: &[Gram], kin: &Kinematics, inflation: [f64; 3], joint: [[f64; 5]; 3]) -> Option<PaperCheck> {
    debug_assert!(sums.iter().all(|g| g.l == 4), "the linear model has 4 columns");
    let pose_sums = |pose: Pose| Gram::sum(kin.runs.iter().zip(sums).filter(|(r, _)| r.pose == pose).map(|(_, g)| g));
    let eqs = [pose_sums(Pose::One)?, pose_sums(Pose::Two)?];
    let rot = [Pose::One.rotation(), Pose::Two.rotation()];
    let mut axes = Vec::with_capacity(3);
    let mut zs = Vec::with_capacity(12);
    for axis in 0..3 {
        let f1 = fit_pose(&eqs[0], rot[0], axis, inflation[axis], Pose::One)?;
        let f2 = fit_pose(&eqs[1], rot[1], axis, inflation[axis], Pose::Two)?;
        let mut p = [0.0; 8];
        p[..4].copy_from_slice(&f1.sinusoid.coef.map(|c| c.value));
        p[4..].copy_from_slice(&f2.sinusoid.coef.map(|c| c.value));
        let mut cov = DMatrix::zeros(8, 8);
        cov.view_mut((0, 0), (4, 4)).copy_from(&f1.cov);
        cov.view_mut((4, 4), (4, 4)).copy_from(&f2.cov);
        let means = [f1.sinusoid.mean_theta2_rate_dps, f2.sinusoid.mean_theta2_rate_dps];
        let (y, c) = delta_method(|v| construct(v, [&f1.r, &f2.r], means, axis), &p, &cov);
        let est: Vec<Estimate> = (0..5).map(|i| Estimate::from_variance(y[i], c[(i, i)])).collect();
        let z: Vec<f64> = (0..5).map(|i| (joint[axis][i] - y[i]) / est[i].sigma).collect();
        // The on-axis component of s is cos(tilt): its first-order σ vanishes with the tilt,
        // so it is reported but not pooled.
        zs.extend(z.iter().enumerate().filter(|&(i, _)| i != axis).map(|(_, v)| *v));
        axes.push(PaperAxis {
            axis: AXES[axis],
            s: [est[0], est[1], est[2]],
            k_counts_per_dps: est[3],
            offset_counts: est[4],
            z_s: [z[0], z[1], z[2]],
            z_k: z[3],
            z_offset: z[4],
            sinusoids: [f1.sinusoid, f2.sinusoid],
        });
    }
    let zv = dvec(&zs);
    Some(PaperCheck {
        axes: axes.try_into().ok()?,
        max_abs_z: zv.amax(),
        rms_z: (zv.norm_squared() / zs.len() as f64).sqrt(),
    })
}
