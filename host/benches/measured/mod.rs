//! What the benchmarks share: where their data lives, and running one child process with the
//! kernel's accounting of that child alone (`wait4`), so neither the bench itself nor anything
//! else on the machine counts in its CPU time and peak memory. [`replay`] simulates, calibrates
//! and reads back (the accuracy benches); [`trust`] is the trust matrix's arithmetic; [`remix`]
//! makes another sensor of an independent capture (`validation_remix`). Their
//! unit tests run in the `bench_measured` test target (`cargo test -p host --test
//! bench_measured`): a `harness = false` bench runs its `main`, never its `#[test]`s.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

// Each bench uses its own part of these (`throughput` only `replay::captures_in`).
#[allow(dead_code)]
pub mod remix;
#[allow(dead_code)]
pub mod replay;
#[allow(dead_code)]
pub mod trust;

/// One child's figures.
pub struct Usage {
    /// Exit status (−1 when it did not exit normally).
    pub code: i32,
    /// Wall time from spawn to reaping, s.
    pub wall_s: f64,
    /// User + system CPU time of the child, s.
    pub cpu_s: f64,
    /// Peak resident set of the child, MiB.
    #[allow(dead_code)] // read by `throughput` only
    pub peak_mib: f64,
}

/// `target/bench-data/<sub>`, created.
pub fn bench_dir(sub: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/bench-data").join(sub);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("create {}: {e}", dir.display()));
    dir
}

/// Spawns `cmd` and reaps it with `wait4`, which hands back that child's own resource usage;
/// std's `Child::wait` cannot replace it: it drops the usage.
pub fn run_measured(mut cmd: Command) -> Result<Usage, String> {
    let t = Instant::now();
    // Reaped by the `wait4` below.
    #[allow(clippy::zombie_processes)]
    let child = cmd.spawn().map_err(|e| format!("{:?}: {e}", cmd.get_program()))?;
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: an all-zero `rusage` is a valid value of the plain C struct.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `pid` is our own child, not yet waited for (`child` is never waited on or killed
    // through std after this); `status` and `usage` are valid for writes.
    let got = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    let wall_s = t.elapsed().as_secs_f64();
    if got != pid {
        return Err(format!("wait4: {}", std::io::Error::last_os_error()));
    }
    let code = if libc::WIFEXITED(status) { libc::WEXITSTATUS(status) } else { -1 };
    Ok(Usage {
        code,
        wall_s,
        cpu_s: cpu_s(&usage),
        // Linux reports ru_maxrss in KiB.
        peak_mib: usage.ru_maxrss as f64 / 1024.0,
    })
}

/// The median (NaN of nothing).
pub fn median(v: Vec<f64>) -> f64 {
    statrs::statistics::OrderStatistics::median(&mut statrs::statistics::Data::new(v))
}

/// CPU time (user + system) of every child of this process that has been waited for, s.
#[allow(dead_code)] // read by `trust_matrix` only
pub fn children_cpu_s() -> f64 {
    // SAFETY: an all-zero `rusage` is a valid value of the plain C struct.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `usage` is valid for writes; RUSAGE_CHILDREN is a valid `who`.
    let got = unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage) };
    if got != 0 {
        return f64::NAN;
    }
    cpu_s(&usage)
}

/// User + system time of a `rusage`, s.
fn cpu_s(usage: &libc::rusage) -> f64 {
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    secs(usage.ru_utime) + secs(usage.ru_stime)
}
