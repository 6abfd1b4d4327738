//! A run's residual and speed deviation summed into θ2 bins, and the least-squares fits read
//! from those sums: each harmonic 0…32× of the residual and of the speed deviation, and the
//! ripple test's slope of the one against the other with every harmonic removed from both.
//!
//! Every sum the fits need is a sum over bins of something times sin nθ or cos nθ at the bin
//! centres, for n up to 64 (sin² nθ = (1 − cos 2nθ)/2): the real FFT of the bins gives them all
//! at once, and its inverse gives the fitted harmonic series at every bin centre. Taken one order
//! at a time the same sums cost 33 sine-cosine pairs and 7 products per bin and axis, 5 % of
//! `host calibrate` on `realistic-2speed-s101`; `realfft` does them in a few hundred thousand
//! operations per run.

use crate::calib::effects::MAX_HARMONIC_ORDER as MAX_ORDER;
use realfft::num_complex::Complex;
use realfft::RealFftPlanner;

/// θ2 bins of the harmonic fits and the speed-ripple test: 2^13 per turn. Summing the samples
/// into θ2 bins first costs one addition per sample instead of 33 sine-cosine pairs, and the
/// ripple test needs no second pass. Each harmonic becomes the step function of its values at the
/// bin centres, and the fits are exact least squares on that basis: at 32× a bin spans
/// 32·2π/8192 = 0.025 rad of phase, which costs a harmonic 2.5e-5 of its power (sinc²), far below
/// what any test at the Bonferroni level can notice.
pub(super) const ANGLE_BINS: usize = 8192;

/// sin θ, cos θ at the centre of each of the [`ANGLE_BINS`].
pub(super) fn angle_bin_centres() -> Vec<(f64, f64)> {
    (0..ANGLE_BINS).map(|b| bin_centre_rad(b).sin_cos()).collect()
}

/// The centre of bin `b`, rad.
fn bin_centre_rad(b: usize) -> f64 {
    (b as f64 + 0.5) * std::f64::consts::TAU / ANGLE_BINS as f64
}

/// Sums for a least-squares fit of a·sin + b·cos (or a mean, n = 0).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct OrderSums {
    pub(super) ss: f64,
    pub(super) cc: f64,
    pub(super) sc: f64,
    pub(super) es: f64,
    pub(super) ec: f64,
}

impl OrderSums {
    /// Least-squares (a, b) of a·sin + b·cos (for n = 0, (mean, 0) with cos = 1).
    pub(super) fn solve(&self) -> (f64, f64) {
        if self.ss == 0.0 {
            return if self.cc > 0.0 { (0.0, self.ec / self.cc) } else { (0.0, 0.0) };
        }
        let det = self.ss * self.cc - self.sc * self.sc;
        if det > 0.0 {
            ((self.es * self.cc - self.ec * self.sc) / det, (self.ec * self.ss - self.es * self.sc) / det)
        } else {
            (0.0, 0.0)
        }
    }
}

/// (a, b) of every order.
pub(super) fn harmonic_coefficients(o: &[OrderSums; MAX_ORDER + 1]) -> [(f64, f64); MAX_ORDER + 1] {
    std::array::from_fn(|n| o[n].solve())
}

/// Running sums for a slope of e against x.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct SlopeSums {
    n: f64,
    x: f64,
    xx: f64,
    e: f64,
    xe: f64,
}

impl SlopeSums {
    pub(super) fn add(&mut self, x: f64, e: f64) {
        self.n += 1.0;
        self.x += x;
        self.xx += x * x;
        self.e += e;
        self.xe += x * e;
    }

    /// (slope, σ of slope) for residual variance `var`.
    pub(super) fn slope(&self, var: f64) -> (f64, f64) {
        let sxx = self.xx - self.x * self.x / self.n;
        if sxx <= 0.0 || self.n < 3.0 {
            return (0.0, f64::INFINITY);
        }
        ((self.xe - self.x * self.e / self.n) / sxx, (var / sxx).sqrt())
    }
}

/// One run's sums per θ2 bin for the harmonic fits of the residual and of the speed deviation d
/// (in %), and for the slope of the residual against d with every harmonic 0…32× removed from
/// both (the ripple test).
#[derive(Debug, Clone)]
pub(super) struct AngleSums {
    /// Used samples per bin.
    count: Vec<f64>,
    /// Σ d per bin over the used samples.
    dev: Vec<f64>,
    /// Σ d² over the used samples.
    dev_sq: f64,
    /// Per axis: Σ e per bin over its unclipped samples.
    e: [Vec<f64>; 3],
    /// Per axis: Σ d·e over its unclipped samples.
    dev_e: [f64; 3],
    /// Per axis: its clipped samples' count and Σ d per bin, and Σ d² (taken off the shared sums).
    clip_count: [Vec<f64>; 3],
    clip_dev: [Vec<f64>; 3],
    clip_dev_sq: [f64; 3],
}

/// What [`AngleSums`] give per axis: the residual's order sums, the harmonic fit of the speed
/// deviation, and the ripple test's slope sums.
pub(super) struct AngleFits {
    pub(super) orders: [[OrderSums; MAX_ORDER + 1]; 3],
    pub(super) ripple: [SlopeSums; 3],
}

impl AngleSums {
    pub(super) fn new() -> Self {
        let zeros = || vec![0.0; ANGLE_BINS];
        Self {
            count: zeros(),
            dev: zeros(),
            dev_sq: 0.0,
            e: std::array::from_fn(|_| zeros()),
            dev_e: [0.0; 3],
            clip_count: std::array::from_fn(|_| zeros()),
            clip_dev: std::array::from_fn(|_| zeros()),
            clip_dev_sq: [0.0; 3],
        }
    }

    /// A used sample in bin `b` with speed deviation `dev_pct`.
    #[inline]
    pub(super) fn add_sample(&mut self, b: usize, dev_pct: f64) {
        self.count[b] += 1.0;
        self.dev[b] += dev_pct;
        self.dev_sq += dev_pct * dev_pct;
    }

    /// Axis `a`'s residual `e` at that sample.
    #[inline]
    pub(super) fn add_residual(&mut self, a: usize, b: usize, dev_pct: f64, e: f64) {
        self.e[a][b] += e;
        self.dev_e[a] += dev_pct * e;
    }

    /// Axis `a` clipped at that sample.
    #[inline]
    pub(super) fn add_clipped(&mut self, a: usize, b: usize, dev_pct: f64) {
        self.clip_count[a][b] += 1.0;
        self.clip_dev[a][b] += dev_pct;
        self.clip_dev_sq[a] += dev_pct * dev_pct;
    }

    /// Axis `a`'s bins: its used samples, their Σ d and Σ e (d is 0 where no sample is used).
    fn axis_bins(&self, a: usize) -> [Vec<f64>; 3] {
        let n: Vec<f64> = (0..ANGLE_BINS).map(|b| self.count[b] - self.clip_count[a][b]).collect();
        let d = (0..ANGLE_BINS).map(|b| if n[b] == 0.0 { 0.0 } else { self.dev[b] - self.clip_dev[a][b] }).collect();
        [n, d, self.e[a].clone()]
    }

    /// The fits, on the bin-centre basis, with the FFT plans of `planner`.
    pub(super) fn fits(&self, planner: &mut RealFftPlanner<f64>) -> AngleFits {
        let mut fourier = Fourier::new(planner);
        let mut orders = [[OrderSums::default(); MAX_ORDER + 1]; 3];
        let ripple = std::array::from_fn(|a| {
            let [n, d, e] = self.axis_bins(a);
            let (n_total, e_total, d_total) = (n.iter().sum::<f64>(), e.iter().sum::<f64>(), d.iter().sum::<f64>());
            let (fn_, fd, fe) = (fourier.sums(&n), fourier.sums(&d), fourier.sums(&e));
            // Order 0 from plain sums: its sin is exactly 0, and the solve tells it by ss == 0.
            let mut dev_orders = [OrderSums { cc: n_total, ec: d_total, ..OrderSums::default() }; MAX_ORDER + 1];
            orders[a][0] = OrderSums { cc: n_total, ec: e_total, ..OrderSums::default() };
            for o in 1..=MAX_ORDER {
                let (c2, s2) = fn_[2 * o];
                let (ss, cc, sc) = ((n_total - c2) / 2.0, (n_total + c2) / 2.0, s2 / 2.0);
                orders[a][o] = OrderSums { ss, cc, sc, es: fe[o].1, ec: fe[o].0 };
                dev_orders[o] = OrderSums { ss, cc, sc, es: fd[o].1, ec: fd[o].0 };
            }
            let fit_d = fourier.series(&harmonic_coefficients(&dev_orders));
            let fit_e = fourier.series(&harmonic_coefficients(&orders[a]));
            // Σ (d − D(θ))·(e − E(θ)) and its companions from the bin sums: D and E, the harmonic
            // fits, are constant within a bin.
            let mut s = SlopeSums { xx: self.dev_sq - self.clip_dev_sq[a], xe: self.dev_e[a], ..SlopeSums::default() };
            for b in (0..ANGLE_BINS).filter(|&b| n[b] != 0.0) {
                let (n, d, e, fit_d, fit_e) = (n[b], d[b], e[b], fit_d[b], fit_e[b]);
                s.n += n;
                s.x += d - n * fit_d;
                s.xx += n * fit_d * fit_d - 2.0 * d * fit_d;
                s.e += e - n * fit_e;
                s.xe += n * fit_d * fit_e - d * fit_e - e * fit_d;
            }
            s
        });
        AngleFits { orders, ripple }
    }
}

/// The forward and inverse real FFTs of [`ANGLE_BINS`] points, turned to the bin centres.
struct Fourier {
    forward: std::sync::Arc<dyn realfft::RealToComplex<f64>>,
    inverse: std::sync::Arc<dyn realfft::ComplexToReal<f64>>,
    real: Vec<f64>,
    spectrum: Vec<Complex<f64>>,
    /// e^{ikΔ/2}, k = 0…2·[`MAX_ORDER`]: the half bin from bin b's start, b·Δ, to its centre.
    half_bin: Vec<Complex<f64>>,
}

impl Fourier {
    fn new(planner: &mut RealFftPlanner<f64>) -> Self {
        let forward = planner.plan_fft_forward(ANGLE_BINS);
        let inverse = planner.plan_fft_inverse(ANGLE_BINS);
        let (real, spectrum) = (forward.make_input_vec(), forward.make_output_vec());
        let half_bin = (0..=2 * MAX_ORDER).map(|k| Complex::from_polar(1.0, k as f64 * bin_centre_rad(0))).collect();
        Self { forward, inverse, real, spectrum, half_bin }
    }

    /// (Σ x_b cos kθ_b, Σ x_b sin kθ_b) over the bins, θ_b their centres, k = 0…2·[`MAX_ORDER`]:
    /// Σ x_b e^{−ikθ_b} = e^{−ikΔ/2}·X_k, X the FFT of the bins.
    fn sums(&mut self, x: &[f64]) -> Vec<(f64, f64)> {
        self.real.copy_from_slice(x);
        self.forward.process(&mut self.real, &mut self.spectrum).expect("buffers made by the plan have its lengths");
        (0..=2 * MAX_ORDER)
            .map(|k| {
                let z = self.half_bin[k].conj() * self.spectrum[k];
                (z.re, -z.im)
            })
            .collect()
    }

    /// Σ_n a_n sin nθ_b + b_n cos nθ_b at every bin centre, from `coefs` (a_n, b_n): the inverse
    /// FFT (unnormalised, of the Hermitian spectrum) of Y_0 = b_0, Y_n = (b_n − i·a_n)·e^{inΔ/2}/2.
    fn series(&mut self, coefs: &[(f64, f64); MAX_ORDER + 1]) -> Vec<f64> {
        self.spectrum.fill(Complex::new(0.0, 0.0));
        self.spectrum[0] = Complex::new(coefs[0].1, 0.0);
        for (n, &(a, b)) in coefs.iter().enumerate().skip(1) {
            self.spectrum[n] = Complex::new(b, -a) * self.half_bin[n] * 0.5;
        }
        self.inverse.process(&mut self.spectrum, &mut self.real).expect("a real spectrum of the plan's length");
        self.real.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Sums a run's samples, some clipped, into bins the way the walk does.
    fn filled(seed: u64) -> AngleSums {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let mut s = AngleSums::new();
        for i in 0..200_000 {
            // Bins of half a turn only for the last quarter: some bins stay empty.
            let b = if i % 4 == 3 { rng.random_range(0..ANGLE_BINS / 2) } else { rng.random_range(0..ANGLE_BINS) };
            let theta = bin_centre_rad(b);
            let dev_pct = 0.3 * (3.0 * theta).sin() + rng.random_range(-0.1..0.1);
            s.add_sample(b, dev_pct);
            for a in 0..3 {
                if a == 2 && i % 97 == 0 {
                    s.add_clipped(a, b, dev_pct);
                    continue;
                }
                let e = 2.0 * (5.0 * theta + a as f64).cos() - 0.4 * dev_pct + 0.5 + rng.random_range(-1.0..1.0);
                s.add_residual(a, b, dev_pct, e);
            }
        }
        s
    }

    /// The order sums and the ripple's slope sums from the FFT are those of the plain sums over
    /// bins, each harmonic taken at each bin centre (the method it replaced, kept here as the
    /// reference), to 1e-9 of their scale.
    #[test]
    fn fourier_sums_match_the_plain_sums_over_bins() {
        let sums = filled(3);
        let fits = sums.fits(&mut RealFftPlanner::new());
        for a in 0..3 {
            let [n, d, e] = sums.axis_bins(a);
            let used: Vec<usize> = (0..ANGLE_BINS).filter(|&b| n[b] != 0.0).collect();
            let harmonic = |o: usize, b: usize| (o as f64 * bin_centre_rad(b)).sin_cos();
            let plain = |o: usize, x: &[f64]| -> OrderSums {
                let mut s = OrderSums::default();
                for &b in &used {
                    let (sn, cn) = harmonic(o, b);
                    (s.ss, s.cc, s.sc) = (s.ss + n[b] * sn * sn, s.cc + n[b] * cn * cn, s.sc + n[b] * sn * cn);
                    (s.es, s.ec) = (s.es + x[b] * sn, s.ec + x[b] * cn);
                }
                s
            };
            let scale = n.iter().sum::<f64>();
            let close = |got: f64, want: f64, what: &str| {
                assert!((got - want).abs() <= 1e-9 * scale, "axis {a} {what}: {got} against {want}");
            };
            for (o, got) in fits.orders[a].iter().enumerate() {
                let want = plain(o, &e);
                for (g, w, what) in [(got.ss, want.ss, "ss"), (got.cc, want.cc, "cc"), (got.sc, want.sc, "sc")] {
                    close(g, w, &format!("order {o} {what}"));
                }
                close(got.es, want.es, &format!("order {o} es"));
                close(got.ec, want.ec, &format!("order {o} ec"));
            }
            let dev_orders: [OrderSums; MAX_ORDER + 1] = std::array::from_fn(|o| plain(o, &d));
            assert_eq!(fits.orders[a][0].ss, 0.0, "order 0 has no sine");
            let (cd, ce) = (harmonic_coefficients(&dev_orders), harmonic_coefficients(&fits.orders[a]));
            let at = |c: &[(f64, f64); MAX_ORDER + 1], b: usize| -> f64 {
                (0..=MAX_ORDER).map(|o| c[o].0 * harmonic(o, b).0 + c[o].1 * harmonic(o, b).1).sum()
            };
            let mut want =
                SlopeSums { xx: sums.dev_sq - sums.clip_dev_sq[a], xe: sums.dev_e[a], ..SlopeSums::default() };
            for &b in &used {
                let (fit_d, fit_e) = (at(&cd, b), at(&ce, b));
                want.n += n[b];
                want.x += d[b] - n[b] * fit_d;
                want.xx += n[b] * fit_d * fit_d - 2.0 * d[b] * fit_d;
                want.e += e[b] - n[b] * fit_e;
                want.xe += n[b] * fit_d * fit_e - d[b] * fit_e - e[b] * fit_d;
            }
            let got = fits.ripple[a];
            for (g, w, what) in [
                (got.n, want.n, "n"),
                (got.x, want.x, "x"),
                (got.xx, want.xx, "xx"),
                (got.e, want.e, "e"),
                (got.xe, want.xe, "xe"),
            ] {
                close(g, w, &format!("ripple {what}"));
            }
            // The fit finds what was put in: 2 cos(5θ + a) = −2 sin a·sin 5θ + 2 cos a·cos 5θ on the
            // residual, 0.3 sin 3θ on d. Each order is fitted alone, and the extra samples on half
            // the turn leave the orders a few % short of orthogonal: the other orders leak in.
            let want5 = (-2.0 * (a as f64).sin(), 2.0 * (a as f64).cos());
            let off5 = (ce[5].0 - want5.0).hypot(ce[5].1 - want5.1);
            assert!(off5 < 0.06, "axis {a}: 5× {:?} against {want5:?}", ce[5]);
            assert!((cd[3].0 - 0.3).abs() < 0.01 && cd[3].1.abs() < 0.01, "3× of d: {:?}", cd[3]);
        }
    }
}
