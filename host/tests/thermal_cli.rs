//! The thermal session through the `host` binary (issue 27): `simulate --chamber-c` writes one
//! folder per setpoint and the manifest, `calibrate --replay <folder>` fits the thermal model
//! into `calibration.json`, and `apply --temp-c` uses it inside its range and refuses outside.

mod common;
use common::host_command;
use std::process::Output;

fn host(args: &[&str]) -> Output {
    host_command().args(args).output().expect("host runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn simulate_calibrate_and_apply_a_thermal_session() {
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("thermal");
    let out = dir.path().join("cal");
    let (sim_s, out_s) = (sim.to_str().unwrap(), out.to_str().unwrap());
    // Short runs: the test checks the plumbing; the bars are the library's test and the bench.
    let o = host(&["simulate", "--out", sim_s, "--chamber-c", "-20,0,25,50,70", "--duration", "8", "--seed", "2"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    for d in ["sp1_m20c", "sp3_25c", "sp5_70c"] {
        assert!(sim.join(d).join("session.cap").is_file() && sim.join(d).join("session.truth.json").is_file());
    }
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sim.join("thermal.json")).unwrap()).unwrap();
    assert_eq!(manifest["setpoints"][0]["setpoint_c"], -20.0);
    assert!(manifest["setpoints"][4]["settle_s"].as_f64().unwrap() > 1200.0, "a full settle window at least");

    let o = host(&["calibrate", "--replay", sim_s, "--out-dir", out_s, "--no-db"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("Thermal model: 5 setpoints"), "{text}");
    assert_eq!(text.lines().filter(|l| l.contains(" held out ")).count(), 60, "{text}");
    let cal: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap()).unwrap();
    assert_eq!(cal["thermal"]["curves"].as_array().unwrap().len(), 12);
    assert_eq!(cal["thermal_base_setpoint_c"], 25.0);
    assert!(out.join("sp2_0c").join("report.html").is_file());
    let page = std::fs::read_to_string(out.join("thermal.html")).unwrap();
    assert_eq!(page.matches("<svg").count(), 12, "one figure per quantity and axis");

    let cal_s = out.join("calibration.json");
    let cal_s = cal_s.to_str().unwrap();
    let rate = |t: &str| {
        let o = host(&["apply", "--cal", cal_s, "--counts", "5700,-2850,8550", "--temp-c", t]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).trim().split(',').map(|v| v.parse::<f64>().unwrap()).collect::<Vec<_>>()
    };
    // The same reading means a different rate at −10 °C and at 60 °C (the offsets move by
    // ≈ 0.03 °/s/°C, the sensitivities by ≈ 100 ppm/°C).
    let (cold, warm) = (rate("-10"), rate("60"));
    assert!((cold[0] - warm[0]).abs() > 1.0, "{cold:?} vs {warm:?}");
    let o = host(&["apply", "--cal", cal_s, "--counts", "1,2,3", "--temp-c", "80"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("outside the calibrated range") && stderr(&o).contains("not extrapolated"),
        "{}",
        stderr(&o)
    );
    assert_eq!(stderr(&o).lines().count(), 1);
    // A calibration without a thermal model says so.
    let plain = out.join("sp1_m20c").join("calibration.json");
    let o = host(&["apply", "--cal", plain.to_str().unwrap(), "--counts", "1,2,3", "--temp-c", "0"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("holds no thermal model"), "{}", stderr(&o));
}

#[test]
fn bad_setpoints_are_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("t");
    let o = host(&["simulate", "--out", sim.to_str().unwrap(), "--chamber-c", "-60,25"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("−40…85 °C"), "{}", stderr(&o));
    let o = host(&["simulate", "--out", sim.to_str().unwrap(), "--chamber-c", "0,nan"]);
    assert_eq!(o.status.code(), Some(2));
    // Two setpoints cannot hold one out: the replay refuses in one line.
    let o = host(&["simulate", "--out", sim.to_str().unwrap(), "--chamber-c", "0,40", "--duration", "5"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = dir.path().join("cal");
    let o = host(&["calibrate", "--replay", sim.to_str().unwrap(), "--out-dir", out.to_str().unwrap(), "--no-db"]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.lines().last().unwrap().contains("needs at least 3"), "{err}");
}
