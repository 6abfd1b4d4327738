//! Tests of the closed loop on simulated captures with effects the model was not told about.

use super::*;
use crate::calib::analysis::closure;
use crate::calib::analysis::closure::Note;
use crate::calib::analysis::diagnostics::FindingKind;
use crate::calib::data::kinematics;
use crate::calib::engine::{cells::CellForm, Col, Evaluator, Gram, LinCol, LoopData, Model, SharedPar};
use crate::calib::result::truth_check::TruthErrors;
use crate::capture::{decode, Run};
use crate::geometry::Pose;
use crate::sim::{simulate, RunSpec, SimConfig, Truth};
use protocol::FullScale;

/// The bar's drive rates: 0.5 Hz and 0.25 Hz (°/s of the base table).
const BAR_RATES_DPS: [f64; 2] = [180.0, 90.0];

/// Run length of the bar, s.
const BAR_DURATION_S: f64 = 120.0;

/// The bar's effects together: 5 ms delay, 3° index offset, warm-up drift, 0.5 % speed ripple.
const BAR_EFFECTS: [&str; 4] = ["delay_ms=5", "index_offset_deg=3", "offset_drift", "speed_ripple=0.005"];

/// Bars on the final calibration.
const MAX_DIRECTION_ERROR_DEG: f64 = 0.005;
const MAX_SENSITIVITY_ERROR_PPM: f64 = 50.0;

/// "Within 3σ": |z| for a sensitivity, and for a direction the 2-D Mahalanobis radius with the
/// same 99.73 % coverage, √(−2 ln 0.0027) = 3.44 (as in `acceptance_tests`).
const Z_1D: f64 = 3.0;
const Z_2D: f64 = 3.44;

/// Run length of the single-effect tests, s: 40 s is 20 table revolutions at 0.5 Hz, enough for
/// every effect at its default size to stand out by tens of σ, and keeps each test a few seconds.
const SHORT_S: f64 = 40.0;

/// Simulates pose 1 then pose 2, each at every rate in `rates_dps`, with `effects` switched on.
/// Both poses, each at `rates_dps` in turn, `duration_s` per run.
fn plan(rates_dps: &[f64], duration_s: f64) -> Vec<RunSpec> {
    Pose::ALL
        .iter()
        .flat_map(|&pose| rates_dps.iter().map(move |&rate_dps| RunSpec { pose, rate_dps, duration_s }))
        .collect()
}

fn capture_with(seed: u64, rates_dps: &[f64], duration_s: f64, effects: &[&str], fs: FullScale) -> (Vec<Run>, Truth) {
    let mut cfg = SimConfig::with_runs(seed, plan(rates_dps, duration_s));
    cfg.gyro.full_scale = fs;
    for e in effects {
        cfg.effects.enable(e).expect("known effect");
    }
    let out = simulate(&cfg).unwrap();
    let cap = decode(&out.bytes);
    assert!(cap.loss.is_clean());
    (cap.runs, out.truth)
}

/// Latitude of every simulated lab of these tests, degrees: Earth rotates under each of them (as
/// under every real rig), and the loop is told the latitude, as a lab would tell it.
const LAB_LATITUDE_DEG: f64 = 45.0;

fn run_loop(seed: u64, rates_dps: &[f64], duration_s: f64, effects: &[&str]) -> (LoopReport, Truth) {
    let earth = format!("earth_rotation={LAB_LATITUDE_DEG}");
    let with_earth: Vec<&str> = effects.iter().copied().chain([earth.as_str()]).collect();
    let (runs, truth) = capture_with(seed, rates_dps, duration_s, &with_earth, FullScale::Dps500);
    let opts = LoopOptions { latitude_deg: Some(LAB_LATITUDE_DEG), ..LoopOptions::default() };
    let report = close_loop(&runs, &opts, Some(truth.sensor())).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
    (report, truth)
}

/// The loop's result on every seed, two threads (the bar's 10 captures take a while in the test
/// profile).
fn seeds_in_parallel<T: Send>(seeds: std::ops::RangeInclusive<u64>, f: impl Fn(u64) -> T + Sync) -> Vec<T> {
    let seeds: Vec<u64> = seeds.collect();
    let (a, b) = seeds.split_at(seeds.len() / 2);
    std::thread::scope(|s| {
        let h = s.spawn(|| a.iter().map(|&x| f(x)).collect::<Vec<_>>());
        let mut out: Vec<T> = b.iter().map(|&x| f(x)).collect();
        let mut first = h.join().expect("worker panicked");
        first.append(&mut out);
        first
    })
}

fn truth_of(step: &closure::StepReport) -> TruthErrors {
    step.truth.expect("simulated runs carry the truth")
}

fn assert_within_3_sigma(t: &TruthErrors, context: &str) {
    for a in 0..3 {
        assert!(t.direction_z[a] <= Z_2D, "{context}: axis {a} direction {:.2}σ off", t.direction_z[a]);
        assert!(t.sensitivity_z[a].abs() <= Z_1D, "{context}: axis {a} sensitivity {:.2}σ off", t.sensitivity_z[a]);
    }
}

/// The issue's bar: 10 seeds, both poses at 0.5 and 0.25 Hz for 120 s, with a 5 ms delay, a 3°
/// index offset, warm-up drift and 0.5 % speed ripple, none of them declared.
#[test]
fn bar_combined_undeclared_effects_ten_seeds() {
    let results = seeds_in_parallel(1..=10, |seed| run_loop(seed, &BAR_RATES_DPS, BAR_DURATION_S, &BAR_EFFECTS));
    let (mut max_dir, mut max_ppm, mut max_z) = (0.0f64, 0.0f64, 0.0f64);
    for (r, truth) in &results {
        let ctx = format!("seed {}", truth.seed);
        let effects = r.effects();
        assert!(effects.contains(&Effect::Delay), "{ctx}: {effects:?}\n{}", r.summary());
        assert!(effects.contains(&Effect::IndexOffset), "{ctx}: {effects:?}");
        assert!(effects.iter().any(|e| e.is_drift()), "{ctx}: {effects:?}");
        assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{ctx}\n{}", r.summary());
        let t = truth_of(r.steps.last().expect("steps"));
        assert!(t.max_direction_deg() <= MAX_DIRECTION_ERROR_DEG, "{ctx}\n{}", r.summary());
        assert!(t.max_sensitivity_ppm() <= MAX_SENSITIVITY_ERROR_PPM, "{ctx}\n{}", r.summary());
        assert_within_3_sigma(&t, &ctx);
        max_dir = max_dir.max(t.max_direction_deg());
        max_ppm = max_ppm.max(t.max_sensitivity_ppm());
        max_z = max_z.max(t.max_z());
    }
    eprintln!("bar over 10 seeds: max direction error {max_dir:.5}°, max sensitivity error {max_ppm:.1} ppm, max |z| {max_z:.2}");
}

/// No effect on but Earth's rotation, which the base model holds: nothing is added and the
/// verdict is "at the noise floor", on every seed.
#[test]
fn clean_captures_add_nothing_and_pass() {
    let results = seeds_in_parallel(1..=10, |seed| run_loop(seed, &BAR_RATES_DPS, SHORT_S, &[]));
    for (r, truth) in &results {
        assert_eq!(r.effects(), [Effect::EarthRotationAtLatitude], "seed {}\n{}", truth.seed, r.summary());
        assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "seed {}\n{}", truth.seed, r.summary());
        assert!(r.initial.findings.is_empty(), "seed {}: {:?}", truth.seed, r.initial.findings);
        // Two speeds without gravity in the model: the runs' agreement checks a change of M
        // with speed.
        assert!(
            !r.notes
                .iter()
                .any(|n| matches!(n, Note::SpeedChangeUnchecked { .. } | Note::SpeedChangeHeldByGravity { .. })),
            "seed {}: {:?}",
            truth.seed,
            r.notes
        );
    }
}

/// (a) structure found, (b) the right effect named first, (c) within 3σ of the truth after it,
/// with the error `error` at least 10× smaller than with the linear model.
fn assert_single_effect(
    effect_spec: &str,
    expected: impl Fn(Effect) -> bool,
    structure: impl Fn(FindingKind) -> bool,
    error: impl Fn(&TruthErrors) -> f64,
) {
    assert_single_effect_gains(effect_spec, 10.0, expected, structure, error);
}

/// [`assert_single_effect`] with the error at least `gain`× smaller than with the linear model.
fn assert_single_effect_gains(
    effect_spec: &str,
    gain: f64,
    expected: impl Fn(Effect) -> bool,
    structure: impl Fn(FindingKind) -> bool,
    error: impl Fn(&TruthErrors) -> f64,
) {
    let (r, _) = run_loop(7, &BAR_RATES_DPS, SHORT_S, &[effect_spec]);
    assert!(
        r.initial.findings.iter().any(|f| structure(f.kind)),
        "{effect_spec}: expected structure not found\n{}",
        r.summary()
    );
    let first = r.steps.get(1).and_then(|s| s.effect).expect("an effect was added");
    assert!(expected(first), "{effect_spec}: added {first:?}\n{}", r.summary());
    let before = error(&truth_of(&r.steps[0]));
    let after = truth_of(r.steps.last().expect("steps"));
    assert!(error(&after) * gain <= before, "{effect_spec}: error {before} → {}\n{}", error(&after), r.summary());
    assert_within_3_sigma(&after, effect_spec);
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{effect_spec}\n{}", r.summary());
}

#[test]
fn undeclared_delay_is_found_named_and_corrected() {
    assert_single_effect(
        "delay_ms=5",
        |e| e == Effect::Delay,
        |k| k == FindingKind::Harmonic(1),
        |t| t.max_direction_deg(),
    );
}

#[test]
fn undeclared_index_offset_is_found_named_and_corrected() {
    assert_single_effect(
        "index_offset_deg=3",
        |e| e == Effect::IndexOffset,
        |k| k == FindingKind::Harmonic(1),
        |t| t.max_direction_deg(),
    );
}

#[test]
fn undeclared_warm_up_drift_is_found_named_and_corrected() {
    assert_single_effect(
        "offset_drift",
        |e| e.is_drift(),
        |k| matches!(k, FindingKind::RunOffset | FindingKind::TimeDrift),
        |t| t.max_direction_deg().max(t.max_sensitivity_ppm() * 1e-6f64.to_degrees()),
    );
}

#[test]
fn undeclared_nonlinearity_is_found_named_and_corrected() {
    assert_single_effect(
        "nonlinearity",
        |e| e == Effect::RateScale,
        |k| matches!(k, FindingKind::Harmonic(n) if n >= 2),
        |t| t.max_sensitivity_ppm(),
    );
}

/// A sense chain that saturates softly bends as r³, not as r·|r|. Fitted with r·|r| alone it was
/// 6.5-7.5σ off at exit 0 on the default design.
#[test]
fn undeclared_cubic_nonlinearity_is_found_named_and_corrected() {
    assert_single_effect_gains(
        "nonlinearity_cubic",
        10.0,
        |e| e == Effect::RatePower(3),
        |k| matches!(k, FindingKind::Harmonic(n) if n >= 2),
        |t| t.max_sensitivity_ppm(),
    );
}

/// IEEE Std 952's even square law (K2·ω²), which the asymmetry |r| only approximates: before it
/// was catalogued its speed-dependent M flagged every seed of the default design.
#[test]
fn undeclared_square_law_nonlinearity_is_found_named_and_corrected() {
    assert_single_effect(
        "nonlinearity_square",
        |e| e == Effect::RatePower(2),
        |k| matches!(k, FindingKind::Harmonic(n) if n >= 2),
        |t| t.max_sensitivity_ppm(),
    );
}

/// (d) A θ2 harmonic on one axis is in no catalogue entry: the result is flagged, with where
/// and how big, and not passed.
#[test]
fn out_of_catalogue_harmonic_is_flagged_untrusted() {
    let (r, _) = run_loop(5, &BAR_RATES_DPS, SHORT_S, &["mystery_harmonic=0.3", "delay_ms=5"]);
    assert_eq!(r.verdict(), Verdict::UnexplainedStructure, "{}", r.summary());
    let f = r
        .final_diagnostics()
        .findings
        .iter()
        .find(|f| f.kind == FindingKind::Harmonic(3))
        .unwrap_or_else(|| panic!("3× not reported\n{}", r.summary()));
    assert!(f.places.iter().any(|&(_, axis)| axis == 0), "{f:?}");
    // 0.3 °/s injected; whatever the catalogue absorbed, most of it is still there.
    assert!(f.max_dps > 0.1, "{f:?}");
    let verdict = crate::present::loop_text::verdict(&r);
    assert!(verdict.contains("DO NOT TRUST"), "{verdict}");
    assert!(r.summary().contains("UNEXPLAINED STRUCTURE"));
}

/// A package turned 0.03° on its mount at 180 °/s, growing with the square of the speed: M
/// changes with speed and no catalogued effect says why. Three signed speeds hold it, and the
/// runs at 90 °/s want another M than those at 180: the result is flagged with the
/// disagreement, not passed 30σ off (docs/trust.md, "M changing with speed").
#[test]
fn a_change_of_m_with_speed_is_flagged_by_the_runs_disagreement() {
    let (r, _) = run_loop(1, &[180.0, 90.0, -180.0], SHORT_S, &["mount_compliance"]);
    assert_eq!(r.verdict(), Verdict::UnexplainedStructure, "{}", r.summary());
    let c = r.consistency.as_ref().unwrap_or_else(|| panic!("no consistency test\n{}", r.summary()));
    assert!(c.disagrees(), "{c:?}");
    let slow = c.groups.iter().find(|g| (g.rate_dps - 90.0).abs() < 1.0).expect("the 90 °/s group");
    assert!(slow.max_z > 4.0, "{slow:?}");
    assert!(!r.notes.iter().any(|n| matches!(n, Note::SpeedChangeUnchecked { .. })), "{:?}", r.notes);
}

/// One speed, one direction: a delay is fitted as a combined phase, and the tool asks for the
/// run that separates it from an index offset.
#[test]
fn one_speed_fits_a_combined_phase_and_asks_for_a_second_speed() {
    let (r, truth) = run_loop(2, &[180.0], SHORT_S, &["delay_ms=5"]);
    assert_eq!(r.steps.get(1).and_then(|s| s.effect), Some(Effect::Phase), "{}", r.summary());
    let asks = crate::present::loop_text::asks(&r);
    assert!(asks.iter().any(|a| a.contains("--rates-dps 180,90")), "{asks:?}");
    // At one speed a change of M with speed is part of M: the notes say no run checked it.
    let unchecked = r.notes.iter().find_map(|n| match n {
        Note::SpeedChangeUnchecked { rate_dps } => Some(*rate_dps),
        _ => None,
    });
    assert!(unchecked.is_some_and(|v| (v - 180.0).abs() < 1.0), "{:?}", r.notes);
    // The combined phase corrects these runs: the calibration is right for them.
    let t = TruthErrors::of(&r.final_report().axes, &truth.sensor());
    assert_within_3_sigma(&t, "one speed");
}

/// A full scale too small: pose 1 at 220 °/s peaks at 220·(√6/3 + 1/√3) = 306 °/s, beyond the
/// ±250 °/s range's rails (32767 × 8.75 m°/s = 287 °/s). The clipped samples are left out and
/// counted, and the calibration stays right.
#[test]
fn clipped_samples_are_excluded_and_reported() {
    let (runs, truth) = capture_with(4, &[220.0], SHORT_S, &[], FullScale::Dps250);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    let clipped: u64 = r.final_report().clipped.iter().sum();
    assert!(clipped > 0, "nothing clipped");
    let notes = crate::present::loop_text::notes(&r);
    assert!(notes.iter().any(|n| n.starts_with("Clipping")), "{notes:?}");
    assert_within_3_sigma(&TruthErrors::of(&r.final_report().axes, &truth.sensor()), "clipped");
}

/// The report serialises, and its final calibration is what `apply` uses.
#[test]
fn loop_report_serialises_and_feeds_apply() {
    let (r, truth) = run_loop(6, &BAR_RATES_DPS, 20.0, &["index_offset_deg=3"]);
    let json = serde_json::to_string(&r).expect("serialises");
    let back: LoopReport = serde_json::from_str(&json).expect("deserialises");
    assert_eq!(back.verdict(), r.verdict());
    let dir = std::env::temp_dir().join(format!("loop-report-{}", std::process::id()));
    let html = crate::present::write_report(&dir, &r).expect("report written");
    let text = std::fs::read_to_string(&html).expect("readable");
    assert!(text.contains("<svg") && text.contains("index offset"), "report lacks figures or the effect");
    let _ = std::fs::remove_dir_all(&dir);
    let cal = r.final_report().calibration();
    // The calibration inverts the true M to within its σ-sized error: a true rate of 100 °/s
    // along x comes back within 0.01 °/s.
    let m = truth.m();
    let counts = m * nalgebra::Vector3::new(100.0, 0.0, 0.0) + truth.offset();
    let raw = [0, 1, 2].map(|i| counts[i].round() as i16);
    let w = cal.apply(raw);
    assert!((w[0] - 100.0).abs() < 0.05 && w[1].abs() < 0.05 && w[2].abs() < 0.05, "{w:?}");
}

/// A random walk of the offset that a quadratic curve takes first is then taken by the free
/// drift, which is scored in the curve's place (with both the sums are singular): the run
/// offsets and the drift the curve left are gone, the result is at the floor and within 3σ.
/// (Before, both seeds of the trust bench's cell ended flagged, structure left.)
#[test]
fn a_random_walk_a_curve_took_first_goes_to_the_free_drift() {
    let (runs, truth) =
        capture_with(1, &[180.0, 90.0, -180.0], BAR_DURATION_S, &["bias_random_walk"], FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    assert!(r.effects().iter().any(|e| e.is_free_drift()), "{}", r.summary());
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "random walk");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
    assert_drift_kept_by_bic(&r);
}

/// The drift step compared its alternatives by BIC: the model kept is the fitted one with the
/// lowest (or the free drift, where that one was a curve that biased M: its skip says so), and
/// each alternative left unfitted trailed it by at least the margin.
fn assert_drift_kept_by_bic(r: &LoopReport) {
    let step = r.steps.iter().find(|s| !s.drift_choice.is_empty()).expect("a step compared drift models");
    let kept = step.score.as_ref().expect("the step added a model").effect;
    let fitted: Vec<_> = step.drift_choice.iter().filter(|d| d.fitted).collect();
    let best = fitted.iter().min_by(|a, b| a.bic.total_cmp(&b.bic)).expect("one fitted");
    if r.skipped.iter().any(|s| s.effect == best.effect && s.why.contains("Hausman")) {
        assert!(kept.is_free_drift(), "{kept:?} kept in place of {best:?}");
    } else {
        assert_eq!(best.effect, kept, "{:?}", step.drift_choice);
    }
    for d in step.drift_choice.iter().filter(|d| !d.fitted) {
        assert!(
            d.bic >= best.bic + crate::calib::analysis::selection::DRIFT_BIC_MARGIN,
            "{d:?} left unfitted within the margin of {best:?}"
        );
    }
}

/// A random walk three times the simulator's default (0.006 °/s/√s) leaves run offsets between
/// 40-s knots; 20-s knots take their place (scored in their place, as the free drift is on a
/// curve), and the result is at the floor within 3σ. (Before, flagged on both seeds of the
/// trust bench's cell.)
#[test]
fn finer_knots_replace_coarser_ones_that_leave_a_random_walk() {
    let (runs, truth) =
        capture_with(1, &[180.0, 90.0, -180.0], BAR_DURATION_S, &["bias_random_walk=0.006"], FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    let effects = r.effects();
    assert!(effects.iter().any(|e| matches!(e, Effect::DriftKnots(s) if *s < 40)), "{}", r.summary());
    assert_eq!(effects.iter().filter(|e| e.is_free_drift()).count(), 1, "{effects:?}");
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "random walk 3×");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// A short two-direction capture with speed ripple (seed 8, 6-s runs) and a model with a 4-ms
/// delay and plausible rows of M and offsets: the accumulation tests' data and model.
fn short_capture_and_delay_model() -> (LoopData, Model) {
    let (runs, _) = capture_with(8, &[180.0, -90.0], 6.0, &["speed_ripple"], FullScale::Dps500);
    let data = LoopData::new(kinematics::reconstruct(&runs, &KinOptions::default()).expect("kinematics"));
    let mut model = Model::base_for(&data.poses).with(Effect::Delay, Default::default(), vec![0.004]);
    for (a, row) in [[57.0, 0.9, -0.4, 12.0], [-0.5, 56.5, 1.1, -20.0], [0.3, -0.8, 58.0, 5.0]].iter().enumerate() {
        model.beta[a] = row.to_vec();
    }
    (data, model)
}

/// Every catalogued candidate `model` could take on `data`, whatever the evidence.
fn every_candidate(data: &LoopData, model: &Model) -> Vec<crate::calib::analysis::selection::Candidate> {
    let everything = super::effects::terms::Evidence {
        phase: true,
        drift: true,
        rate_scale: true,
        orders: [true; crate::calib::analysis::diagnostics::MAX_ORDER + 1],
    };
    crate::calib::analysis::selection::candidates(data, &model.effects, &everything)
}

/// A candidates' pass sums only the pairs a test needs (the model's columns with every column,
/// each candidate's with its own): those are the full pass's sums (to 1e-12 of the pair's scale
/// √(xᵢᵀxᵢ·xⱼᵀxⱼ), a reordered sum's rounding; a score reads differences of χ² far above it),
/// the rest are exactly 0.
/// Every catalogued candidate of a model with a delay, the free drift's sparse knots among them.
#[test]
fn a_candidates_pass_sums_the_pairs_a_test_needs_and_no_others() {
    let (data, model) = short_capture_and_delay_model();
    let cands = every_candidate(&data, &model);
    assert!(cands.len() >= 10 && cands.iter().any(|c| c.effect.is_free_drift()), "{}", cands.len());
    let lead = model.cols().len();
    let cols: Vec<Col> = model.cols().into_iter().chain(cands.iter().flat_map(|c| c.cols.iter().copied())).collect();
    let reach = crate::calib::engine::Reach::blocks(lead, cands.iter().map(|c| c.cols.len()));
    let full = crate::calib::engine::accumulate(&data, &model, &cols);
    let blocks =
        crate::calib::engine::accumulate_pairs(&data, &model, &cols, &reach, crate::calib::engine::Cells::Exact);
    // The block each column is in: the model's (0) or a candidate's (1, 2, ...).
    let block_of: Vec<usize> = std::iter::repeat_n(0, lead)
        .chain(cands.iter().enumerate().flat_map(|(b, c)| std::iter::repeat_n(b + 1, c.cols.len())))
        .collect();
    let l = cols.len();
    let close = |got: f64, want: f64, scale: f64| (got - want).abs() <= 1e-12 * scale;
    for (f, b) in full.iter().zip(&blocks) {
        assert_eq!(f.n, b.n);
        for a in 0..3 {
            assert!(close(b.ete[a], f.ete[a], f.ete[a]), "axis {a}: eᵀe {} vs {}", b.ete[a], f.ete[a]);
            let diag = |m: &Vec<f64>, i: usize| m[i * l + i];
            for i in 0..l {
                let scale = (diag(&f.xtx[a], i) * f.ete[a]).sqrt();
                assert!(close(b.xte[a][i], f.xte[a][i], scale), "axis {a}, xᵀe {i}");
                for j in 0..l {
                    let paired = block_of[i] == 0 || block_of[j] == 0 || block_of[i] == block_of[j];
                    let got = b.xtx[a][i * l + j];
                    if paired {
                        let scale = (diag(&f.xtx[a], i) * diag(&f.xtx[a], j)).sqrt();
                        assert!(close(got, f.xtx[a][i * l + j], scale), "axis {a}, ({i}, {j})");
                    } else {
                        assert_eq!(got, 0.0, "axis {a}, ({i}, {j}) is no pair");
                    }
                }
            }
        }
    }
}

/// A run's sums leave out the columns that are zero in it (a table harmonic's pairs of other
/// runs): they are the sums of every column, sample by sample, to 1e-12 of each entry's scale,
/// and those columns' entries are exactly 0.
#[test]
fn a_runs_sums_leave_out_the_columns_of_other_runs() {
    use crate::calib::engine::{accumulate, sums::CHUNK};
    let (data, model) = short_capture_and_delay_model();
    let harmonics = [Effect::TableHarmonic(1), Effect::TableHarmonic(12), Effect::TableHarmonic(24)];
    let cols: Vec<Col> = model
        .cols()
        .into_iter()
        .chain(harmonics.iter().flat_map(|e| e.params(&data.layout).1).map(Col::Shared))
        .collect();
    let l = cols.len();
    let got = accumulate(&data, &model, &cols);
    let ev = Evaluator::for_columns(&data, &model, &cols);
    assert!(data.kin.runs.len() >= 2);
    for (r, rk) in data.kin.runs.iter().enumerate() {
        let want = cell_reference(&data, (&ev, &cols), r, (CellForm { size: 1, intervals: 0 }, CHUNK), false);
        let g = &got[r];
        assert_eq!(g.n, want.n);
        let outside: Vec<usize> = (0..l).filter(|&i| !cols[i].in_run(r, rk.pose)).collect();
        let other_runs_and_pose = 2 * 2 * (data.kin.runs.len() - 1) + 2 * (data.poses.len() - 1);
        assert_eq!(outside.len(), other_runs_and_pose, "run {r}: 12× and 24× of each other run, 1× of the other pose");
        for a in 0..3 {
            assert!((g.ete[a] - want.ete[a]).abs() <= 1e-12 * want.ete[a]);
            let diag = |i: usize| want.xtx[a][i * l + i];
            for i in 0..l {
                let scale = (diag(i) * want.ete[a]).sqrt();
                assert!((g.xte[a][i] - want.xte[a][i]).abs() <= 1e-12 * scale, "run {r}, axis {a}, xᵀe {i}");
                for j in 0..l {
                    let (got, want) = (g.xtx[a][i * l + j], want.xtx[a][i * l + j]);
                    if outside.contains(&i) || outside.contains(&j) {
                        assert_eq!((got, want), (0.0, 0.0), "run {r}, axis {a}, ({i}, {j})");
                    } else {
                        assert!(
                            (got - want).abs() <= 1e-12 * (diag(i) * diag(j)).sqrt(),
                            "run {r}, axis {a}, ({i}, {j})"
                        );
                    }
                }
            }
        }
    }
}

/// A pass in cells sums, within each chunk of the pass, each stretch of consecutive valid
/// samples in cells (the last of a stretch shorter): of 32 samples with the chain taken at five
/// nodes where every column varies slowly (the base model), else of eight at three nodes (its
/// first sample, the next cell's first or its own last, and equal parts between), and at each
/// sample from the polynomial through them: XᵀX and Xᵀe are those of each cell's sums over the
/// root of its count, eᵀe and the counts the samples' own (to 1e-12 of each entry's scale). The
/// base model without the delay (every column axis-independent: one row for the three axes),
/// the model with it and every candidate but the free drift's (a row per axis), and with every
/// candidate (the knots' path: the knots are the samples' own values, which a pass sums as the
/// count times the values at the samples' mean time in a cell no corner crosses, and sample by
/// sample in one a corner does). And they are the sums of the same cells of the samples'
/// own values to 5e-3 of each entry's scale: the quadratic's error on the catalogue's highest
/// harmonic, 48× at 180 °/s (24 Hz, 0.75 rad between nodes: 0.06·0.75³ ≈ 2.5e-2 at a sample, less
/// in a sum; 3.6e-3 of its sum of squares here, 1.1e-3 at 36×), and the encoder's rate noise each
/// sample carries and a quadratic smooths (3e-5 of ω_s, rms: 2e-4 of eᵀe here).
#[test]
fn a_pass_in_cells_sums_the_quadratic_through_its_nodes() {
    use crate::calib::engine::{accumulate_pairs, sums::CHUNK, Cells, Reach};
    let (data, model) = short_capture_and_delay_model();
    let mut base = Model::base_for(&data.poses);
    base.beta = model.beta.clone();
    let cands = every_candidate(&data, &model);
    let with = |knots: bool| -> Vec<Col> {
        let extra = cands.iter().filter(|c| knots || !c.effect.is_free_drift()).flat_map(|c| c.cols.iter().copied());
        model.cols().into_iter().chain(extra).collect()
    };
    // The base model varies at the turn rate (0.5 Hz): long cells, 32 samples, five nodes. The
    // candidates reach 49× (24.5 Hz): short cells, eight samples, three nodes.
    let long = CellForm { size: 32, intervals: 4 };
    let short = CellForm { size: 8, intervals: 2 };
    for (model, cols, form) in [(&base, base.cols(), long), (&model, with(false), short), (&model, with(true), short)] {
        let l = cols.len();
        let got = accumulate_pairs(&data, model, &cols, &Reach::all(l), Cells::Span);
        let ev = Evaluator::for_columns(&data, model, &cols);
        for (r, rk) in data.kin.runs.iter().enumerate() {
            assert_eq!(rk.sample_rate_hz, 800.0);
            let want = cell_reference(&data, (&ev, &cols), r, (form, CHUNK), true);
            let samples = cell_reference(&data, (&ev, &cols), r, (form, CHUNK), false);
            for (g, (w, tol)) in [(&got[r], (&want, 1e-12)), (&got[r], (&samples, 5e-3))] {
                assert_eq!(g.n, w.n, "run {r}: every sample counted once");
                for a in 0..3 {
                    let diag = |i: usize| w.xtx[a][i * l + i];
                    assert!((g.ete[a] - w.ete[a]).abs() <= tol * w.ete[a], "run {r}, axis {a}: eᵀe, tolerance {tol}");
                    for (i, col) in cols.iter().enumerate() {
                        let scale = (diag(i) * w.ete[a]).sqrt();
                        assert!((g.xte[a][i] - w.xte[a][i]).abs() <= tol * scale, "run {r}, axis {a}, xᵀe {i} of {l}");
                        for j in 0..l {
                            let (got, want) = (g.xtx[a][i * l + j], w.xtx[a][i * l + j]);
                            let scale = (diag(i) * diag(j)).sqrt();
                            assert!(
                                (got - want).abs() <= tol * scale,
                                "run {r}, axis {a}, ({i}, {j}) of {l}: {got} vs {want}, tolerance {tol}, {col:?}"
                            );
                        }
                    }
                }
            }
        }
    }
}

/// A walk through the cells' nodes visits every valid sample once, in order, with the values
/// at the nodes themselves exact (each cell's first sample) and elsewhere those of the
/// quadratic through them: ω_s within 0.01 °/s rms and 0.1 °/s at worst of the sample's own
/// (the encoder's rate noise, which each sample carries and the quadratic smooths, not the
/// quadratic's error: 2.5e-7 of 180 °/s at 0.5 Hz).
#[test]
fn a_walk_through_the_nodes_visits_every_sample_with_the_quadratic_between_them() {
    let (data, model) = short_capture_and_delay_model();
    let ev = Evaluator::for_columns(&data, &model, &model.cols());
    for r in 0..data.kin.runs.len() {
        let (mut visited, mut sq, mut worst, mut stretch) = (Vec::new(), 0.0, 0.0f64, 0);
        crate::calib::engine::for_each_interpolated(
            &ev,
            &data,
            r,
            |p| p.omega,
            |i, s, omega| {
                assert_eq!(s.t_us(), data.kin.runs[r].samples.get(i).t_us());
                let own = ev.point(r, i).omega;
                if visited.last().is_none_or(|&j| j + 1 != i) {
                    stretch = i;
                }
                for (a, b) in omega.iter().zip(own) {
                    let d = (a - b).abs();
                    (sq, worst) = (sq + d * d, worst.max(d));
                    let node = (i - stretch) % 8 == 0;
                    assert!(!node || d <= 1e-12 * b.abs().max(1.0), "sample {i} is a node: {a} against {b}");
                }
                visited.push(i);
            },
        );
        assert_eq!(visited, data.runs[r].valid.indices().collect::<Vec<_>>(), "run {r}");
        let rms = (sq / (3 * visited.len()) as f64).sqrt();
        assert!(rms < 0.01 && worst < 0.1, "run {r}: rms {rms} °/s, worst {worst} °/s");
    }
}

/// The sums of run `r` in cells of `size` samples (within chunks of `chunk`), made directly: each
/// sample's columns and output from the quadratic through its cell's nodes (see the test above)
/// if `through_nodes`, else the sample's own. The free drift's knots, straight lines with corners,
/// are the sample's own either way, as a pass takes them.
fn cell_reference(
    data: &LoopData,
    (ev, cols): (&Evaluator, &[Col]),
    r: usize,
    (form, chunk): (CellForm, usize),
    through_nodes: bool,
) -> Gram {
    let size = form.size;
    let (rk, l) = (&data.kin.runs[r], cols.len());
    let mut g = Gram {
        l,
        xtx: std::array::from_fn(|_| vec![0.0; l * l]),
        xte: std::array::from_fn(|_| vec![0.0; l]),
        ete: [0.0; 3],
        n: [0; 3],
    };
    let mut row = vec![0.0; 3 * l];
    for start in (0..rk.samples.len()).step_by(chunk) {
        for stretch in data.runs[r].valid.ranges_in(start, (start + chunk).min(rk.samples.len())) {
            let idx: Vec<usize> = stretch.clone().collect();
            for cell in idx.chunks(size) {
                let first = cell[0];
                let last = if cell[cell.len() - 1] + 1 < stretch.end { cell[0] + size } else { cell[cell.len() - 1] };
                let mut at = |i: usize| -> (Vec<f64>, [f64; 3]) {
                    let p = ev.point(r, i);
                    ev.fill(&p, cols, &mut row);
                    (row.clone(), std::array::from_fn(|a| ev.predict(&p, a)))
                };
                let (mut sx, mut se, mut m) = (vec![0.0; 3 * l], [0.0; 3], 0.0);
                for &i in cell {
                    let q = form.intervals.min(last - first);
                    let nodes: Vec<usize> = match through_nodes {
                        false => vec![i],
                        true => (0..=q).map(|j| first + (j * (last - first)).checked_div(q).unwrap_or(0)).collect(),
                    };
                    let t = |i: usize| rk.samples.get(i).t_s();
                    let weight = |j: usize, x: f64| -> f64 {
                        let others = (0..nodes.len()).filter(|&q| q != j);
                        others.map(|q| (x - t(nodes[q])) / (t(nodes[j]) - t(nodes[q]))).product()
                    };
                    let own = at(i).0;
                    let at: Vec<(Vec<f64>, [f64; 3])> = nodes.iter().map(|&i| at(i)).collect();
                    let w: Vec<f64> = (0..nodes.len()).map(|j| weight(j, t(i))).collect();
                    for (c, s) in sx.iter_mut().enumerate() {
                        *s += if is_knot(&cols[c % l]) {
                            own[c]
                        } else {
                            (0..nodes.len()).map(|j| w[j] * at[j].0[c]).sum::<f64>()
                        };
                    }
                    let pred: [f64; 3] = std::array::from_fn(|a| (0..nodes.len()).map(|j| w[j] * at[j].1[a]).sum());
                    for a in 0..3 {
                        let e = f64::from(rk.samples.get(i).rate_counts[a]) - pred[a];
                        (se[a], g.ete[a], g.n[a]) = (se[a] + e, g.ete[a] + e * e, g.n[a] + 1);
                    }
                    m += 1.0;
                }
                for a in 0..3 {
                    let x = &sx[a * l..(a + 1) * l];
                    for i in 0..l {
                        g.xte[a][i] += x[i] * se[a] / m;
                        for j in 0..l {
                            g.xtx[a][i * l + j] += x[i] * x[j] / m;
                        }
                    }
                }
            }
        }
    }
    g
}

/// The drift table takes each run's modelled offset at its first valid sample and then at the
/// first valid sample at least [`DRIFT_TABLE_STEP_S`] after the last it took, each value the
/// model's offset columns there: 25-s runs give three rows each.
#[test]
fn the_drift_table_takes_the_offset_every_step_through_each_run() {
    use crate::calib::result::report::DRIFT_TABLE_STEP_S;
    let (runs, _) = capture_with(3, &[180.0], 25.0, &["offset_drift"], FullScale::Dps500);
    let data = LoopData::new(kinematics::reconstruct(&runs, &KinOptions::default()).expect("kinematics"));
    let model =
        Model::base_for(&data.poses).with(Effect::DriftWarmUp, [vec![30.0], vec![-20.0], vec![10.0]], vec![40.0]);
    let table = closure::drift_table(&model, &data);
    let ev = Evaluator::new(&data, &model);
    assert_eq!(table.len(), data.kin.runs.len());
    for (r, row) in table.iter().enumerate() {
        let valid: Vec<usize> = data.runs[r].valid.indices().collect();
        let t = |i: usize| data.kin.runs[r].samples.get(i).t_s();
        let mut want = vec![valid[0]];
        for &i in &valid {
            if t(i) >= t(*want.last().unwrap()) + DRIFT_TABLE_STEP_S {
                want.push(i);
            }
        }
        assert_eq!(want.len(), 3, "run {r}");
        assert_eq!(row.t_s, want.iter().map(|&i| t(i)).collect::<Vec<_>>(), "run {r}");
        for (k, &i) in want.iter().enumerate() {
            let p = ev.point(r, i);
            for a in 0..3 {
                let offset: f64 = model
                    .lin
                    .iter()
                    .zip(&model.beta[a])
                    .filter(|(c, _)| c.is_offset())
                    .map(|(&c, b)| b * ev.lin_value(c, &p, a))
                    .sum();
                assert_eq!(row.offset_counts[a][k], offset, "run {r}, axis {a}, row {k}");
            }
            assert_eq!(row.temp_c[k], p.temp_c, "run {r}, row {k}");
        }
    }
}

/// Whether `col` is one of the free drift's knots.
fn is_knot(col: &Col) -> bool {
    matches!(col, Col::Lin(LinCol::DriftKnot { .. }))
}

/// Earth's fit starts from the last candidates' pass, read in place of a pass of its own: the
/// sums read for some of the gathered groups (a group's columns in another order, a subset of a
/// group) are those a pass of their own takes (to 1e-12 of each entry's scale, as above), and
/// sums of another model, of columns never gathered together, or summed otherwise, are not read.
#[test]
fn sums_gathered_for_candidates_are_read_for_any_part_of_them() {
    let (data, model) = short_capture_and_delay_model();
    let cols_of = |e: Effect| -> Vec<Col> {
        let (lin, shared) = e.params(&data.layout);
        lin.into_iter().map(Col::Lin).chain(shared.into_iter().map(Col::Shared)).collect()
    };
    let (g, h, t) = (cols_of(Effect::GSensitivity), cols_of(Effect::RateScale), cols_of(Effect::TableTilt));
    use crate::calib::engine::{Cells, CrossSums};
    let gathered = CrossSums::gather(&data, &model, &[&g, &h, &t], Cells::Span).expect("runs");
    let g_rev: Vec<Col> = g.iter().rev().copied().collect();
    let wanted: [&[Col]; 3] = [&t, &g_rev, &h[..1]];
    let read = gathered.read(&model, &wanted, Cells::Span).expect("every group lies within a gathered one");
    let own = CrossSums::gather(&data, &model, &wanted, Cells::Span).expect("runs");
    let own = own.total();
    let l = own.l;
    assert_eq!((read.l, read.n), (l, own.n));
    let diag = |m: &Vec<f64>, i: usize| m[i * l + i];
    for a in 0..3 {
        assert!((read.ete[a] - own.ete[a]).abs() <= 1e-12 * own.ete[a]);
        for i in 0..l {
            let scale = (diag(&own.xtx[a], i) * own.ete[a]).sqrt();
            assert!((read.xte[a][i] - own.xte[a][i]).abs() <= 1e-12 * scale, "axis {a}, xᵀe {i}");
            for j in 0..l {
                let scale = (diag(&own.xtx[a], i) * diag(&own.xtx[a], j)).sqrt();
                let (got, want) = (read.xtx[a][i * l + j], own.xtx[a][i * l + j]);
                assert!((got - want).abs() <= 1e-12 * scale, "axis {a}, ({i}, {j}): {got} vs {want}");
            }
        }
    }
    // Columns of two gathered groups were never summed against each other.
    let across: Vec<Col> = g.iter().chain(&h).copied().collect();
    assert!(gathered.read(&model, &[&across], Cells::Span).is_none());
    // Nor are these sums of a model at other values, nor sums of cells read as the samples'.
    let mut moved = model.clone();
    moved.beta[0][0] += 1e-9;
    assert!(gathered.read(&moved, &[&g], Cells::Span).is_none());
    assert!(gathered.read(&model, &[&g], Cells::Exact).is_none());
}

/// The analytic Jacobian of every shared parameter matches a central difference of the model's
/// prediction (the delay's to 2 %: [`assert_jacobians_match`]).
#[test]
fn shared_parameter_jacobians_match_finite_differences() {
    let (runs, _) = capture_with(8, &[180.0, -90.0], 6.0, &["speed_ripple"], FullScale::Dps500);
    let kin = kinematics::reconstruct(&runs, &KinOptions::default()).expect("kinematics");
    let data = LoopData::new(kin);
    let mut model = Model::for_data(&data);
    for (a, row) in [[57.0, 0.9, -0.4, 12.0], [-0.5, 56.5, 1.1, -20.0], [0.3, -0.8, 58.0, 5.0]].iter().enumerate() {
        model.beta[a] = row.to_vec();
    }
    // A harmonic's pairs: one per pose at 1×, one per run above.
    let pairs = |n: u32, ab: [f64; 4]| {
        let count = Effect::TableHarmonic(n).params(&model.layout).1.len();
        ab.iter().copied().cycle().take(count).collect::<Vec<f64>>()
    };
    let (h2, h12) = (pairs(2, [0.003, -0.002, 0.001, 0.002]), pairs(12, [0.004, 0.001, -0.002, 0.003]));
    let model = model
        .with(Effect::IndexOffset, Default::default(), vec![0.05])
        .with(Effect::Phase, Default::default(), vec![-0.02])
        .with(Effect::Delay, Default::default(), vec![0.004])
        .with(Effect::DriftWarmUp, [vec![30.0], vec![-20.0], vec![10.0]], vec![40.0])
        .with(Effect::RateScale, [vec![0.01, 2e-5], vec![-0.01, 1e-5], vec![0.0, -2e-5]], vec![])
        .with(Effect::RatePower(3), [vec![5e-8], vec![-3e-8], vec![4e-8]], vec![])
        .with(Effect::RatePower(2), [vec![2e-6], vec![-1e-6], vec![3e-6]], vec![])
        .with(Effect::TableHarmonic(2), Default::default(), h2)
        .with(Effect::TableHarmonic(12), Default::default(), h12)
        .with(Effect::EarthRotation, Default::default(), vec![0.003, -0.002, 0.001])
        .with(Effect::FilterGain, Default::default(), vec![1.2e-5])
        .with(Effect::GearLag, Default::default(), vec![0.003])
        .with(Effect::TableTilt, Default::default(), vec![0.004])
        .with(Effect::PoseFixture, Default::default(), vec![0.0015]);
    // The fixture's tilts about x2 and y2 are not an effect of their own (catalogue), but their
    // Jacobian is the same code: check it too.
    let mut model = model;
    model.shared.extend([0, 1].map(|k| SharedPar { effect: Effect::PoseFixture, k }));
    model.theta.extend([0.002, -0.001]);
    let at = [(0usize, 2000usize), (1, 1500), (0, 3333), (2, 1800), (3, 2600)];
    assert_jacobians_match(&data, &model, &at, |p, _| match p.effect {
        Effect::DriftWarmUp => 1e-3,
        _ => 1e-6,
    });
}

/// Asserts that at samples `at` (run, index) every shared parameter's analytic Jacobian matches a
/// central difference of the model's prediction with step `h(parameter, value)`: to 1e-4, the
/// delay's to [`DELAY_JACOBIAN_TOL`] with a step of its own ([`delay_step_s`]).
fn assert_jacobians_match(data: &LoopData, model: &Model, at: &[(usize, usize)], h: impl Fn(SharedPar, f64) -> f64) {
    let cols: Vec<Col> = model.shared.iter().map(|&p| Col::Shared(p)).collect();
    let ev = Evaluator::new(data, model);
    let mut jac = vec![0.0; 3 * cols.len()];
    for &(r, i) in at {
        let p = ev.point(r, i);
        ev.fill(&p, &cols, &mut jac);
        for (k, &par) in model.shared.iter().enumerate() {
            let h = if par.effect == Effect::Delay { delay_step_s(data) } else { h(par, model.theta[k]) };
            let shifted = |d: f64| {
                let mut m = model.clone();
                m.theta[k] += d;
                let e = Evaluator::new(data, &m);
                let q = e.point(r, i);
                [0, 1, 2].map(|a| e.predict(&q, a))
            };
            let (up, down) = (shifted(h), shifted(-h));
            for a in 0..3 {
                let numeric = (up[a] - down[a]) / (2.0 * h);
                let analytic = jac[a * cols.len() + k];
                let tol = if par.effect == Effect::Delay { DELAY_JACOBIAN_TOL } else { 1e-4 };
                assert!(
                    (numeric - analytic).abs() <= tol * numeric.abs().max(1e-3),
                    "{par:?} axis {a} sample {r}/{i}: {analytic} vs {numeric}"
                );
            }
        }
    }
}

/// The delay's Jacobian against its central difference: within this fraction. The delay moves
/// θ1' by −θ1''·τ, and its column takes θ1'' smoothed over the rates' own window (the speed
/// ripple; `rate_slope_dps2`), while the model reads θ1' between samples, whose slope from one to
/// the next carries the encoder's quantisation (7.5 °/s² rms at 800 Hz). A difference over the
/// window ([`delay_step_s`]) sees the smoothed slope; what is left is the straight-line
/// interpolation's and the window's curvature on the ripple and the angle (≲ 1 %).
const DELAY_JACOBIAN_TOL: f64 = 0.02;

/// The delay's step for its central difference, s: half the rates' window, so that the
/// difference spans the window the column's θ1'' is taken over.
fn delay_step_s(data: &LoopData) -> f64 {
    let rk = &data.kin.runs[0];
    (rk.rate_window_samples / 2) as f64 / rk.sample_rate_hz
}

/// Every registered effect on its own (the catalogue, so a new effect is checked without
/// touching this test): each shared parameter's analytic Jacobian matches a central difference
/// of the prediction, at a value of one reported unit (1 ms, 1°, 1 ppm, 1 °/h; the middle of its
/// range when that is at a bound), with the effect's linear columns at 10 counts
/// ([`assert_jacobians_match`]).
#[test]
fn every_registered_effects_jacobian_matches_finite_differences() {
    let (runs, _) = capture_with(8, &[180.0, -90.0], 6.0, &["speed_ripple"], FullScale::Dps500);
    let kin = kinematics::reconstruct(&runs, &KinOptions::default()).expect("kinematics");
    let data = LoopData::new(kin);
    let mut base = Model::for_data(&data);
    for (a, row) in [[57.0, 0.9, -0.4, 12.0], [-0.5, 56.5, 1.1, -20.0], [0.3, -0.8, 58.0, 5.0]].iter().enumerate() {
        base.beta[a] = row.to_vec();
    }
    let mut checked = 0;
    for e in Effect::catalogue() {
        let (lin, shared) = e.params(&data.layout);
        if shared.is_empty() {
            continue;
        }
        let value = |p: SharedPar| {
            let unit = 1.0 / p.reported().scale;
            match p.bound() {
                Some(b) if unit <= b.lo || unit >= b.hi => (b.lo * b.hi).abs().sqrt(),
                _ => unit,
            }
        };
        let model =
            base.with(e, std::array::from_fn(|_| vec![10.0; lin.len()]), shared.iter().map(|&p| value(p)).collect());
        let at = [(0usize, 2000usize), (1, 1500), (2, 1800), (3, 2600)];
        assert_jacobians_match(&data, &model, &at, |_, value| (1e-3 * value.abs()).max(1e-6));
        checked += 1;
    }
    // Every effect with a shared parameter: 15 besides the harmonics.
    assert_eq!(checked, 15 + crate::calib::effects::MAX_HARMONIC_ORDER);
}

#[test]
#[ignore = "prints the summary of one bar capture; run with -- --ignored --nocapture"]
fn print_bar_summary() {
    let t = std::time::Instant::now();
    let (r, _) = run_loop(1, &BAR_RATES_DPS, BAR_DURATION_S, &BAR_EFFECTS);
    eprintln!("{}\n{:.1} s", r.summary(), t.elapsed().as_secs_f64());
    if let Ok(dir) = std::env::var("LOOP_REPORT_DIR") {
        let html = crate::present::write_report(std::path::Path::new(&dir), &r).expect("report written");
        eprintln!("report: {}", html.display());
    }
}

/// The magnetic gears' pole-pass error (0.03° at 12×, 0.01° at 24× of the base's turn), not
/// declared: found at 12× and 24×, named as the gears' transmission error, and corrected to
/// within 3σ of the truth with the residual at the floor.
#[test]
fn undeclared_gear_transmission_error_is_found_named_and_corrected() {
    let (r, _) = run_loop(3, &BAR_RATES_DPS, BAR_DURATION_S, &["gear_transmission"]);
    assert!(r.initial.findings.iter().any(|f| f.kind == FindingKind::Harmonic(12)), "{}", r.summary());
    let effects = r.effects();
    assert_eq!(r.steps.get(1).and_then(|s| s.effect), Some(Effect::TableHarmonic(12)), "{}", r.summary());
    assert!(effects.contains(&Effect::TableHarmonic(24)), "{effects:?}\n{}", r.summary());
    assert!(Effect::TableHarmonic(12).name().contains("magnetic-gear transmission error"));
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "gear_transmission");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// A 16-pole gear's lines (0.03° at 16×, 0.01° at 32× of the base's turn) seen through the
/// L3G4200D's 30-Hz low-pass at 800 Hz (BW = 00, datasheet Table 21) on the default design: the
/// filter turns the 32× line (16 Hz at 180 °/s) 3.2° past its group delay and damps it 3.8 %,
/// at 90 °/s 0.4° and 0.2 %, so one pair per pose left lines in some runs and the calibration,
/// right to 1.5σ, was flagged on three seeds of three. Each run's own pair takes them.
#[test]
fn gear_lines_through_a_low_cut_off_are_fitted_in_each_run() {
    assert_gear_lines_fitted((1, BAR_DURATION_S), 16, Some(protocol::Bandwidth::Bw0));
}

/// A 20-pole gear (0.03° at 20×, 0.01° at 40× of the base's turn, 1.3 °/s of rate at 40× and 180
/// °/s): both lines are in the catalogue, and the calibration ends at the floor, right to 3σ.
#[test]
fn a_twenty_pole_gears_overtone_is_fitted() {
    assert_gear_lines_fitted((2, SHORT_S), 20, None);
}

/// A `poles`-pole gear's lines (0.03° at poles×, 0.01° at 2·poles×) on the default design, seed
/// and run length `(seed, duration_s)`, behind the gyro's low-pass at `bandwidth` (none without):
/// both lines fitted and the calibration at the floor, within 3σ.
fn assert_gear_lines_fitted((seed, duration_s): (u64, f64), poles: u32, bandwidth: Option<protocol::Bandwidth>) {
    let mut cfg = SimConfig::with_runs(seed, plan(&[180.0, 90.0, -180.0], duration_s));
    cfg.effects.gear_transmission =
        Some(crate::sim::GearTransmission { harmonics: [(poles, 0.03, 0.7), (2 * poles, 0.01, -1.2)] });
    cfg.effects.enable(&format!("earth_rotation={LAB_LATITUDE_DEG}")).expect("known effect");
    if let Some(bw) = bandwidth {
        cfg.gyro.bandwidth = bw;
        cfg.effects.enable("filter_delay").expect("known effect");
    }
    let out = simulate(&cfg).unwrap();
    let opts = LoopOptions { latitude_deg: Some(LAB_LATITUDE_DEG), ..LoopOptions::default() };
    let r = close_loop(&decode(&out.bytes).runs, &opts, Some(out.truth.sensor())).expect("the loop runs");
    let effects = r.effects();
    let lines = [Effect::TableHarmonic(poles), Effect::TableHarmonic(2 * poles)];
    assert!(lines.iter().all(|l| effects.contains(l)), "{effects:?}");
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), &format!("{poles}-pole gear"));
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// Gravity felt as a rate (0.05 °/s/g at most, not declared): found, named, and corrected to
/// within 3σ. Two speeds separate it from M: it does not scale with θ1'. But at two speeds in one
/// direction gravity and M together fit any θ2'³ shape, so nothing tells it from a change of M
/// with speed: flagged, and the notes say so. Runs in both directions tell them apart: there it
/// ends at the floor.
#[test]
fn undeclared_g_sensitivity_is_found_named_and_corrected() {
    let held = |r: &LoopReport| {
        r.notes.iter().find_map(|n| match n {
            Note::SpeedChangeHeldByGravity { rates_dps } => Some(rates_dps.clone()),
            _ => None,
        })
    };
    let (r, _) = run_loop(5, &BAR_RATES_DPS, BAR_DURATION_S, &["g_sensitivity"]);
    assert!(r.effects().contains(&Effect::GSensitivity), "{}", r.summary());
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "g_sensitivity");
    assert_eq!(r.verdict(), Verdict::UnexplainedStructure, "{}", r.summary());
    assert!(r.summary().contains("cannot tell the g-sensitivity the model took from a change of M with speed"));
    assert!(held(&r).is_some_and(|v| v.len() == 2), "{:?}", r.notes);
    assert!(!r.notes.iter().any(|n| matches!(n, Note::SpeedChangeUnchecked { .. })), "{:?}", r.notes);
    let (r, _) = run_loop(5, &[180.0, 90.0, -180.0], BAR_DURATION_S, &["g_sensitivity"]);
    assert!(r.effects().contains(&Effect::GSensitivity), "{}", r.summary());
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "g_sensitivity");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
    assert_eq!(held(&r), None, "{:?}", r.notes);
}

/// A sensor-table axis 0.3° off perpendicular, not declared: its θ1'·sin ε along z2 biases the
/// sensitivities by thousands of ppm until it is found; then within 3σ at the floor.
#[test]
fn undeclared_table_tilt_is_found_named_and_corrected() {
    let (r, _) = run_loop(5, &BAR_RATES_DPS, SHORT_S, &["table_tilt"]);
    assert_eq!(r.steps.get(1).and_then(|s| s.effect), Some(Effect::TableTilt), "{}", r.summary());
    let before = truth_of(&r.steps[0]).max_sensitivity_ppm();
    let after = truth_of(r.steps.last().expect("steps"));
    assert!(
        after.max_sensitivity_ppm() * 10.0 <= before,
        "{before} → {}\n{}",
        after.max_sensitivity_ppm(),
        r.summary()
    );
    assert_within_3_sigma(&after, "table_tilt");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// The pose-2 fixture turned 0.1° about the table axis, not declared: a single index offset
/// cannot hold both poses, and the directions are 0.05° off until it is found; then within 3σ
/// at the floor.
#[test]
fn undeclared_pose_fixture_is_found_named_and_corrected() {
    let (r, _) = run_loop(6, &BAR_RATES_DPS, SHORT_S, &["pose_fixture", "index_offset_deg"]);
    assert!(r.effects().contains(&Effect::PoseFixture), "{}", r.summary());
    let before = truth_of(&r.steps[0]).max_direction_deg();
    let after = truth_of(r.steps.last().expect("steps"));
    assert!(after.max_direction_deg() * 10.0 <= before, "{before} → {}\n{}", after.max_direction_deg(), r.summary());
    assert_within_3_sigma(&after, "pose_fixture");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// A fixture turned 1° (ten times the default), not declared: the fixture is a candidate from
/// the first step, so it is chosen before a 1× transmission error and fine drift knots can take
/// it (they did, and stayed: exit 0 at 9σ), and the turn is exact (Rodrigues), where its first
/// order left e²/2 = 150 ppm for a spurious table tilt. Found first; within 3σ at the floor.
#[test]
fn a_fixture_turned_a_whole_degree_is_found_first_and_corrected() {
    let (r, _) = run_loop(11, &BAR_RATES_DPS, SHORT_S, &["pose_fixture=1"]);
    assert_eq!(r.steps.get(1).and_then(|s| s.effect), Some(Effect::PoseFixture), "{}", r.summary());
    let after = truth_of(r.steps.last().expect("steps"));
    assert!(after.max_sensitivity_ppm() < 30.0, "{} ppm\n{}", after.max_sensitivity_ppm(), r.summary());
    assert_within_3_sigma(&after, "pose_fixture=1");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// Earth rotation with no latitude given and runs at one speed, where it cannot be fitted: the
/// sensitivities' σ carries it (Type B), so the calibration is never confidently wrong.
#[test]
fn earth_rotation_without_a_latitude_is_never_confidently_wrong() {
    for seed in [11, 12] {
        let (runs, truth) = capture_with(seed, &[180.0], BAR_DURATION_S, &["earth_rotation=60"], FullScale::Dps500);
        let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
        assert!(
            r.notes.iter().any(|n| matches!(n, Note::Unseparated(t) if t.effect == Effect::EarthRotation.key())),
            "{:?}",
            r.notes
        );
        assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
        assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), &format!("earth, seed {seed}"));
    }
}

/// Earth rotation is added without a test where the runs separate it (it is in every lab), and
/// on the default live design (180, 90, −180 °/s), which also separates it from the gyro
/// filter's droop, that costs nothing where the lab does not turn: seed 7 with no effect (the
/// README's round trip) ends within 3σ and within 15 ppm of the truth, Earth in the model.
/// (With 180 and 90 °/s in one direction the droop rides on Earth's vertical part: 21 → 46 ppm,
/// within σ.) Its fit starts at its linearised solution from the last candidates' pass, so it
/// takes one pass.
#[test]
fn earth_added_without_a_test_costs_nothing_on_the_default_design() {
    let (runs, truth) = capture_with(7, &[180.0, 90.0, -180.0], BAR_DURATION_S, &[], FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    assert!(r.effects().contains(&Effect::EarthRotation), "{}", r.summary());
    let earth_step = r.steps.last().expect("steps");
    assert_eq!(earth_step.score.as_ref().map(|s| s.effect), Some(Effect::EarthRotation));
    assert_eq!(earth_step.passes, 1, "{}", r.summary());
    let t = truth_of(r.steps.last().expect("steps"));
    assert!(t.max_sensitivity_ppm() <= 15.0, "{}", r.summary());
    assert_within_3_sigma(&t, "no Earth simulated, Earth fitted");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// g-sensitivity and Earth rotation with no latitude given, in both directions: gravity and
/// Earth's vertical part turn in the sensor frame alike, so the model holds g-sensitivity and
/// only Earth's horizontal part (the vertical one in the g-sensitivity), says so, and is within
/// 3σ at the floor.
#[test]
fn g_sensitivity_holds_earths_vertical_part_without_a_latitude() {
    let effects = ["g_sensitivity", "earth_rotation=45"];
    let (runs, truth) = capture_with(7, &[180.0, -180.0], BAR_DURATION_S, &effects, FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    let effects = r.effects();
    assert!(effects.contains(&Effect::GSensitivity), "{}", r.summary());
    assert_eq!(effects.last(), Some(&Effect::EarthRotationHorizontal), "{}", r.summary());
    assert!(r.notes.iter().any(|n| matches!(n, Note::EarthHorizontalOnly { .. })), "{:?}", r.notes);
    assert!(
        !r.notes.iter().any(|n| matches!(n, Note::Unseparated(t) if t.effect == Effect::EarthRotation.key())),
        "{:?}",
        r.notes
    );
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "g-sensitivity with Earth");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// Taking an effect out leaves exactly the model it was added to: columns, parameters, values.
#[test]
fn an_effect_taken_out_leaves_the_model_it_was_added_to() {
    let base = Model::base().with(Effect::Delay, Default::default(), vec![0.004]);
    let both = base.with(Effect::GSensitivity, std::array::from_fn(|a| vec![0.1 * a as f64; 3]), Vec::new());
    let both = both.with(Effect::TableTilt, Default::default(), vec![0.005]);
    let back = both.without(Effect::GSensitivity).without(Effect::TableTilt);
    assert_eq!(back.effects, base.effects);
    assert_eq!(back.lin, base.lin);
    assert_eq!(back.shared, base.shared);
    assert_eq!(back.beta, base.beta);
    assert_eq!(back.theta, base.theta);
    let tilt_only = both.without(Effect::GSensitivity);
    assert_eq!(tilt_only.theta_of(SharedPar { effect: Effect::TableTilt, k: 0 }), Some(0.005));
    assert_eq!(tilt_only.theta_of(SharedPar { effect: Effect::Delay, k: 0 }), Some(0.004));
}

/// A warm-up with a rate random walk on top and a table tilted 0.3°, in both directions: the
/// final model drifts freely (no curve follows a random walk, and a curve that entered first is
/// replaced), and the tilt, whose only trace is a constant rate per run, is not in it once each
/// run has its own level (dropped if it entered before). Within 3σ at the floor.
#[test]
fn a_random_walk_ends_in_the_free_drift_and_the_tilt_is_found_beside_it() {
    // One capture, runs in both directions a few seconds apart: the free drift follows the
    // offset through them, so the tilt's constant θ1'·sin ε, which flips with the direction,
    // stays the tilt's (with a level per run it was the levels', and the tilt went).
    let effects = ["offset_drift", "bias_random_walk", "table_tilt", "earth_rotation=45"];
    let (runs, truth) = capture_with(8, &[180.0, -180.0], BAR_DURATION_S, &effects, FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    let effects = r.effects();
    let drifts: Vec<&Effect> = effects.iter().filter(|e| e.is_drift()).collect();
    assert!(matches!(drifts[..], [Effect::DriftKnots(_)]), "{}", r.summary());
    let last = r.steps.last().expect("steps");
    let tilt = last.effect_params.iter().find(|p| p.name.starts_with("sensor-table axis tilt")).expect("tilt fitted");
    let truth_deg = crate::sim::TableTilt::default().tilt_deg;
    assert!(
        tilt.estimate.z(truth_deg).abs() <= Z_1D,
        "ε = {} ± {} °\n{}",
        tilt.estimate.value,
        tilt.estimate.sigma,
        r.summary()
    );
    assert_within_3_sigma(&truth_of(last), "random walk and tilt");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// The smoothed die temperature computed as the samples are visited is the per-sample array
/// the loop used to hold (the same running sums, written out here as they were), to 1e-5 °C
/// (f32 rounding; OUT_TEMP reads whole °C), visited forward, from the middle, or going back.
#[test]
fn smoothed_temperatures_are_the_per_sample_ones() {
    use crate::calib::engine::{RunTemperatures, TEMPERATURE_SMOOTHING_S};
    let (runs, _) = capture_with(9, &[180.0], 30.0, &["offset_drift"], FullScale::Dps500);
    let data = LoopData::new(kinematics::reconstruct(&runs, &KinOptions::default()).expect("kinematics"));
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for rk in &data.kin.runs {
        let n = rk.samples.len();
        let h = ((TEMPERATURE_SMOOTHING_S / 2.0) / (1.0 / rk.sample_rate_hz)).round() as usize;
        let counts: Vec<f32> = rk.temperatures_counts().collect();
        let mut prefix = vec![0.0f64; n + 1];
        for (k, &t) in counts.iter().enumerate() {
            prefix[k + 1] = prefix[k] + if t.is_finite() { f64::from(t) } else { data.temp_mean_counts };
        }
        let expected: Vec<f32> = (0..n)
            .map(|i| {
                let (a, b) = (i.saturating_sub(h), (i + h + 1).min(n));
                (-((prefix[b] - prefix[a]) / (b - a) as f64 - data.temp_mean_counts)) as f32
            })
            .collect();
        assert!(n > 2 * h + 1000, "{n} samples, half-window {h}");
        let first = expected[0];
        assert!(expected.iter().any(|&t| (t - first).abs() > 0.1), "the temperature changes");
        let mut temps = RunTemperatures::new(rk, data.temp_mean_counts);
        for (i, &want) in expected.iter().enumerate() {
            assert!((temps.at(i) - want).abs() <= 1e-5, "sample {i}: {} vs {want}", temps.at(i));
            lo = lo.min(f64::from(want));
            hi = hi.max(f64::from(want));
        }
        for i in [n / 2, n / 2 + 1, 3 * n / 4, 10, 2 * h + 500, 2] {
            assert!((temps.at(i) - expected[i]).abs() <= 1e-5, "sample {i}, out of order");
        }
    }
    assert!((data.temp_spread_c() - (hi - lo)).abs() <= 2e-5, "{} vs {}", data.temp_spread_c(), hi - lo);
}

/// The passes' grid of the smoothed temperature is the swept value at its points, and within
/// the bound its spacing gives ([`crate::calib::engine::TEMPERATURE_GRID_S`]: 1.25e-4 °C next
/// to a kink, with 1e-5 for f32 rounding) at every sample between, through a warm-up whose
/// whole-°C steps make the kinks.
#[test]
fn the_temperature_grid_follows_the_swept_temperature() {
    use crate::calib::engine::{RunTemperatures, TEMPERATURE_GRID_S};
    let (runs, _) = capture_with(9, &[180.0], 30.0, &["offset_drift"], FullScale::Dps500);
    let data = LoopData::new(kinematics::reconstruct(&runs, &KinOptions::default()).expect("kinematics"));
    for (r, rk) in data.kin.runs.iter().enumerate() {
        let step = (TEMPERATURE_GRID_S * rk.sample_rate_hz).round() as usize;
        let (grid, mut swept) = (data.temperature_grid(r), RunTemperatures::new(rk, data.temp_mean_counts));
        let (mut worst, mut moved, first) = (0.0f32, 0.0f32, grid.at(0));
        for i in 0..rk.samples.len() {
            let want = swept.at(i);
            let off = (grid.at(i) - want).abs();
            if i % step == 0 || i + 1 == rk.samples.len() {
                assert_eq!(grid.at(i), want, "run {r}, grid point {i}");
            }
            worst = worst.max(off);
            moved = moved.max((want - first).abs());
        }
        assert!(worst <= 1.35e-4, "run {r}: {worst} °C off between the grid's points");
        assert!(moved > 0.5, "run {r}: the temperature moved {moved} °C");
    }
}

/// g-sensitivity at three times its simulated default (0.15 °/s/g at most) with one speed in one
/// direction, where it turns in the sensor frame exactly as the signal does: no test can see it,
/// M absorbs it (hundreds of ppm), and only σ can carry it. The consider term names it, its
/// source and the runs that remove it, and the result is within 3σ of the truth. Without the term
/// this was |z| ≈ 8 at exit 0 (the trust bench, `180@20`).
#[test]
fn one_speed_carries_an_inseparable_g_sensitivity_in_sigma() {
    let (runs, truth) = capture_with(8, &[180.0], SHORT_S, &["g_sensitivity=0.15"], FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    let term = r
        .notes
        .iter()
        .find_map(|n| match n {
            Note::Unseparated(t) if t.effect == Effect::GSensitivity.key() => Some(t.clone()),
            _ => None,
        })
        .unwrap_or_else(|| panic!("no g-sensitivity term: {:?}", r.notes));
    assert!(term.k_sigma_ppm.iter().all(|&p| p > 100.0), "{term:?}");
    assert!(term.removed_by.contains("two speeds"), "{term:?}");
    assert_eq!(r.final_report().consider.first().map(|t| t.effect.clone()), Some(Effect::GSensitivity.key()));
    let t = truth_of(r.steps.last().expect("steps"));
    assert!(t.max_sensitivity_ppm() > 50.0, "the effect must bias M for this test to mean anything: {t:?}");
    assert_within_3_sigma(&t, "one speed, g-sensitivity");
}

/// The index pulse sees the transmission error at its two edges, and their midpoint is where the
/// index-referenced θ2 is 0: the effective θ2 subtracts their mean error (`IndexEdge`). With the
/// gears' 0.03° at 12× and 0.01° at 24× and a 12° plate, leaving it out shifts θ2 = 0 by up to
/// 0.03° (0.03·(1 − cos 72°) + 0.01·(1 − cos 144°)), the same in every run of both poses, and
/// the fitted axes turn with it; with it, the model with both harmonics fits every axis to within
/// 0.008° (measured over seeds 1-7: 0.0003-0.0028° with it; 0.011° on seeds 2, 3 and 6 without).
#[test]
fn the_transmission_error_at_the_index_pulse_does_not_turn_the_axes() {
    let runs = plan(&[180.0, 90.0], 30.0);
    let mut cfg = SimConfig::with_runs(2, runs);
    cfg.index_plate_width_deg = 12.0;
    cfg.effects.enable("gear_transmission").expect("known effect");
    let out = simulate(&cfg).unwrap();
    let truth = out.truth.sensor();
    let data =
        LoopData::new(kinematics::reconstruct(&decode(&out.bytes).runs, &KinOptions::default()).expect("kinematics"));
    let linear = crate::calib::engine::fit(&data, Model::for_data(&data), [1.0; 3]).expect("the linear model fits");
    let zeros = |n: u32| vec![0.0; Effect::TableHarmonic(n).params(&linear.model.layout).1.len()];
    let model = linear.model.with(Effect::TableHarmonic(12), Default::default(), zeros(12)).with(
        Effect::TableHarmonic(24),
        Default::default(),
        zeros(24),
    );
    let fitted = crate::calib::engine::fit(&data, model, [1.0; 3]).expect("fits");
    let m = fitted.model.m();
    for a in 0..3 {
        let row = [m[(a, 0)], m[(a, 1)], m[(a, 2)]];
        let norm = row.iter().map(|v| v * v).sum::<f64>().sqrt();
        let cos = (0..3).map(|j| row[j] / norm * truth.s[a][j]).sum::<f64>();
        let error_deg = cos.clamp(-1.0, 1.0).acos().to_degrees();
        assert!(error_deg < 0.008, "axis {a}: direction {error_deg:.4}° off the truth");
    }
}

/// A sensitivity that follows the die temperature (120 / −90 / 60 ppm/°C, within the L3G4200D's
/// ±2 % over −40…85 °C) through a 10 °C warm-up, not declared: found, named and corrected, each
/// coefficient within 3σ of the truth, the calibration within 3σ at the floor. Without the
/// effect the loop took g-sensitivity, a fixture, an eccentricity and a gear lag for it and
/// flagged the result (exit 3).
#[test]
fn undeclared_temperature_dependent_sensitivity_is_found_named_and_corrected() {
    let truth_ppm_per_c = [120.0, -90.0, 60.0];
    let runs = plan(&[180.0, 90.0, -180.0], SHORT_S);
    let mut cfg = SimConfig::with_runs(1, runs);
    cfg.effects.enable("offset_drift").expect("known effect");
    cfg.effects.temperature_dependence = Some(crate::sim::thermal::TemperatureDependence {
        offset_dps_per_c: [0.0; 3],
        offset_dps_per_c2: [0.0; 3],
        sensitivity_ppm_per_c: truth_ppm_per_c,
        sensitivity_ppm_per_c2: [0.0; 3],
        direction_deg_per_c: [[0.0; 3]; 3],
        ..Default::default()
    });
    let out = simulate(&cfg).unwrap();
    let r =
        close_loop(&decode(&out.bytes).runs, &LoopOptions::default(), Some(out.truth.sensor())).expect("calibrates");
    assert!(r.effects().contains(&Effect::ScaleTemperature), "{}", r.summary());
    let last = r.steps.last().expect("steps");
    for (a, truth) in truth_ppm_per_c.iter().enumerate() {
        let name = format!("sensitivity vs temperature, {}", crate::calib::result::axes::AXES[a]);
        let p = last.effect_params.iter().find(|p| p.name == name).unwrap_or_else(|| panic!("{name}\n{}", r.summary()));
        let z = (p.estimate.value - truth) / p.estimate.sigma;
        assert!(z.abs() <= Z_1D, "{name}: {} ± {} against {truth}", p.estimate.value, p.estimate.sigma);
    }
    assert_within_3_sigma(&truth_of(last), "scale_temperature");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// An effect taken out of a fitted model starts the smaller model's fit at that model's optimum
/// as the full fit's sums see it: within Gauss-Newton's 0.1-σ stopping step of where the fit from
/// the model merely without it ends (hundreds of σ away here), so the fit from it stops after one
/// pass, at the same answer to 0.01 σ (the golden tests' tolerance).
#[test]
fn an_effect_taken_out_starts_its_refit_at_the_smaller_models_optimum() {
    let (runs, _) = capture_with(3, &[180.0, 90.0], 30.0, &["g_sensitivity", "delay_ms=5"], FullScale::Dps500);
    let data = LoopData::new(kinematics::reconstruct(&runs, &KinOptions::default()).expect("kinematics"));
    let w = [1.0; 3];
    let linear = crate::calib::engine::fit(&data, Model::for_data(&data), w).expect("the linear model fits");
    let model = linear.model.with(Effect::Delay, Default::default(), vec![0.0]).with(
        Effect::GSensitivity,
        std::array::from_fn(|_| vec![0.0; 3]),
        vec![],
    );
    let full = crate::calib::engine::fit(&data, model, w).expect("fits");
    let refit = crate::calib::engine::fit(&data, full.model.without(Effect::GSensitivity), w).expect("fits");
    let off = |m: &Model| {
        let nl = m.lin.len();
        (0..3 * nl + m.shared.len())
            .map(|i| {
                let (v, r) = if i < 3 * nl {
                    (m.beta[i / nl][i % nl], refit.model.beta[i / nl][i % nl])
                } else {
                    (m.theta[i - 3 * nl], refit.model.theta[i - 3 * nl])
                };
                (v - r).abs() / refit.solution.cov[(i, i)].sqrt()
            })
            .fold(0.0, f64::max)
    };
    let naive = off(&full.model.without(Effect::GSensitivity));
    let start = crate::calib::analysis::selection::start_without(&full, Effect::GSensitivity, w);
    let started = off(&start);
    assert!(naive > 10.0, "taking g-sensitivity out moves the model by only {naive:.3} σ");
    assert!(started < 0.1, "the start is {started:.3} σ from the refit (without it: {naive:.3} σ)");
    let from_start = crate::calib::engine::fit(&data, start, w).expect("fits");
    assert_eq!((refit.passes > 1, from_start.passes), (true, 1));
    let ended = off(&from_start.model);
    assert!(ended < 0.01, "the one-pass fit ends {ended:.4} σ from the refit");
}

/// A warm-up three times the simulator's default (30 °C), default design, seed 2: the warm-up's
/// fit beats the temperature-driven drift by 121 in BIC, though its best grid time constant
/// scored behind it. Compared on a floor under its profile over the time constant, it is fitted
/// and kept; compared on a parabola through the grid (which put it 1165 behind), it was left
/// unfitted and the answer ended 6σ off (trust bench, `offset_drift_x3`).
#[test]
fn a_warm_up_behind_on_its_grid_is_still_fitted_when_its_profile_may_win() {
    let (runs, truth) =
        capture_with(2, &[180.0, 90.0, -180.0], BAR_DURATION_S, &["offset_drift=30"], FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    assert!(r.effects().contains(&Effect::DriftWarmUp), "{}", r.summary());
    assert_drift_kept_by_bic(&r);
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "warm-up 3×");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// A fit that runs out of passes says so: a 5-ms delay fitted from 0 needs more than one
/// Gauss-Newton pass, so one pass leaves it unconverged (and the loop then treats it as no fit:
/// a candidate skipped, a final model not vouched for); given its passes it converges.
#[test]
fn a_fit_that_runs_out_of_passes_is_not_converged() {
    let (runs, _) = capture_with(4, &[180.0, 90.0], 20.0, &["delay_ms=5"], FullScale::Dps500);
    let data = LoopData::new(kinematics::reconstruct(&runs, &KinOptions::default()).expect("kinematics"));
    let linear = crate::calib::engine::fit(&data, Model::for_data(&data), [1.0; 3]).expect("the linear model fits");
    assert!(linear.converged, "a linear model converges in its one pass");
    let start = linear.model.with(Effect::Delay, Default::default(), vec![0.0]);
    let once = crate::calib::engine::solve::fit_at_most(&data, start.clone(), [1.0; 3], 1).expect("one pass");
    assert_eq!((once.passes, once.converged), (1, false));
    assert_eq!(
        crate::calib::analysis::selection::not_converged(&once),
        "its fit had not converged after 1 Gauss-Newton pass"
    );
    let full = crate::calib::engine::fit(&data, start, [1.0; 3]).expect("fits");
    assert!(full.converged && full.passes > 1, "{} passes", full.passes);
}

/// Axes sampled 0.3 ms (y) and −0.15 ms (z) behind x, not declared: each axis looks turned about
/// the table axis by θ2'·δ (0.05° on y at 180 °/s, half that at 90 °/s), so no one M fits both
/// speeds until the delays between the axes are found (the linear model's directions are more
/// than 10σ off); then both delays and every direction within 3σ of the truth, at the floor.
#[test]
fn undeclared_delays_between_the_axes_are_found_named_and_corrected() {
    let (r, _) = run_loop(9, &BAR_RATES_DPS, SHORT_S, &["axis_delay=0.3"]);
    assert_eq!(r.steps.get(1).and_then(|s| s.effect), Some(Effect::AxisDelay), "{}", r.summary());
    let last = r.steps.last().expect("steps");
    for (axis, truth_ms) in [("y", 0.3), ("z", -0.15)] {
        let name = format!("delay of {axis} behind x");
        let p = last.effect_params.iter().find(|p| p.name == name).unwrap_or_else(|| panic!("{name}\n{}", r.summary()));
        assert!(p.estimate.z(truth_ms).abs() <= Z_1D, "{name}: {} ± {} ms", p.estimate.value, p.estimate.sigma);
    }
    let before = truth_of(&r.steps[0]).direction_z.into_iter().fold(0.0, f64::max);
    assert!(before > 10.0, "the delays must matter for this test to mean anything: {before:.1}σ");
    assert_within_3_sigma(&truth_of(last), "axis_delay=0.3");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// The rig's crystal 60 ppm fast: the encoder's rates come out 60 ppm low, so every sensitivity
/// comes out 60 ppm high, alike, and no run can tell. The consider term carries its 20-ppm bound
/// in every sensitivity and nothing in the directions; declared at 60 ppm
/// (`--consider rig_clock=60`), the answer is within 3σ.
#[test]
fn a_rig_clock_off_its_frequency_moves_every_sensitivity_alike_and_sigma_carries_it() {
    let (runs, truth) = capture_with(4, &BAR_RATES_DPS, SHORT_S, &["rig_clock=60"], FullScale::Dps500);
    let calibrate = |consider: Option<&str>| {
        let mut opts = LoopOptions::default();
        if let Some(spec) = consider {
            opts.consider.add(spec).expect("a valid --consider");
        }
        close_loop(&runs, &opts, Some(truth.sensor())).expect("calibrates")
    };
    let r = calibrate(None);
    let term = r
        .final_report()
        .consider
        .iter()
        .find(|t| t.effect == Effect::RigClock.key())
        .cloned()
        .unwrap_or_else(|| panic!("no rig-clock term\n{}", r.summary()));
    for a in 0..3 {
        assert!((term.k_sigma_ppm[a] - 20.0).abs() < 0.01, "{term:?}");
        assert!(term.direction_sigma_deg[a] < 1e-9, "{term:?}");
    }
    let t = truth_of(r.steps.last().expect("steps"));
    for a in 0..3 {
        // σ of the sensitivity without the clock's 20 ppm: what the runs and the other terms give.
        let sigma_ppm = t.sensitivity_error_ppm[a] / t.sensitivity_z[a];
        let rest_ppm = (sigma_ppm * sigma_ppm - 400.0).sqrt();
        let off = t.sensitivity_error_ppm[a] - 60.0;
        assert!(off.abs() <= Z_1D * rest_ppm, "axis {a}: {} ppm against +60 ± {rest_ppm}", t.sensitivity_error_ppm[a]);
    }
    let declared = calibrate(Some("rig_clock=60"));
    assert_within_3_sigma(&truth_of(declared.steps.last().expect("steps")), "rig_clock=60 declared");
}

/// A random walk at 180 and 90 °/s in one direction (the trust bench's seed 5): the quadratic
/// drift wins on BIC, but it leaves wander that M takes up (0.006° and 42 ppm, 5.6σ, at exit 0).
/// Tested against the free drift on M (Hausman), the curve gives way: the free drift is kept, the
/// curve's skip says why, the residual is white and the answer within 3σ. The runs' elements
/// of M agree (χ² 23.1 for 8 against 27.9); the turn's test between the speeds flags this seed
/// (18.8 for 3 against 17.7): the walk's wander, which the consider covariance carries, is in
/// neither test's variance (docs/trust.md, "M changing with speed"; one seed in ten of this
/// cell, none of the default design's).
#[test]
fn a_drift_curve_that_biases_m_gives_way_to_the_free_drift() {
    let (runs, truth) = capture_with(5, &BAR_RATES_DPS, BAR_DURATION_S, &["bias_random_walk"], FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    let drifts: Vec<Effect> = r.effects().into_iter().filter(|e| e.is_drift()).collect();
    assert!(matches!(drifts[..], [Effect::DriftKnots(_)]), "{}", r.summary());
    assert!(r.skipped.iter().any(|s| s.why.contains("Hausman")), "the curve's skip must say why\n{}", r.summary());
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "random walk at 180, 90");
    assert!(!r.final_diagnostics().has_structure(), "{}", r.summary());
    let c = r.consistency.as_ref().expect("two speeds are compared");
    assert!(c.chi2 < c.threshold, "{c:?}");
}

/// Both directions at one speed with every realistic effect (the trust bench's seed 5): the
/// filter's droop is even in θ2', so these runs cannot tell it from a scale of M. Tried anyway
/// (two signed speeds), it took the table tilt's structure at Δχ² 11531 through the speed
/// ripple's harmonics, and every sensitivity ended 5000 ppm off at exit 0 (98σ). It is tried only
/// with two |θ2'| now: the tilt is found in its place, the droop's bound is carried in σ, and the
/// answer is within 3σ at the floor.
#[test]
fn both_directions_at_one_speed_never_fit_the_filter_droop() {
    let effects = crate::sim::Effects::REALISTIC;
    let (runs, truth) = capture_with(5, &[180.0, -180.0], BAR_DURATION_S, &effects, FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    assert!(!r.effects().contains(&Effect::FilterGain), "{}", r.summary());
    assert!(r.effects().contains(&Effect::TableTilt), "{}", r.summary());
    assert!(
        r.final_report().consider.iter().any(|t| t.effect == Effect::FilterGain.key()),
        "the droop's bound must be carried\n{}",
        r.summary()
    );
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "realistic at ±180");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// Twenty-second runs of a rig drawn at random (`host simulate --drawn-rig`, the trust bench's
/// `drawn` column), calibrated with nothing declared.
fn drawn_rig_loop(seed: u64, rates_dps: &[f64]) -> (LoopReport, Truth) {
    grown_rig_loop(seed, rates_dps, 20.0, 1.0)
}

/// [`drawn_rig_loop`] with runs of `duration_s` and every size range `scale` times
/// (`--drawn-rig=SCALE`).
fn grown_rig_loop(seed: u64, rates_dps: &[f64], duration_s: f64, scale: f64) -> (LoopReport, Truth) {
    let mut cfg = SimConfig::with_runs(seed, plan(rates_dps, duration_s));
    cfg.effects = crate::sim::Effects::drawn_scaled(&mut crate::sim::effects_rng(seed), scale);
    let out = simulate(&cfg).unwrap();
    let cap = decode(&out.bytes);
    let r = close_loop(&cap.runs, &LoopOptions::default(), Some(out.truth.sensor())).expect("calibrates");
    (r, out.truth)
}

/// The drawn rig of seed 1 at 180, 90 °/s for 20 s: the g-sensitivity was tried and its score
/// fell below the test's χ² 35 once the tilt and the fixture were in, but along directions the
/// runs see at λ between 25 and 50 a test of nine parameters misses an effect of plausible size
/// one time in four or more, and the bias it left was 4.4σ at exit 0. Those directions are now
/// carried in σ: within 3σ.
#[test]
fn a_test_too_weak_to_see_a_plausible_effect_does_not_speak_for_it() {
    let (r, _) = drawn_rig_loop(1, &[180.0, 90.0]);
    assert!(!r.effects().contains(&Effect::GSensitivity), "{}", r.summary());
    assert!(
        r.final_report().consider.iter().any(|t| t.effect == Effect::GSensitivity.key()),
        "the g-sensitivity's unseen part must be carried\n{}",
        r.summary()
    );
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "drawn rig 1 at 180, 90 for 20 s");
}

/// The drawn rig of seed 1 at ±180 °/s for 20 s: its offset walks 0.0034 °/s/√s under a
/// warm-up, which the loop fits as a curve. A curve never follows a walk, and in 20 s the walk's
/// wander is not slow against the table's turn: it left 0.005° in a direction (4.6σ) at exit 0.
/// The walk's steps between the finest knots are now carried in σ, at the size the residual
/// allows (0.74 of the datasheet-sized prior here, whose 0.003 °/s/√s the drawn walk exceeds):
/// the issue's bar, |z| ≤ 4 at exit 0 (3.46 on this direction).
#[test]
fn an_offset_random_walk_no_knots_follow_is_carried_in_sigma() {
    let (r, _) = drawn_rig_loop(1, &[180.0, -180.0]);
    assert!(!r.effects().iter().any(|e| matches!(e, Effect::DriftKnots(10))), "{}", r.summary());
    let walk = r.final_report().consider.iter().find(|t| t.effect == "drift_knots_10s");
    assert!(walk.is_some_and(|t| t.unseparated > 0), "the walk's bound must be carried\n{}", r.summary());
    let t = truth_of(r.steps.last().expect("steps"));
    assert!(t.max_z() <= 4.0, "drawn rig 1 at ±180 for 20 s: max |z| {:.2}\n{}", t.max_z(), r.summary());
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
}

/// The loop on one capture per run of `rates_dps` in both poses for `duration_s` each, as the
/// independent captures are, each simulated alone with `effects`; with the sensor's truth.
fn capture_per_run_loop(seed: u64, rates_dps: &[f64], duration_s: f64, effects: &[&str]) -> (LoopReport, Truth) {
    capture_per_run_loop_at(seed, rates_dps, duration_s, effects, protocol::GyroConfig::DEFAULT)
}

/// [`capture_per_run_loop`] with the gyro set to `gyro`.
fn capture_per_run_loop_at(
    seed: u64,
    rates_dps: &[f64],
    duration_s: f64,
    effects: &[&str],
    gyro: protocol::GyroConfig,
) -> (LoopReport, Truth) {
    let (mut runs, mut truth) = (Vec::new(), None);
    for spec in plan(rates_dps, duration_s) {
        let mut cfg = SimConfig::with_runs(seed, vec![spec]);
        cfg.gyro = gyro;
        for e in effects {
            cfg.effects.enable(e).expect("known effect");
        }
        let out = simulate(&cfg).unwrap();
        runs.extend(decode(&out.bytes).runs);
        truth.get_or_insert(out.truth);
    }
    let truth = truth.expect("a capture per run");
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    (r, truth)
}

/// Seed 9 at ±180 °/s for 120 s, each run captured on its own as the independent captures
/// are, each capture with a zero-rate level of its own (`capture_level`, 0.005 °/s rms per
/// axis): the model held one offset through the four captures, and their levels, too small for
/// the run-to-run test, bent M through its constant rate θ2'·M R_qᵀ e_z2: 3.84σ at exit 0 (z RMS
/// 1.68). The level of each stretch is now carried in σ at the size the residual's levels allow
/// (the trust bench's `180,-180@120/files` design): 2.11.
#[test]
fn an_offset_step_between_captures_is_carried_in_sigma() {
    let (r, _) = capture_per_run_loop(9, &[180.0, -180.0], 120.0, &["capture_level"]);
    assert!(!r.effects().iter().any(|e| e.is_free_drift()), "{}", r.summary());
    let level = r.final_report().consider.iter().find(|t| t.effect == "stretch_level");
    assert!(level.is_some_and(|t| t.unseparated > 0), "the levels' bound must be carried\n{}", r.summary());
    let t = truth_of(r.steps.last().expect("steps"));
    assert!(t.max_z() <= 3.0, "seed 9 at ±180, a capture per run: max |z| {:.2}\n{}", t.max_z(), r.summary());
}

/// A table tilt of 0.9° (three times its plausible 0.3°) on a capture per run, with a warm-up
/// for which the free drift gives each capture its level: the tilt's constant rate θ1'·sin ε is
/// then the levels', and what is left, cos ε on every in-plane rate, scales M where no run sees
/// it (ε²/2 = 123 ppm). The tilt's column, ∂/∂ε at ε = 0, carries none of that: every
/// sensitivity ended 127 ppm off, 5.1σ, at exit 0. The consider covariance now carries the
/// second-order scale of the tilt's posterior (here its prior: √3·ε²/2 = 24 ppm at 0.3°).
#[test]
fn a_tilt_only_levels_per_capture_could_show_is_carried_to_second_order() {
    let (r, _) = capture_per_run_loop(12, &[180.0, -180.0], 120.0, &["table_tilt=0.9", "offset_drift"]);
    assert!(r.effects().iter().any(|e| e.is_free_drift()), "{}", r.summary());
    assert!(!r.effects().contains(&Effect::TableTilt), "{}", r.summary());
    let tilt = r.final_report().consider.iter().find(|t| t.effect == "table_tilt").expect("the tilt is considered");
    assert!(tilt.k_sigma_ppm.iter().all(|&p| p >= 23.7), "{:?}\n{}", tilt.k_sigma_ppm, r.summary());
    let t = truth_of(r.steps.last().expect("steps"));
    assert!(t.max_z() <= 4.0, "seed 12, a 0.9° tilt, a capture per run: max |z| {:.2}\n{}", t.max_z(), r.summary());
}

/// A capture per run at ±180 °/s with a warm-up and a random walk the warm-up curve leaves: the
/// captures' levels differ by the walk's wander, and a level that differs between the +180 and
/// −180 captures is what a turn of the sensor about the table's in-plane axes would put there
/// (θ2'·M·Rᵀe_z2 changes sign with the direction). The consistency test read it as the runs at
/// −180 °/s seeing the sensor turned by 0.0044° (χ² 50.8 for 3 degrees of freedom) and flagged a
/// calibration 0.0024° and 18 ppm from the truth (max |z| 1.7). Each capture's level is now a
/// nuisance of the test: no disagreement, exit 0.
#[test]
fn levels_that_differ_between_captures_are_not_read_as_m_changing_with_speed() {
    let (r, _) =
        capture_per_run_loop(1, &[180.0, -180.0], 120.0, &["offset_drift", "bias_random_walk", "capture_level=0"]);
    assert!(!r.effects().iter().any(|e| e.is_free_drift()), "the warm-up curve holds the levels\n{}", r.summary());
    let c = r.consistency.as_ref().expect("two signed speeds");
    assert!(!c.disagrees(), "{c:?}\n{}", r.summary());
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
    let t = truth_of(r.steps.last().expect("steps"));
    assert!(t.max_z() <= 4.0, "max |z| {:.2}\n{}", t.max_z(), r.summary());
}

/// What `../shared/validation`'s README says its realistic captures hold: the gyro's low-pass,
/// timestamp jitter, speed ripple, Earth at 45°, a warm-up with a random walk, the gears' error
/// (each capture with the level it starts at, no level of its own).
const INDEPENDENT_EFFECTS: [&str; 8] = [
    "filter_delay",
    "timestamp_jitter",
    "speed_ripple",
    "earth_rotation",
    "offset_drift",
    "bias_random_walk",
    "gear_transmission",
    "capture_level=0",
];

/// The independent captures' effect set with the gyro at 400 Hz and its 20-Hz low-pass (11 ms
/// of delay), 180 and 90 °/s in one direction, a capture per run, seed 2. The loop takes the
/// filter's droop κ (gain 1 − κω², 4.1σ), which at two speeds in one direction leaves Earth's
/// vertical rate without a shape of its own: fitted freely it read 1143 ± 634 °/h, κ −229 ±
/// 132 ms², every sensitivity 4000 ppm off with a σ of 9000 ppm (exit 0, |z| 0.6: honest and
/// useless). The runs do not bound the vertical within the 15.041 °/h the Earth turns, so its
/// prior (Ω/√3) holds it: κ stays where the data put it before Earth, and what is left is the
/// g-sensitivity these runs cannot separate (its 760-ppm consider term).
#[test]
fn an_earth_rate_the_runs_cannot_bound_is_held_by_physics() {
    let gyro = protocol::GyroConfig {
        odr: protocol::Odr::Hz400,
        bandwidth: protocol::Bandwidth::Bw0,
        ..protocol::GyroConfig::DEFAULT
    };
    let (r, _) = capture_per_run_loop_at(2, &[180.0, 90.0], 120.0, &INDEPENDENT_EFFECTS, gyro);
    let omega_dph = 15.041;
    let vertical = r.steps.last().and_then(|s| s.effect_params.iter().find(|p| p.name == "Earth rate, vertical"));
    let v = vertical.unwrap_or_else(|| panic!("Earth's vertical is in the model\n{}", r.summary())).estimate;
    assert!(v.value.abs() <= omega_dph && v.sigma <= omega_dph / 3f64.sqrt() + 0.01, "{v:?}\n{}", r.summary());
    let held = r.notes.iter().any(|n| matches!(n, Note::HeldByPrior { name, .. } if name == "Earth rate, vertical"));
    assert!(held, "the notes say the vertical is held by its prior\n{}", r.summary());
    let t = truth_of(r.steps.last().expect("steps"));
    let sigma_ppm: Vec<f64> = (0..3).map(|a| t.sensitivity_error_ppm[a] / t.sensitivity_z[a]).collect();
    assert!(sigma_ppm.iter().all(|s| s.abs() < 1000.0), "σ k {sigma_ppm:?} ppm\n{}", r.summary());
    assert!(t.sensitivity_error_ppm.iter().all(|e| e.abs() < 300.0), "{:?}\n{}", t.sensitivity_error_ppm, r.summary());
    assert!(t.max_z() <= 3.0, "max |z| {:.2}\n{}", t.max_z(), r.summary());
}

/// One speed, a capture per run, the gyro's low-pass at 35 Hz (6.4 ms) and the motor's default
/// speed ripple (0.5 % at 1×, 0.25 % at 2×, 0.1 % at 12×), seed 1. At one speed the combined
/// phase takes θ2's part of the delay, and the ripple reaches the gyro 6.4 ms after the encoder
/// reads it: lines at 11× and 13× (9σ) were left that no effect explained, flagged on every seed
/// of the trust bench, while the delay's column lacked the rate's part (−θ1''·τ) and the delay
/// was not tried on top of the phase. With both, the ripple's timing gives the delay (and the
/// phase, with no index offset here, is then dropped as redundant).
#[test]
fn at_one_speed_the_ripples_timing_tells_the_delay() {
    let (r, truth) = capture_per_run_loop(1, &[180.0], 120.0, &["filter_cutoff_hz=35", "speed_ripple"]);
    assert_eq!(r.steps[1].effects, [Effect::Phase], "{}", r.summary());
    assert!(r.effects().contains(&Effect::Delay), "{}", r.summary());
    let last = r.steps.last().expect("steps");
    let tau = last.effect_params.iter().find(|p| p.name == "delay τ").expect("the delay is reported").estimate;
    let true_ms = truth.runs[0].total_delay_ms;
    assert!((tau.value - true_ms).abs() <= 4.0 * tau.sigma + 0.05, "τ {tau:?} ms against {true_ms} ms");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
    let t = truth_of(last);
    assert!(t.max_z() <= 4.0, "max |z| {:.2}\n{}", t.max_z(), r.summary());
}

/// The independent captures' effect set with the gyro at 100 Hz and its 25-Hz low-pass (7.1 ms),
/// 180 and 90 °/s, a capture per run, seed 4. Before the delay's column carried the rate's part
/// (−θ1''·τ), the fit settled where that incomplete Jacobian stopped, and the structure it left
/// took a g-sensitivity, a delay between the axes and a turn of the pose-2 fixture that are not
/// there: every sensitivity 555 ppm and the directions 0.1° off (|z| 7.1), flagged by the
/// g-sensitivity's note, as on four of six seeds. Now it is calibrated within the noise.
#[test]
fn a_slow_gyros_delay_fitted_with_the_ripples_part_leaves_no_false_effects() {
    let gyro = protocol::GyroConfig {
        odr: protocol::Odr::Hz100,
        bandwidth: protocol::Bandwidth::Bw1,
        ..protocol::GyroConfig::DEFAULT
    };
    let (r, _) = capture_per_run_loop_at(4, &[180.0, 90.0], 120.0, &INDEPENDENT_EFFECTS, gyro);
    let effects = r.effects();
    let false_ones = [Effect::GSensitivity, Effect::AxisDelay, Effect::PoseFixture];
    assert!(!false_ones.iter().any(|e| effects.contains(e)), "{effects:?}\n{}", r.summary());
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
    let t = truth_of(r.steps.last().expect("steps"));
    assert!(t.sensitivity_error_ppm.iter().all(|e| e.abs() < 100.0), "{:?}\n{}", t.sensitivity_error_ppm, r.summary());
    assert!(t.max_z() <= 4.0, "max |z| {:.2}\n{}", t.max_z(), r.summary());
}

/// The independent captures' effect set (filter, timestamp jitter, speed ripple, Earth at 45°, a
/// warm-up with a random walk, the gears' error) on a capture per run at ±180 °/s, seed 8: Earth's
/// free rate reads 24.3 ± 4.0 °/h, 2.3σ above the 15.041 °/h the Earth turns, with every value
/// within 1.7σ of the truth. Tested at 2σ, that flagged the calibration; at the loop's α (3.1σ)
/// it is what noise gives, and the calibration ends at exit 0.
#[test]
fn a_free_earth_rate_a_little_above_the_earths_is_not_flagged() {
    let (r, _) = capture_per_run_loop(8, &[180.0, -180.0], 120.0, &INDEPENDENT_EFFECTS);
    let earth = r.steps.last().and_then(|s| s.effect_params.iter().find(|p| p.name.contains("Earth rate")));
    assert!(earth.is_some(), "Earth is fitted freely\n{}", r.summary());
    assert!(r.earth_excess.is_none(), "{:?}\n{}", r.earth_excess, r.summary());
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
    let t = truth_of(r.steps.last().expect("steps"));
    assert!(t.max_z() <= 4.0, "max |z| {:.2}\n{}", t.max_z(), r.summary());
}

/// The drawn rig of seed 2 with every range tripled, at 180, 90 °/s for 30 s: once the
/// g-sensitivity was in, the loop fitted the filter gain at κ ≈ −970 ms², 500 times what a
/// low-pass with the fitted 1.9-ms delay allows, the pair standing in for a speed ripple no
/// effect models (at 120 s every sensitivity ended 1.5 % off, 8σ, at exit 0). Two speeds in one
/// direction cannot tell the droop (∝ θ2'³) from M and gravity: it is no longer tried, and what
/// the loop ends with is within 4σ or flagged.
#[test]
fn a_filter_gain_the_rates_cannot_tell_from_m_and_gravity_is_not_tried() {
    let (r, _) = grown_rig_loop(2, &[180.0, 90.0], 30.0, 3.0);
    assert!(r.effects().contains(&Effect::GSensitivity), "{}", r.summary());
    assert!(!r.effects().contains(&Effect::FilterGain), "{}", r.summary());
    assert!(!r.skipped.iter().any(|s| s.effect == Effect::FilterGain), "{:?}\n{}", r.skipped, r.summary());
    let t = truth_of(r.steps.last().expect("steps"));
    assert!(
        r.verdict() != Verdict::AtNoiseFloor || t.max_z() <= 4.0,
        "max |z| {:.2} at the noise floor\n{}",
        t.max_z(),
        r.summary()
    );
}

/// The linear model fitted to a simulated session, then `effect` (its shared parameters from 0)
/// fitted on top of it: an effect's own fit, without the loop.
fn linear_and(cfg: &SimConfig, effect: Effect) -> crate::calib::engine::Fitted {
    let out = simulate(cfg).unwrap();
    let data =
        LoopData::new(kinematics::reconstruct(&decode(&out.bytes).runs, &KinOptions::default()).expect("kinematics"));
    let linear = crate::calib::engine::fit(&data, Model::for_data(&data), [1.0; 3]).expect("the linear model fits");
    let n_shared = effect.params(&data.layout).1.len();
    let model = linear.model.with(effect, Default::default(), vec![0.0; n_shared]);
    crate::calib::engine::fit(&data, model, [1.0; 3]).expect("fits")
}

/// A delay between the axes delays the motor's own speed ripple too, which the encoder's rates
/// carry: with a 2 % ripple at 16× (the 16-pole gears' pole pass) and y 0.3 ms, z −0.15 ms
/// behind x, a model that turned each axis by θ2'·δ only left the ripple's θ1''·δ in the
/// residual at 16× (y: 0.02·180 °/s·16·π rad/s·0.3 ms = 0.054 °/s). No gyro noise here: what
/// remains is the counts' rounding (0.29 counts rms) and the encoder's rate noise through M
/// (0.016 °/s, ≈ 0.85 counts rms): 0.81-0.89 counts rms on the three axes, where leaving the
/// ripple's term out left 1.52 on y; both delays come out within 3 µs (1 % of y's).
#[test]
fn a_delay_between_the_axes_delays_the_motor_speed_ripple_too() {
    use crate::sim::effects::{AxisDelay, RippleHarmonic, SpeedRipple};
    let runs = plan(&[180.0, -90.0], 20.0);
    let mut cfg = SimConfig::with_runs(4, runs);
    cfg.noise_dps_per_sqrt_hz = 0.0;
    let still = RippleHarmonic { order: 1, amplitude: 0.0, phase_rad: 0.0 };
    cfg.effects.speed_ripple =
        Some(SpeedRipple { harmonics: [RippleHarmonic { order: 16, amplitude: 0.02, phase_rad: 0.4 }, still, still] });
    let truth_ms = [0.3, -0.15];
    cfg.effects.axis_delay = Some(AxisDelay { delay_ms: [0.0, truth_ms[0], truth_ms[1]] });
    let fitted = linear_and(&cfg, Effect::AxisDelay);
    let sol = &fitted.solution;
    let rms_counts: [f64; 3] = std::array::from_fn(|a| (sol.rss[a] / sol.n[a] as f64).sqrt());
    for (a, rms) in rms_counts.iter().enumerate() {
        assert!(*rms < 1.0, "axis {a}: residual {rms:.2} counts rms, {rms_counts:?}");
    }
    let delays_ms: Vec<f64> = (0..2)
        .map(|k| fitted.model.theta_of(SharedPar { effect: Effect::AxisDelay, k }).expect("fitted") * 1e3)
        .collect();
    for (got, want) in delays_ms.iter().zip(truth_ms) {
        assert!((got - want).abs() < 3e-3, "{delays_ms:?} ms vs {truth_ms:?}");
    }
}

/// The motor's speed ripple at 16× (1.5 %, the 16-pole gears' pole pass; 8 Hz at 180 °/s) is
/// in the encoder's rates, and θ1' multiplies every axis's signal: a straight line through 20 ms
/// of counts kept 97.2 % of it, and the 0.076 °/s it missed came back as lines at 15× and 17×
/// (0.038 °/s each, ~7σ in 30-s runs) that no effect explains, so the loop flagged the capture.
/// The rate exact for cubics keeps 99.9 % (`data::encoder_rate`): at the floor, within 3σ.
#[test]
fn the_motor_ripple_at_the_pole_pass_is_in_the_rates_the_model_uses() {
    use crate::sim::effects::{RippleHarmonic, SpeedRipple};
    let runs = plan(&[180.0, 90.0], 30.0);
    let mut cfg = SimConfig::with_runs(6, runs);
    cfg.effects.speed_ripple = Some(SpeedRipple {
        harmonics: [
            RippleHarmonic { order: 1, amplitude: 0.005, phase_rad: 0.7 },
            RippleHarmonic { order: 2, amplitude: 0.0025, phase_rad: 2.1 },
            RippleHarmonic { order: 16, amplitude: 0.015, phase_rad: -1.5 },
        ],
    });
    let out = simulate(&cfg).unwrap();
    let runs = decode(&out.bytes).runs;
    let r = close_loop(&runs, &LoopOptions::default(), Some(out.truth.sensor())).expect("calibrates");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "a 1.5 % ripple at 16×");
}

/// A 5 % speed ripple at 1× and 2.5 % at 2× (ten times the simulator's default) is the motor's
/// own, which the encoder tracks. Cutting every sample more than 2 % off the run's speed kept a
/// sixth of them, at the few phases of θ1 where the ripple is near its mean, and the trust
/// bench's 120-s runs were flagged by a 9σ line at 1× in what was left. A sample whose base
/// revolution's mean speed is steady is kept: only the ramps are cut, and the answer is at the
/// floor within 3σ.
#[test]
fn a_large_speed_ripple_is_tracked_not_cut() {
    use crate::sim::effects::{RippleHarmonic, SpeedRipple};
    let mut cfg = SimConfig::with_runs(3, plan(&[180.0, -180.0], 40.0));
    cfg.effects.speed_ripple = Some(SpeedRipple {
        harmonics: [
            RippleHarmonic { order: 1, amplitude: 0.05, phase_rad: 0.7 },
            RippleHarmonic { order: 2, amplitude: 0.025, phase_rad: 2.1 },
            RippleHarmonic { order: 12, amplitude: 0.01, phase_rad: 0.0 },
        ],
    });
    let out = simulate(&cfg).unwrap();
    let runs = decode(&out.bytes).runs;
    let kin = kinematics::reconstruct(&runs, &KinOptions::default()).expect("kinematics");
    for k in &kin.runs {
        let kept = k.samples.len() as f64 / k.total as f64;
        // The 40-s run less its spin-up, the half revolution after it (whose ripple peaks the
        // revolution's mean cannot yet tell from the ramp) and the rate windows' edges: 93 %.
        // With every sample 2 % off cut, a third.
        assert!(kept > 0.9, "run {}: {:.1} % of its samples kept", k.run, 100.0 * kept);
        assert!(k.excluded_unsteady > 100, "run {}: the spin-up is cut ({})", k.run, k.excluded_unsteady);
    }
    let r = close_loop(&runs, &LoopOptions::default(), Some(out.truth.sensor())).expect("calibrates");
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), "a 5 % ripple at 1×");
}

/// The model reads ω_s through θ1', so the encoder's own noise on θ1' moves the prediction and not
/// the gyro: the residual follows the speed deviation with slope −k·⟨ω_a⟩/100 per %, which long
/// clean captures resolve (the clean hour's note said the kinematics may not track the table at
/// 14.9σ). Taken against that echo, the speed ripple check finds nothing on a clean 2 × 300 s at
/// one speed (a table that does not do what the encoder says would leave a slope outside it).
#[test]
fn the_rate_estimates_own_noise_is_not_taken_for_a_table_the_encoder_misses() {
    use crate::calib::analysis::diagnostics::ripple_beyond_echo;
    assert_eq!(ripple_beyond_echo(-3.0, -5.0), 0.0);
    assert_eq!(ripple_beyond_echo(-6.0, -5.0), -1.0);
    assert_eq!(ripple_beyond_echo(2.0, -5.0), 2.0);
    assert_eq!(ripple_beyond_echo(4.0, 5.0), 0.0);
    let (runs, truth) = capture_with(7, &[180.0], 300.0, &[], FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    for run in &r.final_diagnostics().runs {
        for a in &run.axes {
            assert!(a.ripple.sigma < 3.0, "run {} axis {}: {:.1}σ beyond the echo", run.run, a.axis, a.ripple.sigma);
        }
    }
}

/// A base encoder whose scale sits off its shaft reads θ1 with an error once a turn, and θ1'
/// with its derivative; θ2, geared to the base, inherits the angle error, while the tables turn
/// evenly. A sensor-table eccentricity and a pose fixture took its place and left the
/// directions 0.07° off at exit 0 (89σ) for 0.05° of eccentricity. Modelled, it comes out at
/// its size (without noise, to 1 %), and the loop finds it and ends at the floor within 3σ.
#[test]
fn an_eccentric_encoder_is_found_not_taken_up_by_the_directions() {
    use crate::sim::effects::EncoderEccentricity;
    let truth = EncoderEccentricity { amplitude_deg: 0.05, phase_rad: 0.3, order: 1 };
    assert_encoder_error_found(truth, |e| e.encoder_eccentricity = Some(truth), Effect::EncoderEccentricity);
}

/// An out-of-round scale errs twice a turn: its θ1' ripple at 2× makes a 1× part of the
/// in-plane rate, which M took up, and a 3× line. Unmodelled it was flagged (8.6-52σ off had it
/// been believed); modelled it comes out at its size and the loop ends at the floor within 3σ.
#[test]
fn an_elliptical_encoder_is_found_not_taken_up_by_the_directions() {
    use crate::sim::effects::EncoderEccentricity;
    let truth = EncoderEccentricity { amplitude_deg: 0.05, phase_rad: 1.1, order: 2 };
    assert_encoder_error_found(truth, |e| e.encoder_ellipticity = Some(truth), Effect::EncoderEllipticity);
}

/// The encoder error `truth`, switched on by `set`: noise-free, the effect `effect` fitted on
/// the linear model gives its amplitude to 1 %; with noise, the loop takes it and ends at the
/// floor within 3σ of the truth.
fn assert_encoder_error_found(
    truth: crate::sim::effects::EncoderEccentricity,
    set: impl Fn(&mut crate::sim::Effects),
    effect: Effect,
) {
    let mut quiet = SimConfig::with_runs(5, plan(&[180.0, -90.0], 20.0));
    quiet.noise_dps_per_sqrt_hz = 0.0;
    set(&mut quiet.effects);
    let fitted = linear_and(&quiet, effect);
    let [a, b] = [0, 1].map(|k| fitted.model.theta_of(SharedPar { effect, k }).expect("fitted"));
    let amplitude_deg = a.hypot(b).to_degrees();
    assert!((amplitude_deg - truth.amplitude_deg).abs() < 0.01 * truth.amplitude_deg, "{amplitude_deg}° of {truth:?}");

    let mut cfg = SimConfig::with_runs(5, plan(&[180.0, 90.0, -180.0], 30.0));
    set(&mut cfg.effects);
    let out = simulate(&cfg).unwrap();
    let r =
        close_loop(&decode(&out.bytes).runs, &LoopOptions::default(), Some(out.truth.sensor())).expect("calibrates");
    assert!(r.steps.iter().any(|s| s.effect == Some(effect)), "{}", r.summary());
    assert_eq!(r.verdict(), Verdict::AtNoiseFloor, "{}", r.summary());
    assert_within_3_sigma(&truth_of(r.steps.last().expect("steps")), &format!("a base encoder 0.05° off, {truth:?}"));
}

/// A near tie carried into the report: with 20-s runs at two speeds, a per-axis delay (0.1 ms on
/// the y axis, the simulator's default) and a table tilt explain nearly the same structure, and
/// the loop took the tilt (the trust bench's `180,90@20`, `axis_delay`, seed 8: Δχ² 18.8 against
/// 15.3). The alternative is named in the notes and in `calibration.json`'s `model_choice`, with
/// its Akaike weight, and its spread of M is in σ: the answer is within 4σ (3.56 measured; 4.02
/// before the term).
#[test]
fn a_near_tie_between_candidates_is_carried_in_sigma_and_reported() {
    let (runs, truth) = capture_with(8, &[180.0, 90.0], 20.0, &["axis_delay"], FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    let noted: Vec<_> = r
        .notes
        .iter()
        .filter_map(|n| match n {
            Note::ModelChoice(t) => Some(t.clone()),
            _ => None,
        })
        .collect();
    let tie = noted.iter().find(|t| t.alternative == Effect::AxisDelay.key());
    let tie = tie.unwrap_or_else(|| panic!("no axis-delay alternative: {noted:?}"));
    assert_eq!(tie.taken, Effect::TableTilt.key(), "{tie:?}");
    assert!((0.01..0.5).contains(&tie.weight), "{tie:?}");
    assert!(tie.direction_sigma_deg[1] > 0.001, "the tie moves the y axis by ~0.002°: {tie:?}");
    assert_eq!(r.final_report().model_choice, noted);
    let t = truth_of(r.steps.last().expect("steps"));
    for a in 0..3 {
        assert!(t.direction_z[a] <= 4.0, "axis {a} direction {:.2}σ off", t.direction_z[a]);
        assert!(t.sensitivity_z[a].abs() <= Z_1D, "axis {a} sensitivity {:.2}σ off", t.sensitivity_z[a]);
    }
}

/// A base-encoder eccentricity of the simulator's default 0.01° on 20-s runs in both
/// directions: the residual's 2× line is too weak on such runs for the diagnostics to let the
/// loop try it, M takes up its constant part, and the answer was 4.26σ off at exit 0 (the trust
/// bench, `180,-180@20`, seed 44). The consider term sees the residual's score along it and
/// carries it in σ: within 3σ, with the term named.
#[test]
fn an_encoder_eccentricity_too_weak_to_try_is_carried_in_sigma() {
    let (runs, truth) = capture_with(44, &[180.0, -180.0], 20.0, &["encoder_eccentricity"], FullScale::Dps500);
    let r = close_loop(&runs, &LoopOptions::default(), Some(truth.sensor())).expect("calibrates");
    let term = r.final_report().consider.iter().find(|t| t.effect == Effect::EncoderEccentricity.key()).cloned();
    let term = term.unwrap_or_else(|| panic!("no encoder term: {:?}", r.final_report().consider));
    assert!(term.direction_sigma_deg.iter().any(|&d| d > 0.002), "{term:?}");
    let t = truth_of(r.steps.last().expect("steps"));
    assert!(t.max_sensitivity_ppm() > 20.0, "the effect must bias M for this test to mean anything: {t:?}");
    assert_within_3_sigma(&t, "20-s runs, encoder eccentricity");
}

/// A once-per-turn transmission error of the sensor table (0.01°, a drive 10 µm off centre) on
/// 20-s runs in both directions: its 2× line too weak for the diagnostics on such runs, it
/// turns the fitted axes by as much (0.010° here), and left untried it was 4.3σ off at exit 0.
/// Scored at every step, it is taken, and M ends within 3σ.
#[test]
fn a_sensor_table_eccentricity_with_a_weak_line_is_still_tried() {
    let mut cfg = SimConfig::with_runs(41, plan(&[180.0, -180.0], 20.0));
    cfg.effects.gear_transmission = Some(crate::sim::GearTransmission { harmonics: [(1, 0.01, 0.41), (24, 0.0, 0.0)] });
    let out = simulate(&cfg).unwrap();
    let r =
        close_loop(&decode(&out.bytes).runs, &LoopOptions::default(), Some(out.truth.sensor())).expect("calibrates");
    let last = r.steps.last().expect("steps");
    assert!(last.effects.contains(&Effect::TableHarmonic(1)), "{:?}", last.effects);
    let t = truth_of(last);
    assert!(t.direction_error_deg.iter().all(|&d| d < 0.005), "{t:?}");
    assert_within_3_sigma(&t, "20-s runs, sensor-table eccentricity");
}
