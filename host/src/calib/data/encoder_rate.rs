//! The base table's rate θ1' from encoder counts sampled at the gyro's data-ready instants.
//!
//! A local straight-line fit of count against time over 2h+1 samples is exact for a constant
//! speed, but over its span T it averages a ripple of frequency f by 1 − (πfT)²/10: with
//! T = 20 ms, 2.8 % of a ripple at 8 Hz (the 16-pole gears' pole pass at 180 °/s) and 11 % at
//! 16 Hz. θ1' multiplies every axis's signal, so a ripple at n× θ2 that θ1' misses leaves lines at
//! (n ± 1)× in the residual, which no effect explains: the trust bench's drawn rig at 3× has the
//! motor's speed ripple at 0.59 % at 16×, of which θ1' missed 0.03 °/s, and was flagged by
//! lines of 0.015-0.019 °/s (11σ) at 15× and 17× (`docs/trust.md`).
//!
//! The straight line's bias is its window's third moment: on θ1 = b·u + d·u³ the slope is
//! b + d·Σu⁴/Σu², i.e. θ1' + θ1'''·κ with κ = Σu⁴/(6Σu²) = Δt²(3h² + 3h − 1)/30 for even spacing
//! Δt. The slopes at the window's own ends, h samples either side, give θ1''' by their second
//! difference (exact on a cubic: the slope of a cubic is θ1' plus a constant), and subtracting
//! κ·θ1''' makes the estimate exact for cubics: the attenuation falls to ≈ 0.015·(πfT)⁴ (1.1e-3 at
//! 8 Hz, 1.6e-2 at 16 Hz with T = 20 ms) for 1.28× the quantisation noise of the straight line
//! ([`noise_gain`]). A cubic Savitzky-Golay slope over the same span does a little better
//! (1.5e-4 at 8 Hz) for 2.5× the noise; this keeps the straight line's exact sliding sums and
//! uses the samples' actual times in the second difference, so gaps and timestamp jitter stay
//! where the straight line put them.

use crate::capture::{RunSample, Samples};

/// Local straight-line slopes of encoder count against time, counts/s, over windows of 2h+1
/// consecutive samples: `f(centre index, centre sample, slope)` for every sample with a full
/// window. Sliding sums of offsets from the run's first sample, in i128 so that they stay exact
/// for any run length: O(1) per sample, the samples read in one pass and held while in the
/// window. The centred combinations n·Σte − Σt·Σe and n·Σtt − (Σt)² are those of the window
/// alone (≲ 1e13 for any sane window), so they pass through i64 on their way to f64.
pub fn for_each_slope_cps(samples: &(impl Samples + ?Sized), h: usize, mut f: impl FnMut(usize, &RunSample, f64)) {
    let w = 2 * h + 1;
    let Some(first) = samples.iter_from(0).next() else {
        return;
    };
    if samples.len() < w {
        return;
    }
    let (t0, e0) = (first.t_us, first.encoder);
    let te = |s: &RunSample| (i128::from(s.t_us - t0), i128::from(s.encoder - e0));
    let (mut st, mut stt, mut se, mut ste) = (0i128, 0i128, 0i128, 0i128);
    // The window's samples, each unpacked once as it enters (a cursor each for the entering,
    // leaving and centre samples unpacked every sample three times, 2 % of a 1-h replay).
    // `window[oldest]` is its first sample, the others follow it round the ring.
    let mut entering = samples.iter_from(0);
    let mut window: Vec<RunSample> = Vec::with_capacity(w);
    for s in entering.by_ref().take(w) {
        let (t, e) = te(&s);
        st += t;
        stt += t * t;
        se += e;
        ste += t * e;
        window.push(s);
    }
    let n = w as i128;
    let mut oldest = 0;
    for j in 0..=samples.len() - w {
        if j > 0 {
            let Some(new) = entering.next() else {
                unreachable!("the window stays inside the samples");
            };
            let (to, eo) = te(&window[oldest]);
            let (ti, ei) = te(&new);
            st += ti - to;
            stt += ti * ti - to * to;
            se += ei - eo;
            ste += ti * ei - to * eo;
            window[oldest] = new;
            oldest = if oldest + 1 == w { 0 } else { oldest + 1 };
        }
        let centre = &window[if oldest + h < w { oldest + h } else { oldest + h - w }];
        let num = (n * ste - st * se) as i64 as f64;
        let den = (n * stt - st * st) as i64 as f64;
        f(j + h, centre, num / den * 1e6);
    }
}

/// The same slope at one centre `i` (h ≤ i < len − h), directly: offsets from sample `i` are
/// small enough for i64.
pub fn slope_at_cps(samples: &(impl Samples + ?Sized), i: usize, h: usize) -> f64 {
    let c = samples.iter_from(i).next().expect("the centre is a sample");
    let (mut st, mut stt, mut se, mut ste) = (0i64, 0i64, 0i64, 0i64);
    for s in samples.iter_from(i - h).take(2 * h + 1) {
        let (t, e) = (s.t_us - c.t_us, s.encoder - c.encoder);
        st += t;
        stt += t * t;
        se += e;
        ste += t * e;
    }
    let n = (2 * h + 1) as i64;
    (n * ste - st * se) as f64 / (n * stt - st * st) as f64 * 1e6
}

/// κ = Σu⁴/(6Σu²) of 2h+1 samples `dt_s` apart, s²: the straight-line slope's bias per unit of
/// θ1''' (module docs).
fn third_moment_s2(h: usize, dt_s: f64) -> f64 {
    let h = h as f64;
    dt_s * dt_s * (3.0 * h * h + 3.0 * h - 1.0) / 30.0
}

/// θ1' exact for cubics, counts/s: the straight-line slopes corrected by κ·θ1''' from their second
/// difference at ±h samples (module docs), `f(centre index, centre sample, rate)` for every sample
/// with full windows at both ends (2h samples from either end of the run). `dt_s` is the
/// samples' nominal spacing.
pub fn for_each_rate_cps(
    samples: &(impl Samples + ?Sized),
    h: usize,
    dt_s: f64,
    mut f: impl FnMut(usize, &RunSample, f64),
) {
    let kappa_s2 = third_moment_s2(h, dt_s);
    // The last 2h+1 slopes, round a ring: slope j sits at j % (2h+1).
    let w = 2 * h + 1;
    let mut ring: Vec<(RunSample, f64)> = Vec::with_capacity(w);
    for_each_slope_cps(samples, h, |j, s, slope| {
        let k = j - h; // the k-th slope made
        if ring.len() < w {
            ring.push((*s, slope));
        } else {
            ring[k % w] = (*s, slope);
        }
        if k + 1 < w {
            return;
        }
        let (lo, mid, hi) = (&ring[(k + 1) % w], &ring[(k + 1 + h) % w], &ring[k % w]);
        let tau_lo_s = (mid.0.t_us - lo.0.t_us) as f64 * 1e-6;
        let tau_hi_s = (hi.0.t_us - mid.0.t_us) as f64 * 1e-6;
        let third = 2.0 * ((hi.1 - mid.1) / tau_hi_s - (mid.1 - lo.1) / tau_lo_s) / (tau_hi_s + tau_lo_s);
        f(j - h, &mid.0, mid.1 - kappa_s2 * third);
    });
}

/// The rms of [`for_each_rate_cps`]'s θ1' per unit of white noise on each count, at 2h+1 samples
/// `dt_s` apart, 1/s: the norm of its weights (the straight line's, `j/(Δt·Σj²)`, at the centre
/// and at ±h, combined as the second difference combines them).
pub fn noise_gain_per_s(h: usize, dt_s: f64) -> f64 {
    let hi = h as i64;
    let sum_j2: f64 = (-hi..=hi).map(|j| (j * j) as f64).sum();
    let alpha = third_moment_s2(h, dt_s) / (h as f64 * dt_s).powi(2);
    let mut weights = vec![0.0; 4 * h + 1];
    for j in -hi..=hi {
        let p = j as f64 / (dt_s * sum_j2);
        for (shift, c) in [(0, 1.0 + 2.0 * alpha), (-hi, -alpha), (hi, -alpha)] {
            weights[(2 * hi + shift + j) as usize] += c * p;
        }
    }
    weights.iter().map(|w| w * w).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples at `fs_hz` whose encoder counts are the angle `theta_counts(t_s)`, rounded down.
    fn sampled(n: usize, fs_hz: f64, theta_counts: impl Fn(f64) -> f64) -> Vec<RunSample> {
        (0..n)
            .map(|i| {
                let t_s = i as f64 / fs_hz;
                RunSample {
                    t_us: (t_s * 1e6).round() as i64,
                    encoder: theta_counts(t_s).floor() as i64,
                    rate_counts: [0; 3],
                    status: 0,
                }
            })
            .collect()
    }

    /// Amplitude of a ripple that θ1' keeps: the fitted sine at `f_hz` over its rates.
    fn kept_fraction(rates: &[(f64, f64)], f_hz: f64) -> f64 {
        let w = std::f64::consts::TAU * f_hz;
        let (mut s, mut c, mut ss, mut cc, mut sc) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(t, r) in rates {
            let (sn, cs) = (w * t).sin_cos();
            s += r * sn;
            c += r * cs;
            ss += sn * sn;
            cc += cs * cs;
            sc += sn * cs;
        }
        let det = ss * cc - sc * sc;
        let (a, b) = ((s * cc - c * sc) / det, (c * ss - s * sc) / det);
        a.hypot(b)
    }

    /// A 1 % ripple at 8 Hz on 180 °/s at 800 Hz, 324 000 counts/rev (the L3G4200D's ODR and the
    /// rig's encoder): the straight line keeps 1 − (πfT)²/10 of it, 2.8 % short; the corrected
    /// rate keeps it to the 1.1e-3 of the cubic's residual bias (module docs), and both read
    /// the steady 180 °/s.
    #[test]
    fn the_corrected_rate_keeps_a_pole_pass_ripple_the_straight_line_averages() {
        let (fs_hz, h, cpd) = (800.0, 8, 900.0);
        // 180 °/s less a little, so that the count's rounding does not repeat every other sample
        // (180 °/s is exactly 202.5 counts a sample).
        let (w0, a, f_hz) = (179.9859 * cpd, 0.01, 8.0);
        let wr = std::f64::consts::TAU * f_hz;
        let samples = sampled(8000, fs_hz, |t| w0 * t + w0 * a / wr * (wr * t).sin() + 0.5);
        let mut line = Vec::new();
        for_each_slope_cps(&samples[..], h, |i, _, r| line.push((i as f64 / fs_hz, r - w0)));
        let mut corrected = Vec::new();
        for_each_rate_cps(&samples[..], h, 1.0 / fs_hz, |i, _, r| corrected.push((i as f64 / fs_hz, r - w0)));
        let line_loss = 1.0 - kept_fraction(&line, f_hz) / (w0 * a);
        let corrected_loss = 1.0 - kept_fraction(&corrected, f_hz) / (w0 * a);
        assert!((line_loss - 0.0280).abs() < 0.001, "{line_loss}");
        assert!((corrected_loss - 0.0011).abs() < 0.0004, "{corrected_loss}");
        assert_eq!(corrected.len(), samples.len() - 4 * h);
        assert_eq!(corrected[0].0, (2 * h) as f64 / fs_hz);
        let mean = corrected.iter().map(|p| p.1).sum::<f64>() / corrected.len() as f64;
        assert!(mean.abs() < 0.02 * cpd, "{mean}");
    }

    /// A cubic angle (a constant jerk) is read exactly where the straight line is off by κ·θ'''.
    #[test]
    fn the_corrected_rate_is_exact_on_a_cubic() {
        let (fs_hz, h) = (800.0, 8);
        let (b, d) = (1.0e5, 4.0e7); // counts/s, counts/s³: κ·θ''' = 2700 counts/s
        let samples = sampled(200, fs_hz, |t| b * t + d * (t - 0.1).powi(3) + 1e6);
        let mut worst: f64 = 0.0;
        for_each_rate_cps(&samples[..], h, 1.0 / fs_hz, |i, s, r| {
            let t = s.t_us as f64 * 1e-6;
            assert_eq!(s.t_us, (i as f64 / fs_hz * 1e6).round() as i64);
            worst = worst.max((r - (b + 3.0 * d * (t - 0.1).powi(2))).abs());
        });
        // The counts' rounding alone: 0.29 counts through a gain of ~50/s.
        assert!(worst < 5.0 * noise_gain_per_s(h, 1.0 / fs_hz), "{worst}");
        let mut line_bias: f64 = 0.0;
        for_each_slope_cps(&samples[..], h, |_, s, r| {
            let t = s.t_us as f64 * 1e-6;
            line_bias = line_bias.max(r - (b + 3.0 * d * (t - 0.1).powi(2)));
        });
        let kappa = third_moment_s2(h, 1.0 / fs_hz) * 6.0 * d;
        assert!((line_bias - kappa).abs() < 5.0 * 39.6, "{line_bias} vs {kappa}");
    }

    /// The weights' norm: the straight line's is 1/(Δt·√Σj²) = 39.6/s at 17 samples at 800 Hz,
    /// the corrected rate's 50.6/s (1.28×).
    #[test]
    fn the_noise_gain_is_the_weights_norm() {
        let g = noise_gain_per_s(8, 1.0 / 800.0);
        assert!((g - 50.6).abs() < 0.1, "{g}");
    }
}
