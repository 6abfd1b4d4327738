//! The diagnostics in words: each finding as one sentence (what, where, how large, what it
//! suggests), and the notes on clipping and on the speed-ripple check.

use crate::calib::analysis::diagnostics::{Diagnostics, Finding, FindingKind};
use crate::calib::result::axes::AXES;
use crate::geometry::Pose;
use std::fmt::Write as _;

/// How a run is named in a sentence.
fn run_label(run: usize, pose: Pose, commanded_rate_dps: f64) -> String {
    format!("run {run} ({pose}, {commanded_rate_dps:+.0} °/s)")
}

/// What a kind of structure is called.
fn describe(kind: FindingKind) -> String {
    match kind {
        FindingKind::RunOffset => "Run-to-run offset (mean residual)".into(),
        FindingKind::Harmonic(n) => format!("Residual at {n}× the sensor-table rate"),
        FindingKind::NotWhite => "Residual not white (Ljung–Box on 40-ms block means)".into(),
        FindingKind::TimeDrift => "Residual drifting in time (10-s means)".into(),
        FindingKind::Temperature => "Residual following the temperature".into(),
        FindingKind::RateDependence => "Residual depending on |rate along the axis|".into(),
        FindingKind::SpeedRipple => "Residual following the speed ripple".into(),
        FindingKind::RmsExcess => "Residual RMS above the noise floor".into(),
    }
}

/// What a kind of structure suggests.
fn suggestion(kind: FindingKind) -> &'static str {
    match kind {
        FindingKind::RunOffset => {
            "the offset differs between runs: offset drift (warm-up or temperature), or the constant θ2'·M R_qᵀ e_z2 term is mis-modelled"
        }
        FindingKind::Harmonic(1) => {
            "the axes look turned about z2 differently in different runs: a delay between gyro and encoder (phase grows with θ2') or an index offset (same phase at every speed)"
        }
        FindingKind::Harmonic(_) => {
            "a harmonic of the sensor-table rate: rate-dependent scale if it follows each axis's own rate, table-speed ripple if every axis shows it in proportion to M R_qᵀ e_z2, otherwise something outside the catalogue"
        }
        FindingKind::NotWhite => "the residual is correlated in time beyond the sensor noise: unmodelled structure",
        FindingKind::TimeDrift => "the offset changes within the run: drift with time (warm-up) or with temperature",
        FindingKind::Temperature => "the offset follows the die temperature",
        FindingKind::RateDependence => "the output depends on the rate along the axis beyond the linear scale: non-linearity, asymmetry, or clipping",
        FindingKind::SpeedRipple => "the residual follows the motor's speed ripple: the encoder-derived rate does not track the table",
        FindingKind::RmsExcess => "the residual is larger than the noise floor measured from the data",
    }
}

/// One finding as a sentence: what, on which axes in which runs, the largest instance, and what
/// it suggests.
pub fn finding(f: &Finding) -> String {
    let mut text = describe(f.kind);
    text.push_str(": ");
    let per_axis: Vec<String> = (0..3)
        .filter_map(|a| {
            let runs: Vec<String> = f.places.iter().filter(|p| p.1 == a).map(|p| p.0.to_string()).collect();
            (!runs.is_empty()).then(|| format!("{} in run {}", AXES[a], runs.join(", ")))
        })
        .collect();
    text.push_str(&per_axis.join("; "));
    let w = &f.worst;
    let _ = write!(
        text,
        ". Largest: {:.4} {} on {} in {}",
        w.size,
        f.kind.unit(),
        AXES[w.axis],
        run_label(w.run, w.pose, w.commanded_rate_dps)
    );
    match w.sigma {
        Some(sigma) => {
            let _ = write!(text, " ({sigma:.0}σ)");
        }
        None => {
            let _ = write!(text, " (RMS {:.4} vs floor {:.4} °/s)", w.rms_dps, w.floor_dps);
        }
    }
    let _ = write!(text, ". Suggests: {}.", suggestion(f.kind));
    text
}

/// Every finding of `d` as a sentence.
pub fn findings(d: &Diagnostics) -> Vec<String> {
    d.findings.iter().map(finding).collect()
}

/// Sentences about clipping and the speed-ripple check, which are not structure.
pub fn notes(d: &Diagnostics) -> Vec<String> {
    let mut out = Vec::new();
    let clipped: [u64; 3] = std::array::from_fn(|a| d.runs.iter().map(|r| r.axes[a].clipped).sum());
    if clipped.iter().any(|&c| c > 0) {
        out.push(format!(
            "Clipping: {} / {} / {} samples on x / y / z sat at the output rails and were left out of that axis; a larger full scale avoids it.",
            clipped[0], clipped[1], clipped[2]
        ));
    }
    let dev = d.runs.iter().flat_map(|r| r.axes.first()).map(|a| a.speed_deviation_rms_percent).fold(0.0f64, f64::max);
    let (mut worst, mut at) = (0.0f64, String::new());
    for r in &d.runs {
        for a in &r.axes {
            if a.ripple.sigma.is_finite() && a.ripple.sigma > worst {
                worst = a.ripple.sigma;
                at = format!("{} in {}", a.axis, run_label(r.run, r.pose, r.commanded_rate_dps));
            }
        }
    }
    let rippling = d.runs.iter().any(|r| r.axes.iter().any(|a| a.ripple.significant));
    if rippling {
        out.push(format!(
            "Speed ripple check: the encoder-derived speed deviates {dev:.3} % rms from steady at most, and the residual (table harmonics removed) follows it {worst:.1}σ beyond the echo of the rate estimate's own noise on {at}: the kinematics may not track the table."
        ));
    } else {
        out.push(format!(
            "Speed ripple check: the encoder-derived speed deviates {dev:.3} % rms from steady at most; the residual does not follow it beyond the echo of the rate estimate's own noise (largest {worst:.1}σ), so the kinematics track it."
        ));
    }
    out
}
