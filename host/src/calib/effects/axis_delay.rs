//! The gyro's axes sampled at different instants.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};
use crate::calib::result::axes::AXES;

/// Largest delay of an axis behind x the model represents, s. The shift is first-order in
/// θ2'·δ: the term it leaves out is (θ2'·δ)²/2 of the signal, 5 ppm at 1 ms and 180 °/s.
pub const MAX_AXIS_DELAY_S: f64 = 1e-3;

/// Each axis's output lags x's by its own δ (beyond the common delay): axis a reads the
/// kinematics at t − τ − δ_a, to first order its output moved by −θ2'·δ_a·∂v_a/∂θ2. A delay
/// that differs between the axes turns each axis's apparent direction about the table axis by
/// θ2'·δ_a: 0.018° per 0.1 ms at 180 °/s. Two parameters: δ_y and δ_z (s).
pub struct AxisDelay;

impl Behaviour for AxisDelay {
    fn name(&self) -> String {
        "delay between the gyro's axes".into()
    }

    fn key(&self) -> String {
        "axis_delay".into()
    }

    fn meaning(&self) -> &'static str {
        "the gyro samples its axes at different instants (a multiplexed converter: a third of an output period apart) or its sense channels lag differently; each axis looks turned about the table axis by θ2'·δ"
    }

    fn identified_by(&self) -> &'static str {
        "runs at two speeds or in both directions: the turn scales with θ2', a direction does not"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![], (0..2).map(|k| SharedPar { effect: Effect::AxisDelay, k }).collect())
    }

    fn reported(&self, own: Own, _: f64) -> Option<Reported> {
        let Own::Shared(k) = own else { return None };
        Some(Reported::new(format!("delay of {} behind x", AXES[usize::from(k) + 1]), 1e3, "ms"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        Some(Bound { lo: -MAX_AXIS_DELAY_S, hi: MAX_AXIS_DELAY_S, what: "delay between axes", unit: "s" })
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    /// First order in θ2'·δ ([`MAX_AXIS_DELAY_S`]): the prediction adds δ times the column.
    fn on_output(&self) -> bool {
        true
    }

    /// Delaying axis a by δ moves its output by −δ·dv_a/dt: its θ2 by −θ2'·δ, and its θ1' by
    /// −θ1''·δ. The second is the motor's own speed ripple (the encoder's rates carry it), which
    /// the output follows as ∂v_a/∂θ1' ([`AxisTerms::per_theta1_rate`]). Without it a 0.6 %
    /// ripple at the 16-pole gears' pole pass and a 0.24-ms delay left a 6σ line at 16× on one
    /// axis (`docs/trust.md`, drawn rig at 3×).
    fn value(&self, own: Own, p: &Point, a: usize, t: &AxisTerms, _: &Ctx) -> f64 {
        match own {
            Own::Shared(k) if usize::from(k) + 1 == a => {
                -p.rate2_dps.to_radians() * t.d_shift - p.theta1_accel_dps2 * t.per_theta1_rate(p)
            }
            _ => 0.0,
        }
    }

    /// 0.05 ms: a gyro that converts its axes together still shows its sense resonators' phase
    /// mismatch, tens of µs (engineering judgement; the L3G4200D datasheet gives no figure). A
    /// part with one multiplexed converter needs `--consider axis_delay=` a third of its output
    /// period (0.42 ms at 800 Hz).
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.has(Effect::AxisDelay)).then_some(ConsiderBound {
            sigma: 0.05,
            source: "phase mismatch between a MEMS gyro's sense channels, tens of µs (engineering judgement; none in the L3G4200D datasheet)",
        })
    }

    /// Whenever the runs turn at two signed speeds (a g-sensitivity also turns the axes at the
    /// table frequency, and would take the structure if tried alone).
    fn candidate(&self, s: &Situation) -> bool {
        s.separates_delay_and_index && !s.has(Effect::AxisDelay)
    }
}
