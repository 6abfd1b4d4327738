//! `host calibrate --port <pty> --static-s N` against the firmware's virtual rig, step by step as
//! host/src/cli.rs runs it: the session ends with a static run (a `Start` at 0 °/s), recorded
//! to its own capture, framed by `RunStarted`/`RunStopped` with the motor off throughout, and
//! its samples give the noise figures `host calibrate` adds to the result.

use e2e::LockstepRig;
use host::calib::{self, LoopOptions};
use host::capture;
use host::geometry::Pose;
use host::link::Link;
use host::session;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// The virtual gyro's rate noise, °/s/√Hz (`L3g4200dModel::with_noise`, datasheet Table 4).
const NOISE_DENSITY_DPS_PER_SQRT_HZ: f64 = firmware::plant::l3g4200d_model::NOISE_DENSITY_DPS_PER_SQRT_HZ;

/// Seconds of the static run: ARW is firm from a minute (README, "Noise figures").
const STATIC_S: f64 = 120.0;

#[test]
fn static_run_records_the_gyro_at_rest_and_gives_its_noise_figures() {
    let rig = LockstepRig::spawn(env!("CARGO_BIN_EXE_virtual_rig"), &[]);
    let port = rig.path.clone();
    let clock = rig.clock();
    let out_dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("virtual-rig-static");
    let _ = std::fs::remove_dir_all(&out_dir);
    let mut link = Link::with_clock(rig, port.as_str(), Box::new(clock));
    // `--rates-dps 180 --duration 8 --static-s 120`.
    let plan = session::plan_with_static(&Pose::ALL, &[180.0], 8.0, Some(STATIC_S));
    assert_eq!(plan.last().map(|r| (r.pose, r.rate_dps)), Some((Pose::Two, 0.0)), "static run last, in pose 2");
    let files = session::record_session(&mut link, &plan, &out_dir, &mut session::AssumeYes, &AtomicBool::new(false))
        .expect("live session");
    assert_eq!(files.last().unwrap().file_name().unwrap(), "pose2-static.cap");

    let caps: Vec<_> = files.iter().map(|f| capture::decode(&std::fs::read(f).expect("capture"))).collect();
    let stat = caps.last().unwrap();
    assert!(stat.loss.errors.is_empty() && stat.loss.seq_gaps.is_empty(), "{:?}", stat.loss);
    assert!(stat.faults.is_empty(), "{:?}", stat.faults);
    assert_eq!(stat.runs.len(), 1);
    let run = &stat.runs[0];
    assert_eq!((run.pose, run.rate_mdps), (Pose::Two, 0));
    assert!(run.stopped && run.faults.is_empty(), "framed by RunStopped, no fault: {:?}", run.faults);
    // Motor off: every report of the run says setpoint and duty 0, and speed 0 once the first
    // 100 ms window is past (the table may still settle by a count after the run before: the rig
    // ends a run once it moves at most one count per millisecond).
    assert!(run.motor.len() as f64 >= STATIC_S * 10.0, "{} Motor reports", run.motor.len());
    assert!(run.motor.iter().all(|(_, m)| m.setpoint_cps == 0 && m.duty_permille == 0), "the bridge stayed off");
    let moving: Vec<_> = run.motor.iter().skip(1).filter(|(_, m)| m.speed_cps != 0).collect();
    assert!(moving.is_empty(), "the table moved: {moving:?}");
    let lo = run.samples.iter().map(|s| s.encoder).min().unwrap();
    let hi = run.samples.iter().map(|s| s.encoder).max().unwrap();
    assert!(hi - lo <= 2, "the encoder moved {} counts during a static run", hi - lo);
    // 800 Hz, 1.2 % fast (the chip model's clock), for the recorded time.
    let per_s = run.samples.len() as f64 / run.duration_s();
    assert!((per_s - 809.6).abs() < 1.0, "{per_s} samples/s");
    assert!(run.duration_s() >= STATIC_S, "{} s recorded", run.duration_s());

    // What `host calibrate` does with it: calibrate from the moving runs, noise figures from the
    // static one through that calibration.
    let moving: Vec<_> = caps.iter().flat_map(|c| c.runs.iter().filter(|r| r.rate_mdps != 0).cloned()).collect();
    assert_eq!(moving.len(), 2);
    let result = calib::close_loop(&moving, &LoopOptions::default(), None).expect("calibration");
    let noise = host::allan::session_noise(&caps, &result.final_report().calibration()).expect("noise figures");
    // The chip model draws σ = ρ √(f_s/2) per sample (ρ over the Nyquist band), so the Allan
    // white-noise level is N = σ √τ0 = ρ/√2 and the ARW 60 ρ/√2 = 1.273 °/√h (as host::allan's
    // own test of the simulator); within 10 % on each axis.
    let arw_expected = 60.0 * NOISE_DENSITY_DPS_PER_SQRT_HZ / 2f64.sqrt();
    for a in &noise.axes {
        eprintln!("axis {}: ARW {:.4} °/√h (expected {arw_expected:.4})", a.axis, a.arw_deg_per_sqrt_h);
        assert!(
            (a.arw_deg_per_sqrt_h / arw_expected - 1.0).abs() < 0.10,
            "axis {}: ARW {} °/√h vs {arw_expected}",
            a.axis,
            a.arw_deg_per_sqrt_h
        );
    }
}
