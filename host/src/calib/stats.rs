//! Tail quantiles for the loop's significance tests: the normal by Acklam's rational
//! approximation, the χ² by Wilson–Hilferty on top of it.

/// Inverse of the standard normal CDF. P. J. Acklam's rational approximation (2003, published
/// on his web page and reproduced widely): relative error < 1.15e-9 over (0, 1), far below what a
/// significance threshold needs.
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] =
        [7.784_695_709_041_462e-3, 3.224_671_290_700_398e-1, 2.445_134_137_142_996, 3.754_408_661_907_416];
    const P_LOW: f64 = 0.024_25;
    let tail = |q: f64| {
        let r = (-2.0 * q.ln()).sqrt();
        (((((C[0] * r + C[1]) * r + C[2]) * r + C[3]) * r + C[4]) * r + C[5])
            / ((((D[0] * r + D[1]) * r + D[2]) * r + D[3]) * r + 1.0)
    };
    if p <= 0.0 {
        f64::NEG_INFINITY
    } else if p >= 1.0 {
        f64::INFINITY
    } else if p < P_LOW {
        tail(p)
    } else if p > 1.0 - P_LOW {
        -tail(1.0 - p)
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// Upper-tail χ² quantile: the x with P(χ²_dof > x) = `alpha`. One and two degrees of freedom
/// are exact (z², −2 ln α); more use the Wilson–Hilferty cube (Wilson & Hilferty, PNAS 17, 684,
/// 1931), within 3 % (on the high, conservative side) of tables for 3–30 degrees of freedom at
/// the 1e-6…1e-2 tails used here.
pub fn chi2_upper_quantile(dof: usize, alpha: f64) -> f64 {
    match dof {
        // χ²_1 = Z², two-sided.
        0 | 1 => return normal_quantile(0.5 * alpha).powi(2),
        2 => return -2.0 * alpha.ln(),
        _ => {}
    }
    let z = -normal_quantile(alpha);
    let k = dof as f64;
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3)
}

/// "How many σ" a χ² value is: for 1 degree of freedom |z| = √χ²; for more, the one-sided normal
/// deviate with the same upper tail (exact for 2, Wilson–Hilferty beyond).
pub fn chi2_to_sigma(dof: usize, chi2: f64) -> f64 {
    match dof {
        0 | 1 => return chi2.max(0.0).sqrt(),
        // Exponential tail; beyond f64's range the deviate grows like √χ².
        2 => {
            let p = (-0.5 * chi2.max(0.0)).exp();
            return if p > 0.0 { -normal_quantile(p) } else { chi2.sqrt() };
        }
        _ => {}
    }
    let k = dof as f64;
    let a = 2.0 / (9.0 * k);
    ((chi2.max(0.0) / k).cbrt() - (1.0 - a)) / a.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_quantile_matches_tables() {
        for (p, z) in [(0.975, 1.959_964), (0.999, 3.090_232), (1e-6, -4.753_424), (0.5, 0.0)] {
            assert!((normal_quantile(p) - z).abs() < 1e-5, "{p}");
        }
    }

    #[test]
    fn chi2_quantiles_match_tables() {
        // Exact upper points: χ²_1(1e-3) = 10.828, χ²_2(1e-4) = 18.421, χ²_10(1e-3) = 29.588,
        // χ²_4(1e-4) = 23.513.
        for (dof, alpha, exact) in [(1, 1e-3, 10.828), (2, 1e-4, 18.421), (10, 1e-3, 29.588), (4, 1e-4, 23.513)] {
            let q = chi2_upper_quantile(dof, alpha);
            assert!((q / exact - 1.0).abs() < 0.03, "{dof} {alpha}: {q}");
            let one_sided = if dof == 1 { 0.5 * alpha } else { alpha };
            assert!((chi2_to_sigma(dof, q) + normal_quantile(one_sided)).abs() < 1e-6);
        }
    }
}
