//! Tail quantiles for the loop's significance tests, from `statrs`'s exact normal and χ²
//! distributions (`Normal`, `ChiSquared`: the inverse error function and the regularised
//! incomplete gamma function, to ~1e-15 relative).
//!
//! These replaced Acklam's normal approximation and the Wilson–Hilferty χ² cube. The cube sat
//! high for 3–12 degrees of freedom, more the further out the tail (not "within 3 %" as its
//! comment said): 3 parameters at α/m = 1e-4 needed Δχ² > 21.84 rather than 21.11 (+3.5 %), at
//! 1e-6 32.81 rather than 30.66 (+7.0 %); and as a deviate it shrank a large Δχ² of 3 parameters
//! (1000: 22.1σ rather than 31.4σ), which ordered the candidates against the many-parameter ones.
//!
//! One piece stays hand-written, the far tail of [`chi2_to_sigma`]: `statrs` has no logarithm of
//! the χ² survival function, and beyond ~37σ that survival function underflows f64 (a large
//! effect's first Δχ² is in the thousands), so the deviate is taken there from the logarithm of
//! the tail's asymptotic series (`far_sigma`); it joins the exact path to 1e-6σ.

use statrs::distribution::{ChiSquared, ContinuousCDF, Normal};
use statrs::function::gamma::ln_gamma;

/// Inverse of the standard normal CDF (`statrs`: −√2 erfc⁻¹(2p)); −∞ at 0, +∞ at 1, NaN for NaN.
pub fn normal_quantile(p: f64) -> f64 {
    if p.is_nan() {
        f64::NAN
    } else if p <= 0.0 {
        f64::NEG_INFINITY
    } else if p >= 1.0 {
        f64::INFINITY
    } else {
        Normal::standard().inverse_cdf(p)
    }
}

/// The χ² distribution of `dof` degrees of freedom (0 is taken as 1, as the tests of a single
/// parameter do).
fn chi2(dof: usize) -> ChiSquared {
    ChiSquared::new(dof.max(1) as f64).expect("a positive, finite number of degrees of freedom")
}

/// Upper-tail χ² quantile: the x with P(χ²_dof > x) = `alpha` (`statrs`'s inverse CDF at 1 − α,
/// exact to the rounding of 1 − α, 1e-16 absolute: 1e-10 relative at the smallest α the loop
/// uses, ~1e-7). α ≤ 0 is +∞ (nothing is significant), α ≥ 1 is 0.
pub fn chi2_upper_quantile(dof: usize, alpha: f64) -> f64 {
    if alpha.is_nan() {
        f64::NAN
    } else if alpha <= 0.0 {
        f64::INFINITY
    } else if alpha >= 1.0 {
        0.0
    } else {
        chi2(dof).inverse_cdf(1.0 - alpha)
    }
}

/// "How many σ" a χ² value is: for 1 degree of freedom |z| = √χ² (the two-sided deviate, an
/// identity); for more, the one-sided normal deviate with the same upper tail. Finite for every
/// finite χ² (see `far_sigma` beyond f64's range of tail probabilities).
pub fn chi2_to_sigma(dof: usize, chi2_value: f64) -> f64 {
    let x = chi2_value.max(0.0);
    if dof <= 1 {
        return x.sqrt();
    }
    let d = chi2(dof);
    let p = d.sf(x);
    if p > 0.5 {
        // The lower tail from the CDF, which keeps its precision there (1 − sf would not). At
        // χ² = 0 the deviate is −∞: floored at f64's smallest normal probability (−37.5σ) so
        // that it stays a number in the loop's JSON.
        normal_quantile(d.cdf(x).max(f64::MIN_POSITIVE))
    } else if p >= FAR_TAIL_P {
        -normal_quantile(p)
    } else {
        far_sigma(dof, x)
    }
}

/// Below this upper-tail probability `chi2_to_sigma` leaves `statrs`'s survival function (which
/// loses relative precision among the subnormals and underflows to 0 soon after, at ~37.5σ).
const FAR_TAIL_P: f64 = 1e-290;

/// The normal deviate of a χ² tail too small for f64, from logarithms: ln Q(a, x) for a = dof/2,
/// x = χ²/2 by the asymptotic series Q ≈ x^(a−1) e^(−x)/Γ(a) · Σₙ (a−1)…(a−n)/xⁿ (Abramowitz &
/// Stegun 6.5.32; finite and exact for even dof), then the z with ln Φc(z) = ln Q by Newton on
/// Mills' ratio, ln Φc(z) = −z²/2 − ln z − ½ ln 2π + ln(1 − z⁻² + 3z⁻⁴ − 15z⁻⁶). Used only
/// where Q < 1e-290 (z > 36), where both series are accurate to ~1e-8.
fn far_sigma(dof: usize, x: f64) -> f64 {
    let a = 0.5 * dof as f64;
    let x = 0.5 * x;
    let (mut term, mut sum) = (1.0f64, 1.0f64);
    for n in 1..200 {
        let next = term * (a - n as f64) / x;
        // An asymptotic series: stop at its smallest term (or where it terminates).
        if next.abs() >= term.abs() || next.abs() <= 1e-17 * sum.abs() {
            break;
        }
        term = next;
        sum += term;
    }
    let ln_q = (a - 1.0) * x.ln() - x - ln_gamma(a) + sum.ln();
    let ln_tail = |z: f64| {
        let r = 1.0 / (z * z);
        -0.5 * z * z - z.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln()
            + (1.0 - r + 3.0 * r * r - 15.0 * r * r * r).ln()
    };
    let mut z = (-2.0 * ln_q).sqrt();
    for _ in 0..8 {
        // d/dz ln Φc(z) ≈ −z − 1/z.
        let step = (ln_tail(z) - ln_q) / (z + 1.0 / z);
        z += step;
        if step.abs() < 1e-12 * z {
            break;
        }
    }
    z
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference values from mpmath at 40 digits (erfinv; the regularised upper incomplete gamma,
    /// inverted by root finding), rounded to 7 significant digits: the tolerances are that
    /// rounding, far above statrs's own error.
    #[test]
    fn normal_quantile_matches_tables() {
        for (p, z) in [
            (0.975, 1.959_964),
            (0.999, 3.090_232),
            (0.995, 2.575_829),
            (1e-6, -4.753_424),
            (1e-12, -7.034_484),
            (0.5, 0.0),
        ] {
            let q = normal_quantile(p);
            assert!((q - z).abs() < 1e-6, "p = {p}: {q} vs {z}");
        }
        assert_eq!(normal_quantile(0.0), f64::NEG_INFINITY);
        assert_eq!(normal_quantile(1.0), f64::INFINITY);
        assert!(normal_quantile(f64::NAN).is_nan());
    }

    #[test]
    fn chi2_quantiles_match_tables() {
        for (dof, alpha, exact) in [
            (1, 1e-3, 10.827_566),
            (2, 1e-3, 13.815_511),
            (2, 1e-4, 18.420_681),
            (3, 1e-3, 16.266_236),
            (3, 1e-4, 21.107_513),
            (4, 1e-4, 23.512_742),
            (6, 1e-5, 33.107_057),
            (10, 1e-3, 29.588_298),
            (10, 0.01, 23.209_251),
            (30, 1e-6, 82.044_143),
        ] {
            let q = chi2_upper_quantile(dof, alpha);
            assert!((q - exact).abs() < 2e-6 * exact, "χ²_{dof}({alpha}) = {q}, table {exact}");
            // The deviate of the threshold is the normal quantile of the same tail.
            let one_sided = if dof == 1 { 0.5 * alpha } else { alpha };
            let s = chi2_to_sigma(dof, q);
            assert!((s + normal_quantile(one_sided)).abs() < 1e-6, "{dof} {alpha}: {s}σ");
        }
        assert_eq!(chi2_upper_quantile(0, 1e-3), chi2_upper_quantile(1, 1e-3));
        assert_eq!(chi2_upper_quantile(3, 0.0), f64::INFINITY);
        assert_eq!(chi2_upper_quantile(3, 1.0), 0.0);
    }

    /// The deviate of a χ² value against mpmath: −√2 erf⁻¹(1 − 2Q(k/2, x/2)).
    #[test]
    fn chi2_sigma_matches_tables() {
        for (dof, x, z) in
            [(2, 5.991_465, 1.644_854), (3, 7.814_728, 1.644_854), (5, 1.0, -1.781_269), (12, 40.0, 3.801_509)]
        {
            let s = chi2_to_sigma(dof, x);
            assert!((s - z).abs() < 1e-5, "χ²_{dof} = {x}: {s}σ vs {z}");
        }
        // The lower tail: 30 parameters with χ² = 1, far below their mean of 30.
        assert!((chi2_to_sigma(30, 1.0) + 8.449_637).abs() < 1e-5, "{}", chi2_to_sigma(30, 1.0));
        assert!((chi2_to_sigma(3, 0.0) - normal_quantile(f64::MIN_POSITIVE)).abs() < 1e-9);
        assert_eq!(chi2_to_sigma(1, 9.0), 3.0);
        assert_eq!(chi2_to_sigma(3, -1.0), chi2_to_sigma(3, 0.0));
    }

    /// Where statrs's tail is still in range (z ≈ 31–36), the far-tail path agrees with it, and
    /// beyond it the deviate keeps growing with χ² without a step at the switch.
    #[test]
    fn far_tail_joins_the_exact_tail() {
        for dof in [2, 3, 5, 8, 30, 61] {
            for x in [1000.0, 1200.0] {
                let exact = -normal_quantile(chi2(dof).sf(x));
                let far = far_sigma(dof, x);
                assert!((far - exact).abs() < 1e-6, "dof {dof}, χ² {x}: {far} vs {exact}");
            }
            let mut last = chi2_to_sigma(dof, 1000.0);
            let mut x = 1000.0;
            while x < 1e7 {
                x *= 1.01;
                let s = chi2_to_sigma(dof, x);
                assert!(s.is_finite() && s > last && s - last < 0.05 * last, "dof {dof}, χ² {x}: {last} -> {s}");
                last = s;
            }
        }
    }
}
