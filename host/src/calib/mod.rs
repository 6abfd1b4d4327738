//! Calibration of a 3-axis gyro from two-table exciter runs (EXCITER.md): the joint fit of
//! `v = M R_qᵀ ω2 + v_off` over all samples of both poses, extended by the catalogued effects the
//! residual calls for, with honest covariances, and the paper's per-pose sinusoid method as a
//! cross-check.
//!
//! Five one-way layers, each a folder; a layer imports only those below it
//! (`host/tests/structure.rs` checks it), and this module's re-exports are the face for the rest
//! of the program:
//!
//! 1. [`result`]: the vocabulary: the reported quantities with their JSON layouts, the errors;
//! 2. [`data`]: captures → the kinematics the model is fitted to (θ2, θ1', θ2' per sample, once:
//!    [`data::kinematics::reconstruct`]), the runs' layout;
//! 3. [`effects`]: one file per catalogued effect behind one trait, and their registry;
//! 4. [`engine`]: the model's kinematic chain, accumulation and solve ([`engine::fit`]:
//!    Gauss-Newton on accumulated normal equations; the linear model is its base case);
//! 5. [`analysis`]: the closed loop ([`analysis::diagnostics::diagnose`]: noise floor,
//!    autocorrelation, structure left in the residual → [`analysis::selection::step`]: the effect
//!    the data support most → … → [`analysis::closure::close_loop`]'s verdict), the consider
//!    covariance, the runs' consistency, the sanity checks and the paper method's cross-check.
//!
//! Presentation (text, HTML) lives outside, in `present/` and `report/`.

pub mod analysis;
pub mod data;
pub mod effects;
pub mod engine;
pub mod result;

#[cfg(test)]
mod acceptance_tests;
#[cfg(test)]
mod loop_tests;
#[cfg(test)]
mod testgen;
#[cfg(test)]
mod tests;

pub use analysis::closure::CalOptions;
pub use analysis::closure::{calibrate, close_loop, close_loop_reconstructed, LoopOptions, LoopReport, Verdict};
pub use data::kinematics::KinOptions;
pub use effects::Effect;
pub use result::apply::{Calibration, CalibrationFileError};
pub use result::error::CalError;
pub use result::estimate::Estimate;
pub use result::report::CalReport;
