//! What the runs cannot separate goes into σ: the consider covariance of the calibration.
//!
//! A catalogued effect the final model lacks biases M and the offsets by S·c, where c are its
//! parameters and S = P·B the sensitivity of the estimate to them: P the model's covariance
//! (the inverse weighted normal matrix) and B the cross-products of the model's columns with the
//! effect's (Tapley, Schutz & Born, *Statistical Orbit Determination*, §6.3, "consider
//! covariance"). What the data know of c beyond the model is the partial information
//! I = C − Bᵀ·P·B (C the effect's own block).
//!
//! Each effect says how large it may plausibly be (one σ, with a source:
//! [`crate::calib::effects::Behaviour::consider`]). In the prior's whitened coordinates
//! (I_w = D·I·D, D the σs), a direction whose information λ reaches [`SEPARATED_SNR2`] would show
//! an effect of plausible size at ≥ 5σ: the runs separate it, and the loop's tests, which did not
//! add it, speak for it. Every other direction is not separated: its posterior variance
//! σ²/(1 + λ) and the square of its posterior mean (what the residual says of it) enter the
//! covariance of M and the offsets through S. The effect at its bound would move the estimate by
//! that much and no test could have seen it.
//!
//! The cross-products come from one pass over the data with the model's columns and every
//! considered effect's: the same sums a candidate's score is read from.

use crate::calib::analysis::stats::chi2_upper_quantile;
use crate::calib::effects::terms::{Col, ConsiderBound, ConsiderCtx, LinCol, Own, Reported};
use crate::calib::effects::Effect;
use crate::calib::engine::{
    accumulate_pairs, normal_equations, Cells, CrossSums, Fitted, Gram, LoopData, Reach, Selection,
};
use crate::calib::result::consider_term::{added_sigmas, ConsiderTerm, ConsideredParam};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Information, in units of the prior (an effect of one σ along the direction gives this Δχ²),
/// from which the runs are taken to separate a direction of an effect: 25 is a 5σ signal for an
/// effect of plausible size, past the loop's Bonferroni threshold for one parameter
/// (χ²₁ at 1e-3/40: 16.4).
pub const SEPARATED_SNR2: f64 = 25.0;

/// One-sided normal quantile of the power the loop's test must have against an effect of
/// plausible size for its silence to speak for a direction: 95 %.
const POWER_Z: f64 = 1.645;

/// The information (whitened, as [`SEPARATED_SNR2`]) from which a test of `dof` degrees of
/// freedom at χ² threshold `threshold` sees an effect of plausible size along one direction with
/// 95 % power: the least λ with k + λ − z·√(2(k + 2λ)) ≥ T, the normal approximation to the
/// non-central χ²(k, λ) (mean k + λ, variance 2(k + 2λ); Johnson, Kotz & Balakrishnan,
/// *Continuous Univariate Distributions* vol. 2, ch. 29). With m = k + λ − T ≥ 0 the equality
/// is m² − 4z²·m − 2z²·(2T − k) = 0, whose larger root gives λ. Never below [`SEPARATED_SNR2`].
/// A nine-parameter effect tested at χ² 35 needs λ ≈ 50, twice what one 5σ signal is: below it
/// an effect of plausible size may pass the test unseen and still move M.
fn seen_by_test(dof: usize, threshold: f64) -> f64 {
    if !threshold.is_finite() {
        return f64::INFINITY;
    }
    let (k, z2) = (dof as f64, POWER_Z * POWER_Z);
    let m = 2.0 * z2 + (4.0 * z2 * z2 + 2.0 * z2 * (2.0 * threshold - k)).max(0.0).sqrt();
    (m + threshold - k).max(SEPARATED_SNR2)
}

/// Smallest added σ of a sensitivity (ppm) or a direction (°) that a term is reported for; below
/// it the runs separate the effect in all that matters.
const REPORTED_PPM: f64 = 0.05;
const REPORTED_DEG: f64 = 1e-6;

/// The consider covariance: what it adds to the 12 base parameters' covariance, and its terms.
#[derive(Debug, Clone, PartialEq)]
pub struct Consideration {
    /// Added covariance of the base parameters (`CalReport` order).
    pub cov: DMatrix<f64>,
    /// The terms, largest first.
    pub terms: Vec<ConsiderTerm>,
}

impl Consideration {
    /// Nothing considered.
    pub fn none() -> Self {
        Self { cov: DMatrix::zeros(12, 12), terms: Vec::new() }
    }
}

/// A user's own size for an effect's parameters, in their reported units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ConsiderOverride {
    /// The effect.
    pub effect: Effect,
    /// One σ of each of its parameters, reported unit (0 leaves it out).
    pub sigma: f64,
}

/// Effects whose size the user gave, at most this many (the catalogue's physical effects).
pub const MAX_OVERRIDES: usize = 8;

/// The sizes given on the command line (`--consider KEY=SIGMA`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ConsiderOverrides(pub [Option<ConsiderOverride>; MAX_OVERRIDES]);

impl ConsiderOverrides {
    /// Parses `KEY=SIGMA`, KEY an effect's key (`g_sensitivity`, `earth_rotation`, …).
    pub fn add(&mut self, spec: &str) -> Result<(), String> {
        let (key, value) = spec.split_once('=').ok_or_else(|| format!("'{spec}' is not KEY=SIGMA"))?;
        let effect = Effect::catalogue()
            .into_iter()
            .find(|e| e.key() == key)
            .ok_or_else(|| format!("no effect '{key}' (keys: {})", considered_keys().join(", ")))?;
        let sigma: f64 = value.parse().map_err(|_| format!("'{value}' is not a number"))?;
        if !(sigma.is_finite() && sigma >= 0.0) {
            return Err(format!("the size of {key} must be a finite number ≥ 0, not {value}"));
        }
        let slot = self.0.iter_mut().find(|s| s.is_none_or(|o| o.effect == effect)).ok_or("too many --consider")?;
        *slot = Some(ConsiderOverride { effect, sigma });
        Ok(())
    }

    fn of(&self, e: Effect) -> Option<f64> {
        self.0.iter().flatten().find(|o| o.effect == e).map(|o| o.sigma)
    }
}

/// Keys of the effects that may be considered (those with a plausible size in some model).
pub fn considered_keys() -> Vec<String> {
    let cx = ConsiderCtx { current: &[], cutoff_hz: 30.0, full_scale_dps: 500.0, delay_s: None, temp_moved: true };
    Effect::catalogue()
        .into_iter()
        .filter(|e| {
            (0..3).any(|k| e.consider(Own::Lin(k), &cx).is_some() || e.consider(Own::Shared(k as u8), &cx).is_some())
        })
        .map(|e| e.key())
        .collect()
}

/// An effect's columns that have a plausible size, with that size in the fit's units.
struct Candidate {
    effect: Effect,
    cols: Vec<Col>,
    /// One σ per column, fitted unit (a linear column's: counts per unit of the column, from
    /// each axis's sensitivity).
    sigma: Vec<[f64; 3]>,
    params: Vec<ConsideredParam>,
    source: &'static str,
    /// Whether the loop tried it (`selection::tried`): a test then rules out what the runs
    /// see of it, and only what they do not see is considered.
    tried: bool,
    /// For the levels of a walk ([`Effect::considered_as_walk`]): each column's predecessor
    /// in its stretch (None for a stretch's first considered level). Empty otherwise.
    walk: Vec<Option<usize>>,
    /// How the notes say that its size is the data's bound ([`Effect::size_read_from_data`]).
    from_data: Option<&'static str>,
    /// Its shared parameters that also scale M by −f·p² ([`Effect::scale_per_square`]): each
    /// one's place among [`prior_params`]' and f.
    squares: Vec<(usize, f64)>,
}

fn candidates(
    data: &LoopData,
    f: &Fitted,
    cx: &ConsiderCtx,
    k: [f64; 3],
    overrides: &ConsiderOverrides,
) -> Vec<Candidate> {
    let mut out = Vec::new();
    for effect in Effect::catalogue().into_iter().filter(|e| !f.model.effects.contains(e)) {
        let (lin, shared) = effect.params(&data.layout);
        let tried = crate::calib::analysis::selection::tried(data, &f.model.effects, effect);
        let walk_step = effect.considered_as_walk();
        let mut c = Candidate {
            effect,
            cols: Vec::new(),
            sigma: Vec::new(),
            params: Vec::new(),
            source: "",
            tried,
            walk: Vec::new(),
            from_data: effect.size_read_from_data(),
            squares: Vec::new(),
        };
        let mut walk = Vec::new();
        // Adds a column with its bound; whether it was (it has a size and a reported unit).
        let mut add = |col: Col, own: Own, bound: Option<ConsiderBound>| -> bool {
            let Some(mut b) = bound else { return false };
            let r = match col {
                Col::Lin(LinCol::DriftKnot { .. }) => walk_step.clone().map(|step| Reported::new(step, 1.0, "°/s")),
                Col::Lin(l) => l.reported(cx.full_scale_dps),
                Col::Shared(p) => Some(p.reported()),
            };
            let Some(r) = r else { return false };
            if let Some(s) = overrides.of(effect) {
                b = ConsiderBound { sigma: s, source: "given with --consider" };
            }
            if b.sigma <= 0.0 {
                return false;
            }
            let fitted = b.sigma / r.scale;
            c.sigma.push(match own {
                Own::Lin(_) => k.map(|ka| fitted * ka),
                Own::Shared(_) => [fitted; 3],
            });
            c.params.push(ConsideredParam { name: r.name, sigma: b.sigma, unit: r.unit.into() });
            c.cols.push(col);
            c.source = b.source;
            true
        };
        let mut last_level: Option<(u16, usize)> = None;
        for l in lin {
            match l {
                LinCol::Of(_, kk) => {
                    add(Col::Lin(l), Own::Lin(kk), effect.consider(Own::Lin(kk), cx));
                }
                // A stretch's first level is its offset's: the walk starts from it.
                LinCol::DriftKnot { stretch, knot, .. } => {
                    let level = knot > 0 && add(Col::Lin(l), Own::Lin(0), effect.consider(Own::Lin(0), cx));
                    if level {
                        walk.push(last_level.filter(|(s, _)| *s == stretch).map(|(_, i)| i));
                        last_level = Some((stretch, walk.len() - 1));
                    }
                }
                _ => {}
            }
        }
        for p in shared {
            add(Col::Shared(p), Own::Shared(p.k), effect.consider(Own::Shared(p.k), cx));
        }
        debug_assert!(walk.is_empty() || walk.len() == c.cols.len(), "a walk is all levels");
        c.walk = walk;
        c.squares = squares_of(effect, &c.cols);
        if !c.cols.is_empty() {
            out.push(c);
        }
    }
    out
}

/// `effect`'s shared parameters among `cols` that scale M by −f·p² beyond their columns: each
/// one's place among its parameters as [`prior_params`] lists them (a linear column is three,
/// one per axis; a shared one is one), with f.
fn squares_of(effect: Effect, cols: &[Col]) -> Vec<(usize, f64)> {
    let mut at = 0;
    let mut out = Vec::new();
    for col in cols {
        match col {
            Col::Lin(_) => at += 3,
            Col::Shared(p) => {
                if let Some(f) = effect.scale_per_square(Own::Shared(p.k)) {
                    out.push((at, f));
                }
                at += 1;
            }
        }
    }
    out
}

/// The estimate's sensitivity `s12` (12 × the effect's parameters), then a row for each
/// parameter whose square scales M (`squares`): its own posterior comes out of the same factor.
fn with_squares(s12: &DMatrix<f64>, squares: &[(usize, f64)]) -> DMatrix<f64> {
    let mut rows = s12.clone().resize_vertically(12 + squares.len(), 0.0);
    for (r, &(j, _)) in squares.iter().enumerate() {
        rows[(12 + r, j)] = 1.0;
    }
    rows
}

/// The second moment of the estimate's bias from [`posterior`]'s factor `along` of the rows
/// [`with_squares`] gave: F·Fᵀ of the 12 base rows, plus each squared parameter's scale
/// ([`second_order_scale`]) from its own row's mean (the last column) and variance (the rest).
fn second_moment(
    along: &DMatrix<f64>,
    squares: &[(usize, f64)],
    s12: &DMatrix<f64>,
    params: &[f64; 12],
) -> DMatrix<f64> {
    let base_rows = along.rows(0, 12);
    let mut added = base_rows * base_rows.transpose();
    // A common scale moves M's elements by −M per unit and leaves the offsets.
    let scale_move = DVector::from_fn(12, |i, _| if i % 4 == 3 { 0.0 } else { -params[i] });
    for (r, &(j, f)) in squares.iter().enumerate() {
        let own = along.row(12 + r);
        let last = own.len() - 1;
        let var = (0..last).map(|q| own[q] * own[q]).sum::<f64>();
        added += second_order_scale(f, own[last], var, &s12.column(j).into_owned(), &scale_move);
    }
    added
}

/// What a parameter p that scales M by −f·p² (`f`) adds to the second moment of the estimate's
/// bias beyond its first-order part: its posterior is N(`mean`, `var`) (p in its fitted unit),
/// `s` the estimate's sensitivity to p (the first-order move per unit), `d` the estimate's move
/// per unit of scale (−M's elements, 0 for the offsets). With b = s·p − f·p²·m (m = −d), the
/// second moment E[b·bᵀ] is s·sᵀ·E[p²] (the first-order part, carried already) plus
/// f²·E[p⁴]·d·dᵀ and f·E[p³]·(s·dᵀ + d·sᵀ), Gaussian moments E[p³] = μ³ + 3μv and
/// E[p⁴] = μ⁴ + 6μ²v + 3v². The bias is one-sided (cos ε ≤ 1), carried here as its root mean
/// square: an unseen 0.3° tilt, √3·ε²/2 = 24 ppm in every sensitivity.
fn second_order_scale(f: f64, mean: f64, var: f64, s: &DVector<f64>, d: &DVector<f64>) -> DMatrix<f64> {
    let (m2, v) = (mean * mean, var.max(0.0));
    let p3 = mean * (m2 + 3.0 * v);
    let p4 = m2 * m2 + 6.0 * m2 * v + 3.0 * v * v;
    let sd = s * d.transpose();
    d * d.transpose() * (f * f * p4) + (&sd + sd.transpose()) * (f * p3)
}

/// Positions of parameters in the joint solve of a selection of `nl` linear and some shared
/// columns: linear column p of axis a, or shared q.
fn lin_param(nl: usize, a: usize, p: usize) -> usize {
    a * nl + p
}

/// Where each candidate's columns sit in a selection: (is linear, position in `lin` or `shared`).
type Places = Vec<Vec<(bool, usize)>>;

/// The model's columns followed by every candidate's, the selection of all of them, and where
/// each candidate's columns sit in it.
fn with_candidates(f: &Fitted, cands: &[Candidate]) -> (Vec<Col>, Selection, Places) {
    let (nl, ns) = (f.model.lin.len(), f.model.shared.len());
    let mut cols = f.model.cols();
    let mut sel = Selection { lin: (0..nl).collect(), shared: (nl..nl + ns).collect() };
    let mut places = Vec::with_capacity(cands.len());
    for c in cands {
        let mut pl = Vec::new();
        for &col in &c.cols {
            let j = cols.len();
            cols.push(col);
            match col {
                Col::Lin(_) => {
                    pl.push((true, sel.lin.len()));
                    sel.lin.push(j);
                }
                Col::Shared(_) => {
                    pl.push((false, sel.shared.len()));
                    sel.shared.push(j);
                }
            }
        }
        places.push(pl);
    }
    (cols, sel, places)
}

/// The columns [`consider`] sums against `f`'s, one group per effect: what the loop's last
/// candidates' pass gathers beside its own when the model it scores will be the final one.
pub fn columns(data: &LoopData, f: &Fitted, cx: &ConsiderCtx, overrides: &ConsiderOverrides) -> Vec<Vec<Col>> {
    // The sensitivities scale only the σs, not which columns are considered.
    candidates(data, f, cx, [1.0; 3], overrides).into_iter().map(|c| c.cols).collect()
}

/// The consider covariance of `f` (fitted with `weights`) for every catalogued effect it lacks.
/// `base` are the 12 base parameters' indices in `f`'s covariance; `k` the sensitivities.
/// `alpha` is the loop's family-wise level, which the test of an effect it tried uses. The
/// cross-products are read from `sums` when those are of `f`'s model and hold every effect's
/// columns ([`CrossSums::read`]), else summed in a pass of their own, in cells as the fit's
/// were ([`Cells`]): the terms are the bias of the fit as it was made.
#[allow(clippy::too_many_arguments)]
pub fn consider(
    data: &LoopData,
    f: &Fitted,
    weights: [f64; 3],
    cx: &ConsiderCtx,
    base: &[usize; 12],
    params: &[f64; 12],
    nominal: f64,
    overrides: &ConsiderOverrides,
    alpha: f64,
    sums: Option<&CrossSums>,
) -> Consideration {
    let k: [f64; 3] = std::array::from_fn(|a| (0..3).map(|j| params[4 * a + j].powi(2)).sum::<f64>().sqrt());
    let cands = candidates(data, f, cx, k, overrides);
    if cands.is_empty() {
        return Consideration::none();
    }
    let (nl, ns) = (f.model.lin.len(), f.model.shared.len());
    let (cols, sel, places) = with_candidates(f, &cands);
    let groups: Vec<&[Col]> = cands.iter().map(|c| c.cols.as_slice()).collect();
    let read = sums.and_then(|s| s.read(&f.model, &groups, Cells::Span));
    let Some(total) = read.or_else(|| {
        let reach = Reach::blocks(nl + ns, cands.iter().map(|c| c.cols.len()));
        Gram::sum(&accumulate_pairs(data, &f.model, &cols, &reach, Cells::Span))
    }) else {
        return Consideration::none();
    };
    let (n_mat, b_vec) = normal_equations(&total, &sel, weights, &f.model.priors());
    let nl_ext = sel.lin.len();
    let model_idx: Vec<usize> = (0..3)
        .flat_map(|a| (0..nl).map(move |p| lin_param(nl_ext, a, p)))
        .chain((0..ns).map(|q| 3 * nl_ext + q))
        .collect();
    let a_mat = DMatrix::from_fn(model_idx.len(), model_idx.len(), |i, j| n_mat[(model_idx[i], model_idx[j])]);
    let Some(chol) = a_mat.cholesky() else {
        return Consideration::none();
    };
    let b_model = DVector::from_fn(model_idx.len(), |i, _| b_vec[model_idx[i]]);
    let mut out = Consideration::none();
    for (c, pl) in cands.iter().zip(&places) {
        let (idx, sd) = prior_params(c, pl, nl_ext);
        let mut b = DMatrix::from_fn(model_idx.len(), idx.len(), |i, j| n_mat[(model_idx[i], idx[j])]);
        let mut c_mat = DMatrix::from_fn(idx.len(), idx.len(), |i, j| n_mat[(idx[i], idx[j])]);
        let mut b_own = DVector::from_fn(idx.len(), |i, _| b_vec[idx[i]]);
        if !c.walk.is_empty() {
            to_steps(&mut b, &mut c_mat, &mut b_own, &c.walk);
        }
        let s_mat = chol.solve(&b);
        let info = &c_mat - b.transpose() * &s_mat;
        // The residual's correlation with the effect, beyond what the model's own step takes.
        let grad = b_own - s_mat.transpose() * &b_model;
        let threshold = |dof: usize| chi2_upper_quantile(dof, alpha / cands.len() as f64);
        let mut tried: Option<&dyn Fn(usize) -> f64> = if c.tried { Some(&threshold) } else { None };
        let (mut considered, mut source) = (c.params.clone(), c.source.to_string());
        let s12 = DMatrix::from_fn(12, idx.len(), |i, j| s_mat[(base[i], j)]);
        let Some(mut whitened) = whiten(&info, &grad, &sd, &with_squares(&s12, &c.squares)) else { continue };
        if let Some(how) = c.from_data {
            // Its size is read from the data (its scale's upper bound), every direction
            // counted at it: no test of hundreds of steps, or of a level per stretch, speaks for
            // any one of them.
            let Some(scale) = scale_bound(&whitened) else { continue };
            whitened = whitened.scaled(scale);
            considered.iter_mut().for_each(|p| p.sigma *= scale);
            source = format!("{source}, times {scale:.2}: {how} (95 % bound)");
            tried = None;
        }
        let (along, lambdas) = posterior(&whitened, tried);
        if lambdas.is_empty() {
            continue;
        }
        let added = second_moment(&along, &c.squares, &s12, params);
        let (k_sigma_ppm, direction_sigma_deg) = added_sigmas(params, &added, nominal);
        let term = ConsiderTerm {
            effect: c.effect.key(),
            name: c.effect.name(),
            params: considered,
            source,
            k_sigma_ppm,
            direction_sigma_deg,
            unseparated: lambdas.len(),
            least_seen: lambdas.iter().copied().fold(f64::INFINITY, f64::min),
            removed_by: c.effect.identified_by().into(),
        };
        out.cov += added;
        if term.k_sigma_ppm.iter().any(|&p| p > REPORTED_PPM)
            || term.direction_sigma_deg.iter().any(|&d| d > REPORTED_DEG)
        {
            out.terms.push(term);
        }
    }
    out.terms.sort_by(|a, b| max3(b.k_sigma_ppm).total_cmp(&max3(a.k_sigma_ppm)));
    out
}

/// A candidate's parameters in the joint solve (a linear column is one per axis, of `nl_ext`
/// linear columns) at its places `pl`, and their prior σs.
fn prior_params(c: &Candidate, pl: &[(bool, usize)], nl_ext: usize) -> (Vec<usize>, Vec<f64>) {
    let mut idx = Vec::new();
    let mut sd = Vec::new();
    for (&(is_lin, p), s) in pl.iter().zip(&c.sigma) {
        if is_lin {
            for (a, &sa) in s.iter().enumerate() {
                idx.push(lin_param(nl_ext, a, p));
                sd.push(sa);
            }
        } else {
            idx.push(3 * nl_ext + p);
            sd.push(s[0]);
        }
    }
    (idx, sd)
}

/// Half the χ²₁ quantile of a one-sided 95 % bound (2.71 / 2): how far the log-likelihood of
/// a prior's scale falls from its maximum at the bound [`scale_bound`] returns.
const SCALE_BOUND_DROP: f64 = 1.353;

/// Empirical Bayes for parameters (a walk's steps, the levels between stretches) whose prior
/// σs are known up to a common scale s: the upper 95 % bound of s from the data's own sight of
/// them (`w`, their partial information and the residual's gradient whitened by those σs). Along each eigendirection of it (λ),
/// the whitened score p has variance λ + s²λ² (noise plus the walk), so the log-likelihood of s²
/// is −½ Σ [ln(λ + s²λ²) + p²/(λ + s²λ²)]; the bound is where it falls [`SCALE_BOUND_DROP`] below
/// its maximum on the far side (Morris, JASA 78, 47, 1983, for the parametric empirical Bayes).
/// A gyro whose residual shows no wander carries a fraction of the datasheet-sized walk, one
/// that shows more carries more.
fn scale_bound(w: &Whitened) -> Option<f64> {
    let seen: Vec<(f64, f64)> = (0..w.eigenvalues.len())
        .filter(|&i| w.eigenvalues[i] > 1e-9)
        .map(|i| (w.eigenvalues[i], w.projections[i].powi(2)))
        .collect();
    let ll = |s2: f64| -> f64 {
        -0.5 * seen.iter().map(|&(l, p2)| (l + s2 * l * l).ln() + p2 / (l + s2 * l * l)).sum::<f64>()
    };
    // The maximum on a grid of s² (0, then 1e-4 to 1e4 a tenth of a decade apart), refined by
    // golden section between the best point's neighbours; then the bound beyond it by bisection.
    let grid: Vec<f64> = std::iter::once(0.0).chain((0..=80).map(|i| 10f64.powf(-4.0 + 0.1 * f64::from(i)))).collect();
    let at = (0..grid.len()).max_by(|&i, &j| ll(grid[i]).total_cmp(&ll(grid[j])))?;
    let (mut a, mut b) = (grid[at.saturating_sub(1)], grid[(at + 1).min(grid.len() - 1)]);
    let golden = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..80 {
        let (c, d) = (b - golden * (b - a), a + golden * (b - a));
        if ll(c) >= ll(d) {
            b = d;
        } else {
            a = c;
        }
    }
    let s2_best = 0.5 * (a + b);
    let best = (s2_best, ll(s2_best).max(ll(grid[at])));
    let floor = best.1 - SCALE_BOUND_DROP;
    let (mut lo, mut hi) = (best.0, best.0.max(1e-4));
    while ll(hi) > floor {
        if hi > 1e8 {
            return Some(1e4);
        }
        lo = hi;
        hi *= 2.0;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if ll(mid) > floor {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(hi.sqrt())
}

/// A walk's cross-products with the model (`b`), with itself (`c_mat`) and with the residual
/// (`b_own`), from its levels' to its steps': the parameters its prior bounds are the steps,
/// levels = A·steps ([`times_walk`]), so B·A, Aᵀ·C·A and Aᵀ·b.
fn to_steps(b: &mut DMatrix<f64>, c_mat: &mut DMatrix<f64>, b_own: &mut DVector<f64>, walk: &[Option<usize>]) {
    times_walk(b, walk);
    times_walk(c_mat, walk);
    c_mat.transpose_mut();
    times_walk(c_mat, walk);
    let mut row = DMatrix::from_row_slice(1, b_own.len(), b_own.as_slice());
    times_walk(&mut row, walk);
    *b_own = DVector::from_row_slice(row.as_slice());
}

/// `m` times the map from a walk's steps to its levels (`walk` each level's predecessor in its
/// stretch; three parameters per level, in axis order): each level's column becomes the sum of
/// its own and its successors' in the stretch, since a step moves every later level. Running
/// sums from the stretch's end, O(rows·n), where a product with the dense map was O(rows·n²)
/// and with it the 1-h replay's largest matrix products.
fn times_walk(m: &mut DMatrix<f64>, walk: &[Option<usize>]) {
    for (level, &before) in walk.iter().enumerate().rev() {
        let Some(p) = before else { continue };
        for axis in 0..3 {
            let (from, to) = (3 * level + axis, 3 * p + axis);
            for r in 0..m.nrows() {
                m[(r, to)] += m[(r, from)];
            }
        }
    }
}

fn max3(v: [f64; 3]) -> f64 {
    v.into_iter().fold(0.0, f64::max)
}

/// The estimate's sensitivity times a factor F of the covariance F·Fᵀ (posterior variance plus
/// the square of the posterior mean) of an effect's parameters in the directions the runs do not
/// separate, from its partial information and the residual's gradient along its columns,
/// whitened by its prior σs (`w`); with those directions' information λ. An effect the loop did
/// not try (`tried` None) has every direction counted: no test ruled out what the runs see of
/// it, and its posterior mean is what they say it is. One it tried (`tried` the loop's χ² threshold for a
/// number of degrees of freedom) has its separated directions left to the test, unless the
/// residual's score along them passes that threshold.
fn posterior(w: &Whitened, tried: Option<&dyn Fn(usize) -> f64>) -> (DMatrix<f64>, Vec<f64>) {
    let n = w.eigenvalues.len();
    let lambdas: Vec<f64> = w.eigenvalues.iter().map(|l| l.max(0.0)).collect();
    // A direction the loop's test of the whole effect would see at plausible size with 95 %
    // power; the test's silence speaks for no other.
    let seen = tried.map_or(SEPARATED_SNR2, |threshold| seen_by_test(n, threshold(n)));
    // The score (Lagrange-multiplier) statistic of the separated directions, gᵀI⁻¹g over them:
    // what the loop's test of the effect reads. Past its threshold the model lacks an effect
    // the runs see (its candidate rule, gated by the residual's diagnostics, never let the loop
    // score it), so no test speaks for those directions either.
    let separated: Vec<usize> = (0..n).filter(|&i| lambdas[i] >= seen).collect();
    let score: f64 = separated.iter().map(|&i| w.projections[i].powi(2) / lambdas[i]).sum();
    let tested = tried.is_some_and(|threshold| separated.is_empty() || score <= threshold(separated.len()));
    let kept: Vec<usize> = (0..n).filter(|&i| !(tested && lambdas[i] >= seen)).collect();
    // F = diag(sd)·[U·diag(1/√(1 + λ)), U·diag(1/(1 + λ))·(Uᵀg)] over the kept directions: the
    // covariance diag(sd)·(Σ u uᵀ/(1 + λ) + m mᵀ)·diag(sd) with m = Σ u (u·g)/(1 + λ). Only its
    // product with the estimate's sensitivity S is wanted (`w.rows` = S·diag(sd)·U), and a walk
    // has hundreds of directions: the n × n covariance itself was an n³ product.
    let mut along = DMatrix::zeros(w.rows.nrows(), kept.len() + 1);
    for (c, &i) in kept.iter().enumerate() {
        let shrink = 1.0 / (1.0 + lambdas[i]);
        let (root, mean) = (shrink.sqrt(), shrink * w.projections[i]);
        for r in 0..w.rows.nrows() {
            let u = w.rows[(r, i)];
            along[(r, c)] = u * root;
            along[(r, kept.len())] += u * mean;
        }
    }
    (along, kept.iter().map(|&i| lambdas[i]).collect())
}

/// An effect's partial information and the residual's gradient in units of its prior σs: the
/// eigenvalues of diag(sd)·info·diag(sd), the whitened gradient's projection on each
/// eigenvector and the estimate's sensitivity to a step along each. [`scale_bound`] and
/// [`posterior`] both read it.
struct Whitened {
    eigenvalues: DVector<f64>,
    /// S·diag(sd)·U: the estimate's move per whitened unit along each eigenvector (S the
    /// estimate's sensitivity to the effect's parameters, U the eigenvectors).
    rows: DMatrix<f64>,
    projections: Vec<f64>,
}

/// [`Whitened`] of `info`, `grad` and prior σs `sd`, for an estimate of sensitivity `sens` to the
/// effect's parameters; None when any is not finite.
fn whiten(info: &DMatrix<f64>, grad: &DVector<f64>, sd: &[f64], sens: &DMatrix<f64>) -> Option<Whitened> {
    let (n, p) = (sd.len(), sens.nrows());
    let w = DMatrix::from_fn(n, n, |r, c| 0.5 * (info[(r, c)] + info[(c, r)]) * sd[r] * sd[c]);
    if w.iter().chain(grad.iter()).chain(sens.iter()).any(|v| !v.is_finite()) {
        return None;
    }
    // The rows the eigenvectors are wanted in: S·diag(sd), then the whitened gradient.
    let rows = DMatrix::from_fn(p + 1, n, |r, c| if r < p { sens[(r, c)] * sd[c] } else { grad[c] * sd[c] });
    let (eigenvalues, along) = block_eigen(w, rows);
    let projections = along.row(p).iter().copied().collect();
    Some(Whitened { eigenvalues, rows: along.rows(0, p).into_owned(), projections })
}

/// The eigenvalues of the symmetric `w` and `rows` times its eigenvectors, block by block: its
/// parameters fall into groups no entry links (the three axes' walks when no shared parameter
/// of the model couples the axes), each decomposed alone. The same eigenpairs as one
/// decomposition, in another order, at a ninth of its cost for three equal blocks: a 1-h
/// capture's walk has 3 × 360 steps, and one decomposition of all 1080 was a fifth of its
/// replay.
fn block_eigen(w: DMatrix<f64>, rows: DMatrix<f64>) -> (DVector<f64>, DMatrix<f64>) {
    let n = w.nrows();
    let blocks = linked_groups(n, |r, c| w[(r, c)] != 0.0);
    if blocks.len() <= 1 {
        return eigen_rows(w, rows);
    }
    let mut values = DVector::zeros(n);
    let mut along = DMatrix::zeros(rows.nrows(), n);
    let mut at = 0;
    for idx in blocks {
        let (v, a) = eigen_rows(w.select_rows(&idx).select_columns(&idx), rows.select_columns(&idx));
        values.rows_mut(at, idx.len()).copy_from(&v);
        along.columns_mut(at, idx.len()).copy_from(&a);
        at += idx.len();
    }
    (values, along)
}

/// The eigenvalues of the symmetric `w` and `rows` times its eigenvectors: its tridiagonal form
/// with the reflections applied to `rows` ([`tridiagonalize`]), then the QL iteration applying
/// its rotations to them ([`tridiagonal_eigen`]); nalgebra's whole decomposition if that fails
/// to converge.
fn eigen_rows(w: DMatrix<f64>, rows: DMatrix<f64>) -> (DVector<f64>, DMatrix<f64>) {
    if w.nrows() > 1 {
        let mut along = rows.clone();
        let (mut d, off) = tridiagonalize(w.clone(), &mut along);
        if tridiagonal_eigen(&mut d, &off, &mut along) {
            return (DVector::from_vec(d), along);
        }
    }
    let eig = w.symmetric_eigen();
    (eig.eigenvalues, rows * eig.eigenvectors)
}

/// The symmetric `a` as Q·T·Qᵀ, T tridiagonal, by Householder reflections (Golub & Van Loan,
/// *Matrix Computations*, 4th ed., Alg. 8.3.1): T's diagonal and off-diagonal, and `rows`·Q in
/// `rows`. Written here rather than taken from nalgebra's `SymmetricTridiagonal`, which gives Q
/// only as the n × n matrix (n³ more work, a sixth of a 1-h replay's consider covariance) where
/// each reflection applied to a dozen rows costs 2·12·n.
fn tridiagonalize(mut a: DMatrix<f64>, rows: &mut DMatrix<f64>) -> (Vec<f64>, Vec<f64>) {
    let n = a.nrows();
    let mut off = vec![0.0; n.saturating_sub(1)];
    for (k, off_k) in off.iter_mut().enumerate().take(n.saturating_sub(2)) {
        let m = n - k - 1;
        // The reflection H = I − β·v·vᵀ taking column k below the diagonal to (∓|x|, 0, …).
        let mut v: DVector<f64> = a.view((k + 1, k), (m, 1)).column(0).into_owned();
        let norm = v.norm();
        if norm == 0.0 {
            continue;
        }
        let sign = if v[0] >= 0.0 { 1.0 } else { -1.0 };
        v[0] += sign * norm;
        let beta = 2.0 / v.norm_squared();
        *off_k = -sign * norm;
        // The trailing block B → H·B·H = B − v·wᵀ − w·vᵀ, p = β·B·v, w = p − (β·pᵀv/2)·v.
        let p = a.view((k + 1, k + 1), (m, m)) * &v * beta;
        let w = &p - &v * (0.5 * beta * p.dot(&v));
        let mut b = a.view_mut((k + 1, k + 1), (m, m));
        b.ger(-1.0, &v, &w, 1.0);
        b.ger(-1.0, &w, &v, 1.0);
        // rows·H on the columns it acts on.
        let mut r = rows.columns_mut(k + 1, m);
        let rv = &r * &v;
        r.ger(-beta, &rv, &v, 1.0);
    }
    if n >= 2 {
        off[n - 2] = a[(n - 1, n - 2)];
    }
    ((0..n).map(|i| a[(i, i)]).collect(), off)
}

/// The eigenvalues of the symmetric tridiagonal matrix of diagonal `d` and off-diagonal `off`
/// (`off[i]` joins i and i + 1), left in `d`, and `rows` (m × n) times its eigenvectors, left in
/// `rows`: the implicit QL iteration with Wilkinson's shift (Bowdler, Martin, Reinsch &
/// Wilkinson, Numer. Math. 11, 293, 1968: EISPACK's tql2). Written here rather than taken from
/// nalgebra, whose decomposition rotates all n eigenvectors where the consider covariance
/// wants their products with a dozen rows: for a walk of 360 steps the rotations were most of
/// the decomposition. False if an eigenvalue is not found in 60 iterations.
fn tridiagonal_eigen(d: &mut [f64], off: &[f64], rows: &mut DMatrix<f64>) -> bool {
    let n = d.len();
    let mut e = off.to_vec();
    e.push(0.0);
    for l in 0..n {
        let mut iterations = 0;
        loop {
            // The first negligible off-diagonal at or after l splits the matrix there.
            let m = (l..n - 1).find(|&m| e[m].abs() <= f64::EPSILON * (d[m].abs() + d[m + 1].abs())).unwrap_or(n - 1);
            if m == l {
                break;
            }
            iterations += 1;
            if iterations > 60 {
                return false;
            }
            ql_step(d, &mut e, (l, m), rows);
        }
    }
    true
}

/// One implicit QL step on the block l..=m of [`tridiagonal_eigen`], its rotations applied to
/// the columns of `rows`.
fn ql_step(d: &mut [f64], e: &mut [f64], (l, m): (usize, usize), rows: &mut DMatrix<f64>) {
    // Wilkinson's shift: the eigenvalue of the leading 2 × 2 nearer d[l].
    let g0 = (d[l + 1] - d[l]) / (2.0 * e[l]);
    let mut g = d[m] - d[l] + e[l] / (g0 + g0.hypot(1.0).copysign(g0));
    let (mut s, mut c, mut p) = (1.0, 1.0, 0.0);
    for i in (l..m).rev() {
        let (f, b) = (s * e[i], c * e[i]);
        let r = f.hypot(g);
        e[i + 1] = r;
        if r == 0.0 {
            // The block split at i + 1: undo the shift there and iterate again.
            d[i + 1] -= p;
            e[m] = 0.0;
            return;
        }
        (s, c) = (f / r, g / r);
        let h = d[i + 1] - p;
        let t = (d[i] - h) * s + 2.0 * c * b;
        p = s * t;
        d[i + 1] = h + p;
        g = c * t - b;
        for k in 0..rows.nrows() {
            let (x, y) = (rows[(k, i)], rows[(k, i + 1)]);
            rows[(k, i + 1)] = s * x + c * y;
            rows[(k, i)] = c * x - s * y;
        }
    }
    d[l] -= p;
    e[l] = g;
    e[m] = 0.0;
}

/// The groups of `0..n` that `linked(r, c)` (for r < c) joins, directly or through others,
/// each in increasing order, the groups in order of their first member.
fn linked_groups(n: usize, linked: impl Fn(usize, usize) -> bool) -> Vec<Vec<usize>> {
    // Union-find with the smallest member as each group's root.
    let mut root: Vec<usize> = (0..n).collect();
    fn find(root: &mut [usize], mut i: usize) -> usize {
        while root[i] != i {
            root[i] = root[root[i]];
            i = root[i];
        }
        i
    }
    for r in 0..n {
        for c in r + 1..n {
            if linked(r, c) {
                let (a, b) = (find(&mut root, r), find(&mut root, c));
                root[a.max(b)] = a.min(b);
            }
        }
    }
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut group_of = vec![usize::MAX; n];
    for i in 0..n {
        let g = find(&mut root, i);
        if group_of[g] == usize::MAX {
            group_of[g] = groups.len();
            groups.push(Vec::new());
        }
        groups[group_of[g]].push(i);
    }
    groups
}

impl Whitened {
    /// The same effect with prior σs `scale` times: information and gradient along the same
    /// eigenvectors, the one by scale², the other (and the estimate's move per whitened unit)
    /// by scale.
    fn scaled(mut self, scale: f64) -> Self {
        self.rows *= scale;
        self.eigenvalues *= scale * scale;
        self.projections.iter_mut().for_each(|p| *p *= scale);
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`whiten`] for the effect's parameters themselves (S = I): [`posterior`] then gives F.
    fn whiten_id(info: &DMatrix<f64>, grad: &DVector<f64>, sd: &[f64]) -> Option<Whitened> {
        whiten(info, grad, sd, &DMatrix::identity(sd.len(), sd.len()))
    }

    /// [`posterior`]'s covariance F·Fᵀ.
    fn posterior_cov(w: &Whitened, tried: Option<&dyn Fn(usize) -> f64>) -> (DMatrix<f64>, Vec<f64>) {
        let (f, n) = posterior(w, tried);
        (&f * f.transpose(), n)
    }

    /// The map from a walk's steps to its levels, written out: level i is the sum of its own
    /// step and its predecessors' in the stretch, axis by axis.
    fn walk_sums(walk: &[Option<usize>], n: usize) -> DMatrix<f64> {
        let mut a = DMatrix::identity(n, n);
        for (col, &first) in walk.iter().enumerate() {
            let mut before = first;
            while let Some(j) = before {
                for axis in 0..3 {
                    a[(3 * col + axis, 3 * j + axis)] = 1.0;
                }
                before = walk[j];
            }
        }
        a
    }

    /// Parameters no entry links are decomposed apart, with the eigenpairs of the whole.
    #[test]
    fn unlinked_blocks_are_decomposed_apart_with_the_same_eigenpairs() {
        assert_eq!(linked_groups(5, |r, c| (r, c) == (0, 3) || (r, c) == (3, 4)), [vec![0, 3, 4], vec![1], vec![2]]);
        // x and z linked, y alone: the 3 × 3 of one axis per parameter.
        let w = DMatrix::from_row_slice(3, 3, &[4.0, 0.0, 1.0, 0.0, 2.0, 0.0, 1.0, 0.0, 3.0]);
        let (values, vectors) = block_eigen(w.clone(), DMatrix::identity(3, 3));
        let whole = w.clone().symmetric_eigen();
        let mut got: Vec<f64> = values.iter().copied().collect();
        let mut want: Vec<f64> = whole.eigenvalues.iter().copied().collect();
        got.sort_by(f64::total_cmp);
        want.sort_by(f64::total_cmp);
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() < 1e-12, "{got:?} against {want:?}");
        }
        // W = V·diag(λ)·Vᵀ with V orthonormal.
        let back = &vectors * DMatrix::from_diagonal(&values) * vectors.transpose();
        assert!((back - &w).abs().max() < 1e-12);
        assert!((vectors.transpose() * &vectors - DMatrix::identity(3, 3)).abs().max() < 1e-12);
    }

    /// The QL iteration's eigenvalues are nalgebra's, and its rows times the eigenvectors give
    /// what nalgebra's vectors give for any function of the matrix: rows·f(W)·rowsᵀ, for
    /// matrices of one to 60 parameters (random, one with a repeated eigenvalue, one already
    /// diagonal), to 1e-10 of their scale.
    #[test]
    fn the_ql_iteration_gives_nalgebras_eigenvalues_and_rows() {
        let mut state = 12345u64;
        let mut uniform = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for n in [1, 2, 3, 7, 20, 60] {
            let a = DMatrix::from_fn(n, n, |_, _| uniform());
            let random = &a * a.transpose();
            let mut repeated = DMatrix::identity(n, n) * 2.0;
            repeated[(0, 0)] = 5.0;
            let diagonal = DMatrix::from_fn(n, n, |r, c| if r == c { r as f64 } else { 0.0 });
            for w in [random, repeated, diagonal] {
                let rows = DMatrix::from_fn(4, n, |_, _| uniform());
                let mut reflected = rows.clone();
                let (mut d, off) = tridiagonalize(w.clone(), &mut reflected);
                let converged = tridiagonal_eigen(&mut d, &off, &mut reflected);
                assert!(converged, "n = {n}: the QL iteration itself converges");
                let (values, along) = eigen_rows(w.clone(), rows.clone());
                let whole = w.clone().symmetric_eigen();
                let (mut got, mut want): (Vec<f64>, Vec<f64>) =
                    (values.iter().copied().collect(), whole.eigenvalues.iter().copied().collect());
                got.sort_by(f64::total_cmp);
                want.sort_by(f64::total_cmp);
                let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
                assert!(got.iter().zip(&want).all(|(g, w)| (g - w).abs() <= 1e-10 * scale), "{got:?} against {want:?}");
                let f = |l: f64| 1.0 / (1.0 + l.abs());
                let mine = &along * DMatrix::from_diagonal(&values.map(f)) * along.transpose();
                let theirs = &rows * &whole.eigenvectors;
                let theirs = &theirs * DMatrix::from_diagonal(&whole.eigenvalues.map(f)) * theirs.transpose();
                let size = theirs.abs().max().max(1e-300);
                assert!((mine - &theirs).abs().max() <= 1e-10 * size, "n = {n}");
            }
        }
    }

    /// A direction the data do not see keeps its prior; one they see well is left to the tests.
    #[test]
    fn posterior_keeps_the_prior_where_the_runs_see_nothing() {
        let info = DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 0.0, 1e6]);
        let (c, n) =
            posterior_cov(&whiten_id(&info, &DVector::zeros(2), &[2.0, 3.0]).expect("finite"), Some(&|_| 16.4));
        assert_eq!(n, [0.0]);
        assert!((c[(0, 0)] - 4.0).abs() < 1e-12, "{c}");
        assert!(c[(1, 1)].abs() < 1e-12 && c[(0, 1)].abs() < 1e-12, "{c}");
        // Seen at λ = 40 (a 6σ signal at plausible size) but by a test at χ² 35, which would
        // miss it one time in four: counted.
        let info40 = DMatrix::from_row_slice(1, 1, &[40.0]);
        let (c, n) = posterior_cov(&whiten_id(&info40, &DVector::zeros(1), &[1.0]).expect("finite"), Some(&|_| 35.0));
        assert_eq!(n, [40.0]);
        assert!((c[(0, 0)] - 1.0 / 41.0).abs() < 1e-12, "{c}");
        let (_, n) = posterior_cov(&whiten_id(&info40, &DVector::zeros(1), &[1.0]).expect("finite"), Some(&|_| 16.4));
        assert!(n.is_empty(), "{n:?}");
        // Half-seen: λ = 3 (σ = 1, information 3) shrinks the variance to 1/4.
        let info = DMatrix::from_row_slice(1, 1, &[3.0]);
        let (c, n) =
            posterior_cov(&whiten_id(&info, &DVector::zeros(1), &[1.0]).expect("finite"), Some(&|_| f64::INFINITY));
        assert_eq!(n.len(), 1);
        assert!((n[0] - 3.0).abs() < 1e-12, "{n:?}");
        assert!((c[(0, 0)] - 0.25).abs() < 1e-12, "{c}");
        // A direction seen well (whitened λ = 3²·1e6 ≥ 25) of an effect the loop did not try is
        // counted: its posterior variance is 1/(1 + λ) of the prior's.
        let info2 = DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 0.0, 1e6]);
        let (c2, n2) = posterior_cov(&whiten_id(&info2, &DVector::zeros(2), &[2.0, 3.0]).expect("finite"), None);
        assert_eq!(n2.len(), 2);
        assert!((c2[(1, 1)] - 9.0 / (1.0 + 9e6)).abs() < 1e-15, "{c2}");
        // A tried effect whose separated direction the residual pulls on past the test's
        // threshold (whitened g = 3·3000, score 9000²/9e6 = 9 > 0.5) was never tested: it is counted, with
        // the posterior mean g_w/(1 + λ) = 9000/(1 + 9e6) of its whitened σ (3).
        let g = DVector::from_column_slice(&[0.0, 3000.0]);
        let (c3, n3) = posterior_cov(&whiten_id(&info2, &g, &[2.0, 3.0]).expect("finite"), Some(&|_| 0.5));
        assert_eq!(n3.len(), 2);
        let mean = 3.0 * 9000.0 / (1.0 + 9e6);
        assert!((c3[(1, 1)] - (9.0 / (1.0 + 9e6) + mean * mean)).abs() < 1e-15, "{c3}");
        // Below the threshold (9 ≤ 10) the test speaks for it.
        let (c4, n4) = posterior_cov(&whiten_id(&info2, &g, &[2.0, 3.0]).expect("finite"), Some(&|_| 10.0));
        assert_eq!((n4.len(), c4[(1, 1)]), (1, 0.0));
        // The residual's pull adds the square of the posterior mean: g = 2 → mean 2/4.
        let (c, _) = posterior_cov(
            &whiten_id(&info, &DVector::from_element(1, 2.0), &[1.0]).expect("finite"),
            Some(&|_| f64::INFINITY),
        );
        assert!((c[(0, 0)] - 0.5).abs() < 1e-12, "{c}");
    }

    /// The power bound: one parameter at the loop's usual χ² 16.4 needs λ ≈ 35; nine at 35.2
    /// need ≈ 50.6 (from k + λ − 1.645·√(2(k + 2λ)) = T); a weak test never falls below 25.
    #[test]
    fn a_test_speaks_for_what_it_would_see_with_95_percent_power() {
        assert!((seen_by_test(1, 16.4) - 35.0).abs() < 0.1, "{}", seen_by_test(1, 16.4));
        assert!((seen_by_test(9, 35.2) - 50.6).abs() < 0.1, "{}", seen_by_test(9, 35.2));
        assert_eq!(seen_by_test(1, 1.0), SEPARATED_SNR2);
        assert_eq!(seen_by_test(3, f64::INFINITY), f64::INFINITY);
    }

    /// A walk's levels are its steps summed back to its stretch's start, axis by axis: levels
    /// 0, 1 of one stretch and level 2 of the next.
    #[test]
    fn a_walks_levels_sum_its_steps_within_a_stretch() {
        let a = walk_sums(&[None, Some(0), None], 9);
        for axis in 0..3 {
            for (level, steps) in [(0, vec![0]), (1, vec![0, 1]), (2, vec![2])] {
                for step in 0..3 {
                    let want = if steps.contains(&step) { 1.0 } else { 0.0 };
                    assert_eq!(a[(3 * level + axis, 3 * step + axis)], want, "level {level} step {step}");
                }
            }
            assert_eq!(a.row(axis).sum(), 1.0);
        }
        assert_eq!(a.sum(), 12.0);
        assert_eq!(walk_sums(&[], 4), DMatrix::identity(4, 4));
        // The running sums are the product with the map: two stretches, of three levels and
        // of two, twelve rows.
        let walk = [None, Some(0), Some(1), None, Some(3)];
        let m = DMatrix::from_fn(12, 15, |r, c| ((r * 15 + c) as f64 * 0.37).sin());
        let mut fast = m.clone();
        times_walk(&mut fast, &walk);
        assert!((fast - &m * walk_sums(&walk, 15)).abs().max() < 1e-12);
    }

    /// A hundred steps seen at λ = 4 each: where the scores are what noise alone gives (p² = λ)
    /// the walk's bound is a small fraction of its prior; where they carry a walk of the prior's
    /// size (p² = λ + λ²) the bound is just above 1.
    #[test]
    fn a_walks_size_is_bounded_by_the_wander_the_data_show() {
        let n = 100;
        let info = DMatrix::from_diagonal_element(n, n, 4.0);
        let quiet = scale_bound(&whiten_id(&info, &DVector::from_element(n, 2.0), &vec![1.0; n]).expect("finite"))
            .expect("finite");
        assert!(quiet > 0.05 && quiet < 0.3, "{quiet}");
        let walking =
            scale_bound(&whiten_id(&info, &DVector::from_element(n, 20f64.sqrt()), &vec![1.0; n]).expect("finite"))
                .expect("finite");
        assert!(walking > 1.0 && walking < 1.4, "{walking}");
        // The prior's σs only set the units: for the same data, twice the σ, half the scale.
        let halved =
            scale_bound(&whiten_id(&info, &DVector::from_element(n, 20f64.sqrt()), &vec![2.0; n]).expect("finite"));
        assert!((halved.expect("finite") - walking / 2.0).abs() < 1e-6 * walking);
    }

    #[test]
    fn overrides_parse_and_refuse() {
        let mut o = ConsiderOverrides::default();
        o.add("g_sensitivity=0.02").expect("parses");
        assert_eq!(o.of(Effect::GSensitivity), Some(0.02));
        o.add("g_sensitivity=0.03").expect("replaces");
        assert_eq!(o.of(Effect::GSensitivity), Some(0.03));
        assert_eq!(o.add("g_sens=1").unwrap_err().split(" (keys").next(), Some("no effect 'g_sens'"));
        assert_eq!(o.add("g_sensitivity").unwrap_err(), "'g_sensitivity' is not KEY=SIGMA");
        assert_eq!(
            o.add("g_sensitivity=-1").unwrap_err(),
            "the size of g_sensitivity must be a finite number ≥ 0, not -1"
        );
        let keys = considered_keys();
        for k in
            ["g_sensitivity", "earth_rotation", "rate_scale", "rate_cubic", "filter_gain", "table_tilt", "pose_fixture"]
        {
            assert!(keys.iter().any(|x| x == k), "{k} in {keys:?}");
        }
    }

    /// Scaling a whitening's priors gives what whitening with the scaled priors gives: the walk's
    /// posterior reuses the decomposition its scale was read from.
    #[test]
    fn a_scaled_whitening_is_the_whitening_of_scaled_priors() {
        let info = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0]);
        let grad = DVector::from_column_slice(&[1.0, -2.0, 0.5]);
        let sd = [0.5, 1.5, 2.0];
        let (c1, l1) = posterior_cov(&whiten_id(&info, &grad, &sd).expect("finite").scaled(3.0), None);
        let (c2, l2) = posterior_cov(&whiten_id(&info, &grad, &sd.map(|v| 3.0 * v)).expect("finite"), None);
        assert!((c1 - &c2).amax() <= 1e-12 * c2.amax(), "{c2}");
        for (a, b) in l1.iter().zip(&l2) {
            assert!((a - b).abs() <= 1e-12 * b.abs(), "{l1:?} against {l2:?}");
        }
    }

    /// The second-order scale's moments: a parameter known exactly (variance 0) at μ moves the
    /// estimate by b = s·μ + f·μ²·d, so the first-order part s·sᵀ·μ² plus this term is b·bᵀ to
    /// rounding; one unseen (mean 0, variance σ²) adds 3·f²·σ⁴·d·dᵀ and no cross term, an RMS
    /// scale of √3·f·σ² (24 ppm for a 0.3° tilt at f = ½).
    #[test]
    fn a_squared_parameter_adds_the_second_moment_of_its_scale() {
        let s = DVector::from_vec(vec![0.3, -1.2, 0.0, 2.0]);
        let d = DVector::from_vec(vec![-57.0, 0.5, -0.2, 0.0]);
        let (f, mu) = (0.5, 0.02);
        let b = &s * mu + &d * (f * mu * mu);
        let got = &s * s.transpose() * (mu * mu) + second_order_scale(f, mu, 0.0, &s, &d);
        let want = &b * b.transpose();
        for (g, w) in got.iter().zip(want.iter()) {
            assert!((g - w).abs() <= 1e-15 * want.amax(), "{got} against {want}");
        }
        let sigma = 0.3f64.to_radians();
        let unseen = second_order_scale(f, 0.0, sigma * sigma, &s, &d);
        let rms_ppm = unseen[(0, 0)].sqrt() / 57.0 * 1e6;
        let want_ppm = 3f64.sqrt() * f * sigma * sigma * 1e6;
        assert!((rms_ppm - want_ppm).abs() <= 1e-9 * want_ppm, "{rms_ppm} ppm against {want_ppm}");
        assert!((want_ppm - 23.7).abs() < 0.1, "{want_ppm} ppm");
        assert!(unseen[(0, 3)] == 0.0 && unseen[(3, 3)] == 0.0, "the offsets do not scale: {unseen}");
    }
}
