//! A power of the rate along the axis: the non-linearity's other shapes.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// The powers catalogued: IEEE Std 952's square law and the odd cubic.
pub const RATE_POWERS: [u8; 2] = [2, 3];

/// Per axis rⁿ (n = 2 or 3), r the rate along the axis (the row of M normalised), counts per
/// (°/s)ⁿ.
///
/// The datasheet bounds the non-linearity, not its shape. [`super::rate_scale::RateScale`] holds
/// a gain that changes with the rate's size (r·|r|) and an asymmetry (|r|). A chain that
/// saturates softly (a drive loop's amplitude control, a converter's front end) bends as r³; IEEE
/// Std 952 writes the scale factor as a power series whose second term, K2·r², is even. On this
/// rig an axis's rate is a sinusoid of amplitude A about a constant C (the table's own rate along
/// the axis):
/// - r³ makes a 3× line of −1/3 of its 1× part, where r·|r|'s is −1/5, and a 1× part growing as
///   A³: modelled as r·|r|, the 1× part M takes up is mistaken, and 0.2 % of full scale of r³ left
///   the default design 6.5-7.5σ off at exit 0 on the simulator;
/// - r² makes a 2× line of A²/2 and a 1× part 2·A·C that grows with the square of the speed: at
///   two speeds the runs disagreed about M, and the default design was flagged on every seed.
///
/// Each power is an effect of its own rather than more columns of r·|r|'s: each is then tested,
/// and considered, against M alone. As a third column of r·|r|'s, r³ gave the pair a direction
/// (coefficients of opposite sign whose harmonics cancel) that 120-s runs see at λ = 10, and its
/// bound tripled every session's σ of the sensitivities.
pub struct RatePower(pub u8);

impl Behaviour for RatePower {
    fn name(&self) -> String {
        match self.0 {
            2 => "square-law non-linearity (IEEE Std 952 K2)".into(),
            3 => "cubic non-linearity (soft saturation)".into(),
            n => format!("non-linearity in the rate to the power {n}"),
        }
    }

    /// `rate_square` and `rate_cubic`: what `--consider` and loop.json call them.
    fn key(&self) -> String {
        match self.0 {
            2 => "rate_square".into(),
            3 => "rate_cubic".into(),
            n => format!("rate_power_{n}"),
        }
    }

    fn meaning(&self) -> &'static str {
        if self.0.is_multiple_of(2) {
            "the sense chain's output has a part in the square of the rate, alike for either sign"
        } else {
            "the sense chain saturates softly: its gain changes with the square of the rate"
        }
    }

    fn identified_by(&self) -> &'static str {
        if self.0.is_multiple_of(2) {
            "the 2× line it makes in proportion to each axis's own rate squared, and a 1× part, where the table's own rate adds a constant to the axis's, that grows with the square of the speed"
        } else {
            "the 3× line it makes in proportion to each axis's own rate cubed (2× too where the table's own rate adds a constant to the axis's), and a 1× part that grows with the cube of the speed"
        }
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![LinCol::Of(Effect::RatePower(self.0), 0)], vec![])
    }

    /// rⁿ per (°/s)ⁿ is reported at full scale, the natural unit of a non-linearity.
    fn reported(&self, _: Own, full_scale_dps: f64) -> Option<Reported> {
        let name = match self.0 {
            2 => "even quadratic (r²) at full scale".into(),
            3 => "odd cubic (r³) at full scale".into(),
            n => format!("r^{n} at full scale"),
        };
        Some(Reported::new(name, 100.0 * full_scale_dps.powi(i32::from(self.0) - 1), "% of full scale"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    fn value(&self, _: Own, p: &Point, a: usize, _: &AxisTerms, cx: &Ctx) -> f64 {
        cx.axis_rate(p, a).powi(i32::from(self.0))
    }

    /// The L3G4200D's non-linearity, 0.2 % of full scale (datasheet, Table 4: best-fit straight
    /// line), as one σ of the power's term at full scale: the datasheet does not give the
    /// shape, so each shape is allowed the whole of it.
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.has(Effect::RatePower(self.0))).then_some(ConsiderBound {
            sigma: 0.2,
            source: "non-linearity 0.2 % of full scale (L3G4200D datasheet Table 4)",
        })
    }

    /// rⁿ of the axis's rate, a sinusoid at the turn rate about a constant, has lines up to n×.
    fn turn_multiple(&self) -> u32 {
        u32::from(self.0)
    }

    fn candidate(&self, s: &Situation) -> bool {
        s.evidence.rate_scale && !s.has(Effect::RatePower(self.0))
    }

    fn rate_slope(&self, _: u16, r_dps: f64) -> Option<f64> {
        let n = i32::from(self.0);
        Some(f64::from(n) * r_dps.powi(n - 1))
    }
}
