//! Temperature dependence of the simulated L3G4200D and the thermal chamber around the rig.
//!
//! The gyro's offset, sensitivity and axis directions move with its die temperature
//! ([`TemperatureDependence`], polynomials in `T − reference_c`); a chamber step
//! ([`ChamberStep`]) moves the die from one setpoint to the next through the chamber's air ramp
//! and the board's thermal lag. `host simulate --chamber-c` simulates one session per setpoint,
//! each starting once the die has settled by the live session's own criterion (the chamber
//! programme is `host::thermal::session::programme`, outside `sim` so that `sim` imports nothing
//! of `thermal`).

use nalgebra::{Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// Reference temperature of the simulated sensor's offsets, sensitivities and directions, °C:
/// the datasheet's (L3G4200D Table 4 quotes its typical values at 25 °C).
pub const REFERENCE_C: f64 = 25.0;

/// How the gyro's calibration moves with die temperature, as polynomials in `T − reference_c`.
///
/// Sizes and sources of the defaults:
/// - offset: L3G4200D datasheet Table 4, "zero-rate level change vs. temperature", ±0.03 °/s/°C
///   typical; the per-axis linear terms are 0.03, −0.02 and 0.025 °/s/°C. The curvature
///   (1e-4, −0.5e-4, 0.8e-4 °/s/°C²) is engineering judgement: MEMS bias-temperature curves
///   bend (PX4 and ArduPilot fit a third-order polynomial for that reason); at these sizes the
///   curve leaves its tangent by ≤ 0.2 °/s at the ends of −20…70 °C.
/// - sensitivity: Table 4, "sensitivity change vs. temperature", ±2 % over −40…85 °C, i.e. at
///   most 160 ppm/°C on average; the linear terms are 120, −90 and 60 ppm/°C and the curvature
///   0.5, 0.3 and −0.4 ppm/°C² (judgement), together within ±2 % over the datasheet's range.
/// - direction: the datasheet gives no figure. Engineering judgement: package stress from the
///   mismatched expansion of die, mould and board turns the sensing axes by a fraction of the
///   ±2 % (≈ 1.1°) cross-axis figure over the whole range; 0.001-0.002 °/°C, i.e. 0.1-0.2° over
///   −20…70 °C, each axis about its own perpendicular.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TemperatureDependence {
    /// Temperature at which the sensor's drawn values hold, °C.
    pub reference_c: f64,
    /// Offset change per °C, °/s/°C, per axis.
    pub offset_dps_per_c: [f64; 3],
    /// Offset change per °C², °/s/°C², per axis.
    pub offset_dps_per_c2: [f64; 3],
    /// Relative sensitivity change per °C, ppm/°C, per axis.
    pub sensitivity_ppm_per_c: [f64; 3],
    /// Relative sensitivity change per °C², ppm/°C², per axis.
    pub sensitivity_ppm_per_c2: [f64; 3],
    /// Rotation of each sensing axis per °C, a rotation vector in the package frame, °/°C (a
    /// part along the axis itself turns nothing).
    pub direction_deg_per_c: [[f64; 3]; 3],
}

impl Default for TemperatureDependence {
    fn default() -> Self {
        Self {
            reference_c: REFERENCE_C,
            offset_dps_per_c: [0.03, -0.02, 0.025],
            offset_dps_per_c2: [1.0e-4, -0.5e-4, 0.8e-4],
            sensitivity_ppm_per_c: [120.0, -90.0, 60.0],
            sensitivity_ppm_per_c2: [0.5, 0.3, -0.4],
            direction_deg_per_c: [[0.0, 0.0015, -0.001], [0.001, 0.0, 0.0015], [-0.002, 0.001, 0.0]],
        }
    }
}

impl TemperatureDependence {
    /// Offset change from the reference temperature, °/s per axis.
    pub fn offset_change_dps(&self, temp_c: f64) -> [f64; 3] {
        let d = temp_c - self.reference_c;
        [0, 1, 2].map(|i| self.offset_dps_per_c[i] * d + self.offset_dps_per_c2[i] * d * d)
    }

    /// Sensitivity at `temp_c` relative to the reference, per axis.
    pub fn sensitivity_factor(&self, temp_c: f64) -> [f64; 3] {
        let d = temp_c - self.reference_c;
        [0, 1, 2].map(|i| 1.0 + 1e-6 * (self.sensitivity_ppm_per_c[i] * d + self.sensitivity_ppm_per_c2[i] * d * d))
    }

    /// Axis `axis`'s direction at `temp_c`, from its direction `s_ref` at the reference.
    pub fn direction(&self, axis: usize, s_ref: &Vector3<f64>, temp_c: f64) -> Vector3<f64> {
        let w = Vector3::from(self.direction_deg_per_c[axis]).map(f64::to_radians);
        Rotation3::new(w * (temp_c - self.reference_c)) * s_ref
    }

    /// Whether every number is finite.
    pub fn is_finite(&self) -> bool {
        let flat = self
            .offset_dps_per_c
            .iter()
            .chain(&self.offset_dps_per_c2)
            .chain(&self.sensitivity_ppm_per_c)
            .chain(&self.sensitivity_ppm_per_c2)
            .chain(self.direction_deg_per_c.iter().flatten());
        self.reference_c.is_finite() && flat.into_iter().all(|v| v.is_finite())
    }
}

/// Default chamber air ramp, °C/min. Engineering judgement: bench-top chambers (e.g. Espec
/// SU-series, Binder MK) specify 2-5 °C/min; the slower end is the one to plan for.
pub const DEFAULT_RAMP_C_PER_MIN: f64 = 2.0;

/// Default time constant of the die behind the chamber air, s. Engineering judgement: a small
/// board on the sensor table in circulated air (convective h ≈ 20-50 W/m²K, a few grams of FR-4
/// and aluminium table) lags the air by 2-5 minutes; 180 s.
pub const DEFAULT_DIE_TAU_S: f64 = 180.0;

/// One setpoint of a chamber programme, as the die sees it: the chamber air ramps from
/// `from_c` to `setpoint_c` at `ramp_c_per_min`, the die follows with a first-order lag of
/// `die_tau_s`, and the capture begins `capture_after_s` after the step (when the die has
/// settled). The die also sits `self_heating_c` above the air (the board's own dissipation).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ChamberStep {
    /// Chamber setpoint, °C.
    pub setpoint_c: f64,
    /// Air (and die, settled) temperature before the step, °C.
    pub from_c: f64,
    /// Air ramp rate, °C/min (> 0).
    pub ramp_c_per_min: f64,
    /// Die time constant behind the air, s (> 0).
    pub die_tau_s: f64,
    /// Time from the step to the capture's power-up instant (t = 0 of the capture), s.
    pub capture_after_s: f64,
    /// The die's steady rise above the air, °C.
    #[serde(default)]
    pub self_heating_c: f64,
    /// Which setpoint of the programme this is: it separates the noise of the sessions (the
    /// sensor and the rig stay the same).
    pub index: u32,
}

impl ChamberStep {
    /// A step from `from_c` to `setpoint_c` with the default ramp and lag, the capture at 0.
    pub fn new(index: u32, from_c: f64, setpoint_c: f64) -> Self {
        Self {
            setpoint_c,
            from_c,
            ramp_c_per_min: DEFAULT_RAMP_C_PER_MIN,
            die_tau_s: DEFAULT_DIE_TAU_S,
            capture_after_s: 0.0,
            self_heating_c: 0.0,
            index,
        }
    }

    /// Duration of the air ramp, s.
    pub fn ramp_s(&self) -> f64 {
        (self.setpoint_c - self.from_c).abs() / (self.ramp_c_per_min / 60.0)
    }

    /// Die temperature `t_s` after the step, °C: the first-order lag's exact response to a ramp
    /// of the air, then to its hold.
    pub fn die_c(&self, t_s: f64) -> f64 {
        let t = t_s.max(0.0);
        let tau = self.die_tau_s;
        let rate = (self.setpoint_c - self.from_c).signum() * self.ramp_c_per_min / 60.0;
        let ramp_s = self.ramp_s();
        let during = |t: f64| self.from_c + rate * (t - tau * (1.0 - (-t / tau).exp()));
        let lagged = if t <= ramp_s {
            during(t)
        } else {
            let at_end = during(ramp_s);
            self.setpoint_c - (self.setpoint_c - at_end) * (-(t - ramp_s) / tau).exp()
        };
        lagged + self.self_heating_c
    }

    /// Whether the numbers describe a chamber.
    pub fn is_valid(&self) -> bool {
        self.setpoint_c.is_finite()
            && self.from_c.is_finite()
            && self.ramp_c_per_min.is_finite()
            && self.ramp_c_per_min > 0.0
            && self.die_tau_s.is_finite()
            && self.die_tau_s > 0.0
            && self.capture_after_s.is_finite()
            && self.capture_after_s >= 0.0
            && self.self_heating_c.is_finite()
    }
}

/// The simulated sensor's thermal truth, written in the truth file of a capture simulated with
/// temperature dependence.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct ThermalTruth {
    /// The coefficients.
    pub dependence: TemperatureDependence,
    /// M = K S at the reference temperature, counts per °/s, rows = axes.
    pub m_ref_counts_per_dps: [[f64; 3]; 3],
    /// Offsets at the reference temperature, counts.
    pub offset_ref_counts: [f64; 3],
    /// Sensitivities at the reference temperature, counts per °/s.
    pub k_ref_counts_per_dps: [f64; 3],
    /// Axis directions at the reference temperature (rows).
    pub s_ref: [[f64; 3]; 3],
    /// The chamber step before this capture, if any.
    pub chamber: Option<ChamberStep>,
    /// Mean die temperature over the runs' samples, °C: the temperature the capture's
    /// `m_counts_per_dps` and `offset_counts` are given at.
    pub die_mean_c: f64,
}

impl ThermalTruth {
    /// Offset (counts), sensitivity (counts per °/s) and direction of axis `axis` at `temp_c`.
    pub fn axis_at(&self, axis: usize, temp_c: f64) -> (f64, f64, Vector3<f64>) {
        let dep = &self.dependence;
        let k = self.k_ref_counts_per_dps[axis] * dep.sensitivity_factor(temp_c)[axis];
        let offset =
            self.offset_ref_counts[axis] + self.k_ref_counts_per_dps[axis] * dep.offset_change_dps(temp_c)[axis];
        (offset, k, dep.direction(axis, &Vector3::from(self.s_ref[axis]), temp_c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn die_follows_the_ramp_with_its_lag_and_settles_on_the_setpoint() {
        let step = ChamberStep::new(0, 25.0, -20.0);
        assert_eq!(step.die_c(0.0), 25.0);
        // 45 °C at 2 °C/min: a 22.5-min ramp; the die lags the air by rate·τ = 6 °C at its end.
        assert!((step.ramp_s() - 1350.0).abs() < 1e-9);
        let air_end = -20.0;
        assert!((step.die_c(1350.0) - (air_end + 6.0 * (1.0 - (-1350.0f64 / 180.0).exp()))).abs() < 1e-9);
        // Continuous across the ramp's end, monotonic, and on the setpoint after 10 τ.
        assert!((step.die_c(1350.0 - 1e-6) - step.die_c(1350.0 + 1e-6)).abs() < 1e-6);
        let mut last = f64::INFINITY;
        for i in 0..400 {
            let t = f64::from(i) * 10.0;
            assert!(step.die_c(t) <= last + 1e-12);
            last = step.die_c(t);
        }
        assert!((step.die_c(1350.0 + 1800.0) + 20.0).abs() < 1e-3);
        let warm = ChamberStep { self_heating_c: 3.0, ..step };
        assert!((warm.die_c(1e5) + 17.0).abs() < 1e-9);
    }

    #[test]
    fn dependence_is_the_identity_at_the_reference_and_sized_as_the_datasheet() {
        let d = TemperatureDependence::default();
        assert_eq!(d.offset_change_dps(REFERENCE_C), [0.0; 3]);
        assert_eq!(d.sensitivity_factor(REFERENCE_C), [1.0; 3]);
        let s = Vector3::new(0.0, 0.01, 1.0).normalize();
        assert!((d.direction(2, &s, REFERENCE_C) - s).norm() < 1e-15);
        // Sensitivity within ±2 % over −40…85 °C (datasheet Table 4).
        for t in [-40.0, 85.0] {
            for f in d.sensitivity_factor(t) {
                assert!((f - 1.0).abs() <= 0.02, "{t} °C: {f}");
            }
        }
        // Direction: 0.1-0.25° over −20…70 °C, and a rotation keeps the axis a unit vector.
        for axis in 0..3 {
            let e = Vector3::ith(axis, 1.0);
            let (a, b) = (d.direction(axis, &e, -20.0), d.direction(axis, &e, 70.0));
            let angle = a.angle(&b).to_degrees();
            assert!((0.09..0.25).contains(&angle), "axis {axis}: {angle}°");
            assert!((a.norm() - 1.0).abs() < 1e-12);
        }
    }
}
