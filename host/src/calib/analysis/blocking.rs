//! Long-run variance of an autocorrelated series by automatic blocking: M. Jonsson, "Standard
//! error estimation by an automated blocking method", Phys. Rev. E 98, 043304 (2018).
//!
//! The series is halved repeatedly by averaging neighbours; at each level the lag-1
//! autocorrelation is tested, and the first level from which all coarser levels look
//! uncorrelated (a χ² test at 99 %) gives the variance of the mean. Streaming: one push per value,
//! amortised two level updates, no storage of the series; independent segments (runs) are
//! separated by [`Blocking::end_segment`] so no block straddles two runs.
//!
//! Written here: no kept crate implements Jonsson's blocking, least of all streaming over three
//! lanes with segment ends; its χ² quantile comes from `statrs` (through [`crate::calib::analysis::stats`]).

/// Levels kept: 2^48 samples is beyond any capture.
const LEVELS: usize = 48;

/// Jonsson's test level: a level's lag-1 correlations are kept as noise below their upper 1 %
/// point.
const ALPHA: f64 = 0.01;

/// Sums of one level, for L series blocked in lockstep.
#[derive(Debug, Clone, Copy)]
struct Level<const L: usize> {
    n: u64,
    sum: [f64; L],
    sumsq: [f64; L],
    lag: [f64; L],
    lag_n: u64,
    prev: [f64; L],
    has_prev: bool,
    pending: [f64; L],
    has_pending: bool,
}

impl<const L: usize> Default for Level<L> {
    fn default() -> Self {
        Self {
            n: 0,
            sum: [0.0; L],
            sumsq: [0.0; L],
            lag: [0.0; L],
            lag_n: 0,
            prev: [0.0; L],
            has_prev: false,
            pending: [0.0; L],
            has_pending: false,
        }
    }
}

/// Streaming blocking accumulator of L series sampled together (the three gyro axes): one
/// control flow for all lanes.
#[derive(Debug, Clone)]
pub struct Blocking<const L: usize> {
    levels: [Level<L>; LEVELS],
}

impl<const L: usize> Default for Blocking<L> {
    fn default() -> Self {
        Self { levels: [Level::default(); LEVELS] }
    }
}

/// What blocking found for one series.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LongRun {
    /// Variance of one value.
    pub variance: f64,
    /// Long-run variance: n × variance of the mean.
    pub long_run_variance: f64,
    /// Blocking level chosen (block length 2^level).
    pub level: usize,
}

impl LongRun {
    /// Factor by which autocorrelation inflates the variance of a mean (1 for white noise).
    pub fn inflation(&self) -> f64 {
        self.long_run_variance / self.variance
    }
}

/// χ² quantile at 99 % (exact, `statrs` through [`crate::calib::analysis::stats`]).
fn chi2_99(dof: usize) -> f64 {
    crate::calib::analysis::stats::chi2_upper_quantile(dof, ALPHA)
}

impl<const L: usize> Blocking<L> {
    /// Adds the next values of the current segment.
    #[inline]
    pub fn push(&mut self, mut x: [f64; L]) {
        for level in self.levels.iter_mut() {
            level.n += 1;
            for ((sum, sumsq), v) in level.sum.iter_mut().zip(level.sumsq.iter_mut()).zip(&x) {
                *sum += v;
                *sumsq += v * v;
            }
            if level.has_prev {
                for (lag, (p, v)) in level.lag.iter_mut().zip(level.prev.iter().zip(&x)) {
                    *lag += p * v;
                }
                level.lag_n += 1;
            }
            level.prev = x;
            level.has_prev = true;
            if !level.has_pending {
                level.pending = x;
                level.has_pending = true;
                return;
            }
            level.has_pending = false;
            let pending = level.pending;
            x = std::array::from_fn(|i| 0.5 * (pending[i] + x[i]));
        }
    }

    /// Ends a segment: the next value starts an independent one (odd leftovers are dropped).
    pub fn end_segment(&mut self) {
        for level in self.levels.iter_mut() {
            level.has_prev = false;
            level.has_pending = false;
        }
    }

    /// Values pushed per lane.
    pub fn len(&self) -> u64 {
        self.levels[0].n
    }

    /// Whether nothing was pushed.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The long-run variance of lane `lane`, or None with fewer than two values.
    pub fn estimate(&self, lane: usize) -> Option<LongRun> {
        // Per level: n_k, σ²_k and (γ_k/σ²_k)², over the levels with at least two values.
        let stats: Vec<(f64, f64, f64)> = self
            .levels
            .iter()
            .take_while(|l| l.n >= 2)
            .map(|l| {
                let n = l.n as f64;
                let mean = l.sum[lane] / n;
                let var = (l.sumsq[lane] / n - mean * mean).max(0.0);
                let lag_n = l.lag_n as f64;
                let gamma = (l.lag[lane] - 2.0 * mean * l.sum[lane] * (lag_n / n) + lag_n * mean * mean) / n;
                let r2 = if var > 0.0 { (gamma / var).powi(2) } else { 0.0 };
                (n, var, r2)
            })
            .collect();
        let d = stats.len();
        if d == 0 {
            return None;
        }
        // M_j = Σ_{k≥j} n_k (γ_k/σ²_k)², compared with χ²_{d−j} at 99 %.
        let mut tail = vec![0.0; d + 1];
        for k in (0..d).rev() {
            tail[k] = tail[k + 1] + stats[k].0 * stats[k].2;
        }
        let level = (0..d).find(|&j| tail[j] < chi2_99(d - j)).unwrap_or(d - 1);
        let (n0, var0, _) = stats[0];
        let (nj, varj, _) = stats[level];
        Some(LongRun { variance: var0, long_run_variance: n0 * varj / nj, level })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    fn white(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n).map(|_| rng.sample::<f64, _>(StandardNormal)).collect()
    }

    #[test]
    fn white_noise_is_not_inflated() {
        let mut b = Blocking::<1>::default();
        white(1 << 17, 1).into_iter().for_each(|x| b.push([x]));
        let lr = b.estimate(0).unwrap();
        // The estimate at the chosen level has ~√(2/n_j) relative error; level ≤ 3 keeps n_j ≥ 2^14.
        assert!(lr.level <= 3, "{lr:?}");
        assert!((lr.inflation() - 1.0).abs() < 0.1, "{lr:?}");
    }

    /// AR(1) with coefficient a: long-run variance / variance = (1 + a)/(1 − a).
    #[test]
    fn ar1_inflation_matches_theory() {
        let a: f64 = 0.8;
        let mut b = Blocking::<1>::default();
        let mut x = 0.0;
        for (i, e) in white(1 << 18, 2).into_iter().enumerate() {
            x = a * x + e;
            if i == 100_000 {
                b.end_segment();
            }
            b.push([x]);
        }
        let lr = b.estimate(0).unwrap();
        let theory = (1.0 + a) / (1.0 - a);
        // At the chosen level (≥ 2^6 blocks of 2^level) the relative error is √(2/n_j) ≲ 0.1.
        assert!((lr.inflation() / theory - 1.0).abs() < 0.2, "{lr:?} vs {theory}");
    }

    #[test]
    fn chi2_quantile_matches_tables() {
        // Exact 99 % points for 1, 2, 10, 47 degrees of freedom (mpmath, 7 significant digits).
        for (dof, exact) in [(1, 6.634_897), (2, 9.210_340), (10, 23.209_251), (47, 72.443_307)] {
            assert!((chi2_99(dof) / exact - 1.0).abs() < 1e-6, "{dof}: {}", chi2_99(dof));
        }
    }
}
