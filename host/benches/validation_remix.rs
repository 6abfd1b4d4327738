//! Is σ honest on data this project did not write, for sensors it was never shown? The captures
//! of `../shared/validation` come from an independent model of the exciter, one sensor each.
//! This bench makes `REMIX_SEEDS` other sensors of every folder (default 5): each gyro sample's
//! counts mixed by a matrix A (diagonal 1 ± 3 %, cross terms ±1°) and given 3 counts of fresh
//! noise, every other frame as it was, so the truth moves exactly to M' = A·M
//! (`measured/remix.rs`). Each is calibrated (`host calibrate --replay`, nothing declared) and
//! judged on `check.py`'s 21 z-values against its truth.
//!
//! For every folder it prints each seed (exit status, max |z|, worst direction and sensitivity
//! error) and then the folder's figures over its seeds: exit statuses, max |z| at exit 0 and over
//! all, the z RMS at exit 0, how many seeds were confidently wrong (exit 0 with some |z| > 4).
//! The bar is each folder's own (its README): `clean-*` at exit 0 with every |z| ≤ 4, every other
//! folder never confidently wrong. The realistic folder's 0.002° / 20 ppm are the figures of its
//! own sensor and noise draw, which need not hold for another: they are printed, not judged.
//! The bench exits 0 whatever it finds: a measurement, not a test.
//!
//! `REMIX_SEEDS=N` (or `A-B`: seeds A..=B), `REMIX_FOLDERS=clean-s101,gsens-1speed-s101`
//! (default: every folder with a `truth.json`), `REMIX_ROOT=DIR` (default `../shared/validation`:
//! folders of captures in its layout, such as its folders with runs left out),
//! `REMIX_CUT_S=30,45,none`: each folder also (or, without `none`, only) with every run cut to
//! its first so many seconds, a design no folder holds (default: whole runs);
//! `REMIX_GAIN=3,none`: each folder that shares `clean-s101`'s rig and noise draw frame for
//! frame (the g-sensitivity and Earth folders) also (or only) with its difference from
//! `clean-s101`, its one effect, grown that many times (`measured::remix::grown`).
//! Remixed captures are kept in `target/bench-data/remix/<folder>/m<seed>/`.
//!
//! `cargo bench -p host --bench validation_remix --profile release`: 6 folders × 5 seeds, 30
//! calibrations, about 30 s of their CPU (2.5 s at most each, `realistic-2speed-s101`).

mod measured;
use measured::remix::{grown, m_true, Remix};
use measured::replay::{self, max_abs};
use measured::trust::{cell_stats, SeedOutcome, BAR_Z};
use std::path::{Path, PathBuf};

/// What one row of the table remixes: a folder, its runs cut or whole, its effect grown or not.
#[derive(Debug, Clone)]
struct Cell {
    folder: PathBuf,
    cut_s: Option<f64>,
    /// The folder's difference from its clean twin ([`TWIN`]) times this ([`grown`]).
    gain: Option<f64>,
}

/// The folder whose rig and noise draw the others of `../shared/validation` that hold one
/// effect share, frame for frame: what an effect is grown from.
const TWIN: &str = "clean-s101";

impl Cell {
    /// The folder's name, with its cut and gain.
    fn label(&self) -> String {
        let mut name = self.folder.file_name().and_then(|n| n.to_str()).unwrap_or("folder").to_string();
        if let Some(g) = self.gain {
            name += &format!("-x{g}");
        }
        if let Some(c) = self.cut_s {
            name += &format!("-cut{c}s");
        }
        name
    }

    /// A capture of the cell's folder, its effect grown if the cell says so.
    fn capture_bytes(&self, cap: &Path, file: &str) -> Result<Vec<u8>, String> {
        let read = |p: &Path| std::fs::read(p).map_err(|e| format!("read {}: {e}", p.display()));
        let bytes = read(cap)?;
        let Some(gain) = self.gain else { return Ok(bytes) };
        let twin = self.folder.with_file_name(TWIN).join(file);
        grown(file, &read(&twin)?, &bytes, gain)
    }
}

/// A cell's remix of seed `seed`, made once: its captures and truth.
fn remixed(cell: &Cell, seed: u64) -> Result<(PathBuf, Vec<PathBuf>), String> {
    let dir = measured::bench_dir(&format!("remix/{}/m{seed}", cell.label()));
    let remix = Remix { cut_s: cell.cut_s, ..Remix::drawn(seed) };
    let truth = replay::read_json(&cell.folder.join("truth.json"))?;
    let text = serde_json::to_string_pretty(&remix.truth(&truth)?).expect("a JSON value");
    std::fs::write(dir.join("truth.json"), text).map_err(|e| format!("write truth.json: {e}"))?;
    let mut caps = Vec::new();
    for cap in replay::captures_in(&cell.folder)? {
        let file = cap.file_name().and_then(|n| n.to_str()).unwrap_or("x.cap").to_string();
        let out = dir.join(&file);
        if !out.exists() {
            let (mixed, held) = remix.capture(&file, &cell.capture_bytes(&cap, &file)?)?;
            if held > 0 {
                eprintln!("{}: {held} counts held at the i16 range", out.display());
            }
            let part = dir.join(format!("{file}.part"));
            std::fs::write(&part, mixed).map_err(|e| format!("write {}: {e}", part.display()))?;
            std::fs::rename(&part, &out).map_err(|e| format!("rename {}: {e}", part.display()))?;
        }
        caps.push(out);
    }
    Ok((dir, caps))
}

/// One seed's outcome, and its line.
fn judge(cell: &Cell, seed: u64) -> (SeedOutcome, String) {
    let mut o = SeedOutcome::default();
    let mut wall_s = f64::NAN;
    let run = remixed(cell, seed).and_then(|(dir, caps)| {
        let usage = replay::calibrate_files(&dir, &caps)?;
        (o.code, o.cpu_s, wall_s) = ((usage.code >= 0).then_some(usage.code), Some(usage.cpu_s), usage.wall_s);
        let truth = replay::read_json(&dir.join("truth.json"))?;
        let cal = replay::read_json(&dir.join("out/calibration.json"))?;
        let z = host::calib::result::truth_check::z_values(&cal, &m_true(&truth)?)?;
        o.z = Some(z);
        Ok(errors(&cal, &truth))
    });
    let line = match run {
        Ok((dir_deg, ppm)) => format!(
            "exit {}  max|z| {:.2}  direction error {dir_deg:.4}°  sensitivity error {ppm:.1} ppm  wall {wall_s:.1} s  CPU {:.1} s",
            o.code.map_or("-".into(), |c| c.to_string()),
            o.z.map_or(f64::NAN, |z| max_abs(&z)),
            o.cpu_s.unwrap_or(f64::NAN)
        ),
        Err(e) => format!("exit {}: {e}", o.code.map_or("-".into(), |c| c.to_string())),
    };
    (o, line)
}

/// The worst direction error, °, and sensitivity error, ppm, of a calibration against its truth.
fn errors(cal: &serde_json::Value, truth: &serde_json::Value) -> (f64, f64) {
    let (mut dir_deg, mut ppm) = (0.0f64, 0.0f64);
    for i in 0..3 {
        let s = replay::triple(&cal["axes"][i]["s"], "s").unwrap_or([f64::NAN; 3]);
        let t = replay::triple(&truth["sensor"]["S"][i], "S").unwrap_or([f64::NAN; 3]);
        let cos = s.iter().zip(&t).map(|(a, b)| a * b).sum::<f64>().clamp(-1.0, 1.0);
        dir_deg = dir_deg.max(cos.acos().to_degrees());
        let k = cal["axes"][i]["k_counts_per_dps"].as_f64().unwrap_or(f64::NAN);
        let kt = truth["sensor"]["k"][i].as_f64().unwrap_or(f64::NAN);
        ppm = ppm.max(((k - kt) / kt).abs() * 1e6);
    }
    (dir_deg, ppm)
}

/// A list of positive numbers or `none` from `var` (`REMIX_CUT_S`, `REMIX_GAIN`); `[None]`
/// when it is not set.
fn options_from_env(var: &str) -> Vec<Option<f64>> {
    let Ok(spec) = std::env::var(var) else {
        return vec![None];
    };
    spec.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| match s {
            "none" => None,
            _ => Some(s.parse::<f64>().ok().filter(|c| *c > 0.0).unwrap_or_else(|| {
                eprintln!("{var}: {s:?} is neither a positive number nor none");
                std::process::exit(2)
            })),
        })
        .collect()
}

/// Every cell: each folder with each cut, and each gain where the folder has a twin to grow
/// its effect from (every capture of it also in [`TWIN`], which is not its own twin).
fn cells(folders: &[PathBuf]) -> Vec<Cell> {
    let (cuts, gains) = (options_from_env("REMIX_CUT_S"), options_from_env("REMIX_GAIN"));
    let has_twin = |f: &Path| {
        !f.ends_with(TWIN)
            && replay::captures_in(f).is_ok_and(|caps| {
                caps.iter().all(|c| c.file_name().is_some_and(|n| f.with_file_name(TWIN).join(n).exists()))
            })
    };
    let mut out = Vec::new();
    for folder in folders {
        for &gain in gains.iter().filter(|g| g.is_none() || has_twin(folder)) {
            for &cut_s in &cuts {
                out.push(Cell { folder: folder.clone(), cut_s, gain });
            }
        }
    }
    out
}

fn main() {
    let root = std::env::var_os("REMIX_ROOT")
        .map_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/validation"), PathBuf::from);
    let seeds = replay::seeds_from_env("REMIX_SEEDS", 5);
    let only: Vec<String> = std::env::var("REMIX_FOLDERS")
        .map(|v| v.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect())
        .unwrap_or_default();
    let Ok(entries) = std::fs::read_dir(&root) else {
        println!("{}: absent, nothing to remix", root.display());
        return;
    };
    let mut folders: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join("truth.json").exists())
        .filter(|p| only.is_empty() || only.iter().any(|o| p.ends_with(o)))
        .collect();
    folders.sort();
    let cells = cells(&folders);
    let jobs: Vec<(usize, u64)> = (0..cells.len()).flat_map(|c| seeds.clone().map(move |s| (c, s))).collect();
    let name = |c: usize| cells[c].label();
    let results = replay::run_parallel(
        &jobs,
        |&(c, seed)| judge(&cells[c], seed),
        |i, (_, line)| println!("{} m{}: {line}", name(jobs[i].0), jobs[i].1),
    );
    println!(
        "\nfolder                              seeds  exit 0/3/other  max|z| exit0  max|z| all  z RMS exit0  conf.wrong  CPU s/cal  bar"
    );
    let mut all_hold = true;
    for f in 0..cells.len() {
        let outcomes: Vec<SeedOutcome> =
            jobs.iter().zip(&results).filter(|((g, _), _)| *g == f).map(|(_, (o, _))| o.clone()).collect();
        let c = cell_stats(&outcomes);
        let holds = if name(f).starts_with("clean") {
            c.all_exit0() && c.max_z_exit0.is_some_and(|z| z <= BAR_Z)
        } else {
            c.never_confidently_wrong() && c.other == 0
        };
        all_hold &= holds;
        let fmt = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.2}"));
        println!(
            "{:<35} {:>5}  {:>14}  {:>12}  {:>10}  {:>11}  {:>10}  {:>9.2}  {}",
            name(f),
            c.seeds,
            format!("{}/{}/{}", c.exit0, c.exit3, c.other),
            fmt(c.max_z_exit0),
            fmt(c.max_z_all),
            fmt(c.z_rms_exit0),
            c.confidently_wrong,
            measured::median(outcomes.iter().filter_map(|o| o.cpu_s).collect()),
            if holds { "holds" } else { "SHORT" }
        );
    }
    println!("\nevery folder's bar on every remix: {}", if all_hold { "holds" } else { "SHORT" });
}
