//! Issue 27's bars on the simulator, over seeds: per seed (one simulated sensor) a chamber
//! programme at −20, 0, 25, 50 and 70 °C with the realistic effects on, each setpoint calibrated
//! by the tool's closed loop, the thermal model fitted over them; and, for the third bar, a
//! separate session at 25 °C. Prints, per seed and in summary:
//!
//! - every thermal coefficient's z against the truth (bar: |z| ≤ 3);
//! - the rate predicted at each held-out interior setpoint (0, 25, 50 °C) for a reference rate of
//!   (100, −50, 150) °/s, in units of its σ (bar: within its σ) and in °/s, beside the error the
//!   25 °C calibration alone makes there (what the thermal model buys);
//! - the model at the 25 °C session's die temperature against that session's own calibration,
//!   in units of the combined σ (bar: |z| ≤ 3).
//!
//! Effects: the realistic set of the all-effects bench except `pose_fixture` (a rotation of the
//! pose-2 fixture is the same at every setpoint, so it is not thermal; it biases the directions'
//! constant terms by the mount's extrinsic σ, which the all-effects bench judges). The bench exits
//! 0 whatever it finds: a measurement, not a test.
//!
//! `cargo bench -p host --bench thermal --profile release` (the `bench` profile's fat LTO is
//! not needed for these figures); `BENCH_SEEDS=N` (default 10), `BENCH_DURATION_S` per run
//! (default 60), the default run design 180, 90, −180 °/s in both poses; `BENCH_NO_EFFECTS=1`
//! switches the rig effects off (the temperature dependence alone).

use host::calib::{self, LoopOptions};
use host::geometry::Pose;
use host::sim::{self, RunSpec, SimConfig};
use host::thermal::programme::programme;
use host::thermal::{settle::SettleCriterion, truth_check, SetpointCal, ThermalModel};
use std::time::Instant;

const SETPOINTS_C: [f64; 5] = [-20.0, 0.0, 25.0, 50.0, 70.0];
const RATES_DPS: [f64; 3] = [180.0, 90.0, -180.0];
/// The realistic set but the pose-2 fixture (module documentation).
fn effects() -> Vec<&'static str> {
    sim::Effects::REALISTIC.into_iter().filter(|e| *e != "pose_fixture").collect()
}
const REFERENCE_RATE_DPS: [f64; 3] = [100.0, -50.0, 150.0];
/// Index of the separate 25 °C session's noise streams (apart from the programme's 1…5).
const SINGLE_SESSION_INDEX: u32 = 100;

fn env_or(name: &str, default: f64) -> f64 {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn base(seed: u64, duration_s: f64, effects_on: bool) -> SimConfig {
    let runs =
        Pose::ALL.iter().flat_map(|&pose| RATES_DPS.map(|rate_dps| RunSpec { pose, rate_dps, duration_s })).collect();
    let mut cfg = SimConfig::with_runs(seed, runs);
    for e in effects().iter().filter(|_| effects_on) {
        cfg.effects.enable(e).expect("a known effect");
    }
    cfg
}

/// Simulates and calibrates one session with the tool's loop.
fn calibrate(cfg: &SimConfig, setpoint_c: f64) -> Result<(SetpointCal, sim::Truth, bool), String> {
    let out = sim::simulate(cfg).map_err(|e| e.to_string())?;
    let cap = host::capture::decode(&out.bytes);
    let lr =
        calib::close_loop(&cap.runs, &LoopOptions::default(), Some(out.truth.sensor())).map_err(|e| e.to_string())?;
    let temps: Vec<i8> = cap.runs.iter().flat_map(|r| r.temperatures.iter().map(|t| t.raw)).collect();
    let sp = SetpointCal::from_report(setpoint_c, lr.final_report(), &temps).ok_or("no OUT_TEMP reading")?;
    Ok((sp, out.truth, lr.verdict() == calib::Verdict::AtNoiseFloor))
}

struct SeedFigures {
    coef_z: Vec<f64>,
    held_z: Vec<f64>,
    held_err_dps: Vec<f64>,
    single_cal_err_dps: Vec<f64>,
    single_z: Vec<f64>,
    floor: usize,
}

fn run_seed(seed: u64, duration_s: f64, effects: bool) -> Result<SeedFigures, String> {
    let b = base(seed, duration_s, effects);
    let steps = programme(&b, &SETPOINTS_C, SettleCriterion::default()).map_err(|e| e.to_string())?;
    let mut setpoints = Vec::new();
    let mut truths = Vec::new();
    let mut floor = 0;
    for (s, sp) in steps.iter().zip(SETPOINTS_C) {
        let (cal, truth, at_floor) = calibrate(&s.config, sp)?;
        setpoints.push(cal);
        truths.push(truth);
        floor += usize::from(at_floor);
    }
    let model = ThermalModel::fit(&setpoints).map_err(|e| e.to_string())?;
    let th = truths[0].thermal.as_ref().ok_or("no thermal truth")?;
    let (checks, _) = truth_check::coefficients(&model, th, truths[0].out_temp_at_0c);
    let mut single_cfg =
        programme(&b, &[25.0], SettleCriterion::default()).map_err(|e| e.to_string())?.remove(0).config;
    if let Some(c) = single_cfg.chamber.as_mut() {
        c.index = SINGLE_SESSION_INDEX;
    }
    let (single, single_truth, _) = calibrate(&single_cfg, 25.0)?;
    let single_z = truth_check::single_setpoint_z(&model, &single).map_err(|e| e.to_string())?;
    let mut held_z = Vec::new();
    let mut held_err_dps = Vec::new();
    let mut single_cal_err_dps = Vec::new();
    // The interior setpoints (0, 25, 50 °C): a held-out end would be an extrapolation.
    for (held, truth) in truths.iter().enumerate().take(4).skip(1) {
        let z = truth_check::held_out_rate_z(&setpoints, &model, held, truth, REFERENCE_RATE_DPS)
            .map_err(|e| e.to_string())?;
        held_z.extend(z);
        let (err, err_single) = held_out_errors(&setpoints, &model, held, truth, &single_truth)?;
        held_err_dps.extend(err);
        single_cal_err_dps.extend(err_single);
    }
    Ok(SeedFigures {
        coef_z: checks.iter().map(|c| c.z).collect(),
        held_z,
        held_err_dps,
        single_cal_err_dps,
        single_z: single_z.iter().map(|(_, z)| *z).collect(),
        floor,
    })
}

/// The held-out model's rate error at setpoint `held`, °/s, and the error of the true 25 °C
/// calibration used there (no thermal model: what a calibration at 25 °C alone gives).
fn held_out_errors(
    setpoints: &[SetpointCal],
    model: &ThermalModel,
    held: usize,
    truth: &sim::Truth,
    truth_25: &sim::Truth,
) -> Result<([f64; 3], [f64; 3]), String> {
    let others: Vec<SetpointCal> =
        setpoints.iter().enumerate().filter(|(i, _)| *i != held).map(|(_, s)| s.clone()).collect();
    let refit = ThermalModel::fit_with(&others, Some(&model.orders())).map_err(|e| e.to_string())?;
    let raw = truth.m() * nalgebra::Vector3::from(REFERENCE_RATE_DPS) + truth.offset();
    let raw = [raw[0], raw[1], raw[2]];
    let temp_c = refit.temp_c_from_raw_mean(setpoints[held].out_temp_mean_lsb);
    let (rate, _) = refit.rate_at(raw, temp_c).map_err(|e| e.to_string())?;
    let at_25 =
        truth_25.m().try_inverse().ok_or("singular truth")? * (nalgebra::Vector3::from(raw) - truth_25.offset());
    Ok(([0, 1, 2].map(|i| rate[i] - REFERENCE_RATE_DPS[i]), [0, 1, 2].map(|i| at_25[i] - REFERENCE_RATE_DPS[i])))
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

fn main() {
    let seeds = env_or("BENCH_SEEDS", 10.0) as u64;
    let duration_s = env_or("BENCH_DURATION_S", 60.0);
    let effects = std::env::var("BENCH_NO_EFFECTS").is_err();
    let named: Vec<&str> = if effects { self::effects() } else { Vec::new() };
    println!("thermal bench: {seeds} seeds, setpoints {SETPOINTS_C:?} °C, runs {RATES_DPS:?} °/s × 2 poses × {duration_s} s, effects {named:?}");
    println!("seed  floor  coef max|z| rms z  held-out rate: max|z| rms z, max err °/s (25 °C cal alone)  25 °C: max|z| rms z   wall s");
    let mut all: Vec<SeedFigures> = Vec::new();
    for seed in 1..=seeds {
        let t0 = Instant::now();
        match run_seed(seed, duration_s, effects) {
            Ok(f) => {
                println!(
                    "{seed:>4}  {}/5    {:>6.2} {:>5.2}            {:>5.2} {:>5.2}, {:>7.4} ({:>6.3})                    {:>5.2} {:>5.2}   {:>6.1}",
                    f.floor,
                    max_abs(&f.coef_z),
                    rms(&f.coef_z),
                    max_abs(&f.held_z),
                    rms(&f.held_z),
                    max_abs(&f.held_err_dps),
                    max_abs(&f.single_cal_err_dps),
                    max_abs(&f.single_z),
                    rms(&f.single_z),
                    t0.elapsed().as_secs_f64()
                );
                all.push(f);
            }
            Err(e) => println!("{seed:>4}  failed: {e}"),
        }
    }
    let cat = |f: fn(&SeedFigures) -> &Vec<f64>| all.iter().flat_map(|s| f(s).iter().copied()).collect::<Vec<f64>>();
    let (coef, held, single) = (cat(|s| &s.coef_z), cat(|s| &s.held_z), cat(|s| &s.single_z));
    let over = |v: &[f64], bar: f64| v.iter().filter(|z| z.abs() > bar).count();
    println!("summary over {} seeds:", all.len());
    println!(
        "  coefficients: {} values, rms z {:.2}, max |z| {:.2}, {} beyond 3σ",
        coef.len(),
        rms(&coef),
        max_abs(&coef),
        over(&coef, 3.0)
    );
    println!(
        "  held-out rate: {} components, rms z {:.2}, {} beyond 1σ ({:.0} %), max error {:.4} °/s (25 °C calibration alone: {:.3} °/s)",
        held.len(),
        rms(&held),
        over(&held, 1.0),
        100.0 * over(&held, 1.0) as f64 / held.len().max(1) as f64,
        max_abs(&cat(|s| &s.held_err_dps)),
        max_abs(&cat(|s| &s.single_cal_err_dps))
    );
    println!(
        "  25 °C session vs model: {} values, rms z {:.2}, max |z| {:.2}, {} beyond 3σ",
        single.len(),
        rms(&single),
        max_abs(&single),
        over(&single, 3.0)
    );
    println!("  setpoints at the noise floor: {}/{}", all.iter().map(|s| s.floor).sum::<usize>(), 5 * all.len());
}
