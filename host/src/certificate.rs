//! The results part of the calibration certificate in `report.html`: each result with its
//! standard uncertainty and its expanded uncertainty at k = 2 in the GUM's wording, the angles
//! between the axes, the correction matrix a firmware applies, and the sensor's previous
//! calibrations from the records with each change in units of the combined σ.

use crate::calib::CalReport;
use crate::records::views::History;
use crate::report::html::escape;
use nalgebra::Matrix3;
use std::fmt::Write as _;

/// Coverage factor of the expanded uncertainty: k = 2, about 95 % for a normal distribution
/// (JCGM 100:2008, GUM §6.2-6.3; EA-4/02 M asks calibration certificates for it).
pub const COVERAGE_FACTOR: f64 = 2.0;

/// The statement EA-4/02 M (Expression of the Uncertainty of Measurement in Calibration) gives
/// for a certificate's expanded uncertainty.
pub const GUM_STATEMENT: &str = "The reported expanded uncertainty of measurement is stated as the standard \
uncertainty of measurement multiplied by the coverage factor k = 2, which for a normal distribution corresponds \
to a coverage probability of approximately 95 %. The standard uncertainty has been determined in accordance with \
the GUM (JCGM 100:2008); it includes the plausible size of every catalogued effect the runs could not separate.";

fn row(o: &mut String, cells: &[String]) {
    o.push_str("<tr>");
    for c in cells {
        let _ = write!(o, "<td>{}</td>", escape(c));
    }
    o.push_str("</tr>\n");
}

fn head(o: &mut String, cells: &[&str]) {
    o.push_str("<tr>");
    for c in cells {
        let _ = write!(o, "<th scope=\"col\">{}</th>", escape(c));
    }
    o.push_str("</tr>\n");
}

/// The certificate's results section, ending with the sensor's `history`.
pub fn html_section(r: &CalReport, history: &History) -> String {
    let k = COVERAGE_FACTOR;
    let mut o = String::from("<section class=\"certificate\">\n<h2>Results with expanded uncertainty (k = 2)</h2>\n");
    o.push_str("<table>\n");
    head(&mut o, &["axis", "quantity", "value", "standard uncertainty u", "expanded uncertainty U (k = 2)", "unit"]);
    for a in &r.axes {
        let ax = a.axis.to_string();
        let s = a.k_counts_per_dps;
        row(
            &mut o,
            &[
                ax.clone(),
                "sensitivity".into(),
                format!("{:.5}", s.value),
                format!("{:.5}", s.sigma),
                format!("{:.5}", k * s.sigma),
                "counts/(°/s)".into(),
            ],
        );
        // The datasheet's unit: mdps/LSB = 1000 / k; its uncertainty by first-order propagation.
        let mdps = 1000.0 / s.value;
        let u_mdps = mdps * s.sigma / s.value;
        row(
            &mut o,
            &[
                ax.clone(),
                "sensitivity (datasheet unit)".into(),
                format!("{mdps:.5}"),
                format!("{u_mdps:.5}"),
                format!("{:.5}", k * u_mdps),
                "mdps/LSB".into(),
            ],
        );
        // The tilt's u combines the runs' σ and the pose fixture's, independent.
        let u_tilt = a.tilt_deg.sigma.hypot(a.tilt_mount_sigma_deg);
        row(
            &mut o,
            &[
                ax.clone(),
                "tilt from the package axis".into(),
                format!("{:.4}", a.tilt_deg.value),
                format!("{u_tilt:.4}"),
                format!("{:.4}", k * u_tilt),
                "°".into(),
            ],
        );
        row(
            &mut o,
            &[
                ax,
                "offset (zero-rate level)".into(),
                format!("{:+.3}", a.offset_counts.value),
                format!("{:.3}", a.offset_counts.sigma),
                format!("{:.3}", k * a.offset_counts.sigma),
                "counts".into(),
            ],
        );
    }
    for ia in &r.inter_axis {
        row(
            &mut o,
            &[
                format!("{}–{}", ia.axes[0], ia.axes[1]),
                "angle between the axes".into(),
                format!("{:.4}", ia.angle_deg.value),
                format!("{:.4}", ia.angle_deg.sigma),
                format!("{:.4}", k * ia.angle_deg.sigma),
                "°".into(),
            ],
        );
    }
    o.push_str("</table>\n");
    let _ = writeln!(o, "<p>{}</p>", escape(GUM_STATEMENT));
    o.push_str("<h3>Correction applied by a firmware</h3>\n");
    let _ = writeln!(
        o,
        "<p>{}</p>",
        escape("ω = (K S)⁻¹ (v − v_off): the rate in the package frame, °/s, from the raw reading v, counts (what `host export` writes).")
    );
    let m = Matrix3::from_fn(|i, j| r.m_counts_per_dps[i][j]);
    o.push_str("<table>\n");
    head(&mut o, &["(K S)⁻¹ [°/s per count]", "x", "y", "z", "v_off [counts]"]);
    match m.try_inverse() {
        Some(inv) => {
            for (i, ax) in ['x', 'y', 'z'].iter().enumerate() {
                row(
                    &mut o,
                    &[
                        ax.to_string(),
                        format!("{:+.8e}", inv[(i, 0)]),
                        format!("{:+.8e}", inv[(i, 1)]),
                        format!("{:+.8e}", inv[(i, 2)]),
                        format!("{:+.4}", r.offset_counts[i]),
                    ],
                );
            }
        }
        None => row(
            &mut o,
            &["M is singular: no correction".into(), String::new(), String::new(), String::new(), String::new()],
        ),
    }
    o.push_str("</table>\n");
    o.push_str(&history_html(history));
    o.push_str("</section>\n");
    o
}

/// The sensor's previous calibrations: per record and axis the sensitivity and tilt then and
/// the change to this calibration in combined σ, and every parameter that moved beyond 3σ.
pub fn history_html(history: &History) -> String {
    let mut o = String::from("<h3>Previous calibrations of this sensor</h3>\n");
    let _ = writeln!(o, "<p>{}</p>", escape(&history.headline()));
    let rows = history.rows();
    if rows.is_empty() {
        return o;
    }
    o.push_str("<table class=\"history\">\n");
    let header = History::header();
    head(&mut o, &header.iter().map(String::as_str).collect::<Vec<_>>());
    for r in &rows {
        row(&mut o, r);
    }
    o.push_str("</table>\n<ul>\n");
    for l in history.beyond_lines() {
        let _ = writeln!(o, "<li>{}</li>", escape(&l));
    }
    o.push_str("</ul>\n");
    o
}
