//! An even square law in the rate along the axis (IEEE Std 952's K2).

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// Per axis r², r the rate along the axis (the row of M normalised), counts per (°/s)².
///
/// IEEE Std 952 writes a gyro's scale-factor non-linearity as a power series, K2·ω² + K3·ω³:
/// the square term is even, the same for either sign of the rate, where the catalogue's other
/// even term, the asymmetry |r| ([`super::rate_scale::RateScale`]), has a kink at zero. On this
/// rig an axis's rate is a sinusoid of amplitude A about a constant C (the table's own rate
/// along the axis, θ2'·(M R_qᵀ e_z2) of it): r² makes a 2× line of A²/2 and a 1× part 2·A·C,
/// which grows with the square of the speed and which M takes up at one speed. Unmodelled, 0.2 %
/// of full scale of it was flagged on every seed of the default design (the runs disagreed
/// about M), and at 0.6 % ended 7.5-13.9σ off (flagged).
pub struct RateSquare;

impl Behaviour for RateSquare {
    fn name(&self) -> String {
        "square-law non-linearity (IEEE Std 952 K2)".into()
    }

    fn key(&self) -> String {
        "rate_square".into()
    }

    fn meaning(&self) -> &'static str {
        "the sense chain's output has a part in the square of the rate, alike for either sign"
    }

    fn identified_by(&self) -> &'static str {
        "the 2× line it makes in proportion to each axis's own rate squared, and a 1× part, where the table's own rate adds a constant to the axis's, that grows with the square of the speed"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![LinCol::Of(Effect::RateSquare, 0)], vec![])
    }

    /// r² per (°/s)² is reported at full scale, the natural unit of a non-linearity.
    fn reported(&self, _: Own, full_scale_dps: f64) -> Option<Reported> {
        Some(Reported::new("even quadratic (r²) at full scale", 100.0 * full_scale_dps, "% of full scale"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    fn value(&self, _: Own, p: &Point, a: usize, _: &AxisTerms, cx: &Ctx) -> f64 {
        cx.axis_rate(p, a).powi(2)
    }

    /// The L3G4200D's non-linearity, 0.2 % of full scale (datasheet, Table 4: best-fit straight
    /// line), as one σ of the square term at full scale: the datasheet does not give the shape,
    /// so each shape is allowed the whole of it.
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.has(Effect::RateSquare)).then_some(ConsiderBound {
            sigma: 0.2,
            source: "non-linearity 0.2 % of full scale (L3G4200D datasheet Table 4)",
        })
    }

    fn candidate(&self, s: &Situation) -> bool {
        s.evidence.rate_scale && !s.has(Effect::RateSquare)
    }

    fn rate_slope(&self, _: u16, r_dps: f64) -> Option<f64> {
        Some(2.0 * r_dps)
    }
}
