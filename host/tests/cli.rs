//! The `host` binary's contract with its user: exit codes and one-line errors that say what and
//! where.

use std::process::{Command, Output};

fn host(args: &[&str]) -> Output {
    host_command().args(args).output().expect("host runs")
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
    // Without a source, both sources are named.
    let o = host(&["calibrate"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("<--port <PORT>|--replay <REPLAY>...>"), "{}", stderr(&o));
}

/// `--static-s` is a live option with a positive duration.
#[test]
fn static_s_is_live_only_and_positive() {
    let o = host(&["calibrate", "--replay", "x.cap", "--static-s", "60"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o)
            .starts_with("error: the argument '--replay <REPLAY>...' cannot be used with '--static-s <STATIC_S>'"),
        "{}",
        stderr(&o)
    );
    let o = host(&["calibrate", "--port", "/dev/null", "--sensor", "S", "--static-s", "0"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("invalid value '0' for '--static-s <STATIC_S>': \"0\" is not a duration"),
        "{}",
        stderr(&o)
    );
}

/// `configure-drive` checks the protocol's limits before it opens the port.
#[test]
fn configure_drive_refuses_values_outside_the_protocols_limits() {
    for (args, msg) in [
        (["--gear-ratio", "0.5", "--load-inertia-kgm2", "0.012"], "invalid value '0.5' for '--gear-ratio <GEAR_RATIO>': \"0.5\" is not a gear ratio from 1 to 500"),
        (["--gear-ratio", "66", "--load-inertia-kgm2", "nan"], "invalid value 'nan' for '--load-inertia-kgm2 <LOAD_INERTIA_KGM2>': \"nan\" is not an inertia from 0.0001 to 1 kg·m²"),
    ] {
        let o = host(&[&["configure-drive", "--port", "/dev/null"][..], &args[..]].concat());
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).starts_with(&format!("error: {msg}")), "{}", stderr(&o));
    }
    let o = host(&[
        "configure-drive",
        "--port",
        "/dev/null",
        "--gear-ratio",
        "66",
        "--load-inertia-kgm2",
        "0.012",
        "--supply-v",
        "60",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("\"60\" is not a supply from 6 to 48 V"), "{}", stderr(&o));
}

/// The simulator cannot promise what the firmware refuses: its rate limit is the protocol's.
#[test]
fn simulate_refuses_a_rate_the_rig_refuses() {
    let tmp = scratch("fast");
    let out = tmp.path().join("fast.cap");
    let o = host(&["simulate", "--rates-dps", "500", "--out", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(
        stderr(&o),
        "error: invalid simulation: runs[0].rate_dps must be within ±360 °/s, the rig's limit (0: a static run, for noise figures)\n"
    );
    assert!(!out.exists());
}

/// `--drawn-rig`: the seed's rig has every effect of a real one, drawn from its own stream (the
/// sensor is the one the same seed gives without it), and `--effect NAME=VALUE` still sets one;
/// `--drawn-rig=3` grows the same rig, and a scale past 10 is refused before a file is made.
#[test]
fn simulate_draws_a_rig_per_seed_and_keeps_the_seeds_sensor() {
    let tmp = scratch("drawn");
    let truth = |name: &str, extra: &[&str]| -> serde_json::Value {
        let out = tmp.path().join(format!("{name}.cap"));
        let mut args = vec!["simulate", "--seed", "3", "--duration", "5", "--out", out.to_str().unwrap()];
        args.extend(extra);
        let o = host(&args);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        serde_json::from_str(&std::fs::read_to_string(out.with_extension("truth.json")).unwrap()).unwrap()
    };
    let plain = truth("plain", &[]);
    let drawn = truth("drawn", &["--drawn-rig"]);
    let tilted = truth("tilted", &["--drawn-rig", "--effect", "table_tilt=0.25"]);
    let expected = host::sim::Effects::drawn(&mut host::sim::effects_rng(3));
    let effects: host::sim::Effects = serde_json::from_value(drawn["effects"].clone()).unwrap();
    assert_eq!(effects, expected);
    assert_eq!(drawn["m_counts_per_dps"], plain["m_counts_per_dps"]);
    let tilted: host::sim::Effects = serde_json::from_value(tilted["effects"].clone()).unwrap();
    assert_eq!(tilted.table_tilt.unwrap().tilt_deg, 0.25);
    assert_eq!(host::sim::Effects { table_tilt: expected.table_tilt, ..tilted }, expected);
    let grown = truth("grown", &["--drawn-rig=3"]);
    let grown: host::sim::Effects = serde_json::from_value(grown["effects"].clone()).unwrap();
    assert_eq!(grown, host::sim::Effects::drawn_scaled(&mut host::sim::effects_rng(3), 3.0));
    let out = tmp.path().join("too-big.cap");
    let o = host(&["simulate", "--seed", "3", "--duration", "5", "--drawn-rig=11", "--out", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).starts_with("error: invalid value '11' for '--drawn-rig[=<SCALE>]': 11 is outside 0-10\n"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
}

/// Issue 28: `--duration 1e12` wrote 4.27 GB in 57 s before it was killed; a run is now at most
/// 6 h (`sim::MAX_RUN_S`), refused before any file is created.
#[test]
fn simulate_refuses_a_run_longer_than_six_hours() {
    let tmp = scratch("long");
    let out = tmp.path().join("long.cap");
    for duration in ["1e12", "21600.5"] {
        let o = host(&["simulate", "--duration", duration, "--out", out.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(2), "{duration}");
        assert_eq!(
            stderr(&o),
            "error: invalid simulation: runs[0].duration_s must be > 0 and at most 21600 s (6 h: ≈ 400 MB of capture per run)\n"
        );
        assert!(!out.exists());
    }
}

/// Issue 28: a live session whose port cannot be opened leaves nothing in its --out-dir (no
/// `session.json`), so the same command succeeds once the port is there: the retry gets the
/// same one line, not "already holds a session".
#[test]
fn a_port_that_cannot_be_opened_leaves_no_session_behind() {
    let tmp = scratch("noport");
    let dir = tmp.path().join("session");
    let db = format!("sqlite:{}", tmp.path().join("records.sqlite").display());
    for attempt in 1..=2 {
        let o = host(&[
            "calibrate",
            "--port",
            "/dev/ttyNOPE9",
            "--sensor",
            "SN-1",
            "--yes",
            "--out-dir",
            dir.to_str().unwrap(),
            "--db",
            &db,
        ]);
        assert_eq!(o.status.code(), Some(1), "attempt {attempt}");
        assert_eq!(
            stderr(&o),
            "error: cannot open serial port /dev/ttyNOPE9: No such file or directory\n",
            "attempt {attempt}"
        );
        assert!(!dir.join("session.json").exists(), "attempt {attempt}");
    }
}

/// A fresh directory for one test, removed when dropped (also when the test fails).
fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new().prefix(&format!("host-cli-{name}-")).tempdir().expect("temporary directory")
}

#[test]
fn simulate_inspect_calibrate_apply() {
    let tmp = scratch("flow");
    let dir = tmp.path();
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
    let db = format!("sqlite:{}", dir.join("records.sqlite").display());
    let o = host(&[
        "calibrate",
        "--replay",
        cap.to_str().unwrap(),
        "--out-dir",
        out.to_str().unwrap(),
        "--sensor",
        "SIM-5",
        "--operator",
        "ada",
        "--rig",
        "sim",
        "--db",
        &db,
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let cal = out.join("calibration.json");
    assert!(cal.exists());
    let summary = String::from_utf8_lossy(&o.stdout);
    assert!(summary.starts_with("Sensor: SIM-5   operator: ada   rig: sim\n"), "{summary}");
    assert!(stderr(&o).contains("recorded as 1 in sqlite:"), "{}", stderr(&o));

    // Provenance in the result: the capture's SHA-256 and the simulated rig's firmware.
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&cal).unwrap()).unwrap();
    let prov = &report["provenance"];
    assert_eq!(prov["sensor_serial"], "SIM-5");
    assert_eq!(prov["rig_firmware"], "0.1.0");
    assert_eq!(prov["gyro"]["odr"], "Hz800");
    let sha = prov["captures"][0]["sha256"].as_str().unwrap();
    assert_eq!(sha.len(), 64);

    // The records: listed, shown, compared with a second calibration of the same capture (every
    // parameter identical: z = 0).
    let o = host(&["records", "--db", &db, "list"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let list = String::from_utf8_lossy(&o.stdout);
    assert_eq!(list.lines().count(), 2, "{list}");
    assert!(list.lines().nth(1).unwrap().trim_start().starts_with("1  SIM-5 "), "{list}");
    let o = host(&["records", "--db", &db, "show", "1"]);
    let show = String::from_utf8_lossy(&o.stdout);
    assert!(show.contains(&format!("capture 1 sha256 {sha}")), "{show}");
    let again = dir.join("cal2");
    let o = host(&[
        "calibrate",
        "--replay",
        cap.to_str().unwrap(),
        "--out-dir",
        again.to_str().unwrap(),
        "--sensor",
        "SIM-5",
        "--db",
        &db,
        "--again",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // A third session with a static capture beside the moving one: noise figures in the result,
    // the record and the Kalibr export (ARW 60 ρ/√2 = 1.27 °/√h, see allan.rs).
    let still = dir.join("still.cap");
    let o = host(&[
        "simulate",
        "--out",
        still.to_str().unwrap(),
        "--seed",
        "5",
        "--poses",
        "1",
        "--rates-dps",
        "0",
        "--duration",
        "20",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let third = dir.join("cal3");
    let o = host(&[
        "calibrate",
        "--replay",
        cap.to_str().unwrap(),
        still.to_str().unwrap(),
        "--out-dir",
        third.to_str().unwrap(),
        "--sensor",
        "SIM-5",
        "--db",
        &db,
        "--again",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("\nNoise figures:\n"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let r3: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(third.join("calibration.json")).unwrap()).unwrap();
    let arw = r3["noise"]["axes"][2]["arw_deg_per_sqrt_h"].as_f64().unwrap();
    assert!((arw / 1.2728 - 1.0).abs() < 0.1, "{arw}");
    let show3 = String::from_utf8_lossy(&host(&["records", "--db", &db, "show", "3"]).stdout).into_owned();
    assert!(show3.contains("axis  ARW [°/√h]"), "{show3}");
    let o = host(&["export", "--cal", third.join("calibration.json").to_str().unwrap(), "--format", "kalibr"]);
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("\ngyroscope_noise_density: "),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let html = std::fs::read_to_string(third.join("report.html")).unwrap();
    assert!(html.contains("<h2>Calibration certificate</h2>") && html.contains("SIM-5"));
    assert!(html.contains("<h2>Noise figures</h2>") && html.contains("Overlapping Allan deviation"));

    let o = host(&["records", "--db", &db, "compare", "1", "2"]);
    let cmp = String::from_utf8_lossy(&o.stdout);
    assert!(cmp.contains("0 of 33 parameters changed by more than 3 σ"), "{cmp}");

    // Exports: every format from the same file; the JSON one carries the same M.
    for format in ["c", "rust", "kalibr", "json", "csv"] {
        let o = host(&["export", "--cal", cal.to_str().unwrap(), "--format", format]);
        assert_eq!(o.status.code(), Some(0), "{format}: {}", stderr(&o));
        assert!(String::from_utf8_lossy(&o.stdout).contains("SIM-5"), "{format}");
    }
    let exported = dir.join("cal.json");
    let o = host(&["export", "--cal", cal.to_str().unwrap(), "--format", "json", "--out", exported.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0));
    let j: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&exported).unwrap()).unwrap();
    assert_eq!(j["parameters"]["m_xy"]["value"], report["m_counts_per_dps"][0][1]);

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

    // Issue 28: a file that holds no sample (garbage, or an empty capture) is refused with one
    // line, exit 1, instead of a header-only CSV and exit 0.
    let garbage = tmp.path().join("garbage.cap");
    std::fs::write(&garbage, (0..5000u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect::<Vec<_>>())
        .unwrap();
    let o = host(&["apply", "--cal", cal.to_str().unwrap(), "--capture", garbage.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(o.stdout, b"");
    assert_eq!(
        stderr(&o),
        format!(
            "error: {} holds no sample of any run (5000 bytes, 0 valid frames, 0 runs): nothing to apply the calibration to\n",
            garbage.display()
        )
    );

    // The same calibration over a whole capture: one CSV line per sample, plus the header.
    let o = host(&["apply", "--cal", cal.to_str().unwrap(), "--capture", cap.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0));
    let csv = String::from_utf8_lossy(&o.stdout);
    assert_eq!(csv.lines().next(), Some("t_s,pose,x_dps,y_dps,z_dps"));
    let samples = truth["runs"].as_array().unwrap().iter().map(|r| r["samples"].as_u64().unwrap()).sum::<u64>();
    assert_eq!(csv.lines().count() as u64, samples + 1);
}

/// A records database that cannot be reached never costs the calibration: the files are
/// written, the one-line error says where they are and what refused, exit 1.
#[test]
fn an_unreachable_database_keeps_the_files_and_exits_1() {
    let tmp = scratch("nodb");
    let dir = tmp.path();
    let cap = dir.join("s.cap");
    // 6 s per pose: shorter runs leave the gear ratio's σ undefined (NaN, written as null), which
    // `apply` cannot read back (a known limitation of the report, not of the records).
    let o = host(&["simulate", "--out", cap.to_str().unwrap(), "--seed", "6", "--duration", "6"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = dir.join("cal");
    // Port 1 on the loopback: nothing listens there, the connection is refused at once.
    let o = host(&[
        "calibrate",
        "--replay",
        cap.to_str().unwrap(),
        "--out-dir",
        out.to_str().unwrap(),
        "--db",
        "postgres://gyrocal:pw@127.0.0.1:1/records",
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    let last = err.lines().last().unwrap();
    assert!(
        last.starts_with(&format!(
            "error: the calibration is saved in {} but was not recorded in postgres://gyrocal:***@127.0.0.1:1/records: cannot connect to",
            out.display()
        )),
        "{err}"
    );
    assert!(!err.contains(":pw@"), "the password is not printed: {err}");
    assert!(out.join("calibration.json").exists() && out.join("report.html").exists());
    // An older calibration.json, without provenance, still exports and applies.
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap()).unwrap();
    v.as_object_mut().unwrap().remove("provenance");
    let old = dir.join("old.json");
    std::fs::write(&old, v.to_string()).unwrap();
    let o = host(&["export", "--cal", old.to_str().unwrap(), "--format", "c"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("#define GYROCAL_SENSOR_SERIAL \"unknown\""));
    assert_eq!(host(&["apply", "--cal", old.to_str().unwrap(), "--counts", "0,0,0"]).status.code(), Some(0));
}

/// `host noise` on a simulated static run prints the three figures per axis.
#[test]
fn noise_of_a_simulated_static_run() {
    let tmp = scratch("noise");
    let dir = tmp.path();
    let cap = dir.join("static.cap");
    let o = host(&["simulate", "--out", cap.to_str().unwrap(), "--poses", "1", "--rates-dps", "0", "--duration", "20"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = host(&["noise", "--capture", cap.to_str().unwrap(), "--json"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["axes"].as_array().unwrap().len(), 3);
    // 60 ρ/√2 with ρ = 0.03 °/s/√Hz (see allan.rs): 1.27 °/√h, within the part's ±5 % in k
    // and the estimate's few % at 20 s.
    let arw = r["axes"][0]["arw_deg_per_sqrt_h"].as_f64().unwrap();
    assert!((arw / 1.2728 - 1.0).abs() < 0.1, "{arw}");
    // As text: three significant digits, and a term the 20-s curve cannot show is "none seen",
    // never 0.000.
    let o = host(&["noise", "--capture", cap.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(!text.contains(" 0.000 "), "{text}");
    assert!(
        text.contains(&format!("  x   {:>10}", format!("{:.2}", r["axes"][0]["arw_deg_per_sqrt_h"].as_f64().unwrap()))),
        "{text}"
    );
    // A capture without a static stretch says how to record one.
    let moving = dir.join("moving.cap");
    assert_eq!(host(&["simulate", "--out", moving.to_str().unwrap(), "--duration", "3"]).status.code(), Some(0));
    let o = host(&["noise", "--capture", moving.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("host simulate --poses 1 --rates-dps 0"), "{}", stderr(&o));
}

#[test]
fn a_capture_without_pose_two_fails_naming_it() {
    let tmp = scratch("onepose");
    let dir = tmp.path();
    let cap = dir.join("p1.cap");
    let o = host(&["simulate", "--out", cap.to_str().unwrap(), "--poses", "1", "--duration", "3"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let db = format!("sqlite:{}", dir.join("records.sqlite").display());
    let o = host(&[
        "calibrate",
        "--replay",
        cap.to_str().unwrap(),
        "--out-dir",
        dir.join("c").to_str().unwrap(),
        "--db",
        &db,
    ]);
    assert_eq!(o.status.code(), Some(1));
    let last = stderr(&o).lines().last().unwrap().to_string();
    assert_eq!(
        last,
        "error: calibration failed: only pose 1 was captured: pose 2 is needed too (axis directions need both poses)"
    );
}

#[test]
fn an_unknown_effect_is_refused_with_the_list() {
    let tmp = scratch("effect");
    let dir = tmp.path();
    let o = host(&["simulate", "--out", dir.join("x.cap").to_str().unwrap(), "--effect", "wobble"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).starts_with(
            "error: unknown effect \"wobble\"; known: filter_delay, filter_order, filter_cutoff_hz, delay_ms, "
        ),
        "{}",
        stderr(&o)
    );
}

/// `host simulate --help` names every effect `--effect` takes (the list is written out in
/// `cli.rs`'s doc comment; this keeps it whole).
#[test]
fn simulate_help_lists_every_effect() {
    let o = host(&["simulate", "--help"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let help = String::from_utf8_lossy(&o.stdout).into_owned();
    let words: Vec<&str> = help.split(|c: char| c.is_whitespace() || c == ',' || c == '.').collect();
    for (name, _) in host::sim::Effects::NAMES {
        assert!(words.contains(&name), "{name} missing: {help}");
    }
}

/// A simulation config that cannot be read or simulated is a usage error (exit 2) with one
/// `error:` line naming the file or the field, never a panic; nothing is written.
#[test]
fn a_bad_simulation_config_is_a_usage_error_naming_the_field() {
    let tmp = scratch("bad-config");
    let dir = tmp.path();
    let out = dir.join("x.cap");
    let config = dir.join("c.json");
    let gyro = r#""gyro":{"full_scale":"Dps500","odr":"Hz800","bandwidth":"Bw3"}"#;
    let cases = [
        (
            format!(
                r#"{{"seed":1,"runs":[{{"pose":"One","rate_dps":180.0,"duration_s":-1.0}}],{gyro},"noise_dps_per_sqrt_hz":0.03,"effects":{{}},"spin_up_s":1.0,"gap_s":0.5,"start_t_us":0,"start_encoder":0,"index_plate_width_deg":10.0}}"#
            ),
            "error: invalid simulation: runs[0].duration_s must be > 0 and at most 21600 s (6 h: ≈ 400 MB of capture per run)\n".to_string(),
        ),
        (
            r#"{"seed":1,"runs":[]}"#.to_string(),
            format!(
                "error: {} is not a simulation config: missing field `gyro` at line 1 column 20\n",
                config.display()
            ),
        ),
    ];
    for (text, expected) in cases {
        std::fs::write(&config, text).unwrap();
        let o = host(&["simulate", "--out", out.to_str().unwrap(), "--config", config.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert_eq!(stderr(&o), expected);
        assert!(!out.exists());
    }
}

/// `host virtual-rig` with a setting it cannot serve: one `error:` line naming the option and
/// what it must be, exit 2, and no pty served (nothing on standard output).
#[test]
fn a_bad_virtual_rig_setting_is_a_usage_error() {
    for (args, expected) in [
        (
            &["virtual-rig", "--speedup", "0"][..],
            "invalid value '0' for '--speedup <SPEEDUP>': \"0\" is not a positive number",
        ),
        (
            &["virtual-rig", "--loss", "1"],
            "invalid value '1' for '--loss <LOSS>': \"1\" is not a probability in [0, 1)",
        ),
        (
            &["virtual-rig", "--drop", "Sample:0"],
            "invalid value 'Sample:0' for '--drop <DROPS>': \"Sample:0\": N counts from 1",
        ),
        (
            &["virtual-rig", "--duration", "nan"],
            "invalid value 'nan' for '--duration <DURATION>': \"nan\" is not a positive number",
        ),
    ] {
        let o = host(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert_eq!(stderr(&o), format!("error: {expected}\n\nFor more information, try '--help'.\n"), "{args:?}");
        assert!(o.stdout.is_empty(), "{args:?}");
    }
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
    let tmp = scratch("dup");
    let dir = tmp.path();
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

/// `host`, with the records database's default kept out of the user's data folder: a run
/// without `--db` records under the temporary directory, never in ~/.local/share.
fn host_command() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_host"));
    c.env_remove("GYROCAL_DB").env("XDG_DATA_HOME", std::env::temp_dir().join("gyrocal-tests-data"));
    c
}

/// A fitted g-sensitivity leaves the loop: into calibration.json (°/s per g, row = gyro axis)
/// and from there into Kalibr's A; without one, calibration.json has no such key. (Runs in both
/// directions: at two speeds in one it would be flagged, exit 3, as not told from a change of M
/// with speed.)
#[test]
fn a_fitted_g_sensitivity_reaches_calibration_json_and_the_kalibr_export() {
    let tmp = scratch("gsens");
    let dir = tmp.path();
    let cap = dir.join("g.cap");
    let o = host(&[
        "simulate",
        "--out",
        cap.to_str().unwrap(),
        "--seed",
        "3",
        "--duration",
        "12",
        "--rates-dps",
        "180,90,-180",
        "--effect",
        "g_sensitivity=0.05",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = dir.join("cal");
    let o = host(&["calibrate", "--replay", cap.to_str().unwrap(), "--out-dir", out.to_str().unwrap(), "--no-db"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let cal = out.join("calibration.json");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&cal).unwrap()).unwrap();
    // The loop's own figure for gyro y from gravity along package z (loop.json's final step).
    let lr: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("loop.json")).unwrap()).unwrap();
    let steps = lr["steps"].as_array().unwrap();
    let params = steps.last().unwrap()["effect_params"].as_array().unwrap();
    let fitted = |name: &str| params.iter().find(|p| p["name"] == name).unwrap()["value"].as_f64().unwrap();
    let g = &v["g_sensitivity_dps_per_g"];
    assert_eq!(g[1][2].as_f64().unwrap(), fitted("g-sensitivity along package z, y"), "{g}");
    let g00 = fitted("g-sensitivity along package x, x");
    assert_eq!(g[0][0].as_f64().unwrap(), g00);
    let o = host(&["export", "--cal", cal.to_str().unwrap(), "--format", "kalibr"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let yaml = String::from_utf8_lossy(&o.stdout);
    let a00 = g00 * std::f64::consts::PI / 180.0 / 9.80665;
    // The export's own arithmetic may round the last bit otherwise: equal to 1e-12.
    let got: f64 = yaml.split("\n  A:\n  - - ").nth(1).and_then(|t| t.lines().next()).unwrap().parse().unwrap();
    assert!((got - a00).abs() <= 1e-12 * a00.abs(), "{got} against {a00}: {yaml}");
    let demo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/demo.cap");
    let plain = dir.join("plain");
    let o = host(&["calibrate", "--replay", demo.to_str().unwrap(), "--out-dir", plain.to_str().unwrap(), "--no-db"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(plain.join("calibration.json")).unwrap()).unwrap();
    assert!(v.get("g_sensitivity_dps_per_g").is_none());
}

/// `host export` reads `calibration/calibration.json` when `--cal` is not given: right after a
/// `calibrate` without `--out-dir` it needs only the format. `host --help` names every command.
#[test]
fn export_defaults_to_the_calibration_calibrate_writes_and_help_names_every_command() {
    let tmp = scratch("export-default");
    let demo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/demo.cap");
    let run = |args: &[&str]| host_command().current_dir(tmp.path()).args(args).output().expect("host runs");
    let o = run(&["calibrate", "--replay", demo.to_str().unwrap(), "--no-db"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // The summary reads on a terminal: no line over 100 characters (one was 326), and it says
    // plainly that the residual is noise.
    let summary = String::from_utf8_lossy(&o.stdout);
    let longest = summary.lines().map(|l| l.chars().count()).max().unwrap();
    assert!(longest <= 100, "a {longest}-character line:\n{summary}");
    assert!(
        summary.contains("\n  only noise: no test of the residual found a pattern the model misses.\n"),
        "{summary}"
    );
    let o = run(&["export", "--format", "csv"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).starts_with("name,"), "{}", String::from_utf8_lossy(&o.stdout));
    let o = run(&["--help"]);
    assert!(String::from_utf8_lossy(&o.stdout).starts_with(
        "Gyro calibration rig: calibrate, record, simulate, virtual-rig, inspect, apply, export, records, noise, configure-drive\n"
    ));
}
