//! The bars of issue 27 on the simulator, for one seed in the time a unit test may take: five
//! setpoints −20…70 °C, both poses at 180 °/s for 20 s each, the die settled by the live
//! session's criterion. `host/benches/thermal.rs` runs ten seeds with longer runs and every
//! realistic effect.

use super::programme::programme;
use super::truth_check::{coefficients, held_out_rate_z, single_setpoint_z};
use super::*;
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
