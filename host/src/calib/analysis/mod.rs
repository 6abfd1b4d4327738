//! What the calibration concludes from fits: the closed loop (diagnose the residual, select an
//! effect, refit), the consider covariance of what the runs cannot separate, the consistency of
//! runs that should agree, the sanity checks that refuse a degenerate fit, the paper method's
//! cross-check, and the statistics they share. The top layer: imports every layer below.

pub mod angle_sums;
pub mod binning;
pub mod blocking;
pub mod closure;
pub mod consider;
pub mod consistency;
pub mod diagnostics;
pub mod model_choice;
pub mod paper;
pub mod sanity;
pub mod selection;
pub mod spectrum;
pub mod stats;
