//! Result files that survive: written before the summary, whole (temporary name, then rename),
//! one calibration at a time per output directory; a closed or full standard output is an error
//! line, never a panic, and never costs the files or the record.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn demo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/demo.cap")
}

/// `host` with the user's data folder out of reach: a run without `--db` would record into this
/// scratch `XDG_DATA_HOME`, never into ~/.local/share.
fn host_cmd(data_home: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_host"));
    c.env_remove("GYROCAL_DB").env("XDG_DATA_HOME", data_home);
    c
}

fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new().prefix(&format!("host-files-{name}-")).tempdir().expect("temporary directory")
}

fn calibrate_args<'a>(out: &'a Path, db: &'a str) -> Vec<String> {
    let demo = demo();
    vec![
        "calibrate".into(),
        "--replay".into(),
        demo.to_str().unwrap().into(),
        "--out-dir".into(),
        out.to_str().unwrap().into(),
        "--sensor".into(),
        "SN-FILES".into(),
        "--db".into(),
        db.into(),
    ]
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn records(dir: &Path, db: &str) -> String {
    let o = host_cmd(dir).args(["records", "--db", db, "list"]).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// `host calibrate … | true`: the reader is gone before the summary is printed.
#[test]
fn a_closed_stdout_is_one_error_line_after_the_files_and_the_record() {
    let tmp = scratch("epipe");
    let out = tmp.path().join("cal");
    let db = format!("sqlite:{}", tmp.path().join("r.sqlite").display());
    let mut child = host_cmd(tmp.path())
        .args(calibrate_args(&out, &db))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(err.lines().last().unwrap(), "error: cannot write to standard output: Broken pipe (os error 32)");
    assert!(!err.contains("panicked"), "{err}");
    let cal: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap()).unwrap();
    assert_eq!(cal["provenance"]["sensor_serial"], "SN-FILES");
    assert!(std::fs::read_to_string(out.join("report.html")).unwrap().ends_with("</html>\n"));
    assert!(records(tmp.path(), &db).lines().nth(1).unwrap().trim_start().starts_with("1  SN-FILES "));
}

/// `host calibrate … > /dev/full`.
#[test]
fn a_full_stdout_is_one_error_line_after_the_files_and_the_record() {
    let tmp = scratch("enospc");
    let out = tmp.path().join("cal");
    let db = format!("sqlite:{}", tmp.path().join("r.sqlite").display());
    let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
    let o = host_cmd(tmp.path()).args(calibrate_args(&out, &db)).stdout(full).output().unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(
        err.lines().last().unwrap(),
        "error: cannot write to standard output: No space left on device (os error 28)"
    );
    assert!(out.join("calibration.json").exists() && out.join("loop.json").exists());
    assert_eq!(records(tmp.path(), &db).lines().count(), 2);
}

/// A directory another calibration holds is refused at once, before any file is written.
#[test]
fn a_calibration_into_a_busy_out_dir_is_refused_with_one_line() {
    let tmp = scratch("busy");
    let out = tmp.path().join("cal");
    let db = format!("sqlite:{}", tmp.path().join("r.sqlite").display());
    let lock = host::files::DirLock::acquire(&out).unwrap();
    let o = host_cmd(tmp.path()).args(calibrate_args(&out, &db)).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        stderr(&o),
        format!(
            "error: {} is in use by another calibration (it holds .gyrocal.lock): wait for it to finish or choose another --out-dir\n",
            out.display()
        )
    );
    assert!(!out.join("calibration.json").exists());
    assert!(!tmp.path().join("r.sqlite").exists(), "nothing recorded");
    drop(lock);
}

/// Eight calibrations of four sensors into one directory at once: each either succeeds or is
/// refused with the one line; what is left is one sensor's set, the same in every file.
#[test]
fn concurrent_calibrations_into_one_out_dir_never_mix_their_files() {
    let tmp = scratch("concurrent");
    let out = tmp.path().join("cal");
    let db = format!("sqlite:{}", tmp.path().join("r.sqlite").display());
    let children: Vec<_> = (0..8)
        .map(|i| {
            let mut args = calibrate_args(&out, &db);
            args[6] = format!("SN-{}", i % 4);
            // On a loaded machine one may start after another has finished and recorded the
            // same capture: that refusal is not what this test is about.
            args.push("--again".into());
            host_cmd(tmp.path()).args(args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap()
        })
        .collect();
    let refused = format!(
        "error: {} is in use by another calibration (it holds .gyrocal.lock): wait for it to finish or choose another --out-dir",
        out.display()
    );
    let mut succeeded = 0;
    for c in children {
        let o = c.wait_with_output().unwrap();
        match o.status.code() {
            Some(0) => succeeded += 1,
            Some(1) => assert_eq!(stderr(&o).trim_end(), refused),
            other => panic!("exit {other:?}: {}", stderr(&o)),
        }
    }
    assert!(succeeded >= 1);
    let cal: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap()).unwrap();
    let serial = cal["provenance"]["sensor_serial"].as_str().unwrap();
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.ends_with("</html>\n"));
    assert_eq!(html.matches("<h1>").count(), 1, "one page");
    for other in (0..4).map(|i| format!("SN-{i}")).filter(|s| s != serial) {
        assert!(!html.contains(&other), "report.html names {other}, calibration.json {serial}");
    }
    assert!(html.contains(serial));
}

/// kill -9 at spread instants of a re-run into a directory holding a calibration: what is left
/// is always a whole calibration.json (the old or the new), never 0 bytes, never a fragment.
#[test]
fn a_kill_at_any_point_of_a_rerun_leaves_a_whole_calibration_json() {
    let tmp = scratch("kill");
    let out = tmp.path().join("cal");
    let db = format!("sqlite:{}", tmp.path().join("r.sqlite").display());
    let t0 = std::time::Instant::now();
    let o = host_cmd(tmp.path()).args(calibrate_args(&out, &db)).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let whole = std::time::Instant::now() - t0;
    let first = std::fs::read_to_string(out.join("calibration.json")).unwrap();
    // 12 instants spread over a whole run's length, the last ones past its file writes.
    for i in 0..12u32 {
        let mut c = host_cmd(tmp.path())
            .args(calibrate_args(&out, &db))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(whole * i / 10);
        let _ = c.kill();
        let _ = c.wait();
        let text = std::fs::read_to_string(out.join("calibration.json")).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_else(|e| panic!("kill {i}: {e}"));
        assert_eq!(v["provenance"]["sensor_serial"], "SN-FILES");
        assert_eq!(text.len(), first.len(), "kill {i}: same data, same length, old or new");
    }
    let left: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n != ".gyrocal.lock")
        .collect();
    // A kill between a temporary file's creation and its rename may leave it (hidden, named
    // after its target); never a visible partial file.
    assert!(left.iter().all(|n| n.ends_with(".tmp") || n.starts_with(".report.")), "{left:?}");
}

/// `--no-db`: the files, no record, and the user's data folder untouched.
#[test]
fn no_db_writes_the_files_and_records_nothing() {
    let tmp = scratch("nodb");
    let (o, out) = calibrate_demo_without_a_record(tmp.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).lines().any(|l| l == "not recorded (--no-db)"), "{}", stderr(&o));
    assert!(out.join("calibration.json").exists());
    assert!(!tmp.path().join("gyrocal").exists(), "no database created in the data folder");
}

/// The certificate in report.html: each result with u and U = 2u (GUM wording), the
/// sensitivity in the datasheet's mdps/LSB too, the angles between the axes, the correction.
#[test]
fn the_certificate_gives_expanded_uncertainties_angles_and_the_correction() {
    let tmp = scratch("cert");
    let (o, out) = calibrate_demo_without_a_record(tmp.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let cal: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap()).unwrap();
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    let x = &cal["axes"][0];
    let (k, u) = (f(&x["k_counts_per_dps"]), f(&x["k_sigma"]));
    assert!(
        html.contains(&format!(
            "<tr><td>x</td><td>sensitivity</td><td>{k:.5}</td><td>{u:.5}</td><td>{:.5}</td><td>counts/(°/s)</td></tr>",
            2.0 * u
        )),
        "{html}"
    );
    let mdps = 1000.0 / k;
    assert!(html.contains(&format!("<td>sensitivity (datasheet unit)</td><td>{mdps:.5}</td>")));
    let ut = f(&x["tilt_sigma_deg"]).hypot(f(&x["tilt_mount_sigma_deg"]));
    assert!(html.contains(&format!(
        "<td>tilt from the package axis</td><td>{:.4}</td><td>{ut:.4}</td><td>{:.4}</td>",
        f(&x["tilt_deg"]),
        2.0 * ut
    )));
    let xy = &cal["inter_axis"][0];
    assert!(html.contains(&format!(
        "<tr><td>x–y</td><td>angle between the axes</td><td>{:.4}</td><td>{:.4}</td><td>{:.4}</td><td>°</td></tr>",
        f(&xy["angle_deg"]),
        f(&xy["sigma_deg"]),
        2.0 * f(&xy["sigma_deg"])
    )));
    assert!(html.contains("stated as the standard uncertainty of measurement multiplied by the coverage factor k = 2"));
    assert!(html.contains("<h3>Correction applied by a firmware</h3>"));
    // Without a database, the sensor's history is not looked up, and the certificate says so.
    assert!(html.contains(
        "<h3>Previous calibrations of this sensor</h3>\n<p>Previous calibrations: not looked up (--no-db: no records database read).</p>"
    ));
    assert_eq!(html.matches("<th scope=\"col\">(K S)⁻¹ [°/s per count]</th>").count(), 1);
}

/// `--spec`: each limit PASS or FAIL in the summary, the certificate and the record; a failed
/// limit exits 4, all within exit 0. The demo's z axis is tilted 1.8143° (see its summary).
#[test]
fn spec_limits_pass_or_fail_with_exit_4() {
    let tmp = scratch("spec");
    let demo = demo();
    let db = format!("sqlite:{}", tmp.path().join("r.sqlite").display());
    let run = |name: &str, spec: &str| {
        let file = tmp.path().join(format!("{name}.json"));
        std::fs::write(&file, spec).unwrap();
        let out = tmp.path().join(name);
        let o = host_cmd(tmp.path())
            .args(["calibrate", "--replay", demo.to_str().unwrap(), "--out-dir", out.to_str().unwrap()])
            .args(["--db", &db, "--again", "--spec", file.to_str().unwrap()])
            .output()
            .unwrap();
        (o, std::fs::read_to_string(out.join("report.html")).unwrap_or_default())
    };
    let (o, html) = run("strict", r#"{"max_tilt_deg": 1.5, "sensitivity_tolerance_percent": 2.0}"#);
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("\nSpecification: FAIL\n"), "{text}");
    assert!(text.contains("\n  FAIL  tilt z: 1.8143 ° > 1.5 °\n"), "{text}");
    assert!(text.contains("\n  PASS  tilt x: 1.1035 ° ≤ 1.5 °\n"), "{text}");
    assert!(html.contains("<h2>Specification: FAIL</h2>"));
    assert!(html.contains("<tr><td>FAIL</td><td>tilt z</td><td>1.8143 °</td><td>1.5 °</td></tr>"), "{html}");
    let (o, _) = run("loose", r#"{"max_tilt_deg": 2.0}"#);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("\nSpecification: PASS\n"));
    // The record keeps the outcome: spec_pass 0, then 1.
    for (id, pass) in [("1", "0"), ("2", "1")] {
        let o = host_cmd(tmp.path()).args(["records", "show", id, "--db", &db, "--format", "csv"]).output().unwrap();
        let csv = String::from_utf8_lossy(&o.stdout).into_owned();
        assert!(csv.contains(&format!("\n{id},spec_pass,{pass},,1\n")), "{csv}");
    }
    let (o, _) = run("bad", r#"{"max_tilt": 2.0}"#);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).starts_with(&format!(
            "error: {} is not a spec: unknown field `max_tilt`",
            tmp.path().join("bad.json").display()
        )),
        "{}",
        stderr(&o)
    );
}

/// `host calibrate --replay demo.cap --no-db` into `dir/cal`: its output and that directory.
fn calibrate_demo_without_a_record(dir: &std::path::Path) -> (std::process::Output, std::path::PathBuf) {
    let out = dir.join("cal");
    let demo = demo();
    let o = host_cmd(dir)
        .args(["calibrate", "--replay", demo.to_str().unwrap(), "--out-dir", out.to_str().unwrap(), "--no-db"])
        .output()
        .unwrap();
    (o, out)
}
