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

/// Simulated seconds per wall-clock second: keeps the rig's 2 s link watchdog well above the
/// host's 0.25 s heartbeat interval (0.25 × 5 = 1.25 s of simulated time).
const SPEEDUP: f64 = 5.0;

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
    assert_eq!(last, format!("error: no answer from the rig on {path} within 2 s (command Identify)"));
    // The empty capture of the run that never started is kept, not deleted.
    assert!(dir.join("pose1-p180dps.cap").exists());
}
