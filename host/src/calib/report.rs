//! The calibration report: every estimate with its 1-σ, the evidence behind it (residuals
//! against the measured noise floor, sample accounting, index and gear checks) and the paper
//! method's cross-check, serialisable and printable.

use super::apply::Calibration;
use super::derived::{AxisEstimate, InterAxisAngle};
use super::kinematics::{GearEstimate, IndexStats};
use super::paper::PaperCheck;
use crate::geometry::Pose;
use protocol::GyroConfig;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// Residual size of one axis against its noise floor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AxisResidual {
    /// Axis name.
    pub axis: char,
    /// Samples (unclipped).
    pub n: u64,
    /// RMS residual, counts.
    pub rms_counts: f64,
    /// RMS residual, °/s (counts / k).
    pub rms_dps: f64,
    /// White-noise floor from the residual's high-frequency part, counts.
    pub noise_floor_counts: f64,
    /// Noise floor, °/s.
    pub noise_floor_dps: f64,
    /// rms / floor: ≈1 when the model leaves nothing but noise.
    pub rms_over_floor: f64,
}

/// Residuals of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunResidualReport {
    /// Run number, from 1.
    pub run: usize,
    /// Pose.
    pub pose: Pose,
    /// Commanded base-table rate, °/s (signed by direction).
    pub commanded_rate_dps: f64,
    /// Per axis.
    pub axes: [AxisResidual; 3],
}

/// How residual autocorrelation inflates the covariance of one axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Autocorrelation {
    /// Axis name.
    pub axis: char,
    /// Long-run variance / variance of the residual (1 for white noise); multiplies the
    /// covariance.
    pub inflation: f64,
    /// Block length at which blocking found the block means uncorrelated, samples.
    pub block_samples: u64,
    /// Samples / inflation.
    pub effective_samples: f64,
}

/// What happened to the samples of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// Run number, from 1.
    pub run: usize,
    /// Pose.
    pub pose: Pose,
    /// Commanded base-table rate, °/s.
    pub commanded_rate_dps: f64,
    /// Median measured base-table rate, °/s.
    pub steady_rate_dps: f64,
    /// Sample rate from the timestamps, Hz.
    pub sample_rate_hz: f64,
    /// Samples in the run.
    pub samples_total: usize,
    /// Samples used.
    pub samples_used: usize,
    /// Excluded as spin-up, stop or off-speed.
    pub excluded_unsteady: usize,
    /// Excluded at the run ends for want of a full rate window.
    pub excluded_window_edge: usize,
    /// Excluded as stale.
    pub excluded_stale: usize,
    /// Samples in the θ1' window.
    pub rate_window_samples: usize,
    /// Encoder quantisation on θ1', °/s rms.
    pub rate_quantisation_dps: f64,
    /// θ2 reference from the index.
    pub index: IndexStats,
}

/// The full calibration report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalReport {
    /// Model fitted.
    pub model: String,
    /// Gyro settings of every run.
    pub gyro: GyroConfig,
    /// Datasheet sensitivity of the full scale in use, counts per °/s.
    pub nominal_counts_per_dps: f64,
    /// M = K S, counts per °/s; row i is axis i.
    pub m_counts_per_dps: [[f64; 3]; 3],
    /// Offsets, counts.
    pub offset_counts: [f64; 3],
    /// Names of the 12 parameters in `cov` order: m_x (3), b_x, m_y (3), b_y, m_z (3), b_z.
    pub param_names: Vec<String>,
    /// Covariance of the parameters (12×12, rows), inflated for residual autocorrelation.
    pub cov: Vec<Vec<f64>>,
    /// Per-axis sensitivity, direction, offset, tilt.
    pub axes: [AxisEstimate; 3],
    /// Angles between the real axes.
    pub inter_axis: [InterAxisAngle; 3],
    /// Residuals per axis over all runs.
    pub residuals: [AxisResidual; 3],
    /// Residuals per run.
    pub run_residuals: Vec<RunResidualReport>,
    /// Autocorrelation of the residuals.
    pub autocorrelation: [Autocorrelation; 3],
    /// Contemporaneous correlation of the residuals between axes.
    pub residual_correlation: [[f64; 3]; 3],
    /// Per-run sample accounting and index reference.
    pub runs: Vec<RunSummary>,
    /// Samples used, all runs.
    pub samples_used: usize,
    /// Samples excluded, all runs (unsteady + window edge + stale).
    pub samples_excluded: usize,
    /// Clipped samples per axis (excluded from that axis only).
    pub clipped: [u64; 3],
    /// Gear ratio from the index pulses.
    pub gear: GearEstimate,
    /// Paper method cross-check (None if its per-pose systems were singular).
    pub paper: Option<PaperCheck>,
    /// The offset the drift model gives through each run (empty without a drift model): what
    /// `offset_counts` becomes at other times and die temperatures.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub drift: Vec<RunDrift>,
}

/// The modelled offset through one run, sampled every [`DRIFT_TABLE_STEP_S`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunDrift {
    /// Run number.
    pub run: usize,
    /// Run label (pose and rate).
    pub label: String,
    /// Times on the run's capture clock, s.
    pub t_s: Vec<f64>,
    /// Smoothed die temperature at those times, °C from the capture mean.
    pub temp_c: Vec<f64>,
    /// Modelled offset per axis at those times, counts.
    pub offset_counts: [Vec<f64>; 3],
}

/// Spacing of the exported drift table, s: as fine as the finest free-drift knots.
pub const DRIFT_TABLE_STEP_S: f64 = 10.0;

impl CalReport {
    /// The part needed to turn raw counts into rates.
    pub fn calibration(&self) -> Calibration {
        Calibration::new(self.model.clone(), self.gyro.full_scale, self.m_counts_per_dps, self.offset_counts)
            .expect("M passed the fit's conditioning check, so it is invertible")
    }

    /// A readable multi-line summary, units everywhere, 1-σ beside each value.
    pub fn summary(&self) -> String {
        let mut o = String::new();
        let g = &self.gyro;
        let _ = writeln!(o, "Model: {}", self.model);
        let _ = writeln!(
            o,
            "Gyro: ±{} °/s, {} Hz; nominal sensitivity {:.4} counts/(°/s)",
            g.full_scale.range_dps(),
            g.odr.hz(),
            self.nominal_counts_per_dps
        );
        let _ = writeln!(
            o,
            "Samples: {} used, {} excluded (spin-up/stop, window edges, stale); clipped x/y/z: {}/{}/{}",
            self.samples_used, self.samples_excluded, self.clipped[0], self.clipped[1], self.clipped[2]
        );
        let _ = writeln!(o, "\nAxis  k [counts/(°/s)]          vs nominal   offset [counts]      tilt [°]              direction s (±1σ)");
        for a in &self.axes {
            let _ = writeln!(
                o,
                "  {}   {:9.5} ± {:.5}   {:+7.3} %   {:+9.3} ± {:.3}   {:7.4} ± {:.4}   [{:+.6} ± {:.1e}, {:+.6} ± {:.1e}, {:+.6} ± {:.1e}]",
                a.axis,
                a.k_counts_per_dps,
                a.k_sigma,
                a.k_vs_nominal_percent,
                a.offset_counts,
                a.offset_sigma_counts,
                a.tilt_deg,
                a.tilt_extrinsic_sigma_deg(),
                a.s[0],
                a.s_sigma[0],
                a.s[1],
                a.s_sigma[1],
                a.s[2],
                a.s_sigma[2]
            );
        }
        let _ = writeln!(o, "\nTilt components [°] (toward the other package axes):");
        for a in &self.axes {
            let c = &a.tilt_components_cov_deg2;
            let _ = writeln!(
                o,
                "  {} → {}: {:+.4} ± {:.4}   {} → {}: {:+.4} ± {:.4}",
                a.axis,
                a.tilt_component_axes[0],
                a.tilt_components_deg[0],
                c[0][0].sqrt(),
                a.axis,
                a.tilt_component_axes[1],
                a.tilt_components_deg[1],
                c[1][1].sqrt()
            );
        }
        let _ = writeln!(o, "\nAngles between axes [°]:");
        for p in &self.inter_axis {
            let _ = writeln!(
                o,
                "  {}–{}: {:.4} ± {:.4}  (non-orthogonality {:+.4}°)",
                p.axes[0], p.axes[1], p.angle_deg, p.sigma_deg, p.non_orthogonality_deg
            );
        }
        let _ = writeln!(o, "\nResiduals (RMS vs noise floor measured from the data):");
        for r in &self.residuals {
            let _ = writeln!(
                o,
                "  {}: {:.2} counts = {:.4} °/s; floor {:.2} counts = {:.4} °/s; ratio {:.3}",
                r.axis, r.rms_counts, r.rms_dps, r.noise_floor_counts, r.noise_floor_dps, r.rms_over_floor
            );
        }
        for rr in &self.run_residuals {
            let ratios: Vec<String> = rr
                .axes
                .iter()
                .map(|a| format!("{} {:.2}/{:.2} counts", a.axis, a.rms_counts, a.noise_floor_counts))
                .collect();
            let _ =
                writeln!(o, "  run {} ({}, {:+.1} °/s): {}", rr.run, rr.pose, rr.commanded_rate_dps, ratios.join(", "));
        }
        let ac: Vec<String> = self
            .autocorrelation
            .iter()
            .map(|a| format!("{} ×{:.2} (blocks of {})", a.axis, a.inflation, a.block_samples))
            .collect();
        let _ = writeln!(o, "  covariance inflation for autocorrelation: {}", ac.join(", "));
        let gr = &self.gear;
        let _ = writeln!(
            o,
            "\nGear ratio θ2'/θ1': {:.8} (nominal {:.6}; {:+.3} ± {:.3} ppm from nominal)",
            gr.estimated,
            gr.nominal,
            gr.deviation_ppm,
            gr.sigma / gr.nominal * 1e6
        );
        for r in &self.runs {
            let i = &r.index;
            let _ = writeln!(
                o,
                "  run {} ({}, {:+.1} °/s → {:+.3} °/s measured, {:.1} Hz): {}/{} samples used ({} unsteady, {} edge, {} stale); index {} pulses ({} rejected), θ2 ref ± {:.1e}°, centre rms {:.2} counts; θ1' window {} samples, quantisation {:.4} °/s",
                r.run,
                r.pose,
                r.commanded_rate_dps,
                r.steady_rate_dps,
                r.sample_rate_hz,
                r.samples_used,
                r.samples_total,
                r.excluded_unsteady,
                r.excluded_window_edge,
                r.excluded_stale,
                i.pulses,
                i.rejected,
                i.ref_sigma_deg,
                i.centre_rms_counts,
                r.rate_window_samples,
                r.rate_quantisation_dps
            );
        }
        match &self.paper {
            Some(p) => {
                let _ = writeln!(o, "\nPaper method (eq. 4-5) cross-check, z = (joint − paper)/σ_paper:");
                for a in &p.axes {
                    let _ = writeln!(
                        o,
                        "  {}: k {:.5} ± {:.5} (z {:+.2}); offset {:+.3} ± {:.3} counts (z {:+.2}); s [{:+.6}, {:+.6}, {:+.6}] (z {:+.2}, {:+.2}, {:+.2})",
                        a.axis,
                        a.k_counts_per_dps,
                        a.k_sigma,
                        a.z_k,
                        a.offset_counts,
                        a.offset_sigma_counts,
                        a.z_offset,
                        a.s[0],
                        a.s[1],
                        a.s[2],
                        a.z_s[0],
                        a.z_s[1],
                        a.z_s[2]
                    );
                }
                let _ = writeln!(o, "  agreement: max |z| {:.2}, rms z {:.2}", p.max_abs_z, p.rms_z);
            }
            None => {
                let _ = writeln!(o, "\nPaper method cross-check: not available (a per-pose sinusoid fit was singular)");
            }
        }
        o
    }
}
