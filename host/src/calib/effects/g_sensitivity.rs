//! A rate bias in proportion to gravity.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};
use crate::calib::result::axes::AXES;

/// g-sensitivity: a bias in proportion to the specific force, here gravity, which turns in the
/// sensor frame with θ2 at the table's own frequency (so it bends directions): three
/// coefficients per axis, °/s per g, of gravity's components in the package frame. Gravity
/// holds the lab's −z1, so a table at rest feels +1 g along z1 = (sin θ2, cos θ2, 0) in O2.
pub struct GSensitivity;

impl Behaviour for GSensitivity {
    fn name(&self) -> String {
        "g-sensitivity (bias from gravity)".into()
    }

    fn key(&self) -> String {
        "g_sensitivity".into()
    }

    fn meaning(&self) -> &'static str {
        "the MEMS proof masses feel gravity as a rate bias (typically 0.02-0.1 °/s/g); gravity turns with θ2 in the sensor frame"
    }

    fn identified_by(&self) -> &'static str {
        "runs at two speeds: the bias does not scale with θ1', a direction or sensitivity does"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        ((0..3).map(|k| LinCol::Of(Effect::GSensitivity, k)).collect(), vec![])
    }

    fn reported(&self, own: Own, _: f64) -> Option<Reported> {
        let Own::Lin(k) = own else { return None };
        Some(Reported::new(format!("g-sensitivity along package {}", AXES[usize::from(k)]), 1.0, "°/s per g"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    /// z1 in the package frame is the vertical column of Earth's basis.
    fn value(&self, own: Own, p: &Point, _: usize, _: &AxisTerms, _: &Ctx) -> f64 {
        let Own::Lin(k) = own else { return 0.0 };
        p.d_earth[0][usize::from(k)]
    }

    /// 0.1 °/s per g on each component: the L3G4200D datasheet gives none; MEMS gyros of its
    /// class give 0.1 °/s/g typical (InvenSense MPU-6000 product specification, §6.1), taken
    /// as one σ (engineering judgement).
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.has(Effect::GSensitivity)).then_some(ConsiderBound {
            sigma: 0.1,
            source: "typical linear-acceleration sensitivity of a MEMS gyro (MPU-6000 spec. §6.1; none in the L3G4200D datasheet)",
        })
    }

    /// Tried whenever two speeds separate it (it acts at the table's own frequency, so one fit's
    /// residual cannot show it). With nine parameters it could soak up a phase error, but the
    /// selection takes the most significant drop for its parameter count, which a one-parameter
    /// delay or index offset wins when the structure is a phase; keeping it out while a phase is
    /// suspected let a real g-sensitivity end in a drift model and a biased M (the trust bench,
    /// `180,90@120`, `g_sensitivity`: 300 ppm, flagged only by the runs' disagreement).
    ///
    /// With the filter's droop in the model, only where the rates also tell gravity (∝ 1) from
    /// M (∝ θ2') and the droop (∝ θ2'³) ([`Situation::separates_rate_powers`]).
    fn candidate(&self, s: &Situation) -> bool {
        let shapes_apart = !s.has(Effect::FilterGain) || s.separates_rate_powers(&[0, 1, 3]);
        s.separates_delay_and_index && !s.has(Effect::GSensitivity) && shapes_apart
    }
}
