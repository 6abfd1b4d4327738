//! The gyro's output lags the encoder.

use super::terms::{
    along_gradient, shift_vector, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point,
    Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// Longest delay (either sign) the model represents, s: 50 ms is 6× the slowest L3G4200D filter
/// delay (7.5 ms at 30 Hz cut-off, `sim::FilterDelay`). Samples within it of a run's ends or of a
/// gap are left out of every fit, so that all models see the same samples.
pub const MAX_DELAY_S: f64 = 0.05;

/// The gyro output lags the encoder by τ: v(t) = f(kinematics at t − τ). Shifts θ2 by −θ2'·τ,
/// so it differs from an index offset only between runs at different θ2'. One parameter, τ (s).
pub struct Delay;

impl Behaviour for Delay {
    fn name(&self) -> String {
        "delay between gyro and encoder".into()
    }

    fn key(&self) -> String {
        "delay".into()
    }

    fn meaning(&self) -> &'static str {
        "the gyro's low-pass filter delays its output (≈√2/(2π·f_c): 2 ms at 110 Hz, 7.5 ms at 30 Hz)"
    }

    fn identified_by(&self) -> &'static str {
        "runs at two speeds or in both directions (the delay's phase scales with θ2', the index offset's does not)"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![], vec![SharedPar { effect: Effect::Delay, k: 0 }])
    }

    fn reported(&self, _: Own, _: f64) -> Option<Reported> {
        Some(Reported::new("delay τ", 1e3, "ms"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        Some(Bound { lo: -MAX_DELAY_S, hi: MAX_DELAY_S, what: "delay", unit: "s" })
    }

    fn shift(&self, _: u8, value: f64, s: &mut Shifts) {
        s.delay_s = value;
    }

    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        along_gradient(t, self.gradient_factor(own, p, cx))
    }

    /// Delaying by τ moves θ2 by −θ2'·τ (and the angles after it with it), and θ1' by −θ1''·τ:
    /// the motor's own speed ripple, which the encoder's rates carry and the output follows as
    /// ω_s/θ1' (every table term is in proportion to θ1'; Earth's 1e-5 of it aside), as the
    /// delay between the axes' column has it ([`super::axis_delay`]). The model shifts both
    /// (`Evaluator::full_point` reads the kinematics τ earlier); a column without the second saw
    /// nothing of the ripple's timing, which at one speed, where the phase takes θ2's part, is
    /// all a delay adds ([`Delay::candidate`]).
    fn gradient_factor(&self, _: Own, p: &Point, _: &Ctx) -> Option<[f64; 3]> {
        let per_s = -p.rate2_dps.to_radians();
        let per_rate = if p.theta1_rate_dps == 0.0 { 0.0 } else { -p.theta1_accel_dps2 / p.theta1_rate_dps };
        let shift = shift_vector(p);
        Some(std::array::from_fn(|i| per_s * shift[i] + per_rate * p.omega[i]))
    }

    /// 5 ms: the L3G4200D's LPF2 cut-off is 30-110 Hz at 800 Hz ODR (datasheet, Table 5); a
    /// filter chain's group delay there is ≈ 1/(2π·30 Hz) = 5.3 ms (engineering judgement).
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.has(Effect::Delay) && !cx.has(Effect::Phase)).then_some(ConsiderBound {
            sigma: 5.0,
            source: "group delay of the L3G4200D's low-pass chain at its 30-Hz cut-off (datasheet Table 5), engineering judgement",
        })
    }

    /// Where the runs separate it from an index offset, when the residual shows a phase. Where
    /// they do not (one signed speed), the combined phase comes first ([`super::phase`]); a delay
    /// on top of it is then told only by what the speed does within a run: the motor's ripple
    /// reaches the gyro through its filter τ later than the encoder reads it, which a phase
    /// cannot follow, and leaves lines beside the ripple's order, (n ± 1)× θ2, in the residual.
    /// The trust bench's one-speed cells with a 35-Hz filter (9 ms) and the default 0.1 % ripple
    /// at 12×: lines of 0.035 °/s (12σ) at 11× and 13×, flagged on every seed, which the delay
    /// takes (`docs/trust.md`). Without a ripple the pair is singular and never passes.
    fn candidate(&self, s: &Situation) -> bool {
        if s.has(Effect::Delay) {
            return false;
        }
        if s.separates_delay_and_index {
            s.evidence.phase && !s.has(Effect::Phase)
        } else {
            s.has(Effect::Phase) && s.evidence.orders[2..].contains(&true)
        }
    }
}
