//! What the loop's choices leave open: at a step where another candidate explains the residual
//! nearly as well as the one taken, the data cannot say which is right, and M moves with the
//! choice. Each such alternative the final model lacks adds the spread of M it would give, at
//! its Akaike weight, to the covariance (model averaging: Burnham & Anderson, *Model Selection
//! and Multimodel Inference*, 2nd ed., 2002, §4.3.2, the unconditional variance of an estimate
//! over the models considered, here about the model taken rather than their average).
//!
//! The weights and the moves come from the candidates' pass of that step: each candidate's
//! linearised joint solution on top of the model as it stood, and its Δχ². The Akaike weight of
//! a candidate with Δχ² and p parameters is ∝ exp(Δχ²/2 − p); alternatives below
//! [`MIN_WEIGHT`] of the step's total are left out. Where the candidates' signatures differ,
//! as on every step of the default design, the weights are e^−1000 and nothing is added; on
//! 20-s runs at 180 and 90 °/s the trust bench found a table tilt taken at Δχ² 18.8 in place of
//! an axis delay at 15.3 (weight 0.06), which had left M 4σ off.

use crate::calib::effects::Effect;
use crate::calib::result::consider_term::{added_sigmas, ModelChoiceTerm};
use nalgebra::DMatrix;

/// Least Akaike weight of an alternative that is carried (engineering judgement: below it, a
/// move of M beyond 100σ would add under 1σ in quadrature).
pub const MIN_WEIGHT: f64 = 1e-4;

/// A candidate at a step: its effect, its Δχ² and parameter count, and M (axis-major) in its
/// linearised joint solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidacy {
    pub effect: Effect,
    pub delta_chi2: f64,
    pub params: usize,
    pub m: [f64; 9],
}

/// An alternative to the effect a step took, with its weight among the step's candidates and the
/// move of M from the taken one's solution to its own.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alternative {
    pub taken: Effect,
    pub effect: Effect,
    pub weight: f64,
    pub m_shift: [f64; 9],
}

/// The alternatives to `taken` among `others` whose Akaike weight, normalised over the taken
/// candidate and every alternative, reaches [`MIN_WEIGHT`].
pub fn alternatives(taken: &Candidacy, others: &[Candidacy]) -> Vec<Alternative> {
    let log_weight = |c: &Candidacy| c.delta_chi2 / 2.0 - c.params as f64;
    let relative: Vec<f64> = others.iter().map(|c| (log_weight(c) - log_weight(taken)).exp()).collect();
    let total = 1.0 + relative.iter().sum::<f64>();
    others
        .iter()
        .zip(&relative)
        .map(|(c, &w)| Alternative {
            taken: taken.effect,
            effect: c.effect,
            weight: w / total,
            m_shift: std::array::from_fn(|i| c.m[i] - taken.m[i]),
        })
        .filter(|a| a.weight >= MIN_WEIGHT && a.weight.is_finite())
        .collect()
}

/// The covariance of the 12 base parameters (`CalReport` order: per axis M's row, then the
/// offset) the alternatives add, leaving out those the final model holds (`in_final`), and a
/// term for each, with what it adds to the sensitivities and directions at `params`.
pub fn spread(
    alternatives: &[Alternative],
    in_final: &[Effect],
    params: &[f64; 12],
    nominal: f64,
) -> (DMatrix<f64>, Vec<ModelChoiceTerm>) {
    let mut cov = DMatrix::zeros(12, 12);
    let mut terms = Vec::new();
    for alt in alternatives.iter().filter(|a| !in_final.contains(&a.effect)) {
        let d = DMatrix::from_fn(12, 1, |p, _| if p % 4 == 3 { 0.0 } else { alt.m_shift[3 * (p / 4) + p % 4] });
        let added = alt.weight * &d * d.transpose();
        let (k_sigma_ppm, direction_sigma_deg) = added_sigmas(params, &added, nominal);
        terms.push(ModelChoiceTerm {
            taken: alt.taken.key(),
            alternative: alt.effect.key(),
            weight: alt.weight,
            k_sigma_ppm,
            direction_sigma_deg,
        });
        cov += added;
    }
    (cov, terms)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn candidacy(effect: Effect, delta_chi2: f64, params: usize, m0: f64) -> Candidacy {
        Candidacy { effect, delta_chi2, params, m: std::array::from_fn(|i| if i % 4 == 0 { m0 } else { 0.0 }) }
    }

    /// The trust bench's near tie: a table tilt (1 parameter) at Δχ² 18.8 against an axis delay
    /// (2) at 15.3 and a g-sensitivity (9) at 20.9: log-weights 8.4, 5.65 and 1.45, so the delay
    /// weighs e^−2.75 and the g-sensitivity e^−6.95 against the tilt, each normalised over the
    /// three; a pose fixture (1) at Δχ² 0, log-weight −1, e^−9.4 ≈ 8e-5: below [`MIN_WEIGHT`], left out.
    #[test]
    fn akaike_weights_of_a_near_tie() {
        let taken = candidacy(Effect::TableTilt, 18.8, 1, 57.0);
        let others = [
            candidacy(Effect::AxisDelay, 15.3, 2, 57.004),
            candidacy(Effect::GSensitivity, 20.9, 9, 57.01),
            candidacy(Effect::PoseFixture, 0.0, 1, 57.02),
        ];
        let alts = alternatives(&taken, &others);
        assert_eq!(alts.iter().map(|a| a.effect).collect::<Vec<_>>(), [Effect::AxisDelay, Effect::GSensitivity]);
        let total = 1.0 + (-2.75f64).exp() + (-6.95f64).exp() + (-9.4f64).exp();
        assert!((alts[0].weight - (-2.75f64).exp() / total).abs() < 1e-12, "{}", alts[0].weight);
        assert!((alts[1].weight - (-6.95f64).exp() / total).abs() < 1e-12, "{}", alts[1].weight);
        assert!((alts[0].m_shift[0] - 0.004).abs() < 1e-12 && alts[0].m_shift[1] == 0.0);
    }

    /// The spread adds w·d·dᵀ on M's elements and nothing on the offsets, leaves out an
    /// alternative the final model holds, and its term gives the sensitivity's added σ: on x,
    /// √w·0.004 counts/(°/s) of k = 57 is 17.1 ppm at w = 0.06.
    #[test]
    fn the_spread_is_the_weighted_move_of_m() {
        let alt = |effect| Alternative {
            taken: Effect::TableTilt,
            effect,
            weight: 0.06,
            m_shift: [0.004, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        };
        let mut params = [0.0; 12];
        (params[0], params[5], params[10]) = (57.0, 57.0, 57.0);
        let (cov, terms) =
            spread(&[alt(Effect::AxisDelay), alt(Effect::GSensitivity)], &[Effect::GSensitivity], &params, 57.0);
        assert_eq!(terms.len(), 1);
        assert!((cov[(0, 0)] - 0.06 * 0.004f64.powi(2)).abs() < 1e-15);
        assert_eq!(cov.iter().filter(|v| **v != 0.0).count(), 1, "only M_xx moves");
        let want_ppm = 0.06f64.sqrt() * 0.004 / 57.0 * 1e6;
        assert!((terms[0].k_sigma_ppm[0] - want_ppm).abs() < 0.01, "{:?} against {want_ppm}", terms[0].k_sigma_ppm);
        assert_eq!(terms[0].k_sigma_ppm[1], 0.0);
    }
}
