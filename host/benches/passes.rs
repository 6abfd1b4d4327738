//! Issue 25's steering measurement: what the closed loop costs, in decode passes. For each case,
//! `host calibrate --replay` and `host inspect` (one decode of the same captures, and nothing
//! else) run as child processes, alternately, `BENCH_RUNS` times each (default 3); the bench
//! prints the best CPU time (user + system, the kernel's accounting of that child alone) of each
//! and their ratio: the number of decode passes the whole calibration costs. A ratio of two
//! processes measured in the same minutes holds when the machine drifts or differs, where
//! seconds do not.
//!
//! Cases and their bars: the independent realistic capture `../shared/validation/
//! realistic-2speed-s101` (≤ 25), a clean simulated 1-h capture (two poses × 1800 s, no effect;
//! ≤ 5), the all-effects capture (the realistic effects, 180 and 90 °/s in both poses, 300 s
//! each; ≤ 25). `BENCH_ONLY=realistic,1h,all-effects` runs only the named cases. The bench
//! exits 0 whatever it finds: a measurement, not a test.
//!
//! `cargo bench -p host --bench passes`.

mod measured;
use measured::replay::{self, HOST, REALISTIC_EFFECTS};
use measured::Usage;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// One case: its name, its bar in decode passes, its captures.
struct Case {
    name: &'static str,
    bar_passes: f64,
    files: Vec<PathBuf>,
}

fn realistic() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/validation/realistic-2speed-s101");
    replay::captures_in(&dir).unwrap_or_else(|e| panic!("{e}"))
}

fn cases(only: &[String]) -> Vec<Case> {
    let wanted = |name: &str| only.is_empty() || only.iter().any(|o| o == name);
    let mut out = Vec::new();
    if wanted("realistic") {
        out.push(Case { name: "realistic", bar_passes: 25.0, files: realistic() });
    }
    if wanted("1h") {
        let dir = measured::bench_dir("passes/clean-1h");
        let none: [&str; 0] = [];
        let cap = replay::simulated(&dir, "180@1800", 7, &none).unwrap_or_else(|e| panic!("{e}"));
        out.push(Case { name: "1h", bar_passes: 5.0, files: vec![cap] });
    }
    if wanted("all-effects") {
        let dir = measured::bench_dir("passes/all-effects");
        let cap = replay::simulated(&dir, "180,90@300", 1, &REALISTIC_EFFECTS).unwrap_or_else(|e| panic!("{e}"));
        out.push(Case { name: "all-effects", bar_passes: 25.0, files: vec![cap] });
    }
    out
}

/// `host calibrate --replay files` into a fresh directory, nothing recorded.
fn calibrate(files: &[PathBuf]) -> Usage {
    let out = measured::bench_dir("passes/out");
    let _ = std::fs::remove_dir_all(&out);
    let mut cmd = Command::new(HOST);
    cmd.arg("calibrate").arg("--replay").args(files).arg("--out-dir").arg(&out).arg("--no-db");
    cmd.stdout(Stdio::null()).stderr(Stdio::null());
    let u = measured::run_measured(cmd).unwrap_or_else(|e| panic!("{e}"));
    // 0 at the noise floor, 3 with structure left: both are a whole calibration's cost.
    assert!(u.code == 0 || u.code == 3, "host calibrate exited {}", u.code);
    u
}

/// `host inspect files`: one decode of the same captures.
fn inspect(files: &[PathBuf]) -> Usage {
    let mut cmd = Command::new(HOST);
    cmd.arg("inspect").args(files).stdout(Stdio::null()).stderr(Stdio::null());
    let u = measured::run_measured(cmd).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(u.code, 0, "host inspect exited {}", u.code);
    u
}

fn best(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::INFINITY, f64::min)
}

fn main() {
    let runs: usize = std::env::var("BENCH_RUNS").ok().and_then(|v| v.trim().parse().ok()).unwrap_or(3).max(1);
    let only: Vec<String> = std::env::var("BENCH_ONLY")
        .map(|v| v.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect())
        .unwrap_or_default();
    println!(
        "decode passes = best CPU of host calibrate --replay / best CPU of host inspect, {runs} of each, alternated"
    );
    for case in cases(&only) {
        let (mut cal, mut ins, mut wall_s) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..runs {
            let c = calibrate(&case.files);
            wall_s.push(c.wall_s);
            cal.push(c.cpu_s);
            ins.push(inspect(&case.files).cpu_s);
        }
        let passes = best(&cal) / best(&ins);
        println!(
            "{:>12}: calibrate {:7.3} s CPU ({:.1} s wall, median)  inspect {:6.4} s  → {:6.1} decode passes (bar ≤ {:.0}: {}; medians: {:.1})  calibrate each {:?}  inspect each {:?}",
            case.name,
            best(&cal),
            measured::median(wall_s),
            best(&ins),
            passes,
            case.bar_passes,
            if passes <= case.bar_passes { "holds" } else { "fails" },
            measured::median(cal.clone()) / measured::median(ins.clone()),
            cal.iter().map(|c| (c * 1000.0).round() / 1000.0).collect::<Vec<_>>(),
            ins.iter().map(|c| (c * 10000.0).round() / 10000.0).collect::<Vec<_>>(),
        );
    }
}
