//! Unit tests of the calibration pipeline on runs from the in-test generator.

use super::testgen::{two_pose_runs, GenRun, COUNTS_PER_REV};
use super::*;
use crate::calib::data::kinematics;
use crate::geometry::Pose;
use protocol::{Bandwidth, GyroConfig};

/// θ2 and the rates come back from the encoder and index in both directions, and the real gear
/// ratio is found.
#[test]
fn kinematics_reference_theta2_in_both_directions() {
    for rate in [180.0, -180.0] {
        let mut g = GenRun::new(Pose::One, rate, 3);
        g.gear_ratio = 1.0 + 200e-6;
        let run = g.generate();
        let kin = kinematics::reconstruct(std::slice::from_ref(&run), &KinOptions::default()).unwrap();
        let k = &kin.runs[0];
        // Gear ratio: ~19 pulses, centres to ±0.3 count over 19 × 324 000 counts: σ ~ 1e-8.
        assert!((kin.gear.ratio.value - g.gear_ratio).abs() < 1e-6, "{:?}", kin.gear);
        assert!((kin.gear.deviation_ppm - 200.0).abs() < 1.0, "{:?}", kin.gear);
        // θ2 is known to the encoder quantum (360°/324 000 = 0.0011°) and the reference's σ.
        let tol_rad = (2.0 * 360.0 / f64::from(COUNTS_PER_REV)).to_radians();
        let (mut max_err, mut max_rate_err) = (0.0f64, 0.0f64);
        for s in &k.samples {
            let t = s.t_s();
            let truth = g.theta2_0_rad + g.gear_ratio * g.theta1(t).0.to_radians();
            let d = (s.theta2_rad() - truth + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            max_err = max_err.max(d.abs());
            // Windows straddling the end of the ramp (a step in acceleration, 2h samples either
            // side reach it) are not a cubic.
            if (t - g.ramp_s).abs() > 0.021 {
                max_rate_err = max_rate_err.max((s.theta1_rate_dps() - g.theta1(t).1).abs());
            }
        }
        assert!(max_err < tol_rad, "θ2 error {max_err} rad, {:?} {:?}", kin.gear, k.index);
        // Rate quantisation is 0.016 °/s rms (KinOptions); 5σ.
        assert!(max_rate_err < 5.0 * k.rate_quantisation_dps, "{max_rate_err} vs {}", k.rate_quantisation_dps);
        assert!((k.rate_quantisation_dps - 0.0162).abs() < 0.001, "{}", k.rate_quantisation_dps);
        // The 1 s ramp to within 2 % of speed lasts 0.98 s: 784 samples at 800 Hz, less the 16
        // at the start that lack full windows (the rate's and those h samples either side).
        assert_eq!(k.rate_window_samples, 17);
        assert_eq!(k.excluded_window_edge, 32);
        assert!((k.excluded_unsteady as i64 - 768).abs() <= 2, "{}", k.excluded_unsteady);
        assert_eq!(k.index.rejected, 0);
    }
}

/// The joint fit recovers M and offsets within its own σ, and the paper method agrees.
#[test]
fn joint_fit_recovers_the_generated_sensor() {
    let runs = two_pose_runs(1);
    let rep = calibrate(&runs, &CalOptions::default()).unwrap();
    let (m, off) = testgen::typical_sensor();
    // 12 parameters: a 4σ bound fails an honest σ with probability 12 × 6e-5 < 0.1 %.
    for i in 0..3 {
        for j in 0..3 {
            let sd = rep.cov[4 * i + j][4 * i + j].sqrt();
            let z = (rep.m_counts_per_dps[i][j] - m[(i, j)]) / sd;
            assert!(z.abs() < 4.0, "M[{i}][{j}] z = {z}");
        }
        let sd = rep.cov[4 * i + 3][4 * i + 3].sqrt();
        assert!(((rep.offset_counts[i] - off[i]) / sd).abs() < 4.0);
        // White noise of 7 counts plus rounding (1/12 count²): the floor and the residual both.
        let expect = (49.0f64 + 1.0 / 12.0).sqrt();
        let r = &rep.residuals[i];
        assert!((r.rms_counts / expect - 1.0).abs() < 0.02, "{r:?}");
        assert!((r.noise_floor_counts / expect - 1.0).abs() < 0.03, "{r:?}");
        // White noise: no inflation beyond the estimate's ~5 % scatter.
        assert!((rep.autocorrelation[i].inflation - 1.0).abs() < 0.15, "{:?}", rep.autocorrelation[i]);
    }
    let paper = rep.paper.as_ref().unwrap();
    assert!(paper.max_abs_z < 3.0, "{}", rep.summary());
    assert_eq!(rep.clipped, [0, 0, 0]);
}

/// A spurious pulse (a glint on the photo-interrupter) is rejected and leaves θ2 untouched.
#[test]
fn spurious_index_pulse_is_rejected() {
    let runs = two_pose_runs(8);
    let clean = kinematics::reconstruct(&runs, &KinOptions::default()).unwrap();
    let mut bad = runs.clone();
    let at = bad[0].index.len() / 2;
    let e = bad[0].index[at];
    // Between two real pulses: a quarter revolution after an edge.
    let quarter = i64::from(COUNTS_PER_REV) / 4;
    let glint = |d: i64, edge| crate::capture::RunIndexEdge {
        t_us: e.t_us + 500_000 + d,
        encoder: e.encoder + quarter + d,
        edge,
    };
    bad[0].index.insert(at + 1, glint(0, protocol::Edge::Rising));
    bad[0].index.insert(at + 2, glint(10, protocol::Edge::Falling));
    bad[0].index.sort_by_key(|x| x.t_us);
    let kin = kinematics::reconstruct(&bad, &KinOptions::default()).unwrap();
    let (a, b) = (&kin.runs[0].index, &clean.runs[0].index);
    assert_eq!((a.pulses, a.rejected), (b.pulses + 1, 1));
    assert_eq!(a.ref_counts.value, b.ref_counts.value);
}

#[test]
fn clipped_samples_are_excluded_per_axis_and_counted() {
    let mut runs = two_pose_runs(2);
    let reference = calibrate(&runs, &CalOptions::default()).unwrap();
    let steady_from = 2000;
    let mut clipped = [0u64; 3];
    for (k, s) in runs[0].samples.iter_mut().enumerate().skip(steady_from).step_by(97).take(50) {
        let axis = k % 3;
        s.rate_counts[axis] = if k % 2 == 0 { i16::MAX } else { i16::MIN };
        clipped[axis] += 1;
    }
    let rep = calibrate(&runs, &CalOptions::default()).unwrap();
    assert_eq!(rep.clipped, clipped);
    for (a, &c) in clipped.iter().enumerate() {
        assert_eq!(rep.residuals[a].n, reference.residuals[a].n - c);
        // A rail value kept in the fit would pull the offset by ~32 000/n ≈ 0.8 counts per
        // sample: far more than σ. Excluded, the fit barely moves.
        let sd = rep.axes[a].offset_counts.sigma;
        assert!((rep.offset_counts[a] - reference.offset_counts[a]).abs() < 0.5 * sd, "axis {a}");
    }
}

#[test]
fn error_messages_say_what_and_where() {
    let opts = CalOptions::default();
    assert_eq!(calibrate(&[], &opts).unwrap_err().to_string(), "no runs to calibrate: the capture holds no run");

    let runs = two_pose_runs(4);
    let err = calibrate(&runs[..1], &opts).unwrap_err();
    assert_eq!(err.to_string(), "only pose 1 was captured: pose 2 is needed too (axis directions need both poses)");
    let err = calibrate(&runs[1..], &opts).unwrap_err();
    assert_eq!(err.to_string(), "only pose 2 was captured: pose 1 is needed too (axis directions need both poses)");

    let mut bad = runs.clone();
    bad[1].index.clear();
    assert_eq!(
        calibrate(&bad, &opts).unwrap_err().to_string(),
        "run 2 (pose 2, +180.0 °/s): no complete index pulse (rising then falling edge) among 0 edges, cannot reference θ2"
    );

    // A lone falling edge (the run started with the plate blocking) is no pulse.
    let mut bad = runs.clone();
    bad[1].index.retain(|e| e.edge == protocol::Edge::Falling);
    bad[1].index.truncate(1);
    assert_eq!(
        calibrate(&bad, &opts).unwrap_err().to_string(),
        "run 2 (pose 2, +180.0 °/s): no complete index pulse (rising then falling edge) among 1 edges, cannot reference θ2"
    );

    let mut bad = runs.clone();
    bad[1].gyro = GyroConfig { bandwidth: Bandwidth::Bw0, ..GyroConfig::DEFAULT };
    assert_eq!(
        calibrate(&bad, &opts).unwrap_err().to_string(),
        "run 2 (pose 2, +180.0 °/s): gyro config GyroConfig { full_scale: Dps500, odr: Hz800, bandwidth: Bw0 } differs from run 1's GyroConfig { full_scale: Dps500, odr: Hz800, bandwidth: Bw3 }"
    );

    // 1.5 s: within 2 % of speed from 0.98 s (sample 784) to the last full rate window (sample
    // 1183): 399 samples, less than one 2 s revolution (1600 samples).
    let mut g = GenRun::new(Pose::Two, 180.0, 5);
    g.duration_s = 1.5;
    let short = vec![runs[0].clone(), g.generate()];
    assert_eq!(
        calibrate(&short, &opts).unwrap_err().to_string(),
        "run 2 (pose 2, +180.0 °/s): too few usable samples (399 of 1200 at steady speed), need at least 1600 (one sensor-table revolution)"
    );

    let mut dead = runs.clone();
    for r in &mut dead {
        for s in &mut r.samples {
            s.rate_counts[2] = i16::MAX;
        }
    }
    assert_eq!(
        calibrate(&dead, &opts).unwrap_err().to_string(),
        "axis z: every one of the 30234 samples at steady speed is clipped at the output's rails (the axis is dead, or the rates exceed the full scale)"
    );
    // Three samples left on axis z cannot hold its four parameters (M's row and the offset).
    for s in dead[0].samples.iter_mut().skip(5000).step_by(1000).take(3) {
        s.rate_counts[2] = 100;
    }
    let err = calibrate(&dead, &opts).unwrap_err().to_string();
    let (head, tail) = (
        "normal matrix of axis z is singular (reciprocal condition ",
        "): its unclipped samples do not excite every rate direction",
    );
    assert!(err.starts_with(head) && err.ends_with(tail), "{err}");
    let rcond: f64 = err[head.len()..err.len() - tail.len()].parse().unwrap();
    assert!(rcond < 1e-13, "{err}");
}

#[test]
fn report_and_calibration_round_trip_through_json() {
    let rep = calibrate(&two_pose_runs(6), &CalOptions::default()).unwrap();
    let json = serde_json::to_string(&rep).unwrap();
    let back: CalReport = serde_json::from_str(&json).unwrap();
    assert_eq!(back, rep);
    let cal = rep.calibration();
    assert_eq!(Calibration::from_json(&cal.to_json()).unwrap(), cal);
    let text = rep.summary();
    for needle in ["counts/(°/s)", "Angles between axes", "Gear ratio", "Paper method", "noise floor measured"] {
        assert!(text.contains(needle), "summary lacks {needle:?}:\n{text}");
    }
    // The generator's plate spans 4° of θ2 = 3600 counts at 1:1; its 50 µs edge grid is 8 counts.
    let width = rep.runs[0].index.plate_width_counts;
    assert!((width - 4.0 / 360.0 * f64::from(COUNTS_PER_REV)).abs() <= 16.0, "{width}");
}
