//! The simulated exciter: the DC drive, the encoder, the shield plate and photo-interrupter, and
//! the kinematics that give the gyro its input (EXCITER.md, eq. 1-3). The register-level gyro
//! lives in [`l3g4200d_model`]; [`crate::virtual_rig`] ties everything to the firmware core.

pub mod encoder;
pub mod l3g4200d_model;
pub mod motor;
pub mod photo_interrupter;

use crate::pwm::MotorCommand;
use core::f64::consts::TAU;
use encoder::Encoder;
use libm::{cos, sin};
use motor::{DriveParams, Motor};
use photo_interrupter::{Crossing, PhotoInterrupter};
use protocol::ENCODER_COUNTS_PER_REV;

/// Gyro mounting on the sensor table: R_q from the package frame to the table frame O2
/// (EXCITER.md eq. 3), one of the poses of [`protocol::exciter`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation from the package frame to the table frame O2.
    pub r: [[f64; 3]; 3],
}

impl Pose {
    /// Pose 1 ([`protocol::exciter::POSE_1_ROTATION`]).
    pub fn pose1() -> Self {
        Self { r: protocol::exciter::POSE_1_ROTATION }
    }

    /// Pose 2 ([`protocol::exciter::POSE_2_ROTATION`]).
    pub fn pose2() -> Self {
        Self { r: protocol::exciter::POSE_2_ROTATION }
    }

    /// The pose a run tag names ([`protocol::run_tag`]); the virtual rig's "automatic mount".
    pub fn from_run_tag(tag: u8) -> Option<Self> {
        protocol::exciter::rotation(tag).map(|&r| Self { r })
    }

    /// `Rᵀ ω`: a table-frame vector in the package frame (eq. 2).
    pub fn to_package(&self, w: [f64; 3]) -> [f64; 3] {
        protocol::exciter::to_package(&self.r, w)
    }
}

/// A level change of the index, located inside a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IndexCrossing {
    /// Where in the step, as a fraction.
    pub fraction: f64,
    /// Beam blocked after it.
    pub level: bool,
    /// Encoder counter at that instant.
    pub encoder: u32,
}

/// Everything mechanical and optical.
#[derive(Debug, Clone)]
pub struct Plant {
    /// Drive and tables.
    pub motor: Motor,
    /// Base-table encoder.
    pub encoder: Encoder,
    /// Index.
    pub index: PhotoInterrupter,
    /// Gyro mounting.
    pub pose: Pose,
    /// θ2 when θ1 = 0, rad.
    pub theta2_offset_rad: f64,
    /// The gyro's own imperfection, `K S` (EXCITER.md eq. 6): row i is axis i's sensitivity
    /// times its true direction in the package frame. Identity for an ideal gyro.
    pub sensor_ks: [[f64; 3]; 3],
    /// Zero-rate offset per axis, °/s.
    pub sensor_offset_dps: [f64; 3],
    /// OUT_TEMP the gyro reports.
    pub temp_raw: i8,
    volts: Option<f64>,
}

impl Plant {
    /// The prototype: RE 30 drive, plate 10° wide centred on θ2 = 0 (the host's reference: θ2 = 0
    /// at the pulse centre, host/src/calib/data/kinematics.rs), gyro in pose 1, encoder counter
    /// starting 2 s of 0.5 Hz travel short of its 32-bit wrap.
    pub fn prototype() -> Self {
        Self {
            motor: Motor::new(DriveParams::PROTOTYPE),
            encoder: Encoder { offset_counts: u32::MAX - 324_000, reversed: false },
            index: PhotoInterrupter { plate_start_rad: -5f64.to_radians(), plate_width_rad: 10f64.to_radians() },
            pose: Pose::pose1(),
            theta2_offset_rad: 0.0,
            sensor_ks: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            sensor_offset_dps: [0.0; 3],
            temp_raw: 20,
            volts: None,
        }
    }

    /// Applies the bridge command: the mean terminal voltage over a PWM period.
    pub fn set_drive(&mut self, cmd: MotorCommand) {
        self.volts = cmd.enable.then(|| f64::from(cmd.duty()) * self.motor.params.vbus_v);
    }

    /// Whether the bridge drives the motor now (enabled), as last set by [`Self::set_drive`].
    pub fn driven(&self) -> bool {
        self.volts.is_some()
    }

    /// Sensor-table angle θ2: the 1:1 magnetic gears turn it with the base.
    pub fn theta2_rad(&self) -> f64 {
        self.motor.theta_rad + self.theta2_offset_rad
    }

    /// Encoder counter now.
    pub fn encoder_count(&self) -> u32 {
        self.encoder.count(self.motor.theta_rad)
    }

    /// True base-table speed, counts/s.
    pub fn speed_cps(&self) -> f64 {
        self.motor.omega_rad_s / TAU * f64::from(ENCODER_COUNTS_PER_REV)
    }

    /// Beam blocked now.
    pub fn index_level(&self) -> bool {
        self.index.blocked(self.theta2_rad())
    }

    /// What the gyro's three axes sense, °/s: `K S Rᵀ ω2 + offset` (eq. 1, 2, 6).
    pub fn gyro_rates_dps(&self) -> [f64; 3] {
        let w1 = self.motor.omega_rad_s;
        let th2 = self.theta2_rad();
        // The 1:1 gears turn the sensor table at the base's rate: θ2' = θ1'.
        let table = protocol::exciter::table_rate(w1, (sin(th2), cos(th2)), w1);
        let package = self.pose.to_package(table).map(f64::to_degrees);
        let ks = &self.sensor_ks;
        [0, 1, 2].map(|i| (0..3).map(|j| ks[i][j] * package[j]).sum::<f64>() + self.sensor_offset_dps[i])
    }

    /// Advances by `dt_s`; reports an index edge inside the step, with the encoder counter at
    /// the edge.
    pub fn step(&mut self, dt_s: f64) -> Option<IndexCrossing> {
        let theta1_before = self.motor.theta_rad;
        let theta2_before = self.theta2_rad();
        self.motor.step(dt_s, self.volts, theta2_before);
        let Crossing { fraction, level } = self.index.crossing(theta2_before, self.theta2_rad())?;
        let theta1_at = theta1_before + fraction * (self.motor.theta_rad - theta1_before);
        Some(IndexCrossing { fraction, level, encoder: self.encoder.count(theta1_at) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::{FRAC_PI_2, FRAC_PI_6, PI};
    use libm::sqrt;

    #[test]
    fn pose1_rates_match_the_closed_form() {
        // EXCITER.md: ω_s = θ1'(√6/3)[sin(θ2+π/6), sin(θ2+5π/6), sin(θ2+3π/2)] + θ2'/√3 [1,1,1].
        let mut plant = Plant::prototype();
        plant.motor.omega_rad_s = PI; // 180 °/s
        for k in 0..24 {
            plant.motor.theta_rad = f64::from(k) * TAU / 24.0;
            let th2 = plant.theta2_rad();
            let a = 180.0 * sqrt(6.0) / 3.0;
            let b = 180.0 / sqrt(3.0);
            let expected =
                [a * sin(th2 + FRAC_PI_6) + b, a * sin(th2 + 5.0 * FRAC_PI_6) + b, a * sin(th2 + 3.0 * FRAC_PI_2) + b];
            let got = plant.gyro_rates_dps();
            for i in 0..3 {
                assert!((got[i] - expected[i]).abs() < 1e-9, "θ2={th2} axis {i}");
            }
        }
        // Pose 2 (eq. 10): x = θ1'/√2 sin(θ2+π/2+φ) + θ2'/√2, z = θ1' sin(θ2+π+φ).
        plant.pose = Pose::pose2();
        let phi = libm::acos(1.0 / sqrt(3.0));
        for k in 0..24 {
            plant.motor.theta_rad = f64::from(k) * TAU / 24.0;
            let th2 = plant.theta2_rad();
            let got = plant.gyro_rates_dps();
            let x = 180.0 / sqrt(2.0) * (sin(th2 + FRAC_PI_2 + phi) + 1.0);
            let y = 180.0 / sqrt(2.0) * (sin(th2 + FRAC_PI_2 + phi) - 1.0);
            let z = 180.0 * sin(th2 + PI + phi);
            assert!((got[0] - x).abs() < 1e-9, "pose 2 x at θ2={th2}: {} vs {x}", got[0]);
            assert!((got[1] - y).abs() < 1e-9, "pose 2 y at θ2={th2}: {} vs {y}", got[1]);
            assert!((got[2] - z).abs() < 1e-9, "pose 2 z at θ2={th2}: {} vs {z}", got[2]);
        }
        plant.pose = Pose::pose1();
        // And the EXCITER.md peak: 147 + 104 = 251 °/s.
        plant.motor.theta_rad = FRAC_PI_2 - FRAC_PI_6;
        assert!((plant.gyro_rates_dps()[0] - 250.9).abs() < 0.1);
    }
}
