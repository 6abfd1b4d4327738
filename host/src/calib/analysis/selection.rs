//! Forward stepwise selection over the catalogue. At each step one pass accumulates the sums of
//! the current model's columns and every candidate's (the linearised fit of each candidate is a
//! solve of a sub-system of them); the candidate with the best BIC gain is added if its χ² drop
//! passes a nested-model test at a Bonferroni-corrected level, and the model is then refitted by
//! Gauss-Newton.
//!
//! The test: with the χ² weighted by the long-run noise variance measured between the table
//! harmonics, the drop Δχ² from adding k parameters is χ²_k-distributed if the effect is absent;
//! the effect is added if Δχ² exceeds the upper α/m point, m the candidates tried at this step.
//! Among those that pass, the most significant is taken (the largest normal deviate of its drop
//! for its k: the classical F-to-enter order), which prefers the effect with fewer parameters when
//! two explain the same structure. A BIC order (Δχ² − k·ln n) was used before and lost to a
//! one-parameter effect with a drop of 18 a nine-parameter g-sensitivity with a drop of 114
//! (p ≈ 1e-19): with 10⁶ samples ln n charges each parameter 14.

use crate::calib::analysis::diagnostics::{Diagnostics, FindingKind, MAX_ORDER};
use crate::calib::analysis::model_choice::{self, Alternative, Candidacy};
use crate::calib::effects::terms::{Evidence, Situation};
use crate::calib::effects::{Effect, DRIFT_TAU_RANGE_S};
use crate::calib::engine::{
    apply_step, fit, full_selection, normal_equations, residual_after, solve_joint, Cells, Col, CrossSums, Fitted,
    Gram, LinCol, LoopData, Selection,
};
use crate::calib::result::error::CalError;
use crate::geometry::Pose;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Two runs' θ2' differ enough to separate a delay from an index offset if they differ by this
/// fraction (5 %: their phases then differ by 5 % of the delay's).
const DISTINCT_RATE_FRACTION: f64 = 0.05;

/// A candidate addition.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// The effect.
    pub effect: Effect,
    /// Its columns in the accumulation.
    pub cols: Vec<Col>,
    /// For an effect tried at grid values of its one shared parameter (the warm-up's time
    /// constant, s), this trial's value, held for the first pass.
    pub held_at: Option<f64>,
}

/// A candidate's score at one step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Score {
    /// Effect name.
    pub effect: Effect,
    /// Warm-up variant, s.
    pub drift_tau_s: Option<f64>,
    /// χ² drop.
    pub delta_chi2: f64,
    /// Parameters added.
    pub dof: usize,
    /// Threshold the drop had to exceed.
    pub threshold: f64,
    /// The drop's significance: the normal deviate with the same upper tail as Δχ² for `dof`
    /// parameters ([`crate::calib::analysis::stats::chi2_to_sigma`]). The order of the candidates.
    pub significance_sigma: f64,
    /// Added without a test because the physics is certain to be there (Earth rotation): only
    /// its parameters are unknown.
    #[serde(default)]
    pub known_physics: bool,
}

/// Whether the runs contain two distinct signed θ2' (speeds or directions).
pub fn separates_delay_and_index(data: &LoopData) -> bool {
    two_distinct(&table_rates_dps(data))
}

/// Each run's steady θ2', °/s.
fn table_rates_dps(data: &LoopData) -> Vec<f64> {
    data.kin.runs.iter().map(|r| r.gear_ratio * r.steady_rate_dps).collect()
}

/// Whether two of `rates` differ by more than [`DISTINCT_RATE_FRACTION`] of the larger.
pub fn two_distinct(rates: &[f64]) -> bool {
    rates.iter().any(|a| rates.iter().any(|b| (a - b).abs() > DISTINCT_RATE_FRACTION * a.abs().max(b.abs())))
}

/// The runs' distinct signed θ2', °/s: each rate once, rates within [`DISTINCT_RATE_FRACTION`]
/// of each other counted as one.
pub fn distinct_rates_dps(data: &LoopData) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::new();
    for r in table_rates_dps(data) {
        if !out.iter().any(|&o| !two_distinct(&[o, r])) {
            out.push(r);
        }
    }
    out
}

/// Whether the runs include both directions.
pub fn both_directions(data: &LoopData) -> bool {
    let r = &data.kin.runs;
    r.iter().any(|k| k.steady_rate_dps > 0.0) && r.iter().any(|k| k.steady_rate_dps < 0.0)
}

/// Which effects the residual points to ([`Evidence`]), read from the findings of a fit's
/// diagnostics.
pub fn evidence(d: &Diagnostics) -> Evidence {
    let mut e = Evidence { phase: false, drift: false, rate_scale: false, orders: [false; MAX_ORDER + 1] };
    let mut broadband = false;
    for f in &d.findings {
        match f.kind {
            FindingKind::Harmonic(n) => {
                e.orders[n as usize] = true;
                if n == 1 {
                    e.phase = true;
                } else {
                    e.rate_scale = true;
                }
            }
            FindingKind::RunOffset | FindingKind::TimeDrift | FindingKind::Temperature => e.drift = true,
            FindingKind::RateDependence => e.rate_scale = true,
            FindingKind::NotWhite | FindingKind::RmsExcess | FindingKind::SpeedRipple => broadband = true,
        }
    }
    if broadband && !(e.phase || e.drift || e.rate_scale) {
        e.phase = true;
        e.drift = true;
        e.rate_scale = true;
        e.orders = [true; MAX_ORDER + 1];
    }
    e
}

/// `f` of the situation of a model with `current` effects and `evidence` on `data`.
fn in_situation<R>(data: &LoopData, current: &[Effect], evidence: &Evidence, f: impl FnOnce(&Situation) -> R) -> R {
    f(&Situation {
        current,
        evidence: *evidence,
        separates_delay_and_index: separates_delay_and_index(data),
        distinct_rates_dps: &distinct_rates_dps(data),
        free_drift_keeps_constant_rates: free_drift_keeps_constant_rates(data),
        poses: data.poses.len(),
        temp_spread_c: &|| data.temp_spread_c(),
    })
}

/// Whether the loop would try `effect` on top of `current` had the residual pointed at it (every
/// kind of evidence, and the phase a 1× harmonic first brings in: a delay and an index offset
/// where the runs separate them, their combined phase where not): what it would not try, no
/// test has ruled out. Earth rotation is tried without evidence wherever the runs separate it
/// (`closure`).
pub fn tried(data: &LoopData, current: &[Effect], effect: Effect) -> bool {
    let all = Evidence { phase: true, drift: true, rate_scale: true, orders: [true; MAX_ORDER + 1] };
    let phase: &[Effect] =
        if separates_delay_and_index(data) { &[Effect::Delay, Effect::IndexOffset] } else { &[Effect::Phase] };
    let mut after_phase = current.to_vec();
    after_phase.extend(phase.iter().filter(|e| !current.contains(e)));
    let fires = |model: &[Effect]| in_situation(data, model, &all, |s| effect.behaviour(|b| b.candidate(s)));
    (effect.is_earth() && separates_delay_and_index(data)) || fires(current) || fires(&after_phase)
}

/// The candidates applicable to a model, among those the evidence points to: every effect of
/// the catalogue whose rule says so (`Behaviour::candidate`), in each form it is tried in.
pub fn candidates(data: &LoopData, current: &[Effect], evidence: &Evidence) -> Vec<Candidate> {
    let chosen: Vec<Effect> = in_situation(data, current, evidence, |s| {
        Effect::catalogue().into_iter().filter(|e| e.behaviour(|b| b.candidate(s))).collect()
    });
    chosen
        .into_iter()
        .flat_map(|effect| {
            effect.behaviour(|b| b.trials(&data.layout)).into_iter().map(move |t| Candidate {
                effect,
                cols: t.cols,
                held_at: t.held_at,
            })
        })
        .collect()
}

/// A candidate that passed the test on its linearised fit but could not be fitted to the end.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Skipped {
    /// The effect.
    pub effect: Effect,
    /// Why, in words (singular, a parameter at its bound).
    pub why: String,
}

/// The outcome of one selection step.
#[derive(Debug, Clone)]
pub struct StepOutcome {
    /// Every candidate's score, best first.
    pub scores: Vec<Score>,
    /// Candidates that passed but could not be fitted, with why; the step moved on to the next.
    pub skipped: Vec<Skipped>,
    /// The accepted candidate's index in `scores` and the refitted model, if one passed.
    pub accepted: Option<(usize, Fitted)>,
    /// When a drift model was added: each alternative compared, and its BIC.
    pub drift_choice: Vec<DriftChoice>,
    /// The candidates' pass (of the model the step started from), when one was made.
    pub sums: Option<CrossSums>,
    /// The near ties of the accepted candidate, a drift model's excepted (its alternatives are
    /// compared by BIC): [`crate::calib::analysis::model_choice`].
    pub alternatives: Vec<Alternative>,
}

/// A drift model compared as an alternative.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriftChoice {
    /// The model.
    pub effect: Effect,
    /// χ² after fitting.
    pub chi2: f64,
    /// χ² + k·ln n.
    pub bic: f64,
    /// Whether χ² is after fitting; otherwise it is the scoring pass's linearised one, and the
    /// model trailed the best fitted one by too much to be fitted ([`DRIFT_BIC_MARGIN`]).
    #[serde(default = "fitted_by_default")]
    pub fitted: bool,
}

/// Loop reports written before drift alternatives could be compared unfitted fitted every one.
fn fitted_by_default() -> bool {
    true
}

/// The model with a candidate added, started at the candidate's linearised solution; the
/// warm-up's time constant is not in that solution (its grid value stands).
fn start_model(
    state: &Fitted,
    c: &Candidate,
    sol: &crate::calib::engine::JointSolution,
) -> crate::calib::engine::Model {
    let ns = state.model.shared.len();
    let mut model = start_model_at_zero(state, c);
    let frozen: Vec<bool> = (0..model.shared.len()).map(|k| k >= ns && c.held_at.is_some()).collect();
    let nl = model.lin.len();
    apply_step(&mut model, nl, &sol.delta, &frozen);
    model
}

/// The model's effects that candidate `c` replaces when added ([`replaced_by_free_drift`]).
fn replaced(state: &Fitted, c: &Candidate, data: &LoopData) -> Vec<Effect> {
    if !c.effect.is_free_drift() {
        return Vec::new();
    }
    state.model.effects.iter().copied().filter(|&e| replaced_by_free_drift(e, data)).collect()
}

/// `base` without the columns of the effects candidate `c` replaces, and how many parameters
/// that takes out.
fn without_replaced(state: &Fitted, c: &Candidate, data: &LoopData, base: &Selection) -> (Selection, usize) {
    let mut sel = base.clone();
    let nl = state.model.lin.len();
    for e in replaced(state, c, data) {
        let (lin, shared) = e.params(&state.model.layout);
        sel.lin.retain(|&j| !lin.contains(&state.model.lin[j]));
        sel.shared.retain(|&j| !shared.contains(&state.model.shared[j - nl]));
    }
    let removed = base.len() - sel.len();
    (sel, removed)
}

/// The model with candidate `c` added at zero (its warm-up time constant at its grid value).
fn start_model_at_zero(state: &Fitted, c: &Candidate) -> crate::calib::engine::Model {
    let (lin, shared) = c.effect.params(&state.model.layout);
    state.model.with(
        c.effect,
        std::array::from_fn(|_| vec![0.0; lin.len()]),
        shared.iter().map(|_| c.held_at.unwrap_or(0.0)).collect(),
    )
}

/// One step from `state` with χ² weights `weights`; `alpha` is the family-wise level. `extra`
/// are groups of columns summed against the model in the candidates' pass (the consider
/// covariance's, read from the outcome's `sums` when no candidate passes), its samples summed
/// in `cells`.
pub fn step(
    data: &LoopData,
    state: &Fitted,
    diag: &Diagnostics,
    alpha: f64,
    (extra, cells): (&[Vec<Col>], Cells),
) -> Result<StepOutcome, CalError> {
    let weights = diag.weights();
    let cands = candidates(data, &state.model.effects, &evidence(diag));
    let nothing = || StepOutcome {
        scores: Vec::new(),
        skipped: Vec::new(),
        accepted: None,
        drift_choice: Vec::new(),
        sums: None,
        alternatives: Vec::new(),
    };
    if cands.is_empty() {
        return Ok(nothing());
    }
    let Some((mut scores, n_total, sums)) = score_all(data, state, &cands, (extra, cells), alpha, weights)? else {
        // The current model was fitted, so this only happens at the edge of f64: nothing more
        // can be added on top of it.
        return Ok(nothing());
    };
    scores.sort_by(|a, b| b.score.significance_sigma.total_cmp(&a.score.significance_sigma));
    let fitter = CandidateFit { data, state, cands: &cands, weights };
    let mut skipped = Vec::new();
    let mut drift_choice = Vec::new();
    let mut accepted = None;
    let mut tried_drift = false;
    for bi in (0..scores.len()).filter(|&i| scores[i].passed()) {
        let effect = scores[bi].score.effect;
        if effect.is_drift() {
            // The drift models are alternatives, tried together once: the best of them or none.
            if tried_drift {
                continue;
            }
            tried_drift = true;
            let (choices, best) = best_drift(&scores, &fitter, n_total, alpha, &mut skipped);
            drift_choice = choices;
            if best.is_some() {
                accepted = best;
                break;
            }
        } else {
            match fitter.fit(&scores[bi]) {
                Ok(f) => {
                    accepted = Some((bi, f));
                    break;
                }
                Err(why) => skipped.push(Skipped { effect, why }),
            }
        }
    }
    let alternatives = accepted.as_ref().map_or_else(Vec::new, |(bi, _)| near_ties(&scores, *bi));
    Ok(StepOutcome {
        scores: scores.into_iter().map(|s| s.score).collect(),
        skipped,
        accepted,
        drift_choice,
        sums: Some(sums),
        alternatives,
    })
}

/// A candidate's score, its index in the candidate list, its linearised joint solution, and
/// where M's nine elements are in that solution (axis-major).
struct Scored {
    score: Score,
    candidate: usize,
    solution: Option<crate::calib::engine::JointSolution>,
    m_at: Vec<usize>,
}

impl Scored {
    /// Whether it passed its test.
    fn passed(&self) -> bool {
        self.solution.is_some() && self.score.delta_chi2 > self.score.threshold
    }
}

/// Every candidate scored from one pass of cross-products (the model's columns against all,
/// each candidate's block against itself; `extra` groups summed alongside), the samples summed,
/// and the sums. `None` when the current model's own normal equations are singular.
fn score_all(
    data: &LoopData,
    state: &Fitted,
    cands: &[Candidate],
    (extra, cells): (&[Vec<Col>], Cells),
    alpha: f64,
    weights: [f64; 3],
) -> Result<Option<(Vec<Scored>, u64, CrossSums)>, CalError> {
    let nl = state.model.lin.len();
    let ns = state.model.shared.len();
    let groups: Vec<&[Col]> = cands.iter().map(|c| c.cols.as_slice()).chain(extra.iter().map(Vec::as_slice)).collect();
    let sums = CrossSums::gather(data, &state.model, &groups, cells).ok_or(CalError::NoRuns)?;
    let total = sums.total();
    let positions: Vec<_> = (0..cands.len()).map(|g| sums.block(g)).collect();
    let base_sel = Selection { lin: (0..nl).collect(), shared: (nl..nl + ns).collect() };
    let priors = state.model.priors();
    let Some(base) = solve_joint(total, &base_sel, weights, &priors) else {
        return Ok(None);
    };
    let n_total: u64 = total.n.iter().sum();
    let m = cands.len();
    let scores = cands
        .iter()
        .zip(&positions)
        .enumerate()
        .map(|(ci, (c, pos))| {
            // The free drift is scored as it is fitted: in place of what it replaces (a drift
            // curve already in: with both the sums are singular, and a random walk that a curve
            // took first was left as structure, flagged on every seed of the trust bench).
            let (mut sel, removed) = without_replaced(state, c, data, &base_sel);
            let mut dof: usize = 0;
            for (j, col) in pos.clone().zip(&c.cols) {
                match col {
                    Col::Lin(_) => {
                        sel.lin.push(j);
                        dof += 3;
                    }
                    Col::Shared(_) => {
                        sel.shared.push(j);
                        dof += 1;
                    }
                }
            }
            let dof = dof.saturating_sub(removed).max(1);
            let threshold = crate::calib::analysis::stats::chi2_upper_quantile(dof, alpha / m as f64);
            let solution = solve_joint(total, &sel, weights, &priors);
            let m_at = m_positions(&state.model.lin, &sel);
            let delta_chi2 = solution.as_ref().map_or(0.0, |s| base.chi2 - s.chi2);
            let score = Score {
                effect: c.effect,
                drift_tau_s: c.held_at,
                delta_chi2,
                dof,
                threshold,
                significance_sigma: crate::calib::analysis::stats::chi2_to_sigma(dof, delta_chi2),
                known_physics: false,
            };
            Scored { score, candidate: ci, solution, m_at }
        })
        .collect();
    Ok(Some((scores, n_total, sums)))
}

/// Where M's elements (the base model's `Omega` columns on each axis) are in the solution of
/// selection `sel` (axis-major linear parameters, `sel.lin.len()` per axis).
fn m_positions(lin: &[LinCol], sel: &Selection) -> Vec<usize> {
    let per_axis: Vec<usize> = (0..3)
        .filter_map(|k| {
            let j = lin.iter().position(|c| *c == LinCol::Omega(k))?;
            sel.lin.iter().position(|&x| x == j)
        })
        .collect();
    (0..3).flat_map(|a| per_axis.iter().map(move |p| a * sel.lin.len() + p)).collect()
}

/// The alternatives to candidate `bi` among `scores` ([`model_choice::alternatives`]): every
/// other candidate with a linearised solution that places M, drift models excepted.
fn near_ties(scores: &[Scored], bi: usize) -> Vec<Alternative> {
    let candidacy = |s: &Scored| -> Option<Candidacy> {
        let sol = s.solution.as_ref().filter(|_| s.m_at.len() == 9 && !s.score.effect.is_drift())?;
        Some(Candidacy {
            effect: s.score.effect,
            delta_chi2: s.score.delta_chi2,
            params: s.score.dof,
            m: std::array::from_fn(|i| sol.delta[s.m_at[i]]),
        })
    };
    let Some(taken) = candidacy(&scores[bi]) else { return Vec::new() };
    let others: Vec<Candidacy> = (0..scores.len())
        .filter(|&j| j != bi && scores[j].score.effect != taken.effect)
        .filter_map(|j| candidacy(&scores[j]))
        .collect();
    model_choice::alternatives(&taken, &others)
}

/// Hausman's specification test (Econometrica 46, 1251, 1978) of a drift curve against the free
/// drift, on M: if the curve holds the drift, both estimate M without bias and the curve's
/// estimate is the more precise, so their difference has covariance C_free − C_curve; a
/// difference beyond it says the curve leaves drift that M takes up. Returns the statistic and
/// its degrees of freedom (the rank of that covariance), both from the candidates' linearised
/// solutions; None when either has none.
fn curve_against_free_drift(curve: &Scored, free: &Scored) -> Option<(f64, usize)> {
    let (c, f) = (curve.solution.as_ref()?, free.solution.as_ref()?);
    if curve.m_at.len() != 9 || free.m_at.len() != 9 {
        return None;
    }
    let d = DVector::from_fn(9, |i, _| c.delta[curve.m_at[i]] - f.delta[free.m_at[i]]);
    let v = DMatrix::from_fn(9, 9, |i, j| f.cov[(free.m_at[i], free.m_at[j])] - c.cov[(curve.m_at[i], curve.m_at[j])]);
    let eig = nalgebra::SymmetricEigen::new(v);
    let largest = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    // Directions the free drift does not widen (to 1e-9 of the widest) carry no test.
    let kept: Vec<usize> = (0..9).filter(|&i| eig.eigenvalues[i] > 1e-9 * largest).collect();
    let stat = kept
        .iter()
        .map(|&i| {
            let u = eig.eigenvectors.column(i).dot(&d);
            u * u / eig.eigenvalues[i]
        })
        .sum();
    (!kept.is_empty()).then_some((stat, kept.len()))
}

/// Fits a scored candidate to the end.
struct CandidateFit<'a> {
    data: &'a LoopData,
    state: &'a Fitted,
    cands: &'a [Candidate],
    weights: [f64; 3],
}

impl CandidateFit<'_> {
    /// A candidate that cannot be fitted to the end (singular, or a parameter at its bound) is
    /// skipped with its reason and the next passing one is tried: one bad candidate never ends
    /// the calibration.
    fn fit(&self, scored: &Scored) -> Result<Fitted, String> {
        let (state, data) = (self.state, self.data);
        let sol = scored.solution.as_ref().ok_or_else(|| "its linearised fit is singular".to_string())?;
        let cand = &self.cands[scored.candidate];
        // A step solved without the replaced columns does not map onto the model's parameters:
        // the replacement starts at zero (the knots enter linearly; one pass places them).
        let mut start = if replaced(state, cand, data).is_empty() {
            start_model(state, cand, sol)
        } else {
            start_model_at_zero(state, cand)
        };
        if cand.effect.is_free_drift() {
            // The free drift replaces what it holds: a drift curve already in (with both, the
            // knots hold the curve's shape and its parameters run off) and, when each run has
            // a level of its own, a table tilt, whose only trace is a constant rate in each run
            // (with both, ε runs off along the null direction: −60° ± 5° on a 0.3° tilt).
            for e in state.model.effects.iter().filter(|e| replaced_by_free_drift(**e, data)) {
                start = start.without(*e);
            }
        }
        let f = fit(data, start, self.weights).map_err(|e| e.to_string())?;
        match f.at_bound().or_else(|| f.beyond_physics()) {
            Some(why) => Err(why),
            None if !f.converged => Err(not_converged(&f)),
            None => Ok(f),
        }
    }
}

/// BIC by which a drift alternative linear in its parameters may trail the best fitted one and
/// still be fitted. Its linearised χ² (the scoring pass's joint solution) is its fitted χ² but
/// for the coupling with the model's own non-linear parameters (a delay, a phase: ≪ 1 in χ²);
/// the warm-up's floor over its time constant ([`profile_floor`]) is at or below its fitted χ²
/// where that profile is convex;
/// 10 is the "very strong" evidence of Kass & Raftery (1995, §3.2) on the BIC scale, so an
/// alternative further behind cannot win by being fitted.
pub(crate) const DRIFT_BIC_MARGIN: f64 = 10.0;

/// Why a fit that ran out of passes is not one.
pub fn not_converged(f: &Fitted) -> String {
    let unit = if f.passes == 1 { "pass" } else { "passes" };
    format!("its fit had not converged after {} Gauss-Newton {unit}", f.passes)
}

/// The drift models are alternatives: the best-scoring variant of each that passed is compared
/// by BIC, and the lowest kept. Each is compared on its linearised χ² (the warm-up's on a floor
/// under it over its time constant, [`profile_floor`]) and fitted only when within
/// [`DRIFT_BIC_MARGIN`] of the best fitted so far. Returns every variant with
/// its χ² and BIC (fitted or linearised), and the chosen one (its index in `scores`, and its
/// fit); those that could not be fitted go into `skipped`.
fn best_drift(
    scores: &[Scored],
    fitter: &CandidateFit,
    n_total: u64,
    alpha: f64,
    skipped: &mut Vec<Skipped>,
) -> (Vec<DriftChoice>, Option<(usize, Fitted)>) {
    let ln_n = (n_total as f64).ln();
    let mut variants: Vec<(usize, f64, f64, bool)> = Vec::new();
    let mut seen: Vec<Effect> = Vec::new();
    for (i, scored) in scores.iter().enumerate().filter(|(_, s)| s.passed() && s.score.effect.is_drift()) {
        let sc = &scored.score;
        // Only the best-scoring variant of each: the warm-up's other time constants start the
        // same model elsewhere, and where the runs do not separate it every one failed alike
        // (six fits to convergence, 29 % of realistic-2speed-s101's CPU, for one line in the
        // skipped list).
        if seen.contains(&sc.effect) {
            continue;
        }
        seen.push(sc.effect);
        let (lin, shared) = sc.effect.params(&fitter.data.layout);
        let k = 3 * lin.len() + shared.len();
        let grid_chi2 = scored.solution.as_ref().map_or(f64::INFINITY, |s| s.chi2);
        // A variant held at a grid value of its shape parameter (the warm-up's time constant) is
        // compared at a floor under its profile over that parameter.
        let (chi2, comparable) = match sc.drift_tau_s {
            None => (grid_chi2, shared.is_empty()),
            Some(_) => profile_floor(scores, sc.effect).map_or((grid_chi2, false), |c| (c, true)),
        };
        variants.push((i, chi2, chi2 + k as f64 * ln_n, comparable));
    }
    variants.sort_by(|a, b| a.2.total_cmp(&b.2));
    let mut table = Vec::with_capacity(variants.len());
    let mut best: Option<(usize, Fitted, f64)> = None;
    for (i, chi2, linearised_bic, comparable) in variants {
        let effect = scores[i].score.effect;
        if comparable && best.as_ref().is_some_and(|b| linearised_bic >= b.2 + DRIFT_BIC_MARGIN) {
            table.push(DriftChoice { effect, chi2, bic: linearised_bic, fitted: false });
            continue;
        }
        match fitter.fit(&scores[i]) {
            Ok(f) => {
                let bic = linearised_bic - chi2 + f.solution.chi2;
                table.push(DriftChoice { effect, chi2: f.solution.chi2, bic, fitted: true });
                if best.as_ref().is_none_or(|b| bic < b.2) {
                    best = Some((i, f, bic));
                }
            }
            Err(why) => {
                if !skipped.iter().any(|s: &Skipped| s.effect == effect) {
                    skipped.push(Skipped { effect, why });
                }
            }
        }
    }
    let best = best.map(|b| (b.0, b.1));
    (table, free_drift_if_the_curve_biases_m(scores, fitter, alpha, best, skipped))
}

/// The chosen drift curve linear in its parameters, unless it biases M
/// (`curve_against_free_drift`, at `alpha`) against the free drift that scored best: then that free drift, fitted, and the curve goes to
/// `skipped` with the test. A random walk that a quadratic took by BIC left 0.006° and 42 ppm in
/// M at exit 0, 5.6σ off (trust bench, 180, 90 °/s, random walk, seed 5): BIC chooses the drift
/// that explains the residual with fewest parameters, not the one that leaves M alone.
fn free_drift_if_the_curve_biases_m(
    scores: &[Scored],
    fitter: &CandidateFit,
    alpha: f64,
    best: Option<(usize, Fitted)>,
    skipped: &mut Vec<Skipped>,
) -> Option<(usize, Fitted)> {
    let (i, fitted) = best?;
    let curve = &scores[i];
    // A curve scored at a grid value of its shape parameter (the warm-up's time constant) has no
    // linearised M of its fitted self to test: on a tripled warm-up the grid's M differed from
    // the free drift's, and the warm-up that fitted the drift exactly gave way.
    if curve.score.effect.is_free_drift() || curve.score.drift_tau_s.is_some() {
        return Some((i, fitted));
    }
    let free = scores
        .iter()
        .enumerate()
        .filter(|(_, s)| s.passed() && s.score.effect.is_free_drift())
        .max_by(|a, b| a.1.score.significance_sigma.total_cmp(&b.1.score.significance_sigma));
    let Some((j, free)) = free else { return Some((i, fitted)) };
    match curve_against_free_drift(curve, free) {
        Some((stat, dof)) if stat > crate::calib::analysis::stats::chi2_upper_quantile(dof, alpha) => {
            match fitter.fit(free) {
                Ok(f) => {
                    skipped.push(Skipped {
                        effect: curve.score.effect,
                        why: format!(
                            "its M differs from the free drift's by χ² = {stat:.1} for {dof} degrees of freedom (Hausman's test): the curve leaves drift that M takes up"
                        ),
                    });
                    Some((j, f))
                }
                Err(_) => Some((i, fitted)),
            }
        }
        _ => Some((i, fitted)),
    }
}

/// A floor under the least χ² of `effect` over its shape parameter (the warm-up's time constant
/// τ), from its variants scored at the grid values (`Score::drift_tau_s`, a factor 2 apart),
/// taking the profile to be convex in ln τ (engineering judgement: one exponential's fit
/// worsens steadily as its time constant leaves the best). A convex profile falls, beyond the
/// best grid value, by no more per doubling than it fell over the doubling before it: within
/// the grid, by at most the larger of the two neighbours' rises over one step; at the grid's
/// edge, by the last step's fall for every further doubling up to τ's bound
/// ([`DRIFT_TAU_RANGE_S`]). A parabola through the three was tried and is no floor: with the
/// warm-up tripled (trust bench, seed 2) it put the warm-up 1165 above the χ² its fit reached,
/// so a better model went unfitted and the answer ended 6σ off. `None` with fewer than two grid
/// values.
fn profile_floor(scores: &[Scored], effect: Effect) -> Option<f64> {
    let mut grid: Vec<(f64, f64)> = scores
        .iter()
        .filter(|s| s.score.effect == effect)
        .filter_map(|s| Some((s.score.drift_tau_s?, s.solution.as_ref()?.chi2)))
        .collect();
    grid.sort_by(|a, b| a.0.total_cmp(&b.0));
    let best = (0..grid.len()).min_by(|&a, &b| grid[a].1.total_cmp(&grid[b].1))?;
    let (tau, y) = grid[best];
    let rise = |neighbour: usize| grid[neighbour].1 - y;
    let doublings = |bound_s: f64| (bound_s / tau).ln().abs() / std::f64::consts::LN_2;
    match best {
        _ if grid.len() < 2 => None,
        0 => Some(y - doublings(DRIFT_TAU_RANGE_S.0).max(1.0) * rise(1)),
        b if b + 1 == grid.len() => Some(y - doublings(DRIFT_TAU_RANGE_S.1).max(1.0) * rise(b - 1)),
        b => Some(y - rise(b - 1).max(rise(b + 1))),
    }
}

/// Whether adding the free drift takes `e` out of the model: every drift curve, and the table
/// tilt when the free drift's levels hold its constant rate (see [`step`]).
pub fn replaced_by_free_drift(e: Effect, data: &LoopData) -> bool {
    e.is_drift() || (e == Effect::TableTilt && !free_drift_keeps_constant_rates(data))
}

/// Whether the free drift leaves the constant rate terms (θ2'·M R_qᵀ e_z2, a table tilt's
/// θ1'·sin ε) to the model: it follows the offset continuously through runs at different rates,
/// where those terms step and the offset does not. When every stretch is one run (or one rate),
/// each level holds them.
pub fn free_drift_keeps_constant_rates(data: &LoopData) -> bool {
    let rates: Vec<f64> = data.kin.runs.iter().map(|r| r.commanded_rate_dps).collect();
    data.layout.shares_levels_across_rates(&rates)
}

/// `fitted`'s model without `effect`, moved to the smaller model's linearised optimum from the
/// sums `fitted`'s last pass holds (no pass of its own): taking an effect out moves the
/// parameters correlated with it by up to several σ, which the fit would otherwise spend a pass
/// on. With N, b the full normal equations at the point x₀ of those sums, K the kept parameters
/// and R the effect's, the move is N_KK·d_K = b_K + N_KR·x_R (x_R going to 0). The model already
/// holds the full fit's last (sub-0.1 σ) step beyond x₀, so that step is taken back out.
pub fn start_without(fitted: &Fitted, effect: Effect, weights: [f64; 3]) -> crate::calib::engine::Model {
    let mut start = fitted.model.without(effect);
    let model = &fitted.model;
    let (nl, ns) = (model.lin.len(), model.shared.len());
    let last = &fitted.solution.delta;
    let Some(total) = Gram::sum(&fitted.per_run) else { return start };
    if last.len() != 3 * nl + ns {
        // Some shared parameter was held in the last pass: its step is not in `last`.
        return start;
    }
    let (lin, shared) = effect.params(&model.layout);
    let kept_lin: Vec<usize> = (0..nl).filter(|&j| !lin.contains(&model.lin[j])).collect();
    let kept_shared: Vec<usize> = (0..ns).filter(|&k| !shared.contains(&model.shared[k])).collect();
    let keep: Vec<usize> = (0..3)
        .flat_map(|a| kept_lin.iter().map(move |&j| a * nl + j))
        .chain(kept_shared.iter().map(|&k| 3 * nl + k))
        .collect();
    let value = |i: usize| if i < 3 * nl { model.beta[i / nl][i % nl] } else { model.theta[i - 3 * nl] };
    let gone: Vec<usize> = (0..3 * nl + ns).filter(|i| !keep.contains(i)).collect();
    let (n_mat, b) = normal_equations(&total, &full_selection(model), weights, &model.priors());
    let n_kk = DMatrix::from_fn(keep.len(), keep.len(), |i, j| n_mat[(keep[i], keep[j])]);
    let x_r = DVector::from_fn(gone.len(), |i, _| value(gone[i]) - last[gone[i]]);
    let n_kr = DMatrix::from_fn(keep.len(), gone.len(), |i, j| n_mat[(keep[i], gone[j])]);
    let rhs = DVector::from_fn(keep.len(), |i, _| b[keep[i]]) + n_kr * x_r;
    let Some(chol) = n_kk.cholesky() else { return start };
    let step = chol.solve(&rhs) - DVector::from_fn(keep.len(), |i, _| last[keep[i]]);
    let held = vec![false; start.shared.len()];
    apply_step(&mut start, kept_lin.len(), &step, &held);
    start
}

/// An effect taken out of the model because a later one made it redundant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dropped {
    /// The effect dropped.
    pub effect: Effect,
    /// The effect whose arrival made it redundant.
    pub after: Effect,
    /// Its Wald statistic θᵀ C⁻¹ θ in the model before it was dropped (the χ² its removal
    /// costs, to first order).
    pub wald_chi2: f64,
    /// The χ² point at α it fell below.
    pub threshold: f64,
}

/// The effect of `fitted`'s model that its runs need least, if they do not need it: its
/// parameters' Wald statistic θᵀ C⁻¹ θ (χ²-distributed if the effect is absent) is below the
/// upper α point. Leaving is tested at α while entering is at α/m, so an effect cannot cycle in
/// and out. The free drift (whose absence is not θ = 0: its knots hold each run's level), Earth's
/// rotation (known physics) and `keep` (just added) are never dropped. Backward elimination is what makes the forward steps
/// safe: an effect that entered early can be made redundant by a later one (a table tilt, whose
/// only trace is a constant rate per run, once each run has its own offset level).
pub fn least_needed(fitted: &Fitted, alpha: f64, keep: Effect) -> Option<(Effect, f64, f64)> {
    let mut worst: Option<(Effect, f64, f64, f64)> = None;
    for &e in &fitted.model.effects {
        if e == keep || e.is_free_drift() || e.is_earth() {
            continue;
        }
        let (lin, mut shared) = e.params(&fitted.model.layout);
        // A shared parameter that only shapes the effect's columns (a warm-up's time constant)
        // does not say whether it is there: an amplitude of 0 is absent whatever its shape.
        if !lin.is_empty() {
            shared.clear();
        }
        let mut idx: Vec<usize> = Vec::new();
        let mut val: Vec<f64> = Vec::new();
        for c in &lin {
            for a in 0..3 {
                if let (Some(i), Some(v)) = (fitted.lin_index(a, *c), fitted.model.beta_of(a, *c)) {
                    idx.push(i);
                    val.push(v);
                }
            }
        }
        for p in &shared {
            if let (Some(i), Some(v)) = (fitted.shared_index(*p), fitted.model.theta_of(*p)) {
                idx.push(i);
                val.push(v);
            }
        }
        let c = DMatrix::from_fn(idx.len(), idx.len(), |i, j| fitted.solution.cov[(idx[i], idx[j])]);
        let Some(ci) = c.cholesky() else { continue };
        let v = DVector::from_vec(val);
        let wald = v.dot(&ci.solve(&v));
        let threshold = crate::calib::analysis::stats::chi2_upper_quantile(idx.len(), alpha);
        let sig = crate::calib::analysis::stats::chi2_to_sigma(idx.len(), wald);
        if wald < threshold && worst.as_ref().is_none_or(|w| sig < w.3) {
            worst = Some((e, wald, threshold, sig));
        }
    }
    worst.map(|w| (w.0, w.1, w.2))
}

/// How much fitting the columns `own` of axis `a` to the residual left by `delta` (a step
/// of selection `sel`) lowers the residual sum of squares of the sums `g`: bᵀA⁻¹b with A the
/// columns' Gram matrix and b their correlation with that residual.
fn own_level_gain(g: &Gram, a: usize, own: &[usize], sel: &Selection, delta: &DVector<f64>) -> f64 {
    let l = g.l;
    let nl = sel.lin.len();
    let step: Vec<(usize, f64)> = sel
        .lin
        .iter()
        .enumerate()
        .map(|(p, &c)| (c, delta[a * nl + p]))
        .chain(sel.shared.iter().enumerate().map(|(q, &c)| (c, delta[3 * nl + q])))
        .collect();
    let b = DVector::from_iterator(
        own.len(),
        own.iter().map(|&i| g.xte[a][i] - step.iter().map(|&(j, d)| g.xtx[a][i * l + j] * d).sum::<f64>()),
    );
    let m = DMatrix::from_fn(own.len(), own.len(), |i, j| g.xtx[a][own[i] * l + own[j]]);
    m.cholesky().map_or(0.0, |c| b.dot(&c.solve(&b)))
}

/// A run is held out only if the other runs determine every element of M to within this factor
/// of the σ the full fit gives: 10× is a rank loss, not a weaker but honest prediction (dropping
/// one of four runs costs at most √(4/3)·a few for a well-posed model).
const HELD_OUT_MAX_SIGMA_RATIO: f64 = 10.0;

/// Prediction of one held-out run from a fit to the others.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HeldOut {
    /// Run number held out.
    pub run: usize,
    /// RMS prediction error per axis, counts (noise included).
    pub rms_counts: [f64; 3],
}

/// For every run whose removal leaves a solvable system: fit the other runs, predict it.
///
/// A run is only held out when another run has its pose: one pose alone leaves M unidentified
/// (EXCITER.md: two poses give two planes per axis), so "predicting" a lone pose would measure
/// nothing but the rank deficiency.
pub fn held_out(fitted: &Fitted, weights: [f64; 3], run_numbers: &[usize], poses: &[Pose]) -> Vec<HeldOut> {
    let sel = full_selection(&fitted.model);
    let mut out = Vec::new();
    for (r, g) in fitted.per_run.iter().enumerate() {
        if !poses.iter().enumerate().any(|(i, &p)| i != r && p == poses[r]) {
            continue;
        }
        let Some(others) = Gram::sum(fitted.per_run.iter().enumerate().filter(|(i, _)| *i != r).map(|(_, g)| g)) else {
            continue;
        };
        // The free drift's knots that only the held-out run sees are its own level, which no
        // other run can predict: they are left out of the fit to the others and fitted to the
        // run itself. A knot it shares with a run beside it in its stretch is predicted.
        let own = |c: usize| match fitted.model.lin[c] {
            LinCol::DriftKnot { stretch, knot, spacing_s } => {
                fitted.model.layout.knot_only_in_run(usize::from(stretch), knot, spacing_s, r)
            }
            _ => false,
        };
        let others_sel =
            Selection { lin: sel.lin.iter().copied().filter(|&c| !own(c)).collect(), shared: sel.shared.clone() };
        let Some(sol) = solve_joint(&others, &others_sel, weights, &fitted.model.priors()) else {
            continue;
        };
        // Without this run the others may not determine M: with g-sensitivity a pose left at
        // one speed cannot tell the gravity term from its columns of M. A "prediction" then
        // measures only that rank loss, so the run is not held out.
        let omega_sigma_ratio = (0..3)
            .flat_map(|a| (0..3).map(move |k| (a, k)))
            .filter_map(|(a, k)| {
                let col = fitted.model.lin.iter().position(|&q| q == LinCol::Omega(k))?;
                let full = fitted.lin_index(a, LinCol::Omega(k))?;
                let p = a * others_sel.lin.len() + others_sel.lin.iter().position(|&q| q == col)?;
                let full_sigma = fitted.solution.cov[(full, full)].max(f64::MIN_POSITIVE).sqrt();
                Some(sol.cov[(p, p)].max(0.0).sqrt() / full_sigma)
            })
            .fold(0.0, f64::max);
        if omega_sigma_ratio > HELD_OUT_MAX_SIGMA_RATIO {
            continue;
        }
        let mut rss = residual_after(g, &others_sel, &sol.delta);
        let own_cols: Vec<usize> = sel.lin.iter().copied().filter(|&c| own(c)).collect();
        if !own_cols.is_empty() {
            for (a, rss_a) in rss.iter_mut().enumerate() {
                *rss_a -= own_level_gain(g, a, &own_cols, &others_sel, &sol.delta);
            }
        }
        out.push(HeldOut {
            run: run_numbers[r],
            rms_counts: std::array::from_fn(|a| (rss[a] / g.n[a].max(1) as f64).sqrt()),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The warm-up's variants scored on its grid with χ² = `profile(τ)`.
    fn scored_on_grid(profile: impl Fn(f64) -> f64) -> Vec<Scored> {
        [15.0, 30.0, 60.0, 120.0, 240.0, 480.0, 960.0]
            .into_iter()
            .enumerate()
            .map(|(i, tau_s)| Scored {
                score: Score {
                    effect: Effect::DriftWarmUp,
                    drift_tau_s: Some(tau_s),
                    delta_chi2: 0.0,
                    dof: 4,
                    threshold: 0.0,
                    significance_sigma: 0.0,
                    known_physics: false,
                },
                candidate: i,
                solution: Some(crate::calib::engine::JointSolution {
                    delta: DVector::zeros(1),
                    cov: DMatrix::identity(1, 1),
                    chi2: profile(tau_s),
                    rss: [0.0; 3],
                    n: [1; 3],
                }),
                m_at: Vec::new(),
            })
            .collect()
    }

    /// A convex profile's least value is never below the floor, wherever it lies: inside the
    /// grid, beyond its long end, beyond its short end; and the floor is not far below it.
    #[test]
    fn a_time_constants_profile_floor_is_under_its_least_value() {
        let parabola = |tau_min_s: f64| move |tau_s: f64| 5.0 + 1000.0 * (tau_s / tau_min_s).ln().powi(2);
        for tau_min_s in [100.0, 85.0, 3000.0, 4.0] {
            let floor = profile_floor(&scored_on_grid(parabola(tau_min_s)), Effect::DriftWarmUp).expect("a floor");
            assert!(floor <= 5.0, "least at {tau_min_s} s: floor {floor}");
        }
        // Inside, the floor is one step's rise below the best grid value: 1000·ln²2 = 480.
        let floor = profile_floor(&scored_on_grid(parabola(120.0)), Effect::DriftWarmUp).expect("a floor");
        assert!((floor - (5.0 - 1000.0 * std::f64::consts::LN_2.powi(2))).abs() < 1e-9, "{floor}");
        assert_eq!(profile_floor(&scored_on_grid(parabola(100.0)), Effect::DriftPolynomial), None);
    }

    /// A scored drift whose M (the first nine parameters) moved by `m` with covariance
    /// `var`·I, and one more parameter of its own.
    fn scored_drift(effect: Effect, m: f64, var: f64) -> Scored {
        let mut cov = DMatrix::identity(10, 10) * var;
        cov[(9, 9)] = 1.0;
        Scored {
            score: Score {
                effect,
                drift_tau_s: None,
                delta_chi2: 100.0,
                dof: 3,
                threshold: 10.0,
                significance_sigma: 5.0,
                known_physics: false,
            },
            candidate: 0,
            solution: Some(crate::calib::engine::JointSolution {
                delta: DVector::from_fn(10, |i, _| if i < 9 { m } else { 0.0 }),
                cov,
                chi2: 0.0,
                rss: [0.0; 3],
                n: [1; 3],
            }),
            m_at: (0..9).collect(),
        }
    }

    /// Hausman's statistic is the difference of the two M against the difference of their
    /// covariances: 9 × 2²/2 = 18 for a difference of 2 in each element with variances 1 and 3;
    /// where the free drift widens no element, no test.
    #[test]
    fn a_curve_is_tested_against_the_free_drift_on_m() {
        let curve = scored_drift(Effect::DriftPolynomial, 0.0, 1.0);
        let free = scored_drift(Effect::DriftKnots(40), 2.0, 3.0);
        let (stat, dof) = curve_against_free_drift(&curve, &free).expect("a test");
        assert!((stat - 18.0).abs() < 1e-9, "{stat}");
        assert_eq!(dof, 9);
        let alike = scored_drift(Effect::DriftKnots(40), 2.0, 1.0);
        assert_eq!(curve_against_free_drift(&curve, &alike), None);
    }
}
