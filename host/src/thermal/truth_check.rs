//! The thermal model against a simulated sensor's truth: the bars of issue 27 as numbers, for
//! the tests and the bench (`host/benches/thermal.rs`).
//!
//! The model's temperature scale is OUT_TEMP anchored on the chamber (`out_temp_at_0c`); the
//! simulator's is the die's own. A die at `T` reads `c_true − T`, so the model's `T_model` is
//! the truth's `T_model + (c_true − c_model)` (to OUT_TEMP's rounding, which the model carries
//! as each setpoint's temperature σ).

use super::model::ThermalModel;
use super::{Quantity, SetpointCal, ThermalError};
use crate::sim::thermal::ThermalTruth;

/// Step of the central differences that take the truth's Taylor coefficients, °C: the
/// simulated offset and sensitivity are exact quadratics (exact at any step); the direction's
/// rotation is linear to 1e-6 over it.
const TAYLOR_STEP_C: f64 = 5.0;

/// One quantity of one axis of the truth at the die's own temperature `temp_c`.
pub fn truth_value(truth: &ThermalTruth, axis: usize, quantity: Quantity, temp_c: f64) -> f64 {
    let (offset, k, s) = truth.axis_at(axis, temp_c);
    match quantity {
        Quantity::OffsetCounts => offset,
        Quantity::SensitivityCountsPerDps => k,
        Quantity::DirectionNext => s[(axis + 1) % 3],
        Quantity::DirectionOther => s[(axis + 2) % 3],
    }
}

/// Taylor coefficients (constant first, up to the cube) of `f` at 0 by central differences.
fn taylor(f: impl Fn(f64) -> f64) -> [f64; 4] {
    let h = TAYLOR_STEP_C;
    let (m2, m1, z, p1, p2) = (f(-2.0 * h), f(-h), f(0.0), f(h), f(2.0 * h));
    [
        z,
        (p1 - m1) / (2.0 * h),
        (p1 - 2.0 * z + m1) / (2.0 * h * h),
        (p2 - 2.0 * p1 + 2.0 * m1 - m2) / (12.0 * h * h * h),
    ]
}

/// One coefficient against the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct CoefficientCheck {
    /// The curve, e.g. "x offset [counts]".
    pub curve: String,
    /// Power of (T − reference).
    pub degree: usize,
    /// Fitted value, its σ, and the truth.
    pub fitted: f64,
    /// σ of `fitted`.
    pub sigma: f64,
    /// The truth's coefficient on the model's scale.
    pub truth: f64,
    /// (fitted − truth)/σ.
    pub z: f64,
}

/// Every fitted coefficient against the truth's Taylor coefficient of the same degree, and,
/// for each curve, the largest effect of the truth's terms above its order at the range's ends
/// in units of the curve's σ there (terms the order left out must be below the data's reach).
pub fn coefficients(
    model: &ThermalModel,
    truth: &ThermalTruth,
    c_true: f64,
) -> (Vec<CoefficientCheck>, Vec<(String, f64)>) {
    let shift = c_true - model.out_temp_at_0c;
    let mut checks = Vec::new();
    let mut omitted = Vec::new();
    for (curve, (axis, q)) in model.curves.iter().zip(Quantity::all()) {
        let t = taylor(|x| truth_value(truth, axis, q, x + model.reference_c + shift));
        for (d, c) in curve.coef.iter().enumerate() {
            checks.push(CoefficientCheck {
                curve: curve.label(),
                degree: d,
                fitted: c.value,
                sigma: c.sigma,
                truth: t[d],
                z: c.z(t[d]),
            });
        }
        let worst = model
            .range_c
            .iter()
            .map(|&temp| {
                let x = temp - model.reference_c;
                let left: f64 = (curve.order + 1..4).map(|d| t[d] * x.powi(d as i32)).sum();
                left.abs() / curve.at(model.reference_c, temp).sigma
            })
            .fold(0.0, f64::max);
        omitted.push((curve.label(), worst));
    }
    (checks, omitted)
}

/// The rate predicted at a held-out setpoint: the model refitted without setpoint `held` (same
/// orders) predicts, at that setpoint's die temperature, the rate for the reading the true
/// sensor gives there for `rate_dps` (the model at `held`'s die temperature; `model` gives the
/// orders). Returns the z of each component, (predicted − true)/σ,
/// σ including OUT_TEMP's rounding through each curve's slope.
pub fn held_out_rate_z(
    setpoints: &[SetpointCal],
    model: &ThermalModel,
    held: usize,
    held_truth: &crate::sim::Truth,
    rate_dps: [f64; 3],
) -> Result<[f64; 3], ThermalError> {
    let mut sorted: Vec<&SetpointCal> = setpoints.iter().collect();
    sorted.sort_by(|a, b| a.setpoint_c.total_cmp(&b.setpoint_c));
    let target = sorted[held];
    let others: Vec<SetpointCal> = sorted.iter().filter(|s| !std::ptr::eq(**s, target)).map(|s| (*s).clone()).collect();
    let refit = ThermalModel::fit_with(&others, Some(&model.orders()))?;
    // On the refit's own scale: its anchor is the other setpoints' (see `ThermalModel`).
    let temp_c = refit.temp_c_from_raw_mean(target.out_temp_mean_lsb);
    let raw = held_truth.m() * nalgebra::Vector3::from(rate_dps) + held_truth.offset();
    let (rate, sigma) = refit.rate_at_reading([raw[0], raw[1], raw[2]], temp_c, refit.temp_sigma_c)?;
    Ok([0, 1, 2].map(|i| (rate[i] - rate_dps[i]) / sigma[i]))
}

/// Each quantity of the model at a single-setpoint session's die temperature against that
/// session's own calibration, in units of the σ of their difference: the model's (with the
/// temperature's through the slope) and the session's, plus the between-session σ of the
/// quantity's kind (the session is another session), less twice their covariance through the
/// part of σ common to every calibration on the rig (`SetpointCal::common_sigma`): a common
/// systematic moves both alike and is not counted in their difference.
pub fn single_setpoint_z(model: &ThermalModel, single: &SetpointCal) -> Result<Vec<(String, f64)>, ThermalError> {
    let temp_c = model.temp_c_from_raw_mean(single.out_temp_mean_lsb);
    Quantity::all()
        .zip(&model.curves)
        .map(|((axis, q), curve)| {
            let at = curve.at(model.reference_c, temp_c);
            let slope_sigma = curve.slope_at(model.reference_c, temp_c) * model.temp_sigma_c;
            let mine = single.value(axis, q);
            let shared = curve.common_covariance(model.reference_c, temp_c, single.common(axis, q));
            let var = at.sigma.powi(2) + slope_sigma.powi(2) + mine.sigma.powi(2) + curve.between_sigma.powi(2)
                - 2.0 * shared;
            Ok((curve.label(), (at.value - mine.value) / var.max(0.0).sqrt()))
        })
        .collect()
}

/// How a set of z-values (each (fitted − truth)/σ) compares with the standard normal they
/// should follow if every σ is honest: the counts beyond 1, 2 and 3σ against chance, the
/// chance of at least the count seen beyond 3σ, and the Kolmogorov-Smirnov statistic with its
/// asymptotic p-value. The z-values of one seed share setpoints and are not independent, so
/// the p-values are indicative.
#[derive(Debug, Clone, PartialEq)]
pub struct Normality {
    /// z-values.
    pub n: usize,
    /// Beyond 1, 2 and 3σ: (seen, expected of a standard normal).
    pub beyond: [(usize, f64); 3],
    /// P(at least the count seen beyond 3σ) for n standard normal values (binomial).
    pub p_beyond_3: f64,
    /// sup |F_n(z) − Φ(z)|.
    pub ks_d: f64,
    /// Its asymptotic p-value, Q_KS((√n + 0.12 + 0.11/√n)·D) (Stephens 1970; Numerical Recipes,
    /// 3rd ed., §14.3.3).
    pub ks_p: f64,
}

/// Terms of the Kolmogorov series Q_KS(λ) = 2 Σ (−1)^(j−1) exp(−2 j² λ²): below 1e-16 by the
/// 100th for any λ ≥ 0.04, and Q is 1 to double precision below that.
const KS_TERMS: i32 = 100;

/// The normality of `z` ([`Normality`]); `None` for no value.
pub fn normality(z: &[f64]) -> Option<Normality> {
    use statrs::distribution::{Binomial, ContinuousCDF, DiscreteCDF, Normal};
    if z.is_empty() {
        return None;
    }
    let n = z.len();
    let phi = Normal::standard();
    let beyond = [1.0, 2.0, 3.0].map(|b| {
        let seen = z.iter().filter(|v| v.abs() > b).count();
        (seen, n as f64 * 2.0 * phi.cdf(-b))
    });
    let p3 = 2.0 * phi.cdf(-3.0);
    let p_beyond_3 = match beyond[2].0 {
        0 => 1.0,
        k => Binomial::new(p3, n as u64).map_or(f64::NAN, |b| b.sf(k as u64 - 1)),
    };
    let mut sorted = z.to_vec();
    sorted.sort_by(f64::total_cmp);
    let ks_d = sorted
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let f = phi.cdf(v);
            (f - i as f64 / n as f64).abs().max(((i + 1) as f64 / n as f64 - f).abs())
        })
        .fold(0.0, f64::max);
    let sqrt_n = (n as f64).sqrt();
    let lambda = (sqrt_n + 0.12 + 0.11 / sqrt_n) * ks_d;
    let ks_p = if lambda < 0.04 {
        1.0
    } else {
        let q: f64 = (1..=KS_TERMS)
            .map(|j| {
                let sign = if j % 2 == 1 { 1.0 } else { -1.0 };
                sign * (-2.0 * f64::from(j * j) * lambda * lambda).exp()
            })
            .sum();
        (2.0 * q).clamp(0.0, 1.0)
    };
    Some(Normality { n, beyond, p_beyond_3, ks_d, ks_p })
}
