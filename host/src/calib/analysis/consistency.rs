//! Do the runs agree? What each group of runs (one signed speed) says about M, tested against
//! the others.
//!
//! An effect outside the catalogue that changes with speed is absorbed into M by the joint fit
//! and can leave a white residual; but then the runs at one speed want another M than the runs
//! at the other. The test adds, for every group but the first, its own change of the nine
//! elements of M to the final model, and asks whether the data want it: the score (Lagrange
//! multiplier) statistic sᵀ I⁻¹ s, with s the residual's gradient along the added columns and I
//! their information beyond the model's, is χ² with as many degrees of freedom as the runs
//! separate if the groups agree (Rao 1948; Engle, *Handbook of Econometrics* II, ch. 13). It is
//! read from the per-run sums the final fit already holds: no pass of its own.
//!
//! Nine elements per group spread the evidence thin when what changes with speed is the
//! sensor's orientation: a mount, fixture or bearing that gives under the table's load turns
//! every axis alike, by a rotation φ fixed in the table frame O2 (where the load is), three
//! numbers where the omnibus test spends nine. So each group is also tested for such a turn
//! (in a pose with rotation Rᵀ from O2 to the package, M's rows turned by ψ = Rᵀ·φ): the same
//! score statistic on those three columns, at the family-wise level it shares with the omnibus
//! test (Bonferroni). A turn too small for either test still biases M, and a turn that is the
//! same at every speed is M itself (`docs/trust.md`, "M changing with speed").
//!
//! Where the model holds one offset through stretches of capture (a file per run, a remount)
//! whose levels may differ, those levels stand in for a change with speed: a turn about the
//! table's in-plane axes moves θ2'·M·Rᵀe_z2 into every axis's level, and so does the offset's
//! wander between captures. The consider covariance carries the levels in σ
//! (`effects::stretch_level`); here each stretch after the first whose runs are all of one group
//! gets a level of its own as a nuisance of the test (its efficient score, Rao 1948), so that
//! levels which differ are not read as M changing with speed. A change shows in the table-rate
//! sinusoids whatever the levels do.

use crate::calib::analysis::stats::{chi2_to_sigma, chi2_upper_quantile};
use crate::calib::data::layout::Stretch;
use crate::calib::engine::{full_selection, normal_equations, Fitted, Gram, LinCol, LoopData};
use crate::calib::result::axes::AXES;
use crate::geometry::Pose;
use nalgebra::{Cholesky, DMatrix, DVector, Dyn, Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::ops::AddAssign;

/// A direction of the added columns keeps less than this fraction of its own information once
/// the model has taken its share: the model already spends the difference between the groups
/// there (g-sensitivity is told from M only by the speeds), or the groups do not see it (one
/// pose at a speed sees two of M's three columns). Such directions are left out of the test and
/// its degrees of freedom: 1 % (engineering judgement; a test there would weigh a residual by
/// 100× its own information).
const SURVIVING_FRACTION: f64 = 0.01;

/// Two signed speeds are one group when they differ by less than this fraction (the same
/// commanded rate with a slightly different steady one).
const SAME_RATE_FRACTION: f64 = 0.05;

/// What one group says about M, against the first group.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroupDifference {
    /// The group's signed base-table rate, °/s.
    pub rate_dps: f64,
    /// The first group's, °/s.
    pub reference_rate_dps: f64,
    /// Its change of M, counts per °/s (row = axis), where the runs separate it.
    pub delta_m: [[f64; 3]; 3],
    /// Its σ.
    pub delta_m_sigma: [[f64; 3]; 3],
    /// The largest |Δ/σ| of an element.
    pub max_z: f64,
    /// That element's change in ppm of the axis's sensitivity.
    pub max_ppm: f64,
    /// That element, e.g. `m_x.omega_y`.
    pub element: String,
}

/// One group's sensor turned against the first group's by a small rotation φ in the table frame
/// O2: the score test of every row of M turned by φ, seen from the package in each pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroupTurn {
    /// The group's signed base-table rate, °/s.
    pub rate_dps: f64,
    /// The first group's, °/s.
    pub reference_rate_dps: f64,
    /// The turn's rotation vector in the table frame O2, degrees (about its x, y, z); 0 along a
    /// direction the runs do not separate from the model (not tested).
    pub turn_deg: [f64; 3],
    /// Its σ (0 along such a direction).
    pub turn_sigma_deg: [f64; 3],
    /// The score statistic.
    pub chi2: f64,
    /// Its degrees of freedom (the turn's directions the runs separate, at most 3).
    pub dof: usize,
    /// The upper point it is tested against (the family's level shared with the omnibus test).
    pub threshold: f64,
}

impl GroupTurn {
    /// Whether the group's axes turned beyond chance.
    pub fn significant(&self) -> bool {
        self.chi2 > self.threshold
    }
}

/// The test of all groups together.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Consistency {
    /// The score statistic.
    pub chi2: f64,
    /// Its degrees of freedom.
    pub dof: usize,
    /// The upper α point it is tested against.
    pub threshold: f64,
    /// The statistic as a normal deviate.
    pub significance_sigma: f64,
    /// Each group against the first.
    pub groups: Vec<GroupDifference>,
    /// Each group's turn against the first (where the runs separate one).
    #[serde(default)]
    pub turns: Vec<GroupTurn>,
}

impl Consistency {
    /// Whether the groups disagree beyond chance: all their elements together, or one group's
    /// axes turned together.
    pub fn disagrees(&self) -> bool {
        self.chi2 > self.threshold || self.turns.iter().any(GroupTurn::significant)
    }
}

/// Run indices grouped by signed speed, in order of first appearance.
fn groups(data: &LoopData) -> Vec<(f64, Vec<usize>)> {
    let mut out: Vec<(f64, Vec<usize>)> = Vec::new();
    for (r, k) in data.kin.runs.iter().enumerate() {
        let rate = k.steady_rate_dps;
        match out.iter_mut().find(|(g, _)| (g - rate).abs() <= SAME_RATE_FRACTION * g.abs().max(rate.abs())) {
            Some((_, runs)) => runs.push(r),
            None => out.push((rate, vec![r])),
        }
    }
    out
}

/// The test on a converged fit with its χ² weights, at family-wise level `alpha`; None with
/// one group, or when the groups separate nothing.
pub fn consistency(data: &LoopData, f: &Fitted, weights: [f64; 3], k: [f64; 3], alpha: f64) -> Option<Consistency> {
    let groups = groups(data);
    if groups.len() < 2 {
        return None;
    }
    let sel = full_selection(&f.model);
    let total = Gram::sum(&f.per_run)?;
    let (n_mat, b_tot) = normal_equations(&total, &sel, weights, &f.model.priors());
    let model_chol = n_mat.clone().cholesky()?;
    // The sums were taken before the fit's last (negligible) step: the gradient after it.
    let delta = model_chol.solve(&b_tot);
    let m_idx: Vec<usize> = (0..3)
        .flat_map(|a| (0..3).map(move |j| (a, j)))
        .map(|(a, j)| f.lin_index(a, LinCol::Omega(j)))
        .collect::<Option<_>>()?;
    let levels = Levels::of(data, f, weights, &delta, &groups);
    // The null model: the fit's, with the stretches' levels where they are free.
    let (chol, nuisance) = match levels.as_ref().and_then(|l| l.null(&n_mat)) {
        Some((chol, w)) => (chol, Some(w)),
        None => (model_chol, None),
    };
    let np = chol.l().nrows();
    let extra = groups.len() - 1;
    let ne = 9 * extra;
    let mut cross = DMatrix::zeros(np, ne);
    let mut own = DMatrix::zeros(ne, ne);
    let mut score = DVector::zeros(ne);
    // Per group but the first, per pose: its runs' block of ΔM's columns, and the pose's
    // rotation from the table frame to the package's.
    let mut blocks: Vec<Vec<(Added, Matrix3<f64>)>> = Vec::with_capacity(extra);
    for (gi, (_, runs)) in groups.iter().skip(1).enumerate() {
        let mut per_pose = Vec::new();
        for pose in Pose::ALL {
            let of_pose: Vec<usize> = runs.iter().copied().filter(|&r| data.kin.runs[r].pose == pose).collect();
            let Some(&first) = of_pose.first() else { continue };
            let Some(g) = Gram::sum(of_pose.iter().map(|&r| &f.per_run[r])) else { continue };
            let (ng, bg) = normal_equations(&g, &sel, weights, &[]);
            let mut added = Added::of(&ng, &(bg - &ng * &delta), &m_idx);
            if let (Some(l), Some(w)) = (&levels, &nuisance) {
                added = added.beside_levels(&l.cross_with(data, f, weights, &of_pose, &m_idx), w);
            }
            let at = 9 * gi..9 * gi + 9;
            score.rows_mut(at.start, 9).add_assign(&added.score);
            cross.columns_mut(at.start, 9).add_assign(&added.cross);
            own.view_mut((at.start, at.start), (9, 9)).add_assign(&added.own);
            // The pose's rotation as the runs' kinematics hold it.
            per_pose.push((added, data.kin.runs[first].rot_t));
        }
        blocks.push(per_pose);
    }
    let info = &own - cross.transpose() * chol.solve(&cross);
    let (inv, dof) = surviving_inverse(&info, &own)?;
    let est = &inv * &score;
    let chi2 = score.dot(&est);
    // One family: the omnibus test and a turn per group, at level α shared equally.
    let alpha_each = alpha / groups.len() as f64;
    let threshold = chi2_upper_quantile(dof, alpha_each);
    let m = f.model.m();
    let turns = groups
        .iter()
        .skip(1)
        .zip(&blocks)
        .filter_map(|((rate, _), per_pose)| {
            let t = turn_test(&m, &chol, per_pose)?;
            let threshold = chi2_upper_quantile(t.dof, alpha_each);
            Some(GroupTurn { rate_dps: *rate, reference_rate_dps: groups[0].0, threshold, ..t })
        })
        .collect();
    let group_diffs = groups
        .iter()
        .skip(1)
        .enumerate()
        .map(|(gi, (rate, _))| {
            let at = |a: usize, j: usize| 9 * gi + 3 * a + j;
            let delta_m = std::array::from_fn(|a| std::array::from_fn(|j| est[at(a, j)]));
            let delta_m_sigma =
                std::array::from_fn(|a| std::array::from_fn(|j| inv[(at(a, j), at(a, j))].max(0.0).sqrt()));
            let mut worst = (0.0, 0.0, String::new());
            for a in 0..3 {
                for j in 0..3 {
                    let (d, s): (f64, f64) = (delta_m[a][j], delta_m_sigma[a][j]);
                    if s > 0.0 && (d / s).abs() > worst.0 {
                        worst = ((d / s).abs(), d / k[a] * 1e6, format!("m_{}.omega_{}", AXES[a], AXES[j]));
                    }
                }
            }
            GroupDifference {
                rate_dps: *rate,
                reference_rate_dps: groups[0].0,
                delta_m,
                delta_m_sigma,
                max_z: worst.0,
                max_ppm: worst.1,
                element: worst.2,
            }
        })
        .collect();
    Some(Consistency { chi2, dof, threshold, significance_sigma: chi2_to_sigma(dof, chi2), groups: group_diffs, turns })
}

/// The pseudo-inverse of the information `info` of some added columns on the directions that
/// keep more than [`SURVIVING_FRACTION`] of their own information (`own`: the columns' Gram
/// matrix), and how many there are; None when none does or the decomposition fails.
fn surviving_inverse(info: &DMatrix<f64>, own: &DMatrix<f64>) -> Option<(DMatrix<f64>, usize)> {
    let n = info.nrows();
    // In units of the columns' own information, so that an eigenvalue is the fraction that
    // survives the model.
    let scale = DVector::from_fn(n, |i, _| if own[(i, i)] > 0.0 { 1.0 / own[(i, i)].sqrt() } else { 0.0 });
    let d = DMatrix::from_diagonal(&scale);
    let info_n = &d * info * &d;
    let eig = ((&info_n + info_n.transpose()) * 0.5).symmetric_eigen();
    if eig.eigenvalues.iter().any(|l| !l.is_finite()) {
        return None;
    }
    let mut inv_n = DMatrix::zeros(n, n);
    let mut dof = 0;
    for (i, &l) in eig.eigenvalues.iter().enumerate() {
        if l > SURVIVING_FRACTION {
            let u = eig.eigenvectors.column(i);
            inv_n += u * u.transpose() / l;
            dof += 1;
        }
    }
    (dof > 0).then(|| (&d * inv_n * &d, dof))
}

/// A level of its own (per axis) for every stretch after the first whose runs are all of one
/// group, where the model holds one offset through the stretches: its columns' cross-products
/// with the model's parameters and with each other, and the residual's gradient along them, from
/// the fit's per-run sums (a level is the offset's column over its stretch's runs). Such a
/// stretch's level cannot be told from its group's own change of level; one that runs of several
/// groups share (the runs of a pose in one capture) is pinned by them, and a change with speed
/// keeps showing in how its groups' levels differ.
struct Levels {
    /// Per level: its stretch and axis.
    of: Vec<(usize, usize)>,
    /// The offset's index among the model's parameters, per axis.
    one: [usize; 3],
    cross: DMatrix<f64>,
    own: DMatrix<f64>,
    score: DVector<f64>,
}

impl Levels {
    /// None where no stretch after the first is of one group ([`groups`]), or the free drift
    /// already gives each its level.
    fn of(
        data: &LoopData,
        f: &Fitted,
        weights: [f64; 3],
        delta: &DVector<f64>,
        groups: &[(f64, Vec<usize>)],
    ) -> Option<Self> {
        if f.model.effects.iter().any(|e| e.is_free_drift()) {
            return None;
        }
        let mut group_of_run = vec![0; data.kin.runs.len()];
        for (g, (_, runs)) in groups.iter().enumerate() {
            runs.iter().for_each(|&r| group_of_run[r] = g);
        }
        let one_group = |s: &Stretch| s.runs.clone().all(|r| group_of_run[r] == group_of_run[s.runs.start]);
        let of: Vec<(usize, usize)> = (data.layout.stretches.iter().enumerate().skip(1))
            .filter(|(_, st)| one_group(st))
            .flat_map(|(s, _)| (0..3).map(move |a| (s, a)))
            .collect();
        if of.is_empty() {
            return None;
        }
        let one: [usize; 3] = [0, 1, 2].map(|a| f.lin_index(a, LinCol::One)).map(Option::unwrap_or_default);
        let np = delta.len();
        let (mut cross, mut own, mut score) =
            (DMatrix::zeros(np, of.len()), DMatrix::zeros(of.len(), of.len()), DVector::zeros(of.len()));
        // A stretch's three levels (one per axis) are consecutive in `of`.
        for (l0, &(s, _)) in of.iter().enumerate().step_by(3) {
            let (ns, bs) = Self::normal(data, f, weights, s, &[])?;
            let grad = bs - &ns * delta;
            for (a, &o) in one.iter().enumerate() {
                cross.set_column(l0 + a, &ns.column(o));
                own[(l0 + a, l0 + a)] = ns[(o, o)];
                score[l0 + a] = grad[o];
            }
        }
        Some(Self { of, one, cross, own, score })
    }

    /// The normal equations of the fit's sums over stretch `s`'s runs (those among `only`, when
    /// given); None when it has none.
    fn normal(
        data: &LoopData,
        f: &Fitted,
        weights: [f64; 3],
        s: usize,
        only: &[usize],
    ) -> Option<(DMatrix<f64>, DVector<f64>)> {
        let runs = (0..f.per_run.len())
            .filter(|&r| data.layout.run_stretch.get(r) == Some(&s) && (only.is_empty() || only.contains(&r)));
        let g = Gram::sum(runs.map(|r| &f.per_run[r]))?;
        Some(normal_equations(&g, &full_selection(&f.model), weights, &[]))
    }

    /// The null model's normal matrix with the levels beside the model's `n_mat`, factored, and
    /// N⁻¹·(0, levels' gradient): what the efficient score of an added column subtracts. None
    /// when the levels and the model are not separable (the test then keeps one offset).
    fn null(&self, n_mat: &DMatrix<f64>) -> Option<(Cholesky<f64, Dyn>, DVector<f64>)> {
        let (np, nl) = (n_mat.nrows(), self.of.len());
        let mut ext = DMatrix::zeros(np + nl, np + nl);
        ext.view_mut((0, 0), (np, np)).copy_from(n_mat);
        ext.view_mut((0, np), (np, nl)).copy_from(&self.cross);
        ext.view_mut((np, 0), (nl, np)).copy_from(&self.cross.transpose());
        ext.view_mut((np, np), (nl, nl)).copy_from(&self.own);
        let chol = ext.cholesky()?;
        let mut grad = DVector::zeros(np + nl);
        grad.rows_mut(np, nl).copy_from(&self.score);
        let w = chol.solve(&grad);
        Some((chol, w))
    }

    /// The levels' cross-products with the nine columns of ΔM over runs `runs` (levels × 9).
    fn cross_with(
        &self,
        data: &LoopData,
        f: &Fitted,
        weights: [f64; 3],
        runs: &[usize],
        m_idx: &[usize],
    ) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(self.of.len(), 9);
        // A stretch's three levels are consecutive in `of`: one sum of its runs serves them.
        for (l0, &(s, _)) in self.of.iter().enumerate().step_by(3) {
            if let Some((ns, _)) = Self::normal(data, f, weights, s, runs) {
                for (a, &o) in self.one.iter().enumerate() {
                    for c in 0..9 {
                        out[(l0 + a, c)] = ns[(o, m_idx[c])];
                    }
                }
            }
        }
        out
    }
}

/// Some runs' block of the nine columns of a change ΔM of M (axis-major): their cross-products
/// with the model's parameters, with each other, and the residual's gradient along them.
struct Added {
    cross: DMatrix<f64>,
    own: DMatrix<f64>,
    score: DVector<f64>,
}

impl Added {
    /// From the runs' normal equations `ng` and gradient `grad`; `m_idx`: M's elements among the
    /// parameters.
    fn of(ng: &DMatrix<f64>, grad: &DVector<f64>, m_idx: &[usize]) -> Self {
        Self {
            cross: DMatrix::from_fn(ng.nrows(), 9, |p, c| ng[(p, m_idx[c])]),
            own: DMatrix::from_fn(9, 9, |c, d| ng[(m_idx[c], m_idx[d])]),
            score: DVector::from_fn(9, |c, _| grad[m_idx[c]]),
        }
    }

    /// The same columns against a null model with the stretches' levels beside the model's
    /// parameters: `levels` their cross-products with the columns (levels × 9), `w` the null
    /// model's N⁻¹·(0, levels' gradient). The cross-products gain the levels' rows, and the
    /// gradient becomes the efficient score, what is left once the levels take their share.
    fn beside_levels(self, levels: &DMatrix<f64>, w: &DVector<f64>) -> Self {
        let (np, nl) = (self.cross.nrows(), levels.nrows());
        let mut cross = DMatrix::zeros(np + nl, 9);
        cross.view_mut((0, 0), (np, 9)).copy_from(&self.cross);
        cross.view_mut((np, 0), (nl, 9)).copy_from(levels);
        let score = self.score - cross.transpose() * w;
        Self { cross, own: self.own, score }
    }
}

/// The score test of one group's sensor turned by a small rotation φ in the table frame O2, the
/// frame a load of the table's own spin is fixed in: in a pose whose rotation from O2 to the
/// package is Rᵀ, every row of M turns to r_a + ψ × r_a with ψ = Rᵀ·φ (ΔM = M·[ψ]×ᵀ), so the
/// turn's three columns are the poses' ΔM columns through ∂ΔM[a][j]/∂φ_k = ((Rᵀe_k) × r_a)_j.
/// A turn's change along the table's axis (Rᵀe_z) shows in the run's constant level,
/// θ2'·r_a·Rᵀe_z, which the offset's wander between runs also moves; the test takes the levels
/// as the model leaves them (a random walk's share is carried by the consider covariance, not
/// here: the walk's size is read from the residual a turn leaves wander in; docs/trust.md,
/// "M changing with speed").
///
/// `per_pose`: the group's block per pose, with its Rᵀ; `chol`: the model's normal matrix.
/// The rates and the threshold are the caller's to set.
fn turn_test(m: &Matrix3<f64>, chol: &Cholesky<f64, Dyn>, per_pose: &[(Added, Matrix3<f64>)]) -> Option<GroupTurn> {
    let np = per_pose.first()?.0.cross.nrows();
    let (mut cross, mut own, mut score) = (DMatrix::zeros(np, 3), DMatrix::zeros(3, 3), DVector::zeros(3));
    for (added, rot_t) in per_pose {
        let p = DMatrix::from_fn(9, 3, |c, k| {
            let (a, j) = (c / 3, c % 3);
            (rot_t * Vector3::ith(k, 1.0)).cross(&Vector3::new(m[(a, 0)], m[(a, 1)], m[(a, 2)]))[j]
        });
        cross += &added.cross * &p;
        own += p.transpose() * &added.own * &p;
        score += p.transpose() * &added.score;
    }
    let info = &own - cross.transpose() * chol.solve(&cross);
    let (inv, dof) = surviving_inverse(&info, &own)?;
    let phi = &inv * &score;
    Some(GroupTurn {
        rate_dps: f64::NAN,
        reference_rate_dps: f64::NAN,
        turn_deg: std::array::from_fn(|k| phi[k].to_degrees()),
        turn_sigma_deg: std::array::from_fn(|k| inv[(k, k)].max(0.0).sqrt().to_degrees()),
        chi2: score.dot(&phi),
        dof,
        threshold: f64::NAN,
    })
}

#[cfg(test)]
mod tests {
    use crate::calib::analysis::stats::chi2_to_sigma;
    use crate::calib::{close_loop, LoopOptions};
    use crate::capture::{decode, Run};
    use crate::geometry::Pose;
    use crate::sim::{simulate, RunSpec, SimConfig};

    /// Both poses at 180 and 90 °/s, 40 s each, no effect: one simulated sensor.
    fn two_speeds(seed: u64) -> Vec<Run> {
        let runs = Pose::ALL
            .iter()
            .flat_map(|&pose| [180.0, 90.0].map(|rate_dps| RunSpec { pose, rate_dps, duration_s: 40.0 }))
            .collect();
        let out = simulate(&SimConfig::with_runs(seed, runs)).expect("simulates");
        decode(&out.bytes).runs
    }

    /// The runs at 90 °/s read `ppm` more than the sensor does: an effect that changes with speed
    /// and that no catalogued effect is (every axis, every column alike).
    fn scale_slow_runs(runs: &mut [Run], ppm: f64) {
        for r in runs.iter_mut().filter(|r| r.commanded_rate_dps().abs() < 100.0) {
            for s in &mut r.samples {
                s.rate_counts = s.rate_counts.map(|c| (f64::from(c) * (1.0 + ppm * 1e-6)).round() as i16);
            }
        }
    }

    /// The runs at 90 °/s with the sensor turned by `deg` about the table frame's axis `axis`:
    /// in each pose every reading c → c − ψ × c with ψ = Rᵀ·φ, φ in the package frame (small
    /// angle; with the sensitivities within 1 % of each other, the rows of M turned by ψ), as a
    /// mount that gives under the table's load turns them.
    fn turn_slow_runs(runs: &mut [Run], axis: usize, deg: f64) {
        let phi = nalgebra::Vector3::ith(axis, deg.to_radians());
        for r in runs.iter_mut().filter(|r| r.commanded_rate_dps().abs() < 100.0) {
            let psi = r.pose.rotation().transpose() * phi;
            for s in &mut r.samples {
                let c = nalgebra::Vector3::from(s.rate_counts.map(f64::from));
                let turned = c - psi.cross(&c);
                s.rate_counts = std::array::from_fn(|a| turned[a].round() as i16);
            }
        }
    }

    /// Runs that agree show no turn; runs at 90 °/s whose sensor turned by 0.01° about the
    /// table's x axis (several times the turn's σ on these 40-s runs) are flagged by the turn's
    /// own test, which reads the turn back within 4σ and is more significant than the nine
    /// elements' test.
    #[test]
    fn axes_turned_together_at_one_speed_are_flagged_as_a_turn() {
        let opts = LoopOptions { max_effects: 0, ..LoopOptions::default() };
        let r = close_loop(&two_speeds(21), &opts, None).expect("calibrates");
        let c = r.consistency.as_ref().expect("two speeds are compared");
        let t = &c.turns[0];
        assert!(!t.significant() && t.dof == 3, "{t:?}");
        assert!((0..3).all(|k| t.turn_deg[k].abs() < 4.0 * t.turn_sigma_deg[k]), "{t:?}");

        let mut runs = two_speeds(21);
        turn_slow_runs(&mut runs, 0, 0.01);
        let r = close_loop(&runs, &opts, None).expect("calibrates");
        let c = r.consistency.as_ref().expect("two speeds are compared");
        let t = &c.turns[0];
        assert!(t.significant() && c.disagrees(), "{t:?}");
        assert!((t.turn_deg[0] - 0.01).abs() < 4.0 * t.turn_sigma_deg[0], "{t:?}");
        assert!((1..3).all(|k| t.turn_deg[k].abs() < 4.0 * t.turn_sigma_deg[k]), "{t:?}");
        assert!(chi2_to_sigma(t.dof, t.chi2) > c.significance_sigma, "{c:?}");
        assert!(r.summary().contains("see the sensor turned by"), "{}", r.summary());
    }

    /// Runs that agree pass; runs at 90 °/s that read 1000 ppm more than those at 180 °/s are
    /// named, with the size of the disagreement.
    #[test]
    fn runs_at_two_speeds_that_want_different_m_are_named() {
        let opts = LoopOptions { max_effects: 0, ..LoopOptions::default() };
        let runs = two_speeds(21);
        let r = close_loop(&runs, &opts, None).expect("calibrates");
        let c = r.consistency.as_ref().expect("two speeds are compared");
        assert!(!c.disagrees(), "χ² {} for {} dof against {}", c.chi2, c.dof, c.threshold);
        assert_eq!(c.groups.len(), 1);
        assert_eq!((c.groups[0].rate_dps.round(), c.groups[0].reference_rate_dps.round()), (90.0, 180.0));

        let mut runs = two_speeds(21);
        scale_slow_runs(&mut runs, 1000.0);
        let r = close_loop(&runs, &opts, None).expect("calibrates");
        let c = r.consistency.as_ref().expect("two speeds are compared");
        assert!(c.disagrees(), "χ² {} for {} dof against {}", c.chi2, c.dof, c.threshold);
        let g = &c.groups[0];
        // The diagonal element that moved most reads ≈ +1000 ppm of its sensitivity.
        assert!(g.max_z > 4.0 && (g.max_ppm - 1000.0).abs() < 300.0, "{g:?}");
        assert_eq!(r.verdict(), crate::calib::Verdict::UnexplainedStructure);
        assert!(r.summary().contains("The runs disagree about M"), "{}", r.summary());
    }
}
