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
//! not needed for these figures); `BENCH_SEEDS=N` (default 10) or `BENCH_SEED_LIST=7,1`,
//! `BENCH_DURATION_S` per run (default 120, the live session's default), the default run design
//! 180, 90, −180 °/s in both poses; `BENCH_NO_EFFECTS=1` switches the rig effects off (the
//! temperature dependence alone), `BENCH_EFFECTS=a,b` replaces the set (to find which effect a
//! figure comes from). `BENCH_CACHE_DIR=dir` keeps each seed's calibrated sessions (the
//! expensive part: the simulation and the loop, deterministic in seed, duration and effects) and
//! reads them back on the next run, so the thermal fit can be measured again in seconds;
//! `BENCH_DETAIL=1` prints, per seed, each session's model, consider terms and effect
//! parameters, each quantity's error against the truth at every setpoint in its own σ, and the
//! curves' orders, between-session σ and scale factors. A setpoint whose loop did not reach
//! the noise floor is left out of the fit as the tool leaves it out
//! (`thermal::model::split_by_noise_floor`); `BENCH_FIT_ALL=1` fits every setpoint (the rule
//! before). After the coefficients and the 25 °C comparison, their z-values against N(0,1):
//! counts beyond 1, 2, 3σ against chance and a Kolmogorov-Smirnov statistic
//! (`thermal::truth_check::normality`).

use host::calib::{self, LoopOptions};
use host::geometry::Pose;
use host::sim::{self, RunSpec, SimConfig};
use host::thermal::programme::programme;
use host::thermal::{settle::SettleCriterion, truth_check, Quantity, SetpointCal, ThermalError, ThermalModel};
use serde::{Deserialize, Serialize};
use std::time::Instant;

const SETPOINTS_C: [f64; 5] = [-20.0, 0.0, 25.0, 50.0, 70.0];
const RATES_DPS: [f64; 3] = [180.0, 90.0, -180.0];
/// The realistic set but the pose-2 fixture (module documentation).
/// `BENCH_EFFECTS=a,b` replaces the set (to find which effect a figure comes from).
fn effects() -> Vec<String> {
    match std::env::var("BENCH_EFFECTS") {
        Ok(list) => list.split(',').map(|e| e.trim().to_string()).filter(|e| !e.is_empty()).collect(),
        Err(_) => sim::Effects::REALISTIC.into_iter().filter(|e| *e != "pose_fixture").map(String::from).collect(),
    }
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

/// One calibrated session of the programme (or the separate 25 °C one), as the bench keeps it.
#[derive(Clone, Serialize, Deserialize)]
struct SessionRun {
    setpoint_c: f64,
    /// The loop's final report (the setpoint's calibration is made from it when read, so a
    /// cached session follows changes to [`SetpointCal::from_report`]).
    report: calib::CalReport,
    /// OUT_TEMP readings of its runs.
    temps: Vec<i8>,
    truth: sim::Truth,
    at_floor: bool,
    /// Effects of the loop's final model (keys).
    effects: Vec<String>,
    /// The final model's effect parameters (name, value, σ, unit).
    effect_params: Vec<(String, f64, f64, String)>,
}

impl SessionRun {
    fn cal(&self) -> SetpointCal {
        SetpointCal::from_report(self.setpoint_c, &self.report, &self.temps)
            .expect("OUT_TEMP readings")
            .with_noise_floor(self.at_floor || std::env::var("BENCH_FIT_ALL").is_ok())
    }
}

/// Simulates and calibrates one session with the tool's loop.
fn calibrate(cfg: &SimConfig, setpoint_c: f64) -> Result<SessionRun, String> {
    let out = sim::simulate(cfg).map_err(|e| e.to_string())?;
    let cap = host::capture::decode(&out.bytes);
    let lr =
        calib::close_loop(&cap.runs, &LoopOptions::default(), Some(out.truth.sensor())).map_err(|e| e.to_string())?;
    let temps: Vec<i8> = cap.runs.iter().flat_map(|r| r.temperatures.iter().map(|t| t.raw)).collect();
    if temps.is_empty() {
        return Err("no OUT_TEMP reading".into());
    }
    Ok(SessionRun {
        setpoint_c,
        report: lr.final_report().clone(),
        temps,
        truth: out.truth,
        at_floor: lr.verdict() == calib::Verdict::AtNoiseFloor,
        effects: lr.steps.last().map(|s| s.effects.iter().map(|e| e.key()).collect()).unwrap_or_default(),
        effect_params: lr
            .steps
            .last()
            .map(|s| {
                s.effect_params
                    .iter()
                    .map(|p| (p.name.clone(), p.estimate.value, p.estimate.sigma, p.unit.clone()))
                    .collect()
            })
            .unwrap_or_default(),
    })
}

/// The five setpoints' sessions and, last, the separate 25 °C session of one seed; read from
/// `BENCH_CACHE_DIR` when a previous run of the same seed, duration and effects left them there
/// (the simulation and the loop are deterministic in these), else computed (and written there).
fn sessions(seed: u64, duration_s: f64, effects: bool) -> Result<Vec<SessionRun>, String> {
    let cache = std::env::var("BENCH_CACHE_DIR").ok().map(|d| {
        std::path::PathBuf::from(d).join(format!(
            "seed{seed}_{duration_s}s_{}.json",
            if effects { self::effects().join("+") } else { "plain".into() }
        ))
    });
    if let Some(runs) = cache.as_ref().and_then(|p| std::fs::read(p).ok()).and_then(|b| serde_json::from_slice(&b).ok())
    {
        return Ok(runs);
    }
    let b = base(seed, duration_s, effects);
    let steps = programme(&b, &SETPOINTS_C, SettleCriterion::default()).map_err(|e| e.to_string())?;
    let mut runs = Vec::new();
    for (s, sp) in steps.iter().zip(SETPOINTS_C) {
        runs.push(calibrate(&s.config, sp)?);
    }
    let mut single_cfg =
        programme(&b, &[25.0], SettleCriterion::default()).map_err(|e| e.to_string())?.remove(0).config;
    if let Some(c) = single_cfg.chamber.as_mut() {
        c.index = SINGLE_SESSION_INDEX;
    }
    runs.push(calibrate(&single_cfg, 25.0)?);
    if let Some(p) = cache {
        let written = std::fs::create_dir_all(p.parent().expect("a folder"))
            .and_then(|_| std::fs::write(&p, serde_json::to_vec(&runs).expect("serialisable")));
        if let Err(e) = written {
            eprintln!("cache {}: {e}", p.display());
        }
    }
    Ok(runs)
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
    let mut runs = sessions(seed, duration_s, effects)?;
    let single_run = runs.pop().ok_or("no single session")?;
    let setpoints: Vec<SetpointCal> = runs.iter().map(SessionRun::cal).collect();
    let truths: Vec<sim::Truth> = runs.iter().map(|r| r.truth.clone()).collect();
    let floor = runs.iter().filter(|r| r.at_floor).count();
    if std::env::var("BENCH_DETAIL").is_ok() {
        detail(seed, &runs, &single_run);
    }
    let model = ThermalModel::fit(&setpoints).map_err(|e| e.to_string())?;
    for line in host::thermal::present::exclusions(&model) {
        println!("  seed {seed}: {line}");
    }
    let th = truths[0].thermal.as_ref().ok_or("no thermal truth")?;
    let (checks, _) = truth_check::coefficients(&model, th, truths[0].out_temp_at_0c);
    let (single, single_truth) = (&single_run.cal(), &single_run.truth);
    let single_z = truth_check::single_setpoint_z(&model, single).map_err(|e| e.to_string())?;
    let mut held_z = Vec::new();
    let mut held_err_dps = Vec::new();
    let mut single_cal_err_dps = Vec::new();
    // The interior setpoints (0, 25, 50 °C): a held-out end would be an extrapolation.
    // A setpoint left out of the fit (not at the noise floor) can take an end of the refit's
    // range with it: a held-out setpoint outside is then not predicted (never extrapolated).
    for (held, truth) in truths.iter().enumerate().take(4).skip(1) {
        let z = match truth_check::held_out_rate_z(&setpoints, &model, held, truth, REFERENCE_RATE_DPS) {
            Err(ThermalError::OutOfRange { temp_c, range_c }) => {
                println!("  seed {seed}: held-out setpoint {held} ({temp_c:.1} °C) outside the refit's range {range_c:?}: not predicted");
                continue;
            }
            z => z.map_err(|e| e.to_string())?,
        };
        held_z.extend(z);
        let (err, err_single) = held_out_errors(&setpoints, &model, held, truth, single_truth)?;
        held_err_dps.extend(err);
        single_cal_err_dps.extend(err_single);
    }
    if std::env::var("BENCH_DETAIL").is_ok() {
        detail_model(&model, th, truths[0].out_temp_at_0c, &single_z);
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

/// Per setpoint: the loop's verdict, its model's effects and its consider terms; per quantity,
/// each setpoint's error against the truth at its own die temperature in its own σ, and the
/// separate 25 °C session's (`BENCH_DETAIL=1`).
fn detail(seed: u64, runs: &[SessionRun], single: &SessionRun) {
    let all: Vec<&SessionRun> = runs.iter().chain(std::iter::once(single)).collect();
    for (i, r) in all.iter().enumerate() {
        let terms: Vec<String> = r
            .report
            .consider
            .iter()
            .map(|t| format!("{}(k {:.0?} ppm, dir {:.4?}°)", t.effect, t.k_sigma_ppm, t.direction_sigma_deg))
            .collect();
        println!(
            "  seed {seed} session {i} ({} °C): floor {}, effects {:?}, consider {}",
            r.setpoint_c,
            r.at_floor,
            r.effects,
            terms.join(", ")
        );
    }
    let names: Vec<&String> = all[0].effect_params.iter().map(|p| &p.0).collect();
    for name in names {
        let row: Vec<String> = all
            .iter()
            .map(|r| {
                r.effect_params.iter().find(|p| &p.0 == name).map_or("-".into(), |p| format!("{:.4e}±{:.1e}", p.1, p.2))
            })
            .collect();
        println!("  seed {seed} param {name}: {}", row.join(" "));
    }
    for (axis, q) in Quantity::all() {
        let zs: Vec<String> = all
            .iter()
            .map(|r| {
                let th = r.truth.thermal.as_ref().expect("a thermal truth");
                let t = truth_check::truth_value(th, axis, q, th.die_mean_c);
                let e = r.cal().value(axis, q);
                format!("{:>6.2} ({:.2e})", e.z(t), e.sigma)
            })
            .collect();
        println!("  seed {seed} {} {:<20} z (σ) per session: {}", ['x', 'y', 'z'][axis], q.label(), zs.join(" "));
    }
}

/// Each coefficient's z against the truth and each quantity's z against the 25 °C session.
fn detail_model(model: &ThermalModel, th: &host::sim::thermal::ThermalTruth, c_true: f64, single_z: &[(String, f64)]) {
    let (checks, _) = truth_check::coefficients(model, th, c_true);
    let curves: Vec<String> = model
        .curves
        .iter()
        .map(|c| format!("{} order {} between {:.1e} σ×{:.2}", c.label(), c.order, c.between_sigma, c.scale_factor))
        .collect();
    println!("  curves: {}", curves.join("; "));
    for c in checks.iter().filter(|c| c.z.abs() > 2.0) {
        println!(
            "  coefficient {} c{}: {:.4e} ± {:.2e} vs {:.4e}, z {:.2}",
            c.curve, c.degree, c.fitted, c.sigma, c.truth, c.z
        );
    }
    for (curve, z) in single_z.iter().filter(|(_, z)| z.abs() > 2.0) {
        println!("  25 °C session vs model {curve}: z {z:.2}");
    }
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
    let seeds: Vec<u64> = match std::env::var("BENCH_SEED_LIST") {
        Ok(list) => list.split(',').filter_map(|v| v.trim().parse().ok()).collect(),
        Err(_) => (1..=env_or("BENCH_SEEDS", 10.0) as u64).collect(),
    };
    let duration_s = env_or("BENCH_DURATION_S", 120.0);
    let effects = std::env::var("BENCH_NO_EFFECTS").is_err();
    let named: Vec<String> = if effects { self::effects() } else { Vec::new() };
    println!("thermal bench: seeds {seeds:?}, setpoints {SETPOINTS_C:?} °C, runs {RATES_DPS:?} °/s × 2 poses × {duration_s} s, effects {named:?}");
    println!("seed  floor  coef max|z| rms z  held-out rate: max|z| rms z, max err °/s (25 °C cal alone)  25 °C: max|z| rms z   wall s");
    let mut all: Vec<SeedFigures> = Vec::new();
    for &seed in &seeds {
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
    print_normality("coefficients", &coef);
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
    print_normality("25 °C session vs model", &single);
    println!("  setpoints at the noise floor: {}/{}", all.iter().map(|s| s.floor).sum::<usize>(), 5 * all.len());
}

/// Whether z-values look standard normal: counts beyond 1, 2, 3σ against chance and the
/// Kolmogorov-Smirnov statistic (`truth_check::normality`).
fn print_normality(what: &str, z: &[f64]) {
    let Some(g) = truth_check::normality(z) else { return };
    let [b1, b2, b3] = g.beyond;
    println!(
        "  {what}, z against N(0,1): beyond 1σ {} (chance {:.1}), 2σ {} ({:.1}), 3σ {} ({:.2}; P(≥ {} by chance) {:.2}); KS D {:.3}, p {:.2}",
        b1.0, b1.1, b2.0, b2.1, b3.0, b3.1, b3.0, g.p_beyond_3, g.ks_d, g.ks_p
    );
}
