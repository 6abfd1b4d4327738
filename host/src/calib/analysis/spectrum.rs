//! Residual spectra: the periodogram of a run's residual by segments (Welch's method with
//! rectangular windows, `realfft`), the amplitude spectrum for the plots, and the noise level of
//! a band clear of the table harmonics, which is the long-run noise variance the loop's χ² tests
//! and covariances use (white or low-pass-coloured, the low-frequency noise is what biases a fit).
//!
//! The Welch averaging around realfft stays here: it is one loop over segments, and its
//! normalisation (|X_k|²/N_seg, the last segment zero-padded) is the one the χ² weights assume,
//! where a spectral-estimation crate would bring its own windows and scaling.

use realfft::RealFftPlanner;
use serde::{Deserialize, Serialize};

/// Bins either side of a table harmonic left out of the noise band: the spectral leakage of a
/// rectangular window falls below 1/(π·3)² ≈ 1 % of the peak power three bins away.
const HARMONIC_GUARD_BINS: usize = 3;

/// Longest FFT, samples: 2^17 is 164 s at 800 Hz, a bin of 0.006 Hz, so the guard bands about
/// the table harmonics (every 0.25-0.5 Hz at 90-180 °/s) leave most of the band to the noise
/// estimate. A longer series is cut into segments of this length (Welch), so memory stays flat
/// and cost linear in the run's length; a series up to this length is one zero-padded segment.
pub const MAX_SEGMENT: usize = 1 << 17;

/// Σ x over the values that are not NaN, in order: what `f64::sum` of them gives, but for the
/// sign of an exact zero (which the periodogram squares away). A NaN adds 0 rather than branch:
/// skipped by a branch, the running sum went through the stack at every value (a store and a
/// reload, 1.4 % of a 1-h replay).
fn nan_skipping_sum<T: Copy + Into<f64>>(x: &[T]) -> f64 {
    let mut sum = -0.0f64;
    for &v in x {
        let v: f64 = v.into();
        sum += if v.is_nan() { 0.0 } else { v };
    }
    sum
}

/// The periodogram of one series.
#[derive(Debug, Clone)]
pub struct Periodogram {
    /// Bin spacing, Hz.
    pub df_hz: f64,
    /// Mean over segments of |X_k|²/N_seg for k = 0..=N_fft/2, N_seg the samples in the segment
    /// before padding: a white series of variance σ² has E[|X_k|²/N_seg] = σ² in every bin.
    pub power: Vec<f64>,
    /// Samples per segment (before padding).
    pub n: usize,
    /// FFT length (zero-padded).
    pub n_fft: usize,
    /// Segments averaged.
    pub segments: usize,
}

impl Periodogram {
    /// Of `x` sampled at `fs_hz`, a NaN (a clipped sample) taken as 0, the mean removed.
    /// Up to [`MAX_SEGMENT`] samples: one segment zero-padded to a power of two. Longer: the
    /// average over consecutive segments of [`MAX_SEGMENT`] samples, the last one ending at the
    /// last sample (it overlaps its neighbour rather than leave samples out). `x` is f64 or f32
    /// (the diagnostics keep their residuals in f32).
    pub fn new<T: Copy + Into<f64>>(x: &[T], fs_hz: f64) -> Self {
        Self::with_planner(x, fs_hz, &mut RealFftPlanner::new())
    }

    /// [`Periodogram::new`] with the FFT plans of `planner`, which keeps them: a plan of 2^17
    /// points computes its twiddles (~200 000 sin/cos), 1.3 % of a 1-h replay when made afresh
    /// for every run and axis.
    // Out of line: inlined into `diagnose`, its running sums lived on the stack (a store and a
    // reload per element; ~1 % of a 1-h replay with the floor's and Ljung–Box's loops).
    #[inline(never)]
    pub fn with_planner<T: Copy + Into<f64>>(x: &[T], fs_hz: f64, planner: &mut RealFftPlanner<f64>) -> Self {
        let n = x.len();
        let mean = nan_skipping_sum(x) / n.max(1) as f64;
        let (seg, n_fft) =
            if n <= MAX_SEGMENT { (n, n.next_power_of_two().max(2)) } else { (MAX_SEGMENT, MAX_SEGMENT) };
        let starts: Vec<usize> = if n <= MAX_SEGMENT {
            vec![0]
        } else {
            let mut s: Vec<usize> = (0..n / seg).map(|i| i * seg).collect();
            if !n.is_multiple_of(seg) {
                s.push(n - seg);
            }
            s
        };
        let fft = planner.plan_fft_forward(n_fft);
        let mut input = fft.make_input_vec();
        let mut output = fft.make_output_vec();
        let mut power = vec![0.0; n_fft / 2 + 1];
        // |X|²/seg: a division per bin and segment (1 % of a 1-h replay), unless seg is a power
        // of two (every segment of a long series), where the reciprocal's product is the same bits.
        let (seg_f, inv_seg, exact) = (seg as f64, 1.0 / seg as f64, seg.is_power_of_two());
        let per_seg = |p: f64| if exact { p * inv_seg } else { p / seg_f };
        for &s0 in &starts {
            for (dst, &v) in input.iter_mut().zip(&x[s0..s0 + seg]) {
                let v: f64 = v.into();
                *dst = if v.is_nan() { 0.0 } else { v } - mean;
            }
            input[seg..].fill(0.0);
            fft.process(&mut input, &mut output).expect("buffers made by the plan have its lengths");
            for (p, c) in power.iter_mut().zip(&output) {
                *p += per_seg(c.norm_sqr());
            }
        }
        let segments = starts.len();
        power.iter_mut().for_each(|p| *p /= segments as f64);
        Self { df_hz: fs_hz / n_fft as f64, power, n: seg, n_fft, segments }
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
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;
    use std::f64::consts::PI;

    #[test]
    fn one_segment_matches_a_direct_dft() {
        // 12 samples: one segment, zero-padded to 16.
        let x: Vec<f64> = (0..12).map(|i| ((i * i) % 7) as f64 - 1.5 * (i % 3) as f64).collect();
        let p = Periodogram::new(&x, 16.0);
        assert_eq!((p.n, p.n_fft, p.segments), (12, 16, 1));
        let mean = x.iter().sum::<f64>() / 12.0;
        for k in 0..=8 {
            let (mut re, mut im) = (0.0, 0.0);
            for (n, v) in x.iter().enumerate() {
                let a = -2.0 * PI * (k * n) as f64 / 16.0;
                re += (v - mean) * a.cos();
                im += (v - mean) * a.sin();
            }
            assert!((p.power[k] - (re * re + im * im) / 12.0).abs() < 1e-9, "bin {k}");
        }
    }

    #[test]
    fn long_series_average_segments_and_clipped_samples_count_as_zero() {
        // 2.5 segments: three segments, the last ending at the last sample.
        let n = 2 * MAX_SEGMENT + MAX_SEGMENT / 2;
        let mut x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin() + 0.25).collect();
        let p = Periodogram::new(&x, 800.0);
        assert_eq!((p.n, p.n_fft, p.segments), (MAX_SEGMENT, MAX_SEGMENT, 3));
        // A clipped (NaN) sample counts as 0, as the explicit 0 does.
        x[10] = 0.0;
        let zero = Periodogram::new(&x, 800.0);
        x[10] = f64::NAN;
        let q = Periodogram::new(&x, 800.0);
        let peak = |p: &Periodogram| (1..p.power.len()).max_by(|&a, &b| p.power[a].total_cmp(&p.power[b])).unwrap();
        assert_eq!(peak(&p), peak(&q));
        assert!((q.power[peak(&q)] / p.power[peak(&p)] - 1.0).abs() < 1e-4);
        assert_eq!(q.power, zero.power);
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
