//! The gyro's low-pass filter's gain at the table frequency.

use super::terms::{
    dot, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts,
    Situation,
};
use super::{Behaviour, Effect, Layout};

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
        "runs at two speeds: the loss grows with the square of the frequency, a sensitivity does not"
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

    fn value(&self, _: Own, p: &Point, _: usize, t: &AxisTerms, _: &Ctx) -> f64 {
        dot(&t.u, &p.d_filter)
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

    /// Once a delay is in (the filter's phase), when the runs have two speeds. Two directions
    /// at one speed do not do: the droop is even in θ2', and there only the speed ripple's
    /// harmonics told it from a scale of M (trust bench, 180, −180 °/s with every realistic
    /// effect, seed 5: added at Δχ² 11531, every sensitivity then 5000 ppm off at exit 0, 98σ).
    fn candidate(&self, s: &Situation) -> bool {
        s.has(Effect::Delay) && !s.has(Effect::FilterGain) && s.distinct_speeds
    }
}
