//! Simulate, calibrate, read back: the machinery of the accuracy benches (`all_effects`,
//! `trust_matrix`). A case is one directory: the capture `x.cap` that `host simulate` writes, its
//! truth `x.truth.json`, the arguments it was simulated with (`simulate.args`), the logs, and the
//! `out/` of `host calibrate --replay`. Captures are cached (simulated once); the calibration is
//! redone on every run, into a fresh `out/` with its own records database, so the operator's
//! records are not filled with bench results and two children never write one file.

use super::Usage;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// The `host` binary cargo built beside the bench.
pub const HOST: &str = env!("CARGO_BIN_EXE_host");

/// The realistic rig's effects ([`host::sim::Effects::REALISTIC`]).
pub const REALISTIC_EFFECTS: [&str; 10] = host::sim::Effects::REALISTIC;

/// Seconds per run, spin-up included, of a plan that gives none: the session an operator runs
/// by default.
pub const DURATION_S: &str = "120";

/// Calibrations run side by side: one per core of the 2-core machine the figures are quoted for.
pub const WORKERS: usize = 2;

/// A plan's rates (`--rates-dps`) and seconds per run: `180,-180@300` or `180,90` (then
/// [`DURATION_S`]).
pub fn rates_and_duration(plan: &str) -> (&str, &str) {
    plan.split_once('@').unwrap_or((plan, DURATION_S))
}

/// A plan written out in full, `rates@seconds`, so that `180,90` and `180,90@120` are one plan.
pub fn full_plan(plan: &str) -> String {
    let (rates, duration_s) = rates_and_duration(plan);
    format!("{rates}@{duration_s}")
}

/// A design's suffix for its runs captured one per file, each simulated on its own, as the
/// independent validation captures hold them: `180,90@120/files`.
pub const FILES: &str = "/files";

/// A design written out in full ([`full_plan`]), its [`FILES`] suffix kept.
pub fn full_design(design: &str) -> String {
    match design.strip_suffix(FILES) {
        Some(plan) => full_plan(plan) + FILES,
        None => full_plan(design),
    }
}

/// The captures one seed of `design` is simulated into, with the effect `options`: (the
/// subdirectory, the plan, the `host simulate` options) of each. One capture of every run; or,
/// with [`FILES`], one per pose and rate in `p<pose>_<rate>/`, each with `capture_level` (a noise
/// draw of its own, and a zero-rate level of its own when the options give it a size; level 0
/// otherwise).
pub fn capture_plans(design: &str, options: &[String]) -> Vec<(String, String, Vec<String>)> {
    let Some(plan) = design.strip_suffix(FILES) else {
        return vec![(String::new(), design.to_string(), options.to_vec())];
    };
    let (rates, duration_s) = rates_and_duration(plan);
    let mut own = options.to_vec();
    if !own.iter().any(|o| o.starts_with("--effect=capture_level")) {
        own.push("--effect=capture_level=0".into());
    }
    let poses = [1, 2].into_iter();
    poses
        .flat_map(|pose| rates.split(',').map(move |rate| (pose, rate)))
        .map(|(pose, rate)| {
            let options = own.iter().cloned().chain([format!("--poses={pose}")]).collect();
            (format!("p{pose}_{rate}"), format!("{rate}@{duration_s}"), options)
        })
        .collect()
}

/// The plans in `var` (`;`-separated, see [`rates_and_duration`]), or in `default`.
pub fn plans_from_env(var: &str, default: &str) -> Vec<String> {
    std::env::var(var)
        .unwrap_or_else(|_| default.into())
        .split(';')
        .map(|p| p.trim().to_string())
        .filter(|p| !p.is_empty())
        .collect()
}

/// The seeds `var` names: `N` for seeds 1 to N (at least 1), `A-B` for seeds A to B (to look
/// at seeds a first run did not cover without redoing it); `1..=default` when unset or unreadable.
pub fn seeds_from_env(var: &str, default: u64) -> std::ops::RangeInclusive<u64> {
    let text = std::env::var(var).unwrap_or_default();
    let range = match text.trim().split_once('-') {
        Some((a, b)) => a.trim().parse::<u64>().ok().zip(b.trim().parse::<u64>().ok()),
        None => text.trim().parse::<u64>().ok().map(|n| (1, n)),
    };
    let (first, last) = range.unwrap_or((1, default));
    first.max(1)..=last.max(first.max(1))
}

/// The cached capture `dir/x.cap` of `plan` for `seed` with `effects` (each `NAME` or
/// `NAME=VALUE`), simulated if absent or if it was simulated with other arguments. The truth
/// and then the arguments are written after the capture is complete, so together they mark a
/// whole one: an interrupted simulation is redone.
pub fn simulated(dir: &Path, plan: &str, seed: u64, effects: &[impl AsRef<str>]) -> Result<PathBuf, String> {
    let effects: Vec<String> = effects.iter().map(|e| format!("--effect={}", e.as_ref())).collect();
    simulated_with(dir, plan, seed, &effects)
}

/// [`simulated`] with `host simulate` options of any kind (`--effect=…`, `--drawn-rig`).
pub fn simulated_with(dir: &Path, plan: &str, seed: u64, options: &[String]) -> Result<PathBuf, String> {
    let cap = dir.join("x.cap");
    let args_file = dir.join("simulate.args");
    let (rates, duration_s) = rates_and_duration(plan);
    // `=`: a plan starting with a negative rate must not read as an option.
    let mut args = vec![format!("--seed={seed}"), format!("--rates-dps={rates}"), format!("--duration={duration_s}")];
    args.extend(options.iter().cloned());
    let args_text = args.join("\n") + "\n";
    if cap.exists()
        && dir.join("x.truth.json").exists()
        && std::fs::read_to_string(&args_file).is_ok_and(|a| a == args_text)
    {
        return Ok(cap);
    }
    let _ = std::fs::remove_file(&args_file);
    std::fs::create_dir_all(dir).map_err(|e| format!("create {}: {e}", dir.display()))?;
    let t = Instant::now();
    let log = std::fs::File::create(dir.join("simulate.log")).map_err(|e| format!("simulate.log: {e}"))?;
    let status = Command::new(HOST)
        .arg("simulate")
        .arg("--out")
        .arg(&cap)
        .args(&args)
        .stdout(Stdio::null())
        .stderr(log)
        .status()
        .map_err(|e| format!("host simulate: {e}"))?;
    if !status.success() {
        return Err(format!("host simulate failed ({status}): see {}", dir.join("simulate.log").display()));
    }
    std::fs::write(&args_file, args_text).map_err(|e| format!("write {}: {e}", args_file.display()))?;
    eprintln!("simulated {} in {:.1} s", cap.display(), t.elapsed().as_secs_f64());
    Ok(cap)
}

/// Runs `host calibrate --replay cap` into a fresh `out/` beside it (a stale `calibration.json`
/// must not stand in for a failed run), stdout to `calibrate.txt` and stderr to `calibrate.log`
/// there, and waits for it with `wait4`, which hands back that child's own CPU time. No effect
/// is declared and no latitude given: the loop has to find everything from the data.
pub fn calibrate(cap: &Path) -> Result<Usage, String> {
    calibrate_files(cap.parent().expect("the capture is in its case directory"), &[cap.to_path_buf()])
}

/// [`calibrate`] of the captures `caps` together, into `dir`.
pub fn calibrate_files(dir: &Path, caps: &[PathBuf]) -> Result<Usage, String> {
    let out = dir.join("out");
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).map_err(|e| format!("create {}: {e}", out.display()))?;
    let db = format!("sqlite:{}", out.join("records.sqlite").display());
    let stdout = std::fs::File::create(dir.join("calibrate.txt")).map_err(|e| format!("calibrate.txt: {e}"))?;
    let stderr = std::fs::File::create(dir.join("calibrate.log")).map_err(|e| format!("calibrate.log: {e}"))?;
    let mut cmd = Command::new(HOST);
    cmd.arg("calibrate")
        .arg("--replay")
        .args(caps)
        .arg("--out-dir")
        .arg(&out)
        .args(["--db", &db])
        .stdout(stdout)
        .stderr(stderr);
    super::run_measured(cmd).map_err(|e| format!("host calibrate: {e}"))
}

/// Runs `run` on every job, [`WORKERS`] at a time, taking them in order; `done` sees each
/// result (with its job's index) as soon as it is there, one at a time. The results come back
/// in job order.
pub fn run_parallel<J: Sync, O: Send>(
    jobs: &[J],
    run: impl Fn(&J) -> O + Sync,
    done: impl FnMut(usize, &O) + Send,
) -> Vec<O> {
    let next = AtomicUsize::new(0);
    let state = Mutex::new((done, (0..jobs.len()).map(|_| None).collect::<Vec<Option<O>>>()));
    std::thread::scope(|scope| {
        for _ in 0..WORKERS {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(job) = jobs.get(i) else { break };
                let o = run(job);
                let mut state = state.lock().expect("no worker panics holding it");
                (state.0)(i, &o);
                state.1[i] = Some(o);
            });
        }
    });
    let (_, results) = state.into_inner().expect("no worker panicked");
    results.into_iter().map(|o| o.expect("every job ran")).collect()
}

/// The captures (`*.cap`) in `dir`, in name order.
pub fn captures_in(dir: &Path) -> Result<Vec<PathBuf>, String> {
    let mut caps: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "cap"))
        .collect();
    caps.sort();
    Ok(caps)
}

pub fn read_json(path: &Path) -> Result<Value, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("read {}: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("parse {}: {e}", path.display()))
}

pub fn number(v: &Value, what: &str) -> Result<f64, String> {
    v.as_f64().ok_or_else(|| format!("{what} is not a number"))
}

/// `v` as 3 numbers.
pub fn triple(v: &Value, what: &str) -> Result<[f64; 3], String> {
    match v.as_array().map(Vec::as_slice) {
        Some([x, y, z]) => Ok([number(x, what)?, number(y, what)?, number(z, what)?]),
        _ => Err(format!("{what} is not 3 numbers")),
    }
}

/// Largest |x|; a NaN (e.g. a z with σ = 0) counts as infinite, so it can never pass a bar.
pub fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(if x.is_nan() { f64::INFINITY } else { x.abs() }))
}
