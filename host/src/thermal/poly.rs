//! Weighted least-squares polynomials in temperature, their order chosen by held-out prediction.
//!
//! Each point has a value with its σ and a temperature with its σ (OUT_TEMP's rounding). The
//! temperature's σ enters by the effective-variance method (Orear, Am. J. Phys. 50 (1982) 912):
//! `σ_eff² = σ_y² + (p'(x)·σ_x)²`, iterated on the fitted slope.
//!
//! A part of each point's σ may be common to every point (`sigma_common`: the same rig's
//! systematic at every setpoint, fully correlated). The fit is then generalised least squares
//! with `V = diag(σ_eff²) + c·cᵀ` (c the points' common σ): when c is the same at every point it
//! lies in the polynomial's column space, so the coefficients are those of the weighted fit on
//! the independent σ alone and the common variance lands on the constant term only (Rao 1967,
//! *Proc. Fifth Berkeley Symp.* 1, 355: least squares under `V = σ²I + XΓXᵀ`).
//!
//! The order is the one with the smallest weighted PRESS (leave-one-out prediction error,
//! Allen 1974): each point predicted by the polynomial fitted to the others, the squared miss
//! in units of that point's own σ, summed. A term the data do not support makes the held-out
//! predictions worse, so it is not chosen; a term they need makes them better.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// One measured point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// Temperature, °C (from the reference of the polynomial).
    pub x: f64,
    /// σ of the temperature, °C.
    pub sigma_x: f64,
    /// Value.
    pub y: f64,
    /// σ of the value independent of the other points'.
    pub sigma_y: f64,
    /// σ of the value common to every point (fully correlated between them).
    #[serde(default)]
    pub sigma_common: f64,
}

/// A fitted polynomial `Σ c_d x^d` with the coefficients' covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct PolyFit {
    /// Coefficients, constant first.
    pub coef: Vec<f64>,
    /// Their covariance.
    pub cov: DMatrix<f64>,
    /// χ² of the points against the fit (`rᵀV⁻¹r`, effective σ and the common part).
    pub chi2: f64,
    /// Effective independent σ of each point.
    pub sigma_eff: Vec<f64>,
    /// The coefficients' response to the points' common part, per unit of it (`G·c`, G the
    /// estimator `(AᵀV⁻¹A)⁻¹AᵀV⁻¹`): their covariance with anything else sharing that part.
    pub common_response: DVector<f64>,
}

/// Why no polynomial could be fitted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PolyError {
    /// More coefficients than points.
    #[error("{points} point(s) cannot fix a polynomial of order {order}")]
    TooFewPoints { points: usize, order: usize },
    /// A σ that is not positive and finite, or temperatures that coincide.
    #[error("the points do not fix a polynomial of order {order} (coincident temperatures or a zero σ)")]
    Degenerate { order: usize },
}

/// Value of `Σ c_d x^d`.
pub fn eval(coef: &[f64], x: f64) -> f64 {
    coef.iter().rev().fold(0.0, |acc, c| acc * x + c)
}

/// Derivative of `Σ c_d x^d`.
pub fn slope(coef: &[f64], x: f64) -> f64 {
    coef.iter().enumerate().skip(1).rev().fold(0.0, |acc, (d, c)| acc * x + d as f64 * c)
}

/// Powers `[1, x, …, x^order]`.
pub fn powers(x: f64, order: usize) -> DVector<f64> {
    DVector::from_iterator(
        order + 1,
        (0..=order).scan(1.0, |p, _| {
            let v = *p;
            *p *= x;
            Some(v)
        }),
    )
}

/// Variance of the fitted value at `x`.
pub fn value_variance(fit: &PolyFit, x: f64) -> f64 {
    let a = powers(x, fit.coef.len() - 1);
    (a.transpose() * &fit.cov * &a)[(0, 0)]
}

/// Effective-variance iterations: the slope moves little between the second and third.
const EV_ITERATIONS: usize = 3;

/// Generalised least-squares fit of order `order`.
pub fn fit(points: &[Point], order: usize) -> Result<PolyFit, PolyError> {
    if points.len() < order + 1 {
        return Err(PolyError::TooFewPoints { points: points.len(), order });
    }
    let valid = |p: &Point| {
        p.sigma_y > 0.0
            && p.sigma_y.is_finite()
            && p.sigma_x >= 0.0
            && p.sigma_common >= 0.0
            && p.sigma_common.is_finite()
    };
    if !points.iter().all(valid) {
        return Err(PolyError::Degenerate { order });
    }
    let mut sigma_eff: Vec<f64> = points.iter().map(|p| p.sigma_y).collect();
    let mut result = None;
    for _ in 0..EV_ITERATIONS {
        let solved = solve(points, &sigma_eff, order).ok_or(PolyError::Degenerate { order })?;
        sigma_eff = points.iter().map(|p| p.sigma_y.hypot(slope(&solved.coef, p.x) * p.sigma_x)).collect();
        result = Some(solved);
    }
    let s = result.expect("at least one iteration");
    let r = DVector::from_iterator(points.len(), points.iter().map(|p| p.y - eval(&s.coef, p.x)));
    let chi2 = (r.transpose() * v_inverse(points, &sigma_eff) * &r)[(0, 0)];
    Ok(PolyFit { coef: s.coef, cov: s.cov, chi2, sigma_eff, common_response: s.common_response })
}

/// V⁻¹ for `V = diag(σ²) + c·cᵀ`, by Sherman-Morrison.
fn v_inverse(points: &[Point], sigma: &[f64]) -> DMatrix<f64> {
    let d_inv = DVector::from_iterator(sigma.len(), sigma.iter().map(|s| 1.0 / (s * s)));
    let dc = DVector::from_iterator(points.len(), points.iter().zip(d_inv.iter()).map(|(p, d)| p.sigma_common * d));
    let denom = 1.0 + points.iter().zip(dc.iter()).map(|(p, x)| p.sigma_common * x).sum::<f64>();
    DMatrix::from_diagonal(&d_inv) - &dc * dc.transpose() / denom
}

struct Solved {
    coef: Vec<f64>,
    cov: DMatrix<f64>,
    common_response: DVector<f64>,
}

/// The generalised normal equations' solution, its covariance and the response to the common
/// part, for fixed σ.
fn solve(points: &[Point], sigma: &[f64], order: usize) -> Option<Solved> {
    let a = DMatrix::from_fn(points.len(), order + 1, |i, d| points[i].x.powi(d as i32));
    let v_inv = v_inverse(points, sigma);
    let cov = (a.transpose() * &v_inv * &a).try_inverse()?;
    let g = &cov * a.transpose() * &v_inv;
    let y = DVector::from_iterator(points.len(), points.iter().map(|p| p.y));
    let c = DVector::from_iterator(points.len(), points.iter().map(|p| p.sigma_common));
    let coef = &g * y;
    coef.iter().all(|c| c.is_finite()).then(|| Solved {
        coef: coef.iter().copied().collect(),
        cov,
        common_response: g * c,
    })
}

/// One held-out prediction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HeldOut {
    /// Which point.
    pub index: usize,
    /// The polynomial of the others at its temperature.
    pub predicted: f64,
    /// σ of that prediction (the others' fit).
    pub sigma_predicted: f64,
    /// The point's own independent effective σ (its value's, widened by its temperature's
    /// through the slope).
    pub sigma_point: f64,
    /// (measured − predicted) in units of the miss's σ: σ_point² + σ_predicted² and the point's
    /// common variance, less twice the prediction's covariance with that common part.
    pub z: f64,
}

/// Leave-one-out predictions at order `order`; `None` when a point's absence leaves too few.
pub fn held_out(points: &[Point], order: usize) -> Option<Vec<HeldOut>> {
    (0..points.len())
        .map(|j| {
            let others: Vec<Point> = points.iter().enumerate().filter(|(i, _)| *i != j).map(|(_, p)| *p).collect();
            let f = fit(&others, order).ok()?;
            let p = points[j];
            let predicted = eval(&f.coef, p.x);
            let sigma_predicted = value_variance(&f, p.x).max(0.0).sqrt();
            let sigma_point = p.sigma_y.hypot(slope(&f.coef, p.x) * p.sigma_x);
            let shared = powers(p.x, order).dot(&f.common_response) * p.sigma_common;
            let var = sigma_point.powi(2) + sigma_predicted.powi(2) + p.sigma_common.powi(2) - 2.0 * shared;
            let z = (p.y - predicted) / var.max(sigma_point.powi(2)).sqrt();
            Some(HeldOut { index: j, predicted, sigma_predicted, sigma_point, z })
        })
        .collect()
}

/// Weighted PRESS at `order`: Σ ((y_j − ŷ_(−j)) / σ_j)², σ_j the point's own (effective) σ.
pub fn weighted_press(points: &[Point], order: usize) -> Option<f64> {
    let ho = held_out(points, order)?;
    Some(ho.iter().map(|h| ((points[h.index].y - h.predicted) / h.sigma_point).powi(2)).sum())
}

/// The order chosen and the evidence for it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrderChoice {
    /// Chosen order.
    pub order: usize,
    /// Weighted PRESS of each order tried, from 0.
    pub press: Vec<f64>,
}

/// Highest order tried: a cubic is what PX4 fits to gyro bias over temperature
/// (`TemperatureCompensation`, third order); it needs six setpoints (see [`choose_order`]).
pub const MAX_ORDER: usize = 3;

/// The order with the smallest weighted PRESS among those whose held-out fits keep a degree of
/// freedom (order ≤ points − 3, at most [`MAX_ORDER`]: with five setpoints, a quadratic), so a
/// held-out curve is never an exact interpolation through its points; a line is always tried
/// (three setpoints: a held-out line through the other two). Ties go to the lower order.
pub fn choose_order(points: &[Point]) -> Option<OrderChoice> {
    let n = points.len();
    if n < 3 {
        return None;
    }
    let max = MAX_ORDER.min((n - 3).max(1));
    let press: Vec<f64> = (0..=max).map_while(|d| weighted_press(points, d)).collect();
    let order = press.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)).map(|(d, _)| d)?;
    Some(OrderChoice { order, press })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points(f: impl Fn(f64) -> f64, noise: &[f64]) -> Vec<Point> {
        [-45.0, -25.0, 0.0, 25.0, 45.0]
            .iter()
            .zip(noise)
            .map(|(&x, n)| Point { x, sigma_x: 0.0, y: f(x) + n * 0.01, sigma_y: 0.01, sigma_common: 0.0 })
            .collect()
    }

    #[test]
    fn exact_polynomials_are_recovered_with_their_covariance() {
        let p = points(|x| 1.0 + 0.03 * x + 1e-4 * x * x, &[0.0; 5]);
        let f = fit(&p, 2).unwrap();
        assert!((f.coef[0] - 1.0).abs() < 1e-12 && (f.coef[1] - 0.03).abs() < 1e-12);
        assert!((f.coef[2] - 1e-4).abs() < 1e-14 && f.chi2 < 1e-18);
        // The constant's σ at order 0 is σ/√n.
        let f0 = fit(&p, 0).unwrap();
        assert!((f0.cov[(0, 0)].sqrt() - 0.01 / 5f64.sqrt()).abs() < 1e-15);
        assert!((eval(&f.coef, 10.0) - 1.31).abs() < 1e-12);
        assert!((slope(&f.coef, 10.0) - 0.032).abs() < 1e-12);
        assert!(matches!(fit(&p[..2], 2), Err(PolyError::TooFewPoints { .. })));
    }

    #[test]
    fn order_follows_what_the_data_support() {
        let noise = [0.7, -1.1, 0.4, 0.9, -0.6];
        assert_eq!(choose_order(&points(|x| 2.0 + 0.0 * x, &noise)).unwrap().order, 0);
        assert_eq!(choose_order(&points(|x| 2.0 + 0.03 * x, &noise)).unwrap().order, 1);
        assert_eq!(choose_order(&points(|x| 2.0 + 0.03 * x + 1e-4 * x * x, &noise)).unwrap().order, 2);
        // Five points: a quadratic is the most whose held-out fits keep a degree of freedom.
        assert_eq!(choose_order(&points(|x| x, &noise)).unwrap().press.len(), 3);
        assert_eq!(choose_order(&points(|x| x, &noise)[..3]).unwrap().press.len(), 2);
        assert_eq!(choose_order(&points(|x| x, &noise)[..3]).unwrap().order, 1);
        assert!(choose_order(&points(|x| x, &noise)[..2]).is_none());
    }

    /// A common part the same at every point lands on the constant term only (Rao 1967): the
    /// coefficients are those of the fit without it, the constant's variance grows by its
    /// square, the slope's does not, and a held-out miss (in which it cancels) is unchanged.
    #[test]
    fn a_common_part_lands_on_the_constant_term_only() {
        let noise = [0.7, -1.1, 0.4, 0.9, -0.6];
        let p = points(|x| 2.0 + 0.03 * x, &noise);
        let mut q = p.clone();
        for pt in &mut q {
            pt.sigma_common = 0.05;
        }
        let (f, g) = (fit(&p, 1).unwrap(), fit(&q, 1).unwrap());
        assert!((f.coef[0] - g.coef[0]).abs() < 1e-12 && (f.coef[1] - g.coef[1]).abs() < 1e-14);
        assert!((g.cov[(0, 0)] - f.cov[(0, 0)] - 0.05 * 0.05).abs() < 1e-12, "{} {}", g.cov, f.cov);
        assert!((g.cov[(1, 1)] - f.cov[(1, 1)]).abs() < 1e-16 && (g.cov[(0, 1)] - f.cov[(0, 1)]).abs() < 1e-15);
        assert!((g.common_response[0] - 0.05).abs() < 1e-12 && g.common_response[1].abs() < 1e-14);
        assert!((f.chi2 - g.chi2).abs() < 1e-9);
        let (hf, hg) = (held_out(&p, 1).unwrap(), held_out(&q, 1).unwrap());
        for (a, b) in hf.iter().zip(&hg) {
            assert!((a.z - b.z).abs() < 1e-9 && a.z.abs() > 0.1, "{a:?} {b:?}");
        }
    }

    #[test]
    fn temperature_sigma_widens_the_points_by_the_slope() {
        let mut p = points(|x| 0.03 * x, &[0.0; 5]);
        for q in &mut p {
            q.sigma_x = 0.29;
        }
        let f = fit(&p, 1).unwrap();
        let want = 0.01f64.hypot(0.03 * 0.29);
        assert!(f.sigma_eff.iter().all(|s| (s - want).abs() < 1e-12), "{:?}", f.sigma_eff);
        let ho = held_out(&p, 1).unwrap();
        assert!(ho.iter().all(|h| h.z.abs() < 1e-9));
    }
}
