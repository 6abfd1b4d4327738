//! The calibration report: every estimate with its 1-σ, the evidence behind it (residuals
//! against the measured noise floor, sample accounting, index and gear checks) and the paper
//! method's cross-check, as data (serialisable); [`crate::present::cal_text`] prints it.

use super::gear::{GearEstimate, IndexStats};
use super::paper::PaperCheck;
use crate::calib::result::apply::Calibration;
use crate::calib::result::derived::{AxisEstimate, InterAxisAngle};
use crate::geometry::Pose;
use protocol::GyroConfig;
use serde::{Deserialize, Serialize};

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
    /// Excluded around gaps in the samples (a lost frame, an excluded stretch): the samples
    /// within the longest delay the model fits of a gap, whose history the delay would need.
    #[serde(default)]
    pub excluded_near_gaps: usize,
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
    /// The catalogued effects the runs do not separate, each with its plausible size and what it
    /// adds to σ (already in `cov` and every σ derived from it).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub consider: Vec<super::consider_term::ConsiderTerm>,
    /// The near ties of the loop's steps: alternatives to an effect it took, about as likely given
    /// the data, each with its Akaike weight and what the spread of M over them adds to σ (already
    /// in `cov` and every σ derived from it).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub model_choice: Vec<super::consider_term::ModelChoiceTerm>,
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
}
