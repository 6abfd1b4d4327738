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
