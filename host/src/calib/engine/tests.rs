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

/// A prior adds its precision to its parameter's diagonal and pulls the step towards −value,
/// only for a parameter the selection holds; the data's part of the system is untouched, and a
/// model holds only the priors of the parameters a fit found unbounded.
#[test]
fn a_prior_adds_its_precision_and_pulls_the_step_towards_zero() {
    use super::model::Prior;
    use super::solve::{normal_equations, Selection};
    use super::sums::Gram;
    // Two columns: one per-axis linear, one shared; each axis sees x = (1, 2), e = 3.
    let g = Gram {
        l: 2,
        xtx: std::array::from_fn(|_| vec![1.0, 2.0, 2.0, 4.5]),
        xte: std::array::from_fn(|_| vec![3.0, 6.5]),
        ete: [9.0; 3],
        n: [1; 3],
    };
    let sel = Selection { lin: vec![0], shared: vec![1] };
    let w = [1.0, 2.0, 0.5];
    let (a0, b0) = normal_equations(&g, &sel, w, &[]);
    // The shared parameter sits after the three axes' linear ones: Σ_a w_a·4.5 and Σ_a w_a·6.5.
    assert_eq!((a0[(3, 3)], b0[3]), (3.5 * 4.5, 3.5 * 6.5));
    let prior = Prior { col: 1, precision: 4.0, value: 0.25 };
    let (a1, b1) = normal_equations(&g, &sel, w, &[prior]);
    let mut expected = a0.clone();
    expected[(3, 3)] += 4.0;
    assert_eq!(a1, expected);
    assert_eq!(b1[3], b0[3] - 1.0);
    assert_eq!(b1.rows(0, 3), b0.rows(0, 3));
    // A prior on a column the selection leaves out changes nothing.
    let (a2, b2) = normal_equations(&g, &Selection { lin: vec![0], shared: vec![] }, w, &[prior]);
    assert_eq!((a2, b2), normal_equations(&g, &Selection { lin: vec![0], shared: vec![] }, w, &[]));
    // Earth's components have a physical size; a model holds a prior only once a fit held it.
    let earth = Model::base().with(Effect::EarthRotation, Default::default(), vec![1e-3, 0.0, 0.0]);
    assert!(earth.priors().is_empty());
    let vertical = SharedPar { effect: Effect::EarthRotation, k: 0 };
    let size = vertical.prior().expect("Earth's rate has a physical size");
    assert!((size.bound - 15.041 / 3600.0).abs() < 1e-6 && (size.sigma * 3f64.sqrt() - size.bound).abs() < 1e-12);
    let mut held = earth.clone();
    held.prior_held.push(vertical);
    let nl = held.lin.len();
    assert_eq!(held.priors(), vec![Prior { col: nl, precision: size.sigma.powi(-2), value: 1e-3 }]);
    assert!(held.without(Effect::EarthRotation).prior_held.is_empty());
}
