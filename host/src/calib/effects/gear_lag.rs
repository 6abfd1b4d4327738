//! The sensor table trailing the base by an angle that grows with speed.

use super::terms::{
    along_gradient, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar,
    Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// The sensor table lags the base by an angle proportional to speed (the magnetic gears'
/// compliance under drag): the transmission error's argument is θ1 + θ1'·c, while θ2 itself is
/// what the index says. Only the transmission error's phase tells it from a gyro delay. One
/// parameter, c (s).
pub struct GearLag;

impl Behaviour for GearLag {
    fn name(&self) -> String {
        "magnetic-gear lag growing with speed".into()
    }

    fn key(&self) -> String {
        "gear_lag".into()
    }

    fn meaning(&self) -> &'static str {
        "the sensor table trails the base by an angle that grows with speed, so the gears' pole-pass error reaches it later than the base angle says"
    }

    fn identified_by(&self) -> &'static str {
        "a transmission error seen at two speeds: its phase against the base angle shifts with speed, the gyro delay's does not"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![], vec![SharedPar { effect: Effect::GearLag, k: 0 }])
    }

    fn reported(&self, _: Own, _: f64) -> Option<Reported> {
        Some(Reported::new("gear lag per unit of speed", 1e3, "ms"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, value: f64, s: &mut Shifts) {
        s.gear_lag_s = value;
    }

    /// Moving the gear angle moves the rippled angle by (ripple − 1) and the rippled speed by
    /// θ2'·∂ripple/∂θ; it also moves the error the index pulse saw.
    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        along_gradient(t, self.gradient_factor(own, p, cx))
    }

    fn gradient_factor(&self, _: Own, p: &Point, cx: &Ctx) -> Option<[f64; 3]> {
        let (along_theta2, along_rate2) = (
            p.theta1_rate_rad_s * (p.dtheta_eff - 1.0) - cx.index_edge[p.run].dshift_dlag,
            p.theta1_rate_rad_s * p.drate_eff_dps,
        );
        Some(std::array::from_fn(|i| along_theta2 * p.d_theta2[i] + along_rate2 * p.d_rate2[i]))
    }

    /// None: it moves only the transmission error's phase, never M or the offsets.
    fn consider(&self, _: Own, _: &ConsiderCtx) -> Option<ConsiderBound> {
        None
    }

    /// Once a transmission error is in, when the runs have two speeds.
    fn candidate(&self, s: &Situation) -> bool {
        let has_transmission = s.current.iter().any(|e| matches!(e, Effect::TableHarmonic(_)));
        has_transmission && !s.has(Effect::GearLag) && s.separates_delay_and_index
    }
}
