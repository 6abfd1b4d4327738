//! The live path for real: the simulated rig on one end of a pseudo-terminal pair, the `host`
//! binary on the other, as a user would run it against /dev/ttyACM0.

use host::capture;
use host::sim::{self, SimConfig, SimRig};
use serialport::{SerialPort, TTYPort};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::Duration;

/// Simulated seconds per wall-clock second. These tests run the real `host` binary, whose clock
/// is the wall clock, against `host::sim`'s rig paced by the wall clock: a heartbeat every 0.25 s
/// is 0.5 s of simulated time, so the rig's 2 s link watchdog tolerates a host descheduled for
/// 0.75 s (at the former 5×, for 0.15 s). The tests that must not depend on timing at all run
/// the live session in lockstep (`tests/tests/live_session.rs`).
const SPEEDUP: f64 = 2.0;

struct VirtualRig {
    path: String,
    stop: Arc<AtomicBool>,
    thread: Option<thread::JoinHandle<SimRig>>,
    _slave: TTYPort,
}

impl VirtualRig {
    fn start(cfg: SimConfig) -> Self {
        let (mut master, slave) = TTYPort::pair().expect("pty pair");
        master.set_timeout(Duration::from_millis(2)).unwrap();
        let path = slave.name().expect("pty name");
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = thread::spawn(move || {
            let mut rig = SimRig::new(&cfg);
            sim::serve(&mut master, &mut rig, SPEEDUP, &flag).expect("serve");
            rig
        });
        Self { path, stop, thread: Some(thread), _slave: slave }
    }

    fn stop(mut self) -> SimRig {
        self.stop.store(true, Ordering::SeqCst);
        self.thread.take().unwrap().join().expect("rig thread")
    }
}

fn host(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host")).args(args).output().expect("host runs")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("host-live-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn decode(path: &Path) -> capture::Capture {
    capture::decode(&std::fs::read(path).unwrap())
}

#[test]
fn calibrate_over_a_serial_port_records_both_poses_and_calibrates() {
    let rig = VirtualRig::start(SimConfig::standard(11, 1.0));
    let dir = scratch("calibrate");
    let db = format!("sqlite:{}", dir.with_extension("records.sqlite").display());
    let o = host(&[
        "calibrate",
        "--port",
        &rig.path,
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
    ]);
    let rig = rig.stop();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(0) || o.status.code() == Some(3), "{err}");
    for (file, pose) in [("pose1-p180dps.cap", 1), ("pose2-p180dps.cap", 2)] {
        let cap = decode(&dir.join(file));
        assert!(cap.loss.is_clean(), "{file}: {:?}", cap.loss);
        assert_eq!(cap.runs.len(), 1, "{file}");
        let run = &cap.runs[0];
        assert_eq!(run.pose.number(), pose);
        assert!(run.stopped, "{file}: the run ends with RunStopped");
        // ≥ 8 s at speed plus the ramp, at 800 Hz (±1 % ODR error of the simulated gyro).
        assert!(run.samples.len() as f64 >= 8.0 * 800.0 * 0.99, "{file}: {} samples", run.samples.len());
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("calibration.json")).unwrap()).unwrap();
    let truth = rig.truth();
    for i in 0..3 {
        let k = report["axes"][i]["k_counts_per_dps"].as_f64().unwrap();
        let sigma = report["axes"][i]["k_sigma"].as_f64().unwrap();
        let k_true = truth.k_counts_per_dps[i];
        assert!((k - k_true).abs() < 4.0 * sigma, "axis {i}: k {k} ± {sigma} vs truth {k_true}");
    }
    // Provenance: the manifest beside the captures names the sensor and fingerprints each
    // capture; the result carries the same, plus the rig's firmware from its Hello.
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("session.json")).unwrap()).unwrap();
    assert_eq!(manifest["sensor_serial"], "G-LIVE-11");
    assert_eq!(manifest["captures"].as_array().unwrap().len(), 4, "2 poses × 2 default rates");
    let prov = &report["provenance"];
    assert_eq!(prov["sensor_serial"], "G-LIVE-11");
    assert_eq!(prov["operator"], "ci");
    assert_eq!(prov["rig_firmware"], "0.1.0");
    assert_eq!(prov["captures"], manifest["captures"]);
    assert!(err.contains("recorded as 1 in sqlite:"), "{err}");

    // Replayed later without --sensor: the manifest beside the captures names the sensor, and
    // the captures are checked against its fingerprints.
    let caps: Vec<String> = ["pose1-p180dps.cap", "pose1-p90dps.cap", "pose2-p180dps.cap", "pose2-p90dps.cap"]
        .iter()
        .map(|f| dir.join(f).display().to_string())
        .collect();
    let again = dir.join("again");
    let mut args = vec!["calibrate", "--out-dir", again.to_str().unwrap(), "--db", &db, "--replay"];
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
    let rig = VirtualRig::start(SimConfig::standard(12, 1.0));
    let dir = scratch("record");
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("p2.cap");
    let o = host(&[
        "record",
        "--port",
        &rig.path,
        "--out",
        out.to_str().unwrap(),
        "--pose",
        "2",
        "--rate-dps=-90",
        "--duration",
        "3",
    ]);
    rig.stop();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let cap = decode(&out);
    assert!(cap.loss.is_clean(), "{:?}", cap.loss);
    assert!(cap.hello.is_some());
    let run = &cap.runs[0];
    assert_eq!((run.pose.number(), run.commanded_rate_dps()), (2, -90.0));
    // A second recording never overwrites the first.
    let rig = VirtualRig::start(SimConfig::standard(12, 1.0));
    let o = host(&["record", "--port", &rig.path, "--out", out.to_str().unwrap(), "--pose", "1", "--duration", "1"]);
    rig.stop();
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
        let mut child = Command::new(env!("CARGO_BIN_EXE_host"))
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

    /// Waits until standard error shows `text` (a hang guard, not a timing assumption).
    fn wait_for(&mut self, text: &str) {
        let t0 = std::time::Instant::now();
        while !self.seen.iter().any(|l| l.contains(text)) {
            assert!(t0.elapsed() < Duration::from_secs(120), "never printed {text:?}: {:?}", self.seen);
            if let Ok(l) = self.lines.recv_timeout(Duration::from_millis(100)) {
                self.seen.push(l);
            }
        }
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

/// F3/F9: Ctrl-C (SIGINT), SIGTERM or SIGHUP at the mounting prompt ends the session at once
/// with a one-line error; the rig was sent Stop (the motor is safe on every path).
#[test]
fn a_signal_at_the_prompt_aborts_the_session() {
    for sig in ["INT", "TERM", "HUP"] {
        let rig = VirtualRig::start(SimConfig::standard(13, 1.0));
        let dir = scratch(&format!("prompt-{sig}"));
        let mut host = Running::start(
            &[
                "calibrate",
                "--port",
                &rig.path,
                "--sensor",
                "SN-1",
                "--duration",
                "1",
                "--out-dir",
                dir.to_str().unwrap(),
            ],
            std::process::Stdio::piped(), // open, and nobody types
        );
        host.wait_for("Press Enter when ready");
        host.signal(sig);
        let (status, err, took) = host.finish();
        eprintln!("SIG{sig} at the prompt: exit after {took:?}");
        rig.stop();
        assert_eq!(status.code(), Some(1), "SIG{sig}: {err}");
        assert!(err.lines().last().unwrap().starts_with("error: interrupted at the prompt"), "SIG{sig}: {err}");
    }
}

/// F9: SIGTERM mid-run: Stop sent (the simulated rig stops at once and says so: the capture
/// ends with RunStopped), the capture kept, exit 1 with a one-line error.
#[test]
fn sigterm_mid_run_stops_the_rig_and_keeps_the_capture() {
    for sig in ["TERM", "HUP", "INT"] {
        let rig = VirtualRig::start(SimConfig::standard(14, 1.0));
        let dir = scratch(&format!("sig-{sig}"));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("run.cap");
        let host = Running::start(
            &["record", "--port", &rig.path, "--out", out.to_str().unwrap(), "--pose", "1", "--duration", "600"],
            std::process::Stdio::null(),
        );
        // Wait until the run is recording samples.
        let t0 = std::time::Instant::now();
        while !std::fs::read(&out).is_ok_and(|b| decode_bytes(&b).runs.first().is_some_and(|r| r.samples.len() > 100)) {
            assert!(t0.elapsed() < Duration::from_secs(60), "the run never started");
            thread::sleep(Duration::from_millis(20));
        }
        host.signal(sig);
        let (status, err, took) = host.finish();
        eprintln!("SIG{sig} mid-run: exit after {took:?}");
        rig.stop();
        assert_eq!(status.code(), Some(1), "{err}");
        assert!(err.lines().last().unwrap().starts_with("error: interrupted during pose 1"), "{err}");
        let cap = decode(&out);
        assert_eq!(cap.runs.len(), 1);
        assert!(cap.runs[0].stopped, "SIG{sig}: the rig got Stop and confirmed it in the capture");
        assert!(cap.loss.errors.is_empty() && cap.loss.seq_gaps.is_empty(), "{:?}", cap.loss);
    }
}

fn decode_bytes(b: &[u8]) -> capture::Capture {
    capture::decode(b)
}

/// F10: end of standard input at a prompt is an abort, not the operator's Enter.
#[test]
fn end_of_input_at_the_prompt_is_an_abort() {
    let rig = VirtualRig::start(SimConfig::standard(15, 1.0));
    let dir = scratch("eof");
    let host = Running::start(
        &["calibrate", "--port", &rig.path, "--sensor", "SN-1", "--duration", "1", "--out-dir", dir.to_str().unwrap()],
        std::process::Stdio::null(),
    );
    let (status, err, _) = host.finish();
    rig.stop();
    assert_eq!(status.code(), Some(1), "{err}");
    assert!(err.lines().last().unwrap().starts_with("error: standard input ended at the prompt"), "{err}");
    assert!(!dir.join("pose1-p180dps.cap").exists(), "no run was started");
}

/// Starts `host virtual-rig ARGS` and returns it with the pty path it prints first.
fn spawn_virtual_rig(args: &[&str]) -> (std::process::Child, String) {
    use std::io::BufRead;
    let mut rig = Command::new(env!("CARGO_BIN_EXE_host"))
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

/// The documented way to try the live session: `host virtual-rig` in one terminal, `host
/// calibrate --port` in another, the operator pressing Enter at each prompt (standard input read
/// while the port is drained), over a line that loses a byte in a thousand and the first Start's
/// Ack. Both captures are kept, each one run without a fault, and the session calibrates.
#[test]
fn calibrate_against_host_virtual_rig_with_an_operator_at_the_keyboard() {
    use std::io::Write;
    let (mut rig, path) = spawn_virtual_rig(&["--speedup", &SPEEDUP.to_string(), "--loss", "1e-3", "--drop", "Ack:2"]);
    let dir = scratch("keyboard");
    let mut host = Running::start(
        &[
            "calibrate",
            "--port",
            &path,
            "--sensor",
            "SN-1",
            "--duration",
            "4",
            "--rates-dps",
            "180",
            "--out-dir",
            dir.to_str().unwrap(),
        ],
        std::process::Stdio::piped(),
    );
    let mut stdin = host.child.stdin.take().unwrap();
    // The operator first confirms the sensor's serial, then mounts each pose.
    host.wait_for("Sensor under calibration: SN-1");
    writeln!(stdin).unwrap();
    host.wait_for("POSE 1");
    host.wait_for("Press Enter when ready");
    writeln!(stdin).unwrap();
    host.wait_for("POSE 2");
    writeln!(stdin).unwrap();
    let (status, err, _) = host.finish();
    let _ = rig.kill();
    let _ = rig.wait();
    assert!(matches!(status.code(), Some(0) | Some(3)), "{err}");
    for file in ["pose1-p180dps.cap", "pose2-p180dps.cap"] {
        let cap = decode(&dir.join(file));
        assert_eq!(cap.runs.len(), 1, "{file}");
        assert!(cap.runs[0].faults.is_empty() && cap.faults.is_empty(), "{file}: {:?}", cap.runs[0].faults);
    }
}
