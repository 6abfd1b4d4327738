//! The engine's own tests: the chain, the accumulation and the solve against direct sums.

use crate::calib::effects::{Effect, MAX_DELAY_S};
use crate::geometry::Pose;
use nalgebra::DVector;

use super::loop_data::ValidSamples;
use super::model::Model;
use super::solve::apply_step;
use crate::calib::effects::terms::{LinCol, SharedPar};

#[test]
fn a_step_past_a_bound_stops_at_it() {
    let base = Model::base_for(&[Pose::One, Pose::Two]);
    let m = base.with(Effect::Delay, Default::default(), vec![0.0]).with(
        Effect::DriftWarmUp,
        std::array::from_fn(|_| vec![0.0]),
        vec![600.0],
    );
    let delay = SharedPar { effect: Effect::Delay, k: 0 };
    let tau = SharedPar { effect: Effect::DriftWarmUp, k: 0 };
    let tau_range = tau.bound().map(|b| (b.lo, b.hi)).unwrap();
    assert_eq!(tau_range, (1.0, 1e5));
    let nl = m.lin.len();
    for (step, delay_s, tau_s) in [(1.0, MAX_DELAY_S, tau_range.1), (-1.0, -MAX_DELAY_S, tau_range.0)] {
        let mut moved = m.clone();
        let mut delta = DVector::zeros(3 * nl + 2);
        delta[3 * nl] = step;
        delta[3 * nl + 1] = step * 1e9;
        apply_step(&mut moved, nl, &delta, &[false, false]);
        assert_eq!(moved.theta_of(delay), Some(delay_s));
        assert_eq!(moved.theta_of(tau), Some(tau_s));
    }
    // The angles and rates are bounded by the data alone.
    assert_eq!(SharedPar { effect: Effect::IndexOffset, k: 0 }.bound(), None);
    assert_eq!(delay.bound().map(|b| (b.what, b.unit)), Some(("delay", "s")));
}

#[test]
fn effect_parameters_are_reported_in_their_units() {
    let r = SharedPar { effect: Effect::Delay, k: 0 }.reported();
    assert_eq!((r.name.as_str(), r.scale, r.unit), ("delay τ", 1e3, "ms"));
    // Parameter 3 of the first harmonic is pose 2's sine; of a higher one, run 2's.
    let r = SharedPar { effect: Effect::TableHarmonic(1), k: 3 }.reported();
    assert_eq!(r.name, "table-speed ripple 1× sin, pose 2");
    let r = SharedPar { effect: Effect::TableHarmonic(12), k: 3 }.reported();
    assert_eq!(r.name, "table-speed ripple 12× sin, run 2");
    // r·|r| per (°/s)² at 500 °/s full scale is 5e4 % of full scale per unit.
    let r = LinCol::Of(Effect::RateScale, 1).reported(500.0).unwrap();
    assert_eq!((r.scale, r.unit), (5e4, "% of full scale"));
    // r³ per (°/s)³ at 500 °/s full scale is 2.5e7 % of full scale per unit.
    let r = LinCol::Of(Effect::RatePower(3), 0).reported(500.0).unwrap();
    assert_eq!((r.name.as_str(), r.scale, r.unit), ("odd cubic (r³) at full scale", 2.5e7, "% of full scale"));
    let r = LinCol::Of(Effect::RatePower(2), 0).reported(500.0).unwrap();
    assert_eq!((r.name.as_str(), r.scale, r.unit), ("even quadratic (r²) at full scale", 5e4, "% of full scale"));
    let r = LinCol::Of(Effect::GSensitivity, 1).reported(500.0).unwrap();
    assert_eq!(r.name, "g-sensitivity along package y");
    // The base columns are M and the offsets, the knots the drift table: not effect parameters.
    for c in [LinCol::Omega(0), LinCol::One, LinCol::DriftKnot { stretch: 0, knot: 1, spacing_s: 40 }] {
        assert_eq!(c.reported(500.0), None);
    }
}

/// The ranges mark exactly the samples the per-sample rule marks (clear of both ends and of
/// every gap by `guard` samples), and their queries agree with the flags.
#[test]
fn valid_ranges_match_the_per_sample_rule() {
    let flags = |t: &[f64], gap: f64, guard: usize| -> Vec<bool> {
        let n = t.len();
        (0..n)
            .map(|i| {
                let before = (0..=i).rev().find(|&j| j > 0 && t[j] - t[j - 1] > gap).unwrap_or(0);
                let after = (i..n).find(|&j| j + 1 < n && t[j + 1] - t[j] > gap).unwrap_or(usize::MAX);
                i >= before + guard && i + guard < n && after.saturating_sub(i) >= guard
            })
            .collect()
    };
    // Gaps after samples 9, 12 (a stretch too short to use) and 40; one right at the end.
    let mut t: Vec<f64> = Vec::new();
    let mut now = 0.0;
    for i in 0..60 {
        t.push(now);
        now += if [9, 12, 40, 58].contains(&i) { 5.0 } else { 1.0 };
    }
    for guard in [0, 1, 2, 3, 30] {
        let v = ValidSamples::of(t.len(), |i| t[i], 1.5, guard);
        let f = flags(&t, 1.5, guard);
        let expected: Vec<usize> = (0..t.len()).filter(|&i| f[i]).collect();
        assert_eq!(v.indices().collect::<Vec<_>>(), expected, "guard {guard}");
        assert_eq!(v.len(), expected.len());
        assert_eq!((v.first(), v.last()), (expected.first().copied(), expected.last().copied()));
        for (i, &fi) in f.iter().enumerate() {
            assert_eq!(v.contains(i), fi, "guard {guard}, sample {i}");
        }
        for (lo, hi) in [(0, 60), (5, 15), (11, 12), (20, 50), (59, 60)] {
            let want: Vec<usize> = expected.iter().copied().filter(|&i| i >= lo && i < hi).collect();
            assert_eq!(v.indices_in(lo, hi).collect::<Vec<_>>(), want, "guard {guard}, {lo}..{hi}");
        }
    }
    assert!(ValidSamples::of(t.len(), |i| t[i], 1.5, 30).is_empty());
}
