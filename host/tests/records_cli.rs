//! `host records` as a line uses it: `--db` anywhere, reads that never create a database, a
//! capture recorded once unless `--again`, and JSON or CSV for scripts and spreadsheets.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn demo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/demo.cap")
}

/// `host`, the user's data folder out of reach (`XDG_DATA_HOME` in the scratch directory).
fn host(scratch: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host"))
        .env_remove("GYROCAL_DB")
        .env("XDG_DATA_HOME", scratch)
        .args(args)
        .output()
        .expect("host runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Calibrates the demo capture into `out` as sensor SN-R, recording into `db`.
fn calibrate(scratch: &Path, out: &str, db: &str, extra: &[&str]) -> Output {
    let out = scratch.join(out);
    let demo = demo();
    let mut args = vec![
        "calibrate",
        "--replay",
        demo.to_str().unwrap(),
        "--out-dir",
        out.to_str().unwrap(),
        "--sensor",
        "SN-R",
        "--db",
        db,
    ];
    args.extend(extra);
    host(scratch, &args)
}

#[test]
fn db_is_taken_after_the_subcommand_too() {
    let tmp = tempfile::tempdir().unwrap();
    let db = format!("sqlite:{}", tmp.path().join("r.sqlite").display());
    assert_eq!(calibrate(tmp.path(), "a", &db, &[]).status.code(), Some(0));
    let before = host(tmp.path(), &["records", "--db", &db, "list"]);
    let after = host(tmp.path(), &["records", "list", "--db", &db]);
    assert_eq!(after.status.code(), Some(0), "{}", stderr(&after));
    assert_eq!(stdout(&after), stdout(&before));
    assert!(stdout(&after).lines().nth(1).unwrap().trim_start().starts_with("1  SN-R "), "{}", stdout(&after));
}

#[test]
fn reading_a_missing_database_is_one_line_and_creates_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("typo.sqlite");
    for cmd in [&["list"][..], &["show", "1"], &["compare", "1", "2"], &["summary"]] {
        let mut args = vec!["records", "--db"];
        let db = format!("sqlite:{}", path.display());
        args.push(&db);
        args.extend(cmd);
        let o = host(tmp.path(), &args);
        assert_eq!(o.status.code(), Some(1), "{cmd:?}");
        assert_eq!(
            stderr(&o),
            format!("error: no records database at {} (check --db or $GYROCAL_DB)\n", path.display())
        );
        assert!(!path.exists(), "{cmd:?} created {}", path.display());
    }
}

#[test]
fn a_capture_already_recorded_is_refused_naming_the_record_unless_again() {
    let tmp = tempfile::tempdir().unwrap();
    let db = format!("sqlite:{}", tmp.path().join("r.sqlite").display());
    let o = calibrate(tmp.path(), "a", &db, &[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let cal: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("a/calibration.json")).unwrap()).unwrap();
    let sha = cal["provenance"]["captures"][0]["sha256"].as_str().unwrap().to_string();
    let o = calibrate(tmp.path(), "b", &db, &[]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        stderr(&o).lines().last().unwrap(),
        format!(
            "error: {} is already in record 1 of {db} (sha256 {}…): give --again to calibrate and record it again",
            demo().display(),
            &sha[..12]
        )
    );
    assert!(!tmp.path().join("b/calibration.json").exists(), "refused before any file");
    let o = calibrate(tmp.path(), "b", &db, &["--again"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains(&format!("recorded as 2 in {db}")), "{}", stderr(&o));
}

#[test]
fn list_show_and_compare_as_json_and_csv() {
    let tmp = tempfile::tempdir().unwrap();
    let db = format!("sqlite:{}", tmp.path().join("r.sqlite").display());
    assert_eq!(calibrate(tmp.path(), "a", &db, &[]).status.code(), Some(0));
    assert_eq!(calibrate(tmp.path(), "b", &db, &["--again"]).status.code(), Some(0));

    let o = host(tmp.path(), &["records", "list", "--db", &db, "--format", "json"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let list: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(list.as_array().unwrap().len(), 2);
    assert_eq!(list[1]["id"], 2);
    assert_eq!(list[1]["sensor_serial"], "SN-R");
    assert_eq!(list[1]["verdict"], "at noise floor");

    let o = host(tmp.path(), &["records", "list", "--db", &db, "--format", "csv"]);
    let csv = stdout(&o);
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "id,sensor_serial,calibrated_utc,operator,rig,verdict,full_scale_dps,host_version,rig_firmware,captures_sha256"
    );
    assert_eq!(lines.len(), 3);
    assert!(lines[2].starts_with("2,SN-R,"), "{csv}");

    let o = host(tmp.path(), &["records", "show", "2", "--db", &db, "--format", "json"]);
    let show: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let params = show["parameters"].as_array().unwrap();
    let kx = params.iter().find(|p| p["name"] == "k_x").unwrap();
    assert_eq!(kx["unit"], "counts/(deg/s)");
    assert_eq!(show["calibration"]["provenance"]["sensor_serial"], "SN-R");

    let o = host(tmp.path(), &["records", "show", "2", "--db", &db, "--format", "csv"]);
    let csv = stdout(&o);
    assert_eq!(csv.lines().next().unwrap(), "id,name,value,sigma,unit");
    assert_eq!(csv.lines().count(), 1 + params.len());

    let o = host(tmp.path(), &["records", "compare", "1", "2", "--db", &db, "--format", "csv"]);
    let csv = stdout(&o);
    assert_eq!(csv.lines().next().unwrap(), "name,unit,a,b,change,z,changed");
    let unchanged = |l: &str| {
        let f: Vec<&str> = l.split(',').collect();
        f[4] == "0" && (f[5] == "0" || f[5].is_empty()) && f[6] == "false"
    };
    assert!(csv.lines().skip(1).all(unchanged), "the same data: no change\n{csv}");
    let o = host(tmp.path(), &["records", "compare", "1", "2", "--db", &db, "--format", "json"]);
    let cmp: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(cmp["changed_beyond_sigma"], 3.0);
    assert_eq!(cmp["parameters"].as_array().unwrap().len(), csv.lines().count() - 1);
}

/// The parameters of record `id` (`records show --format json`), by name: (value, σ).
fn params_of(scratch: &Path, db: &str, id: i64) -> (serde_json::Value, Vec<(String, f64, Option<f64>)>) {
    let o = host(scratch, &["records", "show", &id.to_string(), "--db", db, "--format", "json"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let params = v["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["name"].as_str().unwrap().to_string(), p["value"].as_f64().unwrap(), p["sigma"].as_f64()))
        .collect();
    (v, params)
}

/// The serial's previous calibrations on the certificate and in `records show`: two simulated
/// sensors (seeds 5 and 6) recorded under one serial, then the second capture again. Each
/// earlier record is listed with its k and tilt per axis and the change to this calibration in
/// combined σ, (this − then)/√(σ_this² + σ_then²), flagged beyond 3σ.
#[test]
fn show_and_the_report_list_the_serials_previous_calibrations_with_each_change_in_sigma() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let db = format!("sqlite:{}", dir.join("r.sqlite").display());
    let mut caps = Vec::new();
    for seed in ["5", "6"] {
        let cap = dir.join(format!("s{seed}.cap"));
        let o = host(dir, &["simulate", "--out", cap.to_str().unwrap(), "--seed", seed, "--duration", "6"]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        caps.push(cap);
    }
    let cal = |cap: &Path, out: &str, extra: &[&str]| {
        let out = dir.join(out);
        let mut args = vec!["calibrate", "--replay", cap.to_str().unwrap(), "--out-dir", out.to_str().unwrap()];
        args.extend(["--sensor", "SN-H", "--db", &db]);
        args.extend(extra);
        let o = host(dir, &args);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        std::fs::read_to_string(out.join("report.html")).unwrap()
    };
    let first = cal(&caps[0], "a", &[]);
    assert!(first.contains("<p>No previous calibration of SN-H in the records database.</p>"), "{first}");
    let second = cal(&caps[1], "b", &[]);
    let third = cal(&caps[1], "c", &["--again"]);

    let (show1, p1) = params_of(dir, &db, 1);
    assert_eq!(show1["history"]["previous"].as_array().unwrap().len(), 0);
    let (show2, p2) = params_of(dir, &db, 2);
    let (show3, _) = params_of(dir, &db, 3);
    let find = |p: &[(String, f64, Option<f64>)], n: &str| p.iter().find(|q| q.0 == n).cloned().unwrap();

    // Record 2 against record 1: another simulated sensor, so its sensitivities moved far
    // beyond their uncertainty.
    let h = &show2["history"];
    assert_eq!(h["looked_up"], true);
    assert_eq!(h["sensor_serial"], "SN-H");
    let prev = h["previous"].as_array().unwrap();
    assert_eq!(prev.len(), 1);
    assert_eq!(prev[0]["id"], 1);
    assert_eq!(prev[0]["calibrated_utc"], show1["calibrated_utc"]);
    let date1 = show1["calibrated_utc"].as_str().unwrap();
    let text = stdout(&host(dir, &["records", "show", "2", "--db", &db]));
    assert!(text.contains("1 previous calibration(s) of SN-H"), "{text}");
    let mut any_beyond = false;
    for ax in ["x", "y", "z"] {
        let mut cells = vec!["1".to_string(), date1.to_string(), ax.to_string()];
        let mut flagged = Vec::new();
        for q in ["k", "tilt"] {
            let name = format!("{q}_{ax}");
            let (_, then, s_then) = find(&p1, &name);
            let (_, this, s_this) = find(&p2, &name);
            let z = (this - then) / s_this.unwrap().hypot(s_then.unwrap());
            let entry = prev[0]["parameters"].as_array().unwrap().iter().find(|p| p["name"] == name.as_str()).unwrap();
            assert_eq!(entry["then"].as_f64().unwrap(), then);
            assert_eq!(entry["this"].as_f64().unwrap(), this);
            let got = entry["z"].as_f64().unwrap();
            assert!((got - z).abs() <= 1e-12 * z.abs().max(1.0), "{name}: z {got} against {z}");
            assert_eq!(entry["changed"], z.abs() > 3.0, "{name}");
            if z.abs() > 3.0 {
                flagged.push(q);
            }
            cells.push(format!("{then:.6}"));
            cells.push(format!("{z:+.2}"));
        }
        any_beyond |= !flagged.is_empty();
        cells.push(if flagged.is_empty() { "no".into() } else { flagged.join(", ") });
        let row = cells.iter().map(|c| format!("<td>{c}</td>")).collect::<String>();
        assert!(second.contains(&format!("<tr>{row}</tr>")), "report.html lacks <tr>{row}</tr>:\n{second}");
        let words: Vec<&str> = cells.iter().map(String::as_str).collect();
        assert!(
            text.lines()
                .any(|l| l.split_whitespace().collect::<Vec<_>>() == words.join(" ").split(' ').collect::<Vec<_>>()),
            "records show 2 lacks {words:?}:\n{text}"
        );
    }
    let kx = find(&p2, "k_x").1 - find(&p1, "k_x").1;
    assert!(any_beyond, "two simulated sensors, yet no k or tilt beyond 3σ (Δk_x {kx})");
    assert!(second.contains("<li>record 1: "), "{second}");

    // Record 3, the same capture as record 2 again: both earlier records listed, nothing
    // changed since record 2.
    let prev = show3["history"]["previous"].as_array().unwrap();
    assert_eq!(prev.iter().map(|p| p["id"].as_i64().unwrap()).collect::<Vec<_>>(), [1, 2]);
    for p in prev[1]["parameters"].as_array().unwrap() {
        assert_eq!(p["change"].as_f64().unwrap(), 0.0, "{p}");
        assert_eq!(p["changed"], false, "{p}");
    }
    assert_eq!(prev[1]["changed"].as_array().unwrap().len(), 0);
    assert!(third.contains("2 previous calibration(s) of SN-H"), "{third}");
    assert!(third.contains("<td>2</td>") && third.contains("<td>+0.00</td>"), "{third}");
}
