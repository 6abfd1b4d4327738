//! Scale depending on the rate along the axis.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// Scale depending on the rate r along the axis (the row of M normalised): per axis |r|
/// (asymmetry between the signs, counts per °/s) and r·|r| (odd quadratic non-linearity,
/// counts per (°/s)²).
pub struct RateScale;

impl Behaviour for RateScale {
    fn name(&self) -> String {
        "rate-dependent scale (non-linearity, asymmetry)".into()
    }

    fn key(&self) -> String {
        "rate_scale".into()
    }

    fn meaning(&self) -> &'static str {
        "the sense chain is not linear, or its gain differs with the sign of the rate"
    }

    fn identified_by(&self) -> &'static str {
        "the harmonics it makes in proportion to each axis's own rate"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![LinCol::Of(Effect::RateScale, 0), LinCol::Of(Effect::RateScale, 1)], vec![])
    }

    /// r·|r| per (°/s)² is reported at full scale, the natural unit of a non-linearity.
    fn reported(&self, own: Own, full_scale_dps: f64) -> Option<Reported> {
        Some(match own {
            Own::Lin(0) => Reported::new("scale asymmetry (|r| term)", 1e6, "ppm of |r|"),
            _ => Reported::new("odd quadratic (r·|r|) at full scale", 100.0 * full_scale_dps, "% of full scale"),
        })
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    fn value(&self, own: Own, p: &Point, a: usize, _: &AxisTerms, cx: &Ctx) -> f64 {
        let r = cx.axis_rate(p, a);
        match own {
            Own::Lin(0) => r.abs(),
            _ => r * r.abs(),
        }
    }

    /// The L3G4200D's non-linearity, 0.2 % of full scale (datasheet, Table 4: best-fit straight
    /// line), as one σ of either term at full scale (2000 ppm of |r| for the asymmetry).
    fn consider(&self, own: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        if cx.has(Effect::RateScale) {
            return None;
        }
        let source = "non-linearity 0.2 % of full scale (L3G4200D datasheet Table 4)";
        Some(match own {
            Own::Lin(0) => ConsiderBound { sigma: 2000.0, source },
            _ => ConsiderBound { sigma: 0.2, source },
        })
    }

    /// r·|r| of a sinusoid about a constant has a 3× line, |r| lines at 2× and 4× falling as 1/n².
    fn turn_multiple(&self) -> u32 {
        3
    }

    fn candidate(&self, s: &Situation) -> bool {
        s.evidence.rate_scale && !s.has(Effect::RateScale)
    }

    fn rate_slope(&self, k: u16, r_dps: f64) -> Option<f64> {
        Some(if k == 0 { r_dps.signum() } else { 2.0 * r_dps.abs() })
    }
}
