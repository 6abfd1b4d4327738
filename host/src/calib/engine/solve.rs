//! The solve: the joint weighted normal equations of the selected columns over the three axes,
//! Gauss-Newton to convergence ([`fit`]), and the fitted model's covariance.

use crate::calib::result::axes::AXES;
use crate::calib::result::error::CalError;
use nalgebra::{DMatrix, DVector};

use super::accumulate::accumulate_pairs;
use super::cells::Cells;
use super::loop_data::LoopData;
use super::model::{Model, Prior};
use super::sums::{Gram, Reach};
use crate::calib::effects::terms::{Bound, LinCol, SharedPar};

/// Smallest reciprocal condition number of the diagonally scaled joint normal matrix accepted:
/// 1e-13 leaves ~3 significant digits of f64's 16 in the worst-determined combination.
const MIN_RCOND: f64 = 1e-13;

/// Gauss-Newton iterations at most; a converging fit needs 2–4 (the effects are small angles).
const MAX_ITERATIONS: usize = 12;

/// A Gauss-Newton step smaller than this many σ in every parameter ends the iteration, once
/// applied. What remains after it is the step times the iteration's contraction rate, itself
/// small for these small-angle effects: a fit started from a candidate's linearised solution
/// then ends after one pass where a bound of 0.01 σ took two, and the answers on
/// `realistic-2speed-s101` moved by 1e-11 σ (engineering judgement, measured; the golden tests
/// hold every answer to 0.01 σ).
const CONVERGED_SIGMAS: f64 = 0.1;

/// Which accumulated columns a joint solve uses: per-axis linear ones and shared ones, as
/// indices into the accumulation's columns.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Selection {
    /// Per-axis linear columns.
    pub lin: Vec<usize>,
    /// Shared parameters.
    pub shared: Vec<usize>,
}

impl Selection {
    /// Parameters: 3 × linear + shared.
    pub fn len(&self) -> usize {
        3 * self.lin.len() + self.shared.len()
    }

    /// Whether it selects nothing.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Columns axis `a` sees, with the index of their parameter.
    fn axis_columns(&self, a: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        let nl = self.lin.len();
        self.lin
            .iter()
            .enumerate()
            .map(move |(p, &c)| (a * nl + p, c))
            .chain(self.shared.iter().enumerate().map(move |(q, &c)| (3 * nl + q, c)))
    }
}

/// A solved joint (linearised) least-squares problem: the step from the model the sums were
/// taken at.
#[derive(Debug, Clone)]
pub struct JointSolution {
    /// Step of every parameter: axis-major linear ones, then shared.
    pub delta: DVector<f64>,
    /// Covariance of the parameters (the inverse weighted normal matrix).
    pub cov: DMatrix<f64>,
    /// Weighted residual sum of squares after the step.
    pub chi2: f64,
    /// Residual sum of squares per axis after the step, counts².
    pub rss: [f64; 3],
    /// Samples per axis.
    pub n: [u64; 3],
}

/// Solves the weighted joint problem (`weights[a]` = 1/variance of axis a's noise), with the
/// `priors` of the selected parameters (those of the model the sums were taken of). χ² is the
/// data's alone.
pub fn solve_joint(g: &Gram, sel: &Selection, weights: [f64; 3], priors: &[Prior]) -> Option<JointSolution> {
    let np = sel.len();
    let (a_mat, b) = normal_equations(g, sel, weights, priors);
    let (scaled, d, rcond) = scaled_rcond(&a_mat);
    if rcond < MIN_RCOND {
        return None;
    }
    let inv_scaled = scaled.cholesky()?.inverse();
    let cov = DMatrix::from_fn(np, np, |i, j| inv_scaled[(i, j)] * d[i] * d[j]);
    let delta = &cov * &b;
    let rss = residual_after(g, sel, &delta);
    let chi2 = (0..3).map(|a| weights[a] * rss[a]).sum();
    Some(JointSolution { delta, cov, chi2, rss, n: g.n })
}

/// The weighted normal equations of a selection: XᵀWX and XᵀWe over the three axes, parameters
/// in the selection's order (axis-major linear ones, then shared), with the `priors` of the
/// selected parameters: each adds its precision to its diagonal and pulls its step towards
/// zero from its value.
pub fn normal_equations(
    g: &Gram,
    sel: &Selection,
    weights: [f64; 3],
    priors: &[Prior],
) -> (DMatrix<f64>, DVector<f64>) {
    let (mut a_mat, mut b) = data_normal_equations(g, sel, weights);
    let first_shared = 3 * sel.lin.len();
    for p in priors {
        if let Some(q) = sel.shared.iter().position(|&c| c == p.col) {
            a_mat[(first_shared + q, first_shared + q)] += p.precision;
            b[first_shared + q] -= p.precision * p.value;
        }
    }
    (a_mat, b)
}

/// [`normal_equations`] of the data alone.
fn data_normal_equations(g: &Gram, sel: &Selection, weights: [f64; 3]) -> (DMatrix<f64>, DVector<f64>) {
    let np = sel.len();
    let l = g.l;
    let mut a_mat = DMatrix::<f64>::zeros(np, np);
    let mut b = DVector::<f64>::zeros(np);
    for (a, &w) in weights.iter().enumerate() {
        let cols: Vec<(usize, usize)> = sel.axis_columns(a).collect();
        for &(pi, ci) in &cols {
            b[pi] += w * g.xte[a][ci];
            for &(pj, cj) in &cols {
                a_mat[(pi, pj)] += w * g.xtx[a][ci * l + cj];
            }
        }
    }
    (a_mat, b)
}

/// A symmetric normal matrix scaled to unit diagonal, the scale, and the reciprocal condition
/// number of the scaled matrix (0 when a diagonal entry is not positive: a column never excited).
fn scaled_rcond(a_mat: &DMatrix<f64>) -> (DMatrix<f64>, DVector<f64>, f64) {
    let np = a_mat.nrows();
    let d = DVector::from_fn(np, |i, _| {
        let v = a_mat[(i, i)];
        if v > 0.0 {
            1.0 / v.sqrt()
        } else {
            0.0
        }
    });
    let scaled = DMatrix::from_fn(np, np, |i, j| a_mat[(i, j)] * d[i] * d[j]);
    if d.iter().any(|&v| v == 0.0) {
        return (scaled, d, 0.0);
    }
    let eig = scaled.clone().symmetric_eigenvalues();
    let rcond = if eig.max() > 0.0 { (eig.min() / eig.max()).max(0.0) } else { 0.0 };
    (scaled, d, rcond)
}

/// Residual sum of squares per axis of the sums `g` after the step `delta` (of a solve with the
/// same selection, possibly on other runs: a held-out prediction).
pub fn residual_after(g: &Gram, sel: &Selection, delta: &DVector<f64>) -> [f64; 3] {
    let l = g.l;
    std::array::from_fn(|a| {
        let cols: Vec<(usize, usize)> = sel.axis_columns(a).collect();
        let mut rss = g.ete[a];
        for &(pi, ci) in &cols {
            rss -= 2.0 * delta[pi] * g.xte[a][ci];
            for &(pj, cj) in &cols {
                rss += delta[pi] * g.xtx[a][ci * l + cj] * delta[pj];
            }
        }
        rss.max(0.0)
    })
}

/// A model fitted to convergence.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The model at the solution.
    pub model: Model,
    /// Per-run sums of the model's columns at the last linearisation point.
    pub per_run: Vec<Gram>,
    /// The last solve (its `delta` is the final, negligible, step; `cov` the covariance).
    pub solution: JointSolution,
    /// Gauss-Newton passes made.
    pub passes: usize,
    /// Whether the last step was below [`CONVERGED_SIGMAS`] in every parameter (or the model is
    /// linear). When not, the passes ran out ([`MAX_ITERATIONS`]) and `model` is not the
    /// minimum: nothing may rest on it.
    pub converged: bool,
}

impl Fitted {
    /// The selection of all the model's columns.
    pub fn selection(&self) -> Selection {
        full_selection(&self.model)
    }

    /// Index of a parameter in `solution.delta`/`cov`: linear column `c` of axis `a`.
    pub fn lin_index(&self, a: usize, c: LinCol) -> Option<usize> {
        let nl = self.model.lin.len();
        self.model.lin.iter().position(|&q| q == c).map(|p| a * nl + p)
    }

    /// Index of a shared parameter in `solution.delta`/`cov`.
    pub fn shared_index(&self, p: SharedPar) -> Option<usize> {
        let nl = self.model.lin.len();
        self.model.shared.iter().position(|&q| q == p).map(|q| 3 * nl + q)
    }

    /// Why the fit is not an estimate, if a bounded parameter ended at its bound: there the
    /// data pushed it further than the model allows, so its value and σ mean nothing.
    pub fn at_bound(&self) -> Option<String> {
        for (&p, &v) in self.model.shared.iter().zip(&self.model.theta) {
            let Some(Bound { lo, hi, what, unit }) = p.bound() else {
                continue;
            };
            // A bound is reached when the value sits within 1e-9 of the range of it.
            let tol = 1e-9 * (hi - lo);
            if v <= lo + tol || v >= hi - tol {
                return Some(format!("the {what} ended at its bound ({v} {unit}, allowed {lo} to {hi})"));
            }
        }
        None
    }

    /// Why the fit is not physics, if an effect's fitted values lie beyond what it can be
    /// ([`crate::calib::effects::Behaviour::beyond_physics`]).
    pub fn beyond_physics(&self) -> Option<String> {
        let fitted = |p: SharedPar| {
            let q = self.model.shared.iter().position(|&s| s == p)?;
            Some((self.model.theta[q], self.shared_index(p).map_or(f64::NAN, |i| self.sigma(i))))
        };
        self.model.effects.iter().find_map(|e| e.beyond_physics(&fitted))
    }

    /// 1-σ of a parameter by its index.
    pub fn sigma(&self, index: usize) -> f64 {
        self.solution.cov[(index, index)].max(0.0).sqrt()
    }
}

/// All columns of a model, in `Model::cols` order.
pub fn full_selection(m: &Model) -> Selection {
    let nl = m.lin.len();
    Selection { lin: (0..nl).collect(), shared: (nl..nl + m.shared.len()).collect() }
}

/// Applies a step to a model.
pub fn apply_step(m: &mut Model, sel_lin: usize, delta: &DVector<f64>, frozen: &[bool]) {
    let nl = sel_lin;
    for a in 0..3 {
        for p in 0..nl {
            m.beta[a][p] += delta[a * nl + p];
        }
    }
    let mut q = 0;
    for (k, th) in m.theta.iter_mut().enumerate() {
        if frozen[k] {
            continue;
        }
        *th += delta[3 * nl + q];
        q += 1;
    }
    for (p, th) in m.shared.iter().zip(m.theta.iter_mut()) {
        if let Some(b) = p.bound() {
            *th = th.clamp(b.lo, b.hi);
        }
    }
    m.update_directions();
}

/// Fits a model by Gauss-Newton from its current values. Shared parameters whose Jacobian is
/// zero at the start (a warm-up time constant while its amplitude is 0) are held for the first
/// pass. After [`MAX_ITERATIONS`] passes without converging the fit ends with
/// [`Fitted::converged`] false.
pub fn fit(data: &LoopData, start: Model, weights: [f64; 3]) -> Result<Fitted, CalError> {
    fit_at_most(data, start, weights, MAX_ITERATIONS)
}

/// [`fit`] in at most `max_passes` passes.
pub(crate) fn fit_at_most(
    data: &LoopData,
    start: Model,
    weights: [f64; 3],
    max_passes: usize,
) -> Result<Fitted, CalError> {
    let mut model = start;
    let cols = model.cols();
    let nl = model.lin.len();
    let linear_only = model.shared.is_empty() && model.lin.iter().all(|c| c.is_common());
    // The linear model's one pass, from zero, sums the samples: its eᵀe is the data's own, which
    // the sums of cells would not reduce by the signal's variation within a cell, and the
    // paper's check reads its χ² from them. Every other fit starts next to its optimum, where
    // cells lose only their share of the columns' information ([`Cells`]).
    let (reach, cells) = (Reach::all(cols.len()), if linear_only { Cells::Exact } else { Cells::Span });
    for pass in 1..=max_passes.max(1) {
        let per_run = accumulate_pairs(data, &model, &cols, &reach, cells);
        let total = Gram::sum(&per_run).ok_or(CalError::NoRuns)?;
        let frozen: Vec<bool> = model.shared.iter().map(|&p| model.shapes_only_zero_columns(p)).collect();
        let sel = Selection {
            lin: (0..nl).collect(),
            shared: (0..model.shared.len()).filter(|&k| !frozen[k]).map(|k| nl + k).collect(),
        };
        let solution = solve_pass(&total, &sel, weights, &mut model).ok_or_else(|| singular(&model, &total, data))?;
        let converged = !frozen.contains(&true)
            && (0..solution.delta.len()).all(|i| {
                let sd = solution.cov[(i, i)].max(0.0).sqrt();
                solution.delta[i].abs() <= CONVERGED_SIGMAS * sd
            });
        apply_step(&mut model, nl, &solution.delta, &frozen);
        let converged = converged || (linear_only && pass == 1);
        if converged || pass >= max_passes {
            // The sums were taken before the (negligible, or exact linear) last step: the
            // solution describes the model as it now is.
            return Ok(Fitted { model, per_run, solution, passes: pass, converged });
        }
    }
    unreachable!("the loop returns at its last pass")
}

/// A fit's pass solved with the priors `model` holds. A parameter with a physical size
/// ([`SharedPar::prior`]) that the runs do not bound within it (its σ larger, or the system
/// singular without its prior) is held by its prior from then on, and the pass solved again.
fn solve_pass(total: &Gram, sel: &Selection, weights: [f64; 3], model: &mut Model) -> Option<JointSolution> {
    let solution = solve_joint(total, sel, weights, &model.priors());
    let (nl, first_shared) = (model.lin.len(), 3 * sel.lin.len());
    let unbounded: Vec<SharedPar> = model
        .shared
        .iter()
        .enumerate()
        .filter(|(_, p)| !model.prior_held.contains(p))
        .filter_map(|(k, &p)| {
            let bound = p.prior()?.bound;
            let i = first_shared + sel.shared.iter().position(|&c| c == nl + k)?;
            solution.as_ref().is_none_or(|s| s.cov[(i, i)].max(0.0).sqrt() > bound).then_some(p)
        })
        .collect();
    if unbounded.is_empty() {
        return solution;
    }
    model.prior_held.extend(unbounded);
    solve_joint(total, sel, weights, &model.priors())
}

/// The error for a joint system that cannot be solved: an axis whose own base columns (ω_s and
/// the offset) are singular, because the runs do not excite every rate direction or every one of
/// its samples is clipped; otherwise the runs do not separate the model's parameters.
fn singular(model: &Model, total: &Gram, data: &LoopData) -> CalError {
    let base: Vec<usize> = [LinCol::Omega(0), LinCol::Omega(1), LinCol::Omega(2), LinCol::One]
        .iter()
        .filter_map(|c| model.lin.iter().position(|q| q == c))
        .collect();
    for (a, &axis) in AXES.iter().enumerate() {
        if total.n[a] == 0 {
            return CalError::AxisClipped { axis, samples: data.runs.iter().map(|r| r.n_valid).sum() };
        }
    }
    for (a, &axis) in AXES.iter().enumerate() {
        let block = DMatrix::from_fn(base.len(), base.len(), |i, j| total.xtx[a][base[i] * total.l + base[j]]);
        let (_, _, rcond) = scaled_rcond(&block);
        if rcond < MIN_RCOND {
            return CalError::Singular { axis, rcond };
        }
    }
    CalError::Unidentifiable { effects: model.effects.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ") }
}
