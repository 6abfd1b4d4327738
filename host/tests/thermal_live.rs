//! A live thermal session through the `host` binary against `host virtual-rig --lockstep
//! --chamber` (issue 27): at each setpoint a slow operator answers the chamber prompt three
//! minutes of rig time later, setting the simulated chamber as they confirm, and each mounting prompt
//! half a minute later; the host waits for the die to settle, records the runs, and fits the
//! thermal model. Lockstep time: a loaded machine makes the test slower, never different.

mod common;
use common::{scratch, LockstepBench, NS};

/// The operator's delay at the chamber prompt, ns of rig time (walking to the chamber).
const CHAMBER_DELAY_NS: u64 = 180 * NS;
/// Wall time after which the bench is taken to be deadlocked: the session is about 1.3 h of rig
/// time, 2-3 minutes of wall time on the 2-core development machine; ten times that on a loaded
/// CI machine still ends.
const GUARD: std::time::Duration = std::time::Duration::from_secs(1800);
/// The operator's delay at a mounting prompt, ns of rig time.
const MOUNT_DELAY_NS: u64 = 30 * NS;
/// The gyro's nominal sensitivity at ±500 °/s, counts per °/s (L3G4200D datasheet Table 4:
/// 17.5 mdps/digit).
const COUNTS_PER_DPS: f64 = 1000.0 / 17.5;

#[test]
fn a_thermal_session_against_the_virtual_rig_with_a_slow_operator_completes_end_to_end() {
    use std::io::Write;
    let t0 = std::time::Instant::now();
    let mut bench = LockstepBench::start_with_guard("thermal-live", &["--chamber"], GUARD);
    let dir = scratch("thermal-live");
    let out = dir.to_str().unwrap();
    let mut host = bench.host(&[
        "calibrate",
        "--sensor",
        "VR-27",
        "--chamber-c",
        "20,25,30",
        "--rates-dps",
        "180,-180",
        "--duration",
        "10",
        "--out-dir",
        out,
        "--no-db",
    ]);
    let mut stdin = host.child.stdin.take().unwrap();
    let pending = bench.pending_control.clone();
    // (when to answer, the chamber setpoint to set first, if the prompt was the chamber's)
    let mut answer: Option<(u64, Option<String>)> = None;
    let mut chamber: Option<String> = None;
    let mut answered_chamber_at_ns = Vec::new();
    let end_ns = bench.relay(&mut host, |now_ns, host| {
        for line in host.drain() {
            if let Some(rest) = line.split("Set the thermal chamber to ").nth(1) {
                chamber = rest.split(" °C").next().map(str::to_string);
            }
            if line.contains("Press Enter when ready") {
                let delay = if chamber.is_some() { CHAMBER_DELAY_NS } else { MOUNT_DELAY_NS };
                answer = Some((now_ns + delay, chamber.take()));
            }
        }
        if let Some((at_ns, setpoint)) = answer.clone() {
            if now_ns >= at_ns {
                if let Some(c) = setpoint {
                    pending.lock().unwrap().push(format!("chamber {c}"));
                    answered_chamber_at_ns.push(now_ns);
                }
                writeln!(stdin).unwrap();
                answer = None;
            }
        }
    });
    let (status, err, _) = host.finish();
    eprintln!("thermal session: {:.0} s of rig time in {:.1?} of wall time", end_ns as f64 * 1e-9, t0.elapsed());
    assert!(status.code().is_some_and(|c| c == 0 || c == 3), "{status:?}\n{err}");
    assert_eq!(answered_chamber_at_ns.len(), 3, "{err}");
    assert_eq!(err.matches("die settled:").count(), 3, "{err}");
    let log = bench.log();
    let set: Vec<&String> = log.iter().filter(|l| l.starts_with("virtual rig: chamber set to")).collect();
    assert_eq!(set.len(), 3, "{log:?}");
    check_manifest_and_model(&dir, &answered_chamber_at_ns, end_ns);
}

/// The manifest names each setpoint with its settle time (at least the 20-minute window after
/// the operator set the chamber), and the model's x offset slope is the virtual gyro's
/// 0.03 °/s/°C (`sim::thermal`'s default) within 3σ.
fn check_manifest_and_model(dir: &std::path::Path, chamber_set_ns: &[u64], end_ns: u64) {
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("thermal.json")).unwrap()).unwrap();
    let setpoints = manifest["setpoints"].as_array().unwrap();
    assert_eq!(setpoints.iter().map(|s| s["setpoint_c"].as_f64().unwrap()).collect::<Vec<_>>(), [20.0, 25.0, 30.0]);
    for (s, set_ns) in setpoints.iter().zip(chamber_set_ns) {
        let settle_s = s["settle_s"].as_f64().unwrap();
        assert!(settle_s >= 1200.0, "{s}");
        assert!(*set_ns < end_ns);
        assert!(dir.join(s["dir"].as_str().unwrap()).join("calibration.json").is_file(), "{s}");
    }
    let cal: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("calibration.json")).unwrap()).unwrap();
    let x_offset = &cal["thermal"]["curves"][0];
    assert_eq!(x_offset["quantity"], "offset_counts");
    let slope = x_offset["coef"][1]["value"].as_f64().unwrap();
    let sigma = x_offset["coef"][1]["sigma"].as_f64().unwrap();
    // The virtual gyro's x sensitivity is 0.97 of nominal (virtual_rig::VIRTUAL_GYRO_KS).
    let truth = 0.03 * 0.9699 * COUNTS_PER_DPS;
    eprintln!("x offset slope {slope:.4} ± {sigma:.4} counts/°C, truth {truth:.4}");
    assert!((slope - truth).abs() <= 3.0 * sigma, "{slope} ± {sigma} vs {truth}");
    assert!(sigma < 0.1 * truth, "σ {sigma} leaves the slope unresolved");
}
