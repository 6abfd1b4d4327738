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
