//! The loop's account in plain text: what the linear model left, each effect added and what it
//! changed, the before/after table, the final calibration with σ, and the verdict.

use super::{advice, axis_table, findings, PlusMinus};
use crate::calib::analysis::closure::{LoopReport, Note, StepReport, Verdict};
use std::fmt::Write as _;

impl LoopReport {
    /// The readable account: findings, the before/after table, the final calibration, verdict.
    /// (Here rather than beside the type: the computation does not depend on its presentation.)
    pub fn summary(&self) -> String {
        summary(self)
    }
}

fn step_name(s: &StepReport) -> String {
    match s.effect {
        None if s.effects.is_empty() => "linear model".into(),
        None => format!("linear model + {}", s.effects.iter().map(|e| e.name()).collect::<Vec<_>>().join(" + ")),
        Some(e) => format!("+ {}", e.name()),
    }
}

fn triple(v: [f64; 3], digits: usize) -> String {
    v.iter().map(|x| format!("{x:.digits$}")).collect::<Vec<_>>().join(" / ")
}

/// The before/after table, one row per model: its name, then its figures on a line beneath
/// (one line per model was up to 127 characters wide).
pub fn table(r: &LoopReport) -> String {
    let mut o = String::new();
    for s in &r.steps {
        let ratio: [f64; 3] = std::array::from_fn(|a| s.rms_dps[a] / s.floor_dps[a]);
        let ho = s.held_out_excess_dps.map_or("n/a".to_string(), |v| format!("{v:.4} °/s"));
        let _ = write!(o, "  {}\n      RMS/floor x / y / z {}, held-out {ho}", step_name(s), triple(ratio, 3));
        if let Some(t) = &s.truth {
            let _ = write!(
                o,
                "\n      against the truth: dir err {:.5}°, sens err {:.1} ppm, max z {:.2}",
                t.max_direction_deg(),
                t.max_sensitivity_ppm(),
                t.max_z()
            );
        }
        o.push('\n');
    }
    o
}

/// The whole account.
pub fn summary(r: &LoopReport) -> String {
    let mut o = String::new();
    let cal = &r.final_report;
    let _ = writeln!(o, "Closed-loop calibration of {} runs ({} samples used).", cal.runs.len(), cal.samples_used);
    let _ = writeln!(o, "\nWhat the linear model left in the residual:");
    if r.initial.findings.is_empty() {
        let _ = writeln!(o, "  nothing: residual at the noise floor.");
    }
    for f in &r.initial.findings {
        let _ = writeln!(o, "  - {}", findings::finding(f));
    }
    for s in r.steps.iter().skip(1) {
        let Some(sc) = &s.score else { continue };
        if sc.known_physics {
            let _ = writeln!(
                o,
                "\nStep {}: {} — added without a test (Δχ² = {:.1} for {} parameters): present in every lab, only its orientation is unknown. Means: {}.",
                s.number,
                step_name(s),
                sc.delta_chi2,
                sc.dof,
                sc.effect.meaning()
            );
        } else {
            let _ = writeln!(
                o,
                "\nStep {}: {} — Δχ² = {:.1} for {} parameters (threshold {:.1}, {:.1}σ). Means: {}.",
                s.number,
                step_name(s),
                sc.delta_chi2,
                sc.dof,
                sc.threshold,
                sc.significance_sigma,
                sc.effect.meaning()
            );
        }
        let others: Vec<String> = s
            .alternatives
            .iter()
            .filter(|a| a.effect != sc.effect || a.drift_tau_s != sc.drift_tau_s)
            .take(3)
            .map(|a| match a.drift_tau_s {
                Some(t) => format!("{} (T = {t} s) Δχ² {:.1}", a.effect.name(), a.delta_chi2),
                None => format!("{} Δχ² {:.1}", a.effect.name(), a.delta_chi2),
            })
            .collect();
        if !others.is_empty() {
            let _ = writeln!(o, "  next best (linearised): {}", others.join("; "));
        }
        if !s.drift_choice.is_empty() {
            let c: Vec<String> = s
                .drift_choice
                .iter()
                .map(|d| format!("{} BIC {:.1}{}", d.effect.name(), d.bic, if d.fitted { "" } else { " (linearised)" }))
                .collect();
            let _ = writeln!(o, "  drift models compared (lowest BIC kept): {}", c.join("; "));
        }
        for e in &s.replaced {
            let why = if e.is_drift() {
                "the residual still drifted with it in the model"
            } else {
                "its only trace, a constant rate in each run, is now each run's own level"
            };
            let _ = writeln!(o, "  replaces: {} ({why})", e.name());
        }
        for d in &s.dropped {
            let _ = writeln!(
                o,
                "  dropped: {} (its parameters' Wald χ² {:.1} < {:.1}): with {} in the model the runs no longer need it",
                d.effect.name(),
                d.wald_chi2,
                d.threshold,
                d.after.name()
            );
        }
        for p in &s.effect_params {
            let _ = writeln!(o, "  {} = {:.5} {}", p.name, PlusMinus(p.estimate), p.unit);
        }
        let prev = &r.steps[s.number - 1];
        let _ = writeln!(
            o,
            "  residual RMS x / y / z: {} → {} °/s (floor {})",
            triple(prev.rms_dps, 4),
            triple(s.rms_dps, 4),
            triple(s.floor_dps, 4)
        );
        let mut moves = s.moves.clone();
        moves.sort_by(|a, b| b.moved_sigma.abs().total_cmp(&a.moved_sigma.abs()));
        let top: Vec<String> = moves.iter().take(3).map(|m| format!("{} {:+.1}σ", m.name, m.moved_sigma)).collect();
        let _ = writeln!(o, "  base parameters moved most: {}", top.join(", "));
        match (prev.held_out_excess_dps, s.held_out_excess_dps) {
            (Some(b), Some(a)) => {
                let _ = writeln!(
                    o,
                    "  held-out prediction (fit the other runs, predict each run), error above the floor: {b:.4} → {a:.4} °/s"
                );
            }
            _ => {
                let _ = writeln!(o, "  held-out prediction: not available (the remaining runs cannot fit the model)");
            }
        }
        if let (Some(b), Some(a)) = (&prev.truth, &s.truth) {
            let _ = writeln!(
                o,
                "  against the truth: direction {:.5} → {:.5}°, sensitivity {:.1} → {:.1} ppm (max |z| {:.2} → {:.2})",
                b.max_direction_deg(),
                a.max_direction_deg(),
                b.max_sensitivity_ppm(),
                a.max_sensitivity_ppm(),
                b.max_z(),
                a.max_z()
            );
        }
    }
    let _ = writeln!(o, "\nBefore and after:\n{}", table(r));
    let _ = writeln!(o, "Final calibration ({}):", cal.model);
    axis_table::write(&mut o, cal);
    for p in &cal.inter_axis {
        let _ = writeln!(o, "  angle {}–{}: {:.4}°", p.axes[0], p.axes[1], PlusMinus(p.angle_deg));
    }
    let _ = writeln!(
        o,
        "  The angles between the axes (intrinsic) rest on the runs alone. The tilts from the package axes (extrinsic) also rest on the fixture, which holds the package to ±{}° (σ {:.3}° per component): a turn of it common to both poses moves all three axes alike and no run can reveal it, so the mount, not the runs, limits them.",
        crate::calib::result::derived::MOUNT_TOLERANCE_DEG,
        crate::calib::result::derived::mount_sigma_deg()
    );
    if let Some(last) = r.steps.last() {
        if !last.effect_params.is_empty() {
            let _ = writeln!(o, "  effects:");
            for p in &last.effect_params {
                let _ = writeln!(o, "    {} = {:.5} {}", p.name, PlusMinus(p.estimate), p.unit);
            }
        }
    }
    let notes = notes(r);
    if !notes.is_empty() {
        let _ = writeln!(o, "\nNotes:");
        for n in &notes {
            let _ = writeln!(o, "  - {n}");
        }
    }
    if !r.skipped.is_empty() {
        let _ = writeln!(o, "\nCandidates skipped (passed the test, could not be fitted):");
        for sk in &r.skipped {
            let _ = writeln!(o, "  - {}: {}", sk.effect.name(), sk.why);
        }
    }
    if !r.asks.is_empty() {
        let _ = writeln!(o, "\nRuns needed:");
        for a in &asks(r) {
            let _ = writeln!(o, "  - {a}");
        }
    }
    let _ = writeln!(o, "\nResidual of the final model:");
    if r.final_diagnostics().findings.is_empty() {
        let _ = writeln!(o, "  only noise: no test of the residual found a pattern the model misses.");
    }
    for f in &r.final_diagnostics().findings {
        let _ = writeln!(o, "  - {}", findings::finding(f));
    }
    let tag = match r.verdict {
        Verdict::AtNoiseFloor => "VERDICT: calibrated, residual at the noise floor.",
        Verdict::UnexplainedStructure if r.unvouched.is_some() => {
            "VERDICT: NOT VOUCHED FOR — do not trust this calibration."
        }
        Verdict::UnexplainedStructure => "VERDICT: UNEXPLAINED STRUCTURE — do not trust this calibration.",
    };
    let _ = writeln!(o, "\n{tag}\n{}", verdict(r));
    o
}

/// The notes: the final diagnostics' (clipping, speed ripple), then the loop's.
pub fn notes(r: &LoopReport) -> Vec<String> {
    findings::notes(r.final_diagnostics()).into_iter().chain(r.notes.iter().map(advice::note)).collect()
}

/// The runs asked for, in words.
pub fn asks(r: &LoopReport) -> Vec<String> {
    r.asks.iter().map(advice::ask).collect()
}

/// What the data hold that the model does not explain, in words: an Earth rate beyond the
/// Earth's, the runs' disagreement, the final residual's findings.
fn structure(r: &LoopReport) -> Vec<String> {
    r.earth_excess
        .iter()
        .map(advice::earth_excess)
        .chain(r.consistency.iter().filter(|c| c.disagrees()).map(advice::disagreement))
        .chain(r.final_diagnostics().findings.iter().map(findings::finding))
        .collect()
}

/// Whether the runs cannot tell the model's g-sensitivity from a change of M with speed.
fn held_by_gravity(r: &LoopReport) -> bool {
    r.notes.iter().any(Note::flags)
}

/// The verdict in words: the residual against the floor, or what is left unexplained.
pub fn verdict(r: &LoopReport) -> String {
    let d = r.final_diagnostics();
    match r.verdict {
        Verdict::AtNoiseFloor => {
            let ratio: Vec<String> = (0..3).map(|a| format!("{:.3}", d.rms_dps[a] / d.floor_dps[a])).collect();
            format!(
                "Calibrated, residual at the noise floor: RMS/floor x, y, z = {}; no test of the residual found a pattern ({} tests, false-alarm rate {} for all together).",
                ratio.join(", "),
                d.tests,
                r.alpha
            )
        }
        Verdict::UnexplainedStructure if r.unvouched.is_some() => format!(
            "DO NOT TRUST THIS CALIBRATION: nothing vouches for the fit ({}): a figure the verdict rests on is not a number, or the fit is not at its minimum. The numbers below are the model's last values, not a characterisation of the sensor.",
            r.unvouched.as_deref().unwrap_or_default()
        ),
        Verdict::UnexplainedStructure if held_by_gravity(r) && structure(r).is_empty() => {
            "DO NOT TRUST THIS CALIBRATION: these runs cannot tell the g-sensitivity the model took from a change of M with speed (see the notes); runs in the other direction can (--rates-dps 180,90,-180). The numbers below are the best fit of the model, not a characterisation of the sensor.".into()
        }
        Verdict::UnexplainedStructure => {
            let what = structure(r);
            format!(
                "DO NOT TRUST THIS CALIBRATION: the data hold a pattern that is not noise and that no effect this program knows explains. {} The numbers below are the best fit of the model, not a characterisation of the sensor.",
                what.join(" ")
            )
        }
    }
}
