//! End-to-end tests of the simulator through the host's own decoder: the bytes must decode with
//! zero loss and carry exactly the physics and effects configured.

use super::*;
use crate::capture::{decode, Capture, Run};
use crate::geometry::Pose;
use protocol::{Direction, Edge, FullScale, GearRatio, RigMsg, StreamDecoder, ENCODER_COUNTS_PER_REV};
use std::f64::consts::TAU;

const CPR: f64 = ENCODER_COUNTS_PER_REV as f64;

pub(super) fn decode_clean(bytes: &[u8]) -> Capture {
    let cap = decode(bytes);
    assert!(cap.loss.is_clean(), "{:?}", cap.loss);
    assert_eq!(cap.loss.bytes, bytes.len() as u64);
    cap
}

/// Encoder counts at the centres of the run's index pulses (midpoint of a rising edge and the
/// falling edge that follows it).
pub(super) fn index_centres(run: &Run) -> Vec<f64> {
    run.index
        .windows(2)
        .filter(|w| w[0].edge == Edge::Rising && w[1].edge == Edge::Falling)
        .map(|w| 0.5 * (w[0].encoder + w[1].encoder) as f64)
        .collect()
}

/// Samples after the spin-up has ended, with a margin.
pub(super) fn steady(run: &Run, cfg: &SimConfig) -> Vec<crate::capture::RunSample> {
    let t0 = run.samples[0].t_us;
    let skip_us = ((cfg.spin_up_s + 0.5) * 1e6) as i64;
    run.samples.iter().copied().filter(|s| s.t_us - t0 > skip_us).collect()
}

/// Least-squares time shift τ (s) of the samples against the truth model, `v(t) = m(t − τ)`,
/// with θ2 from the encoder referenced to the first index centre plus `theta2_extra_rad`, and
/// its standard error from the truth's noise (white noise plus rounding).
pub(super) fn fit_delay_s(run: &Run, cfg: &SimConfig, truth: &Truth, theta2_extra_rad: f64) -> (f64, f64) {
    let rate = run.commanded_rate_dps();
    let ratio = truth.gear_ratio_nominal;
    let w2_rad_s = (ratio * rate).to_radians();
    let c0 = index_centres(run)[0];
    let (mut rg, mut gg) = (0.0, 0.0);
    for s in steady(run, cfg) {
        let th = ratio * (s.encoder as f64 - c0) / CPR * TAU + theta2_extra_rad;
        let m = truth.model_counts(run.pose, rate, th, ratio * rate);
        let h = 1e-5;
        let dm = (truth.model_counts(run.pose, rate, th + h, ratio * rate)
            - truth.model_counts(run.pose, rate, th - h, ratio * rate))
            / (2.0 * h)
            * w2_rad_s;
        for i in 0..3 {
            let r = f64::from(s.rate_counts[i]) - m[i];
            rg += r * dm[i];
            gg += dm[i] * dm[i];
        }
    }
    let sigma = truth.noise_counts_per_sample.iter().fold(0.0f64, |a, &s| a.max((s * s + 1.0 / 12.0).sqrt()));
    (-rg / gg, sigma / gg.sqrt())
}

/// Rms of the steady samples' difference from the truth model over all axes, counts.
pub(super) fn residual_rms(run: &Run, cfg: &SimConfig, truth: &Truth) -> f64 {
    let rate = run.commanded_rate_dps();
    let c0 = index_centres(run)[0];
    let (mut ss, mut n) = (0.0, 0.0);
    for s in steady(run, cfg) {
        let th = (s.encoder as f64 - c0) / CPR * TAU;
        let m = truth.model_counts(run.pose, rate, th, rate);
        for i in 0..3 {
            ss += (f64::from(s.rate_counts[i]) - m[i]).powi(2);
            n += 1.0;
        }
    }
    (ss / n).sqrt()
}

/// Time of one encoder count at `rate_dps`, s: the resolution of an encoder-derived θ2 in time.
pub(super) fn encoder_quantum_s(rate_dps: f64) -> f64 {
    360.0 / CPR / rate_dps.abs()
}

#[test]
fn standard_capture_decodes_cleanly_with_the_configured_structure() {
    let cfg = SimConfig::standard(7, 10.0);
    let out = simulate(&cfg).unwrap();
    let cap = decode_clean(&out.bytes);
    let hello = cap.hello.expect("Hello first");
    assert_eq!(hello.protocol_version, protocol::PROTOCOL_VERSION);
    assert_eq!(hello.encoder_counts_per_rev, 324_000);
    assert_eq!(hello.gear_ratio, GearRatio { num: 1, den: 1 });
    assert_eq!(hello.timestamp_hz, 1_000_000);
    assert_eq!(hello.gyro, GyroConfig::DEFAULT);
    assert_eq!(cap.runs.len(), 2);
    for ((run, spec), rt) in cap.runs.iter().zip(&cfg.runs).zip(&out.truth.runs) {
        assert_eq!(run.pose, spec.pose);
        assert_eq!(run.rate_mdps, 180_000);
        assert_eq!(run.direction, Direction::Ccw);
        assert!(run.stopped);
        assert_eq!(run.samples.len() as u64, rt.samples);
        assert_eq!(run.index.len() as u64, rt.index_edges);
        // Data-ready lattice at the actual ODR: N = duration·ODR, ±1 for the phase.
        let expected = spec.duration_s * out.truth.odr_hz_actual;
        assert!((run.samples.len() as f64 - expected).abs() <= 1.0, "{} vs {expected}", run.samples.len());
        // 10 Hz motor status, 1 Hz temperature and counters, over 10 s.
        assert_eq!(run.motor.len(), 100);
        assert_eq!(run.temperatures.len(), 10);
        assert_eq!(run.counters.len(), 10);
        assert!(run.motor.iter().all(|(_, m)| m.run_tag == spec.pose.run_tag()));
        // Every sample read is accounted for in the counters and no frame is ever dropped.
        let last = run.counters.last().unwrap().1;
        assert_eq!(last.queue_drops, 0);
        assert!(last.samples_read > 0);
    }
    // 135° of ramp then 8.5 s at 180 °/s: 4.6 turns, so 4 or 5 plate passages of 2 edges.
    for run in &cap.runs {
        assert!((8..=10).contains(&run.index.len()), "{}", run.index.len());
    }
}

#[test]
fn sample_rate_encoder_rate_and_index_period_match_the_configuration() {
    let cfg = SimConfig::standard(11, 12.0);
    let out = simulate(&cfg).unwrap();
    let cap = decode_clean(&out.bytes);
    let truth = &out.truth;
    assert!(truth.odr_error_ppm.abs() < 5.0 * 300.0);
    for run in &cap.runs {
        let s = &run.samples;
        let n = (s.len() - 1) as f64;
        // Mean interval: end points carry ±1 µs jitter and ±0.5 µs rounding each.
        let mean_us = (s.last().unwrap().t_us - s[0].t_us) as f64 / n;
        assert!((mean_us - 1e6 / truth.odr_hz_actual).abs() < 10.0 / n, "{mean_us}");
        // Every interval is the period ± jitter (5 σ of the difference of two 1 µs jitters, plus
        // rounding).
        for w in s.windows(2) {
            let d = (w[1].t_us - w[0].t_us) as f64 - 1e6 / truth.odr_hz_actual;
            assert!(d.abs() < 5.0 * 2f64.sqrt() + 1.0, "{d}");
        }
        // Encoder rate at constant speed: 180 °/s = 162 000 counts/s; 1 count and a few µs of
        // timestamp error over ≥ 10 s.
        let st = steady(run, &cfg);
        let (a, b) = (st[0], *st.last().unwrap());
        let cps = (b.encoder - a.encoder) as f64 / ((b.t_us - a.t_us) as f64 * 1e-6);
        assert!((cps - 162_000.0).abs() < 0.5, "{cps}");
        // Index period: one plate passage per sensor-table turn = 324 000 counts at ratio 1,
        // each centre to half a count.
        let c = index_centres(run);
        assert!(c.len() >= 4);
        for w in c.windows(2) {
            assert!((w[1] - w[0] - CPR).abs() <= 1.0, "{}", w[1] - w[0]);
        }
        // Pulse width = plate width (4°) in encoder counts, ±1.
        for w in run.index.windows(2).filter(|w| w[0].edge == Edge::Rising) {
            assert!(((w[1].encoder - w[0].encoder) as f64 - 3600.0).abs() <= 1.0);
        }
    }
}

#[test]
fn index_centres_are_at_theta2_equal_to_the_index_offset_both_ways() {
    // Noise-free so the phase fit is limited only by quantisation.
    for (offset_deg, rate_dps) in [(0.0, 180.0), (3.0, 180.0), (3.0, -180.0), (-2.0, 90.0)] {
        let mut cfg = SimConfig::with_runs(3, vec![RunSpec { pose: Pose::Two, rate_dps, duration_s: 8.0 }]);
        cfg.noise_dps_per_sqrt_hz = 0.0;
        if offset_deg != 0.0 {
            cfg.effects.enable(&format!("index_offset_deg={offset_deg}")).unwrap();
        }
        let out = simulate(&cfg).unwrap();
        let cap = decode_clean(&out.bytes);
        let run = &cap.runs[0];
        assert_eq!(out.truth.index_offset_deg, offset_deg);
        // θ2 = index-derived θ2 + φ: fit φ. A time shift τ of the model is a θ2 shift of θ2'·τ,
        // so the delay fit gives φ = −θ2'·τ when θ2 is taken without the offset.
        let (tau_s, _) = fit_delay_s(run, &cfg, &out.truth, 0.0);
        let phi_deg = -tau_s * rate_dps;
        // Resolution: the encoder count (0.0011°), twice (edges and samples).
        assert!((phi_deg - offset_deg).abs() < 0.003, "offset {offset_deg}, rate {rate_dps}: φ = {phi_deg}");
    }
}

#[test]
fn truth_has_m_equal_k_times_s_with_unit_axes_and_survives_json() {
    let out = simulate(&SimConfig::standard(5, 1.0)).unwrap();
    let t = &out.truth;
    for i in 0..3 {
        let s = nalgebra::Vector3::from(t.s[i]);
        assert!((s.norm() - 1.0).abs() < 1e-12);
        for j in 0..3 {
            assert!((t.m_counts_per_dps[i][j] - t.k_counts_per_dps[i] * t.s[i][j]).abs() < 1e-9);
        }
        assert!((s[i].acos().to_degrees() - t.tilt_deg[i]).abs() < 1e-9);
        // Nominal 57.14 counts/(°/s) at ±500 °/s, within 5 σ of the 1.5 % spread.
        assert!((t.k_counts_per_dps[i] / (1e6 / 17_500.0) - 1.0).abs() < 0.075);
    }
    let back: Truth = serde_json::from_str(&t.to_json_pretty()).unwrap();
    assert_eq!(&back, t);
    let v: serde_json::Value = serde_json::from_str(&t.to_json_pretty()).unwrap();
    for key in [
        "seed",
        "m_counts_per_dps",
        "k_counts_per_dps",
        "s",
        "offset_counts",
        "noise_dps_per_sqrt_hz",
        "gyro",
        "gear_ratio",
        "index_offset_deg",
        "runs",
        "effects",
    ] {
        assert!(v.get(key).is_some(), "{key}");
    }
}

#[test]
fn deterministic_for_a_seed_and_the_sensor_independent_of_the_runs() {
    let a = simulate(&SimConfig::standard(42, 2.0)).unwrap();
    let b = simulate(&SimConfig::standard(42, 2.0)).unwrap();
    assert_eq!(a.bytes, b.bytes);
    assert_eq!(a.truth, b.truth);
    let c = simulate(&SimConfig::standard(43, 2.0)).unwrap();
    assert_ne!(a.truth.m_counts_per_dps, c.truth.m_counts_per_dps);
    assert_ne!(a.bytes, c.bytes);
    // Same seed, longer runs: same sensor, and the first run starts with the same samples.
    let d = simulate(&SimConfig::standard(42, 5.0)).unwrap();
    assert_eq!(a.truth.m_counts_per_dps, d.truth.m_counts_per_dps);
    assert_eq!(a.truth.offset_counts, d.truth.offset_counts);
    assert_eq!(a.truth.odr_hz_actual, d.truth.odr_hz_actual);
    let (ra, rd) = (&decode_clean(&a.bytes).runs[0], &decode_clean(&d.bytes).runs[0]);
    assert_eq!(ra.samples[..], rd.samples[..ra.samples.len()]);
}

#[test]
fn simulate_to_streams_exactly_the_in_memory_bytes() {
    let cfg = SimConfig::standard(9, 1.5);
    let out = simulate(&cfg).unwrap();
    let mut streamed = Vec::new();
    let truth = simulate_to(&cfg, &mut streamed).unwrap();
    assert_eq!(streamed, out.bytes);
    assert_eq!(truth, out.truth);
    let mut bad = cfg.clone();
    bad.runs[0].duration_s = f64::NAN;
    let err = simulate_to(&bad, &mut Vec::new()).unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
}

#[test]
fn several_speeds_and_both_directions_decode_with_their_rates() {
    let runs = vec![
        RunSpec { pose: Pose::One, rate_dps: 90.0, duration_s: 6.0 },
        RunSpec { pose: Pose::One, rate_dps: -180.0, duration_s: 6.0 },
        RunSpec { pose: Pose::Two, rate_dps: 270.0, duration_s: 6.0 },
    ];
    let cfg = SimConfig::with_runs(21, runs.clone());
    let out = simulate(&cfg).unwrap();
    let cap = decode_clean(&out.bytes);
    assert_eq!(cap.runs.len(), 3);
    for (run, spec) in cap.runs.iter().zip(&runs) {
        assert_eq!(run.commanded_rate_dps(), spec.rate_dps);
        let st = steady(run, &cfg);
        let (a, b) = (st[0], *st.last().unwrap());
        let dps = (b.encoder - a.encoder) as f64 / CPR * 360.0 / ((b.t_us - a.t_us) as f64 * 1e-6);
        assert!((dps - spec.rate_dps).abs() < 0.01, "{dps} vs {}", spec.rate_dps);
        // The spin-up is in the stream: the first samples are nearly at rest.
        let early = (run.samples[8].encoder - run.samples[0].encoder).abs();
        assert!(early < 20, "{early}");
        // Plate passages alternate rising/falling in either direction.
        for w in run.index.windows(2) {
            assert_ne!(w[0].edge, w[1].edge);
        }
        // The last motor status reports the setpoint and a measured speed near it.
        let m = run.motor.last().unwrap().1;
        assert_eq!(m.setpoint_cps, (spec.rate_dps * 900.0).round() as i32);
        assert!((m.speed_cps - m.setpoint_cps).abs() <= 10);
        assert_eq!(m.duty_permille.signum(), spec.rate_dps.signum() as i16);
    }
}

#[test]
fn timestamp_and_encoder_wrap_mid_run_decode_monotonic() {
    let mut cfg = SimConfig::standard(4, 3.0);
    // The timer wraps 1 s into the first run, the encoder early in its spin-up.
    cfg.start_t_us = u32::MAX - 3_000_000;
    cfg.start_encoder = u32::MAX - 2_000;
    let out = simulate(&cfg).unwrap();
    let cap = decode_clean(&out.bytes);
    let mut raw_wrapped = false;
    StreamDecoder::new().feed::<RigMsg>(&out.bytes, |ev| {
        if let protocol::Event::Frame { msg: RigMsg::Sample(s), .. } = ev {
            raw_wrapped |= s.t_us < 1_000_000;
        }
    });
    assert!(raw_wrapped, "the test must actually wrap");
    for run in &cap.runs {
        for w in run.samples.windows(2) {
            let d = w[1].t_us - w[0].t_us;
            assert!((1240..=1260).contains(&d), "{d}");
            assert!(w[1].encoder >= w[0].encoder);
        }
    }
    assert_eq!(
        cap.runs[0].samples.len(),
        decode_clean(&simulate(&SimConfig::standard(4, 3.0)).unwrap().bytes).runs[0].samples.len()
    );
}

#[test]
fn clipping_comes_from_the_range_not_from_the_rate() {
    let clipped = |fs: FullScale, rate_dps: f64| {
        let mut cfg = SimConfig::with_runs(8, vec![RunSpec { pose: Pose::One, rate_dps, duration_s: 5.0 }]);
        cfg.gyro.full_scale = fs;
        let cap = decode_clean(&simulate(&cfg).unwrap().bytes);
        let s = &cap.runs[0].samples;
        s.iter().filter(|s| s.rate_counts.iter().any(|&c| c == i16::MAX || c == i16::MIN)).count()
    };
    // ±250 °/s reads up to 32 767 × 8.75 m°/s = 286.7 °/s: pose 1 at 240 °/s peaks at 335 °/s.
    assert!(clipped(FullScale::Dps250, 240.0) > 100);
    assert_eq!(clipped(FullScale::Dps500, 240.0), 0);
    // At 180 °/s pose 1 peaks at 251 °/s: over the rated ±250 but under the register's limit.
    assert_eq!(clipped(FullScale::Dps250, 180.0), 0);
}

/// The same session with and without one effect.
fn with_and_without(seed: u64, spec: &str, secs: f64) -> (SimConfig, SimOutput, Capture, SimOutput, Capture) {
    let base_cfg = SimConfig::standard(seed, secs);
    let mut cfg = base_cfg.clone();
    cfg.effects.enable(spec).unwrap();
    let base = simulate(&base_cfg).unwrap();
    let eff = simulate(&cfg).unwrap();
    let (cb, ce) = (decode_clean(&base.bytes), decode_clean(&eff.bytes));
    assert_eq!(cb.hello, ce.hello, "{spec}: Hello must not reveal an effect");
    assert_eq!(base.truth.m_counts_per_dps, eff.truth.m_counts_per_dps);
    (cfg, base, cb, eff, ce)
}

fn encoders(c: &Capture) -> Vec<(i64, i64)> {
    c.runs.iter().flat_map(|r| r.samples.iter().map(|s| (s.t_us, s.encoder))).collect()
}

fn index(c: &Capture) -> Vec<(i64, i64)> {
    c.runs.iter().flat_map(|r| r.index.iter().map(|e| (e.t_us, e.encoder))).collect()
}

fn axis(c: &Capture, i: usize) -> Vec<i16> {
    c.runs.iter().flat_map(|r| r.samples.iter().map(move |s| s.rate_counts[i])).collect()
}

fn temps(c: &Capture) -> Vec<i8> {
    c.runs.iter().flat_map(|r| r.temperatures.iter().map(|t| t.raw)).collect()
}

#[test]
fn pure_delay_shifts_the_samples_by_exactly_that_delay_and_nothing_else() {
    let (cfg, base, cb, eff, ce) = with_and_without(31, "delay_ms=5", 10.0);
    assert_eq!(encoders(&cb), encoders(&ce));
    assert_eq!(index(&cb), index(&ce));
    assert_eq!(temps(&cb), temps(&ce));
    for (run_b, run_e) in cb.runs.iter().zip(&ce.runs) {
        let (tau0, sigma0) = fit_delay_s(run_b, &cfg, &base.truth, 0.0);
        let (tau, sigma) = fit_delay_s(run_e, &cfg, &eff.truth, 0.0);
        let tol = 5.0 * sigma.max(sigma0) + encoder_quantum_s(180.0);
        assert!(tau0.abs() < tol, "baseline τ = {tau0} ± {sigma0}");
        assert!((tau - 5e-3).abs() < tol, "τ = {tau} ± {sigma}");
    }
    assert!(eff.truth.runs.iter().all(|r| (r.total_delay_ms - 5.0).abs() < 1e-12));
}

#[test]
fn lowpass_delays_by_its_reported_group_delay() {
    for bw in [protocol::Bandwidth::Bw3, protocol::Bandwidth::Bw0] {
        let mut cfg = SimConfig::standard(32, 10.0);
        cfg.gyro.bandwidth = bw;
        cfg.effects.enable("filter_delay").unwrap();
        let out = simulate(&cfg).unwrap();
        let cap = decode_clean(&out.bytes);
        let fc = f64::from(bw.cutoff_dhz(cfg.gyro.odr)) / 10.0;
        assert_eq!(out.truth.lowpass_cutoff_hz, Some(fc));
        for (run, rt) in cap.runs.iter().zip(&out.truth.runs) {
            // Reported: near the analogue √2/(2π·fc) (2.05 ms at 110 Hz, 7.50 ms at 30 Hz); the
            // bilinear map at the 800 Hz ODR shortens it by (πfc/ODR)²-order terms, 6 % at 110 Hz.
            let analogue_ms = 1e3 * std::f64::consts::SQRT_2 / (TAU * fc);
            assert!((rt.filter_group_delay_ms / analogue_ms - 1.0).abs() < 0.08);
            let (tau, sigma) = fit_delay_s(run, &cfg, &out.truth, 0.0);
            let tol = 5.0 * sigma + encoder_quantum_s(180.0);
            assert!((tau - rt.total_delay_ms * 1e-3).abs() < tol, "{bw:?}: τ = {tau} ± {sigma} vs {rt:?}");
        }
    }
}

/// A 3rd-order filter at a cut-off of its own (not the configured bandwidth's): the truth
/// reports that cut-off and the filter's delay, ≈ 2/(2π·fc), and the samples are delayed by it.
#[test]
fn a_third_order_lowpass_at_its_own_cutoff_delays_by_its_reported_group_delay() {
    let mut cfg = SimConfig::standard(34, 10.0);
    cfg.effects.enable("filter_order=3").unwrap();
    cfg.effects.enable("filter_cutoff_hz=35").unwrap();
    let out = simulate(&cfg).unwrap();
    let cap = decode_clean(&out.bytes);
    assert_eq!(out.truth.lowpass_cutoff_hz, Some(35.0));
    for (run, rt) in cap.runs.iter().zip(&out.truth.runs) {
        // Analogue 9.09 ms; the bilinear map at 800 Hz changes it by a few %.
        let analogue_ms = 1e3 * 2.0 / (TAU * 35.0);
        assert!((rt.filter_group_delay_ms / analogue_ms - 1.0).abs() < 0.05, "{rt:?}");
        let (tau, sigma) = fit_delay_s(run, &cfg, &out.truth, 0.0);
        let tol = 5.0 * sigma + encoder_quantum_s(180.0);
        assert!((tau - rt.total_delay_ms * 1e-3).abs() < tol, "τ = {tau} ± {sigma} vs {rt:?}");
    }
}

#[test]
fn index_offset_moves_only_the_index() {
    let (_, _, cb, eff, ce) = with_and_without(33, "index_offset_deg=3", 6.0);
    for i in 0..3 {
        assert_eq!(axis(&cb, i), axis(&ce, i));
    }
    assert_eq!(encoders(&cb), encoders(&ce));
    assert_eq!(eff.truth.index_offset_deg, 3.0);
    for (rb, re) in cb.runs.iter().zip(&ce.runs) {
        // Plate moved +3° in θ2: each centre 2700 counts later (ratio 1), ± 1 count.
        let (b, e) = (index_centres(rb), index_centres(re));
        let shift = e[0] - b.iter().copied().find(|&c| c < e[0] && e[0] - c < CPR / 2.0).unwrap();
        assert!((shift - 2700.0).abs() <= 1.0, "{shift}");
    }
}

#[test]
fn gear_ratio_error_changes_the_index_period_but_not_the_hello() {
    let (_, _, cb, eff, ce) = with_and_without(34, "gear_ratio_error=200", 12.0);
    assert_eq!(eff.truth.gear_ratio, 1.0 + 200e-6);
    assert_eq!(encoders(&cb), encoders(&ce));
    for run in &ce.runs {
        let c = index_centres(run);
        let period = (c.last().unwrap() - c[0]) / (c.len() - 1) as f64;
        assert!((period - CPR / (1.0 + 200e-6)).abs() < 0.5, "{period}");
    }
    assert_ne!(axis(&cb, 0), axis(&ce, 0));
}

#[test]
fn mystery_harmonic_appears_on_one_axis_only_with_its_amplitude() {
    let (cfg, _, cb, eff, ce) = with_and_without(35, "mystery_harmonic", 6.0);
    assert_eq!(encoders(&cb), encoders(&ce));
    assert_eq!(axis(&cb, 1), axis(&ce, 1));
    assert_eq!(axis(&cb, 2), axis(&ce, 2));
    let m = cfg.effects.mystery_harmonic.unwrap();
    let k0 = eff.truth.k_counts_per_dps[0];
    // Identical noise, so the difference is the harmonic itself to within the two roundings.
    for (rb, re) in cb.runs.iter().zip(&ce.runs) {
        let c0 = index_centres(rb)[0];
        let mut peak = 0.0f64;
        for (sb, se) in rb.samples.iter().zip(&re.samples) {
            let th = (se.encoder as f64 - c0) / CPR * TAU;
            let want = m.amplitude_dps * k0 * (f64::from(m.order) * th + m.phase_rad).sin();
            let got = f64::from(se.rate_counts[0]) - f64::from(sb.rate_counts[0]);
            assert!((got - want).abs() <= 1.1, "{got} vs {want}");
            peak = peak.max(got.abs());
        }
        assert!(peak > 0.9 * m.amplitude_dps * k0);
    }
}

#[test]
fn nonlinearity_adds_its_formula_to_the_samples_and_leaves_the_motion() {
    let (cfg, base, cb, _, ce) = with_and_without(36, "nonlinearity", 6.0);
    assert_eq!(encoders(&cb), encoders(&ce));
    assert_eq!(index(&cb), index(&ce));
    let n = cfg.effects.nonlinearity.unwrap();
    let t = &base.truth;
    for (rb, re) in cb.runs.iter().zip(&ce.runs) {
        let rate = rb.commanded_rate_dps();
        let c0 = index_centres(rb)[0];
        for (sb, se) in steady(rb, &cfg).iter().zip(steady(re, &cfg)) {
            let th = (sb.encoder as f64 - c0) / CPR * TAU;
            let v = t.model_counts(rb.pose, rate, th, rate) - t.offset();
            for i in 0..3 {
                let x = v[i] / t.k_counts_per_dps[i];
                let extra = x * 0.5 * n.asymmetry * x.signum() + n.quadratic_fs * x * x.abs() / 500.0;
                let want = extra * t.k_counts_per_dps[i];
                let got = f64::from(se.rate_counts[i]) - f64::from(sb.rate_counts[i]);
                // Two roundings, and θ2 from the encoder to one count (0.0011° ≈ 0.2 counts).
                assert!((got - want).abs() <= 1.3, "axis {i}: {got} vs {want}");
            }
        }
    }
}

#[test]
fn offset_drift_follows_the_warm_up_in_samples_and_temperature() {
    let (cfg, base, cb, _, ce) = with_and_without(37, "offset_drift", 60.0);
    assert_eq!(encoders(&cb), encoders(&ce));
    let d = cfg.effects.offset_drift.unwrap();
    let k = base.truth.k_counts_per_dps;
    let rise = |t_s: f64| d.rise_c * (1.0 - (-t_s / d.tau_s).exp());
    // Samples: the difference is the drift, to within the two roundings.
    let t_first_us = ce.runs[0].samples[0].t_us;
    let t_first_s = cfg.gap_s; // the first sample follows RunStarted by < 1.25 ms
    for (rb, re) in cb.runs.iter().zip(&ce.runs) {
        for (sb, se) in rb.samples.iter().zip(&re.samples).step_by(97) {
            let t_s = t_first_s + (se.t_us - t_first_us) as f64 * 1e-6;
            for (i, (k_i, c_i)) in k.into_iter().zip(d.dps_per_c).enumerate() {
                let want = k_i * c_i * rise(t_s);
                let got = f64::from(se.rate_counts[i]) - f64::from(sb.rate_counts[i]);
                assert!((got - want).abs() <= 1.1, "t {t_s}, axis {i}: {got} vs {want}");
            }
        }
    }
    // Temperature register: −1 LSB/°C, so it falls by the rise (to the 1 LSB rounding).
    assert!(temps(&cb).windows(2).all(|w| w[0] == w[1]), "constant without the effect");
    let t0_raw = temps(&cb)[0];
    for run in &ce.runs {
        for t in &run.temperatures {
            let t_s = t_first_s + (t.t_us - t_first_us) as f64 * 1e-6;
            let fall = f64::from(t0_raw) - f64::from(t.raw);
            assert!((fall - rise(t_s)).abs() <= 1.0, "t {t_s}: {fall} vs {}", rise(t_s));
        }
    }
    let last = ce.runs[1].temperatures.last().unwrap().raw;
    assert!(i32::from(t0_raw) - i32::from(last) >= 6, "the test must span most of the warm-up");
}

#[test]
fn speed_ripple_is_in_the_encoder_derived_rate() {
    let (cfg, _, cb, _, ce) = with_and_without(38, "speed_ripple", 12.0);
    assert_ne!(encoders(&cb), encoders(&ce));
    assert_eq!(temps(&cb), temps(&ce));
    let h1 = cfg.effects.speed_ripple.unwrap().harmonics[0];
    for run in &ce.runs {
        // Rate over 8-sample (10 ms) spans, against θ1, projected on the 1× harmonic.
        let st = steady(run, &cfg);
        let (mut c, mut s, mut n) = (0.0, 0.0, 0.0);
        for w in st.windows(9).step_by(8) {
            let dps = (w[8].encoder - w[0].encoder) as f64 / CPR * 360.0 / ((w[8].t_us - w[0].t_us) as f64 * 1e-6);
            let th1 = 0.5 * (w[8].encoder + w[0].encoder) as f64 / CPR * TAU;
            let rel = dps / 180.0 - 1.0;
            c += rel * th1.cos();
            s += rel * th1.sin();
            n += 1.0;
        }
        let amp = 2.0 * (c * c + s * s).sqrt() / n;
        // The span averages the 2×/12× terms out of the 1× projection only over whole turns:
        // ~2 turns here, so allow 10 % of the amplitude.
        assert!((amp - h1.amplitude).abs() < 0.1 * h1.amplitude, "{amp}");
    }
}

#[test]
fn a_fast_rig_clock_stretches_every_timestamp_and_nothing_else() {
    let (_, base, cb, _, ce) = with_and_without(36, "rig_clock=1000", 6.0);
    for (rb, re) in cb.runs.iter().zip(&ce.runs) {
        // The same samples and edges, each timestamp 1000 ppm further from the timer's zero
        // (±2 µs: two roundings and the jitter), and over the run 1000 ppm longer to 1 ppm.
        assert_eq!(rb.samples.len(), re.samples.len());
        for (sb, se) in rb.samples.iter().zip(&re.samples) {
            assert_eq!((sb.encoder, sb.rate_counts), (se.encoder, se.rate_counts));
            assert!((se.t_us as f64 - sb.t_us as f64 * 1.001).abs() <= 2.0, "{} vs {}", se.t_us, sb.t_us);
        }
        let span = |r: &crate::capture::Run| (r.samples.last().unwrap().t_us - r.samples[0].t_us) as f64;
        assert!((span(re) / span(rb) - 1.001).abs() < 1e-6, "{} vs {}", span(re), span(rb));
        for (eb, ee) in rb.index.iter().zip(&re.index) {
            assert_eq!(eb.encoder, ee.encoder);
            assert!((ee.t_us as f64 - eb.t_us as f64 * 1.001).abs() <= 2.0, "{} vs {}", ee.t_us, eb.t_us);
        }
    }
    assert_eq!(base.truth.start_t_us, 0, "the timer starts at 0, so its reading scales with the clock");
}

#[test]
fn a_jittery_timestamp_moves_only_the_timestamps_by_its_rms() {
    let (_, base, cb, eff, ce) = with_and_without(38, "timestamp_jitter=20", 6.0);
    assert_eq!((base.truth.timestamp_jitter_us, eff.truth.timestamp_jitter_us), (1.0, 20.0));
    let (mut sum_sq, mut n) = (0.0, 0.0);
    for (rb, re) in cb.runs.iter().zip(&ce.runs) {
        assert_eq!(rb.samples.len(), re.samples.len());
        for (sb, se) in rb.samples.iter().zip(&re.samples) {
            assert_eq!((sb.encoder, sb.rate_counts), (se.encoder, se.rate_counts));
            sum_sq += (se.t_us as f64 - sb.t_us as f64).powi(2);
            n += 1.0;
        }
        assert_eq!(index(&cb), index(&ce), "index edges are captured by a timer input, without jitter");
    }
    // The jitter stream draws the same standard normals z at any size, so each pair differs by
    // (20 − 1)·z µs and two roundings: √(19² + 1/6) = 19.00 µs rms; over n ≈ 9600 samples its
    // estimate is within 1.5 % (3σ).
    let rms = (sum_sq / n).sqrt();
    assert!(n > 9000.0 && (rms - 19.0).abs() < 0.015 * 19.0, "{rms} µs rms over {n} samples");
}

/// Mean over run `r` of axis `a`'s counts in `e` less those in `b`, sample by sample.
fn mean_difference(b: &Capture, e: &Capture, r: usize, a: usize) -> (f64, usize) {
    let (rb, re) = (&b.runs[r], &e.runs[r]);
    assert_eq!(rb.samples.len(), re.samples.len());
    let sum: f64 =
        rb.samples.iter().zip(&re.samples).map(|(x, y)| f64::from(y.rate_counts[a] - x.rate_counts[a])).sum();
    (sum / rb.samples.len() as f64, rb.samples.len())
}

#[test]
fn a_capture_taken_on_its_own_has_a_level_and_a_noise_draw_of_its_own() {
    let (mut cfg, base, cb, eff, ce) = with_and_without(39, "capture_level=0.02", 6.0);
    // The same motion (the stamps' jitter is a draw of its own too).
    let counts = |c: &Capture| encoders(c).into_iter().map(|(_, e)| e).collect::<Vec<_>>();
    assert!(counts(&cb) == counts(&ce), "the encoder counts differ");
    // Its level is in the truth's offsets and in the counts: the mean difference from the same
    // capture without it is k·level, within the two noise draws' 3 counts rms each over n
    // samples (5σ).
    let mut moved = 0.0_f64;
    for (a, k) in base.truth.k_counts_per_dps.into_iter().enumerate() {
        let level = eff.truth.offset_counts[a] - base.truth.offset_counts[a];
        moved = moved.max(level.abs() / k);
        for r in 0..cb.runs.len() {
            let (d, n) = mean_difference(&cb, &ce, r, a);
            let tol = 5.0 * base.truth.noise_counts_per_sample[a] * (2.0 / n as f64).sqrt();
            assert!((d - level).abs() < tol, "axis {a}, run {r}: {d} counts against the level's {level}");
        }
    }
    assert!(moved > 0.002 && moved < 0.1, "a level of 0.02 °/s (1σ) drew at most {moved} °/s");
    // Its own noise: two draws of 3 counts rms agree on about one sample in ten.
    let same = axis(&cb, 0).iter().zip(axis(&ce, 0)).filter(|(x, y)| **x == *y).count();
    assert!(same * 4 < axis(&cb, 0).len(), "{same} samples alike");
    // Another capture of the same sensor (pose 1 alone) draws another level; the sensor is the seed's.
    cfg.runs.truncate(1);
    let alone = simulate(&cfg).unwrap();
    assert_eq!(alone.truth.m_counts_per_dps, eff.truth.m_counts_per_dps);
    assert!((0..3).all(|a| alone.truth.offset_counts[a] != eff.truth.offset_counts[a]));
}

#[test]
fn axes_sampled_apart_each_read_the_rate_of_their_own_instant() {
    let (cfg, _, cb, _, ce) = with_and_without(37, "axis_delay=0.4", 6.0);
    assert_eq!(encoders(&cb), encoders(&ce));
    let d_ms = cfg.effects.axis_delay.unwrap().delay_ms;
    assert_eq!(d_ms, [0.0, 0.4, -0.2]);
    // x is untouched; y and z differ by their rate's change over their delay: at most
    // |dω/dt|·δ = (π rad/s)·(180 °/s)·0.4 ms ≈ 0.23 °/s ≈ 13 counts at 57 counts/(°/s) (the
    // table turns at 0.5 Hz), plus the two roundings; and by more than the roundings.
    assert_eq!(axis(&cb, 0), axis(&ce, 0));
    for a in 1..3 {
        let diff: Vec<i32> = axis(&cb, a).iter().zip(axis(&ce, a)).map(|(&b, e)| i32::from(e) - i32::from(b)).collect();
        let most = diff.iter().map(|d| d.abs()).max().unwrap();
        assert!((4..=15).contains(&most), "axis {a}: largest difference {most} counts");
    }
}
