//! The paper method's cross-check as reported: per pose and axis the sinusoid in θ2 (EXCITER.md
//! eq. 4-5), per axis the direction, sensitivity and offset it gives, and their z against the
//! joint fit ([`crate::calib::analysis::paper`] computes them).

use super::estimate::{estimates, sigmas, values, Estimate};
use crate::geometry::Pose;
use serde::{Deserialize, Serialize};

/// The sinusoid fitted to one axis in one pose.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(into = "PoseSinusoidJson", from = "PoseSinusoidJson")]
pub struct PoseSinusoid {
    /// Pose.
    pub pose: Pose,
    /// Coefficients [a, b, d, c]: of θ1' sinθ2 and θ1' cosθ2 (counts per °/s), of θ2' − θ̄2'
    /// (counts per °/s), and the baseline at θ̄2' (counts), each with its σ.
    pub coef: [Estimate; 4],
    /// Amplitude √(a² + b²), counts per °/s of θ1'.
    pub amplitude_counts_per_dps: f64,
    /// Phase φ of a sinθ2 + b cosθ2 = A sin(θ2 + φ), degrees.
    pub phase_deg: f64,
    /// Mean θ2' of the pose's samples, °/s.
    pub mean_theta2_rate_dps: f64,
    /// Samples.
    pub n: u64,
}

/// One axis by the paper's method, compared with the joint fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(into = "PaperAxisJson", from = "PaperAxisJson")]
pub struct PaperAxis {
    /// Axis name.
    pub axis: char,
    /// Direction s_i (sign chosen nearest e_i), per component.
    pub s: [Estimate; 3],
    /// Sensitivity, counts per °/s.
    pub k_counts_per_dps: Estimate,
    /// Offset, counts.
    pub offset_counts: Estimate,
    /// (joint fit − paper)/σ_paper for s (3 components; the on-axis one is not pooled into
    /// `max_abs_z` / `rms_z`), k, offset.
    pub z_s: [f64; 3],
    /// See `z_s`.
    pub z_k: f64,
    /// See `z_s`.
    pub z_offset: f64,
    /// The two sinusoids, pose 1 then pose 2.
    pub sinusoids: [PoseSinusoid; 2],
}

/// The cross-check. The z-scores use the paper method's own σ as the scale: both methods use
/// the same samples, so their difference has variance σ²_paper − σ²_joint (the joint fit being
/// the efficient one), not the sum; σ_paper bounds it from above and is what the paper's method
/// would report alone.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PaperCheck {
    /// Per axis.
    pub axes: [PaperAxis; 3],
    /// Largest |z| over all compared parameters.
    pub max_abs_z: f64,
    /// RMS z over all compared parameters.
    pub rms_z: f64,
}

// The JSON layouts of this module's types (see [`crate::calib::result::estimate::values`] for why).

#[derive(Serialize, Deserialize)]
pub struct PoseSinusoidJson {
    pose: Pose,
    coef: [f64; 4],
    coef_sigma: [f64; 4],
    amplitude_counts_per_dps: f64,
    phase_deg: f64,
    mean_theta2_rate_dps: f64,
    n: u64,
}

impl From<PoseSinusoid> for PoseSinusoidJson {
    fn from(p: PoseSinusoid) -> Self {
        Self {
            pose: p.pose,
            coef: values(p.coef),
            coef_sigma: sigmas(p.coef),
            amplitude_counts_per_dps: p.amplitude_counts_per_dps,
            phase_deg: p.phase_deg,
            mean_theta2_rate_dps: p.mean_theta2_rate_dps,
            n: p.n,
        }
    }
}

impl From<PoseSinusoidJson> for PoseSinusoid {
    fn from(p: PoseSinusoidJson) -> Self {
        Self {
            pose: p.pose,
            coef: estimates(p.coef, p.coef_sigma),
            amplitude_counts_per_dps: p.amplitude_counts_per_dps,
            phase_deg: p.phase_deg,
            mean_theta2_rate_dps: p.mean_theta2_rate_dps,
            n: p.n,
        }
    }
}

#[derive(Serialize, Deserialize)]
pub struct PaperAxisJson {
    axis: char,
    s: [f64; 3],
    s_sigma: [f64; 3],
    k_counts_per_dps: f64,
    k_sigma: f64,
    offset_counts: f64,
    offset_sigma_counts: f64,
    z_s: [f64; 3],
    z_k: f64,
    z_offset: f64,
    sinusoids: [PoseSinusoid; 2],
}

impl From<PaperAxis> for PaperAxisJson {
    fn from(a: PaperAxis) -> Self {
        Self {
            axis: a.axis,
            s: values(a.s),
            s_sigma: sigmas(a.s),
            k_counts_per_dps: a.k_counts_per_dps.value,
            k_sigma: a.k_counts_per_dps.sigma,
            offset_counts: a.offset_counts.value,
            offset_sigma_counts: a.offset_counts.sigma,
            z_s: a.z_s,
            z_k: a.z_k,
            z_offset: a.z_offset,
            sinusoids: a.sinusoids,
        }
    }
}

impl From<PaperAxisJson> for PaperAxis {
    fn from(a: PaperAxisJson) -> Self {
        Self {
            axis: a.axis,
            s: estimates(a.s, a.s_sigma),
            k_counts_per_dps: Estimate::new(a.k_counts_per_dps, a.k_sigma),
            offset_counts: Estimate::new(a.offset_counts, a.offset_sigma_counts),
            z_s: a.z_s,
            z_k: a.z_k,
            z_offset: a.z_offset,
            sinusoids: a.sinusoids,
        }
    }
}
