//! A delay and an index offset that the runs cannot tell apart.

use super::terms::{
    along_gradient, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar,
    Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// A delay and an index offset together when the runs share one θ2' and cannot tell them
/// apart: one phase δ − θ2'·τ (rad), the same maths as the index offset: it moves θ2, not the
/// gear mesh's angle.
pub struct Phase;

impl Behaviour for Phase {
    fn name(&self) -> String {
        "phase (delay and index offset combined)".into()
    }

    fn key(&self) -> String {
        "phase".into()
    }

    fn meaning(&self) -> &'static str {
        "a delay, an index offset, or both"
    }

    fn identified_by(&self) -> &'static str {
        "nothing more: a second speed or direction is needed to split it"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![], vec![SharedPar { effect: Effect::Phase, k: 0 }])
    }

    fn reported(&self, _: Own, _: f64) -> Option<Reported> {
        Some(Reported::new("phase δ − θ2'·τ", 180.0 / std::f64::consts::PI, "°"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, value: f64, s: &mut Shifts) {
        s.theta2_offset_rad += value;
    }

    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        along_gradient(t, self.gradient_factor(own, p, cx))
    }

    /// It moves θ2 as the index offset does (`Shifts::theta2_offset_rad`), not the gear mesh's
    /// angle, so its Jacobian is the index offset's: the delay's turns the mesh too, which with
    /// the gears' error in the model differs by that error's own derivative (5 % on the
    /// Jacobian test), as much as the ripple's timing that tells a delay from this phase at one
    /// speed ([`super::delay`]).
    fn gradient_factor(&self, _: Own, p: &Point, _: &Ctx) -> Option<[f64; 3]> {
        Some(p.d_theta2)
    }

    /// None: held by the delay's and the index offset's own terms.
    fn consider(&self, _: Own, _: &ConsiderCtx) -> Option<ConsiderBound> {
        None
    }

    fn candidate(&self, s: &Situation) -> bool {
        s.evidence.phase && !s.separates_delay_and_index && !s.has(Effect::Phase) && !s.phase_modelled()
    }
}
