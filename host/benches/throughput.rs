//! Decode + calibrate throughput on a 1-hour, 800 Hz, two-pose capture (issue bar: ≥ 5 million
//! samples per second on one core), with the peak memory of the measured process.
//!
//! `cargo bench -p host --bench throughput` prints the figures. The capture is simulated once and
//! cached under `target/bench-data/`. Each measurement runs in a fresh child process so that its
//! peak resident memory (VmHWM) covers only reading, decoding and calibrating, not the simulation.

use host::{calib, capture, sim};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Seconds per pose: one hour in all.
const RUN_S: f64 = 1800.0;
/// Measured repetitions; the median is quoted.
const REPEATS: usize = 5;

fn data_path() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/bench-data");
    std::fs::create_dir_all(&dir).expect("create bench data dir");
    dir.join(format!("two-pose-{RUN_S}s-seed7.cap"))
}

/// Time this process has spent on a CPU, s (`/proc/self/schedstat`, ns): unlike wall time it
/// does not grow when other processes share the cores.
fn cpu_s() -> f64 {
    std::fs::read_to_string("/proc/self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|ns| ns.parse::<f64>().ok()))
        .map_or(f64::NAN, |ns| ns * 1e-9)
}

fn peak_rss_mib() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// The measured work: stream-decode the file, calibrate. Prints one line:
/// `samples wall_decode_s wall_total_s cpu_decode_s cpu_total_s peak_mib`.
fn child(path: &Path) {
    let (t0, c0) = (Instant::now(), cpu_s());
    let cap = capture::decode_reader(std::fs::File::open(path).expect("open capture")).expect("read capture");
    let (t_decode, c_decode) = (t0.elapsed().as_secs_f64(), cpu_s() - c0);
    let samples: usize = cap.runs.iter().map(|r| r.samples.len()).sum();
    let report = calib::calibrate(&cap.runs, &calib::CalOptions::default()).expect("calibrates");
    let (t_total, c_total) = (t0.elapsed().as_secs_f64(), cpu_s() - c0);
    std::hint::black_box(&report);
    println!("{samples} {t_decode} {t_total} {c_decode} {c_total} {}", peak_rss_mib());
}

/// The whole of `host calibrate`: decode, then the closed loop (fit, diagnostics, effect
/// selection). Prints `wall_s cpu_s peak_mib`.
fn child_loop(path: &Path) {
    let (t0, c0) = (Instant::now(), cpu_s());
    let cap = capture::decode_reader(std::fs::File::open(path).expect("open capture")).expect("read capture");
    let lr = calib::close_loop(&cap.runs, &calib::LoopOptions::default(), None).expect("calibrates");
    std::hint::black_box(&lr);
    println!("{} {} {}", t0.elapsed().as_secs_f64(), cpu_s() - c0, peak_rss_mib());
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let path = data_path();
    if let Ok(p) = std::env::var("THROUGHPUT_CHILD") {
        child(Path::new(&p));
        return;
    }
    if let Ok(p) = std::env::var("THROUGHPUT_CHILD_LOOP") {
        child_loop(Path::new(&p));
        return;
    }
    if !path.exists() {
        let t = Instant::now();
        let cfg = sim::SimConfig::standard(7, RUN_S);
        let mut f = std::io::BufWriter::new(std::fs::File::create(&path).expect("create"));
        sim::simulate_to(&cfg, &mut f).expect("simulate");
        drop(f);
        eprintln!("simulated {} in {:.1} s", path.display(), t.elapsed().as_secs_f64());
    }
    let size_mib = std::fs::metadata(&path).expect("capture").len() as f64 / (1 << 20) as f64;
    let exe = std::env::current_exe().expect("own path");
    let mut decode_s = Vec::new();
    let mut total_s = Vec::new();
    let mut cpu_decode_s = Vec::new();
    let mut cpu_total_s = Vec::new();
    let mut peaks = Vec::new();
    let mut samples = 0usize;
    for _ in 0..REPEATS {
        let out = Command::new(&exe).env("THROUGHPUT_CHILD", &path).arg("--bench").output().expect("child runs");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let line = String::from_utf8_lossy(&out.stdout);
        let f: Vec<f64> = line.split_whitespace().map(|x| x.parse().expect("number")).collect();
        samples = f[0] as usize;
        decode_s.push(f[1]);
        total_s.push(f[2]);
        cpu_decode_s.push(f[3]);
        cpu_total_s.push(f[4]);
        peaks.push(f[5]);
    }
    let (d, t) = (median(decode_s.clone()), median(total_s.clone()));
    let (cd, ct) = (median(cpu_decode_s), median(cpu_total_s.clone()));
    println!("capture: {} ({size_mib:.1} MiB, {samples} samples, 2 poses × {RUN_S} s at 800 Hz)", path.display());
    println!("runs: {REPEATS}, one core, figures are medians");
    println!("read + decode:             {d:.3} s  ({:.2} M samples/s)", samples as f64 / d / 1e6);
    println!("read + decode + calibrate: {t:.3} s  ({:.2} M samples/s; bar ≥ 5)", samples as f64 / t / 1e6);
    println!("  wall, all runs (s): {:?}", total_s.iter().map(|x| (x * 1000.0).round() / 1000.0).collect::<Vec<_>>());
    println!("on-CPU time (not inflated by other processes on the machine):");
    println!("read + decode:             {cd:.3} s  ({:.2} M samples/s)", samples as f64 / cd / 1e6);
    println!("read + decode + calibrate: {ct:.3} s  ({:.2} M samples/s; bar ≥ 5)", samples as f64 / ct / 1e6);
    println!(
        "  cpu, all runs (s): {:?}",
        cpu_total_s.iter().map(|x| (x * 1000.0).round() / 1000.0).collect::<Vec<_>>()
    );
    println!("peak resident memory: {:.0} MiB (median of {REPEATS})", median(peaks));

    // The full `host calibrate` (closed loop) on the same capture, for scale: three runs.
    let mut wall = Vec::new();
    let mut cpu = Vec::new();
    let mut peak = Vec::new();
    for _ in 0..3 {
        let out = Command::new(&exe).env("THROUGHPUT_CHILD_LOOP", &path).arg("--bench").output().expect("child runs");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let f: Vec<f64> =
            String::from_utf8_lossy(&out.stdout).split_whitespace().map(|x| x.parse().expect("number")).collect();
        wall.push(f[0]);
        cpu.push(f[1]);
        peak.push(f[2]);
    }
    let (w, c) = (median(wall), median(cpu));
    println!(
        "closed loop (decode + fit + diagnostics + effect selection, what `host calibrate` runs): {w:.2} s wall, \
         {c:.2} s on-CPU ({:.2} M samples/s), peak {:.0} MiB (median of 3)",
        samples as f64 / c / 1e6,
        median(peak)
    );
}
