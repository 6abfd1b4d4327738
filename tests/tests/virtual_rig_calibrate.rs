//! The whole live path: the firmware's virtual rig on a pty, recorded and calibrated by the host
//! code `host calibrate --port <pty> --yes` runs (`host::link`, `host::session`,
//! `host::capture::decode`, `host::calib::close_loop`; see host/src/cli.rs), and the result held
//! against the imperfect gyro the virtual rig simulates.
//!
//! A default session (both poses at 180, 90 and −180 °/s, 120 s each) on a healthy rig must end at the
//! noise floor, which is exit 0 of `host calibrate`. The virtual gyro has the L3G4200D's
//! datasheet noise; without it (`--noiseless-gyro`) the speed loop's table jitter, ≈ 0.03 °/s rms
//! at 20-400 Hz and below the encoder's resolution, is unexplained structure (firmware/README.md).

use e2e::{assert_matches_virtual_gyro, LockstepRig};
use host::calib::{self, LoopOptions, Verdict};
use host::capture;
use host::geometry::Pose;
use host::link::Link;
use host::session;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// Seconds recorded at speed per run: `host calibrate --duration`'s default.
const DURATION_S: f64 = 120.0;

/// `host calibrate --rates-dps`'s default.
const RATES_DPS: [f64; 3] = [180.0, 90.0, -180.0];

#[test]
fn host_calibrate_over_a_pty_recovers_the_virtual_gyro() {
    // The rig in lockstep: the host's clock is the rig's simulated time, so its heartbeats and
    // timeouts hold however loaded the machine is.
    let rig = LockstepRig::spawn(env!("CARGO_BIN_EXE_virtual_rig"), &[]);
    let port = rig.path.clone();
    let clock = rig.clock();

    // `host calibrate --port <pty> --yes --out-dir <dir>`, step by step.
    let out_dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("virtual-rig-calibrate");
    let _ = std::fs::remove_dir_all(&out_dir); // captures are never overwritten
    let mut link = Link::with_clock(rig, port.as_str(), Box::new(clock));
    let plan = session::plan(&Pose::ALL, &RATES_DPS, DURATION_S);
    let files = session::record_session(&mut link, &plan, &out_dir, &mut session::AssumeYes, &AtomicBool::new(false))
        .expect("live session");

    let mut runs = Vec::new();
    for (file, run) in files.iter().zip(&plan) {
        let cap = capture::decode(&std::fs::read(file).expect("capture"));
        let loss = &cap.loss;
        // Samples streamed between the Identify and the Start belong to no run ("orphans"):
        // expected live, and not a loss.
        assert!(
            loss.errors.is_empty() && loss.seq_gaps.is_empty(),
            "{}: {} frames missing, {} bytes corrupt: {loss:?}",
            file.display(),
            loss.frames_missing(),
            loss.bytes_skipped(),
        );
        eprintln!(
            "{}: {} bytes, {} frames, 0 lost, 0 corrupt, {} samples before the run",
            file.display(),
            loss.bytes,
            loss.frames_ok,
            loss.orphan_samples
        );
        assert_eq!(cap.runs.len(), 1, "{}", file.display());
        let r = &cap.runs[0];
        assert_eq!((r.pose, r.commanded_rate_dps()), (run.pose, run.rate_dps), "{}", file.display());
        assert!(r.stopped, "{}: RunStopped recorded", file.display());
        runs.extend(cap.runs);
    }
    let result = calib::close_loop(&runs, &LoopOptions::default(), None).expect("calibration");
    let summary = result.summary();
    // `host calibrate` exits 0 on this verdict, 3 on unexplained structure.
    assert_eq!(result.verdict(), Verdict::AtNoiseFloor, "{summary}");
    assert_matches_virtual_gyro(result.final_report());
}
