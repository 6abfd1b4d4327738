//! The `host` binary's contract with its user: exit codes and one-line errors that say what and
//! where.

use std::process::{Command, Output};

fn host(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host")).args(args).output().expect("host runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn a_missing_port_is_one_line_naming_it() {
    let dir = std::env::temp_dir().join(format!("host-cli-{}", std::process::id()));
    let out = dir.join("never.cap");
    let o = host(&["record", "--port", "/dev/ttyNOPE9", "--out", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.starts_with("error: cannot open serial port /dev/ttyNOPE9: "), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(!out.exists(), "no capture file is created when the port cannot be opened");
}

#[test]
fn a_missing_capture_is_one_line_naming_it() {
    let o = host(&["inspect", "/nonexistent/run.cap"]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(stderr(&o), "error: cannot read capture /nonexistent/run.cap: No such file or directory (os error 2)\n");
}

#[test]
fn a_wrong_option_is_a_usage_error() {
    let o = host(&["record", "--port", "/dev/null", "--out", "x.cap", "--pose", "3"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("pose must be 1 or 2, not \"3\""), "{}", stderr(&o));
    let o = host(&["calibrat"]);
    assert_eq!(o.status.code(), Some(2));
}

fn scratch(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("host-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn simulate_inspect_calibrate_apply() {
    let dir = scratch("flow");
    let cap = dir.join("s.cap");
    let o = host(&["simulate", "--out", cap.to_str().unwrap(), "--seed", "5", "--duration", "6"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("s.truth.json")).unwrap()).unwrap();
    assert_eq!(truth["seed"], 5);

    let o = host(&["inspect", cap.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("  gyro: ±500 °/s, ODR 800 Hz, bandwidth Bw3 (110.0 Hz cut-off)\n"), "{text}");
    assert!(text.contains("0 frames missing (sequence gaps), 0 bytes in 0 bad stretches"), "{text}");
    assert_eq!(text.matches("  run pose ").count(), 2, "{text}");

    let out = dir.join("cal");
    let o = host(&["calibrate", "--replay", cap.to_str().unwrap(), "--out-dir", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let cal = out.join("calibration.json");
    assert!(cal.exists());

    // A raw reading made from the truth's own M and offsets comes back as the rate it encodes,
    // to within the calibration's error (6 s per pose: σ_k ≈ 0.01 %, tilt σ ≈ 0.005°).
    let m = &truth["m_counts_per_dps"];
    let off = &truth["offset_counts"];
    let w = [100.0, -50.0, 30.0];
    let raw: Vec<String> = (0..3)
        .map(|i| {
            let v: f64 = (0..3).map(|j| m[i][j].as_f64().unwrap() * w[j]).sum::<f64>() + off[i].as_f64().unwrap();
            format!("{}", v.round() as i16)
        })
        .collect();
    let o = host(&["apply", "--cal", cal.to_str().unwrap(), "--counts", &raw.join(",")]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let got: Vec<f64> = String::from_utf8_lossy(&o.stdout).trim().split(',').map(|x| x.parse().unwrap()).collect();
    for i in 0..3 {
        assert!((got[i] - w[i]).abs() < 0.05, "axis {i}: {got:?} vs {w:?}");
    }

    // The same calibration over a whole capture: one CSV line per sample, plus the header.
    let o = host(&["apply", "--cal", cal.to_str().unwrap(), "--capture", cap.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0));
    let csv = String::from_utf8_lossy(&o.stdout);
    assert_eq!(csv.lines().next(), Some("t_s,pose,x_dps,y_dps,z_dps"));
    let samples = truth["runs"].as_array().unwrap().iter().map(|r| r["samples"].as_u64().unwrap()).sum::<u64>();
    assert_eq!(csv.lines().count() as u64, samples + 1);
}

#[test]
fn a_capture_without_pose_two_fails_naming_it() {
    let dir = scratch("onepose");
    let cap = dir.join("p1.cap");
    let o = host(&["simulate", "--out", cap.to_str().unwrap(), "--poses", "1", "--duration", "3"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = host(&["calibrate", "--replay", cap.to_str().unwrap(), "--out-dir", dir.join("c").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let last = stderr(&o).lines().last().unwrap().to_string();
    assert_eq!(
        last,
        "error: calibration failed: only pose 1 was captured: pose 2 is needed too (axis directions need both poses)"
    );
}

#[test]
fn an_unknown_effect_is_refused_with_the_list() {
    let dir = scratch("effect");
    let o = host(&["simulate", "--out", dir.join("x.cap").to_str().unwrap(), "--effect", "wobble"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).starts_with("error: unknown effect \"wobble\"; known: filter_delay, delay_ms, "),
        "{}",
        stderr(&o)
    );
}

/// F10: a duration or rate that is not a finite number is a usage error (exit 2) naming it:
/// `nan` seconds would record forever, `nan` °/s would send 0.
#[test]
fn non_finite_durations_and_rates_are_usage_errors() {
    for args in [
        &["calibrate", "--port", "/dev/null", "--duration", "nan"][..],
        &["calibrate", "--port", "/dev/null", "--duration", "inf"],
        &["calibrate", "--port", "/dev/null", "--duration=-3"],
        &["calibrate", "--port", "/dev/null", "--rates-dps", "180,nan"],
        &["calibrate", "--port", "/dev/null", "--rates-dps", "0"],
        &["calibrate", "--port", "/dev/null", "--rates-dps", "400"],
        &["record", "--port", "/dev/null", "--out", "/nonexistent/x.cap", "--rate-dps", "nan"],
        &["record", "--port", "/dev/null", "--out", "/nonexistent/x.cap", "--duration", "NaN"],
    ] {
        let o = host(args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.starts_with("error: invalid value"), "{args:?}: {err}");
        assert!(err.contains("is not a duration") || err.contains("is not a rate"), "{args:?}: {err}");
    }
}

/// F7: the same capture given twice (here once under another name) is refused, naming both:
/// counted twice it would shrink every σ by √2.
#[test]
fn duplicate_runs_are_refused_naming_both() {
    let dir = std::env::temp_dir().join(format!("host-cli-dup-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let a = dir.join("a.cap");
    let o = host(&["simulate", "--out", a.to_str().unwrap(), "--duration", "6", "--seed", "5"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let b = dir.join("b.cap");
    std::fs::copy(&a, &b).unwrap();
    let out = dir.join("out");
    let o =
        host(&["calibrate", "--replay", a.to_str().unwrap(), b.to_str().unwrap(), "--out-dir", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    let last = err.lines().last().unwrap();
    assert_eq!(
        last,
        format!(
            "error: run 1 of {} (pose 1, +180.0 °/s) is the same data as run 1 of {}: give each capture once",
            b.display(),
            a.display()
        )
    );
}
