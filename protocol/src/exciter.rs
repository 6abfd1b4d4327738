//! The exciter's kinematics (EXCITER.md, eq. 1-3 and 8-10): the one implementation the
//! firmware's simulated plant, the host's simulator and the host's calibration all use, so that
//! the poses a run tag names ([`crate::run_tag`]) and the rates they give cannot disagree.
//!
//! No trigonometry here (the crate has no maths library): the pose rotations are exact closed
//! forms, and eq. 1 takes θ2's sine and cosine from the caller, who computes them once.

/// 1/√2 (`core::f64::consts::FRAC_1_SQRT_2`).
const R2: f64 = core::f64::consts::FRAC_1_SQRT_2;
/// 1/√3, correctly rounded.
const R3: f64 = 0.577_350_269_189_625_8;
/// 1/√6, correctly rounded.
const R6: f64 = 0.408_248_290_463_863_1;
/// √(2/3) = sin φ, correctly rounded.
const S23: f64 = 0.816_496_580_927_726;

/// R_q of pose 1, from the package frame to the sensor-table frame O2: Rx(φ)·Rz(45°) with
/// cos φ = 1/√3, sin φ = √(2/3) (eq. 3 and 8, with EXCITER.md's φ = 54.7356°). Its third row
/// puts the package's [1, 1, 1] diagonal along z2, which is what makes every axis see θ2'/√3.
pub const POSE_1_ROTATION: [[f64; 3]; 3] = [[R2, -R2, 0.0], [R6, R6, -S23], [R3, R3, R3]];

/// R_q of pose 2: pose 1 turned −90° about the table's y axis, Ry(−90°)·R1 (eq. 10). Ry(−90°)
/// sends row 3 to row 1 negated and row 1 to row 3.
pub const POSE_2_ROTATION: [[f64; 3]; 3] = [[-R3, -R3, -R3], [R6, R6, -S23], [R2, -R2, 0.0]];

/// The rotation of the pose a run tag names, if it names one.
pub const fn rotation(run_tag: u8) -> Option<&'static [[f64; 3]; 3]> {
    match run_tag {
        crate::run_tag::POSE_1 => Some(&POSE_1_ROTATION),
        crate::run_tag::POSE_2 => Some(&POSE_2_ROTATION),
        _ => None,
    }
}

/// Angular velocity of the sensor table in its own frame O2 (eq. 1): the base's θ1' along z1,
/// which lies at (sin θ2, cos θ2, 0) in O2, plus the table's own θ2' along z2. `theta2_sin_cos`
/// is (sin θ2, cos θ2); the rates in any one unit.
#[inline]
pub fn table_rate(theta1_rate: f64, (sin_theta2, cos_theta2): (f64, f64), theta2_rate: f64) -> [f64; 3] {
    [theta1_rate * sin_theta2, theta1_rate * cos_theta2, theta2_rate]
}

/// A table-frame vector in the package frame, Rᵀ·w (eq. 2).
#[inline]
pub fn to_package(r: &[[f64; 3]; 3], w: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| r[0][i] * w[0] + r[1][i] * w[1] + r[2][i] * w[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
        [0, 1, 2].map(|i| [0, 1, 2].map(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
    }

    #[test]
    fn the_constants_are_the_roots_they_name() {
        for (x, square) in [(R3, 1.0 / 3.0), (R6, 1.0 / 6.0), (S23, 2.0 / 3.0)] {
            assert!((x * x - square).abs() < 2e-16, "{x}² = {}", x * x);
        }
    }

    #[test]
    fn poses_are_rotations_and_pose_2_is_pose_1_turned() {
        for r in [&POSE_1_ROTATION, &POSE_2_ROTATION] {
            let rrt = mul(r, &[0, 1, 2].map(|i| [0, 1, 2].map(|j| r[j][i])));
            for (i, row) in rrt.iter().enumerate() {
                for (j, &v) in row.iter().enumerate() {
                    assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-15, "RRᵀ[{i}][{j}] = {v}");
                }
            }
        }
        let ry_minus_90 = [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]];
        assert_eq!(mul(&ry_minus_90, &POSE_1_ROTATION), POSE_2_ROTATION);
        assert_eq!(rotation(crate::run_tag::POSE_1), Some(&POSE_1_ROTATION));
        assert_eq!(rotation(crate::run_tag::POSE_2), Some(&POSE_2_ROTATION));
        assert_eq!(rotation(crate::run_tag::IDLE), None);
    }

    #[test]
    fn pose_1_gives_every_axis_a_third_of_the_table_rate() {
        // θ1' = 0: only θ2' along z2, seen as θ2'/√3 on each axis (EXCITER.md eq. 9).
        let w = to_package(&POSE_1_ROTATION, table_rate(0.0, (0.0, 1.0), 3.0));
        for v in w {
            assert!((v - 3.0 * R3).abs() < 1e-15, "{w:?}");
        }
    }
}
