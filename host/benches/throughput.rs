//! The whole of `host calibrate --replay` (read, decode, kinematics, every step of the closed
//! loop, diagnostics, JSON, report, record): samples per second per core and peak memory, on
//! simulated captures of 5 min, 30 min, 1 h and 4 h (two poses, no effects) and on the
//! independent realistic capture `../shared/validation/realistic-2speed-s101`.
//!
//! `cargo bench -p host --bench throughput` prints the figures (issue 7's bars: ≥ 5 M samples/s
//! per core and ≤ 128 MiB at 1 h, ≤ 256 MiB at 4 h, cost per sample independent of length).
//! Each measurement runs the built `host` binary as a child process, so it measures exactly what
//! an operator runs; its CPU time (user + system) and peak resident set come from the kernel's
//! accounting of that child (`wait4`), so neither other processes on the machine nor the
//! simulation that made the capture count. The captures are simulated once with `host simulate`
//! and cached under `target/bench-data/`.
//!
//! `BENCH_RUNS=N` sets the repetitions of the short cases (default 5; the 4-hour and realistic
//! ones run ⌈N/2⌉ times); `BENCH_ONLY=1h,4h,…` runs only the named cases.

mod measured;
use measured::Usage;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

/// The `host` binary cargo built beside this bench.
const HOST: &str = env!("CARGO_BIN_EXE_host");

/// Seconds per pose (spin-up included) of each simulated case: 2 poses each.
const CASES: [(&str, f64); 4] = [("5min", 150.0), ("30min", 900.0), ("1h", 1800.0), ("4h", 7200.0)];

/// Bars of issue 7.
const BAR_SAMPLES_PER_S: f64 = 5e6;
const BAR_RSS_1H_MIB: f64 = 128.0;
const BAR_RSS_4H_MIB: f64 = 256.0;

fn bench_dir() -> PathBuf {
    measured::bench_dir("")
}

/// The realistic capture from the independent model, beside the project root.
fn realistic_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/validation/realistic-2speed-s101")
}

/// A cached simulated capture of two poses × `per_pose_s`, made by `host simulate`.
fn simulated(name: &str, per_pose_s: f64) -> PathBuf {
    let path = bench_dir().join(format!("two-pose-{name}-seed7.cap"));
    if !path.exists() {
        let t = Instant::now();
        let status = Command::new(HOST)
            .args(["simulate", "--seed", "7", "--duration", &per_pose_s.to_string(), "--out"])
            .arg(&path)
            .stdout(Stdio::null())
            .status()
            .expect("host simulate runs");
        assert!(status.success(), "host simulate failed for {}", path.display());
        eprintln!("simulated {} in {:.1} s", path.display(), t.elapsed().as_secs_f64());
    }
    path
}

/// Moving samples (what the loop calibrates from) in the captures.
fn samples_in(files: &[PathBuf]) -> usize {
    files
        .iter()
        .map(|f| {
            let cap = host::capture::decode_reader(std::fs::File::open(f).expect("open capture")).expect("decode");
            cap.runs.iter().filter(|r| r.rate_mdps != 0).map(|r| r.samples.len()).sum::<usize>()
        })
        .sum()
}

/// Runs `host calibrate --replay files` once into a fresh directory and waits for it with
/// `wait4`, which hands back that child's own CPU time and peak resident set.
fn run_once(files: &[PathBuf]) -> Usage {
    let out = bench_dir().join("calibrate-out");
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).expect("create output dir");
    let db = format!("sqlite:{}", out.join("records.sqlite").display());
    let log = std::fs::File::create(bench_dir().join("calibrate.log")).expect("log file");
    let mut cmd = Command::new(HOST);
    cmd.arg("calibrate")
        .arg("--replay")
        .args(files)
        .arg("--out-dir")
        .arg(&out)
        .args(["--db", &db])
        .stdout(Stdio::null())
        .stderr(log);
    let usage = measured::run_measured(cmd).unwrap_or_else(|e| panic!("host calibrate: {e}"));
    let code = usage.code;
    // 0: at the noise floor; 3: calibrated with structure left (the realistic capture may be).
    assert!(
        code == 0 || code == 3,
        "host calibrate exited {code}: see {}",
        bench_dir().join("calibrate.log").display()
    );
    usage
}

/// Medians of `runs` children on `files`.
struct Figures {
    samples: usize,
    wall_s: f64,
    cpu_s: f64,
    peak_mib: f64,
    cpu_all: Vec<f64>,
}

impl Figures {
    fn per_core(&self) -> f64 {
        self.samples as f64 / self.cpu_s
    }

    fn ns_per_sample(&self) -> f64 {
        self.cpu_s / self.samples as f64 * 1e9
    }
}

/// The children's figures on `files`, `runs` times. Nothing may grow the bench's own memory
/// before the last child is spawned: a child's `ru_maxrss` includes its parent's peak resident
/// set (at `exec` the kernel folds the high-water mark of the address space it leaves, shared
/// with the parent under `posix_spawn`'s vfork, into the child's), so the sample counts, which
/// decode whole captures here, are taken after every child ran ([`report`]).
fn measure(files: &[PathBuf], runs: usize) -> Vec<Usage> {
    (0..runs).map(|_| run_once(files)).collect()
}

/// Prints one case's figures from its children's usage.
fn report(name: &str, files: &[PathBuf], usages: &[Usage]) -> Figures {
    let f = Figures {
        samples: samples_in(files),
        wall_s: measured::median(usages.iter().map(|u| u.wall_s).collect()),
        cpu_s: measured::median(usages.iter().map(|u| u.cpu_s).collect()),
        peak_mib: measured::median(usages.iter().map(|u| u.peak_mib).collect()),
        cpu_all: usages.iter().map(|u| u.cpu_s).collect(),
    };
    println!(
        "{name:>10}: {:>9} samples  CPU {:7.3} s  wall {:7.3} s  {:6.2} M samples/s per core  {:6.0} ns/sample  peak RSS {:6.1} MiB  (median of {}; CPU each: {})",
        f.samples,
        f.cpu_s,
        f.wall_s,
        f.per_core() / 1e6,
        f.ns_per_sample(),
        f.peak_mib,
        usages.len(),
        f.cpu_all.iter().map(|c| format!("{c:.3}")).collect::<Vec<_>>().join(" ")
    );
    f
}

fn bar(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "NOT MET"
    }
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is taken.
    let runs: usize = std::env::var("BENCH_RUNS").ok().and_then(|v| v.parse().ok()).unwrap_or(5).max(1);
    let only: Option<Vec<String>> =
        std::env::var("BENCH_ONLY").ok().map(|v| v.split(',').map(|s| s.trim().to_string()).collect());
    let wanted = |name: &str| only.as_ref().is_none_or(|o| o.iter().any(|x| x == name));
    println!("host calibrate --replay, whole path, {HOST}");
    println!("CPU = user + system time of the child (wait4), not wall; RSS = its ru_maxrss");
    // Every child first (see `measure`), then the figures.
    let mut cases: Vec<(&str, Vec<PathBuf>, Vec<Usage>)> = Vec::new();
    for (name, per_pose_s) in CASES {
        if !wanted(name) {
            continue;
        }
        let path = simulated(name, per_pose_s);
        let n = if name == "4h" { runs.div_ceil(2) } else { runs };
        cases.push((name, vec![path.clone()], measure(&[path], n)));
    }
    if wanted("realistic") {
        let dir = realistic_dir();
        let caps = measured::replay::captures_in(&dir).unwrap_or_default();
        if caps.is_empty() {
            println!("realistic: SKIPPED, no captures in {} (the shared validation folder is absent)", dir.display());
        } else {
            let usages = measure(&caps, runs.div_ceil(2));
            cases.push(("realistic", caps, usages));
        }
    }
    let figures: std::collections::HashMap<&str, Figures> =
        cases.iter().map(|(name, files, usages)| (*name, report(name, files, usages))).collect();
    println!();
    if let Some(f) = figures.get("1h") {
        println!(
            "bar 1 h: {:.2} M samples/s per core (≥ 5: {}), peak {:.0} MiB (≤ {BAR_RSS_1H_MIB}: {})",
            f.per_core() / 1e6,
            bar(f.per_core() >= BAR_SAMPLES_PER_S),
            f.peak_mib,
            bar(f.peak_mib <= BAR_RSS_1H_MIB)
        );
    }
    if let Some(f) = figures.get("4h") {
        println!("bar 4 h: peak {:.0} MiB (≤ {BAR_RSS_4H_MIB}: {})", f.peak_mib, bar(f.peak_mib <= BAR_RSS_4H_MIB));
    }
    if let (Some(a), Some(b)) = (figures.get("30min"), figures.get("5min")) {
        println!(
            "linearity: CPU per sample at 30 min / at 5 min = {:.3} ({:.0} vs {:.0} ns/sample; 1.000 is linear)",
            a.ns_per_sample() / b.ns_per_sample(),
            a.ns_per_sample(),
            b.ns_per_sample()
        );
    }
}
