//! An odd cubic in the rate along the axis: the sense chain saturating softly.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// Per axis r³, r the rate along the axis (the row of M normalised), counts per (°/s)³.
///
/// The datasheet bounds the non-linearity, not its shape: a chain whose gain changes with the
/// rate's size bends as r·|r| ([`super::rate_scale::RateScale`]), one that saturates softly (a
/// drive loop's amplitude control, a converter's front end) as r³. For a sinusoidal r of
/// amplitude A the two make a 3× line of −1/5 (r·|r|) and −1/3 (r³) of their 1× part, and that 1×
/// part grows as A² and A³: modelled as r·|r|, an r³ bend is mistaken in the 1× part M takes up.
/// On the simulator 0.2 % of full scale of r³ left the default design 6.5-7.5σ off at exit 0
/// before this effect was catalogued. An effect of its own rather than a third column of
/// r·|r|'s: each shape is then tested, and considered, against M alone, and the pair's common
/// direction (large coefficients of opposite sign whose harmonics cancel) is not charged to
/// every session that has neither.
pub struct RateCubic;

impl Behaviour for RateCubic {
    fn name(&self) -> String {
        "cubic non-linearity (soft saturation)".into()
    }

    fn key(&self) -> String {
        "rate_cubic".into()
    }

    fn meaning(&self) -> &'static str {
        "the sense chain saturates softly: its gain changes with the square of the rate"
    }

    fn identified_by(&self) -> &'static str {
        "the 3× line it makes in proportion to each axis's own rate cubed (2× too where the table's own rate adds a constant to the axis's), and a 1× part that grows with the cube of the speed"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![LinCol::Of(Effect::RateCubic, 0)], vec![])
    }

    /// r³ per (°/s)³ is reported at full scale, the natural unit of a non-linearity.
    fn reported(&self, _: Own, full_scale_dps: f64) -> Option<Reported> {
        Some(Reported::new("odd cubic (r³) at full scale", 100.0 * full_scale_dps.powi(2), "% of full scale"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    fn value(&self, _: Own, p: &Point, a: usize, _: &AxisTerms, cx: &Ctx) -> f64 {
        cx.axis_rate(p, a).powi(3)
    }

    /// The L3G4200D's non-linearity, 0.2 % of full scale (datasheet, Table 4: best-fit straight
    /// line), as one σ of the cubic at full scale: the datasheet does not give the shape, so
    /// each shape is allowed the whole of it.
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.has(Effect::RateCubic)).then_some(ConsiderBound {
            sigma: 0.2,
            source: "non-linearity 0.2 % of full scale (L3G4200D datasheet Table 4)",
        })
    }

    fn candidate(&self, s: &Situation) -> bool {
        s.evidence.rate_scale && !s.has(Effect::RateCubic)
    }

    fn rate_slope(&self, _: u16, r_dps: f64) -> Option<f64> {
        Some(3.0 * r_dps * r_dps)
    }
}
