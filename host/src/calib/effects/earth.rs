//! Earth's rotation, fixed in the lab, seen through θ1 and θ2.

use super::terms::{
    along_gradient, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Needs, Own, PhysicalPrior, Point,
    Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// Which of Earth's rate components are fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Form {
    /// All three: its component along the base axis adds to θ1' (a scale error that shrinks
    /// with speed), its horizontal component turns with the base.
    Fitted,
    /// The two horizontal ones (the heading); the vertical part is known from the latitude the
    /// user gave.
    AtLatitude,
    /// The two horizontal ones, in a model with g-sensitivity and no latitude: the vertical part
    /// turns in the sensor frame exactly as gravity does (both lie along the base axis), so it
    /// is a g-sensitivity along M's rows, ≤ Ω/g = 0.0042 °/s/g, and that term holds it; the
    /// sensitivities and directions do not depend on which of the two holds it.
    Horizontal,
}

/// Earth's rotation: parameter k = 0 its rate along the base axis z1 (vertical), 1 the
/// horizontal component along the direction the base points to when the index reads θ2 = 0,
/// 2 the horizontal component 90° further on, °/s. Known physics: added once the loop ends,
/// never a candidate.
pub struct Earth(pub Form);

impl Earth {
    fn effect(&self) -> Effect {
        match self.0 {
            Form::Fitted => Effect::EarthRotation,
            Form::AtLatitude => Effect::EarthRotationAtLatitude,
            Form::Horizontal => Effect::EarthRotationHorizontal,
        }
    }
}

impl Behaviour for Earth {
    fn name(&self) -> String {
        match self.0 {
            Form::Fitted => "Earth rotation",
            Form::AtLatitude => "Earth rotation (vertical from the latitude)",
            Form::Horizontal => "Earth rotation (horizontal; vertical held by the g-sensitivity)",
        }
        .into()
    }

    fn key(&self) -> String {
        match self.0 {
            Form::Fitted => "earth_rotation",
            Form::AtLatitude => "earth_rotation_at_latitude",
            Form::Horizontal => "earth_rotation_horizontal",
        }
        .into()
    }

    fn meaning(&self) -> &'static str {
        "the lab turns with the Earth at 15.041 °/h (IERS: 7.292115e-5 rad/s); at 180 °/s its vertical part alone is ≈ 13 ppm of θ1'"
    }

    fn identified_by(&self) -> &'static str {
        match self.0 {
            Form::Fitted => {
                "runs at two speeds or in both directions (its vertical part does not scale with θ1', a sensitivity does); the horizontal part turns with the base angle θ1"
            }
            Form::AtLatitude => {
                "the base angle θ1: the horizontal part turns with it; the vertical part is Ω·sin(latitude), given"
            }
            Form::Horizontal => {
                "the base angle θ1: the horizontal part turns with it; the vertical part cannot be told from a g-sensitivity along M's rows, which holds it"
            }
        }
    }

    fn kind(&self) -> Kind {
        Kind::Earth
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        let first = if self.0 == Form::Fitted { 0 } else { 1 };
        (vec![], (first..3).map(|k| SharedPar { effect: self.effect(), k }).collect())
    }

    fn reported(&self, own: Own, _: f64) -> Option<Reported> {
        let Own::Shared(k) = own else { return None };
        let name = match k {
            0 => "Earth rate, vertical",
            1 => "Earth rate, horizontal at θ2 = 0",
            _ => "Earth rate, horizontal 90° on",
        };
        Some(Reported::new(name, 3600.0, "°/h"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    /// No component is larger than Ω (15.041 °/h, IERS). Each of a vector of that length in a
    /// direction not known has σ Ω/√3; the horizontal ones, with the vertical known from the
    /// latitude, at most Ω/√2 (a length Ω·cos φ ≤ Ω in an unknown heading). Runs that cannot
    /// tell a component from the model's other terms (the vertical beside a gyro filter's droop
    /// at two speeds in one direction: 1143 ± 634 °/h on a 20-Hz filter, every sensitivity's σ
    /// 9000 ppm) leave it to this prior.
    fn prior(&self, _: u8) -> Option<PhysicalPrior> {
        let omega_dps = crate::geometry::EARTH_RATE_RAD_S.to_degrees();
        let sigma = match self.0 {
            Form::AtLatitude => omega_dps / 2f64.sqrt(),
            Form::Fitted | Form::Horizontal => omega_dps / 3f64.sqrt(),
        };
        Some(PhysicalPrior { bound: omega_dps, sigma })
    }

    fn shift(&self, k: u8, value: f64, s: &mut Shifts) {
        s.earth_dps[usize::from(k)] = value;
    }

    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        along_gradient(t, self.gradient_factor(own, p, cx))
    }

    fn gradient_factor(&self, own: Own, p: &Point, _: &Ctx) -> Option<[f64; 3]> {
        let Own::Shared(k) = own else { return None };
        Some(p.d_earth[usize::from(k)])
    }

    /// While no form of Earth's rotation is in the model, the fitted form's three components
    /// each carry Ω/√3 (Ω = 15.041 °/h, IERS; a vector of that length in an unknown direction).
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (self.0 == Form::Fitted && !cx.current.iter().any(|e| e.is_earth())).then(|| ConsiderBound {
            sigma: crate::geometry::EARTH_RATE_RAD_S.to_degrees() * 3600.0 / 3f64.sqrt(),
            source: "Earth's rate, 15.041 °/h (IERS Conventions 2010), in a direction not known",
        })
    }

    fn candidate(&self, _: &Situation) -> bool {
        false
    }

    /// The horizontal parts turn with the base's heading θ1.
    fn needs(&self, own: Own) -> Needs {
        Needs { heading: own != Own::Shared(0), ..Needs::NONE }
    }
}
