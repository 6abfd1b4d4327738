//! Issue 28's soak: every hostile condition a bench has, one scripted session each, through the
//! `host` binary against `host virtual-rig` in lockstep time (`common::LockstepBench`: a loaded
//! machine slows it down, never changes it). Each scenario is `host calibrate --rates-dps 180
//! --duration 3` in both poses, the operator answering every prompt at once, with one fault:
//! a lossy line (1e-3 to 1e-2 of the bytes, both ways), garbage bursts, each frame kind the rig
//! sends dropped once, SIGINT/TERM/HUP/KILL at the pose-1 prompt, during spin-up, at speed and
//! during the ramp-down, the rig killed at speed, a full disk (a file-size limit: `EFBIG` where
//! a full disk gives `ENOSPC`, the same path), standard input closed at the prompt.
//!
//! The bars (issue 28), asserted for every scenario: the host ends with one clear line (exit
//! 0 or 3 with a calibration, or exit 1 with `error: …`; a SIGKILLed host says nothing, by
//! design), every capture replays (`host inspect` exits 0), no capture holds a trip the host did
//! not report, and no `HostLinkLost` follows a host-initiated stop. After the host has gone the
//! rig runs 5 s more of its time, longer than its 2 s link timeout, so a trip the host's exit
//! would cause shows in its log. The table printed at the end is the one in docs/bench-soak.md.

mod common;

use common::{decode, host, scratch, LockstepBench, NS};
use std::io::Write;
use std::path::Path;

/// Where in the session the fault strikes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum When {
    /// 5 s after the pose-1 mounting prompt appears.
    Prompt,
    /// 1 s after the rig received the first Start: the table ramping up (2 s to 180 °/s).
    SpinUp,
    /// 4 s after the first Start: at speed, recording.
    AtSpeed,
    /// 0.5 s after the rig received the first Stop: the table ramping down.
    RampDown,
}

/// What the test does to the session.
#[derive(Debug, Clone, Copy)]
enum Act {
    /// Nothing: the line's faults (rig options) are the scenario.
    Nothing,
    /// `kill -SIG` to the host.
    Signal(&'static str, When),
    /// The rig process killed: its end of the pty and its clock gone.
    KillRig(When),
    /// The host may write 64 KiB per file (`ulimit -f 64`, SIGXFSZ ignored): the first capture
    /// fills its "disk" during pose 1's spin-up.
    DiskFull,
    /// Standard input closed: nobody answers the prompts.
    StdinClosed,
}

struct Scenario {
    name: String,
    rig: Vec<&'static str>,
    act: Act,
}

/// One row of the table.
struct Row {
    name: String,
    exit: String,
    outcome: String,
    captures: String,
    trips: String,
    violations: Vec<String>,
}

fn scenarios() -> Vec<Scenario> {
    let mut s = Vec::new();
    let plain = |name: String, rig: Vec<&'static str>| Scenario { name, rig, act: Act::Nothing };
    s.push(plain("clean line".into(), vec![]));
    for loss in ["1e-3", "3e-3", "1e-2"] {
        s.push(plain(format!("byte loss {loss}"), vec!["--loss", loss, "--seed", "7"]));
    }
    s.push(plain("garbage every 1 s".into(), vec!["--garbage-every", "1", "--seed", "7"]));
    for kind in
        ["Hello", "Ack", "RunStarted", "RunStopped", "Sample", "Motor", "Index", "Counters", "Temperature", "Fault"]
    {
        let spec: &'static str = Box::leak(format!("{kind}:1").into_boxed_str());
        s.push(plain(format!("{kind} #1 dropped"), vec!["--drop", spec]));
    }
    for sig in ["INT", "TERM", "HUP", "KILL"] {
        for when in [When::Prompt, When::SpinUp, When::AtSpeed, When::RampDown] {
            s.push(Scenario { name: format!("SIG{sig} {when:?}"), rig: vec![], act: Act::Signal(sig, when) });
        }
    }
    s.push(Scenario { name: "rig killed AtSpeed".into(), rig: vec![], act: Act::KillRig(When::AtSpeed) });
    s.push(Scenario { name: "disk full".into(), rig: vec![], act: Act::DiskFull });
    s.push(Scenario { name: "stdin closed".into(), rig: vec![], act: Act::StdinClosed });
    s
}

/// Seconds (rig time) of the lines `virtual rig: <prefix>… at T s`.
fn times(log: &[String], prefix: &str) -> Vec<f64> {
    log.iter()
        .filter(|l| l.starts_with(prefix))
        .filter_map(|l| l.rsplit(" at ").next()?.strip_suffix(" s")?.parse().ok())
        .collect()
}

fn run(index: usize, sc: &Scenario) -> Row {
    let name = format!("soak-{index}");
    let mut bench = LockstepBench::start(&name, &sc.rig);
    let dir = scratch(&name);
    let db = format!("sqlite:{}", dir.with_extension("records.sqlite").display());
    let args = ["calibrate", "--sensor", "SN-SOAK", "--rates-dps", "180", "--duration", "3", "--out-dir"];
    let mut args: Vec<&str> = args.to_vec();
    args.extend([dir.to_str().unwrap(), "--db", &db]);
    let stdin = match sc.act {
        Act::StdinClosed => std::process::Stdio::null(),
        _ => std::process::Stdio::piped(),
    };
    let wrapper: &[&str] = match sc.act {
        Act::DiskFull => &["bash", "-c", "ulimit -f 64; trap '' XFSZ; exec \"$@\"", "bash"],
        _ => &[],
    };
    let mut session = bench.host_via(wrapper, &args, stdin);
    let mut operator = session.child.stdin.take();
    let log = bench.log.clone();
    let rig_pid = bench.rig.id();
    let mut prompts = 0;
    let mut act_at_ns: Option<u64> = None;
    let mut acted = false;
    let when = match sc.act {
        Act::Signal(_, w) | Act::KillRig(w) => Some(w),
        _ => None,
    };
    bench.relay(&mut session, |now_ns, host| {
        for line in host.drain() {
            if line.contains("Press Enter when ready") {
                prompts += 1;
                if when == Some(When::Prompt) && prompts == 2 {
                    act_at_ns = Some(now_ns + 5 * NS);
                } else if let Some(stdin) = operator.as_mut() {
                    let _ = writeln!(stdin);
                }
            }
        }
        if act_at_ns.is_none() {
            let log = log.lock().unwrap();
            let first = |prefix: &str| log.iter().any(|l| l.starts_with(prefix));
            act_at_ns = match when {
                Some(When::SpinUp) if first("virtual rig: received Start") => Some(now_ns + NS),
                Some(When::AtSpeed) if first("virtual rig: received Start") => Some(now_ns + 4 * NS),
                Some(When::RampDown) if first("virtual rig: received Stop") => Some(now_ns + NS / 2),
                _ => None,
            };
        }
        if !acted && act_at_ns.is_some_and(|t| now_ns >= t) {
            acted = true;
            match sc.act {
                Act::Signal(sig, _) => host.signal(sig),
                Act::KillRig(_) => {
                    let ok = std::process::Command::new("kill").args(["-KILL", &rig_pid.to_string()]).status();
                    assert!(ok.is_ok_and(|s| s.success()));
                }
                _ => {}
            }
            // Lets the signal land before the host hears of the next step.
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
    });
    let (status, err, _) = session.finish();
    let rig_alive = !matches!(sc.act, Act::KillRig(_));
    if rig_alive {
        bench.advance(5 * NS);
    }
    let log = bench.log();
    let mut violations = Vec::new();

    // One clear line.
    let last = err.lines().last().unwrap_or_default().trim_start_matches("Press Enter when ready (Ctrl-C to abort) ");
    let killed = matches!(sc.act, Act::Signal("KILL", _));
    let exit = match status.code() {
        Some(c) => c.to_string(),
        None if killed => "SIGKILL".into(),
        None => format!("{status}"),
    };
    let outcome = match status.code() {
        Some(0 | 3) if last.starts_with("recorded as ") => "calibrated and recorded".to_string(),
        Some(1) if last.starts_with("error: ") => last.to_string(),
        None if killed => "(killed: no line, by design)".to_string(),
        _ => {
            violations.push(format!("no clear one-line outcome: exit {exit}, last line {last:?}"));
            last.to_string()
        }
    };
    if matches!(status.code(), Some(c) if c != 0 && c != 1 && c != 3) {
        violations.push(format!("exit {exit}"));
    }

    // Every capture replays; no capture holds a trip the host did not report.
    let mut caps = Vec::new();
    for entry in std::fs::read_dir(&*dir).into_iter().flatten().flatten() {
        let path = entry.path();
        if path.extension().is_some_and(|e| e == "cap") {
            caps.push(path);
        }
    }
    caps.sort();
    for path in &caps {
        let o = host(&["inspect", path.to_str().unwrap()]);
        if o.status.code() != Some(0) {
            violations.push(format!("{} does not replay: {}", file(path), String::from_utf8_lossy(&o.stderr)));
        }
        let cap = decode(path);
        let faults: Vec<String> = cap
            .runs
            .iter()
            .flat_map(|r| r.faults.iter().map(|(_, f)| format!("{:?}", f.fault)))
            .chain(cap.faults.iter().map(|(_, f)| format!("{:?}", f.fault)))
            .collect();
        let motor_bits = cap.runs.iter().flat_map(|r| r.motor.iter()).any(|(_, m)| m.faults != 0);
        for f in &faults {
            let name = f.split([' ', '{']).next().unwrap_or(f);
            if !err.contains(name) {
                violations.push(format!("{}: {f} not reported by the host", file(path)));
            }
        }
        if motor_bits && faults.is_empty() && !err.contains("motor reports show") {
            violations.push(format!("{}: a trip in the Motor reports not reported by the host", file(path)));
        }
    }

    // No HostLinkLost after a host-initiated stop.
    let stops = times(&log, "virtual rig: received Stop");
    let link_trips = times(&log, "virtual rig: sent Fault HostLinkLost");
    let all_trips: Vec<String> = log
        .iter()
        .filter_map(|l| l.strip_prefix("virtual rig: sent Fault "))
        .map(|l| l.replace(" at ", " at rig time "))
        .collect();
    if killed {
        // A host that dies without a word mid-run: the rig's link watchdog cuts the drive. Killed
        // 0.5 s into the ramp-down the rig finishes the stop it was given (2 s) before its 2 s
        // link timeout, so it ends with RunStopped and no trip.
        match when {
            Some(When::SpinUp | When::AtSpeed) if link_trips.is_empty() => {
                violations.push("the rig never cut the drive after the host was killed".into())
            }
            Some(When::RampDown) if !all_trips.is_empty() || times(&log, "virtual rig: sent RunStopped").is_empty() => {
                violations.push("the ramp-down the host began did not end in RunStopped".into())
            }
            _ => {}
        }
    } else if let Some(stop) = stops.first() {
        if let Some(t) = link_trips.iter().find(|t| *t > stop) {
            violations.push(format!("HostLinkLost at {t} s after the host's Stop at {stop} s"));
        }
    }
    let captures = if caps.is_empty() { "none".to_string() } else { format!("{} (all replay)", caps.len()) };
    let captures =
        if violations.iter().any(|v| v.contains("does not replay")) { format!("{} ✗", caps.len()) } else { captures };
    let trips = if all_trips.is_empty() { "none".to_string() } else { all_trips.join("; ") };
    Row {
        name: sc.name.clone(),
        exit,
        outcome: outcome.replace(&*dir.to_string_lossy(), "OUT"),
        captures,
        trips,
        violations,
    }
}

fn file(path: &Path) -> String {
    path.file_name().unwrap_or_default().to_string_lossy().into_owned()
}

#[test]
fn soak_every_hostile_scenario_ends_cleanly() {
    let wall = std::time::Instant::now();
    let mut rows = Vec::new();
    for (i, sc) in scenarios().iter().enumerate() {
        let t = std::time::Instant::now();
        let row = run(i, sc);
        eprintln!("{}: exit {} in {:.1?}: {}", row.name, row.exit, t.elapsed(), row.outcome);
        rows.push(row);
    }
    let mut table = String::from(
        "| scenario | exit | the host's last line | captures | trips the rig sent |\n|---|---|---|---|---|\n",
    );
    for r in &rows {
        table += &format!(
            "| {} | {} | {} | {} | {} |\n",
            r.name,
            r.exit,
            r.outcome.replace('|', "\\|"),
            r.captures,
            r.trips
        );
    }
    eprintln!("\n{table}\n{} scenarios in {:.1?} of wall time", rows.len(), wall.elapsed());
    let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join("bench-soak.md");
    std::fs::write(&path, &table).unwrap();
    eprintln!("table written to {}", path.display());
    let violations: Vec<String> =
        rows.iter().flat_map(|r| r.violations.iter().map(move |v| format!("{}: {v}", r.name))).collect();
    assert_eq!(violations, Vec::<String>::new());
    assert_eq!(rows.len(), 34);
}
