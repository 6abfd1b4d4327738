//! Presentation: the calibration's results as the operator reads them, in plain text
//! ([`cal_text`], [`loop_text`]) and as the HTML report with its figures ([`html`], drawn with
//! [`crate::report`]'s primitives). The computation in the rest of [`crate::calib`] returns data and
//! never depends on this module.

pub mod advice;
pub mod axis_table;
pub mod cal_text;
pub mod findings;
pub mod html;
pub mod loop_text;
pub mod plus_minus;

pub use html::write_report;
pub use plus_minus::PlusMinus;
