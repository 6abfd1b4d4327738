//! The JSON layout of the report types that hold [`Estimate`]s: calibration.json and loop.json
//! are read by programs outside the crate (`validation/check.py` reads `axes[i].s`,
//! `k_counts_per_dps` and `k_sigma`; the all-effects bench also `tilt_mount_sigma_deg`), so each
//! estimate is written flat, its value and its σ as two fields side by side, as they were before
//! the type existed. Each type converts to and from its layout here (`#[serde(into, from)]`);
//! the field docs are on the types.

use super::closure::ParamMove;
use super::derived::{AxisEstimate, InterAxisAngle};
use super::estimate::Estimate;
use super::kinematics::{GearEstimate, IndexStats};
use super::paper::{PaperAxis, PoseSinusoid};
use crate::geometry::Pose;
use serde::{Deserialize, Serialize};

fn values<const N: usize>(e: [Estimate; N]) -> [f64; N] {
    e.map(|e| e.value)
}

fn sigmas<const N: usize>(e: [Estimate; N]) -> [f64; N] {
    e.map(|e| e.sigma)
}

fn estimates<const N: usize>(value: [f64; N], sigma: [f64; N]) -> [Estimate; N] {
    std::array::from_fn(|i| Estimate::new(value[i], sigma[i]))
}

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

#[derive(Serialize, Deserialize)]
pub struct IndexStatsJson {
    pulses: usize,
    rejected: usize,
    ref_counts: f64,
    ref_sigma_counts: f64,
    ref_sigma_deg: f64,
    centre_rms_counts: f64,
    plate_width_counts: f64,
    period_counts: f64,
    period_sigma_counts: f64,
}

impl From<IndexStats> for IndexStatsJson {
    fn from(i: IndexStats) -> Self {
        Self {
            pulses: i.pulses,
            rejected: i.rejected,
            ref_counts: i.ref_counts.value,
            ref_sigma_counts: i.ref_counts.sigma,
            ref_sigma_deg: i.ref_sigma_deg,
            centre_rms_counts: i.centre_rms_counts,
            plate_width_counts: i.plate_width_counts,
            period_counts: i.period_counts.value,
            period_sigma_counts: i.period_counts.sigma,
        }
    }
}

impl From<IndexStatsJson> for IndexStats {
    fn from(i: IndexStatsJson) -> Self {
        Self {
            pulses: i.pulses,
            rejected: i.rejected,
            ref_counts: Estimate::new(i.ref_counts, i.ref_sigma_counts),
            ref_sigma_deg: i.ref_sigma_deg,
            centre_rms_counts: i.centre_rms_counts,
            plate_width_counts: i.plate_width_counts,
            period_counts: Estimate::new(i.period_counts, i.period_sigma_counts),
        }
    }
}

#[derive(Serialize, Deserialize)]
pub struct GearEstimateJson {
    nominal: f64,
    estimated: f64,
    sigma: f64,
    deviation_ppm: f64,
}

impl From<GearEstimate> for GearEstimateJson {
    fn from(g: GearEstimate) -> Self {
        Self { nominal: g.nominal, estimated: g.ratio.value, sigma: g.ratio.sigma, deviation_ppm: g.deviation_ppm }
    }
}

impl From<GearEstimateJson> for GearEstimate {
    fn from(g: GearEstimateJson) -> Self {
        Self { nominal: g.nominal, ratio: Estimate::new(g.estimated, g.sigma), deviation_ppm: g.deviation_ppm }
    }
}

#[derive(Serialize, Deserialize)]
pub struct ParamMoveJson {
    name: String,
    before: f64,
    after: f64,
    sigma: f64,
    moved_sigma: f64,
}

impl From<ParamMove> for ParamMoveJson {
    fn from(m: ParamMove) -> Self {
        Self { name: m.name, before: m.before, after: m.after.value, sigma: m.after.sigma, moved_sigma: m.moved_sigma }
    }
}

impl From<ParamMoveJson> for ParamMove {
    fn from(m: ParamMoveJson) -> Self {
        Self { name: m.name, before: m.before, after: Estimate::new(m.after, m.sigma), moved_sigma: m.moved_sigma }
    }
}
