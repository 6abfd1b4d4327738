//! Offsets settling exponentially after power-up.

use super::terms::{
    decay, AxisTerms, Bound, Col, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar,
    Shifts, Situation, Trial,
};
use super::{Behaviour, Effect, Layout};

/// Bounds of the warm-up time constant, s: 1 s is shorter than any board's thermal time constant,
/// 1e5 s (a day) is a constant offset over any capture.
pub const DRIFT_TAU_RANGE_S: (f64, f64) = (1.0, 1e5);

/// Candidate warm-up time constants, s, spaced by 2×: the exponential's shape changes slowly
/// with T, so the best of them starts Gauss-Newton inside its basin; 15 s to 16 min covers a
/// board's thermal time constants.
const WARM_UP_GRID_S: [f64; 7] = [15.0, 30.0, 60.0, 120.0, 240.0, 480.0, 960.0];

/// Offsets settling exponentially after power-up (warm-up): b + c·exp(−t/T), t from the
/// capture's first sample. Per axis c (a column, counts); shared T (s).
pub struct DriftWarmUp;

/// Its column.
const AMPLITUDE: LinCol = LinCol::Of(Effect::DriftWarmUp, 0);

impl Behaviour for DriftWarmUp {
    fn name(&self) -> String {
        "offset drift: exponential warm-up in time".into()
    }

    fn key(&self) -> String {
        "drift_warm_up".into()
    }

    fn meaning(&self) -> &'static str {
        "the zero-rate level follows the die as it warms up after power-up"
    }

    fn identified_by(&self) -> &'static str {
        "its slow change within and between runs; runs in both directions separate the offset from the constant θ2' term without relying on it"
    }

    fn kind(&self) -> Kind {
        Kind::Drift { offset_reference: "the warmed-up level (t → ∞ of the exponential)", free: false }
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![AMPLITUDE], vec![SharedPar { effect: Effect::DriftWarmUp, k: 0 }])
    }

    fn reported(&self, own: Own, _: f64) -> Option<Reported> {
        Some(match own {
            Own::Lin(_) => Reported::new("warm-up drift at the first sample", 1.0, "°/s"),
            Own::Shared(_) => Reported::new("warm-up time constant T", 1.0, "s"),
        })
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        Some(Bound { lo: DRIFT_TAU_RANGE_S.0, hi: DRIFT_TAU_RANGE_S.1, what: "warm-up time constant", unit: "s" })
    }

    fn shift(&self, _: u8, value: f64, s: &mut Shifts) {
        s.drift_tau_s = value;
    }

    fn value(&self, own: Own, p: &Point, a: usize, _: &AxisTerms, cx: &Ctx) -> f64 {
        let tau_s = cx.shifts.drift_tau_s;
        match own {
            Own::Lin(_) => decay(p.t_rel_s, tau_s),
            // ∂(c·exp(−t/T))/∂T.
            Own::Shared(_) => cx.beta(a, AMPLITUDE) * decay(p.t_rel_s, tau_s) * p.t_rel_s / (tau_s * tau_s),
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

    /// T enters non-linearly, so the warm-up is tried at each grid value with T held.
    fn trials(&self, _: &Layout) -> Vec<Trial> {
        WARM_UP_GRID_S
            .iter()
            .map(|&t| Trial { cols: vec![Col::Lin(LinCol::DriftExpFixed(t))], held_at: Some(t) })
            .collect()
    }
}
