//! The index plate is off the θ2 the poses are defined for.

use super::terms::{
    along_gradient, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar,
    Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// The index plate is δ off θ2 = 0: θ2_true = θ2_index + δ, the same shift at every speed. One
/// parameter, δ (rad).
pub struct IndexOffset;

impl Behaviour for IndexOffset {
    fn name(&self) -> String {
        "index offset".into()
    }

    fn key(&self) -> String {
        "index_offset".into()
    }

    fn meaning(&self) -> &'static str {
        "the index shield plate is mounted off the θ2 the poses are defined for"
    }

    fn identified_by(&self) -> &'static str {
        "runs at two speeds or in both directions (the delay's phase scales with θ2', the index offset's does not)"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![], vec![SharedPar { effect: Effect::IndexOffset, k: 0 }])
    }

    fn reported(&self, _: Own, _: f64) -> Option<Reported> {
        Some(Reported::new("index offset δ", 180.0 / std::f64::consts::PI, "°"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, value: f64, s: &mut Shifts) {
        s.theta2_offset_rad += value;
    }

    /// It moves θ2 but not the gear mesh's angle (the ripple is tied to the gear, not to where
    /// θ2 = 0 is).
    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        along_gradient(t, self.gradient_factor(own, p, cx))
    }

    fn gradient_factor(&self, _: Own, p: &Point, _: &Ctx) -> Option<[f64; 3]> {
        Some(p.d_theta2)
    }

    /// 1°: the index plate is 2° wide, and an edge taken for its centre is 1° off (engineering
    /// judgement).
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.has(Effect::IndexOffset) && !cx.has(Effect::Phase)).then_some(ConsiderBound {
            sigma: 1.0,
            source: "half the 2° width of the index plate (an edge taken for its centre), engineering judgement",
        })
    }

    fn candidate(&self, s: &Situation) -> bool {
        s.evidence.phase && s.separates_delay_and_index && !s.has(Effect::IndexOffset) && !s.has(Effect::Phase)
    }
}
