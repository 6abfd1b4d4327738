//! The host's live session against the firmware's virtual rig on a pty, in lockstep (simulated
//! time, never the wall clock): each test reproduces one defect of issue 8 that a perfect,
//! instantly answered link hid.

use e2e::{assert_matches_virtual_gyro, LockstepRig};
use host::calib::{self, CalOptions};
use host::capture::{self, Capture};
use host::geometry::Pose;
use host::link::{Clock, Link};
use host::session::{self, Operator, Reply, RunPlan};
use protocol::frame::decode_frame;
use protocol::{Command, Fault, MAX_FRAME_LEN};
use std::cell::RefCell;
use std::io::{Read, Write};
use std::path::PathBuf;
use std::rc::Rc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// The host's side of the pty, watched: every command it sends is decoded and kept, and after
/// `mute_after_stop` nothing more reaches the rig (a cable pulled right after `Stop`).
struct Spy {
    rig: LockstepRig,
    sent: Rc<RefCell<Vec<Command>>>,
    partial: Vec<u8>,
    mute_after_stop: bool,
    muted: bool,
}

impl Read for Spy {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.rig.read(buf)
    }
}

impl Write for Spy {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.muted {
            return Ok(buf.len());
        }
        let n = self.rig.write(buf)?;
        for &b in &buf[..n] {
            self.partial.push(b);
            if b == 0 {
                let frame = std::mem::take(&mut self.partial);
                let mut scratch = [0u8; MAX_FRAME_LEN];
                let (_, cmd) = decode_frame::<Command>(&frame[..frame.len() - 1], &mut scratch).expect("host frame");
                self.muted |= self.mute_after_stop && cmd == Command::Stop;
                self.sent.borrow_mut().push(cmd);
            }
        }
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.rig.flush()
    }
}

struct Bench {
    link: Link<Spy>,
    clock: e2e::SimClock,
    sent: Rc<RefCell<Vec<Command>>>,
    dir: PathBuf,
}

fn bench(name: &str, args: &[&str]) -> Bench {
    bench_with(name, args, |c| Box::new(c))
}

/// [`bench`], the link's clock made from the rig's by `clock`.
fn bench_with(name: &str, args: &[&str], clock: impl FnOnce(e2e::SimClock) -> Box<dyn Clock>) -> Bench {
    let make_clock = clock;
    let rig = LockstepRig::spawn(env!("CARGO_BIN_EXE_virtual_rig"), args);
    let clock = rig.clock();
    let path = rig.path.clone();
    let sent = Rc::new(RefCell::new(Vec::new()));
    let spy = Spy { rig, sent: sent.clone(), partial: Vec::new(), mute_after_stop: false, muted: false };
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("live-session-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    Bench { link: Link::with_clock(spy, path, make_clock(clock.clone())), clock, sent, dir }
}

impl Bench {
    fn record(&mut self, run: &RunPlan) -> (anyhow::Result<()>, Capture) {
        let path = self.dir.join(run.file_name());
        let r =
            session::record_run(&mut self.link, run, &path, &indicatif::ProgressBar::hidden(), &AtomicBool::new(false));
        (r, capture::decode(&std::fs::read(&path).unwrap()))
    }

    fn stops_sent(&self) -> usize {
        self.sent.borrow().iter().filter(|c| **c == Command::Stop).count()
    }
}

/// An operator who answers (or presses Ctrl-C, setting `interrupt`) after `delay` of the rig's
/// time.
struct Slow<'a> {
    delay: Duration,
    asked: Option<Duration>,
    interrupt: Option<&'a AtomicBool>,
    prompts: usize,
}

impl<'a> Slow<'a> {
    fn new(delay_s: u64) -> Self {
        Self { delay: Duration::from_secs(delay_s), asked: None, interrupt: None, prompts: 0 }
    }
}

impl Operator for Slow<'_> {
    fn ask(&mut self, _message: &str, now: Duration) {
        self.asked = Some(now);
        self.prompts += 1;
    }
    fn reply(&mut self, now: Duration) -> Option<Reply> {
        if now < self.asked? + self.delay {
            return None;
        }
        match self.interrupt {
            Some(flag) => {
                flag.store(true, Ordering::SeqCst);
                None
            }
            None => Some(Reply::Ready),
        }
    }
}

fn run(pose: Pose, rate_dps: f64, duration_s: f64) -> RunPlan {
    RunPlan { pose, rate_dps, duration_s }
}

fn faults(cap: &Capture) -> Vec<Fault> {
    cap.runs
        .iter()
        .flat_map(|r| r.faults.iter().map(|(_, f)| f.fault))
        .chain(cap.faults.iter().map(|(_, f)| f.fault))
        .collect()
}

/// F1: the ramp-down from 180 °/s (2 s) and from 360 °/s (4 s) outlasts the rig's 2 s link
/// timeout; the host heartbeats through it, so the run ends in a controlled stop, not a trip.
#[test]
fn f1_ramp_down_after_stop_is_heartbeaten_to_a_controlled_stop() {
    let mut b = bench("f1", &[]);
    for rate in [180.0, 360.0] {
        let (r, cap) = b.record(&run(Pose::One, rate, 1.0));
        r.unwrap_or_else(|e| panic!("{rate} °/s: {e:#}"));
        assert_eq!(faults(&cap), [], "{rate} °/s");
        let run = &cap.runs[0];
        assert!(run.stopped, "{rate} °/s: RunStopped recorded");
        // Stopped by the ramp, no drive cut: no motor fault bit, the setpoint nearly down.
        let last = run.motor.last().unwrap().1;
        assert_eq!(last.faults, 0, "{rate} °/s");
        assert!(last.setpoint_cps.abs() < 2_000, "{rate} °/s: setpoint {} cps at the stop", last.setpoint_cps);
    }
}

/// F1: a fault during the ramp-down (here the rig's link watchdog, the host's frames no longer
/// arriving after `Stop`) is an error, not a clean stop.
#[test]
fn f1_a_link_trip_during_ramp_down_is_an_error() {
    let mut b = bench("f1-trip", &[]);
    b.link_port_mute_after_stop();
    let (r, cap) = b.record(&run(Pose::One, 180.0, 1.0));
    let e = format!("{:#}", r.expect_err("a HostLinkLost trip is not a clean stop"));
    assert!(e.contains("HostLinkLost"), "{e}");
    assert_eq!(faults(&cap), [Fault::HostLinkLost]);
}

impl Bench {
    fn link_port_mute_after_stop(&mut self) {
        self.link.port_mut().mute_after_stop = true;
    }
}

/// F4: the Start's Ack is lost: the host sends Start again (the rig answers Busy, its run already
/// started) and heartbeats all along, so the run proceeds; the first RunStopped is lost too: the
/// motor status with no run tag confirms the stop and the clean run is kept.
#[test]
fn f4_lost_ack_and_lost_run_stopped_do_not_fail_a_run() {
    // Ack #1 answers Identify; #2 is the Start's.
    let mut b = bench("f4", &["--drop", "Ack:2", "--drop", "RunStopped:1"]);
    let (r, cap) = b.record(&run(Pose::Two, 180.0, 1.0));
    r.unwrap_or_else(|e| panic!("{e:#}"));
    let starts = b.sent.borrow().iter().filter(|c| matches!(c, Command::Start(_))).count();
    assert_eq!(starts, 2, "the unacknowledged Start is sent again");
    assert_eq!(faults(&cap), []);
    assert_eq!(cap.runs.len(), 1);
    assert!(!cap.runs[0].stopped, "its RunStopped was dropped on the line");
}

/// F4: a lost Hello is asked for again, not an error.
#[test]
fn f4_lost_hello_is_asked_again() {
    // Hello #1 is the power-up one; #2 answers the first Identify.
    let mut b = bench("f4-hello", &["--drop", "Hello:1", "--drop", "Hello:2"]);
    let (r, cap) = b.record(&run(Pose::One, 90.0, 0.5));
    r.unwrap_or_else(|e| panic!("{e:#}"));
    assert!(cap.hello.is_some() && !cap.loss.hello_assumed);
    assert_eq!(b.sent.borrow().iter().filter(|c| **c == Command::Identify).count(), 2);
}

/// F2: an operator who takes a minute at each mounting prompt: the host keeps reading the port,
/// so the rig's queue never overflows and the next Identify is answered at once.
#[test]
fn f2_a_slow_operator_does_not_abort_the_session() {
    let mut b = bench("f2", &[]);
    let plan = session::plan(&Pose::ALL, &[90.0], 0.5);
    let mut operator = Slow::new(60);
    let files = session::record_session(&mut b.link, &plan, &b.dir, &mut operator, &AtomicBool::new(false))
        .unwrap_or_else(|e| panic!("{e:#}"));
    assert_eq!(operator.prompts, 2);
    assert!(b.clock.now() >= Duration::from_secs(120), "two minutes of rig time spent at the prompts");
    for f in files {
        let cap = capture::decode(&std::fs::read(&f).unwrap());
        let run = &cap.runs[0];
        let drops = run.counters.last().map(|(_, c)| c.queue_drops);
        assert_eq!(drops, Some(0), "{}: the rig's queue never overflowed", f.display());
        assert!(cap.loss.seq_gaps.is_empty(), "{}: {:?}", f.display(), cap.loss);
    }
}

/// F3: Ctrl-C at the prompt (the operator presses it after 5 s): the host sends Stop and gives
/// up within 1 s of the rig's time.
#[test]
fn f3_ctrl_c_at_the_prompt_stops_within_a_second() {
    let mut b = bench("f3", &[]);
    let interrupted = AtomicBool::new(false);
    let mut operator = Slow::new(5);
    operator.interrupt = Some(&interrupted);
    let plan = session::plan(&[Pose::One], &[180.0], 1.0);
    let e = session::record_session(&mut b.link, &plan, &b.dir, &mut operator, &interrupted).expect_err("aborted");
    assert!(format!("{e:#}").contains("interrupted at the prompt"), "{e:#}");
    let waited = b.clock.now();
    assert!(waited < Duration::from_secs(6), "gave up {waited:?} after the prompt, Ctrl-C at 5 s");
    assert_eq!(b.stops_sent(), 1);
}

/// F3/F9, issue 28: an interrupt mid-run (Ctrl-C, SIGTERM and SIGHUP set the same flag): Stop
/// sent once, and the host heartbeats the ramp-down (2 s from 180 °/s) until the rig reports the
/// table stopped, then leaves: the capture holds the run up to the interrupt, the ramp-down and
/// its RunStopped, and no fault (a host gone before the table stopped made the rig trip
/// HostLinkLost mid-ramp).
#[test]
fn f9_interrupt_mid_run_sends_stop_and_keeps_the_capture() {
    // At 5 s the table is at speed.
    let flag = Arc::new(AtomicBool::new(false));
    let f = flag.clone();
    let mut b = bench_with("f9", &[], move |c| Box::new(InterruptAt(f, c, Duration::from_secs(5))));
    let path = b.dir.join("interrupted.cap");
    let plan = run(Pose::One, 180.0, 30.0);
    let e = session::record_run(&mut b.link, &plan, &path, &indicatif::ProgressBar::hidden(), &flag)
        .expect_err("interrupted");
    assert!(format!("{e:#}").contains("interrupted during"), "{e:#}");
    let gone_at = b.clock.now();
    assert!(
        gone_at > Duration::from_secs(7) && gone_at < Duration::from_millis(7_500),
        "host gone at {gone_at:?}, interrupt at 5 s, 2 s of ramp-down"
    );
    assert_eq!(b.stops_sent(), 1);
    let cap = capture::decode(&std::fs::read(&path).unwrap());
    assert!(cap.loss.errors.is_empty() && cap.loss.seq_gaps.is_empty(), "{:?}", cap.loss);
    let r = &cap.runs[0];
    assert!(r.stopped && r.faults.is_empty() && cap.faults.is_empty(), "{:?} {:?}", r.faults, cap.faults);
    assert!(r.samples.len() > 3_000, "{} samples kept", r.samples.len());
    // The rig received the Stop: its setpoint ramps down in the recorded motor status.
    let setpoints: Vec<i32> = r.motor.iter().map(|(_, m)| m.setpoint_cps).collect();
    assert!(setpoints.last() < setpoints.iter().max(), "{setpoints:?}");
}

/// The rig's clock, which raises the interrupt flag (as Ctrl-C, SIGTERM or SIGHUP do) at a given
/// time.
struct InterruptAt(Arc<AtomicBool>, e2e::SimClock, Duration);

impl Clock for InterruptAt {
    fn now(&self) -> Duration {
        let t = self.1.now();
        if t >= self.2 {
            self.0.store(true, Ordering::SeqCst);
        }
        t
    }
}

/// F3: Ctrl-C while the host waits for an acknowledgement that does not come (the first
/// Identify's Ack is lost) ends the wait at once, not after the retries.
#[test]
fn f3_interrupt_while_waiting_for_an_ack_gives_up_at_once() {
    let flag = Arc::new(AtomicBool::new(false));
    let f = flag.clone();
    let mut b =
        bench_with("f3-ack", &["--drop", "Ack:1"], move |c| Box::new(InterruptAt(f, c, Duration::from_millis(300))));
    b.link.watch_interrupt(flag.clone());
    let path = b.dir.join("never.cap");
    let e =
        session::record_run(&mut b.link, &run(Pose::One, 180.0, 1.0), &path, &indicatif::ProgressBar::hidden(), &flag)
            .expect_err("interrupted");
    assert!(format!("{e:#}").contains("interrupted while waiting for the rig to answer Identify"), "{e:#}");
    let gone_at = b.clock.now();
    assert!(gone_at < Duration::from_millis(800), "gave up at {gone_at:?}, interrupt at 0.3 s");
    assert_eq!(b.stops_sent(), 1, "Stop sent on the way out");
}

/// F6: a rig that restarted from its watchdog says so with every Hello; the capture records the
/// fault outside any run and `inspect` shows it.
#[test]
fn f6_a_watchdog_reset_is_recorded_and_shown() {
    let mut b = bench("f6", &["--watchdog-reset"]);
    let (r, cap) = b.record(&run(Pose::One, 90.0, 0.5));
    r.unwrap_or_else(|e| panic!("{e:#}"));
    // Reported at power-up and again with the Hello the host asked for.
    assert!(
        !cap.faults.is_empty() && cap.faults.iter().all(|(_, f)| f.fault == Fault::WatchdogReset),
        "{:?}",
        cap.faults
    );
    assert_eq!(cap.runs[0].faults, []);
    let text = host::inspect::inspect("x.cap", &cap).to_string();
    assert!(text.contains("FAULT outside any run: WatchdogReset"), "{text}");
}

/// The hostile bench of issue 8: a full two-pose, two-speed session at the default speeds and
/// duration, without `--yes`, the operator answering each prompt after 30 s, over a line that
/// loses one byte in a thousand both ways, carries a burst of garbage every 2 s, and drops one
/// Start's Ack and one RunStopped. The session completes, no capture holds a fault, and the
/// captures calibrate to the virtual gyro.
#[test]
fn hostile_bench_full_session_completes_and_calibrates() {
    let mut b = bench(
        "hostile",
        &["--loss", "1e-3", "--garbage-every", "2", "--drop", "Ack:2", "--drop", "RunStopped:1", "--seed", "7"],
    );
    let plan = session::plan(&Pose::ALL, &[180.0, 90.0], 120.0);
    let mut operator = Slow::new(30);
    let files = session::record_session(&mut b.link, &plan, &b.dir, &mut operator, &AtomicBool::new(false))
        .unwrap_or_else(|e| panic!("{e:#}"));
    let mut runs = Vec::new();
    for (f, p) in files.iter().zip(&plan) {
        let cap = capture::decode(&std::fs::read(f).unwrap());
        assert_eq!(faults(&cap), [], "{}", f.display());
        assert_eq!(cap.runs.len(), 1, "{}", f.display());
        assert_eq!((cap.runs[0].pose, cap.runs[0].commanded_rate_dps()), (p.pose, p.rate_dps));
        eprintln!(
            "{}: {} frames, {} missing, {} bytes in {} bad stretches",
            f.display(),
            cap.loss.frames_ok,
            cap.loss.frames_missing(),
            cap.loss.bytes_skipped(),
            cap.loss.error_count()
        );
        runs.extend(cap.runs);
    }
    let report = calib::calibrate(&runs, &CalOptions::default()).expect("calibration");
    assert_matches_virtual_gyro(&report);
}
