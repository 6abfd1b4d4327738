//! The guided live session: identify the rig, then for every planned run start it, record its
//! raw bytes to its own capture file, stop it. Calibration then replays those files, so the live
//! and the replay paths compute from exactly the same bytes.

use crate::geometry::Pose;
use crate::link::Link;
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use protocol::{
    timing, units, CmdResult, Command, DriveConfig, Fault, GyroConfig, Hello, RigMsg, StartRun, PROTOCOL_VERSION,
};
use std::fs::File;
use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

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
    /// A static run (motor off) of `duration_s` in `pose`: a Start at 0 °/s
    /// ([`StartRun::static_run`]), for noise figures.
    pub fn static_run(pose: Pose, duration_s: f64) -> Self {
        Self { pose, rate_dps: 0.0, duration_s }
    }

    /// Whether the motor stays off.
    pub fn is_static(&self) -> bool {
        self.rate_dps == 0.0
    }

    /// File name of the run's capture, e.g. `pose1-p180dps.cap`, `pose2-static.cap`.
    pub fn file_name(&self) -> String {
        if self.is_static() {
            return format!("pose{}-static.cap", self.pose.number());
        }
        let sign = if self.rate_dps < 0.0 { 'm' } else { 'p' };
        format!("pose{}-{sign}{:.0}dps.cap", self.pose.number(), self.rate_dps.abs())
    }

    fn start(&self) -> StartRun {
        StartRun {
            rate_mdps: units::mdps_from_dps(self.rate_dps),
            direction: units::direction_of(self.rate_dps),
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

/// `plan` plus, with `static_s`, a static run of that many seconds at the end, in the pose
/// mounted last (no remounting; the gyro has warmed up with the runs before it).
pub fn plan_with_static(poses: &[Pose], rates_dps: &[f64], duration_s: f64, static_s: Option<f64>) -> Vec<RunPlan> {
    let mut runs = plan(poses, rates_dps, duration_s);
    if let (Some(s), Some(&last)) = (static_s, poses.last()) {
        runs.push(RunPlan::static_run(last, s));
    }
    runs
}

const fn ms(v: u32) -> Duration {
    Duration::from_millis(v as u64)
}
/// How long the rig may take to reach speed.
const SPIN_UP_TIMEOUT: Duration = ms(timing::SPIN_UP_TIMEOUT_MS);
/// Without a sample for this long during a run (while other frames arrive), the gyro is silent.
const SAMPLE_TIMEOUT: Duration = ms(timing::SAMPLE_TIMEOUT_MS);
/// How long to wait for the motor to stop after the Stop is acknowledged.
const STOP_TIMEOUT: Duration = ms(timing::STOP_TIMEOUT_MS);
/// Speed within this fraction of the setpoint counts as "at speed".
const AT_SPEED_TOLERANCE: f64 = 0.01;

/// Asks the rig who it is and checks it speaks our protocol. Faults the rig reports with its
/// `Hello` (a watchdog reset, a gyro fault in force) are shown as warnings.
pub fn identify<P: Read + Write>(link: &mut Link<P>) -> Result<Hello> {
    let mut hello = None;
    let mut faults = Vec::new();
    // The Hello itself may be lost on the way while the Ack arrives: ask again.
    for _ in 0..timing::COMMAND_ATTEMPTS {
        link.command(&Command::Identify, |m| match m {
            RigMsg::Hello(h) => hello = Some(*h),
            RigMsg::Fault(f) => faults.push(f.fault),
            _ => {}
        })?;
        if hello.is_some() {
            break;
        }
    }
    faults.dedup();
    for f in faults {
        eprintln!("warning: the rig on {} reports {}", link.name(), describe_fault(f));
    }
    let Some(h) = hello else {
        bail!(
            "the rig on {} acknowledged Identify {} times but no Hello came through: the link loses frames",
            link.name(),
            timing::COMMAND_ATTEMPTS
        );
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

/// A fault in words, for the operator.
pub fn describe_fault(f: Fault) -> String {
    match f {
        Fault::WatchdogReset => "WatchdogReset: its last restart was forced by the watchdog (the firmware hung)".into(),
        Fault::GyroAbsent { who_am_i } => format!("GyroAbsent: the gyro answers WHO_AM_I {who_am_i:#04x}, not 0xd3"),
        Fault::GyroSpi => "GyroSpi: reads from the gyro keep failing".into(),
        Fault::GyroSilent => "GyroSilent: the gyro stopped signalling data-ready".into(),
        Fault::HostLinkLost => "HostLinkLost: it heard nothing from this host for 2 s and cut the drive".into(),
        Fault::Stall => "Stall: the table did not move while driven".into(),
        Fault::OverSpeed => "OverSpeed".into(),
    }
}

/// `Motor.faults` bits in words, for the operator.
pub fn describe_motor_faults(bits: u8) -> String {
    use protocol::motor_faults as mf;
    let names: Vec<&str> = [
        (mf::STALL, "Stall"),
        (mf::OVER_SPEED, "OverSpeed"),
        (mf::HOST_LINK_LOST, "HostLinkLost"),
        (mf::INTERLOCK, "Interlock: a gyro or watchdog fault"),
    ]
    .into_iter()
    .filter(|(bit, _)| bits & bit != 0)
    .map(|(_, name)| name)
    .collect();
    if names.is_empty() {
        "no fault bit set".into()
    } else {
        format!("fault bits {bits:#04x}: {}", names.join(", "))
    }
}

/// Sets the gyro (only between runs).
pub fn configure<P: Read + Write>(link: &mut Link<P>, gyro: GyroConfig) -> Result<()> {
    link.command(&Command::ConfigureGyro(gyro), |_| {})
}

/// Tells the rig the drive train its speed loop must be designed for (until it resets).
pub fn configure_drive<P: Read + Write>(link: &mut Link<P>, drive: DriveConfig) -> Result<()> {
    let what = format!(
        "{}:1 gearhead, {} kg·m² of load, {} V",
        f64::from(drive.gear_ratio_milli) / 1e3,
        f64::from(drive.load_inertia_gcm2) / 1e7,
        f64::from(drive.supply_mv) / 1e3
    );
    match link.request(&Command::ConfigureDrive(drive), |_| {})?.result {
        CmdResult::Ok => Ok(()),
        CmdResult::InvalidArgument if drive.in_limits() => bail!(
            "the rig on {} refused the drive ({what}): at full duty it would not exceed the rig's over-speed limit, so a runaway would go unnoticed (a lower ratio or a higher supply)",
            link.name()
        ),
        CmdResult::InvalidArgument => bail!(
            "the rig on {} refused the drive ({what}): outside the protocol's limits (ratio 1 to 500, load 0.0001 to 1 kg·m², supply 6 to 48 V)",
            link.name()
        ),
        CmdResult::Busy => bail!("the rig on {} refused the drive: a run is in progress (stop it first)", link.name()),
        r => bail!("the rig on {} refused the drive ({what}): {r:?}", link.name()),
    }
}

/// What the operator said at a prompt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reply {
    /// Ready (Enter).
    Ready,
    /// Standard input ended (or failed): nobody is there to mount the gyro.
    EndOfInput,
}

/// The person at the rig: asked to do something, answers some time later. The session keeps
/// reading the port meanwhile, so polling must not block.
pub trait Operator {
    /// Asks (`message` says what to do); `now` is the link's time.
    fn ask(&mut self, message: &str, now: Duration);
    /// The answer, once there is one.
    fn reply(&mut self, now: Duration) -> Option<Reply>;
}

/// `--yes`: a scripted rig mounts by itself; every prompt is answered at once.
pub struct AssumeYes;

impl Operator for AssumeYes {
    fn ask(&mut self, message: &str, _now: Duration) {
        eprintln!("{message}");
    }
    fn reply(&mut self, _now: Duration) -> Option<Reply> {
        Some(Reply::Ready)
    }
}

/// A person at the terminal: standard input read line by line on a thread of its own, so the
/// session can drain the port and notice Ctrl-C while waiting.
pub struct Terminal {
    lines: mpsc::Receiver<Reply>,
}

impl Terminal {
    /// Starts reading standard input.
    pub fn new() -> Self {
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            let mut stdin = std::io::stdin().lock();
            loop {
                let mut line = String::new();
                let reply = match stdin.read_line(&mut line) {
                    Ok(0) | Err(_) => Reply::EndOfInput,
                    Ok(_) => Reply::Ready,
                };
                if tx.send(reply).is_err() || reply == Reply::EndOfInput {
                    return;
                }
            }
        });
        Self { lines }
    }
}

impl Default for Terminal {
    fn default() -> Self {
        Self::new()
    }
}

impl Operator for Terminal {
    fn ask(&mut self, message: &str, _now: Duration) {
        // A line typed before the question is not an answer to it.
        while self.lines.try_recv() == Ok(Reply::Ready) {}
        eprintln!("{message}");
        eprint!("Press Enter when ready (Ctrl-C to abort) ");
        let _ = std::io::stderr().flush();
    }
    fn reply(&mut self, _now: Duration) -> Option<Reply> {
        match self.lines.try_recv() {
            Ok(r) => Some(r),
            Err(mpsc::TryRecvError::Empty) => None,
            Err(mpsc::TryRecvError::Disconnected) => Some(Reply::EndOfInput),
        }
    }
}

/// Asks the operator and waits for the answer, reading the port all the while so the rig's
/// queue never fills (its idle stream is ≈ 18 kB/s), and reporting any fault the rig raises
/// meanwhile. Ctrl-C (or SIGTERM/SIGHUP) aborts within one port timeout, after a `Stop`.
pub fn prompt<P: Read + Write>(
    link: &mut Link<P>,
    message: &str,
    operator: &mut dyn Operator,
    interrupted: &AtomicBool,
) -> Result<()> {
    operator.ask(message, link.now());
    loop {
        if interrupted.load(Ordering::SeqCst) {
            // The motor is off between runs, but a Stop costs nothing and covers a rig that
            // disagrees.
            let _ = link.send(&Command::Stop);
            eprintln!();
            bail!("interrupted at the prompt; the rig was sent Stop");
        }
        let mut faults = Vec::new();
        link.poll(|m| {
            if let RigMsg::Fault(f) = m {
                faults.push(f.fault)
            }
        })?;
        for f in faults {
            eprintln!("warning: the rig on {} reported {f:?} while idle", link.name());
        }
        match operator.reply(link.now()) {
            None => {}
            Some(Reply::Ready) => return Ok(()),
            Some(Reply::EndOfInput) => {
                eprintln!();
                bail!("standard input ended at the prompt: nobody confirmed the mounting (use --yes for a rig that mounts by itself)")
            }
        }
    }
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
/// rig sends from the Identify on is written and flushed before it is decoded. On any failure
/// or interrupt the rig is sent `Stop` and what arrives in the next moments is still recorded.
pub fn record_run<P: Read + Write>(
    link: &mut Link<P>,
    run: &RunPlan,
    path: &Path,
    progress: &ProgressBar,
    interrupted: &AtomicBool,
) -> Result<()> {
    link.record_to_named(Some(Box::new(create_capture(path)?)), path.display().to_string())?;
    let outcome = stream_run(link, run, path, progress, interrupted);
    if outcome.is_err() {
        // The motor must not keep spinning because the host gave up, nor coast because it left:
        // the rig trips `HostLinkLost` 2 s after the last host frame, and a ramp-down lasts up
        // to 4 s. So: `Stop`, then heartbeats until the rig says the table has stopped.
        if let Err(e) = wait_stopped(link, run.start().run_tag) {
            let _ = writeln!(std::io::stderr(), "warning: {e:#}");
        }
    }
    link.record_to(None)?;
    outcome
}

/// After a failed or interrupted run: sends `Stop` and keeps reading (and recording) and
/// heartbeating until the rig reports the run over (`RunStopped` of `tag`, or a `Motor` report
/// without the tag), sending `Stop` again every second until it is acknowledged, for at most
/// [`STOP_TIMEOUT`] (the protocol's bound on a ramp-down's
/// confirmation). A `Stop` while idle is harmless; an idle rig's next `Motor` report (100 ms)
/// ends the wait. Errors say why the stop was not confirmed.
fn wait_stopped<P: Read + Write>(link: &mut Link<P>, tag: u8) -> Result<()> {
    let deadline = link.now() + STOP_TIMEOUT;
    let mut last_stop: Option<(u16, Duration)> = None;
    let (mut acked, mut stopped) = (false, false);
    while !stopped {
        // Again every ACK_TIMEOUT until the rig acknowledges it: a `Stop` lost on the line must
        // not leave the table at speed (`Stop` is idempotent).
        if !acked && last_stop.is_none_or(|(_, t)| link.now().saturating_sub(t) >= crate::link::ACK_TIMEOUT) {
            let seq = link.send(&Command::Stop).context("sending Stop")?;
            last_stop = Some((seq, link.now()));
        }
        if link.now() > deadline {
            bail!(
                "the rig on {} did not report the table stopped within {} s of the Stop",
                link.name(),
                STOP_TIMEOUT.as_secs()
            );
        }
        link.keep_alive().context("heartbeating the ramp-down")?;
        let stop_seq = last_stop.map(|(seq, _)| seq);
        link.poll(|m| match m {
            RigMsg::RunStopped(r) if r.run_tag == tag => stopped = true,
            RigMsg::Motor(ms) if ms.run_tag != tag => stopped = true,
            RigMsg::Ack(a) if Some(a.cmd_seq) == stop_seq => acked = true,
            _ => {}
        })
        .context("waiting for the table to stop")?;
    }
    Ok(())
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
    let target_cps = units::counts_from_deg(units::dps_from_mdps(run.start().rate_mdps), hello.encoder_counts_per_rev);
    let tag = run.start().run_tag;
    let mut started = false;
    let answer = link.request(&Command::Start(run.start()), |m| {
        started |= matches!(m, RigMsg::RunStarted(r) if r.run_tag == tag)
            || matches!(m, RigMsg::Motor(ms) if ms.run_tag == tag);
    })?;
    match answer.result {
        CmdResult::Ok => {}
        // The first attempt started the run and its Ack was lost.
        CmdResult::Busy if answer.attempts > 1 && started => {}
        r => bail!("the rig on {} refused Start: {r:?} during {where_}", link.name()),
    }
    progress.set_style(bar_style());
    progress.set_length((run.duration_s * 10.0).round() as u64);
    progress.set_position(0);
    // A static run is "at speed" once the rig reports the table at rest (setpoint and speed 0).
    let waiting = if run.is_static() { "waiting for the table at rest" } else { "spinning up" };
    progress.set_message(format!("{}: {waiting}", run_label(run)));

    let t_start = link.now();
    let mut last_sample = link.now();
    let mut clock = RigClock::default();
    let mut at_speed_since_us: Option<i64> = None;
    let mut now_us = 0i64;
    let mut fault: Option<Fault> = None;
    let mut stopped_early = false;
    // A trip whose `Fault` and `RunStopped` frames were both lost still shows in the 10 Hz
    // `Motor` reports: after the `Ack` of the `Start` every report of this run carries its tag
    // and no fault bit (the rig clears them at `Start`), so a report without the tag, or with a
    // fault bit, means the rig ended the run by itself.
    let mut motor_ended: Option<u8> = None;
    loop {
        if interrupted.load(Ordering::SeqCst) {
            bail!("interrupted during {where_}");
        }
        link.keep_alive()?;
        let mut sampled = false;
        link.poll(|m| match m {
            RigMsg::Sample(s) => {
                now_us = clock.unwrap(s.t_us);
                sampled = true;
            }
            RigMsg::Motor(ms) => {
                if ms.run_tag != tag || ms.faults != 0 {
                    motor_ended.get_or_insert(ms.faults);
                }
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
        if sampled {
            last_sample = link.now();
        }
        if let Some(f) = fault {
            bail!("the rig reported {} during {where_}", describe_fault(f));
        }
        if stopped_early {
            bail!("the rig stopped the run by itself during {where_}");
        }
        if let Some(bits) = motor_ended {
            bail!(
                "the rig's motor reports show the run ended by the rig ({}) during {where_}; its Fault and RunStopped frames were lost",
                describe_motor_faults(bits)
            );
        }
        if link.now().saturating_sub(last_sample) > SAMPLE_TIMEOUT {
            bail!(
                "the gyro does not answer: the rig on {} sends frames but no sample for {} s during {where_}",
                link.name(),
                SAMPLE_TIMEOUT.as_secs_f64()
            );
        }
        match at_speed_since_us {
            None if link.now().saturating_sub(t_start) > SPIN_UP_TIMEOUT => {
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
    progress.set_message(format!("{}: stopping", run_label(run)));
    stop_run(link, tag, interrupted).with_context(|| format!("stopping {where_}"))?;
    progress.finish_with_message(format!("{}: done", run_label(run)));
    Ok(())
}

/// Sends `Stop` and waits for the motor to stop, heartbeating all along: the ramp-down lasts up
/// to 4 s, longer than the rig's 2 s link timeout. The stop is confirmed by `RunStopped`, or, if
/// that frame was lost, by a `Motor` status that no longer carries the run's tag. A fault during
/// the ramp-down (a `HostLinkLost` trip included) is an error, not a clean stop.
fn stop_run<P: Read + Write>(link: &mut Link<P>, tag: u8, interrupted: &AtomicBool) -> Result<()> {
    let stopped = std::cell::Cell::new(false);
    let fault = std::cell::Cell::new(None);
    let motor_faults = std::cell::Cell::new(0u8);
    let watch = |m: &RigMsg| match m {
        RigMsg::RunStopped(r) if r.run_tag == tag => stopped.set(true),
        RigMsg::Motor(ms) if ms.faults != 0 => motor_faults.set(ms.faults),
        RigMsg::Motor(ms) if ms.run_tag == 0 => stopped.set(true),
        RigMsg::Fault(f) => fault.set(Some(f.fault)),
        _ => {}
    };
    link.command(&Command::Stop, watch)?;
    let deadline = link.now() + STOP_TIMEOUT;
    loop {
        if let Some(f) = fault.get() {
            bail!("the rig reported {} while ramping down", describe_fault(f));
        }
        if motor_faults.get() != 0 {
            bail!(
                "the rig's motor reports show a trip ({}) while ramping down; its Fault frame was lost",
                describe_motor_faults(motor_faults.get())
            );
        }
        if stopped.get() {
            return Ok(());
        }
        if interrupted.load(Ordering::SeqCst) {
            bail!("interrupted while the table ramps down");
        }
        if link.now() > deadline {
            bail!("the rig did not confirm the stop within {} s", STOP_TIMEOUT.as_secs());
        }
        link.keep_alive()?;
        link.poll(watch)?;
    }
}

fn run_label(run: &RunPlan) -> String {
    if run.is_static() {
        return format!("{}, static (motor off)", run.pose);
    }
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
    operator: &mut dyn Operator,
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
            prompt(link, mounting_instructions(run.pose), operator, interrupted)?;
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
