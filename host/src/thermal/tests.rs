//! The bars of issue 27 on the simulator, for one seed in the time a unit test may take: five
//! setpoints −20…70 °C, both poses at 180 °/s for 20 s each, the die settled by the live
//! session's criterion. `host/benches/thermal.rs` runs ten seeds with longer runs and every
//! realistic effect.

use super::programme::programme;
use super::truth_check::{self, coefficients, held_out_rate_z, single_setpoint_z};
use super::*;
use crate::calib::Estimate;
use crate::capture::decode;
use crate::sim::{self, SimConfig};

/// The setpoints.
pub const SETPOINTS_C: [f64; 5] = [-20.0, 0.0, 25.0, 50.0, 70.0];
const DURATION_S: f64 = 20.0;
/// |z| of "within 3σ".
const Z_BAR: f64 = 3.0;

/// Simulates and calibrates one session (linear model: no rig effect is on).
fn calibrate(cfg: &SimConfig, setpoint_c: f64) -> (SetpointCal, sim::Truth) {
    let out = sim::simulate(cfg).unwrap();
    let cap = decode(&out.bytes);
    assert!(cap.loss.is_clean());
    let report = crate::calib::calibrate(&cap.runs, &Default::default()).unwrap();
    let temps: Vec<i8> = cap.runs.iter().flat_map(|r| r.temperatures.iter().map(|t| t.raw)).collect();
    (SetpointCal::from_report(setpoint_c, &report, &temps).unwrap(), out.truth)
}

struct Programme {
    setpoints: Vec<SetpointCal>,
    truths: Vec<sim::Truth>,
    model: ThermalModel,
    /// A separate session at the lab's 25 °C (no chamber): its own noise.
    single: SetpointCal,
}

fn run(seed: u64) -> Programme {
    let base = SimConfig::standard(seed, DURATION_S);
    let steps = programme(&base, &SETPOINTS_C, settle::SettleCriterion::default()).unwrap();
    let (setpoints, truths): (Vec<_>, Vec<_>) =
        steps.iter().zip(SETPOINTS_C).map(|(s, sp)| calibrate(&s.config, sp)).unzip();
    let model = ThermalModel::fit(&setpoints).unwrap();
    let mut plain = base.clone();
    plain.effects.temperature_dependence = steps[0].config.effects.temperature_dependence;
    let (single, _) = calibrate(&plain, 25.0);
    Programme { setpoints, truths, model, single }
}

#[test]
fn thermal_model_meets_the_bars_on_the_simulator() {
    let p = run(1);
    let truth = p.truths[0].thermal.as_ref().expect("a thermal truth");
    let c_true = p.truths[0].out_temp_at_0c;
    // Every coefficient within 3σ of its truth; every term the order left out out of reach.
    let (checks, omitted) = coefficients(&p.model, truth, c_true);
    for c in &checks {
        assert!(
            c.z.abs() <= Z_BAR,
            "{} c{}: {} ± {} vs truth {} (z {:.2})",
            c.curve,
            c.degree,
            c.fitted,
            c.sigma,
            c.truth,
            c.z
        );
    }
    for (curve, worst) in &omitted {
        assert!(*worst <= Z_BAR, "{curve}: terms above its order reach {worst:.1} σ");
    }
    // The offsets' and sensitivities' curvature is found (the datasheet-sized quadratics).
    for axis in 0..3 {
        assert_eq!(p.model.curve(axis, Quantity::OffsetCounts).order, 2, "{}", present::text(&p.model));
        assert_eq!(p.model.curve(axis, Quantity::SensitivityCountsPerDps).order, 2);
    }
    // The rate at each held-out interior setpoint.
    for held in 1..4 {
        let z = held_out_rate_z(&p.setpoints, &p.model, held, &p.truths[held], [100.0, -50.0, 150.0]).unwrap();
        assert!(z.iter().all(|z| z.abs() <= Z_BAR), "held out {held}: {z:?}");
    }
    // At 25 °C the model agrees with a single-setpoint calibration.
    for (curve, z) in single_setpoint_z(&p.model, &p.single).unwrap() {
        assert!(z.abs() <= Z_BAR, "{curve}: z {z:.2}");
    }
}

#[test]
fn queries_outside_the_setpoints_are_refused_not_extrapolated() {
    let p = run(5);
    let [lo, hi] = p.model.range_c;
    assert!(p.model.calibration_at(lo).is_ok() && p.model.calibration_at(hi).is_ok());
    for t in [lo - 0.01, hi + 0.01, f64::NAN] {
        let e = p.model.calibration_at(t).unwrap_err();
        assert!(matches!(e, ThermalError::OutOfRange { .. }), "{e}");
        assert!(p.model.rate_at([0.0; 3], t).is_err());
    }
    assert!(p.model.calibration_at(hi + 0.01).unwrap_err().to_string().contains("not extrapolated"));
    // The model's calibration at a setpoint is the curve values, and reads back through JSON.
    let back: ThermalModel = serde_json::from_str(&serde_json::to_string(&p.model).unwrap()).unwrap();
    assert_eq!(back, p.model);
    let text = present::text(&p.model);
    assert_eq!(text.lines().filter(|l| l.contains(" held out ")).count(), 12 * SETPOINTS_C.len(), "{text}");
}

#[test]
fn too_few_or_repeated_setpoints_are_refused() {
    let p = run(7);
    assert!(matches!(ThermalModel::fit(&p.setpoints[..2]), Err(ThermalError::TooFewSetpoints { found: 2 })));
    let mut twice = p.setpoints.clone();
    twice[1].setpoint_c = twice[0].setpoint_c;
    assert!(ThermalModel::fit(&twice).unwrap_err().to_string().contains("given twice"));
}

/// Five setpoints exactly on curves (offset 1.7 counts/°C, the datasheet's 0.03 °/s/°C;
/// sensitivity 10 ppm/°C, small enough that OUT_TEMP's rounding adds little to its σ; direction
/// 0.002 °/°C), σ of a 60-s calibration; `shift[j]` moves setpoint j's values off their curves
/// (offset by 0.2 counts, sensitivity by 9e-4 counts/(°/s), directions by 2e-5 per unit);
/// `common` is the sensitivity's σ common to all setpoints.
fn synthetic(shift: [f64; 5], common: f64) -> Vec<SetpointCal> {
    SETPOINTS_C
        .iter()
        .zip(shift)
        .map(|(&sp, d)| {
            let dt = sp - 25.0;
            let values = std::array::from_fn(|_| {
                let turn = 0.002f64.to_radians() * dt;
                Quantity::PER_AXIS.map(|q| match q {
                    Quantity::OffsetCounts => Estimate::new(5.0 + 1.7 * dt + d * 0.2, 0.07),
                    Quantity::SensitivityCountsPerDps => Estimate::new(57.0 * (1.0 + 10e-6 * dt) + d * 9e-4, 9e-4),
                    _ => Estimate::new(0.01 + turn + d * 2e-5, 1e-5),
                })
            });
            SetpointCal {
                setpoint_c: sp,
                out_temp_mean_lsb: 10.0 - sp,
                full_scale: protocol::FullScale::Dps500,
                values,
                common_sigma: [[0.0, common, 0.0, 0.0]; 3],
                at_noise_floor: true,
            }
        })
        .collect()
}

/// Setpoints that scatter about their curves by more than their σ (a gyro's bias wanders
/// between sessions) get a between-session σ such that each kind's χ² equals its degrees of
/// freedom (Paule-Mandel); setpoints on their curves get none.
#[test]
fn scatter_beyond_sigma_is_carried_as_a_between_session_sigma() {
    let exact = ThermalModel::fit(&synthetic([0.0; 5], 0.0)).unwrap();
    assert!(exact.curves.iter().all(|c| c.between_sigma == 0.0));
    // Off their curves by up to 8 units, 1.6 counts and 8σ: no line or quadratic through them.
    let m = ThermalModel::fit(&synthetic([4.0, -8.0, 6.0, 3.0, -5.0], 0.0)).unwrap();
    for (k, unit) in [(Quantity::OffsetCounts, 0.2), (Quantity::SensitivityCountsPerDps, 9e-4)] {
        let curves: Vec<&Curve> = m.curves.iter().filter(|c| c.quantity == k).collect();
        let (chi2, dof) = curves.iter().fold((0.0, 0), |(c, d), x| (c + x.chi2, d + x.dof));
        assert!(dof > 0 && (chi2 - dof as f64).abs() < 1e-6 * dof as f64, "{k:?}: χ² {chi2} over {dof}");
        let b = curves[0].between_sigma;
        assert!(b > unit && b < 8.0 * unit, "{k:?}: between {b}");
        // Every held-out setpoint within 3σ of the others' curve once the σ holds the scatter.
        assert!(curves.iter().flat_map(|c| &c.points).all(|p| p.held_out.z.abs() < 3.0), "{}", present::text(&m));
    }
}

/// A σ common to every setpoint (a considered effect of the rig) is the sensitivity constant
/// term's, not its slope's; another session on the same rig shares it, so the model and that
/// session differ by their independent σ only.
#[test]
fn a_common_sigma_is_the_constant_terms_and_cancels_against_another_session() {
    let common = 6e-4;
    let plain = ThermalModel::fit(&synthetic([0.3, -0.5, 0.2, 0.4, -0.1], 0.0)).unwrap();
    let m = ThermalModel::fit(&synthetic([0.3, -0.5, 0.2, 0.4, -0.1], common)).unwrap();
    let (kp, km) = (plain.curve(0, Quantity::SensitivityCountsPerDps), m.curve(0, Quantity::SensitivityCountsPerDps));
    assert_eq!((kp.order, km.order), (1, 1), "{}", present::text(&m));
    // Averaged down over five setpoints as if independent, the constant's σ was below the common
    // part; now it holds it.
    assert!(km.coef[0].sigma > common && kp.coef[0].sigma < common, "{:?} {:?}", km.coef, kp.coef);
    // Independent σ √(9e-4² − 6e-4²) = 0.75 of 9e-4: the slope is better known by about that.
    let ratio = km.coef[1].sigma / kp.coef[1].sigma;
    assert!((ratio - 0.745).abs() < 0.03, "{ratio}: {:?} {:?}", km.coef, kp.coef);
    // A 25 °C session 3 independent σ above the curve.
    let mut single = synthetic([0.0; 5], common)[2].clone();
    let independent = (9e-4f64 * 9e-4 - common * common).sqrt();
    single.values[0][1].value += 3.0 * independent;
    let z = truth_check::single_setpoint_z(&m, &single).unwrap();
    let zk = z.iter().find(|(c, _)| c.starts_with("x k")).unwrap().1;
    let temp_c = m.temp_c_from_raw_mean(single.out_temp_mean_lsb);
    let at_est = km.at(m.reference_c, temp_c);
    let at = at_est.sigma;
    let slope = km.slope_at(m.reference_c, temp_c) * m.temp_sigma_c;
    let between = km.between_sigma;
    let var = at * at - common * common + 9e-4 * 9e-4 - common * common + slope * slope + between * between;
    let expected = (at_est.value - single.values[0][1].value) / var.sqrt();
    assert!((zk - expected).abs() < 1e-9, "z {zk} vs {expected}");
    // Counted twice, as independent σ, the common part would have hidden a third of the shift.
    let naive = (at_est.value - single.values[0][1].value) / (at * at + 9e-4 * 9e-4 + slope * slope).sqrt();
    assert!(zk < -1.0 && zk.abs() > 1.1 * naive.abs(), "z {zk}, counted twice {naive}");
}

/// A setpoint whose calibration did not reach the noise floor (exit 3) is left out of the fit
/// (`model::split_by_noise_floor`): the −20 °C setpoint 40 units off its curves (as seed 6's
/// was, 49σ in an offset) moves nothing once flagged, the range is the other setpoints', and the
/// summary says so; taken in as if at the floor, it pulls the offset's slope off the truth. With
/// three of five flagged, leaving them out would leave two: every setpoint is fitted and the
/// model says not to trust it.
#[test]
fn a_setpoint_not_at_the_noise_floor_is_left_out_of_the_fit() {
    let shifted = synthetic([40.0, 0.0, 0.0, 0.0, 0.0], 0.0);
    let flag = |n: usize| -> Vec<SetpointCal> {
        shifted.iter().cloned().enumerate().map(|(i, s)| s.with_noise_floor(i >= n)).collect()
    };
    let m = ThermalModel::fit(&flag(1)).unwrap();
    assert_eq!(m.excluded.iter().map(|s| s.setpoint_c).collect::<Vec<_>>(), vec![-20.0]);
    assert_eq!(m.setpoints.len(), 4);
    assert!(m.not_at_floor_in_fit.is_empty());
    // The synthetic die is the setpoint itself: the range starts at 0 °C.
    assert_eq!(m.range_c, [-0.5, 70.5]);
    assert!(m.check_range(-10.0).is_err());
    for axis in 0..3 {
        let slope = m.curve(axis, Quantity::OffsetCounts).coef[1];
        assert!((slope.value - 1.7).abs() < 1e-6, "axis {axis}: {slope:?}\n{}", present::text(&m));
    }
    let text = present::text(&m);
    assert!(text.contains("Left out of the fit: setpoint -20 °C (die -20.0 °C)"), "{text}");
    assert!(!text.contains("DO NOT TRUST"), "{text}");
    // Taken in, the same setpoint drags the slope by more than its σ says.
    let taken = ThermalModel::fit(&shifted).unwrap();
    assert!(taken.excluded.is_empty());
    let slope = taken.curve(0, Quantity::OffsetCounts).coef[1];
    assert!((slope.value - 1.7).abs() > 0.02, "{slope:?}\n{}", present::text(&taken));
    // Too many flagged to leave out.
    let all_in = ThermalModel::fit(&flag(3)).unwrap();
    assert!(all_in.excluded.is_empty());
    assert_eq!(all_in.setpoints.len(), 5);
    assert_eq!(all_in.not_at_floor_in_fit, vec![-20.0, 0.0, 25.0]);
    assert!(present::text(&all_in).contains("DO NOT TRUST THIS MODEL: setpoint(s) -20 °C, 0 °C, 25 °C"));
}

/// The bench's goodness check of z-values against N(0,1): exact normal quantiles pass it
/// (counts beyond 1, 2, 3σ at chance, D = 1/(2n), p ≈ 1); values all at 0 fail it (D = 0.5);
/// one value beyond 3σ in 318 is what chance gives 58 % of the time, 1 − (1 − p₃)³¹⁸.
#[test]
fn z_values_are_checked_against_the_standard_normal() {
    use statrs::distribution::{ContinuousCDF, Normal};
    let phi = Normal::standard();
    let n = 1000;
    let q: Vec<f64> = (0..n).map(|i| phi.inverse_cdf((i as f64 + 0.5) / n as f64)).collect();
    let g = truth_check::normality(&q).unwrap();
    assert_eq!(g.n, n);
    for (b, (seen, expected)) in g.beyond.iter().enumerate() {
        assert!((*seen as f64 - expected).abs() <= 1.0, "beyond {}σ: {seen} vs {expected}", b + 1);
    }
    assert!((g.ks_d - 0.5 / n as f64).abs() < 1e-9, "{}", g.ks_d);
    assert!(g.ks_p > 0.999, "{}", g.ks_p);
    let zeros = truth_check::normality(&[0.0; 100]).unwrap();
    assert!((zeros.ks_d - 0.5).abs() < 1e-12 && zeros.ks_p < 1e-10, "{zeros:?}");
    assert_eq!(zeros.beyond.map(|b| b.0), [0, 0, 0]);
    let mut one: Vec<f64> = (0..317).map(|i| phi.inverse_cdf((i as f64 + 0.5) / 318.0).clamp(-2.9, 2.9)).collect();
    one.push(3.37);
    let g = truth_check::normality(&one).unwrap();
    let p3 = 2.0 * phi.cdf(-3.0);
    assert_eq!(g.beyond[2].0, 1);
    assert!((g.p_beyond_3 - (1.0 - (1.0 - p3).powi(318))).abs() < 1e-9, "{}", g.p_beyond_3);
    assert!((g.p_beyond_3 - 0.577).abs() < 0.002, "{}", g.p_beyond_3);
    assert!(truth_check::normality(&[]).is_none());
}

/// One session's warm-up coefficients are read from the loop's final model by the names its
/// effects report; without a warm-up the one line gives the span needed (3·√12·σ of the level
/// over the datasheet's size, at least the loop's own threshold); beside a thermal model they
/// are compared with its slopes at the setpoint's die temperature, in the warm-up's units.
#[test]
fn warm_up_coefficients_are_read_from_the_loop_and_set_beside_the_model() {
    use crate::calib::analysis::closure::EffectParam;
    use crate::calib::Effect;
    use warm_up::WarmUp;
    let out = sim::simulate(&SimConfig::standard(3, 10.0)).unwrap();
    let cap = decode(&out.bytes);
    let mut lr = crate::calib::close_loop(&cap.runs, &Default::default(), None).unwrap();
    let temps: Vec<i8> = cap.runs.iter().flat_map(|r| r.temperatures.iter().map(|t| t.raw)).collect();
    let still = WarmUp::of(&lr, &temps).unwrap();
    assert!(!still.estimated() && still.die_span_c == 0.0, "{still:?}");
    let rep = lr.final_report();
    let level_dps = (0..3).map(|a| rep.axes[a].offset_counts.sigma / rep.axes[a].k_counts_per_dps.value);
    let need = (3.0 * 12f64.sqrt() * level_dps.fold(0.0, f64::max) / 0.03).max(0.5);
    assert!((still.span_needed_c.offset_c - need).abs() < 1e-12, "{still:?}");
    assert!(still.span_needed_c.sensitivity_c >= 1.0);
    let t = temps[0];
    assert!(
        still.text().starts_with(&format!(
            "Warm-up temperature coefficients: not estimated, the die-temperature span was too small: 0 °C (OUT_TEMP {t}…{t} LSB) where about {need:.1} °C"
        )),
        "{}",
        still.text()
    );
    // The loop's offsets linear in temperature, named as it names them.
    let last = lr.steps.last_mut().unwrap();
    last.effects.push(Effect::DriftTemperature);
    for (a, v) in ["x", "y", "z"].iter().zip([0.0298, -0.02, 0.025]) {
        let estimate = Estimate::new(v, 0.001);
        last.effect_params.push(EffectParam {
            name: format!("offset vs temperature, {a}"),
            estimate,
            unit: "°/s per °C".into(),
        });
    }
    let w = WarmUp::of(&lr, &[5, 6, 7, 12]).unwrap();
    assert_eq!(w.offset_dps_per_c.unwrap()[1], Estimate::new(-0.02, 0.001));
    assert!(w.sensitivity_ppm_per_c.is_none());
    assert_eq!((w.die_span_c, w.out_temp_range_lsb, w.reference_out_temp_lsb), (7.0, [5, 12], 7.5));
    let text = w.text();
    assert!(
        text.contains("offset [°/s/°C]: x +0.02980 ± 0.00100, y -0.02000 ± 0.00100, z +0.02500 ± 0.00100"),
        "{text}"
    );
    assert!(text.starts_with("Warm-up temperature coefficients (this session's own, from its warm-up; valid only over its die temperatures, OUT_TEMP 5…12 LSB (a span of 7 °C), not extrapolated):\n"), "{text}");
    assert!(text.contains("  sensitivity: not in the loop's model (the residual did not call for it)"), "{text}");
    // Beside a model of 1.7 counts/°C on k = 57 (1 + 10 ppm/°C): 0.029825 °/s/°C at 25 °C.
    let model = ThermalModel::fit(&synthetic([0.0; 5], 0.0)).unwrap();
    let cal = serde_json::json!({ warm_up::CALIBRATION_KEY: w });
    let rows = warm_up::beside_model(&model, &[(25.0, cal.clone()), (99.0, cal)]);
    assert_eq!(rows.len(), 3, "one per axis, none for a temperature that is not a setpoint");
    let slope = rows[0].model_slope;
    assert!((slope.value - 1.7 / 57.0).abs() < 1e-9 && slope.sigma > 0.0, "{slope:?}");
    assert!(rows[0].z.abs() < 0.1 && rows[1].z < -30.0, "{rows:?}");
    let table = warm_up::beside_model_text(&rows);
    assert!(table.contains("25 °C (die 25.0 °C) y offset [°/s/°C]"), "{table}");
}
