//! The calibration's vocabulary, at the bottom of its layers: the reported quantities, each with
//! its JSON layout beside it (estimates with σ, the report, the axes' directions and angles derived
//! from M, the applied calibration, the comparison with a known truth) and the errors. Every
//! layer above speaks it; it imports none of them.

pub mod apply;
pub mod axes;
pub mod consider_term;
pub mod derived;
pub mod error;
pub mod estimate;
pub mod gear;
pub mod paper;
pub mod report;
pub mod truth_check;
