//! The per-axis table, one format for every text that shows a calibration: sensitivity, tilt
//! with the runs' and the mount's σ apart, offset, and direction with its σ.

use super::PlusMinus;
use crate::calib::result::report::CalReport;
use std::fmt::Write as _;

/// Writes the table's header and one row per axis, then the directions in a table of their own
/// (one table was 140 characters wide; each now fits 100).
pub fn write(o: &mut String, cal: &CalReport) {
    let _ = writeln!(o, "  axis  k [counts/(°/s)]        tilt [°] ± runs ± mount     offset [counts]");
    for a in &cal.axes {
        let _ = writeln!(
            o,
            "  {}     {:.5}   {:.4} ± {:.3}   {:+9.3}",
            a.axis,
            PlusMinus(a.k_counts_per_dps),
            PlusMinus(a.tilt_deg),
            a.tilt_mount_sigma_deg,
            PlusMinus(a.offset_counts),
        );
    }
    let _ = writeln!(o, "  axis  direction s (unit vector, package frame)   its σ per component");
    for a in &cal.axes {
        let _ = writeln!(
            o,
            "  {}     [{:+.6}, {:+.6}, {:+.6}]      [{:.1e}, {:.1e}, {:.1e}]",
            a.axis, a.s[0].value, a.s[1].value, a.s[2].value, a.s[0].sigma, a.s[1].sigma, a.s[2].sigma
        );
    }
}
