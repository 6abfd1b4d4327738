//! The gyro's internal digital low-pass: a Butterworth of order 2 (one biquad, the default) or 3
//! (a first-order section and a biquad of Q = 1), each section designed by the bilinear transform
//! pre-warped at the cut-off.
//!
//! The datasheet gives only the cut-off (Table 21), not the filter structure or the internal
//! rate; a 2nd-order Butterworth is the usual choice and gives the expected low-frequency delay of
//! ≈ √2/(2π·fc). Other parts filter otherwise: the independent model of the exciter the
//! validation captures come from has a 3rd-order filter at 35 Hz in one of its sets (issue 24),
//! whose delay, 2/(2π·fc), and droop the calibration must find from the data like any other.

use nalgebra::Complex;
use std::f64::consts::PI;

/// Filter rate as a multiple of the ODR. Assumed 1: the filter runs after decimation, at the
/// ODR (every Table-21 cut-off is below the ODR's Nyquist frequency). At 800 Hz and 110 Hz this
/// gives 1.92 ms of delay against 2.05 ms for the analogue prototype; the truth reports the
/// digital filter's actual delay.
pub const OVERSAMPLING: u32 = 1;

/// The Butterworth orders the simulator builds.
pub const ORDERS: [u8; 2] = [2, 3];

/// Coefficients of one biquad section, `a0` normalised to 1 (a first-order section has
/// `b[2] = a[1] = 0`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Section {
    b: [f64; 3],
    a: [f64; 2],
}

impl Section {
    /// The section that passes its input unchanged.
    const IDENTITY: Self = Self { b: [1.0, 0.0, 0.0], a: [0.0, 0.0] };

    /// Low-pass biquad of quality `q` whose cut-off fc at sample rate fs gives k = tan(π·fc/fs).
    fn second_order(k: f64, q: f64) -> Self {
        let norm = 1.0 / (1.0 + k / q + k * k);
        let b0 = k * k * norm;
        Self { b: [b0, 2.0 * b0, b0], a: [2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm] }
    }

    /// First-order low-pass, k as for [`Section::second_order`].
    fn first_order(k: f64) -> Self {
        let b0 = k / (1.0 + k);
        Self { b: [b0, b0, 0.0], a: [(k - 1.0) / (1.0 + k), 0.0] }
    }

    /// Complex response at `z1` = e^(−jωT).
    fn response(&self, z1: Complex<f64>) -> Complex<f64> {
        let z2 = z1 * z1;
        let num = self.b[0] + z1 * self.b[1] + z2 * self.b[2];
        let den = Complex::new(1.0, 0.0) + z1 * self.a[0] + z2 * self.a[1];
        num / den
    }
}

/// A Butterworth low-pass of order 2 or 3: its sections in cascade.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Butterworth {
    sections: [Section; 2],
}

impl Butterworth {
    /// Low-pass of `order` ([`ORDERS`]) with cut-off `fc_hz` (−3 dB) at sample rate `fs_hz`: for
    /// order 2 one biquad of Q = 1/√2; for order 3 the real pole and a biquad of Q = 1 (the
    /// Butterworth poles at 180° and ±60° from the negative real axis).
    pub fn lowpass(order: u8, fc_hz: f64, fs_hz: f64) -> Self {
        debug_assert!(ORDERS.contains(&order), "order {order}");
        let k = (PI * fc_hz / fs_hz).tan();
        let sections = match order {
            3 => [Section::first_order(k), Section::second_order(k, 1.0)],
            _ => [Section::second_order(k, std::f64::consts::FRAC_1_SQRT_2), Section::IDENTITY],
        };
        Self { sections }
    }

    /// Complex response at `f_hz` for sample rate `fs_hz`.
    fn response(&self, f_hz: f64, fs_hz: f64) -> Complex<f64> {
        let z1 = Complex::from_polar(1.0, -2.0 * PI * f_hz / fs_hz);
        self.sections.iter().map(|s| s.response(z1)).product()
    }

    /// Group delay −dφ/dω at `f_hz`, s, by a central difference of the phase.
    pub fn group_delay_s(&self, f_hz: f64, fs_hz: f64) -> f64 {
        let h = 1e-3;
        let (f0, f1) = ((f_hz - h).max(0.0), f_hz + h);
        let dphi = (self.response(f1, fs_hz) / self.response(f0, fs_hz)).arg();
        -dphi / (2.0 * PI * (f1 - f0))
    }
}

/// Three channels of a [`Butterworth`], each section in transposed direct form II.
#[derive(Debug, Clone, Copy)]
pub struct Filter3 {
    coef: Butterworth,
    /// Per section, per channel, the two state values.
    s: [[[f64; 2]; 3]; 2],
}

impl Filter3 {
    /// A filter with zero state.
    pub fn new(coef: Butterworth) -> Self {
        Self { coef, s: [[[0.0; 2]; 3]; 2] }
    }

    /// Sets the state to the steady state for a constant input `x` (unit DC gain in every
    /// section, so each passes `x` on).
    pub fn settle(&mut self, x: [f64; 3]) {
        for (sec, states) in self.coef.sections.iter().zip(self.s.iter_mut()) {
            let [b0, b1, b2] = sec.b;
            let [a1, a2] = sec.a;
            for (s, x) in states.iter_mut().zip(x) {
                // Steady state of y = x: s1 = b1·x − a1·y + s2, s2 = b2·x − a2·y.
                s[1] = (b2 - a2) * x;
                s[0] = (b1 - a1) * x + s[1];
                debug_assert!(((b0 * x + s[0]) - x).abs() <= 1e-9 * x.abs().max(1.0));
            }
        }
    }

    /// Filters one input vector.
    pub fn step(&mut self, x: [f64; 3]) -> [f64; 3] {
        let mut y = x;
        for (sec, states) in self.coef.sections.iter().zip(self.s.iter_mut()) {
            let [b0, b1, b2] = sec.b;
            let [a1, a2] = sec.a;
            for (s, v) in states.iter_mut().zip(y.iter_mut()) {
                let x = *v;
                *v = b0 * x + s[0];
                s[0] = b1 * x - a1 * *v + s[1];
                s[1] = b2 * x - a2 * *v;
            }
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cutoff_gain_and_low_frequency_delay_match_the_analogue_prototype() {
        // Analogue 2nd-order Butterworth: τ(0) = √2/(2π·fc) = 2.046 ms; the bilinear map changes
        // it by (πfc/fs)²-order terms, ~1 % here.
        let (fc, fs) = (110.0, 3200.0);
        assert_gains_and_delay(&Butterworth::lowpass(2, fc, fs), fc, fs, std::f64::consts::SQRT_2 / (2.0 * PI * fc));
    }

    /// −3 dB at `fc_hz`, unit gain at DC, and a delay at 0.5 Hz within 3 % of `analogue_s`.
    fn assert_gains_and_delay(f: &Butterworth, fc_hz: f64, fs_hz: f64, analogue_s: f64) {
        assert!((f.response(fc_hz, fs_hz).norm() - 0.5f64.sqrt()).abs() < 1e-9);
        assert!((f.response(0.0, fs_hz).norm() - 1.0).abs() < 1e-12);
        let tau = f.group_delay_s(0.5, fs_hz);
        assert!((tau / analogue_s - 1.0).abs() < 0.03, "{tau} vs {analogue_s}");
    }

    #[test]
    fn a_third_order_has_its_cutoff_gain_and_twice_the_first_sections_delay() {
        let (fc, fs) = (35.0, 800.0);
        let f = Butterworth::lowpass(3, fc, fs);
        // Analogue: τ(0) = 1/ωc (the real pole) + 1/(Q·ωc) (the Q = 1 pair) = 2/(2π·fc) = 9.09 ms;
        // the bilinear map at 800 Hz changes it by (πfc/fs)²-order terms, a few %.
        assert_gains_and_delay(&f, fc, fs, 2.0 / (2.0 * PI * fc));
        // Butterworth of order 3: |H|² = 1/(1 + (f/fc)⁶) in the analogue prototype; the
        // bilinear map, pre-warped at fc, keeps that at tan(πf/fs)/tan(πfc/fs) in place of f/fc.
        let f_hz = 70.0;
        let x = (PI * f_hz / fs).tan() / (PI * fc / fs).tan();
        assert!((f.response(f_hz, fs).norm() - (1.0 + x.powi(6)).powf(-0.5)).abs() < 1e-9);
    }

    #[test]
    fn filter_settles_to_a_constant_and_delays_a_ramp_by_the_group_delay() {
        for order in ORDERS {
            settles_and_delays_a_ramp(Butterworth::lowpass(order, 30.0, 3200.0), 3200.0);
        }
    }

    fn settles_and_delays_a_ramp(coef: Butterworth, fs: f64) {
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
