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

fn peak_rss_mib() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// The measured work: read, decode, calibrate. Prints one line `samples seconds peak_mib`.
fn child(path: &Path) {
    let t0 = Instant::now();
    let bytes = std::fs::read(path).expect("read capture");
    let cap = capture::decode(&bytes);
    drop(bytes);
    let t_decode = t0.elapsed().as_secs_f64();
    let samples: usize = cap.runs.iter().map(|r| r.samples.len()).sum();
    let report = calib::calibrate(&cap.runs, &calib::CalOptions::default()).expect("calibrates");
    let t_total = t0.elapsed().as_secs_f64();
    std::hint::black_box(&report);
    println!("{samples} {t_decode} {t_total} {}", peak_rss_mib());
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
    let mut peaks = Vec::new();
    let mut samples = 0usize;
    for _ in 0..REPEATS {
        let out = Command::new(&exe)
            .env("THROUGHPUT_CHILD", &path)
            .arg("--bench")
            .output()
            .expect("child runs");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let line = String::from_utf8_lossy(&out.stdout);
        let f: Vec<f64> = line.split_whitespace().map(|x| x.parse().expect("number")).collect();
        samples = f[0] as usize;
        decode_s.push(f[1]);
        total_s.push(f[2]);
        peaks.push(f[3]);
    }
    let (d, t) = (median(decode_s.clone()), median(total_s.clone()));
    println!("capture: {} ({size_mib:.1} MiB, {samples} samples, 2 poses × {RUN_S} s at 800 Hz)", path.display());
    println!("runs: {REPEATS}, one core, figures are medians");
    println!("read + decode:             {d:.3} s  ({:.2} M samples/s)", samples as f64 / d / 1e6);
    println!("read + decode + calibrate: {t:.3} s  ({:.2} M samples/s; bar ≥ 5)", samples as f64 / t / 1e6);
    println!("  all runs (s): {:?}", total_s.iter().map(|x| (x * 1000.0).round() / 1000.0).collect::<Vec<_>>());
    println!("peak resident memory: {:.0} MiB (median of {REPEATS})", median(peaks));
}
