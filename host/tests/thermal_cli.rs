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

    let db = format!("sqlite:{}", dir.path().join("records.sqlite").display());
    let o = host(&["calibrate", "--replay", sim_s, "--out-dir", out_s, "--db", &db, "--sensor", "G-27"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("thermal model recorded as 6 in sqlite:"), "{}", stderr(&o));
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
    records_and_exports_hold_the_model(&db, cal_s, &cal);
    // A calibration without a thermal model says so.
    let plain = out.join("sp1_m20c").join("calibration.json");
    let o = host(&["apply", "--cal", plain.to_str().unwrap(), "--counts", "1,2,3", "--temp-c", "0"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("holds no thermal model"), "{}", stderr(&o));
}

/// The thermal calibration's record (after the five setpoints' own) holds the model: `records
/// show` prints its range and coefficients, JSON the same numbers as `calibration.json`, and
/// compared with the 25 °C setpoint's record it has coefficients the other has not; `export`
/// writes the C and Rust forms with the OUT_TEMP input and the range.
fn records_and_exports_hold_the_model(db: &str, cal_path: &str, cal: &serde_json::Value) {
    let o = host(&["records", "--db", db, "list"]);
    assert_eq!(String::from_utf8_lossy(&o.stdout).lines().count(), 7, "{}", String::from_utf8_lossy(&o.stdout));
    let o = host(&["records", "--db", db, "show", "6"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("thermal model: setpoints -20, 0, 25, 50, 70 °C; holds for die"), "{text}");
    assert!(text.contains("thermal_offset_x_c1"), "{text}");
    let o = host(&["records", "--db", db, "--format", "json", "show", "6"]);
    let shown: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let slope =
        shown["thermal"]["coefficients"].as_array().unwrap().iter().find(|c| c["name"] == "thermal_offset_x_c1");
    let x_offset = &cal["thermal"]["curves"][0];
    assert_eq!(x_offset["quantity"], "offset_counts");
    assert_eq!(slope.unwrap()["value"], x_offset["coef"][1]["value"]);
    assert_eq!(shown["thermal"]["range_c"], cal["thermal"]["range_c"]);
    let o = host(&["records", "--db", db, "compare", "3", "6"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("only B holds a thermal model"), "{text}");
    let o = host(&["export", "--cal", cal_path, "--format", "c"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let header = String::from_utf8_lossy(&o.stdout);
    assert!(
        header.contains("static inline int gyrocal_apply(const int16_t raw[3], int8_t temp_raw, float rate_dps[3])")
    );
    assert!(header.contains("Valid for temp_raw "), "{header}");
    c_header_agrees_with_apply(&header, cal_path, cal["thermal"]["out_temp_at_0c"].as_f64().unwrap());
    let o = host(&["export", "--cal", cal_path, "--format", "rust"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("pub fn apply(&self, raw: [i16; 3], temp_raw: i8)"));
}

/// The exported header, compiled, at the OUT_TEMP reading of a 40 °C die gives what `host apply
/// --temp-c` prints at that reading's die temperature (`out_temp_at_0c − reading`), to the
/// printed 1e-4 °/s; at a reading beyond the range it returns the error code.
fn c_header_agrees_with_apply(header: &str, cal_path: &str, out_temp_at_0c: f64) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("gyrocal.h"), header).unwrap();
    let main = r#"#include <stdio.h>
#include <stdlib.h>
#include "gyrocal.h"
int main(int argc, char **argv) {
    const int16_t raw[3] = {5700, -2850, 8550};
    float w[3];
    const int status = gyrocal_apply(raw, (int8_t)atoi(argv[1]), w);
    printf("%d %.6f %.6f %.6f\n", status, w[0], w[1], w[2]);
    return 0;
}
"#;
    std::fs::write(dir.path().join("main.c"), main).unwrap();
    let exe = dir.path().join("apply");
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let o = std::process::Command::new(&cc)
        .args(["-std=c99", "-Wall", "-Werror", "-O2", "-o"])
        .arg(&exe)
        .arg(dir.path().join("main.c"))
        .arg("-lm")
        .output()
        .expect("the C compiler runs");
    assert!(o.status.success(), "{}", stderr(&o));
    let run = |reading: i32| -> Vec<f64> {
        let o = std::process::Command::new(&exe).arg(reading.to_string()).output().unwrap();
        String::from_utf8_lossy(&o.stdout).split_whitespace().map(|v| v.parse::<f64>().unwrap_or(f64::NAN)).collect()
    };
    let reading = (out_temp_at_0c - 40.0).round() as i32;
    let got = run(reading);
    let temp_c = format!("{}", out_temp_at_0c - f64::from(reading));
    let o = host(&["apply", "--cal", cal_path, "--counts", "5700,-2850,8550", "--temp-c", &temp_c]);
    let want: Vec<f64> = String::from_utf8_lossy(&o.stdout).trim().split(',').map(|v| v.parse().unwrap()).collect();
    assert_eq!(got[0], 0.0);
    for i in 0..3 {
        assert!((got[i + 1] - want[i]).abs() <= 1e-4, "axis {i}: C {} vs host apply {}", got[i + 1], want[i]);
    }
    let beyond = run((out_temp_at_0c - 90.0).round() as i32);
    assert_eq!(beyond[0], 1.0, "a 90 °C die is outside −20…70 °C: {beyond:?}");
    assert!(beyond[1].is_nan());
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
