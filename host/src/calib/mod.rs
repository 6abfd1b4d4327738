//! Calibration of a 3-axis gyro from two-table exciter runs (EXCITER.md): the joint linear
//! least-squares fit of `v = M R_qᵀ ω2 + v_off` over all samples of both poses, with honest
//! covariances, and the paper's per-pose sinusoid method as a cross-check.
//!
//! Pipeline: [`kinematics::reconstruct`] (θ2, θ1', θ2' per sample, once) → [`lsq::fit`] of a
//! [`model::Columns`] set (one pass) → [`residuals::residual_pass`] (noise floor,
//! autocorrelation) → [`derived::derive`] and [`paper::paper_check`] (from the sums alone).

pub mod apply;
pub mod blocking;
pub mod catalogue;
pub mod closure;
pub mod derived;
pub mod diagnostics;
pub mod error;
pub mod extended;
pub mod html_report;
pub mod kinematics;
mod loop_summary;
pub mod lsq;
pub mod model;
pub mod paper;
pub mod report;
pub mod residuals;
pub mod selection;
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
pub use catalogue::Effect;
pub use closure::{close_loop, close_loop_owned, LoopOptions, LoopReport, Verdict};
pub use error::CalError;
pub use html_report::write_report;
pub use kinematics::KinOptions;
pub use report::CalReport;

use crate::capture::Run;
use crate::geometry::Pose;
use derived::derive;
use lsq::AXES;
use model::{Columns, LinearRate};
use nalgebra::DMatrix;
use report::{Autocorrelation, AxisResidual, RunResidualReport, RunSummary};
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

/// Calibrates from decoded runs of both poses with the linear model.
pub fn calibrate(runs: &[Run], opts: &CalOptions) -> Result<CalReport, CalError> {
    check_runs(runs)?;
    let kin = kinematics::reconstruct(runs, &opts.kinematics)?;
    calibrate_kinematics(runs, &kin, opts)
}

/// [`calibrate`] from kinematics already reconstructed from `runs` (the loop reconstructs once
/// and shares them).
fn calibrate_kinematics(runs: &[Run], kin: &kinematics::Kinematics, opts: &CalOptions) -> Result<CalReport, CalError> {
    let model = LinearRate;
    let fit = lsq::fit(&model, kin)?;
    let res = residuals::residual_pass(&model, &fit, kin, opts.noise_window_s)?;

    // Long-run residual covariance between axes: each axis's long-run variance, coupled by the
    // contemporaneous correlation (the axes' noise shares no filter dynamics worth more).
    let omega = |i: usize, j: usize| {
        let lr = |a: usize| fit.axes[a].sigma2() * res.long_run[a].inflation();
        res.correlation[i][j] * (lr(i) * lr(j)).sqrt()
    };
    let mut cov = DMatrix::zeros(12, 12);
    for i in 0..3 {
        for j in 0..3 {
            let block = if i == j {
                fit.axes[i].xtx_inv * omega(i, i)
            } else {
                fit.axes[i].xtx_inv * fit.total.xtx_pair(i, j) * fit.axes[j].xtx_inv * omega(i, j)
            };
            cov.view_mut((4 * i, 4 * j), (4, 4)).copy_from(&block);
        }
    }
    let params: [f64; 12] = std::array::from_fn(|p| fit.axes[p / 4].beta[p % 4]);
    let gyro = runs[0].gyro;
    let nominal = nominal_counts_per_dps(gyro.full_scale);
    let (axes, inter_axis) = derive(&params, &cov, nominal);

    let joint: [[f64; 5]; 3] = std::array::from_fn(|i| {
        let a = &axes[i];
        [a.s[0], a.s[1], a.s[2], a.k_counts_per_dps, a.offset_counts]
    });
    let inflation = std::array::from_fn(|i| res.long_run[i].inflation());
    let paper = paper::paper_check(&fit, kin, inflation, joint);

    let axis_residual = |r: &residuals::RunResidual, a: usize| {
        let k = axes[a].k_counts_per_dps;
        AxisResidual {
            axis: AXES[a],
            n: r.n[a],
            rms_counts: r.rms_counts[a],
            rms_dps: r.rms_counts[a] / k,
            noise_floor_counts: r.noise_floor_counts[a],
            noise_floor_dps: r.noise_floor_counts[a] / k,
            rms_over_floor: r.rms_counts[a] / r.noise_floor_counts[a],
        }
    };
    let run_residuals = kin
        .runs
        .iter()
        .zip(&res.per_run)
        .map(|(k, r)| RunResidualReport {
            run: k.run,
            pose: k.pose,
            commanded_rate_dps: k.commanded_rate_dps,
            axes: std::array::from_fn(|a| axis_residual(r, a)),
        })
        .collect();
    let autocorrelation = std::array::from_fn(|a| {
        let lr = &res.long_run[a];
        Autocorrelation {
            axis: AXES[a],
            inflation: lr.inflation(),
            block_samples: 1 << lr.level,
            effective_samples: fit.axes[a].n as f64 / lr.inflation(),
        }
    });
    let runs_summary: Vec<RunSummary> = kin
        .runs
        .iter()
        .map(|k| RunSummary {
            run: k.run,
            pose: k.pose,
            commanded_rate_dps: k.commanded_rate_dps,
            steady_rate_dps: k.steady_rate_dps,
            sample_rate_hz: k.sample_rate_hz,
            samples_total: k.total,
            samples_used: k.samples.len(),
            excluded_unsteady: k.excluded_unsteady,
            excluded_window_edge: k.excluded_window_edge,
            excluded_stale: k.excluded_stale,
            rate_window_samples: k.rate_window_samples,
            rate_quantisation_dps: k.rate_quantisation_dps,
            index: k.index,
        })
        .collect();
    let names = model.column_names();
    let param_names = (0..12)
        .map(|p| match names[p % 4] {
            "one" => format!("offset_{}_counts", AXES[p / 4]),
            c => format!("m_{}.{}", AXES[p / 4], c),
        })
        .collect();

    Ok(CalReport {
        drift: Vec::new(),
        model: model.name().to_string(),
        gyro,
        nominal_counts_per_dps: nominal,
        m_counts_per_dps: std::array::from_fn(|i| std::array::from_fn(|j| params[4 * i + j])),
        offset_counts: std::array::from_fn(|i| params[4 * i + 3]),
        param_names,
        cov: (0..12).map(|i| (0..12).map(|j| cov[(i, j)]).collect()).collect(),
        axes,
        inter_axis,
        residuals: std::array::from_fn(|a| axis_residual(&res.pooled, a)),
        run_residuals,
        autocorrelation,
        residual_correlation: res.correlation,
        samples_used: runs_summary.iter().map(|r| r.samples_used).sum(),
        samples_excluded: runs_summary
            .iter()
            .map(|r| r.excluded_unsteady + r.excluded_window_edge + r.excluded_stale)
            .sum(),
        runs: runs_summary,
        clipped: fit.total.n_clipped,
        gear: kin.gear,
        paper,
    })
}
