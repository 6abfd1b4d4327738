//! The gyro's internal digital low-pass, modelled as a 2nd-order Butterworth biquad.
//!
//! The datasheet gives only the cut-off (Table 21), not the filter structure or the internal
//! rate; a Butterworth section designed by the bilinear transform (pre-warped at the cut-off) is
//! the usual choice and gives the expected low-frequency delay of ≈ √2/(2π·fc).

use nalgebra::Complex;
use std::f64::consts::PI;

/// Filter rate as a multiple of the ODR. Assumed 1: the filter runs after decimation, at the
/// ODR (every Table-21 cut-off is below the ODR's Nyquist frequency). At 800 Hz and 110 Hz this
/// gives 1.92 ms of delay against 2.05 ms for the analogue prototype; the truth reports the
/// digital filter's actual delay.
pub const OVERSAMPLING: u32 = 1;

/// Coefficients of one biquad, `a0` normalised to 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Butterworth2 {
    b: [f64; 3],
    a: [f64; 2],
}

impl Butterworth2 {
    /// Low-pass with cut-off `fc_hz` (−3 dB) at sample rate `fs_hz`.
    pub fn lowpass(fc_hz: f64, fs_hz: f64) -> Self {
        let k = (PI * fc_hz / fs_hz).tan();
        let norm = 1.0 / (1.0 + std::f64::consts::SQRT_2 * k + k * k);
        let b0 = k * k * norm;
        Self {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) * norm, (1.0 - std::f64::consts::SQRT_2 * k + k * k) * norm],
        }
    }

    /// Complex response at `f_hz` for sample rate `fs_hz`.
    fn response(&self, f_hz: f64, fs_hz: f64) -> Complex<f64> {
        let z1 = Complex::from_polar(1.0, -2.0 * PI * f_hz / fs_hz);
        let z2 = z1 * z1;
        let num = self.b[0] + z1 * self.b[1] + z2 * self.b[2];
        let den = Complex::new(1.0, 0.0) + z1 * self.a[0] + z2 * self.a[1];
        num / den
    }

    /// Group delay −dφ/dω at `f_hz`, s, by a central difference of the phase.
    pub fn group_delay_s(&self, f_hz: f64, fs_hz: f64) -> f64 {
        let h = 1e-3;
        let (f0, f1) = ((f_hz - h).max(0.0), f_hz + h);
        let dphi = (self.response(f1, fs_hz) / self.response(f0, fs_hz)).arg();
        -dphi / (2.0 * PI * (f1 - f0))
    }
}

/// Three channels of one biquad, transposed direct form II.
#[derive(Debug, Clone, Copy)]
pub struct Filter3 {
    coef: Butterworth2,
    s: [[f64; 2]; 3],
}

impl Filter3 {
    /// A filter with zero state.
    pub fn new(coef: Butterworth2) -> Self {
        Self { coef, s: [[0.0; 2]; 3] }
    }

    /// Sets the state to the steady state for a constant input `x` (unit DC gain).
    pub fn settle(&mut self, x: [f64; 3]) {
        let [b0, b1, b2] = self.coef.b;
        let [a1, a2] = self.coef.a;
        for (s, x) in self.s.iter_mut().zip(x) {
            // Steady state of y = x: s1 = b1·x − a1·y + s2, s2 = b2·x − a2·y.
            s[1] = (b2 - a2) * x;
            s[0] = (b1 - a1) * x + s[1];
            debug_assert!(((b0 * x + s[0]) - x).abs() <= 1e-9 * x.abs().max(1.0));
        }
    }

    /// Filters one input vector.
    pub fn step(&mut self, x: [f64; 3]) -> [f64; 3] {
        let [b0, b1, b2] = self.coef.b;
        let [a1, a2] = self.coef.a;
        let mut y = [0.0; 3];
        for ((s, x), y) in self.s.iter_mut().zip(x).zip(y.iter_mut()) {
            *y = b0 * x + s[0];
            s[0] = b1 * x - a1 * *y + s[1];
            s[1] = b2 * x - a2 * *y;
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cutoff_gain_and_low_frequency_delay_match_the_analogue_prototype() {
        let (fc, fs) = (110.0, 3200.0);
        let f = Butterworth2::lowpass(fc, fs);
        assert!((f.response(fc, fs).norm() - 0.5f64.sqrt()).abs() < 1e-9);
        assert!((f.response(0.0, fs).norm() - 1.0).abs() < 1e-12);
        // Analogue 2nd-order Butterworth: τ(0) = √2/(2π·fc) = 2.046 ms; the bilinear map changes
        // it by (πfc/fs)²-order terms, ~1 % here.
        let tau = f.group_delay_s(0.5, fs);
        let analogue = std::f64::consts::SQRT_2 / (2.0 * PI * fc);
        assert!((tau / analogue - 1.0).abs() < 0.03, "{tau} vs {analogue}");
    }

    #[test]
    fn filter_settles_to_a_constant_and_delays_a_ramp_by_the_group_delay() {
        let fs = 3200.0;
        let coef = Butterworth2::lowpass(30.0, fs);
        let mut f = Filter3::new(coef);
        f.settle([1.0, -2.0, 0.0]);
        let y = f.step([1.0, -2.0, 0.0]);
        assert!((y[0] - 1.0).abs() < 1e-12 && (y[1] + 2.0).abs() < 1e-12 && y[2] == 0.0);
        // A ramp comes out delayed by exactly the DC group delay once transients decay.
        let mut f = Filter3::new(coef);
        let mut y = [0.0; 3];
        let n = 3200;
        for i in 0..=n {
            y = f.step([i as f64 / fs, 0.0, 0.0]);
        }
        let lag_s = n as f64 / fs - y[0];
        let tau = coef.group_delay_s(0.0, fs);
        assert!((lag_s - tau).abs() < 1e-6, "{lag_s} vs {tau}");
    }
}
