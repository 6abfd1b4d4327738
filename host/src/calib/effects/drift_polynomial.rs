//! Offsets drifting as a quadratic in time.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// Offsets drifting as a quadratic in time: per axis the first two Legendre polynomials of the
/// time scaled to [−1, 1] over the capture (orthogonal, so the terms do not trade off).
pub struct DriftPolynomial;

impl Behaviour for DriftPolynomial {
    fn name(&self) -> String {
        "offset drift: quadratic in time".into()
    }

    fn key(&self) -> String {
        "drift_polynomial".into()
    }

    fn meaning(&self) -> &'static str {
        "the zero-rate level wanders slowly"
    }

    fn identified_by(&self) -> &'static str {
        "its slow change within and between runs; runs in both directions separate the offset from the constant θ2' term without relying on it"
    }

    fn kind(&self) -> Kind {
        Kind::Drift {
            offset_reference: "the middle of the capture's time span, less half the quadratic term",
            free: false,
        }
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![LinCol::Of(Effect::DriftPolynomial, 0), LinCol::Of(Effect::DriftPolynomial, 1)], vec![])
    }

    fn reported(&self, own: Own, _: f64) -> Option<Reported> {
        Some(match own {
            Own::Lin(0) => Reported::new("drift, linear term (over the half-span)", 1.0, "°/s"),
            _ => Reported::new("drift, quadratic term", 1.0, "°/s"),
        })
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    fn value(&self, own: Own, p: &Point, _: usize, _: &AxisTerms, _: &Ctx) -> f64 {
        match own {
            Own::Lin(0) => p.t_scaled,
            _ => 0.5 * (3.0 * p.t_scaled * p.t_scaled - 1.0),
        }
    }

    /// None: an offset drift moves slowly against the table's turn: what it leaves in M is what the drift models and the free drift are tested for.
    fn consider(&self, _: Own, _: &ConsiderCtx) -> Option<ConsiderBound> {
        None
    }

    /// An offset drifts over seconds to minutes, not with the turn.
    fn turn_multiple(&self) -> u32 {
        0
    }

    fn candidate(&self, s: &Situation) -> bool {
        s.evidence.drift && !s.has_drift()
    }
}
