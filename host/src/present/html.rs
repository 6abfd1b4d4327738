//! The loop's HTML report: verdict, findings, the before/after table, the final calibration, and
//! per run and axis the fit and residual against θ2 and the residual spectrum with the table
//! harmonics marked, before (linear model) and after (final model). Written with
//! `crate::report`'s primitives as `report.html` with the SVGs beside it.

use super::{findings, loop_text, PlusMinus};
use crate::calib::analysis::closure::{LoopReport, Verdict};
use crate::calib::analysis::diagnostics::{Diagnostics, RunDiag};
use crate::calib::result::axes::AXES;
use crate::report::{
    palette, spectra_plot, theta2_panel, Document, Marker, PlotSpec, Spectrum, Theta2Bins, Theta2Spec,
};
use std::io;
use std::path::{Path, PathBuf};

/// Harmonics of the sensor-table rate marked on the spectra (the catalogue's 1×–8× and two
/// beyond).
const MARKED_HARMONICS: u32 = 10;

fn theta2_bins(d: &RunDiag, axis: usize, label: &str, colour: usize) -> Theta2Bins {
    let c = &d.plots.theta2[axis];
    Theta2Bins {
        label: label.into(),
        colour,
        theta2_deg: c.theta2_deg.clone(),
        measured: c.fit_dps.iter().zip(&c.residual_dps).map(|(f, r)| f + r).collect(),
        model: c.fit_dps.clone(),
        residual: c.residual_dps.clone(),
        residual_se: c.residual_se_dps.clone(),
        counts: c.counts.clone(),
        noise_floor: Some(d.axes[axis].floor_dps),
    }
}

fn spectrum(d: &RunDiag, axis: usize, label: &str, colour: usize) -> Spectrum {
    let s = &d.plots.spectrum[axis];
    Spectrum { label: label.into(), freqs_hz: s.freq_hz.clone(), amp_dps: s.amplitude_dps.clone(), colour }
}

fn markers(d: &RunDiag) -> Vec<Marker> {
    let mut m: Vec<Marker> = (1..=MARKED_HARMONICS)
        .map(|k| Marker { freq_hz: f64::from(k) * d.plots.table_hz, label: format!("{k}×") })
        .collect();
    // The base table's harmonics coincide with the sensor table's at the nominal 1:1 ratio;
    // marked separately only where they differ by more than a resolution bin.
    if (d.plots.base_hz - d.plots.table_hz).abs() > 1e-3 * d.plots.table_hz {
        m.extend(
            (1..=MARKED_HARMONICS)
                .map(|k| Marker { freq_hz: f64::from(k) * d.plots.base_hz, label: format!("{k}×θ1") }),
        );
    }
    m
}

fn run_title(d: &RunDiag, axis: usize) -> String {
    format!("Axis {}, run {} ({}, {:+.0} °/s)", AXES[axis], d.run, d.pose, d.commanded_rate_dps)
}

fn figures(doc: &mut Document, before: &Diagnostics, after: &Diagnostics, changed: bool) {
    for (b, a) in before.runs.iter().zip(&after.runs) {
        for axis in 0..3 {
            let mut curves = Vec::new();
            if changed {
                curves.push(theta2_bins(b, axis, "before", palette::BEFORE));
            }
            curves.push(theta2_bins(a, axis, "after", palette::AFTER));
            doc.figure_result(
                theta2_panel(&Theta2Spec::new(run_title(a, axis), "°/s"), &curves),
                format!(
                    "{}: fit and measured bin means (top), residual ±1 SE and ±floor/√n (bottom), against θ2.",
                    run_title(a, axis)
                ),
            );
            let mut spectra = Vec::new();
            if changed {
                spectra.push(spectrum(b, axis, "before", palette::BEFORE));
            }
            spectra.push(spectrum(a, axis, "after", palette::AFTER));
            doc.figure_result(
                spectra_plot(
                    &PlotSpec::new(run_title(a, axis), "frequency [Hz]", "residual amplitude [°/s]"),
                    &spectra,
                    &markers(a),
                    None,
                ),
                format!(
                    "{}: residual amplitude spectrum, harmonics of the sensor-table rate marked.",
                    run_title(a, axis)
                ),
            );
        }
    }
}

/// Writes `dir/report.html` and its SVGs; returns the HTML's path.
pub fn write_report(dir: &Path, lr: &LoopReport) -> io::Result<PathBuf> {
    let mut doc = Document::new("Gyro calibration: closed loop");
    let kind = match lr.verdict {
        Verdict::AtNoiseFloor => crate::report::Verdict::Ok,
        Verdict::UnexplainedStructure => crate::report::Verdict::Error,
    };
    doc.verdict(kind, loop_text::verdict(lr));
    doc.heading(2, "What the linear model left in the residual");
    if lr.initial.findings.is_empty() {
        doc.paragraph("Nothing: the residual of the linear model is at the noise floor.");
    } else {
        doc.findings(lr.initial.findings.iter().map(findings::finding));
    }
    doc.heading(2, "Effects added, and the error before and after");
    let truth = lr.steps.iter().any(|s| s.truth.is_some());
    let mut headers = vec!["model", "Δχ² (dof; threshold)", "RMS/floor x / y / z", "held-out error above floor [°/s]"];
    if truth {
        headers.extend(["direction error [°]", "sensitivity error [ppm]", "max |z|"]);
    }
    let rows = lr
        .steps
        .iter()
        .map(|s| {
            let mut row = vec![
                s.effect.map_or("linear model".into(), |e| format!("+ {}", e.name())),
                s.score
                    .as_ref()
                    .map_or("—".into(), |sc| format!("{:.1} ({}; {:.1})", sc.delta_chi2, sc.dof, sc.threshold)),
                (0..3).map(|a| format!("{:.3}", s.rms_dps[a] / s.floor_dps[a])).collect::<Vec<_>>().join(" / "),
                s.held_out_excess_dps.map_or("n/a".into(), |v| format!("{v:.4}")),
            ];
            if let Some(t) = &s.truth {
                row.extend([
                    format!("{:.5}", t.max_direction_deg()),
                    format!("{:.1}", t.max_sensitivity_ppm()),
                    format!("{:.2}", t.max_z()),
                ]);
            } else if truth {
                row.extend(["".into(), "".into(), "".into()]);
            }
            row
        })
        .collect();
    doc.table("One row per model, in the order the effects were added.", &headers, rows);
    if let Some(last) = lr.steps.last() {
        if !last.effect_params.is_empty() {
            doc.table(
                "Parameters of the effects in the final model.",
                &["parameter", "value", "1σ", "unit"],
                last.effect_params
                    .iter()
                    .map(|p| {
                        vec![
                            p.name.clone(),
                            format!("{:.5}", p.estimate.value),
                            format!("{:.5}", p.estimate.sigma),
                            p.unit.clone(),
                        ]
                    })
                    .collect(),
            );
        }
    }
    let cal = &lr.final_report;
    doc.heading(2, "Final calibration");
    doc.paragraph(format!("Model: {}.", cal.model));
    doc.table(
        "Per axis, with 1σ.",
        &["axis", "k [counts/(°/s)]", "tilt [°] ± runs ± mount", "offset [counts]", "direction s"],
        cal.axes
            .iter()
            .map(|a| {
                vec![
                    a.axis.to_string(),
                    format!("{:.5}", PlusMinus(a.k_counts_per_dps)),
                    format!("{:.4} ± {:.3}", PlusMinus(a.tilt_deg), a.tilt_mount_sigma_deg),
                    format!("{:+.3}", PlusMinus(a.offset_counts)),
                    format!("[{:+.6}, {:+.6}, {:+.6}]", a.s[0].value, a.s[1].value, a.s[2].value),
                ]
            })
            .collect(),
    );
    if !lr.asks.is_empty() {
        doc.heading(2, "Runs needed");
        doc.findings(loop_text::asks(lr));
    }
    let notes = loop_text::notes(lr);
    if !notes.is_empty() {
        doc.heading(2, "Notes");
        doc.findings(notes);
    }
    doc.heading(2, "Residual of the final model");
    if lr.final_diagnostics().findings.is_empty() {
        doc.paragraph("No structure found.");
    } else {
        doc.findings(lr.final_diagnostics().findings.iter().map(findings::finding));
    }
    doc.heading(2, "Fit and residual against θ2, residual spectra");
    figures(&mut doc, &lr.initial, lr.final_diagnostics(), lr.steps.len() > 1);
    doc.heading(2, "Full account");
    doc.preformatted(lr.summary());
    Ok(doc.write_with_svgs(dir, "report")?.html)
}
