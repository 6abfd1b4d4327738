//! Acceptance bars of the calibration on simulated captures without extra effects (2 poses ×
//! 120 s at 0.5 Hz, 10 seeds), decoded from the simulator's wire bytes.

use super::*;
use crate::calib::result::derived::mahalanobis2;
use crate::capture::decode;
use crate::sim::{simulate, SimConfig, Truth};

/// Seeds and run length of the bar.
const SEEDS: u64 = 10;
const DURATION_S: f64 = 120.0;

/// |z| bound "within 3σ" for one-dimensional estimates.
const Z_1D: f64 = 3.0;

/// The 2-D equivalent of 3σ for a direction: the Mahalanobis radius with the same 99.73 %
/// coverage, √(−2 ln 0.0027) = 3.44 (the χ² with 2 degrees of freedom is exponential).
const Z_2D: f64 = 3.44;

struct SeedResult {
    truth: Truth,
    report: CalReport,
}

fn run_seed(seed: u64) -> SeedResult {
    let out = simulate(&SimConfig::standard(seed, DURATION_S)).unwrap();
    let capture = decode(&out.bytes);
    assert!(capture.loss.is_clean(), "seed {seed}: {:?}", capture.loss);
    let report = calibrate(&capture.runs, &CalOptions::default()).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
    SeedResult { truth: out.truth, report }
}

fn all_seeds() -> Vec<SeedResult> {
    (1..=SEEDS).map(run_seed).collect()
}

/// The parameters' z-scores (estimate − truth)/σ: M entries and offsets, in `cov` order.
fn parameter_z(r: &SeedResult) -> Vec<f64> {
    let rep = &r.report;
    (0..12)
        .map(|p| {
            let (i, j) = (p / 4, p % 4);
            let (est, truth) = if j < 3 {
                (rep.m_counts_per_dps[i][j], r.truth.m_counts_per_dps[i][j])
            } else {
                (rep.offset_counts[i], r.truth.offset_counts[i])
            };
            (est - truth) / rep.cov[p][p].sqrt()
        })
        .collect()
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|z| z * z).sum::<f64>() / v.len() as f64).sqrt()
}

/// One test for all the bars, so the 10 simulations run once (≈3.8 M samples).
#[test]
fn simulated_captures_meet_the_acceptance_bars() {
    let results = all_seeds();
    let mut zs = Vec::new();
    let mut paper_max = 0.0f64;
    for r in &results {
        let rep = &r.report;
        let seed = r.truth.seed;
        for (i, a) in rep.axes.iter().enumerate() {
            // Sensitivity within 3σ.
            let zk = a.k_counts_per_dps.z(r.truth.k_counts_per_dps[i]);
            assert!(zk.abs() <= Z_1D, "seed {seed} axis {}: k z = {zk:.2}\n{}", a.axis, rep.summary());
            // Direction within the 2-D 3σ ellipse of its tilt components.
            let s = r.truth.s[i];
            let (j, l) = ((i + 1) % 3, (i + 2) % 3);
            let truth_tilt = [s[j].atan2(s[i]).to_degrees(), s[l].atan2(s[i]).to_degrees()];
            let d = [a.tilt_components_deg[0] - truth_tilt[0], a.tilt_components_deg[1] - truth_tilt[1]];
            let md = mahalanobis2(d, a.tilt_components_cov_deg2);
            assert!(md <= Z_2D, "seed {seed} axis {}: direction {md:.2} σ off\n{}", a.axis, rep.summary());
        }
        zs.extend(parameter_z(r));
        let paper = rep.paper.as_ref().expect("paper cross-check");
        paper_max = paper_max.max(paper.max_abs_z);
        // Both methods agree within the paper method's 3σ (the scale `PaperCheck` documents).
        assert!(
            paper.max_abs_z <= Z_1D,
            "seed {seed}: paper vs joint max |z| {:.2}\n{}",
            paper.max_abs_z,
            rep.summary()
        );
        // No extra effects: the residual is the noise, so rms ≈ floor. The floor's estimate is
        // biased low by the noise's correlation over ≈ τ/80 of the window (< 3 %).
        for a in &rep.residuals {
            assert!((a.rms_over_floor - 1.0).abs() < 0.03, "seed {seed}: {a:?}");
        }
    }
    // 120 z-scores: if σ is right their RMS is 1 ± √(1/240) ≈ 1 ± 0.065; the bar is 0.8–1.2.
    let zr = rms(&zs);
    let zmax = zs.iter().fold(0.0f64, |m, z| m.max(z.abs()));
    eprintln!("pooled z rms {zr:.3}, max |z| {zmax:.2}, paper-vs-joint max |z| {paper_max:.2}");
    assert!((0.8..=1.2).contains(&zr), "pooled z RMS {zr:.3}");
}
