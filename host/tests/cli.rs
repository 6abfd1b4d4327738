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
    assert_eq!(
        stderr(&o),
        "error: cannot read capture /nonexistent/run.cap: No such file or directory (os error 2)\n"
    );
}

#[test]
fn a_wrong_option_is_a_usage_error() {
    let o = host(&["record", "--port", "/dev/null", "--out", "x.cap", "--pose", "3"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("pose must be 1 or 2, not \"3\""), "{}", stderr(&o));
    let o = host(&["calibrat"]);
    assert_eq!(o.status.code(), Some(2));
}
