//! An offset level of each stretch of capture its own.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// One σ of the step of the zero-rate level between two stretches of capture that no clock ties
/// (a capture file of its own, a remount, a pause), °/s, before the data bound its scale
/// ([`Behaviour::size_read_from_data`]): the die a fraction of a degree warmer or
/// cooler after the pause at the L3G4200D's zero-rate level change of ±0.03 °/s per °C
/// (datasheet Table 4, TCSo), and the offset's walk over a pause of a minute at
/// 0.003 °/s/√s (IEEE Std 952's MEMS range, [`super::drift_knots`]): 0.015 and 0.023 °/s;
/// 0.015 taken (engineering judgement). Larger steps the loop's run-to-run test sees, and the
/// free drift then gives each stretch its level.
const LEVEL_STEP_DPS: f64 = 0.015;

/// The offset of each stretch of capture other than the first its own level, in the model's
/// stead of one offset throughout. Never fitted as such (the free drift's knots give every
/// stretch its level when the loop finds the offset moving); while no drift does, the model
/// holds the offset equal in every stretch, and the step a pause can make is carried in σ: a
/// capture file per run with a level of its own, 0.005 °/s rms and unseen by the run-to-run
/// test, bent M through its constant rate θ2'·M R_qᵀ e_z2 by up to 3.84σ at ±180 °/s (the
/// trust bench's `/files` designs, z RMS 1.05-1.22 over their cells; docs/trust.md). Its
/// columns: per stretch after the first, 1 in it and 0 elsewhere.
pub struct StretchLevel;

impl Behaviour for StretchLevel {
    fn name(&self) -> String {
        "offset level of each stretch of capture".into()
    }

    fn key(&self) -> String {
        "stretch_level".into()
    }

    fn meaning(&self) -> &'static str {
        "the zero-rate level steps between stretches of capture that no clock ties (a capture file of its own, a remount, a pause): the die's temperature moved, the offset walked over the pause"
    }

    fn identified_by(&self) -> &'static str {
        "runs at two signed speeds within each stretch (one capture of all runs of a pose, as a live session records them): the stretch's level and its constant rate θ2'·M R_qᵀ e_z2 then part; a level that moves is then fitted by the free drift"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, layout: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        let n = layout.stretches.len();
        ((1..n).map(|s| LinCol::Of(Effect::StretchLevel, s as u16)).collect(), vec![])
    }

    fn reported(&self, own: Own, _: f64) -> Option<Reported> {
        let Own::Lin(k) = own else { return None };
        Some(Reported::new(format!("offset level of stretch {} against the first", k + 1), 1.0, "°/s"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    fn value(&self, own: Own, p: &Point, _: usize, _: &AxisTerms, _: &Ctx) -> f64 {
        match own {
            Own::Lin(k) if usize::from(k) == p.stretch => 1.0,
            _ => 0.0,
        }
    }

    /// [`LEVEL_STEP_DPS`] per stretch, times the 95 % bound the residual's own levels put on
    /// its scale, while the free drift does not give the stretches their levels (a drift curve in
    /// time or temperature runs through them without a step).
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.current.iter().any(|e| e.is_free_drift())).then_some(ConsiderBound {
            sigma: LEVEL_STEP_DPS,
            source: "the die's temperature step over a pause at the L3G4200D's ±0.03 °/s/°C (Table 4) and the offset's walk over it, engineering judgement",
        })
    }

    fn size_read_from_data(&self) -> Option<&'static str> {
        Some("as large as the residual's levels between stretches allow")
    }

    /// A level is constant within its stretch.
    fn turn_multiple(&self) -> u32 {
        0
    }

    /// Never: the free drift is the loop's model of an offset that moves between stretches.
    fn candidate(&self, _: &Situation) -> bool {
        false
    }
}
