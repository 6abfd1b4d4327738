//! The sensor-table axis not perpendicular to the base axis.

use super::terms::{
    along_gradient, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar,
    Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// The sensor-table axis z2 not perpendicular to the base axis z1 by ε: θ1' then has a part
/// θ1'·sin ε along z2, which adds to θ2' in proportion to speed, and its in-plane part is scaled
/// by cos ε. One parameter, ε (rad).
pub struct TableTilt;

impl Behaviour for TableTilt {
    fn name(&self) -> String {
        "sensor-table axis not perpendicular to the base axis".into()
    }

    fn key(&self) -> String {
        "table_tilt".into()
    }

    fn meaning(&self) -> &'static str {
        "the sensor table's axis is built a fraction of a degree off 90° to the base axis (0.1-0.5° is typical of such a rig)"
    }

    fn identified_by(&self) -> &'static str {
        "runs at two speeds or directions recorded in one capture per pose: its part of θ2' scales with θ1', an offset does not (a capture per run has a level of its own, which takes that part, and leaves the tilt a scale of M)"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![], vec![SharedPar { effect: Effect::TableTilt, k: 0 }])
    }

    fn reported(&self, _: Own, _: f64) -> Option<Reported> {
        Some(Reported::new("sensor-table axis tilt ε", 180.0 / std::f64::consts::PI, "°"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, value: f64, s: &mut Shifts) {
        s.tilt_sin_cos = value.sin_cos();
    }

    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        along_gradient(t, self.gradient_factor(own, p, cx))
    }

    fn gradient_factor(&self, _: Own, p: &Point, _: &Ctx) -> Option<[f64; 3]> {
        let along_rate2 = p.theta1_rate_dps * p.cos_tilt;
        Some(std::array::from_fn(|i| along_rate2 * p.d_rate2[i] + p.d_tilt[i]))
    }

    /// 0.3°: a table shaft in a bearing seat machined to 0.1 mm over a 20-mm span (engineering
    /// judgement; the simulator's `table_tilt` default).
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.has(Effect::TableTilt)).then_some(ConsiderBound {
            sigma: 0.3,
            source: "sensor-table shaft in a seat machined to 0.1 mm over 20 mm, engineering judgement",
        })
    }

    /// cos ε = 1 − ε²/2 + …: the in-plane rates, which alone give M where each capture has a
    /// level of its own, lose ε²/2 (14 ppm at 0.3°, 136 ppm at 0.94°), every axis alike. The
    /// column, ∂/∂ε at ε = 0, has none of it.
    fn scale_per_square(&self, _: Own) -> Option<f64> {
        Some(0.5)
    }

    /// Acting at the table's own frequency, it shows only between runs at different speeds, so
    /// it is tried whenever they separate it; not when the free drift's per-run levels hold its
    /// constant rate.
    fn candidate(&self, s: &Situation) -> bool {
        s.separates_delay_and_index
            && !s.has(Effect::TableTilt)
            && (!s.has_free_drift() || s.free_drift_keeps_constant_rates)
    }
}
