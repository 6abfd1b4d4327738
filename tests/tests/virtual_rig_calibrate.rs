//! The whole live path: the firmware's virtual rig on a pty, recorded and calibrated by the host
//! code `host calibrate --port <pty> --yes` runs (`host::link`, `host::session`,
//! `host::capture::decode`, `host::calib::close_loop`; see host/src/main.rs), and the result held
//! against the imperfect gyro the virtual rig simulates.
//!
//! A default session (both poses at 180 and 90 °/s, 120 s each) on a healthy rig must end at the
//! noise floor, which is exit 0 of `host calibrate`. The virtual gyro has the L3G4200D's
//! datasheet noise; without it (`--noiseless-gyro`) the speed loop's table jitter, ≈ 0.03 °/s rms
//! at 20-400 Hz and below the encoder's resolution, is unexplained structure (firmware/README.md).

use e2e::{LockstepRig, VIRTUAL_GYRO_KS, VIRTUAL_GYRO_OFFSET_DPS, Z_1D, Z_2D};
use host::calib::{self, derived::mahalanobis2, LoopOptions, Verdict};
use host::capture;
use host::geometry::Pose;
use host::link::Link;
use host::session;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// Seconds recorded at speed per run: `host calibrate --duration`'s default.
const DURATION_S: f64 = 120.0;

/// `host calibrate --rates-dps`'s default.
const RATES_DPS: [f64; 2] = [180.0, 90.0];

/// ±500 °/s full scale (the rig's default): 17.5 m°/s per count (L3G4200D datasheet Table 4).
const DPS_PER_COUNT: f64 = 17.5e-3;

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
        assert_eq!((r.pose, f64::from(r.rate_mdps)), (run.pose, run.rate_dps * 1e3), "{}", file.display());
        assert!(r.stopped, "{}: RunStopped recorded", file.display());
        runs.extend(cap.runs);
    }
    let result = calib::close_loop(&runs, &LoopOptions::default(), None).expect("calibration");
    let summary = result.summary();
    // `host calibrate` exits 0 on this verdict, 3 on unexplained structure.
    assert_eq!(result.verdict(), Verdict::AtNoiseFloor, "{summary}");
    let report = result.final_report();

    // The truth in the host's units: M = K S in counts per °/s, offsets in counts.
    for (i, a) in report.axes.iter().enumerate() {
        let m: [f64; 3] = VIRTUAL_GYRO_KS[i].map(|v| v / DPS_PER_COUNT);
        let k = m.iter().map(|v| v * v).sum::<f64>().sqrt();
        let s = m.map(|v| v / k);
        let offset = VIRTUAL_GYRO_OFFSET_DPS[i] / DPS_PER_COUNT;
        let (j, l) = ((i + 1) % 3, (i + 2) % 3);
        let tilt = [s[j].atan2(s[i]).to_degrees(), s[l].atan2(s[i]).to_degrees()];
        let d = [a.tilt_components_deg[0] - tilt[0], a.tilt_components_deg[1] - tilt[1]];
        let k_z = (a.k_counts_per_dps - k) / a.k_sigma;
        let offset_z = (a.offset_counts - offset) / a.offset_sigma_counts;
        let direction_md = mahalanobis2(d, a.tilt_components_cov_deg2);
        eprintln!(
            "axis {i}: k {:.3} vs {k:.3} ({k_z:+.2} σ), direction {direction_md:.2} σ, \
             offset {:.2} vs {offset:.2} counts ({offset_z:+.2} σ)",
            a.k_counts_per_dps, a.offset_counts
        );
        assert!(
            k_z.abs() <= Z_1D && direction_md <= Z_2D && offset_z.abs() <= Z_1D,
            "axis {i} off the virtual gyro: k {k_z:.2} σ, direction {direction_md:.2} σ, \
             offset {offset_z:.2} σ\n{summary}"
        );
    }
}
