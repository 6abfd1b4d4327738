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

use crate::calib::analysis::stats::{chi2_to_sigma, chi2_upper_quantile};
use crate::calib::engine::{full_selection, normal_equations, Fitted, Gram, LinCol, LoopData};
use crate::calib::result::axes::AXES;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

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
}

impl Consistency {
    /// Whether the groups disagree beyond chance.
    pub fn disagrees(&self) -> bool {
        self.chi2 > self.threshold
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
    let (n_mat, b_tot) = normal_equations(&total, &sel, weights);
    let np = n_mat.nrows();
    let chol = n_mat.clone().cholesky()?;
    // The sums were taken before the fit's last (negligible) step: the gradient after it.
    let delta = chol.solve(&b_tot);
    let m_idx: Vec<usize> = (0..3)
        .flat_map(|a| (0..3).map(move |j| (a, j)))
        .map(|(a, j)| f.lin_index(a, LinCol::Omega(j)))
        .collect::<Option<_>>()?;
    let extra = groups.len() - 1;
    let ne = 9 * extra;
    let mut cross = DMatrix::zeros(np, ne);
    let mut own = DMatrix::zeros(ne, ne);
    let mut score = DVector::zeros(ne);
    for (gi, (_, runs)) in groups.iter().skip(1).enumerate() {
        let g = Gram::sum(runs.iter().map(|&r| &f.per_run[r]))?;
        let (ng, bg) = normal_equations(&g, &sel, weights);
        let grad = bg - &ng * &delta;
        for (e, &pe) in m_idx.iter().enumerate() {
            let c = 9 * gi + e;
            score[c] = grad[pe];
            for p in 0..np {
                cross[(p, c)] = ng[(p, pe)];
            }
            for (e2, &pe2) in m_idx.iter().enumerate() {
                own[(c, 9 * gi + e2)] = ng[(pe, pe2)];
            }
        }
    }
    let info = &own - cross.transpose() * chol.solve(&cross);
    // In units of the columns' own information, so that an eigenvalue is the fraction that
    // survives the model.
    let scale = DVector::from_fn(ne, |i, _| if own[(i, i)] > 0.0 { 1.0 / own[(i, i)].sqrt() } else { 0.0 });
    let d = DMatrix::from_diagonal(&scale);
    let info_n = &d * &info * &d;
    let eig = ((&info_n + info_n.transpose()) * 0.5).symmetric_eigen();
    if eig.eigenvalues.iter().any(|l| !l.is_finite()) {
        return None;
    }
    // The pseudo-inverse on the directions the groups separate beyond the model.
    let mut inv_n = DMatrix::zeros(ne, ne);
    let mut dof = 0;
    for (i, &l) in eig.eigenvalues.iter().enumerate() {
        if l > SURVIVING_FRACTION {
            let u = eig.eigenvectors.column(i);
            inv_n += u * u.transpose() / l;
            dof += 1;
        }
    }
    if dof == 0 {
        return None;
    }
    let inv = &d * inv_n * &d;
    let est = &inv * &score;
    let chi2 = score.dot(&est);
    let threshold = chi2_upper_quantile(dof, alpha);
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
    Some(Consistency { chi2, dof, threshold, significance_sigma: chi2_to_sigma(dof, chi2), groups: group_diffs })
}

#[cfg(test)]
mod tests {
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
