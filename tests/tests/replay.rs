//! Replays of committed and generated captures: what a capture holds, and the calibration it
//! gives, against the truth it was simulated from.

use e2e::{assert_within_3_sigma, committed};
use host::calib::{self, CalOptions};
use host::capture::decode;
use host::geometry::Pose;
use host::sim::{self, RunSpec, SimConfig};

#[test]
fn the_committed_demo_capture_decodes_cleanly_and_calibrates_to_its_truth() {
    let (bytes, truth) = committed("demo");
    let cap = decode(&bytes);
    assert!(cap.loss.is_clean(), "{:?}", cap.loss);
    assert_eq!(cap.loss.bytes, bytes.len() as u64);
    let poses: Vec<Pose> = cap.runs.iter().map(|r| r.pose).collect();
    assert_eq!(poses, [Pose::One, Pose::Two]);
    for (run, rt) in cap.runs.iter().zip(&truth.runs) {
        assert!(run.stopped);
        assert_eq!(run.commanded_rate_dps(), rt.rate_dps);
        // Samples at the simulated gyro's true ODR over the run, ±2 for the run's edges.
        let expected = rt.duration_s * truth.odr_hz_actual;
        assert!((run.samples.len() as f64 - expected).abs() <= 2.0, "{} vs {expected}", run.samples.len());
    }
    let report = calib::calibrate(&cap.runs, &CalOptions::default()).expect("calibrates");
    assert_within_3_sigma(&report, &truth, "demo.cap");
}

#[test]
fn timestamps_and_encoder_wrapping_mid_run_change_nothing() {
    let runs = vec![
        RunSpec { pose: Pose::One, rate_dps: 180.0, duration_s: 8.0 },
        RunSpec { pose: Pose::Two, rate_dps: 180.0, duration_s: 8.0 },
    ];
    let mut plain = SimConfig::with_runs(21, runs);
    plain.start_t_us = 0;
    let mut wrapped = plain.clone();
    // The µs clock wraps 6 s into the session (during pose 1), the encoder 2 s later.
    wrapped.start_t_us = u32::MAX - 6_000_000;
    wrapped.start_encoder = u32::MAX - 1_000_000;
    let a = sim::simulate(&plain).unwrap();
    let b = sim::simulate(&wrapped).unwrap();
    let (ca, cb) = (decode(&a.bytes), decode(&b.bytes));
    assert!(cb.loss.is_clean(), "{:?}", cb.loss);
    for (ra, rb) in ca.runs.iter().zip(&cb.runs) {
        assert_eq!(ra.samples.len(), rb.samples.len());
        assert!(rb.samples.windows(2).all(|w| w[1].t_us > w[0].t_us), "unwrapped time is monotonic");
        assert!(rb.samples.windows(2).all(|w| w[1].encoder >= w[0].encoder), "unwrapped encoder never steps back");
    }
    let ka = calib::calibrate(&ca.runs, &CalOptions::default()).unwrap();
    let kb = calib::calibrate(&cb.runs, &CalOptions::default()).unwrap();
    for i in 0..3 {
        // Same sensor, same noise: only the time origin differs, so the estimates agree to
        // far below their σ.
        let (k_a, k_b) = (ka.axes[i].k_counts_per_dps, kb.axes[i].k_counts_per_dps);
        let dk = (k_a.value - k_b.value).abs();
        assert!(dk < 0.05 * k_a.sigma, "axis {i}: {dk}");
    }
    assert_within_3_sigma(&kb, &b.truth, "wrapped");
}

#[test]
fn a_capture_with_one_pose_is_refused_with_the_missing_pose_named() {
    let out =
        sim::simulate(&SimConfig::with_runs(3, vec![RunSpec { pose: Pose::Two, rate_dps: 180.0, duration_s: 4.0 }]))
            .unwrap();
    let cap = decode(&out.bytes);
    let err = calib::calibrate(&cap.runs, &CalOptions::default()).unwrap_err();
    assert_eq!(err.to_string(), "only pose 2 was captured: pose 1 is needed too (axis directions need both poses)");
}
