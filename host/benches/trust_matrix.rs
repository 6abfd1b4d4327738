//! "Calibrate the calibration": can an operator trust what `host calibrate --replay` says about
//! its own result? A matrix of run designs × simulated effects × seeds (one seed is one simulated
//! sensor), each calibrated with no effect declared and no latitude given, each result compared
//! with the simulator's truth through the z-values of `../shared/validation/check.py` (per axis
//! the sensitivity against `k_sigma`, the three elements of the axis' row of M against the
//! diagonal of `cov`, and the direction as a 2-dof distance in the plane normal to it: 15 values,
//! see `measured/trust.rs`).
//!
//! For every cell (design, effect) it prints, as soon as the cell's seeds are done: the exit
//! statuses (0 = at the noise floor, 3 = flagged, other = no answer), the largest |z| over the
//! exit-0 seeds and over every seed with a result, the RMS of all z-values of the exit-0 seeds,
//! how many seeds were confidently wrong (exit 0 with some |z| > 4), and the calibrations' CPU
//! time (user + system of the child, from `wait4`). Then a summary with the bars:
//!
//! - no cell has an exit-0 seed with max |z| > 4 (never confidently wrong: an honest tool either
//!   flags what it cannot separate or widens its σ to cover it);
//! - every cell with exit-0 seeds has their z RMS within 0.7-1.3 (σ neither inflated nor too
//!   small; an honest σ gives ≈ 1.1, as the direction's z is a 2-dof distance);
//! - every cell of the default live design (`180,90,-180@120`, `host calibrate`'s default, or `TRUST_LIVE`) whose effect is
//!   catalogued (all but `mystery_harmonic` and `mount_compliance`, structure no model
//!   explains) ends at exit 0 on
//!   every seed.
//!
//! The bench exits 0 whatever it finds: it is a measurement, not a test.
//!
//! Designs are the base-table rates of `host simulate --rates-dps` and the seconds per run: one
//! speed `180`, two speeds `180,90`, both directions `180,-180`, three speeds `180,90,-180`, at
//! 20, 120 and 300 s (12 designs). A design ending in `/files` (`180,90@120/files`) has its runs
//! captured one per file, each simulated on its own as the independent validation captures hold
//! them (a clock, a noise draw and, with `capture_level`, a zero-rate level of its own). Effects: `none`; each switch of `host simulate --effect`
//! alone (`host::sim::Effects::NAMES`) at its default size and at 3× it (`NAME=VALUE`, the
//! value read from the simulator's own defaults); `all`, the realistic set of the
//! `all_effects` bench together at default size; and `drawn` (`host simulate --drawn-rig`):
//! every effect of a real rig at once with its sizes, signs and phases drawn per seed, so each
//! seed is another rig (12- or 16-pole gears among them), not the defaults' one. Two switches have no size to scale and run at
//! size 1 only: `filter_delay` (the gyro's own low-pass, no value) and `earth_rotation` (its
//! value is the latitude; Earth's rate is what it is). A value scales the switch's headline
//! parameter only: `speed_ripple` its 1× harmonic, `nonlinearity` its quadratic term (the
//! asymmetry stays), `offset_drift` the temperature rise; `g_sensitivity` and
//! `gear_transmission` scale as a whole, `axis_delay` all three axes. The full matrix is 12 designs
//! × 35 effect cases × 10 seeds = 4200 calibrations (and as many simulations, the first time). A calibration costs
//! from 0.06 s of CPU (`180@20`, no effect) to ≈ 180 s (`180,90,-180@300`, `all`; 45 s at
//! `180,90@120`): with effects on, about 0.1 s of CPU per second of run and pose. The long
//! effectful cells dominate, and the full matrix takes of the order of a day on 2 cores: select.
//!
//! Selection, all optional:
//! - `TRUST_SEEDS=N`: seeds 1..=N (default 10); `TRUST_SEEDS=A-B`: seeds A..=B;
//! - `TRUST_DESIGNS="180@120;180,90@20"`: designs, the syntax of `all_effects`' `BENCH_PLANS`
//!   (no `@`: 120 s);
//! - `TRUST_EFFECTS="g_sensitivity,earth_rotation,none,all"`: effects, in that order; effects
//!   joined by `+` (`offset_drift+speed_ripple`) are one case with each of them on, each at the
//!   case's size (those whose value is no size, `filter_delay` and `earth_rotation`, as they are);
//! - `TRUST_SIZES="1,3"`: sizes, multiples of the default (`none` and `all` run once; `drawn` at
//!   size S is `--drawn-rig=S`, every range of the draw S times wide);
//! - `TRUST_LIVE="180,90,-180@120"`: the live design of the third bar;
//! - `TRUST_CACHE=0`: remove each capture once calibrated (see below).
//!
//! Quick subset (4 cells × 2 seeds: seconds of calibration, once the release build is there):
//!
//! ```text
//! TRUST_SEEDS=2 TRUST_DESIGNS="180@20;180,90@20" TRUST_EFFECTS="none,g_sensitivity" TRUST_SIZES=1 \
//!     cargo bench -p host --bench trust_matrix
//! ```
//!
//! Each calibration runs the built `host` binary as a child process, two at a time (the 2-core
//! machine), exactly what an operator runs. The captures are simulated once with `host simulate`
//! and cached under `target/bench-data/trust-matrix/<rates@seconds>/<effect>/s<seed>/` (redone
//! when simulated with other arguments); the calibration is redone on every run, into `out/`
//! there, and its z-values are written to `z.json` beside it. Of `out/` (≈ 5 MB) a seed at exit 0
//! within |z| ≤ 4 keeps only `calibration.json`; the others keep all of it, to be looked into. A
//! capture is ≈ 20 kB per second of run and pose (1.6 MB for `180,90@20`, 36 MB for
//! `180,90,-180@300`): the full matrix caches ≈ 40 GB. `TRUST_CACHE=0` removes each capture once
//! calibrated (simulating is cheap beside calibrating: 4 s for `180,90,-180@300` with `all`).

mod measured;
use measured::replay::{self, full_design, HOST, REALISTIC_EFFECTS};
use measured::trust::{self, CellStats, SeedOutcome, BAR_RMS, BAR_Z};

use host::sim::Effects;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The designs' rates and run lengths when `TRUST_DESIGNS` is not set.
const DEFAULT_RATES: [&str; 4] = ["180", "180,90", "180,-180", "180,90,-180"];
const DEFAULT_LENGTHS_S: [&str; 3] = ["20", "120", "300"];

/// The design an operator runs live by default (the third bar's).
const DEFAULT_LIVE: &str = "180,90,-180@120";

/// Effects outside the calibration's catalogue: structure no model explains, flagged at best.
/// (The timestamps' jitter is noise in the kinematics, which no effect models: the calibration
/// takes each stamp as the sample's instant.)
const NOT_CATALOGUED: [&str; 3] = ["mystery_harmonic", "mount_compliance", "timestamp_jitter"];

/// The no-effect case, the realistic set together, and a rig drawn at random per seed.
const NONE: &str = "none";
const ALL: &str = "all";
const DRAWN: &str = "drawn";

/// The simulator's effects with `name` switched on (`NAME` or `NAME=VALUE`).
fn enabled(spec: &str) -> Effects {
    let mut e = Effects::default();
    e.enable(spec).unwrap_or_else(|err| panic!("host simulate --effect {spec}: {err}"));
    e
}

/// The headline parameter of effect `name` in `e`: what `--effect NAME=VALUE` sets. None for the
/// switches whose value is not a size: `filter_delay` (no value), `filter_order` and
/// `filter_cutoff_hz` (the filter's shape) and `earth_rotation` (latitude).
fn headline(name: &str, e: &Effects) -> Option<f64> {
    match name {
        "delay_ms" => e.filter_delay.map(|f| f.pure_delay_ms),
        "index_offset_deg" => e.index_offset.map(|x| x.offset_deg),
        "offset_drift" => e.offset_drift.map(|d| d.rise_c),
        "speed_ripple" => e.speed_ripple.map(|r| r.harmonics[0].amplitude),
        "nonlinearity" => e.nonlinearity.map(|n| n.quadratic_fs),
        "nonlinearity_cubic" => e.nonlinearity.map(|n| n.cubic_fs),
        "nonlinearity_square" => e.nonlinearity.map(|n| n.square_fs),
        "gear_ratio_error" => e.gear_ratio_error.map(|g| g.ppm),
        "mystery_harmonic" => e.mystery_harmonic.map(|m| m.amplitude_dps),
        "mount_compliance" => e.mount_compliance.map(|m| m.deg_at_180),
        "gear_transmission" => e.gear_transmission.map(|g| g.harmonics[0].1),
        "g_sensitivity" => e.g_sensitivity.map(|g| replay::max_abs(g.dps_per_g.as_flattened())),
        "table_tilt" => e.table_tilt.map(|t| t.tilt_deg),
        "pose_fixture" => e.pose_fixture.map(|p| p.z2_deg),
        "bias_random_walk" => e.bias_random_walk.map(|b| b.k_dps_per_sqrt_s),
        "axis_delay" => e.axis_delay.map(|d| d.delay_ms[1]),
        "rig_clock" => e.rig_clock.map(|c| c.error_ppm),
        "encoder_eccentricity" => e.encoder_eccentricity.map(|c| c.amplitude_deg),
        "encoder_ellipticity" => e.encoder_ellipticity.map(|c| c.amplitude_deg),
        "timestamp_jitter" => e.timestamp_jitter.map(|j| j.rms_us),
        "capture_level" => e.capture_level.map(|c| c.sigma_dps),
        _ => None,
    }
}

/// One effect column of the matrix.
struct Case {
    /// Its name in the table and its cache directory: `none`, `all`, `NAME`, `NAME_x3`.
    label: String,
    /// The effect options of `host simulate` (`--effect=…`, `--drawn-rig`).
    options: Vec<String>,
    /// Every effect in it is in the calibration's catalogue.
    catalogued: bool,
}

/// The cases of `effects` (names, `none` or `all`) at `sizes`, and the ones left out, in words.
fn cases(effects: &[String], sizes: &[f64]) -> (Vec<Case>, Vec<String>) {
    let known: Vec<&str> = Effects::NAMES.iter().map(|(n, _)| *n).collect();
    let (mut out, mut skipped) = (Vec::new(), Vec::new());
    for name in effects {
        let name = name.as_str();
        if name == NONE {
            out.push(Case { label: NONE.into(), options: Vec::new(), catalogued: true });
            continue;
        }
        if name == ALL {
            let options = REALISTIC_EFFECTS.iter().map(|e| effect_option(e)).collect();
            let catalogued = REALISTIC_EFFECTS.iter().all(|e| !NOT_CATALOGUED.contains(e));
            out.push(Case { label: ALL.into(), options, catalogued });
            continue;
        }
        if name == DRAWN {
            // The drawn rig at each size: `--drawn-rig=SIZE`, every plausible range SIZE times.
            for &size in sizes {
                let (label, option) = match size {
                    1.0 => (DRAWN.into(), "--drawn-rig".into()),
                    _ => (format!("{DRAWN}_x{size}"), format!("--drawn-rig={size}")),
                };
                out.push(Case { label, options: vec![option], catalogued: true });
            }
            continue;
        }
        let parts: Vec<&str> = name.split('+').collect();
        for part in &parts {
            assert!(
                known.contains(part),
                "TRUST_EFFECTS: unknown effect {part:?}; known: none, all, drawn, {}",
                known.join(", ")
            );
        }
        let catalogued = parts.iter().all(|p| !NOT_CATALOGUED.contains(p));
        for &size in sizes {
            if size == 1.0 {
                let options = parts.iter().map(|p| effect_option(p)).collect();
                out.push(Case { label: name.into(), options, catalogued });
                continue;
            }
            let specs: Vec<Option<String>> = parts.iter().map(|p| sized(p, size)).collect();
            // An effect alone whose value is no size has no such case; in a combination it
            // stays as it is beside the others.
            if parts.len() == 1 && specs[0].is_none() {
                skipped.push(format!("{name} ×{size} (its value is no size)"));
                continue;
            }
            let options =
                parts.iter().zip(&specs).map(|(p, spec)| effect_option(spec.as_deref().unwrap_or(p))).collect();
            out.push(Case { label: format!("{name}_x{size}"), options, catalogued });
        }
    }
    (out, skipped)
}

/// `NAME=VALUE` for effect `name` at `size` times its default headline value; None when its
/// value is no size ([`headline`]).
fn sized(name: &str, size: f64) -> Option<String> {
    let d = headline(name, &enabled(name))?;
    // Rounded to 9 decimals, so that 3 × 0.3 reads 0.9 in the arguments.
    let value = (size * d * 1e9).round() / 1e9;
    let spec = format!("{name}={value}");
    // The value must land where `headline` reads it, or the case is not the size it says.
    let got = headline(name, &enabled(&spec)).expect("switched on");
    assert!((got - size * d).abs() <= 1e-9 * (size * d).abs(), "{spec} sets {got}, not {size} × {d}");
    Some(spec)
}

/// `host simulate --effect=SPEC`.
fn effect_option(spec: &str) -> String {
    format!("--effect={spec}")
}

/// A comma-separated list in `var`, or `default`.
fn list_from_env(var: &str, default: Vec<String>) -> Vec<String> {
    match std::env::var(var) {
        Ok(v) => v.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect(),
        Err(_) => default,
    }
}

/// A case's directory under `target/bench-data/trust-matrix/` (a design's `/` as `+`).
fn case_dir(design: &str, case: &Case, seed: u64) -> PathBuf {
    measured::bench_dir("trust-matrix").join(design.replace('/', "+")).join(&case.label).join(format!("s{seed}"))
}

/// The captures of `design` for `seed` with the effect `options` ([`replay::capture_plans`]),
/// simulated if not cached.
fn captures(dir: &Path, design: &str, seed: u64, options: &[String]) -> Result<Vec<PathBuf>, String> {
    replay::capture_plans(design, options)
        .into_iter()
        .map(|(sub, plan, options)| replay::simulated_with(&dir.join(sub), &plan, seed, &options))
        .collect()
}

/// One seed of one cell, and what went wrong when it did.
struct SeedRun {
    outcome: SeedOutcome,
    /// The calibration's wall time, s (it shares the machine with the other worker).
    wall_s: Option<f64>,
    problem: Option<String>,
}

/// The last line of a log (a failed child's one-line error).
fn last_line(path: &Path) -> String {
    std::fs::read_to_string(path).ok().and_then(|t| t.lines().last().map(str::to_string)).unwrap_or_default()
}

/// Simulates (if not cached), calibrates and judges one seed of one cell, then tidies its
/// directory: a result that is no surprise (exit 0 within [`BAR_Z`]) keeps only
/// `out/calibration.json` of its 5 MB of output (report, figures, loop.json, records), every
/// other keeps all for inspection; without `keep_capture` the capture goes too (its truth,
/// logs and z-values stay).
fn run_seed(design: &str, case: &Case, seed: u64, keep_capture: bool) -> SeedRun {
    let dir = case_dir(design, case, seed);
    let r = judge(&dir, design, case, seed);
    let unsurprising = r.outcome.code == Some(0) && r.outcome.z.is_some_and(|z| replay::max_abs(&z) <= BAR_Z);
    if unsurprising {
        for entry in std::fs::read_dir(dir.join("out")).into_iter().flatten().flatten() {
            if entry.file_name() != "calibration.json" {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
    if !keep_capture {
        for (sub, _, _) in replay::capture_plans(design, &case.options) {
            let _ = std::fs::remove_file(dir.join(&sub).join("simulate.args"));
            let _ = std::fs::remove_file(dir.join(&sub).join("x.cap"));
        }
    }
    r
}

fn judge(dir: &Path, design: &str, case: &Case, seed: u64) -> SeedRun {
    let mut r = SeedRun { outcome: SeedOutcome::default(), wall_s: None, problem: None };
    let caps = match captures(dir, design, seed, &case.options) {
        Ok(caps) => caps,
        Err(e) => {
            r.problem = Some(e);
            return r;
        }
    };
    let usage = match replay::calibrate_files(dir, &caps) {
        Ok(u) => u,
        Err(e) => {
            r.problem = Some(e);
            return r;
        }
    };
    r.outcome.cpu_s = Some(usage.cpu_s);
    r.wall_s = Some(usage.wall_s);
    // −1: it did not exit normally.
    r.outcome.code = (usage.code >= 0).then_some(usage.code);
    if !matches!(usage.code, 0 | 3) {
        r.problem = Some(format!("exit {}: {}", usage.code, last_line(&dir.join("calibrate.log"))));
        return r;
    }
    let z = replay::read_json(&dir.join("out/calibration.json")).and_then(|cal| {
        // Every capture's truth holds the seed's sensor.
        trust::z_values(&cal, &replay::read_json(&caps[0].with_file_name("x.truth.json"))?)
    });
    match z {
        Ok(z) => {
            let _ = std::fs::write(dir.join("z.json"), serde_json::to_string(&z.to_vec()).expect("numbers"));
            r.outcome.z = Some(z);
        }
        Err(e) => r.problem = Some(e),
    }
    r
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.2}"))
}

const HEADINGS: &str = "design           effect                seeds  exit 0/3/other  max|z| exit0  max|z| all  z RMS exit0  conf.wrong  CPU s/cal  notes";

fn cell_line(design: &str, case: &Case, live: bool, c: &CellStats) -> String {
    let mut notes = Vec::new();
    if !c.never_confidently_wrong() {
        notes.push("CONFIDENTLY WRONG".to_string());
    }
    if c.rms_holds() == Some(false) {
        notes.push("z RMS OUT".into());
    }
    if live {
        notes.push(if c.all_exit0() { "live".into() } else { "live: NOT ALL EXIT 0".into() });
    }
    if !case.catalogued {
        notes.push("not catalogued".into());
    }
    format!(
        "{design:<16} {:<21} {:>5}  {:>14}  {:>12}  {:>10}  {:>11}  {:>10}  {:>9.2}  {}",
        case.label,
        c.seeds,
        format!("{}/{}/{}", c.exit0, c.exit3, c.other),
        fmt_opt(c.max_z_exit0),
        fmt_opt(c.max_z_all),
        fmt_opt(c.z_rms_exit0),
        c.confidently_wrong,
        c.cpu_per_calibration(),
        notes.join(", ")
    )
}

fn verdict(holds: bool) -> &'static str {
    if holds {
        "HOLDS"
    } else {
        "FAILS"
    }
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is taken.
    let seeds = replay::seeds_from_env("TRUST_SEEDS", 10);
    let n_seeds = seeds.clone().count();
    let default_designs = DEFAULT_RATES.iter().flat_map(|r| DEFAULT_LENGTHS_S.iter().map(move |d| format!("{r}@{d}")));
    let designs: Vec<String> = replay::plans_from_env("TRUST_DESIGNS", &default_designs.collect::<Vec<_>>().join(";"))
        .iter()
        .map(|d| full_design(d))
        .collect();
    let live = full_design(&std::env::var("TRUST_LIVE").unwrap_or_else(|_| DEFAULT_LIVE.into()));
    let default_effects = std::iter::once(NONE)
        .chain(Effects::NAMES.iter().map(|(n, _)| *n))
        .chain([ALL, DRAWN])
        .map(String::from)
        .collect();
    let effects = list_from_env("TRUST_EFFECTS", default_effects);
    let sizes: Vec<f64> = list_from_env("TRUST_SIZES", vec!["1".into(), "3".into()])
        .iter()
        .map(|s| s.parse().unwrap_or_else(|_| panic!("TRUST_SIZES: {s:?} is not a number")))
        .collect();
    let (cases, skipped) = cases(&effects, &sizes);
    let keep_captures = std::env::var("TRUST_CACHE").map_or(true, |v| v.trim() != "0");

    println!("trust matrix: host calibrate --replay, no effect declared, no latitude; {HOST}");
    println!(
        "{} designs × {} effect cases × {n_seeds} seeds (from {}) = {} calibrations, {} at a time; live design {live}",
        designs.len(),
        cases.len(),
        designs.len() * cases.len() * n_seeds,
        seeds.start(),
        replay::WORKERS
    );
    println!("designs: {}", designs.join(" ; "));
    println!("effects: {}", cases.iter().map(|c| c.label.as_str()).collect::<Vec<_>>().join(" "));
    println!("all = {}", REALISTIC_EFFECTS.join(" "));
    if !keep_captures {
        println!("TRUST_CACHE=0: each capture is removed after its calibration");
    }
    if !skipped.is_empty() {
        println!("left out: {}", skipped.join("; "));
    }
    println!(
        "z per calibration: {} (per axis: k, row of M, direction); confidently wrong = exit 0 with |z| > {BAR_Z}; CPU = user + system of the child (wait4)",
        trust::Z_COUNT
    );
    println!();
    println!("{HEADINGS}");

    let cells: Vec<(usize, usize)> = (0..designs.len()).flat_map(|d| (0..cases.len()).map(move |c| (d, c))).collect();
    let jobs: Vec<(usize, u64)> = (0..cells.len()).flat_map(|cell| seeds.clone().map(move |s| (cell, s))).collect();
    let is_live = |d: usize, c: usize| designs[d] == live && cases[c].catalogued;
    let mut per_cell: Vec<Vec<SeedOutcome>> = vec![Vec::new(); cells.len()];
    let mut finished = 0;
    let t = Instant::now();
    let runs = replay::run_parallel(
        &jobs,
        |&(cell, seed)| {
            let (d, c) = cells[cell];
            run_seed(&designs[d], &cases[c], seed, keep_captures)
        },
        |i, r| {
            let (cell, seed) = jobs[i];
            let (d, c) = cells[cell];
            finished += 1;
            let z = r.outcome.z.as_ref().map(|z| format!("  max|z| {:.2}", replay::max_abs(z))).unwrap_or_default();
            let code = r.outcome.code.map_or("-".into(), |c| c.to_string());
            let problem = r.problem.as_ref().map(|p| format!("  {p}")).unwrap_or_default();
            let cost = match (r.wall_s, r.outcome.cpu_s) {
                (Some(w), Some(c)) => format!("  wall {w:.1} s CPU {c:.1} s"),
                _ => String::new(),
            };
            eprintln!(
                "[{finished}/{} after {:.0} s] {} {} s{seed}: exit {code}{z}{cost}{problem}",
                jobs.len(),
                t.elapsed().as_secs_f64(),
                designs[d],
                cases[c].label
            );
            per_cell[cell].push(r.outcome.clone());
            if per_cell[cell].len() == n_seeds {
                println!("{}", cell_line(&designs[d], &cases[c], is_live(d, c), &trust::cell_stats(&per_cell[cell])));
                let _ = std::io::stdout().flush();
            }
        },
    );
    let wall_s = t.elapsed().as_secs_f64();

    let stats: Vec<CellStats> = runs
        .chunks(n_seeds)
        .map(|rs| trust::cell_stats(&rs.iter().map(|r| r.outcome.clone()).collect::<Vec<_>>()))
        .collect();
    println!();
    println!("every cell, in order:");
    println!("{HEADINGS}");
    for (&(d, c), s) in cells.iter().zip(&stats) {
        println!("{}", cell_line(&designs[d], &cases[c], is_live(d, c), s));
    }
    let b = trust::bars(cells.iter().zip(&stats).map(|(&(d, c), s)| (s, is_live(d, c))));
    let calibrations: usize = stats.iter().map(|s| s.calibrations).sum();
    let cpu_s: f64 = stats.iter().map(|s| s.cpu_s).sum();
    let median_cpu_s = measured::median(runs.iter().filter_map(|r| r.outcome.cpu_s).collect());
    let median_wall_s = measured::median(runs.iter().filter_map(|r| r.wall_s).collect());
    println!();
    println!(
        "summary over {} cells: confidently wrong (exit 0, max|z| > {BAR_Z}) in {} cells: {}; z RMS outside {}-{} in {} of {} cells with exit 0: {}; live {live}, catalogued: not every seed exit 0 in {} of {} cells: {}; {}",
        b.cells,
        b.confidently_wrong_cells,
        verdict(b.never_confidently_wrong()),
        BAR_RMS.start(),
        BAR_RMS.end(),
        b.rms_outside,
        b.rms_cells,
        verdict(b.rms_holds()),
        b.live_not_all_exit0,
        b.live_cells,
        b.live_holds().map_or("NOT RUN", verdict),
        if b.all_hold() { "THE BARS HOLD" } else { "THE BARS FAIL" }
    );
    println!(
        "CPU: {calibrations} calibrations {cpu_s:.1} s ({:.2} s per calibration, median {median_cpu_s:.2} s, median wall {median_wall_s:.2} s); every child, simulations included, {:.1} s; bench wall {wall_s:.0} s",
        cpu_s / calibrations as f64,
        measured::children_cpu_s()
    );
}
