//! The user's specification limits (`calibrate --spec FILE`) and the PASS/FAIL of a calibration
//! against them, for the certificate, the summary, the record and the exit status.
//!
//! Decision rule: simple acceptance (ILAC-G8:09/2019, "shared risk"): a result passes
//! when its measured value lies within the limit; the expanded uncertainty is printed beside it
//! so the reader can apply a guard band of their own.

use crate::allan::NoiseReport;
use crate::calib::CalReport;
use crate::report::html::escape;
use anyhow::{Context, Result};
use serde::Deserialize;
use std::fmt::Write as _;
use std::path::Path;

/// Limits, each optional; a JSON object in the file given to `--spec`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spec {
    /// Largest |sensitivity − datasheet nominal| per axis, % of nominal.
    pub sensitivity_tolerance_percent: Option<f64>,
    /// Largest tilt of an axis from its package axis, °.
    pub max_tilt_deg: Option<f64>,
    /// Largest |angle between two axes − 90°|, °.
    pub max_non_orthogonality_deg: Option<f64>,
    /// Largest angle random walk per axis, °/√h (needs a static run).
    pub max_arw_deg_per_sqrt_h: Option<f64>,
}

/// One limit checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// What, e.g. `tilt z`.
    pub what: String,
    /// The measured value (absolute where the limit is on a magnitude).
    pub value: f64,
    /// The limit.
    pub limit: f64,
    /// Unit.
    pub unit: &'static str,
    /// Within the limit.
    pub pass: bool,
}

impl Spec {
    /// Reads a spec file: JSON, every field optional, unknown fields refused.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read spec {}", path.display()))?;
        let spec: Spec = serde_json::from_str(&text).with_context(|| format!("{} is not a spec", path.display()))?;
        for (name, v) in [
            ("sensitivity_tolerance_percent", spec.sensitivity_tolerance_percent),
            ("max_tilt_deg", spec.max_tilt_deg),
            ("max_non_orthogonality_deg", spec.max_non_orthogonality_deg),
            ("max_arw_deg_per_sqrt_h", spec.max_arw_deg_per_sqrt_h),
        ] {
            if v.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
                anyhow::bail!("{}: {name} must be a positive number", path.display());
            }
        }
        Ok(spec)
    }

    /// Every limit given, against the report (and the noise figures, when there are some: a
    /// noise limit without a static run fails, for want of a measurement).
    pub fn check(&self, r: &CalReport, noise: Option<&NoiseReport>) -> Vec<Check> {
        let mut out = Vec::new();
        let mut push = |what: String, value: f64, limit: f64, unit| {
            out.push(Check { what, value, limit, unit, pass: value <= limit });
        };
        for a in &r.axes {
            if let Some(l) = self.sensitivity_tolerance_percent {
                push(format!("sensitivity {} vs nominal", a.axis), a.k_vs_nominal_percent.abs(), l, "%");
            }
            if let Some(l) = self.max_tilt_deg {
                push(format!("tilt {}", a.axis), a.tilt_deg.value.abs(), l, "°");
            }
        }
        if let Some(l) = self.max_non_orthogonality_deg {
            for ia in &r.inter_axis {
                push(
                    format!("non-orthogonality {}–{}", ia.axes[0], ia.axes[1]),
                    ia.non_orthogonality_deg.abs(),
                    l,
                    "°",
                );
            }
        }
        if let Some(l) = self.max_arw_deg_per_sqrt_h {
            match noise {
                Some(n) => {
                    for a in &n.axes {
                        push(format!("ARW {}", a.axis), a.arw_deg_per_sqrt_h, l, "°/√h");
                    }
                }
                None => push("ARW (no static run: not measured)".into(), f64::INFINITY, l, "°/√h"),
            }
        }
        out
    }
}

/// All pass.
pub fn passed(checks: &[Check]) -> bool {
    checks.iter().all(|c| c.pass)
}

/// The summary's lines.
pub fn text(checks: &[Check]) -> String {
    let mut o = format!("Specification: {}\n", if passed(checks) { "PASS" } else { "FAIL" });
    for c in checks {
        let _ = writeln!(
            o,
            "  {:4}  {}: {:.4} {} {} {} {}",
            if c.pass { "PASS" } else { "FAIL" },
            c.what,
            c.value,
            c.unit,
            if c.pass { "≤" } else { ">" },
            c.limit,
            c.unit
        );
    }
    o
}

/// The certificate's section.
pub fn html_section(checks: &[Check]) -> String {
    let mut o = format!(
        "<section class=\"certificate\">\n<h2>Specification: {}</h2>\n<table>\n<tr><th scope=\"col\">result</th><th scope=\"col\">quantity</th><th scope=\"col\">measured</th><th scope=\"col\">limit</th></tr>\n",
        if passed(checks) { "PASS" } else { "FAIL" }
    );
    for c in checks {
        let _ = writeln!(
            o,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            if c.pass { "PASS" } else { "FAIL" },
            escape(&c.what),
            escape(&format!("{:.4} {}", c.value, c.unit)),
            escape(&format!("{} {}", c.limit, c.unit))
        );
    }
    o.push_str("</table>\n<p>Decision rule: simple acceptance (ILAC-G8): a result passes when its measured value is within the limit; its expanded uncertainty is in the results table.</p>\n</section>\n");
    o
}
