//! Calibration of a 3-axis gyro from two-table exciter runs (EXCITER.md): the joint fit of
//! `v = M R_qᵀ ω2 + v_off` over all samples of both poses, extended by the catalogued effects the
//! residual calls for, with honest covariances, and the paper's per-pose sinusoid method as a
//! cross-check.
//!
//! Pipeline: [`kinematics::reconstruct`] (θ2, θ1', θ2' per sample, once) → [`extended::fit`]
//! (Gauss-Newton on accumulated normal equations; the linear model is its base case) →
//! [`diagnostics::diagnose`] (noise floor, autocorrelation, structure left in the residual) →
//! [`selection::step`] (the effect the data supports most) → … → [`closure::close_loop`]'s
//! verdict, with [`derived`] quantities and [`paper::paper_check`] from the sums alone.

pub mod apply;
pub mod axes;
pub mod binning;
pub mod blocking;
pub mod closure;
pub mod consider;
pub mod consistency;
pub mod derived;
pub mod diagnostics;
pub mod effects;
pub mod error;
pub mod estimate;
pub mod extended;
pub mod kinematics;
pub mod layout;
pub mod paper;
pub mod report;
pub mod sanity;
pub mod selection;
pub mod sincos;
pub mod spectrum;
pub mod stats;
pub mod truth_check;

#[cfg(test)]
mod acceptance_tests;
#[cfg(test)]
mod loop_tests;
#[cfg(test)]
mod testgen;
#[cfg(test)]
mod tests;

pub use apply::{Calibration, CalibrationFileError};
pub use closure::{calibrate, close_loop, close_loop_reconstructed, LoopOptions, LoopReport, Verdict};
pub use effects::Effect;
pub use error::CalError;
pub use estimate::Estimate;
pub use kinematics::KinOptions;
pub use report::CalReport;

use crate::capture::Run;
use crate::geometry::Pose;
use serde::{Deserialize, Serialize};

/// Settings of a calibration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CalOptions {
    /// Kinematics reconstruction.
    pub kinematics: KinOptions,
    /// Span of the moving average whose remainder measures the noise floor, s. 0.1 s is 1/20 of
    /// the 2 s table period at 0.5 Hz (a 0.5 Hz misfit leaks < 0.5 % of its amplitude into the
    /// floor) and 80 samples at 800 Hz (noise correlated over a few samples biases it < 3 %).
    pub noise_window_s: f64,
}

impl Default for CalOptions {
    fn default() -> Self {
        Self { kinematics: KinOptions::default(), noise_window_s: 0.1 }
    }
}

/// Datasheet sensitivity in counts per °/s.
fn nominal_counts_per_dps(fs: protocol::FullScale) -> f64 {
    1e6 / f64::from(fs.udps_per_lsb())
}

/// Checks what can be checked before touching the samples: runs present, one gyro config, both
/// poses.
fn check_runs(runs: &[Run]) -> Result<(), CalError> {
    let first = runs.first().ok_or(CalError::NoRuns)?;
    for (i, r) in runs.iter().enumerate().skip(1) {
        if r.gyro != first.gyro {
            return Err(CalError::InconsistentGyro {
                run: i + 1,
                label: r.label(),
                found: r.gyro,
                expected: first.gyro,
            });
        }
    }
    for (pose, other) in [(Pose::One, Pose::Two), (Pose::Two, Pose::One)] {
        if !runs.iter().any(|r| r.pose == pose) {
            return Err(CalError::MissingPose { present: other, missing: pose });
        }
    }
    Ok(())
}
