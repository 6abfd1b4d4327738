//! The live path for real: the firmware's virtual rig (`host virtual-rig`) on one end of a
//! pseudo-terminal pair, the `host` binary on the other, as a user would run it against
//! /dev/ttyACM0. Every test that runs a session does so in lockstep ([`LockstepBench`]): the
//! host's clock is the rig's simulated time, so no test depends on the machine being idle.

use host::capture;
use serialport::{SerialPort, TTYPort};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;
use std::thread;
use std::time::Duration;

fn host(args: &[&str]) -> Output {
    host_command().args(args).output().expect("host runs")
}

/// A test's scratch directory under the temp dir, with the files named after it beside it (its
/// records database, the lockstep clock's socket): removed when the test passes, kept for
/// inspection when it fails (the guard drops while the test panics).
struct Scratch(PathBuf);

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if thread::panicking() {
            return;
        }
        let _ = std::fs::remove_dir_all(&self.0);
        let (Some(parent), Some(name)) = (self.0.parent(), self.0.file_name()) else { return };
        let beside = format!("{}.", name.to_string_lossy());
        for entry in std::fs::read_dir(parent).into_iter().flatten().flatten() {
            if entry.file_name().to_string_lossy().starts_with(&beside) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
}

fn scratch_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("host-live-{}-{name}", std::process::id()))
}

fn scratch(name: &str) -> Scratch {
    let d = scratch_path(name);
    let _ = std::fs::remove_dir_all(&d);
    Scratch(d)
}

/// The captures of a default live session (`--rates-dps 180,90,-180` in both poses), in order.
const DEFAULT_FILES: [&str; 6] = [
    "pose1-p180dps.cap",
    "pose1-p90dps.cap",
    "pose1-m180dps.cap",
    "pose2-p180dps.cap",
    "pose2-p90dps.cap",
    "pose2-m180dps.cap",
];

fn decode(path: &Path) -> capture::Capture {
    capture::decode(&std::fs::read(path).unwrap())
}

#[test]
fn calibrate_over_a_serial_port_records_both_poses_and_calibrates() {
    let mut bench = LockstepBench::start("calibrate", &[]);
    let dir = scratch("calibrate");
    let db = format!("sqlite:{}", dir.with_extension("records.sqlite").display());
    let o = bench.run(
        &[
            "calibrate",
            "--duration",
            "8",
            "--yes",
            "--out-dir",
            dir.to_str().unwrap(),
            "--sensor",
            "G-LIVE-11",
            "--operator",
            "ci",
            "--db",
            &db,
        ],
        std::process::Stdio::null(),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(0) || o.status.code() == Some(3), "{err}");
    for (file, pose) in [("pose1-p180dps.cap", 1), ("pose2-p180dps.cap", 2)] {
        let cap = decode(&dir.join(file));
        // Every byte a frame, none missing (the samples before RunStarted belong to no run).
        assert!(cap.loss.errors.is_empty() && cap.loss.seq_gaps.is_empty(), "{file}: {:?}", cap.loss);
        assert_eq!(cap.runs.len(), 1, "{file}");
        let run = &cap.runs[0];
        assert_eq!(run.pose.number(), pose);
        assert!(run.stopped, "{file}: the run ends with RunStopped");
        // ≥ 8 s at speed plus the ramp, at 800 Hz (±1 % ODR error of the simulated gyro).
        assert!(run.samples.len() as f64 >= 8.0 * 800.0 * 0.99, "{file}: {} samples", run.samples.len());
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("calibration.json")).unwrap()).unwrap();
    for i in 0..3 {
        let k = report["axes"][i]["k_counts_per_dps"].as_f64().unwrap();
        let sigma = report["axes"][i]["k_sigma"].as_f64().unwrap();
        // The virtual gyro's row i is k_i s_iᵀ in °/s per °/s; ±500 °/s is 17.5 m°/s per count.
        let row = host::virtual_rig::VIRTUAL_GYRO_KS[i];
        let k_true = row.iter().map(|v| v * v).sum::<f64>().sqrt() / 17.5e-3;
        assert!((k - k_true).abs() < 4.0 * sigma, "axis {i}: k {k} ± {sigma} vs truth {k_true}");
    }
    // Provenance: the manifest beside the captures names the sensor and fingerprints each
    // capture; the result carries the same, plus the rig's firmware from its Hello.
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("session.json")).unwrap()).unwrap();
    assert_eq!(manifest["sensor_serial"], "G-LIVE-11");
    assert_eq!(manifest["captures"].as_array().unwrap().len(), 6, "2 poses × 3 default rates");
    let prov = &report["provenance"];
    assert_eq!(prov["sensor_serial"], "G-LIVE-11");
    assert_eq!(prov["operator"], "ci");
    assert_eq!(prov["rig_firmware"], "0.1.0");
    assert_eq!(prov["captures"], manifest["captures"]);
    assert!(err.contains("recorded as 1 in sqlite:"), "{err}");

    // Replayed later without --sensor: the manifest beside the captures names the sensor, and
    // the captures are checked against its fingerprints.
    let caps: Vec<String> = DEFAULT_FILES.iter().map(|f| dir.join(f).display().to_string()).collect();
    let again = dir.join("again");
    let mut args = vec!["calibrate", "--out-dir", again.to_str().unwrap(), "--db", &db, "--again", "--replay"];
    args.extend(caps.iter().map(String::as_str));
    let o = host(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(0) || o.status.code() == Some(3), "{err}");
    assert!(!err.contains("warning:"), "{err}");
    let replayed: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(again.join("calibration.json")).unwrap()).unwrap();
    assert_eq!(replayed["provenance"]["sensor_serial"], "G-LIVE-11");
    assert_eq!(replayed["provenance"]["session_started_utc"], manifest["started_utc"]);
}

#[test]
fn live_calibration_needs_a_sensor_serial() {
    let o = host(&["calibrate", "--port", "/dev/null", "--yes"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--sensor <SENSOR>"), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn record_one_pose_over_a_serial_port() {
    let mut bench = LockstepBench::start("record", &[]);
    let dir = scratch("record");
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("p2.cap");
    let o = bench.run(
        &["record", "--out", out.to_str().unwrap(), "--pose", "2", "--rate-dps=-90", "--duration", "3"],
        std::process::Stdio::null(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let cap = decode(&out);
    assert!(cap.loss.errors.is_empty() && cap.loss.seq_gaps.is_empty(), "{:?}", cap.loss);
    assert!(cap.hello.is_some());
    let run = &cap.runs[0];
    assert_eq!((run.pose.number(), run.commanded_rate_dps()), (2, -90.0));
    assert!(run.stopped && run.faults.is_empty(), "{:?}", run.faults);
    // A second recording never overwrites the first.
    let o = bench.run(
        &["record", "--out", out.to_str().unwrap(), "--pose", "1", "--duration", "1"],
        std::process::Stdio::null(),
    );
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.starts_with(&format!("error: cannot create capture {}: ", out.display())), "{err}");
}

#[test]
fn a_rig_that_does_not_answer_is_one_line_and_exit_1() {
    // A pty with nobody on the other end: the host's Identify is never acknowledged.
    let (_master, slave) = TTYPort::pair().expect("pty pair");
    let path = slave.name().unwrap();
    let dir = scratch("silent");
    let db = format!("sqlite:{}", dir.with_extension("records.sqlite").display());
    let o = host(&[
        "calibrate",
        "--port",
        &path,
        "--duration",
        "1",
        "--yes",
        "--out-dir",
        dir.to_str().unwrap(),
        "--sensor",
        "G-1",
        "--db",
        &db,
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    let last = err.lines().last().unwrap();
    // The link is blamed, not the gyro (F10).
    assert!(
        last.starts_with(&format!("error: the link to the rig on {path} is silent: not one byte for 2 s")),
        "{last}"
    );
    // The empty capture of the run that never started is kept, not deleted.
    assert!(dir.join("pose1-p180dps.cap").exists());
}

/// `host` running with its standard error read line by line, so a test can act when a line
/// appears. Killed when dropped.
struct Running {
    child: std::process::Child,
    lines: std::sync::mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Running {
    fn start(args: &[&str], stdin: std::process::Stdio) -> Self {
        use std::io::BufRead;
        let mut child = host_command()
            .args(args)
            .stdin(stdin)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("host runs");
        let err = child.stderr.take().unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        thread::spawn(move || {
            // The prompt ends without a newline: split at "\n" and at the prompt's final space.
            let mut r = std::io::BufReader::new(err);
            let mut buf = Vec::new();
            while r.read_until(b' ', &mut buf).map(|n| n > 0).unwrap_or(false) {
                if buf.ends_with(b"\n") || buf.ends_with(b"abort) ") {
                    let _ = tx.send(String::from_utf8_lossy(&buf).into_owned());
                    buf.clear();
                }
            }
            let _ = tx.send(String::from_utf8_lossy(&buf).into_owned());
        });
        Self { child, lines, seen: Vec::new() }
    }

    /// Lines of standard error that arrived since the last call (never blocks).
    fn drain(&mut self) -> Vec<String> {
        let new: Vec<String> = self.lines.try_iter().collect();
        self.seen.extend(new.iter().cloned());
        new
    }

    fn signal(&self, name: &str) {
        let ok = Command::new("kill").args([&format!("-{name}"), &self.child.id().to_string()]).status().unwrap();
        assert!(ok.success());
    }

    /// Waits for the exit; returns the status, everything on standard error, and the wall time
    /// it took (reported, not asserted: a loaded machine may take longer; the in-process tests
    /// assert the 1 s in the rig's time).
    fn finish(mut self) -> (std::process::ExitStatus, String, Duration) {
        let t0 = std::time::Instant::now();
        let status = loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                break s;
            }
            assert!(t0.elapsed() < Duration::from_secs(60), "host did not exit: {:?}", self.seen);
            thread::sleep(Duration::from_millis(5));
        };
        let took = t0.elapsed();
        while let Ok(l) = self.lines.recv_timeout(Duration::from_secs(5)) {
            self.seen.push(l);
        }
        (status, self.seen.concat(), took)
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// F10: end of standard input at a prompt is an abort, not the operator's Enter.
#[test]
fn end_of_input_at_the_prompt_is_an_abort() {
    let mut bench = LockstepBench::start("eof", &[]);
    let dir = scratch("eof");
    let o = bench.run(
        &["calibrate", "--sensor", "SN-1", "--duration", "1", "--out-dir", dir.to_str().unwrap()],
        std::process::Stdio::null(),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.lines().last().unwrap().starts_with("error: standard input ended at the prompt"), "{err}");
    assert!(!dir.join("pose1-p180dps.cap").exists(), "no run was started");
}

/// Starts `host virtual-rig ARGS` and returns it with the pty path it prints first.
fn spawn_virtual_rig(args: &[&str]) -> (std::process::Child, String) {
    use std::io::BufRead;
    let mut rig = host_command()
        .arg("virtual-rig")
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(rig.stdout.take().unwrap()).read_line(&mut line).unwrap();
    (rig, line.trim().to_string())
}

/// `host virtual-rig`: the pty path is the first line of standard output, and the rig behind it
/// answers the host (here `record`, listening only: Identify, then the idle stream).
#[test]
fn virtual_rig_subcommand_prints_its_pty_and_serves_it() {
    let (mut rig, path) = spawn_virtual_rig(&["--speedup", "1"]);
    assert!(path.starts_with("/dev/pts/"), "{path:?}");
    let dir = scratch("virtual-rig");
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("idle.cap");
    let o = host(&["record", "--port", &path, "--out", out.to_str().unwrap(), "--duration", "1"]);
    let _ = rig.kill();
    let _ = rig.wait();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let cap = decode(&out);
    assert!(cap.hello.is_some_and(|h| h.encoder_counts_per_rev == 324_000));
    assert!(cap.loss.orphan_samples > 100, "the idle rig streams samples: {:?}", cap.loss);
}

/// `host virtual-rig` refuses bad options with a usage error.
#[test]
fn virtual_rig_subcommand_refuses_bad_options() {
    for args in [
        &["virtual-rig", "--loss", "1.5"][..],
        &["virtual-rig", "--drop", "Helo:1"],
        &["virtual-rig", "--speedup", "nan"],
    ] {
        let o = host(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(String::from_utf8_lossy(&o.stderr).starts_with("error: invalid value"), "{args:?}");
    }
}

/// `host virtual-rig --lockstep` and the Unix socket through which a `host` run with the hidden
/// `--lockstep-clock` asks it for time: the test relays every `step` line to the rig and every
/// `at` answer back, so it knows the simulated time the host lives in and can act at a given
/// moment of it (answer a prompt, send a signal).
///
/// Why nothing here can race the wall clock: the rig's time advances only when the host, finding
/// nothing to read, asks for the next 5 ms, after the rig has received every byte the host wrote
/// before asking; the host's timeouts, heartbeats and retries are measured in that same time
/// (`LockstepPort::clock`). A descheduled host, rig or test stops the simulation with it: a
/// loaded machine makes the test slower, never different. The operator's delays are counted in
/// simulated time from the `at` answer current when the test sees the prompt, which is never
/// earlier than the host's time when it printed it, so every answer comes ≥ 30 s after its
/// question. Wall time is only measured (and bounded generously) for the signal tests' exit.
struct LockstepBench {
    rig: std::process::Child,
    control_in: std::process::ChildStdin,
    control_out: std::io::BufReader<std::process::ChildStdout>,
    path: String,
    /// The rig's standard error: its command log (`virtual rig: received Stop (seq 9) at 4.125 s`).
    log: Arc<std::sync::Mutex<Vec<String>>>,
    socket: PathBuf,
    listener: std::os::unix::net::UnixListener,
}

impl LockstepBench {
    fn start(name: &str, args: &[&str]) -> Self {
        use std::io::BufRead;
        let mut rig = host_command()
            .args(["virtual-rig", "--lockstep"])
            .args(args)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let control_in = rig.stdin.take().unwrap();
        let mut control_out = std::io::BufReader::new(rig.stdout.take().unwrap());
        let mut path = String::new();
        control_out.read_line(&mut path).unwrap();
        let log = Arc::new(std::sync::Mutex::new(Vec::new()));
        let sink = log.clone();
        let err = rig.stderr.take().unwrap();
        thread::spawn(move || {
            for line in std::io::BufReader::new(err).lines().map_while(Result::ok) {
                sink.lock().unwrap().push(line);
            }
        });
        let socket = scratch_path(name).with_extension("clock.sock");
        let _ = std::fs::remove_file(&socket);
        let listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
        Self { rig, control_in, control_out, path: path.trim().to_string(), log, socket, listener }
    }

    /// `host ARGS --port PTY --lockstep-clock SOCKET`, standard input piped.
    fn host(&self, args: &[&str]) -> Running {
        self.host_with(args, std::process::Stdio::piped())
    }

    fn host_with(&self, args: &[&str], stdin: std::process::Stdio) -> Running {
        let mut all = args.to_vec();
        all.extend(["--port", &self.path, "--lockstep-clock", self.socket.to_str().unwrap()]);
        Running::start(&all, stdin)
    }

    /// Runs `host ARGS` against the rig to its end; its exit status and standard error.
    fn run(&mut self, args: &[&str], stdin: std::process::Stdio) -> Output {
        let mut running = self.host_with(args, stdin);
        self.relay(&mut running, |_, _| {});
        let (status, err, _) = running.finish();
        Output { status, stdout: Vec::new(), stderr: err.into_bytes() }
    }

    /// Relays the host's time requests until it closes the socket (it exited); `at_step` is
    /// called with the simulated time (ns) after every step, before the host hears of it.
    /// Returns the simulated time of the host's last step.
    fn relay(&mut self, host: &mut Running, mut at_step: impl FnMut(u64, &mut Running)) -> u64 {
        use std::io::{BufRead, Write};
        self.listener.set_nonblocking(true).unwrap();
        let t0 = std::time::Instant::now();
        let stream = loop {
            match self.listener.accept() {
                Ok((s, _)) => break s,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    if host.child.try_wait().unwrap().is_some() {
                        return 0; // exited before asking for time
                    }
                    assert!(t0.elapsed() < Duration::from_secs(120), "the host never connected");
                    thread::sleep(Duration::from_millis(5));
                }
                Err(e) => panic!("accept: {e}"),
            }
        };
        stream.set_nonblocking(false).unwrap();
        // A hang guard: a host that stops asking for time has stopped reading the port (the rig's
        // time advances only through its reads), e.g. blocked at a prompt (F2).
        stream.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        let mut from_host = std::io::BufReader::new(stream.try_clone().unwrap());
        let mut to_host = stream;
        let mut now_ns = 0;
        loop {
            let mut step = String::new();
            match from_host.read_line(&mut step) {
                Ok(0) => return now_ns,
                Ok(_) => {}
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                    panic!(
                        "the host stopped asking for time at {now_ns} ns (blocked, not reading the port): {:?}",
                        host.seen
                    )
                }
                Err(_) => return now_ns,
            }
            self.control_in.write_all(step.as_bytes()).and_then(|()| self.control_in.flush()).unwrap();
            let mut at = String::new();
            assert!(self.control_out.read_line(&mut at).unwrap() > 0, "the virtual rig ended: {:?}", self.log());
            now_ns = at.split_whitespace().nth(1).and_then(|t| t.parse().ok()).expect("at <ns> <bytes>");
            at_step(now_ns, host);
            if to_host.write_all(at.as_bytes()).is_err() {
                return now_ns;
            }
        }
    }

    fn log(&self) -> Vec<String> {
        self.log.lock().unwrap().clone()
    }

    /// After the host has gone: one more step of rig time, so that bytes the host wrote just
    /// before exiting (a `Stop` at the prompt, sent 0 s of rig time before the exit) are handled
    /// rather than left in the pty, then waits (wall time, bounded) until the rig's log shows
    /// `command` or the rig answered. Without it the check below raced the rig's reading.
    fn settle(&mut self, command: &str) {
        use std::io::{BufRead, Write};
        if writeln!(self.control_in, "step {} 0", 5_000_000).and_then(|()| self.control_in.flush()).is_ok() {
            let mut at = String::new();
            let _ = self.control_out.read_line(&mut at);
        }
        let t0 = std::time::Instant::now();
        while self.received(command).is_empty() && t0.elapsed() < Duration::from_secs(10) {
            thread::sleep(Duration::from_millis(10));
        }
    }

    /// Simulated times (s) at which the rig received `command`.
    fn received(&self, command: &str) -> Vec<f64> {
        let prefix = format!("virtual rig: received {command} (");
        self.log()
            .iter()
            .filter(|l| l.starts_with(&prefix))
            .filter_map(|l| l.rsplit(" at ").next()?.strip_suffix(" s")?.parse().ok())
            .collect()
    }
}

impl Drop for LockstepBench {
    fn drop(&mut self) {
        let _ = self.rig.kill();
        let _ = self.rig.wait();
        let _ = std::fs::remove_file(&self.socket);
    }
}

const NS: u64 = 1_000_000_000;

/// What issue 8 asks of the live path, through the `host` binary: `host virtual-rig` on a line
/// as hostile as a real bench (a byte in a thousand lost both ways, a burst of garbage every
/// 2 s, the Start's Ack and the first RunStopped dropped), `host calibrate --port` without
/// `--yes` at the default speeds (180, 90, −180 °/s) and duration (120 s) in both poses, and an
/// operator who answers each prompt 30 s (simulated) after it appears, while the host keeps
/// draining the rig's idle stream. The session completes at exit 0, no capture holds a fault,
/// and the six captures replayed give exactly the live calibration. The 30 s waits are
/// themselves the proof that the host reads the port at a prompt: in lockstep the rig's time
/// advances only through the host's reads (a host blocked at the prompt, F2, would stop the
/// clock and trip the relay's hang guard), and the rig's queue-drop counter stays at 0.
#[test]
fn hostile_bench_through_the_host_binary_completes_and_replays_to_the_same_calibration() {
    use std::io::Write;
    let mut bench = LockstepBench::start(
        "hostile-bin",
        &["--loss", "1e-3", "--garbage-every", "2", "--drop", "Ack:2", "--drop", "RunStopped:1", "--seed", "7"],
    );
    let dir = scratch("hostile-bin");
    let db = format!("sqlite:{}", dir.with_extension("records.sqlite").display());
    let mut session =
        bench.host(&["calibrate", "--sensor", "SN-HOSTILE", "--out-dir", dir.to_str().unwrap(), "--db", &db]);
    let mut stdin = session.child.stdin.take().unwrap();
    let mut asked_at_ns = None;
    let mut waits_s = Vec::new();
    let wall = std::time::Instant::now();
    let end_ns = bench.relay(&mut session, |now_ns, host| {
        if host.drain().iter().any(|l| l.contains("Press Enter when ready")) {
            asked_at_ns = Some(now_ns);
        }
        if let Some(asked) = asked_at_ns.filter(|a| now_ns >= a + 30 * NS) {
            writeln!(stdin).unwrap();
            waits_s.push((now_ns - asked) as f64 * 1e-9);
            asked_at_ns = None;
        }
    });
    let (status, err, _) = session.finish();
    eprintln!(
        "hostile session: {:.1} s of rig time in {:.1?} of wall time; prompts answered after {:.3?} s",
        end_ns as f64 * 1e-9,
        wall.elapsed(),
        waits_s
    );
    assert_eq!(status.code(), Some(0), "{err}\nrig: {:?}", bench.log());
    // The sensor's serial, pose 1, pose 2: each answered 30 s after it was asked.
    assert_eq!(waits_s.len(), 3, "{err}");
    assert!(waits_s.iter().all(|w| *w >= 30.0), "{waits_s:?}");
    assert!(end_ns >= 6 * 120 * NS + 90 * NS, "6 runs of 120 s and 3 prompts of 30 s: {end_ns} ns");
    // The dropped Ack made the host send the first Start again; each run was stopped.
    let starts = bench.received("Start");
    let stops = bench.received("Stop");
    assert!(starts.len() >= 7 && stops.len() >= 6, "Start at {starts:?} s, Stop at {stops:?} s");
    assert!(bench.log().iter().any(|l| l == "virtual rig: dropped Ack #2"), "{:?}", bench.log());
    assert!(bench.log().iter().any(|l| l == "virtual rig: dropped RunStopped #1"), "{:?}", bench.log());

    let files = DEFAULT_FILES;
    for (file, (pose, rate)) in
        files.iter().zip([(1, 180.0), (1, 90.0), (1, -180.0), (2, 180.0), (2, 90.0), (2, -180.0)])
    {
        let cap = decode(&dir.join(file));
        assert_eq!(cap.runs.len(), 1, "{file}");
        let run = &cap.runs[0];
        assert_eq!((run.pose.number(), run.commanded_rate_dps()), (pose, rate), "{file}");
        assert!(run.faults.is_empty() && cap.faults.is_empty(), "{file}: {:?} {:?}", run.faults, cap.faults);
        // F2: the rig's transmit queue never overflowed, the 30 s prompts included.
        let drops: Vec<u32> = run.counters.iter().map(|(_, c)| c.queue_drops).collect();
        assert!(!drops.is_empty() && drops.iter().all(|d| *d == 0), "{file}: queue drops {drops:?}");
        // 120 s at speed at 800 Hz (±1 % ODR error of the simulated gyro), less the frames lost.
        assert!(run.samples.len() as f64 >= 120.0 * 800.0 * 0.99 * 0.95, "{file}: {} samples", run.samples.len());
        let o = host(&["inspect", dir.join(file).to_str().unwrap()]);
        let text = String::from_utf8_lossy(&o.stdout);
        assert_eq!(o.status.code(), Some(0), "{file}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(!text.contains("FAULT"), "{file}: {text}");
        eprintln!(
            "{file}: {} samples, {} frames, {} missing, {} bytes in {} bad stretches",
            run.samples.len(),
            cap.loss.frames_ok,
            cap.loss.frames_missing(),
            cap.loss.bytes_skipped(),
            cap.loss.error_count()
        );
    }

    // Replayed, the same bytes give the same calibration, to the last digit.
    let again = dir.join("again");
    let caps: Vec<String> = files.iter().map(|f| dir.join(f).display().to_string()).collect();
    let mut args = vec!["calibrate", "--out-dir", again.to_str().unwrap(), "--db", &db, "--again", "--replay"];
    args.extend(caps.iter().map(String::as_str));
    let o = host(&args);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |d: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("calibration.json")).unwrap()).unwrap()
    };
    let (mut live, mut replayed) = (read(&dir), read(&again));
    assert!(live["axes"].is_array());
    // Everything but the moment of calculation: every parameter, covariance, residual figure,
    // and the provenance (sensor, session start, capture fingerprints).
    for r in [&mut live, &mut replayed] {
        r["provenance"].as_object_mut().unwrap().remove("calibrated_utc").expect("calibrated_utc");
    }
    assert_eq!(live, replayed);
}

/// Where in the session a signal is sent.
#[derive(Debug, Clone, Copy, PartialEq)]
enum When {
    /// 5 s after the pose-1 mounting prompt appears.
    AtThePrompt,
    /// 5 s after the rig received the first Start: the table at speed, recording.
    MidRun,
}

/// Ctrl-C or SIGTERM sent to `host calibrate --port` (lockstep: see [`LockstepBench`]); returns
/// the bench, the output directory, the host's standard error, and the simulated and wall time
/// from the signal to the host's exit. The operator answers every prompt at once.
fn signal_the_session(sig: &str, when: When) -> (LockstepBench, Scratch, String, f64, Duration) {
    use std::io::Write;
    let name = format!("sig-{sig}-{when:?}");
    let mut bench = LockstepBench::start(&name, &[]);
    let dir = scratch(&name);
    let db = format!("sqlite:{}", dir.with_extension("records.sqlite").display());
    let mut host = bench.host(&["calibrate", "--sensor", "SN-SIG", "--out-dir", dir.to_str().unwrap(), "--db", &db]);
    let mut stdin = host.child.stdin.take().unwrap();
    let log = bench.log.clone();
    let mut prompts = 0;
    let mut act_at_ns = None;
    let mut signalled: Option<(u64, std::time::Instant)> = None;
    let end_ns = bench.relay(&mut host, |now_ns, host| {
        for line in host.drain() {
            if line.contains("Press Enter when ready") {
                prompts += 1;
                if when == When::AtThePrompt && prompts == 2 {
                    act_at_ns = Some(now_ns + 5 * NS);
                } else {
                    writeln!(stdin).unwrap();
                }
            }
        }
        let started = log.lock().unwrap().iter().any(|l| l.starts_with("virtual rig: received Start"));
        if when == When::MidRun && started && act_at_ns.is_none() {
            act_at_ns = Some(now_ns + 5 * NS);
        }
        if signalled.is_none() && act_at_ns.is_some_and(|t| now_ns >= t) {
            host.signal(sig);
            signalled = Some((now_ns, std::time::Instant::now()));
            // Lets the handler thread run before the host hears of the next step, so the
            // simulated figure measures the host's reaction rather than the scheduler's (it has
            // 0.7 s of rig time, 140 steps, of margin; the Stop-to-exit figure has none to need).
            thread::sleep(Duration::from_millis(50));
        }
    });
    let (status, err, _) = host.finish();
    let (signal_ns, signal_wall) = signalled.unwrap_or_else(|| panic!("never signalled: {err}"));
    let wall = signal_wall.elapsed();
    bench.settle("Stop");
    let sim_s = (end_ns - signal_ns) as f64 * 1e-9;
    eprintln!("SIG{sig} {when:?}: the host exited {sim_s:.3} s of rig time and {wall:.2?} of wall time after it");
    assert_eq!(status.code(), Some(1), "{err}");
    // Within 1 s of the rig's time; within 5 s of wall time, however loaded the machine.
    assert!(sim_s < 1.0, "SIG{sig} {when:?}: {sim_s} s");
    assert!(wall < Duration::from_secs(5), "SIG{sig} {when:?}: {wall:?}");
    // The rig received Stop after the signal.
    let stops = bench.received("Stop");
    assert!(
        stops.iter().any(|t| *t >= signal_ns as f64 * 1e-9 - 0.01),
        "SIG{sig} {when:?}: Stop at {stops:?} s, signal at {} s: {:?}",
        signal_ns as f64 * 1e-9,
        bench.log()
    );
    // From the Stop to the exit the host only drains what the rig still sends: 0.3 s of rig time
    // mid-run (`INTERRUPT_DRAIN`), none at the prompt. This figure, unlike the one from the
    // signal, does not depend on when the scheduler runs the host's signal-handling thread.
    let stop_s = stops.last().copied().unwrap_or_default();
    let drained_s = end_ns as f64 * 1e-9 - stop_s;
    let expected_s = if when == When::MidRun { 0.300 } else { 0.0 };
    assert!((drained_s - expected_s).abs() < 0.006, "SIG{sig} {when:?}: exit {drained_s:.3} s after the Stop");
    (bench, dir, err, sim_s, wall)
}

/// F3/F9: Ctrl-C, SIGTERM or SIGHUP at the mounting prompt: Stop sent, exit 1 within 1 s (rig
/// time) with one line, and no run was started.
#[test]
fn a_signal_at_the_prompt_through_the_host_binary_stops_within_a_second() {
    for sig in ["INT", "TERM", "HUP"] {
        let (bench, dir, err, _, _) = signal_the_session(sig, When::AtThePrompt);
        let last = err.lines().last().unwrap();
        assert_eq!(last, "error: interrupted at the prompt; the rig was sent Stop", "SIG{sig}: {err}");
        assert_eq!(bench.received("Start"), Vec::<f64>::new(), "SIG{sig}");
        assert!(!dir.join("pose1-p180dps.cap").exists(), "SIG{sig}");
    }
}

/// F3/F9: Ctrl-C, SIGTERM and SIGHUP mid-run: Stop sent, exit 1 within 1 s (rig time), and the capture
/// so far intact: every byte decodes, no frame missing, no fault, the table was ramping down
/// when the host left, and `host inspect` reads it.
#[test]
fn a_signal_mid_run_through_the_host_binary_stops_and_keeps_the_capture() {
    for sig in ["INT", "TERM", "HUP"] {
        let (_bench, dir, err, _, _) = signal_the_session(sig, When::MidRun);
        // The answered prompt has no newline of its own (a terminal echoes the operator's Enter).
        let last = err.lines().last().unwrap();
        let expected = format!(
            "error: interrupted during pose 1, +180.0 °/s (capture kept in {})",
            dir.join("pose1-p180dps.cap").display()
        );
        assert!(last.ends_with(&expected), "{err}");
        let file = dir.join("pose1-p180dps.cap");
        let cap = decode(&file);
        // Every byte a frame, no frame missing (the few samples before RunStarted belong to no run).
        assert!(cap.loss.errors.is_empty() && cap.loss.seq_gaps.is_empty(), "SIG{sig}: {:?}", cap.loss);
        assert_eq!(cap.runs.len(), 1);
        let run = &cap.runs[0];
        assert!(run.faults.is_empty() && cap.faults.is_empty(), "SIG{sig}: {:?}", run.faults);
        // 5 s after the Start: 2 s of ramp and 3 s at speed, 800 Hz.
        assert!(run.samples.len() > 3_000, "SIG{sig}: {} samples", run.samples.len());
        let setpoints: Vec<i32> = run.motor.iter().map(|(_, m)| m.setpoint_cps).collect();
        assert!(setpoints.last() < setpoints.iter().max(), "SIG{sig}: the ramp-down began: {setpoints:?}");
        let o = host(&["inspect", file.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(0), "SIG{sig}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(!String::from_utf8_lossy(&o.stdout).contains("FAULT"));
    }
}

/// Issue 24, item 3: on a line losing 3 bytes in 1000 (`--loss 3e-3`, seeds 7 and 9) the gaps
/// leave `host calibrate --duration 20` a few dozen usable samples per run. Whatever it makes of
/// them, it never certifies (exit 0) a calibration off the virtual gyro by more than 4σ (|z| as
/// `../shared/validation/check.py` reckons it); a refusal (exit 1) leaves no calibration behind.
#[test]
fn a_lossy_line_never_certifies_a_calibration_off_the_truth() {
    // The virtual gyro's M: row i is k_i s_iᵀ in °/s per °/s; ±500 °/s is 17.5 m°/s per count.
    let m_true = host::virtual_rig::VIRTUAL_GYRO_KS.map(|row| row.map(|v| v / 17.5e-3));
    let mut wrong = Vec::new();
    for seed in ["7", "9"] {
        let name = format!("lossy-{seed}");
        let mut bench = LockstepBench::start(&name, &["--loss", "3e-3", "--seed", seed]);
        let dir = scratch(&name);
        let db = format!("sqlite:{}", dir.with_extension("records.sqlite").display());
        let wall = std::time::Instant::now();
        let o = bench.run(
            &["calibrate", "--sensor", "SN-LOSSY", "--yes", "--duration", "20", "--out-dir", dir.to_str().unwrap()]
                .into_iter()
                .chain(["--db", &db])
                .collect::<Vec<_>>(),
            std::process::Stdio::null(),
        );
        let err = String::from_utf8_lossy(&o.stderr);
        let last = err.lines().last().unwrap_or_default();
        let json = dir.join("calibration.json");
        eprintln!("seed {seed}: exit {:?} after {:.1?} of wall time: {last}", o.status.code(), wall.elapsed());
        let z = json.exists().then(|| max_z_like_check_py(&std::fs::read_to_string(&json).unwrap(), &m_true));
        eprintln!("seed {seed}: max |z| {z:.1?}");
        match o.status.code() {
            Some(0) if z.is_some_and(|z| z <= 4.0) => {}
            Some(0) => wrong.push(format!("seed {seed}: certified at max |z| {z:.1?}")),
            Some(1) if z.is_some() => wrong.push(format!("seed {seed}: refused, yet {} was written", json.display())),
            Some(1 | 3) => {}
            other => wrong.push(format!("seed {seed}: exit {other:?}: {err}")),
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// The largest |z| of `calibration.json` against a true M, as `../shared/validation/check.py`
/// reckons it: each sensitivity against `k_sigma`, each element of M against √ of its variance,
/// each direction as a 2-dof distance in the plane normal to it (from its row's block of `cov`).
/// Read from the JSON, where a NaN is `null`, so that a calibration holding one is judged too (as
/// infinitely far off: it cannot say how far it is).
fn max_z_like_check_py(json: &str, m_true: &[[f64; 3]; 3]) -> f64 {
    use nalgebra::{Matrix2, Matrix3, Vector3};
    let c: serde_json::Value = serde_json::from_str(json).unwrap();
    let num = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let cov = |i: usize, j: usize| num(&c["cov"][i][j]);
    let mut z = Vec::new();
    for i in 0..3 {
        let t = Vector3::from(m_true[i]);
        let m = Vector3::from_fn(|j, _| num(&c["m_counts_per_dps"][i][j]));
        let a = &c["axes"][i];
        z.push((num(&a["k_counts_per_dps"]) - t.norm()).abs() / num(&a["k_sigma"]));
        for j in 0..3 {
            z.push((m[j] - t[j]).abs() / cov(4 * i + j, 4 * i + j).sqrt());
        }
        // ds = (I − s sᵀ) dm / |m|: its components along u and v, normal to s.
        let s = m.normalize();
        let other = if s[0].abs() < 0.9 { Vector3::x() } else { Vector3::y() };
        let u = s.cross(&other).normalize();
        let v = s.cross(&u);
        let c3 = Matrix3::from_fn(|r, q| cov(4 * i + r, 4 * i + q));
        let basis = [u / m.norm(), v / m.norm()];
        let c2 = Matrix2::from_fn(|r, q| basis[r].dot(&(c3 * basis[q])));
        let e = nalgebra::Vector2::new(u.dot(&(s - t.normalize())), v.dot(&(s - t.normalize())));
        z.push(match c2.try_inverse().filter(|_| c2.determinant() > 0.0) {
            Some(ci) => (e.transpose() * ci * e)[(0, 0)].sqrt(),
            None => f64::INFINITY,
        });
    }
    z.into_iter().map(|v| if v.is_nan() { f64::INFINITY } else { v }).fold(0.0, f64::max)
}

/// `host`, with the records database's default kept out of the user's data folder: a run
/// without `--db` records under the temporary directory, never in ~/.local/share.
fn host_command() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_host"));
    c.env_remove("GYROCAL_DB").env("XDG_DATA_HOME", std::env::temp_dir().join("gyrocal-tests-data"));
    c
}
