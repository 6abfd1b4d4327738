//! The engine: the linear model extended by catalogue effects ([`crate::calib::effects`]), fitted
//! jointly over the three axes.
//!
//! Each effect adds per-axis linear columns (drift, rate-dependent scale) and/or parameters shared
//! by all axes that move the kinematics (delay, index offset, table-speed ripple, the warm-up time
//! constant); the engine knows them only through [`crate::calib::effects::Behaviour`]. The shared ones make the model non-linear; it is fitted by Gauss-Newton on all
//! parameters at once, each iteration one pass over the cached kinematics that accumulates, per
//! run and axis, the Gram matrix of [linear columns | Jacobian columns of the shared parameters]
//! against the current residual. The covariance of the converged fit is the inverse of the joint
//! normal matrix, so the uncertainty of a delay or an index offset flows into that of M.
//!
//! The same accumulation over the union of the model's columns and every candidate's gives the
//! linearised fit of any candidate model from one pass (see [`crate::calib::analysis::selection`]).
//!
//! Gauss-Newton is written here rather than taken from `levenberg-marquardt` or `argmin`: those
//! want the residual vector and Jacobian in memory (samples × parameters, millions of rows),
//! where this accumulates the normal equations run by run and reuses them for every candidate;
//! the linear algebra is nalgebra's.
//!
//! Files: [`loop_data`] (the cached data), [`model`], [`chain`] (eq. 1-2 and every effect's
//! inputs), `pass` (what a pass fixes before it visits the samples), [`sums`] (the sums a pass
//! adds its rows to), `knot_split` (the free drift's knots in them), [`accumulate`] (one pass → per-run sums), [`cells`] (a pass's samples
//! summed a few at a time, the chain taken at three nodes of each: `nodes`), [`solve`] (normal
//! equations, Gauss-Newton, covariance), [`cross`] (a model's columns against candidates', read by
//! the score and the consider covariance alike); [`sincos`] (the recurrences the chain's
//! harmonics use).

pub mod accumulate;
pub mod cells;
pub mod chain;
pub mod cross;
mod knot_split;
pub mod loop_data;
pub mod model;
mod nodes;
mod pass;
pub mod sincos;
pub mod solve;
pub mod sums;

#[cfg(test)]
mod tests;

pub use crate::calib::effects::terms::{Bound, Col, LinCol, Point, Reported, SharedPar};
pub use crate::calib::effects::DRIFT_KNOT_SPACINGS_S;
pub use accumulate::{accumulate, accumulate_pairs};
pub use cells::Cells;
pub use chain::{Cursor, Evaluator};
pub use cross::CrossSums;
pub use loop_data::{LoopData, RunTemperatures, TemperatureGrid, TEMPERATURE_GRID_S, TEMPERATURE_SMOOTHING_S};
pub use model::{Model, Prior};
pub use nodes::for_each_interpolated;
pub use solve::{
    apply_step, fit, full_selection, normal_equations, residual_after, solve_joint, Fitted, JointSolution, Selection,
};
pub use sums::{Gram, Reach};
