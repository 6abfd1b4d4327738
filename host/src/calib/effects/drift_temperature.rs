//! Offsets following the die temperature.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Needs, Own, Point, Reported, SharedPar, Shifts,
    Situation,
};
use super::{Behaviour, Effect, Layout};

/// Smallest spread of the smoothed temperature over the capture for the temperature drift to be a
/// candidate, °C: below it the column is a constant and only duplicates the offset.
const MIN_TEMPERATURE_SPREAD_C: f64 = 0.5;

/// Offsets following the die temperature (OUT_TEMP, smoothed), linearly: per axis a coefficient
/// of the temperature from the capture mean.
pub struct DriftTemperature;

impl Behaviour for DriftTemperature {
    fn name(&self) -> String {
        "offset drift: linear in temperature".into()
    }

    fn key(&self) -> String {
        "drift_temperature".into()
    }

    fn meaning(&self) -> &'static str {
        "the zero-rate level follows the die temperature"
    }

    fn identified_by(&self) -> &'static str {
        "its slow change within and between runs; runs in both directions separate the offset from the constant θ2' term without relying on it"
    }

    fn kind(&self) -> Kind {
        Kind::Drift { offset_reference: "the capture's mean die temperature", free: false }
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![LinCol::Of(Effect::DriftTemperature, 0)], vec![])
    }

    fn reported(&self, _: Own, _: f64) -> Option<Reported> {
        Some(Reported::new("offset vs temperature", 1.0, "°/s per °C"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    fn value(&self, _: Own, p: &Point, _: usize, _: &AxisTerms, _: &Ctx) -> f64 {
        p.temp_c
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
        s.evidence.drift && !s.has_drift() && (s.temp_spread_c)() >= MIN_TEMPERATURE_SPREAD_C
    }

    fn needs(&self, _: Own) -> Needs {
        Needs { temperature: true, ..Needs::NONE }
    }
}
