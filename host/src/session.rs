//! The guided live session: identify the rig, then for every planned run start it, record its
//! raw bytes to its own capture file, stop it. Calibration then replays those files, so the live
//! and the replay paths compute from exactly the same bytes.

use crate::geometry::Pose;
use crate::link::Link;
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use protocol::{Command, Direction, Fault, GyroConfig, Hello, RigMsg, StartRun, PROTOCOL_VERSION};
use std::fs::File;
use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// One run of a session.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunPlan {
    /// Pose the operator must mount.
    pub pose: Pose,
    /// Base-table rate, °/s, signed by direction.
    pub rate_dps: f64,
    /// Seconds of data to record once at speed.
    pub duration_s: f64,
}

impl RunPlan {
    /// File name of the run's capture, e.g. `pose1-p180dps.cap`.
    pub fn file_name(&self) -> String {
        let sign = if self.rate_dps < 0.0 { 'm' } else { 'p' };
        format!("pose{}-{sign}{:.0}dps.cap", self.pose.number(), self.rate_dps.abs())
    }

    fn start(&self) -> StartRun {
        StartRun {
            rate_mdps: (self.rate_dps.abs() * 1000.0).round() as u32,
            direction: if self.rate_dps < 0.0 { Direction::Cw } else { Direction::Ccw },
            run_tag: self.pose.run_tag(),
        }
    }
}

/// Every pose × rate combination, grouped by pose so the operator remounts once per pose.
pub fn plan(poses: &[Pose], rates_dps: &[f64], duration_s: f64) -> Vec<RunPlan> {
    poses
        .iter()
        .flat_map(|&pose| rates_dps.iter().map(move |&rate_dps| RunPlan { pose, rate_dps, duration_s }))
        .collect()
}

/// How long the rig may take to reach speed.
const SPIN_UP_TIMEOUT: Duration = Duration::from_secs(20);
/// Without a sample for this long during a run, the gyro is declared silent.
const SAMPLE_TIMEOUT: Duration = Duration::from_secs(2);
/// How long to wait for RunStopped after Stop.
const STOP_TIMEOUT: Duration = Duration::from_secs(10);
/// Speed within this fraction of the setpoint counts as "at speed".
const AT_SPEED_TOLERANCE: f64 = 0.01;

/// Asks the rig who it is and checks it speaks our protocol.
pub fn identify<P: Read + Write>(link: &mut Link<P>) -> Result<Hello> {
    let mut hello = None;
    link.command(&Command::Identify, |m| {
        if let RigMsg::Hello(h) = m {
            hello = Some(*h)
        }
    })?;
    let Some(h) = hello else {
        bail!("the rig on {} acknowledged Identify but sent no Hello", link.name());
    };
    if h.protocol_version != PROTOCOL_VERSION {
        bail!(
            "the rig on {} speaks protocol v{}, this host v{PROTOCOL_VERSION}: update one of them",
            link.name(),
            h.protocol_version
        );
    }
    Ok(h)
}

/// Sets the gyro (only between runs).
pub fn configure<P: Read + Write>(link: &mut Link<P>, gyro: GyroConfig) -> Result<()> {
    link.command(&Command::ConfigureGyro(gyro), |_| {})
}

/// Waits for the operator to press Enter, unless `assume_yes`.
pub fn prompt(message: &str, assume_yes: bool) -> Result<()> {
    eprintln!("{message}");
    if assume_yes {
        return Ok(());
    }
    eprint!("Press Enter when ready (Ctrl-C to abort) ");
    let mut line = String::new();
    std::io::stdin().lock().read_line(&mut line).context("reading the operator's answer")?;
    Ok(())
}

/// How the operator mounts a pose (EXCITER.md, eq. 8-10).
pub fn mounting_instructions(pose: Pose) -> &'static str {
    match pose {
        Pose::One => {
            "Mount the gyro in POSE 1: on the 54.74° wedge (α = φ), package turned 45° about its z axis (γ = 45°)."
        }
        Pose::Two => "Mount the gyro in POSE 2: pose 1 turned −90° about the sensor table's y axis (R2 = Ry(−90°)·R1).",
    }
}

/// Creates a capture file; an existing file is an error, so no recording is ever overwritten.
pub fn create_capture(path: &Path) -> Result<File> {
    File::options()
        .write(true)
        .create_new(true)
        .open(path)
        .with_context(|| format!("cannot create capture {}", path.display()))
}

/// Records one run into `path` (created; an existing file is never overwritten). Every byte the
/// rig sends from the Identify on is written and flushed before it is decoded.
pub fn record_run<P: Read + Write>(
    link: &mut Link<P>,
    run: &RunPlan,
    path: &Path,
    progress: &ProgressBar,
    interrupted: &AtomicBool,
) -> Result<()> {
    link.record_to(Some(Box::new(create_capture(path)?)))?;
    let outcome = stream_run(link, run, path, progress, interrupted);
    if outcome.is_err() {
        // Best effort: the motor must not keep spinning because the host gave up.
        let _ = link.send(&Command::Stop);
        let deadline = Instant::now() + Duration::from_millis(500);
        while Instant::now() < deadline {
            if link.poll(|_| {}).is_err() {
                break;
            }
        }
    }
    link.record_to(None)?;
    outcome
}

fn stream_run<P: Read + Write>(
    link: &mut Link<P>,
    run: &RunPlan,
    path: &Path,
    progress: &ProgressBar,
    interrupted: &AtomicBool,
) -> Result<()> {
    let where_ = format!("{} (capture kept in {})", run_label(run), path.display());
    let hello = identify(link)?;
    let target_cps = f64::from(run.start().rate_mdps) / 1000.0 / 360.0 * f64::from(hello.encoder_counts_per_rev);
    link.command(&Command::Start(run.start()), |_| {})?;
    progress.set_style(bar_style());
    progress.set_length((run.duration_s * 10.0).round() as u64);
    progress.set_position(0);
    progress.set_message(format!("{}: spinning up", run_label(run)));

    let started = Instant::now();
    let mut last_sample = Instant::now();
    let mut clock = RigClock::default();
    let mut at_speed_since_us: Option<i64> = None;
    let mut now_us = 0i64;
    let mut fault: Option<Fault> = None;
    let mut stopped_early = false;
    loop {
        if interrupted.load(Ordering::SeqCst) {
            bail!("interrupted during {where_}");
        }
        link.keep_alive()?;
        link.poll(|m| match m {
            RigMsg::Sample(s) => {
                now_us = clock.unwrap(s.t_us);
                last_sample = Instant::now();
            }
            RigMsg::Motor(ms) => {
                let t = clock.unwrap(ms.t_us);
                let setpoint = f64::from(ms.setpoint_cps);
                let ramp_done = (setpoint.abs() - target_cps).abs() <= target_cps * AT_SPEED_TOLERANCE;
                let at_speed = (f64::from(ms.speed_cps) - setpoint).abs() <= setpoint.abs() * AT_SPEED_TOLERANCE;
                if at_speed_since_us.is_none() && ramp_done && at_speed {
                    at_speed_since_us = Some(t);
                }
            }
            RigMsg::Fault(f) => fault = Some(f.fault),
            RigMsg::RunStopped(_) => stopped_early = true,
            _ => {}
        })?;
        if let Some(f) = fault {
            bail!("the rig reported {f:?} during {where_}");
        }
        if stopped_early {
            bail!("the rig stopped the run by itself during {where_}");
        }
        if last_sample.elapsed() > SAMPLE_TIMEOUT {
            bail!(
                "the gyro does not answer: no sample from {} for {} s during {where_}",
                link.name(),
                SAMPLE_TIMEOUT.as_secs()
            );
        }
        match at_speed_since_us {
            None if started.elapsed() > SPIN_UP_TIMEOUT => {
                bail!("the table did not reach speed within {} s during {where_}", SPIN_UP_TIMEOUT.as_secs())
            }
            None => {}
            Some(t0) => {
                let recorded_s = (now_us - t0) as f64 * 1e-6;
                progress.set_message(format!("{}: recording", run_label(run)));
                progress.set_position((recorded_s.max(0.0) * 10.0) as u64);
                if recorded_s >= run.duration_s {
                    break;
                }
            }
        }
    }
    let mut stopped = false;
    link.command(&Command::Stop, |m| stopped |= matches!(m, RigMsg::RunStopped(_)))?;
    let deadline = Instant::now() + STOP_TIMEOUT;
    while !stopped {
        if Instant::now() > deadline {
            bail!("the rig did not confirm the stop within {} s during {where_}", STOP_TIMEOUT.as_secs());
        }
        link.poll(|m| stopped |= matches!(m, RigMsg::RunStopped(_)))?;
    }
    progress.finish_with_message(format!("{}: done", run_label(run)));
    Ok(())
}

fn run_label(run: &RunPlan) -> String {
    format!("{}, {:+.1} °/s", run.pose, run.rate_dps)
}

fn bar_style() -> ProgressStyle {
    ProgressStyle::with_template("{msg:32} [{bar:40}] {pos:>5}/{len:5} (0.1 s of rig time)")
        .expect("valid template")
        .progress_chars("=> ")
}

/// Unwraps the rig's 32-bit µs clock for progress display.
#[derive(Default)]
struct RigClock {
    last: Option<u32>,
    now: i64,
}

impl RigClock {
    fn unwrap(&mut self, t_us: u32) -> i64 {
        if let Some(last) = self.last {
            let d = i64::from(t_us.wrapping_sub(last) as i32);
            if d > 0 {
                self.now += d;
                self.last = Some(t_us);
            }
            return self.now + d.min(0);
        }
        self.last = Some(t_us);
        0
    }
}

/// Where each run of a session is saved: `<dir>/<file_name>`.
pub fn capture_paths(dir: &Path, runs: &[RunPlan]) -> Vec<PathBuf> {
    runs.iter().map(|r| dir.join(r.file_name())).collect()
}

/// Records a whole session; returns the capture files written.
pub fn record_session<P: Read + Write>(
    link: &mut Link<P>,
    runs: &[RunPlan],
    dir: &Path,
    assume_yes: bool,
    interrupted: &AtomicBool,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let paths = capture_paths(dir, runs);
    if let Some(existing) = paths.iter().find(|p| p.exists()) {
        bail!("{} already exists: choose another --out-dir, captures are never overwritten", existing.display());
    }
    let mut mounted = None;
    for (run, path) in runs.iter().zip(&paths) {
        if mounted != Some(run.pose) {
            prompt(mounting_instructions(run.pose), assume_yes)?;
            mounted = Some(run.pose);
        }
        // indicatif draws on stderr only when it is a terminal.
        let progress = ProgressBar::new(0);
        record_run(link, run, path, &progress, interrupted)?;
        eprintln!("saved {}", path.display());
    }
    let _ = std::io::stderr().flush();
    Ok(paths)
}
