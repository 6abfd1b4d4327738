//! Residual spectra: an in-place radix-2 FFT (a few lines here beat a dependency for one
//! periodogram per run and axis), the amplitude spectrum for the plots, and the noise level of a
//! band clear of the table harmonics, which is the long-run noise variance the loop's χ² tests
//! and covariances use (white or low-pass-coloured, the low-frequency noise is what biases a fit).

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Bins either side of a table harmonic left out of the noise band: the spectral leakage of a
/// rectangular window falls below 1/(π·3)² ≈ 1 % of the peak power three bins away.
const HARMONIC_GUARD_BINS: usize = 3;

/// In-place iterative radix-2 FFT (Cooley–Tukey, decimation in time) of `re + i·im`; the length
/// a power of two. Plain f64 arithmetic: generic complex code is left unoptimised by the test
/// profile.
pub fn fft(re: &mut [f64], im: &mut [f64]) {
    let n = re.len();
    assert!(n.is_power_of_two() && im.len() == n, "FFT length {n} is not a power of two");
    let mut j = 0;
    for i in 1..n {
        let mut bit = n >> 1;
        while j & bit != 0 {
            j ^= bit;
            bit >>= 1;
        }
        j |= bit;
        if i < j {
            re.swap(i, j);
            im.swap(i, j);
        }
    }
    let mut len = 2;
    while len <= n {
        let half = len / 2;
        let twiddles: Vec<(f64, f64)> = (0..half)
            .map(|k| {
                let (s, c) = (-2.0 * PI * k as f64 / len as f64).sin_cos();
                (c, s)
            })
            .collect();
        for start in (0..n).step_by(len) {
            for (k, &(wr, wi)) in twiddles.iter().enumerate() {
                let (a, b) = (start + k, start + k + half);
                let tr = re[b] * wr - im[b] * wi;
                let ti = re[b] * wi + im[b] * wr;
                re[b] = re[a] - tr;
                im[b] = im[a] - ti;
                re[a] += tr;
                im[a] += ti;
            }
        }
        len <<= 1;
    }
}

/// The periodogram of one series.
#[derive(Debug, Clone)]
pub struct Periodogram {
    /// Bin spacing, Hz.
    pub df_hz: f64,
    /// |X_k|²/N for k = 0..=N_fft/2, N the samples before padding: a white series of variance
    /// σ² has E[|X_k|²/N] = σ² in every bin.
    pub power: Vec<f64>,
    /// Samples in the series.
    pub n: usize,
    /// FFT length (zero-padded).
    pub n_fft: usize,
}

impl Periodogram {
    /// Of `x` sampled at `fs_hz`, mean removed, zero-padded to a power of two.
    pub fn new(x: &[f64], fs_hz: f64) -> Self {
        let n = x.len();
        let n_fft = n.next_power_of_two().max(2);
        let mean = x.iter().sum::<f64>() / n.max(1) as f64;
        let mut re: Vec<f64> = x.iter().map(|&v| v - mean).collect();
        re.resize(n_fft, 0.0);
        let mut im = vec![0.0; n_fft];
        fft(&mut re, &mut im);
        let power = re[..=n_fft / 2].iter().zip(&im).map(|(r, i)| (r * r + i * i) / n as f64).collect();
        Self { df_hz: fs_hz / n_fft as f64, power, n, n_fft }
    }

    /// Amplitude a sinusoid at bin k would have, 2|X_k|/N.
    pub fn amplitude(&self, k: usize) -> f64 {
        2.0 * (self.power[k] / self.n as f64).sqrt()
    }

    /// Mean power in [f_lo, f_hi] Hz, leaving out bins near multiples of `f_table_hz`: for
    /// white noise of variance σ² the expected |X_k|²/N is σ² (zero padding spreads the same
    /// energy over more bins without changing the level), and for coloured noise it is the
    /// spectral density there, i.e. the long-run variance if the band is low and flat.
    pub fn noise_variance(&self, f_lo_hz: f64, f_hi_hz: f64, f_table_hz: f64) -> Option<f64> {
        let guard = HARMONIC_GUARD_BINS as f64 * self.df_hz;
        let (mut sum, mut count) = (0.0, 0usize);
        let k_lo = (f_lo_hz / self.df_hz).ceil() as usize;
        let k_hi = ((f_hi_hz / self.df_hz).floor() as usize).min(self.power.len() - 1);
        for k in k_lo..=k_hi {
            let f = k as f64 * self.df_hz;
            if f_table_hz > 0.0 {
                let h = (f / f_table_hz).round() * f_table_hz;
                if (f - h).abs() <= guard {
                    continue;
                }
            }
            sum += self.power[k];
            count += 1;
        }
        (count > 0).then(|| sum / count as f64)
    }
}

/// Amplitude spectrum for a plot, °/s against Hz.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AmplitudeSpectrum {
    /// Frequencies, Hz.
    pub freq_hz: Vec<f64>,
    /// Amplitude of a sinusoid at each frequency, °/s.
    pub amplitude_dps: Vec<f64>,
}

impl AmplitudeSpectrum {
    /// Up to `f_max_hz`, scaled by 1/`counts_per_dps`, at most `max_points` points (each the
    /// largest of the bins it stands for, so that peaks survive).
    pub fn from_periodogram(p: &Periodogram, counts_per_dps: f64, f_max_hz: f64, max_points: usize) -> Self {
        let k_max = ((f_max_hz / p.df_hz) as usize).min(p.power.len() - 1);
        let group = k_max.div_ceil(max_points.max(1)).max(1);
        let (mut freq_hz, mut amplitude_dps) = (Vec::new(), Vec::new());
        let mut k = 1;
        while k <= k_max {
            let end = (k + group).min(k_max + 1);
            let best = (k..end).max_by(|&a, &b| p.power[a].total_cmp(&p.power[b])).unwrap_or(k);
            freq_hz.push(best as f64 * p.df_hz);
            amplitude_dps.push(p.amplitude(best) / counts_per_dps);
            k = end;
        }
        Self { freq_hz, amplitude_dps }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Complex;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    #[test]
    fn fft_matches_a_direct_dft() {
        let x: Vec<Complex<f64>> = (0..16).map(|i| Complex::new((i * i % 7) as f64, (i % 3) as f64)).collect();
        let (mut re, mut im): (Vec<f64>, Vec<f64>) = x.iter().map(|c| (c.re, c.im)).unzip();
        fft(&mut re, &mut im);
        for k in 0..16 {
            let direct: Complex<f64> = x
                .iter()
                .enumerate()
                .map(|(n, xn)| xn * Complex::from_polar(1.0, -2.0 * PI * (k * n) as f64 / 16.0))
                .sum();
            assert!((Complex::new(re[k], im[k]) - direct).norm() < 1e-9, "bin {k}");
        }
    }

    #[test]
    fn sinusoid_amplitude_and_white_noise_level_are_recovered() {
        let fs = 800.0;
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        // 0.5 Hz × 2.0 amplitude over 64 s (a whole number of periods lands on a bin) plus unit
        // white noise.
        let x: Vec<f64> = (0..(64 * 800))
            .map(|i| {
                let t = i as f64 / fs;
                2.0 * (2.0 * PI * 0.5 * t).sin() + rng.sample::<f64, _>(StandardNormal)
            })
            .collect();
        let p = Periodogram::new(&x, fs);
        let k = (0.5 / p.df_hz).round() as usize;
        assert!((p.amplitude(k) - 2.0).abs() < 0.05, "{}", p.amplitude(k));
        // ≈ 3000 bins averaged: the level is within a few % of σ² = 1.
        let v = p.noise_variance(5.0, 40.0, 0.5).unwrap();
        assert!((v - 1.0).abs() < 0.06, "{v}");
    }
}
