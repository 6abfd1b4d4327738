//! The rig's time base off its nominal frequency.

use super::terms::{
    along_gradient, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar,
    Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// Every timestamp the rig sends counts its timer, clocked by the MCU's crystal. With that
/// clock fast by ε, the encoder's rates come out (1 − ε) of the truth while the gyro measures
/// the truth: the gyro's output is M(1 + ε)·ω_measured. One parameter, ε (ppm).
///
/// No run separates it: it scales the whole signal alike at every speed, in every direction and
/// pose, exactly as a common scale of M does. So it is never fitted (no candidate rule); it only
/// enters the consider covariance, where it moves every sensitivity together and leaves the
/// directions and the angles between the axes alone.
pub struct RigClock;

impl Behaviour for RigClock {
    fn name(&self) -> String {
        "rig time base (crystal frequency error)".into()
    }

    fn key(&self) -> String {
        "rig_clock".into()
    }

    fn meaning(&self) -> &'static str {
        "the rig times the encoder with its own crystal: a clock fast by ε ppm makes every sensitivity ε ppm high"
    }

    fn identified_by(&self) -> &'static str {
        "none: it scales the signal as M does at every speed and in every direction; measure the rig's crystal instead (its 8 MHz on the MCO1 pin, with a frequency counter) and declare what remains with --consider rig_clock=PPM"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![], vec![SharedPar { effect: Effect::RigClock, k: 0 }])
    }

    fn reported(&self, _: Own, _: f64) -> Option<Reported> {
        Some(Reported::new("rig clock frequency error", 1.0, "ppm"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    /// The gyro's output is the model's signal times 1 + ε: the prediction adds ε times the column.
    fn on_output(&self) -> bool {
        true
    }

    /// ∂(output)/∂ε: the model's own rate signal on the axis, per ppm.
    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        along_gradient(t, self.gradient_factor(own, p, cx))
    }

    fn gradient_factor(&self, _: Own, p: &Point, _: &Ctx) -> Option<[f64; 3]> {
        Some(p.omega.map(|w| 1e-6 * w))
    }

    /// 20 ppm: the firmware runs on an 8 MHz HSE crystal (`firmware/src/main.rs`); parts of that
    /// class are specified to ±30 ppm at 25 °C (a uniform bound: 17 ppm, GUM 4.3.7), and a board
    /// whose load capacitors do not match the crystal's load capacitance pulls it by more (ST
    /// AN2867 §3.3; STM32F4DISCOVERY's user manual does not give the crystal's), with a few ppm
    /// for a year's ageing (engineering judgement).
    fn consider(&self, _: Own, _: &ConsiderCtx) -> Option<ConsiderBound> {
        Some(ConsiderBound {
            sigma: 20.0,
            source: "the rig's 8 MHz crystal: ±30 ppm at 25 °C as a uniform bound, load-capacitance pulling and ageing (engineering judgement)",
        })
    }

    fn candidate(&self, _: &Situation) -> bool {
        false
    }
}
