//! Kinematics of the two-table exciter (EXCITER.md, eq. 1-3 and 8-10) in the host's types: the
//! maths is [`protocol::exciter`]'s, which the firmware's plant uses too.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// Earth's sidereal rotation rate, rad/s (IERS Conventions 2010, §1.2: 7.292115×10⁻⁵ rad/s,
/// 15.041 °/h).
pub const EARTH_RATE_RAD_S: f64 = 7.292_115e-5;

/// How the gyro package is mounted on the sensor table. The pose travels in the capture itself
/// (`RunStarted::run_tag`), so that a capture cannot be attributed to the wrong pose.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Pose {
    /// Pose 1: α = φ, β = 0, γ = 45° (eq. 8).
    One,
    /// Pose 2: pose 1 turned −90° about the table's y axis, R2 = Ry(−90°)·R1 (eq. 10).
    Two,
}

impl Pose {
    /// All poses, in order.
    pub const ALL: [Pose; 2] = [Pose::One, Pose::Two];

    /// The run tag the host sends in `StartRun` and the rig echoes in `RunStarted`.
    pub const fn run_tag(self) -> u8 {
        match self {
            Pose::One => protocol::run_tag::POSE_1,
            Pose::Two => protocol::run_tag::POSE_2,
        }
    }

    /// The pose a run tag names, if any.
    pub const fn from_run_tag(tag: u8) -> Option<Pose> {
        match tag {
            protocol::run_tag::POSE_1 => Some(Pose::One),
            protocol::run_tag::POSE_2 => Some(Pose::Two),
            _ => None,
        }
    }

    /// 1-based pose number as printed.
    pub const fn number(self) -> u8 {
        self.run_tag()
    }

    /// Rotation R_q from the package frame to the sensor-table frame O2 (eq. 3).
    pub fn rotation(self) -> Matrix3<f64> {
        let r = match self {
            Pose::One => &protocol::exciter::POSE_1_ROTATION,
            Pose::Two => &protocol::exciter::POSE_2_ROTATION,
        };
        Matrix3::from_fn(|i, j| r[i][j])
    }
}

impl std::fmt::Display for Pose {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "pose {}", self.number())
    }
}

/// Angular velocity of the sensor table in its own frame O2 (eq. 1), in the unit of the rates.
pub fn omega2(theta1_rate: f64, theta2_rad: f64, theta2_rate: f64) -> Vector3<f64> {
    Vector3::from(protocol::exciter::table_rate(theta1_rate, theta2_rad.sin_cos(), theta2_rate))
}

/// Angular velocity felt by the package, ω_s = R_qᵀ ω2 (eq. 2).
pub fn omega_package(pose: Pose, theta1_rate: f64, theta2_rad: f64, theta2_rate: f64) -> Vector3<f64> {
    pose.rotation().transpose() * omega2(theta1_rate, theta2_rad, theta2_rate)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Eq. 9 and eq. 10 of the paper, as corrected in EXCITER.md, must follow from the rotations.
    #[test]
    fn poses_reproduce_the_papers_closed_forms() {
        let (w1, w2) = (1.3, 0.7);
        // Tilt of the pose-1 mount: cos φ = 1/√3, φ = 54.7356° (EXCITER.md corrects the
        // paper's misprinted 57.74°).
        let phi = (1.0f64 / 3.0f64.sqrt()).acos();
        assert!((phi.to_degrees() - 54.7356).abs() < 1e-4);
        for k in 0..36 {
            let th = k as f64 * 10f64.to_radians();
            let a = 6f64.sqrt() / 3.0;
            let p1 = Vector3::new(
                w1 * a * (th + PI / 6.0).sin() + w2 / 3f64.sqrt(),
                w1 * a * (th + 5.0 * PI / 6.0).sin() + w2 / 3f64.sqrt(),
                w1 * a * (th + 3.0 * PI / 2.0).sin() + w2 / 3f64.sqrt(),
            );
            assert!((omega_package(Pose::One, w1, th, w2) - p1).norm() < 1e-12);
            let r = 1.0 / 2f64.sqrt();
            let p2 = Vector3::new(
                w1 * r * (th + PI / 2.0 + phi).sin() + w2 * r,
                w1 * r * (th + PI / 2.0 + phi).sin() - w2 * r,
                w1 * (th + PI + phi).sin(),
            );
            assert!((omega_package(Pose::Two, w1, th, w2) - p2).norm() < 1e-12, "θ2 = {th}");
        }
    }

    #[test]
    fn pose_one_peak_exceeds_the_250_dps_range_at_half_a_hertz() {
        let peak = (0..3600)
            .map(|k| omega_package(Pose::One, 180.0, (k as f64 * 0.1).to_radians(), 180.0).amax())
            .fold(0.0, f64::max);
        assert!((peak - 250.9).abs() < 0.1, "{peak}");
    }
}
