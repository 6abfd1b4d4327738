//! Joint linear least squares of all samples of all runs: one pass accumulates XᵀX, Xᵀy and yᵀy
//! per run (the three axes share the regressors), then each axis solves a P×P system.
//!
//! Clipped samples are left out per axis: their contribution to XᵀX is gathered separately and
//! subtracted, so the common accumulation stays branch-free for the usual, unclipped sample.

use super::error::CalError;
use super::kinematics::{KinSample, Kinematics, RunKinematics};
use super::model::Columns;
use nalgebra::SMatrix;

/// Samples summed into a local accumulator before it is added to the run total: keeps rounding
/// error at O(√n) ulp-scale instead of O(n) in long runs.
const CHUNK: usize = 1024;

/// Smallest reciprocal condition number of the diagonally scaled normal matrix accepted as
/// regular: 1e-12 leaves ~4 significant digits of the 16 in f64.
const MIN_RCOND: f64 = 1e-12;

/// Axis names in report order.
pub const AXES: [char; 3] = ['x', 'y', 'z'];

/// A raw count at either rail: the true rate may lie beyond it (L3G4200D outputs saturate at
/// the i16 limits).
#[inline]
pub fn is_clipped(count: i16) -> bool {
    count == i16::MAX || count == i16::MIN
}

/// Sums of a linear least-squares problem with P shared columns and three outputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalEq<const P: usize> {
    /// XᵀX over all samples (full symmetric matrix).
    pub xtx: [[f64; P]; P],
    /// Xᵀy over the unclipped samples of each axis: `xty[axis][column]`.
    pub xty: [[f64; P]; 3],
    /// yᵀy over the unclipped samples of each axis.
    pub yty: [f64; 3],
    /// Samples.
    pub n: u64,
    /// XᵀX over the clipped samples of each axis.
    pub xtx_clipped: [[[f64; P]; P]; 3],
    /// Clipped samples per axis.
    pub n_clipped: [u64; 3],
}

impl<const P: usize> Default for NormalEq<P> {
    fn default() -> Self {
        Self {
            xtx: [[0.0; P]; P],
            xty: [[0.0; P]; 3],
            yty: [0.0; 3],
            n: 0,
            xtx_clipped: [[[0.0; P]; P]; 3],
            n_clipped: [0; 3],
        }
    }
}

impl<const P: usize> NormalEq<P> {
    /// Adds one sample.
    #[inline]
    pub fn add(&mut self, x: &[f64; P], counts: [i16; 3]) {
        for i in 0..P {
            for j in i..P {
                self.xtx[i][j] += x[i] * x[j];
            }
        }
        self.n += 1;
        for (axis, &c) in counts.iter().enumerate() {
            if is_clipped(c) {
                self.n_clipped[axis] += 1;
                for i in 0..P {
                    for j in i..P {
                        self.xtx_clipped[axis][i][j] += x[i] * x[j];
                    }
                }
            } else {
                let y = f64::from(c);
                for (acc, xi) in self.xty[axis].iter_mut().zip(x) {
                    *acc += xi * y;
                }
                self.yty[axis] += y * y;
            }
        }
    }

    /// Adds another set of sums.
    pub fn merge(&mut self, o: &Self) {
        for i in 0..P {
            for j in 0..P {
                self.xtx[i][j] += o.xtx[i][j];
                for a in 0..3 {
                    self.xtx_clipped[a][i][j] += o.xtx_clipped[a][i][j];
                }
            }
        }
        for a in 0..3 {
            for i in 0..P {
                self.xty[a][i] += o.xty[a][i];
            }
            self.yty[a] += o.yty[a];
            self.n_clipped[a] += o.n_clipped[a];
        }
        self.n += o.n;
    }

    /// Mirrors the accumulated upper triangles (call once, after the last `add`).
    fn symmetrise(&mut self) {
        for i in 0..P {
            for j in 0..i {
                self.xtx[i][j] = self.xtx[j][i];
                for a in 0..3 {
                    self.xtx_clipped[a][i][j] = self.xtx_clipped[a][j][i];
                }
            }
        }
    }

    /// XᵀX over the samples where `axis` is not clipped.
    pub fn xtx_axis(&self, axis: usize) -> SMatrix<f64, P, P> {
        SMatrix::from_fn(|i, j| self.xtx[i][j] - self.xtx_clipped[axis][i][j])
    }

    /// XᵀX over the samples where neither axis is clipped (samples clipped on both are rare
    /// enough to subtract twice: the matrix only scales a cross-covariance).
    pub fn xtx_pair(&self, a: usize, b: usize) -> SMatrix<f64, P, P> {
        if a == b {
            return self.xtx_axis(a);
        }
        SMatrix::from_fn(|i, j| self.xtx[i][j] - self.xtx_clipped[a][i][j] - self.xtx_clipped[b][i][j])
    }

    /// Xᵀy of one axis.
    pub fn xty_axis(&self, axis: usize) -> SMatrix<f64, P, 1> {
        SMatrix::from_fn(|i, _| self.xty[axis][i])
    }

    /// Unclipped samples of one axis.
    pub fn n_axis(&self, axis: usize) -> u64 {
        self.n - self.n_clipped[axis]
    }
}

/// Accumulates one run's sums.
pub fn accumulate_run<const P: usize, M: Columns<P>>(model: &M, run: &RunKinematics) -> NormalEq<P> {
    let mut total = NormalEq::default();
    for chunk in run.samples.chunks(CHUNK) {
        let mut local = NormalEq::default();
        for s in chunk {
            local.add(&model.row(run, &s), s.rate_counts);
        }
        total.merge(&local);
    }
    total.symmetrise();
    total
}

/// One axis solved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisSolution<const P: usize> {
    /// Coefficients, one per column.
    pub beta: SMatrix<f64, P, 1>,
    /// (XᵀX)⁻¹ over the axis's unclipped samples.
    pub xtx_inv: SMatrix<f64, P, P>,
    /// Residual sum of squares, counts².
    pub rss: f64,
    /// Samples used.
    pub n: u64,
}

impl<const P: usize> AxisSolution<P> {
    /// Residual variance per sample with the fitted coefficients' degrees of freedom removed.
    pub fn sigma2(&self) -> f64 {
        self.rss / (self.n as f64 - P as f64)
    }
}

/// Solves one axis; `Singular` if the scaled normal matrix is (nearly) rank-deficient.
pub fn solve_axis<const P: usize>(eq: &NormalEq<P>, axis: usize) -> Result<AxisSolution<P>, CalError> {
    let a = eq.xtx_axis(axis);
    let b = eq.xty_axis(axis);
    let d = SMatrix::<f64, P, 1>::from_fn(|i, _| {
        let v = a[(i, i)];
        if v > 0.0 {
            1.0 / v.sqrt()
        } else {
            0.0
        }
    });
    let scaled = SMatrix::<f64, P, P>::from_fn(|i, j| a[(i, j)] * d[i] * d[j]);
    let eig = nalgebra::DMatrix::from_fn(P, P, |i, j| scaled[(i, j)]).symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    let rcond: f64 = if hi > 0.0 { lo / hi } else { 0.0 };
    let singular = || CalError::Singular { axis: AXES[axis], rcond: rcond.max(0.0) };
    let regular = rcond > MIN_RCOND;
    if !regular || d.iter().any(|&v| v == 0.0) {
        return Err(singular());
    }
    let chol = scaled.cholesky().ok_or_else(singular)?;
    let inv_scaled = chol.inverse();
    let xtx_inv = SMatrix::<f64, P, P>::from_fn(|i, j| inv_scaled[(i, j)] * d[i] * d[j]);
    let beta = xtx_inv * b;
    // yᵀy − 2βᵀXᵀy + βᵀXᵀXβ: the residual's own size sets the error, ~1e-11 relative here.
    let rss = (eq.yty[axis] - 2.0 * beta.dot(&b) + (beta.transpose() * a * beta)[(0, 0)]).max(0.0);
    Ok(AxisSolution { beta, xtx_inv, rss, n: eq.n_axis(axis) })
}

/// A model fitted to all runs.
#[derive(Debug, Clone)]
pub struct Fit<const P: usize> {
    /// Per-run sums, in run order.
    pub per_run: Vec<NormalEq<P>>,
    /// Sums over all runs.
    pub total: NormalEq<P>,
    /// Per-axis solutions.
    pub axes: [AxisSolution<P>; 3],
}

impl<const P: usize> Fit<P> {
    /// Residual sum of squares of one axis over one run's samples, from that run's sums.
    pub fn run_rss(&self, run_index: usize, axis: usize) -> f64 {
        let eq = &self.per_run[run_index];
        let a = eq.xtx_axis(axis);
        let b = eq.xty_axis(axis);
        let beta = &self.axes[axis].beta;
        (eq.yty[axis] - 2.0 * beta.dot(&b) + (beta.transpose() * a * beta)[(0, 0)]).max(0.0)
    }

    /// The fitted output of one axis for a row of columns.
    #[inline]
    pub fn predict(&self, axis: usize, x: &[f64; P]) -> f64 {
        let beta = &self.axes[axis].beta;
        (0..P).map(|i| beta[i] * x[i]).sum()
    }
}

/// Fits a model to every sample of every run at once.
pub fn fit<const P: usize, M: Columns<P>>(model: &M, kin: &Kinematics) -> Result<Fit<P>, CalError> {
    let per_run: Vec<NormalEq<P>> = kin.runs.iter().map(|r| accumulate_run(model, r)).collect();
    let mut total = NormalEq::default();
    for r in &per_run {
        total.merge(r);
    }
    let axes = [solve_axis(&total, 0)?, solve_axis(&total, 1)?, solve_axis(&total, 2)?];
    Ok(Fit { per_run, total, axes })
}

/// Residuals of one run, per sample and axis, counts (NaN where the axis clipped): for
/// diagnostics. Writes into `out`, reusing its allocation.
pub fn run_residuals<const P: usize, M: Columns<P>>(
    model: &M,
    fit: &Fit<P>,
    run: &RunKinematics,
    out: &mut Vec<[f64; 3]>,
) {
    out.clear();
    out.extend(run.samples.iter().map(|s: KinSample| {
        let x = model.row(run, &s);
        let mut e = [f64::NAN; 3];
        for (axis, (ea, &c)) in e.iter_mut().zip(&s.rate_counts).enumerate() {
            if !is_clipped(c) {
                *ea = f64::from(c) - fit.predict(axis, &x);
            }
        }
        e
    }));
}
