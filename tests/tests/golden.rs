//! The refactoring guard: closed-loop calibrations (what `host calibrate --replay` computes)
//! against their golden results in `tests/data/`, within tolerances far below σ: the committed
//! demo capture (the linear model, no effect added), and a simulated session of the default
//! design with every realistic effect on (the loop's steps, its consider terms and Earth). A faster or restructured path
//! need not reproduce the old one bit for bit; it must not move any answer by more than
//! [`VALUE_TOL_SIGMA`] of its σ, nor any σ by more than [`SIGMA_TOL_REL`], nor change the model
//! the loop chose or its verdict.
//!
//! After a change that moves the answer on purpose (a better model, not a refactoring), rewrite
//! the golden file with `GOLDEN_WRITE=1 cargo test -p e2e --test golden` and say why in the
//! commit.

use e2e::data;
use host::calib::{close_loop, LoopOptions};
use host::capture::{decode, Run};
use host::geometry::Pose;
use host::sim::{simulate, RunSpec, SimConfig};
use serde::{Deserialize, Serialize};

/// A value may move by this fraction of its σ: 1 % of σ is far below anything a user reads
/// (σ itself is known to ±10 % at best with these sample sizes), yet far above the rounding
/// differences of a reordered sum (≈ 1e-10 σ).
const VALUE_TOL_SIGMA: f64 = 0.01;
/// A σ may move by this fraction of itself.
const SIGMA_TOL_REL: f64 = 0.01;

#[derive(Debug, Serialize, Deserialize)]
struct Golden {
    /// The loop's verdict and the effects it added, in order.
    verdict: String,
    effects: Vec<String>,
    /// Per axis: (value, σ) of k (counts per °/s) and of the three components of s.
    k: Vec<(f64, f64)>,
    s: Vec<[(f64, f64); 3]>,
    /// M row-major, (value, σ) counts per °/s.
    m: Vec<(f64, f64)>,
}

/// Seed 11 of the simulator: both poses at 180, 90 and −180 °/s (`host calibrate`'s default
/// design), 30 s per run, every realistic effect on.
fn realistic_runs() -> Vec<Run> {
    let runs = [Pose::One, Pose::Two]
        .into_iter()
        .flat_map(|pose| [180.0, 90.0, -180.0].map(|rate_dps| RunSpec { pose, rate_dps, duration_s: 30.0 }))
        .collect();
    let mut cfg = SimConfig::with_runs(11, runs);
    for e in host::sim::Effects::REALISTIC {
        cfg.effects.enable(e).unwrap();
    }
    decode(&simulate(&cfg).expect("simulates").bytes).runs
}

fn current(runs: &[Run]) -> Golden {
    let r = close_loop(runs, &LoopOptions::default(), None).expect("calibrates");
    let rep = r.final_report();
    let pair = |e: host::calib::Estimate| (e.value, e.sigma);
    Golden {
        verdict: format!("{:?}", r.verdict()),
        effects: r.effects().iter().map(|e| e.key()).collect(),
        k: rep.axes.iter().map(|a| pair(a.k_counts_per_dps)).collect(),
        s: rep.axes.iter().map(|a| a.s.map(pair)).collect(),
        m: (0..9)
            .map(|i| {
                let (a, j) = (i / 3, i % 3);
                // The base parameters are M's row and the offset per axis: 4 per axis.
                (rep.m_counts_per_dps[a][j], rep.cov[4 * a + j][4 * a + j].sqrt())
            })
            .collect(),
    }
}

/// Every (value, σ) pair of `now` against `then`; the mismatches, named.
fn compare(name: &str, now: &[(f64, f64)], then: &[(f64, f64)], out: &mut Vec<String>) {
    assert_eq!(now.len(), then.len(), "{name}");
    for (i, (&(v, s), &(v0, s0))) in now.iter().zip(then).enumerate() {
        let moved = (v - v0).abs() / s0;
        if moved.is_nan() || moved > VALUE_TOL_SIGMA {
            out.push(format!("{name}[{i}] = {v} moved {moved:.2e} σ from {v0} (σ {s0})"));
        }
        let rel = (s / s0 - 1.0).abs();
        if rel.is_nan() || rel > SIGMA_TOL_REL {
            out.push(format!("{name}[{i}]'s σ = {s} moved {rel:.2e} of itself from {s0}"));
        }
    }
}

#[test]
fn the_demo_calibration_matches_its_golden_result() {
    let cap = decode(&std::fs::read(data("demo.cap")).expect("demo.cap"));
    check(&current(&cap.runs), "demo.golden.json");
}

#[test]
fn a_realistic_session_calibrates_to_its_golden_result() {
    let now = current(&realistic_runs());
    assert!(now.effects.len() >= 4, "the loop added effects: {:?}", now.effects);
    check(&now, "realistic.golden.json");
}

fn check(now: &Golden, file: &str) {
    let path = data(file);
    if std::env::var("GOLDEN_WRITE").is_ok_and(|v| v == "1") {
        std::fs::write(&path, serde_json::to_string_pretty(now).unwrap() + "\n").unwrap();
    }
    let then: Golden = serde_json::from_str(&std::fs::read_to_string(&path).expect("the golden file"))
        .expect("the golden file parses");
    assert_eq!((&now.verdict, &now.effects), (&then.verdict, &then.effects));
    let mut off = Vec::new();
    compare("k", &now.k, &then.k, &mut off);
    let flat = |s: &[[(f64, f64); 3]]| s.iter().flatten().copied().collect::<Vec<_>>();
    compare("s", &flat(&now.s), &flat(&then.s), &mut off);
    compare("M", &now.m, &then.m, &mut off);
    assert!(off.is_empty(), "{off:#?}");
}

/// The comparison itself: a move of 2 % of σ in a value, or of 2 % in a σ, is caught.
#[test]
fn a_move_beyond_the_tolerance_is_caught() {
    let then = [(1.0, 0.1), (2.0, 0.1)];
    let mut off = Vec::new();
    compare("x", &[(1.0005, 0.1), (2.0, 0.1)], &then, &mut off);
    assert!(off.is_empty(), "{off:?}");
    compare("x", &[(1.002, 0.1), (2.0, 0.102)], &then, &mut off);
    assert_eq!(off.len(), 2, "{off:?}");
}
