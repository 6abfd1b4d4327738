//! Why a calibration could not be computed, each as one line that says what and where.

use crate::geometry::Pose;
use protocol::GyroConfig;

/// A calibration failure. Runs are numbered from 1 in the order given to [`crate::calib::calibrate`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalError {
    /// Nothing to calibrate.
    #[error("no runs to calibrate: the capture holds no run")]
    NoRuns,
    /// The axis directions need both poses (EXCITER.md, eq. 4-5; the linear fit is singular too).
    #[error("only {present} was captured: {missing} is needed too (axis directions need both poses)")]
    MissingPose {
        /// The pose that is there.
        present: Pose,
        /// The pose that is not.
        missing: Pose,
    },
    /// A run has too few samples at steady speed.
    #[error("run {run} ({label}): too few usable samples ({usable} of {total} at steady speed), need at least {needed} (one sensor-table revolution)")]
    TooFewSamples {
        /// Run number, from 1.
        run: usize,
        /// Run label (pose, rate).
        label: String,
        /// Samples kept.
        usable: usize,
        /// Samples in the run.
        total: usize,
        /// Samples needed.
        needed: usize,
    },
    /// A run whose gaps leave the fit too few samples: each gap costs the samples within
    /// `MAX_DELAY_S` of it ([`crate::calib::analysis::sanity::needed_samples`] says how many a run needs).
    #[error("run {run} ({label}): too few usable samples once the gaps are cut out ({usable} of {kept} at steady speed lie {clear_ms:.0} ms clear of every gap), need at least {needed} (one sensor-table revolution)")]
    TooFewBetweenGaps {
        /// Run number, from 1.
        run: usize,
        /// Run label (pose, rate).
        label: String,
        /// Samples the fit would use.
        usable: usize,
        /// How far from a gap a sample must lie to be used, ms.
        clear_ms: f64,
        /// Samples kept at steady speed, gaps included.
        kept: usize,
        /// Samples needed.
        needed: usize,
    },
    /// A fit that is not one: a parameter or σ that is not a finite number, or a covariance that
    /// is not positive definite ([`crate::calib::analysis::sanity::sound`]).
    #[error("degenerate fit ({model}): {what}; no calibration")]
    Degenerate {
        /// The model fitted.
        model: String,
        /// What is not a number, and where.
        what: String,
    },
    /// Without a complete index pulse θ2 has no zero.
    #[error("run {run} ({label}): no complete index pulse (rising then falling edge) among {edges} edges, cannot reference θ2")]
    NoIndex {
        /// Run number, from 1.
        run: usize,
        /// Run label (pose, rate).
        label: String,
        /// Index edges seen.
        edges: usize,
    },
    /// Counts mean different things under different gyro settings.
    #[error("run {run} ({label}): gyro config {found:?} differs from run 1's {expected:?}")]
    InconsistentGyro {
        /// Run number, from 1.
        run: usize,
        /// Run label (pose, rate).
        label: String,
        /// Config of this run.
        found: GyroConfig,
        /// Config of run 1.
        expected: GyroConfig,
    },
    /// No sample of an axis is usable: every one sits on a rail.
    #[error("axis {axis}: every one of the {samples} samples at steady speed is clipped at the output's rails (the axis is dead, or the rates exceed the full scale)")]
    AxisClipped {
        /// Axis name, x, y or z.
        axis: char,
        /// Samples at steady speed, clear of the runs' ends.
        samples: usize,
    },
    /// The runs do not excite every regressor independently.
    #[error("normal matrix of axis {axis} is singular (reciprocal condition {rcond:.1e}): its unclipped samples do not excite every rate direction")]
    Singular {
        /// Axis name, x, y or z.
        axis: char,
        /// Reciprocal condition number of the scaled normal matrix.
        rcond: f64,
    },
    /// An extended model whose parameters the runs cannot tell apart.
    #[error("the runs do not separate the parameters of the model with {effects}")]
    Unidentifiable {
        /// The effects in the model.
        effects: String,
    },
}
