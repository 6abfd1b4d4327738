//! A small generator of decoded runs, straight from the geometry (no wire bytes), for the unit
//! tests of the calibration helpers. The acceptance tests use `crate::sim` instead.

use crate::capture::{Run, RunIndexEdge, RunOrigin, RunSample, RunTemperature};
use crate::geometry::{omega2, Pose};
use nalgebra::{Matrix3, Vector3};
use protocol::{Direction, Edge, GearRatio, GyroConfig, Hello, Version};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Encoder counts per revolution of the prototype (EXCITER.md, "Parts": 81 000 pulses × 4).
pub const COUNTS_PER_REV: u32 = 324_000;

/// A sensor and a run to generate.
#[derive(Debug, Clone)]
pub struct GenRun {
    pub pose: Pose,
    /// Steady base-table rate, °/s, signed.
    pub rate_dps: f64,
    pub duration_s: f64,
    /// Linear spin-up time, s.
    pub ramp_s: f64,
    /// M, counts per °/s, rows = axes.
    pub m: Matrix3<f64>,
    pub offset_counts: Vector3<f64>,
    /// White noise, counts rms, before rounding.
    pub noise_counts: f64,
    /// True gear ratio (the Hello always says 1:1).
    pub gear_ratio: f64,
    /// Encoder count at t = 0 (arbitrary), and θ2 at t = 0, rad.
    pub encoder0: i64,
    pub theta2_0_rad: f64,
    pub seed: u64,
}

/// A tilted, scaled sensor with offsets, near the L3G4200D's nominal 57.14 counts per °/s.
pub fn typical_sensor() -> (Matrix3<f64>, Vector3<f64>) {
    let s = Matrix3::new(
        0.999_8, 0.015, -0.012, //
        -0.010, 0.999_7, 0.020, //
        0.008, -0.017, 0.999_8,
    );
    let mut m = s;
    for (i, k) in [57.6, 56.9, 58.1].into_iter().enumerate() {
        let row = s.row(i) / s.row(i).norm() * k;
        m.set_row(i, &row);
    }
    (m, Vector3::new(15.0, -22.0, 8.0))
}

impl GenRun {
    pub fn new(pose: Pose, rate_dps: f64, seed: u64) -> Self {
        let (m, offset_counts) = typical_sensor();
        Self {
            pose,
            rate_dps,
            duration_s: 20.0,
            ramp_s: 1.0,
            m,
            offset_counts,
            noise_counts: 7.0,
            gear_ratio: 1.0,
            encoder0: 1_000_000 + seed as i64 * 7919,
            theta2_0_rad: 1.0 + seed as f64,
            seed,
        }
    }

    /// Base-table angle (deg) and rate (°/s) at t.
    pub fn theta1(&self, t: f64) -> (f64, f64) {
        let r = self.rate_dps;
        if t < self.ramp_s {
            (0.5 * r * t * t / self.ramp_s, r * t / self.ramp_s)
        } else {
            (0.5 * r * self.ramp_s + r * (t - self.ramp_s), r)
        }
    }

    pub fn generate(&self) -> Run {
        let gyro = GyroConfig::DEFAULT;
        let odr = f64::from(gyro.odr.hz());
        let hello = Hello {
            protocol_version: 1,
            firmware: Version { major: 0, minor: 1, patch: 0 },
            gyro,
            encoder_counts_per_rev: COUNTS_PER_REV,
            gear_ratio: GearRatio { num: 1, den: 1 },
            timestamp_hz: 1_000_000,
        };
        let cpr = f64::from(COUNTS_PER_REV);
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let rt = self.pose.rotation().transpose();
        let n = (self.duration_s * odr) as usize;
        let enc = |deg: f64| self.encoder0 + (deg / 360.0 * cpr).floor() as i64;
        let theta2 = |deg1: f64| self.theta2_0_rad + self.gear_ratio * deg1.to_radians();
        let mut samples = Vec::with_capacity(n);
        for i in 0..n {
            let t = i as f64 / odr;
            let (a1, r1) = self.theta1(t);
            let w = rt * omega2(r1, theta2(a1), self.gear_ratio * r1);
            let v = self.m * w + self.offset_counts;
            let mut counts = [0i16; 3];
            for (c, val) in counts.iter_mut().zip(v.iter()) {
                let noisy = val + self.noise_counts * rng.sample::<f64, _>(StandardNormal);
                *c = noisy.round().clamp(-32768.0, 32767.0) as i16;
            }
            samples.push(RunSample {
                t_us: (t * 1e6).round() as i64,
                encoder: enc(a1),
                rate_counts: counts,
                status: 0,
            });
        }
        // Index: the plate covers θ2 ∈ [−2°, 2°] (mod 360°). Scan at 20 kHz for state changes,
        // then bisect each to 1 ns so the edges carry no timing bias.
        let half_width = 2f64.to_radians();
        let tau = std::f64::consts::TAU;
        let blocked_at = |t: f64| {
            let th = theta2(self.theta1(t).0).rem_euclid(tau);
            th.min(tau - th) < half_width
        };
        let mut index = Vec::new();
        let step_s = 1.0 / 20_000.0;
        let steps = (self.duration_s / step_s) as usize;
        let mut prev = blocked_at(0.0);
        for k in 1..steps {
            let t = k as f64 * step_s;
            let b = blocked_at(t);
            if b != prev {
                let (mut lo, mut hi) = (t - step_s, t);
                while hi - lo > 1e-9 {
                    let mid = 0.5 * (lo + hi);
                    if blocked_at(mid) == prev {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                index.push(RunIndexEdge {
                    t_us: (hi * 1e6).round() as i64,
                    encoder: enc(self.theta1(hi).0),
                    edge: if b { Edge::Rising } else { Edge::Falling },
                });
                prev = b;
            }
        }
        let temperatures =
            (0..self.duration_s as i64).map(|s| RunTemperature { t_us: s * 1_000_000, raw: 20 }).collect();
        Run {
            hello,
            pose: self.pose,
            rate_mdps: protocol::units::mdps_from_dps(self.rate_dps),
            direction: if self.rate_dps < 0.0 { Direction::Cw } else { Direction::Ccw },
            gyro,
            origin: RunOrigin::Started,
            offset: 0,
            samples,
            index,
            temperatures,
            motor: Vec::new(),
            counters: Vec::new(),
            faults: Vec::new(),
            stopped: true,
        }
    }
}

/// One run per pose at 0.5 Hz (180 °/s).
pub fn two_pose_runs(seed: u64) -> Vec<Run> {
    vec![GenRun::new(Pose::One, 180.0, seed).generate(), GenRun::new(Pose::Two, 180.0, seed + 1000).generate()]
}
