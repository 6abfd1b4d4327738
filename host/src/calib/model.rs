//! A model is a set of regressor columns evaluated at each sample; the gyro output of every axis
//! is fitted as a linear combination of them. Extra effects (stage 2) are extra columns.

use super::kinematics::{KinSample, RunKinematics};

/// Regressor columns of a linear model, all three axes sharing them.
pub trait Columns<const P: usize> {
    /// Model name as reported.
    fn name(&self) -> &'static str;
    /// Column names, in order.
    fn column_names(&self) -> [&'static str; P];
    /// The columns at one sample of a run.
    fn row(&self, run: &RunKinematics, s: &KinSample) -> [f64; P];
}

/// The sensor model of EXCITER.md eq. 6 with eq. 2: `v = M R_qᵀ ω2 + v_off`. Columns: the rate
/// the package feels, ω_s = R_qᵀ ω2 (°/s, package axes), and 1; the coefficients of axis i are
/// row i of M (counts per °/s) and its offset (counts).
#[derive(Debug, Clone, Copy, Default)]
pub struct LinearRate;

impl LinearRate {
    /// Number of columns.
    pub const P: usize = 4;
}

impl Columns<4> for LinearRate {
    fn name(&self) -> &'static str {
        "linear: v = K S ω + v_off"
    }

    fn column_names(&self) -> [&'static str; 4] {
        ["omega_x_dps", "omega_y_dps", "omega_z_dps", "one"]
    }

    #[inline]
    fn row(&self, run: &RunKinematics, s: &KinSample) -> [f64; 4] {
        let w = run.omega_package_dps(s);
        [w[0], w[1], w[2], 1.0]
    }
}
