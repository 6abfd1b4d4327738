//! The gyro's low-pass filter's gain at the table frequency.

use super::terms::{
    along_gradient, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar,
    Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// How far, in its own σ, a fitted κ may lie beyond |κ| ≤ τ²/2 before the fit is refused: 4σ,
/// the trust bars' line between an honest σ and a wrong one (by chance once in 3·10⁴ fits).
const BEYOND_PHYSICS_SIGMAS: f64 = 4.0;

/// The gyro's low-pass filter beyond its delay: H(jω) ≈ e^{−jωτ}(1 − κω²), output = M(ω + κ·ω̈)
/// at the delayed time, the gain lost at the table frequency (1st order: κ = τ²/2; 2nd-order
/// Butterworth: κ ≈ 0). One parameter, κ (s²).
pub struct FilterGain;

impl Behaviour for FilterGain {
    fn name(&self) -> String {
        "gyro low-pass gain at the table frequency".into()
    }

    fn key(&self) -> String {
        "filter_gain".into()
    }

    fn meaning(&self) -> &'static str {
        "the gyro's low-pass filter attenuates the table-rate sinusoid as well as delaying it (a 1st-order filter with 5 ms of delay loses 120 ppm at 0.5 Hz)"
    }

    fn identified_by(&self) -> &'static str {
        "runs at three signed speeds (--rates-dps 180,90,-180): its loss grows with θ2'³, M's share with θ2', and Earth's vertical rate and gravity's not at all; two speeds in one direction do only with the lab's latitude given (--latitude-deg) and no g-sensitivity fitted"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![], vec![SharedPar { effect: Effect::FilterGain, k: 0 }])
    }

    fn reported(&self, _: Own, _: f64) -> Option<Reported> {
        Some(Reported::new("filter curvature κ (gain 1 − κω²)", 1e6, "ms²"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, value: f64, s: &mut Shifts) {
        s.filter_s2 = value;
    }

    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        along_gradient(t, self.gradient_factor(own, p, cx))
    }

    fn gradient_factor(&self, _: Own, p: &Point, _: &Ctx) -> Option<[f64; 3]> {
        Some(p.d_filter)
    }

    /// |κ| ≤ τ²/2 for a low-pass of real poles with group delay τ (each pole ω_i adds 1/ω_i to
    /// τ and 1/(2ω_i²) to κ: κ = Σ 1/(2ω_i²) ≤ (Σ 1/ω_i)²/2, equal for one pole; a Butterworth
    /// pair gives κ ≈ 0), as a uniform bound: σ = τ²/(2√3) (GUM 4.3.7). τ is the fitted delay,
    /// or without one √2/(2π f_c) at the configured cut-off (L3G4200D datasheet, Table 5).
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        let omega_c = 2.0 * std::f64::consts::PI * cx.cutoff_hz;
        let tau_s = cx.delay_s.unwrap_or(std::f64::consts::SQRT_2 / omega_c).abs();
        (!cx.has(Effect::FilterGain) && tau_s.is_finite() && tau_s > 0.0).then(|| ConsiderBound {
            sigma: 1e6 * tau_s * tau_s / (2.0 * 3f64.sqrt()),
            source: "gain droop of a low-pass with the fitted delay τ, between 0 (Butterworth) and τ²/2 (one pole), uniform",
        })
    }

    /// |κ| ≤ τ²/2 with τ the fitted delay: real poles give 0…τ²/2 (as for [`Behaviour::consider`]),
    /// a resonant pair down to −τ²/2 at Q = 1 (1.25 dB of peaking, more than a sensor's output
    /// filter is designed with). A κ the data hold further out is not the filter: the trust bench
    /// (`--drawn-rig=3`, seed 2, 180, 90 °/s) fitted −884 ± 109 ms² against a bound of 1.9 ms²,
    /// standing in with the g-sensitivity's diagonal for an unmodelled speed ripple, and every
    /// sensitivity ended 1.5 % (8σ) off at exit 0.
    fn beyond_physics(&self, fitted: &dyn Fn(SharedPar) -> Option<(f64, f64)>) -> Option<String> {
        let (kappa_s2, sigma_s2) = fitted(SharedPar { effect: Effect::FilterGain, k: 0 })?;
        let (tau_s, _) = fitted(SharedPar { effect: Effect::Delay, k: 0 })?;
        let bound_s2 = tau_s * tau_s / 2.0;
        (kappa_s2.abs() - bound_s2 > BEYOND_PHYSICS_SIGMAS * sigma_s2).then(|| {
            format!(
                "its filter curvature κ = {:.3} ± {:.3} ms² lies beyond |κ| ≤ τ²/2 = {:.3} ms² of a low-pass with the fitted delay: it stands in for something else",
                kappa_s2 * 1e6,
                sigma_s2 * 1e6,
                bound_s2 * 1e6
            )
        })
    }

    /// Once a delay is in (the filter's phase), when the runs have two speeds. Two directions
    /// at one speed do not do: the droop is even in θ2', and there only the speed ripple's
    /// harmonics told it from a scale of M (trust bench, 180, −180 °/s with every realistic
    /// effect, seed 5: added at Δχ² 11531, every sensitivity then 5000 ppm off at exit 0, 98σ).
    ///
    /// And only where the runs' rates tell its droop (∝ θ2'³) from M (∝ θ2') and, with gravity
    /// or Earth's vertical rate in the model, from a vector fixed to the base (∝ 1): at 180, 90
    /// °/s with the g-sensitivity in, the three are two numbers per shape, and a κ fitted there
    /// stood with the g-sensitivity for a speed ripple (trust bench, `--drawn-rig=2`, seed 4,
    /// 300-s runs: every sensitivity 6800 ppm off at exit 0, 3.6σ of a σ grown to 1900 ppm).
    fn candidate(&self, s: &Situation) -> bool {
        let powers: &[i32] = if s.has_base_vector() { &[0, 1, 3] } else { &[1, 3] };
        s.has(Effect::Delay) && !s.has(Effect::FilterGain) && s.separates_rate_powers(powers)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fit's κ and τ (values in s², s) as [`Behaviour::beyond_physics`] reads them.
    fn with(kappa: Option<(f64, f64)>, tau_s: Option<f64>) -> impl Fn(SharedPar) -> Option<(f64, f64)> {
        move |p: SharedPar| match p.effect {
            Effect::FilterGain => kappa,
            Effect::Delay => tau_s.map(|t| (t, 1e-5)),
            _ => None,
        }
    }

    /// The trust bench's case is refused with the figures that say why; a κ past the bound by
    /// less than 4σ, or one without a delay to bound it, is not.
    #[test]
    fn a_curvature_beyond_a_low_pass_of_the_fitted_delay_is_refused() {
        let why = FilterGain.beyond_physics(&with(Some((-884.2e-6, 109.2e-6)), Some(1.94e-3)));
        assert_eq!(
            why.as_deref(),
            Some("its filter curvature κ = -884.200 ± 109.200 ms² lies beyond |κ| ≤ τ²/2 = 1.882 ms² of a low-pass with the fitted delay: it stands in for something else")
        );
        // 2 ms of delay bounds |κ| by 2 ms²: 3.1 ± 0.3 is 3.7σ past it, 3.3 ± 0.3 is 4.3σ.
        assert!(FilterGain.beyond_physics(&with(Some((3.1e-6, 0.3e-6)), Some(2e-3))).is_none());
        assert!(FilterGain.beyond_physics(&with(Some((-3.3e-6, 0.3e-6)), Some(2e-3))).is_some());
        assert!(FilterGain.beyond_physics(&with(Some((-884e-6, 1e-6)), None)).is_none());
        assert!(FilterGain.beyond_physics(&with(None, Some(2e-3))).is_none());
    }
}
