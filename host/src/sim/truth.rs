//! What the simulated rig really was: the answer a calibration is checked against.

use super::effects::Effects;
use crate::geometry::Pose;
use nalgebra::{Matrix3, Vector3};
use protocol::GyroConfig;
use serde::{Deserialize, Serialize};

/// The simulated sensor and rig, written as pretty JSON beside a simulated capture.
///
/// Counts-valued fields (`m_counts_per_dps`, `k_counts_per_dps`, `offset_counts`) are for the
/// full scale in `gyro`; a run recorded with another full scale (see `RunTruth::gyro`) scales
/// them by the ratio of nominal sensitivities.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct Truth {
    /// Seed everything was drawn from.
    pub seed: u64,
    /// M = K S, counts per °/s, row-major, rows = axes (EXCITER.md eq. 6).
    pub m_counts_per_dps: [[f64; 3]; 3],
    /// Sensitivities k_i = |row i of M|, counts per °/s.
    pub k_counts_per_dps: [f64; 3],
    /// Sensing axes s_i, unit rows in the package frame.
    pub s: [[f64; 3]; 3],
    /// Angle of each s_i from its package axis e_i, degrees.
    pub tilt_deg: [f64; 3],
    /// Offsets v_off at the power-up temperature, counts (they drift only with `offset_drift`).
    pub offset_counts: [f64; 3],
    /// White rate noise density, °/s/√Hz.
    pub noise_dps_per_sqrt_hz: f64,
    /// Per-sample noise, counts rms per axis (density·√(ODR/2)·k_i), before rounding.
    pub noise_counts_per_sample: [f64; 3],
    /// Gyro settings the counts-valued fields refer to.
    pub gyro: GyroConfig,
    /// Gyro's actual output data rate, Hz (nominal × (1 + odr_error_ppm·10⁻⁶)).
    pub odr_hz_actual: f64,
    /// Error of the gyro's internal clock against the rig's µs timer, ppm.
    pub odr_error_ppm: f64,
    /// Sample timestamp jitter, µs rms.
    pub timestamp_jitter_us: f64,
    /// Encoder counts per base-table revolution.
    pub encoder_counts_per_rev: u32,
    /// Gear ratio announced in `Hello` (θ2 turns per θ1 turn).
    pub gear_ratio_nominal: f64,
    /// Actual gear ratio (differs only with `gear_ratio_error`).
    pub gear_ratio: f64,
    /// True θ2 at the centre of the index pulse, degrees (0 unless `index_offset` is on). θ2 is
    /// defined as 0 at the centre of the shield plate as designed.
    pub index_offset_deg: f64,
    /// Angular width of the shield plate, degrees of θ2.
    pub index_plate_width_deg: f64,
    /// Timer value at power-up, µs.
    pub start_t_us: u32,
    /// Encoder register at power-up.
    pub start_encoder: u32,
    /// Die temperature at power-up, °C.
    pub ambient_c: f64,
    /// OUT_TEMP = out_temp_at_0c − T(°C), rounded.
    pub out_temp_at_0c: f64,
    /// Low-pass cut-off in force, Hz (None if the low-pass is off).
    pub lowpass_cutoff_hz: Option<f64>,
    /// Effects in force, with their parameters (null = off).
    pub effects: Effects,
    /// Runs, in stream order.
    pub runs: Vec<RunTruth>,
    /// With temperature dependence: the coefficients and the reference values (`m_counts_per_dps`
    /// and `offset_counts` above are then those at the runs' mean die temperature).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thermal: Option<super::thermal::ThermalTruth>,
}

/// One run as simulated.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct RunTruth {
    /// Pose mounted.
    pub pose: Pose,
    /// Commanded base-table rate, °/s, signed (sign = direction).
    pub rate_dps: f64,
    /// From `RunStarted` to `RunStopped`, s (spin-up included).
    pub duration_s: f64,
    /// Simulated time of `RunStarted`, s since power-up.
    pub start_s: f64,
    /// Samples emitted.
    pub samples: u64,
    /// Index edges emitted.
    pub index_edges: u64,
    /// Gyro settings of the run.
    pub gyro: GyroConfig,
    /// Frequency of the sinusoidal excitation, |θ2'|/360°, Hz.
    pub drive_hz: f64,
    /// Low-pass group delay at `drive_hz`, ms (0 when the low-pass is off).
    pub filter_group_delay_ms: f64,
    /// Total output delay at `drive_hz`, ms: low-pass group delay plus the pure delay.
    pub total_delay_ms: f64,
    /// Whether the run ended by a fault (host link lost) rather than as planned.
    pub faulted: bool,
}

impl Truth {
    /// The sensor alone, as a calibration is compared with it.
    pub fn sensor(&self) -> crate::calib::result::truth_check::SensorTruth {
        crate::calib::result::truth_check::SensorTruth { k_counts_per_dps: self.k_counts_per_dps, s: self.s }
    }

    /// M as a matrix.
    pub fn m(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|r, c| self.m_counts_per_dps[r][c])
    }

    /// Offsets as a vector, counts.
    pub fn offset(&self) -> Vector3<f64> {
        Vector3::from(self.offset_counts)
    }

    /// The noise-free, effect-free output, counts: M R_qᵀ ω2(θ1', θ2, θ2') + v_off (EXCITER.md
    /// eq. 1-2, 6). `theta2_rad` is the true θ2: the index-derived θ2 plus `index_offset_deg`.
    pub fn model_counts(
        &self,
        pose: Pose,
        theta1_rate_dps: f64,
        theta2_rad: f64,
        theta2_rate_dps: f64,
    ) -> Vector3<f64> {
        self.m() * crate::geometry::omega_package(pose, theta1_rate_dps, theta2_rad, theta2_rate_dps) + self.offset()
    }

    /// Pretty JSON.
    pub fn to_json_pretty(&self) -> String {
        serde_json::to_string_pretty(self).expect("Truth has only finite numbers and plain fields")
    }
}
