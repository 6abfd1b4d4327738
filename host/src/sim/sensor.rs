//! The simulated L3G4200D: its true axes, sensitivities and offsets, and its output chain.
//!
//! Model (EXCITER.md eq. 6): `v = K S ω_s + v_off`, with each axis `s_i` tilted from the package
//! axis `e_i`, its own sensitivity `k_i` and offset, white noise, rounding to i16 and clipping.

use super::effects::{Effects, GSensitivity, MountCompliance, MysteryHarmonic, Nonlinearity, OffsetDrift};
use super::thermal::{ChamberStep, TemperatureDependence};
use nalgebra::{Matrix3, Vector3};
use protocol::FullScale;
use rand::Rng;
use rand_distr::{Distribution, Normal, StandardNormal};
use std::f64::consts::TAU;

/// Axis tilts are drawn uniformly in this range, degrees (the brief: typical MEMS packaging and
/// die-placement misalignment; the datasheet gives ±2 % cross-axis, ≈ 1.1°).
pub const TILT_RANGE_DEG: (f64, f64) = (0.5, 2.0);

/// Relative spread of the sensitivities, 1 σ (assumed: datasheet Table 4 gives no spread, only a
/// ±2 % change over temperature; 1.5 % is typical of uncalibrated MEMS gyros).
pub const SENSITIVITY_SIGMA: f64 = 0.015;

/// Offset spread, 1 σ, in LSB at ±500 °/s (assumed: a sensor that has been zeroed once; the
/// datasheet's ±15 °/s is a worst-case bound, not a spread). Held internally in °/s so that a
/// different full scale scales it like a real rate.
pub const OFFSET_SIGMA_COUNTS_AT_500: f64 = 10.0;

/// Rate noise density, °/s/√Hz (datasheet Table 4, "Rn"): the firmware's chip model's figure.
pub const NOISE_DENSITY_DPS_PER_SQRT_HZ: f64 = firmware::plant::l3g4200d_model::NOISE_DENSITY_DPS_PER_SQRT_HZ;

/// Nominal sensitivity, counts per °/s (datasheet Table 4 via `FullScale::udps_per_lsb`).
pub fn nominal_counts_per_dps(fs: FullScale) -> f64 {
    1e6 / f64::from(fs.udps_per_lsb())
}

/// The sensor's true, fixed properties, drawn once from the seed.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorTruth {
    /// Sensing axes, unit vectors in the package frame (rows of S).
    pub s: [Vector3<f64>; 3],
    /// Tilt of each axis from its package axis, degrees.
    pub tilt_deg: [f64; 3],
    /// Sensitivity relative to nominal, k_i / nominal.
    pub k_rel: [f64; 3],
    /// Offsets at the reference temperature, °/s.
    pub offset_dps: [f64; 3],
}

impl SensorTruth {
    /// Draws a sensor. The order and number of draws are fixed, so one seed is one sensor.
    pub fn draw(rng: &mut impl Rng) -> Self {
        let mut s = [Vector3::zeros(); 3];
        let mut tilt_deg = [0.0; 3];
        let mut k_rel = [0.0; 3];
        let mut offset_dps = [0.0; 3];
        let offset_sigma_dps = OFFSET_SIGMA_COUNTS_AT_500 / nominal_counts_per_dps(FullScale::Dps500);
        let spread = Normal::new(0.0, SENSITIVITY_SIGMA).expect("finite σ");
        for i in 0..3 {
            let e = Vector3::ith(i, 1.0);
            let (u, w) = (Vector3::ith((i + 1) % 3, 1.0), Vector3::ith((i + 2) % 3, 1.0));
            let tilt = rng.random_range(TILT_RANGE_DEG.0..TILT_RANGE_DEG.1);
            let dir = rng.random_range(0.0..TAU);
            let (st, ct) = tilt.to_radians().sin_cos();
            s[i] = (e * ct + (u * dir.cos() + w * dir.sin()) * st).normalize();
            tilt_deg[i] = tilt;
            k_rel[i] = 1.0 + spread.sample(rng);
            let z: f64 = StandardNormal.sample(rng);
            offset_dps[i] = z * offset_sigma_dps;
        }
        Self { s, tilt_deg, k_rel, offset_dps }
    }

    /// The sensor at `temp_c`: sensitivities and directions moved by `dep` (the offsets are the
    /// reference's; [`Thermal::offset_drift_dps`] moves them).
    pub fn at_temperature(&self, dep: &TemperatureDependence, temp_c: f64) -> Self {
        let factor = dep.sensitivity_factor(temp_c);
        let s = [0, 1, 2].map(|i| dep.direction(i, &self.s[i], temp_c));
        Self {
            s,
            tilt_deg: [0, 1, 2].map(|i| s[i][i].clamp(-1.0, 1.0).acos().to_degrees()),
            k_rel: [0, 1, 2].map(|i| self.k_rel[i] * factor[i]),
            offset_dps: self.offset_dps,
        }
    }

    /// Sensitivities, counts per °/s.
    pub fn k_counts_per_dps(&self, fs: FullScale) -> [f64; 3] {
        self.k_rel.map(|k| k * nominal_counts_per_dps(fs))
    }

    /// S, rows = axes.
    pub fn s_matrix(&self) -> Matrix3<f64> {
        Matrix3::from_rows(&[self.s[0].transpose(), self.s[1].transpose(), self.s[2].transpose()])
    }

    /// M = K S, counts per °/s, rows = axes.
    pub fn m_counts_per_dps(&self, fs: FullScale) -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vector3::from(self.k_counts_per_dps(fs))) * self.s_matrix()
    }

    /// Offsets at the reference temperature, counts.
    pub fn offset_counts(&self, fs: FullScale) -> [f64; 3] {
        let k = self.k_counts_per_dps(fs);
        [0, 1, 2].map(|i| k[i] * self.offset_dps[i])
    }
}

/// Die temperature and the offsets that follow it.
#[derive(Debug, Clone, Copy)]
pub struct Thermal {
    /// Temperature at power-up, °C.
    pub ambient_c: f64,
    /// OUT_TEMP reads `out_temp_at_0c − T` (datasheet Table 5: −1 LSB/°C, offset unspecified).
    pub out_temp_at_0c: f64,
    /// Warm-up and offset drift, if on.
    pub drift: Option<OffsetDrift>,
    /// Offset, sensitivity and direction as functions of temperature, if on: the offset then
    /// follows it rather than `drift.dps_per_c` (one sensor, one temperature coefficient).
    pub dependence: Option<TemperatureDependence>,
    /// The chamber step before this session, if any: the die follows it, and the warm-up of
    /// `drift` is over (the rig stayed powered through the chamber programme), so its `rise_c` is
    /// the die's steady self-heating.
    pub chamber: Option<ChamberStep>,
}

impl Thermal {
    /// Die temperature at `t_s` after power-up, °C.
    pub fn temperature_c(&self, t_s: f64) -> f64 {
        if let Some(c) = &self.chamber {
            return c.die_c(c.capture_after_s + t_s) + self.drift.map_or(0.0, |d| d.rise_c);
        }
        match &self.drift {
            Some(d) if d.tau_s > 0.0 => self.ambient_c + d.rise_c * (1.0 - (-t_s.max(0.0) / d.tau_s).exp()),
            _ => self.ambient_c,
        }
    }

    /// OUT_TEMP register at `t_s`.
    pub fn out_temp_raw(&self, t_s: f64) -> i8 {
        (self.out_temp_at_0c - self.temperature_c(t_s)).round().clamp(f64::from(i8::MIN), f64::from(i8::MAX)) as i8
    }

    /// Offset change from the reference value at `t_s`, °/s per axis.
    pub fn offset_drift_dps(&self, t_s: f64) -> [f64; 3] {
        if let Some(dep) = &self.dependence {
            return dep.offset_change_dps(self.temperature_c(t_s));
        }
        match &self.drift {
            Some(d) => {
                let dt = self.temperature_c(t_s) - self.ambient_c;
                d.dps_per_c.map(|c| c * dt)
            }
            None => [0.0; 3],
        }
    }
}

/// The analogue part of the output chain for one pose: rate along each axis, nonlinearity,
/// out-of-model structure, sensitivity. Linear filtering, offsets, noise and quantisation follow.
#[derive(Debug, Clone, Copy)]
pub struct SenseChain {
    /// S·R_qᵀ: maps ω2 (table frame) to the rate along each sensing axis.
    axes_from_table: Matrix3<f64>,
    k_counts_per_dps: [f64; 3],
    full_scale_dps: f64,
    nonlinearity: Option<Nonlinearity>,
    mystery: Option<MysteryHarmonic>,
    mount_compliance: Option<MountCompliance>,
    /// R_qᵀ: table frame → package frame (for the specific force).
    package_from_table: Matrix3<f64>,
    g_sensitivity: Option<GSensitivity>,
}

impl SenseChain {
    /// The chain for a sensor mounted with rotation `r_pose` (package → table, eq. 3).
    pub fn new(truth: &SensorTruth, r_pose: &Matrix3<f64>, fs: FullScale, effects: &Effects) -> Self {
        Self {
            axes_from_table: truth.s_matrix() * r_pose.transpose(),
            k_counts_per_dps: truth.k_counts_per_dps(fs),
            full_scale_dps: f64::from(fs.range_dps()),
            nonlinearity: effects.nonlinearity,
            mystery: effects.mystery_harmonic,
            mount_compliance: effects.mount_compliance,
            package_from_table: r_pose.transpose(),
            g_sensitivity: effects.g_sensitivity,
        }
    }

    /// Sensed rate in counts (before offset, noise and quantisation) for the table rate ω2 (°/s)
    /// at table angle `theta2_rad`.
    pub fn counts(&self, omega2_dps: &Vector3<f64>, theta2_rad: f64) -> [f64; 3] {
        // A package turned by C on its mount (table frame) feels Cᵀ·ω2.
        let x = match &self.mount_compliance {
            Some(c) => self.axes_from_table * (c.turn(omega2_dps).transpose() * omega2_dps),
            None => self.axes_from_table * omega2_dps,
        };
        let mut y = [x[0], x[1], x[2]];
        if let Some(n) = &self.nonlinearity {
            for v in &mut y {
                let sign = if *v >= 0.0 { 1.0 } else { -1.0 };
                let fs = self.full_scale_dps;
                *v = *v * (1.0 + 0.5 * sign * n.asymmetry)
                    + n.quadratic_fs * *v * v.abs() / fs
                    + n.cubic_fs * v.powi(3) / (fs * fs)
                    + n.square_fs * v.powi(2) / fs;
            }
        }
        if let Some(g) = &self.g_sensitivity {
            // At rest the table feels +1 g along z1 = (sin θ2, cos θ2, 0) in O2 (EXCITER.md eq. 1).
            let (s2, c2) = theta2_rad.sin_cos();
            let f = self.package_from_table * Vector3::new(s2, c2, 0.0);
            for (v, row) in y.iter_mut().zip(&g.dps_per_g) {
                *v += row[0] * f[0] + row[1] * f[1] + row[2] * f[2];
            }
        }
        if let Some(m) = &self.mystery {
            if let Some(v) = y.get_mut(m.axis) {
                *v += m.amplitude_dps * (f64::from(m.order) * theta2_rad + m.phase_rad).sin();
            }
        }
        [0, 1, 2].map(|i| y[i] * self.k_counts_per_dps[i])
    }
}

/// Rounds to the nearest count and clips to the i16 output register.
pub fn quantise(counts: f64) -> i16 {
    counts.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn drawn_sensor_has_unit_axes_with_the_stated_tilts_and_m_equals_ks() {
        for seed in 0..50 {
            let t = SensorTruth::draw(&mut ChaCha8Rng::seed_from_u64(seed));
            let m = t.m_counts_per_dps(FullScale::Dps500);
            let k = t.k_counts_per_dps(FullScale::Dps500);
            for (i, k_i) in k.into_iter().enumerate() {
                assert!((t.s[i].norm() - 1.0).abs() < 1e-12);
                let tilt = t.s[i][i].acos().to_degrees();
                assert!((tilt - t.tilt_deg[i]).abs() < 1e-9, "{tilt} vs {}", t.tilt_deg[i]);
                assert!((TILT_RANGE_DEG.0..TILT_RANGE_DEG.1).contains(&tilt));
                assert!((m.row(i).norm() - k_i).abs() < 1e-9);
                // 5 σ of the sensitivity spread.
                assert!((t.k_rel[i] - 1.0).abs() < 5.0 * SENSITIVITY_SIGMA);
            }
        }
    }

    #[test]
    fn warm_up_moves_temperature_register_and_offsets_together() {
        let th = Thermal {
            ambient_c: 25.0,
            out_temp_at_0c: 50.0,
            drift: Some(OffsetDrift::default()),
            dependence: None,
            chamber: None,
        };
        assert_eq!(th.out_temp_raw(0.0), 25);
        // After 5 time constants the rise is complete to 0.7 %: 10 °C warmer, 10 LSB lower.
        assert_eq!(th.out_temp_raw(450.0), 15);
        let d = th.offset_drift_dps(1e6);
        assert!((d[0] - 0.3).abs() < 1e-9 && (d[1] + 0.2).abs() < 1e-9);
        let still = Thermal { drift: None, ..th };
        assert_eq!(still.out_temp_raw(450.0), 25);
        assert_eq!(still.offset_drift_dps(450.0), [0.0; 3]);
    }

    #[test]
    fn quantiser_rounds_and_clips() {
        assert_eq!(quantise(1.49), 1);
        assert_eq!(quantise(-1.5), -2);
        assert_eq!(quantise(4e4), i16::MAX);
        assert_eq!(quantise(-4e4), i16::MIN);
    }

    /// The chain of pose 1 ≡ identity with `effects`, for axes along the package's at the
    /// nominal sensitivity, and that sensitivity.
    fn chain_with(effects: &Effects) -> (SenseChain, f64) {
        let chain = SenseChain::new(&ideal_axes(), &Matrix3::identity(), FullScale::Dps500, effects);
        (chain, nominal_counts_per_dps(FullScale::Dps500))
    }

    /// Axes along the package's, at the nominal sensitivity, no offset.
    fn ideal_axes() -> SensorTruth {
        SensorTruth {
            s: [Vector3::x(), Vector3::y(), Vector3::z()],
            tilt_deg: [0.0; 3],
            k_rel: [1.0; 3],
            offset_dps: [0.0; 3],
        }
    }

    #[test]
    fn nonlinearity_follows_its_formula_and_mystery_hits_one_axis() {
        let (chain, k) = chain_with(&Effects { nonlinearity: Some(Nonlinearity::default()), ..Effects::default() });
        let c = chain.counts(&Vector3::new(500.0, -500.0, 0.0), 0.0);
        assert!((c[0] / k - 500.0 * (1.002 + 0.002)).abs() < 1e-9);
        assert!((c[1] / k + 500.0 * (0.998 + 0.002)).abs() < 1e-9);
        // The cubic alone (`nonlinearity_cubic`): 0.2 % of the rate at ±500 °/s (full scale),
        // (250/500)² of that share at 250 °/s, odd.
        let mut cubic = Effects::default();
        cubic.enable("nonlinearity_cubic").unwrap();
        let (chain, _) = chain_with(&cubic);
        let c = chain.counts(&Vector3::new(500.0, -250.0, 0.0), 0.0);
        assert!((c[0] / k - 500.0 * 1.002).abs() < 1e-9, "{c:?}");
        assert!((c[1] / k + 250.0 * (1.0 + 0.002 * 0.25)).abs() < 1e-9, "{c:?}");
        // The square law alone (`nonlinearity_square`): 0.2 % of full scale at ±500 °/s, even.
        let mut square = Effects::default();
        square.enable("nonlinearity_square").unwrap();
        let (chain, _) = chain_with(&square);
        let c = chain.counts(&Vector3::new(500.0, -500.0, 0.0), 0.0);
        assert!((c[0] / k - 500.0 * 1.002).abs() < 1e-9, "{c:?}");
        assert!((c[1] / k + 500.0 * 0.998).abs() < 1e-9, "{c:?}");
        let (chain, _) =
            chain_with(&Effects { mystery_harmonic: Some(MysteryHarmonic::default()), ..Effects::default() });
        let c = chain.counts(&Vector3::zeros(), 0.5);
        assert!((c[0] / k - 0.3 * (1.5f64 + 0.4).sin()).abs() < 1e-12);
        assert_eq!([c[1], c[2]], [0.0, 0.0]);
    }

    /// The package turns about the table's x axis by 0.03° at 180 °/s on both tables, by a
    /// quarter of that at half the speed, and not at rest.
    #[test]
    fn a_compliant_mount_turns_the_package_by_its_load() {
        let (chain, k) =
            chain_with(&Effects { mount_compliance: Some(MountCompliance::default()), ..Effects::default() });
        for (rate_dps, turn_deg) in [(180.0, 0.03), (90.0, 0.0075), (-180.0, 0.03)] {
            // ω2 = (0, θ1', θ2') at θ2 = 0 (EXCITER.md eq. 1): |ω2|² = 2·rate².
            let w2 = Vector3::new(0.0, rate_dps, rate_dps);
            let c = chain.counts(&w2, 0.0).map(|v| v / k);
            // The package turned by +δ about x feels ω2 turned by −δ.
            let d = f64::to_radians(turn_deg);
            let want = [0.0, rate_dps * (d.cos() + d.sin()), rate_dps * (d.cos() - d.sin())];
            for (got, want) in c.iter().zip(want) {
                assert!((got - want).abs() < 1e-9, "{rate_dps}: {c:?} against {want:?}");
            }
        }
        assert_eq!(chain.counts(&Vector3::zeros(), 0.3), [0.0; 3]);
    }
}
