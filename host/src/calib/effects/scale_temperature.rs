//! Sensitivities following the die temperature.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Needs, Own, Point, Reported, SharedPar, Shifts,
    Situation,
};
use super::{Behaviour, Effect, Layout};

/// Smallest spread of the smoothed die temperature over the capture for the effect to be a
/// candidate, °C: below it the column is the rate itself times a near constant, M's own column.
const MIN_TEMPERATURE_SPREAD_C: f64 = 1.0;

/// The L3G4200D's sensitivity change over its range: ±2 % from −40 to 85 °C (datasheet, Table
/// 4, "sensitivity change vs. temperature"), 160 ppm/°C on average, taken as one σ.
const DATASHEET_PPM_PER_C: f64 = 2e4 / 125.0;

/// Sensitivity following the die temperature (OUT_TEMP, smoothed), linearly: per axis a
/// coefficient of the rate along the axis times the temperature from the capture mean. A
/// session's warm-up spans 5-10 °C, so a typical 100 ppm/°C moves the sensitivity by 1000 ppm
/// from its first run to its last.
pub struct ScaleTemperature;

impl Behaviour for ScaleTemperature {
    fn name(&self) -> String {
        "sensitivity following the die temperature".into()
    }

    fn key(&self) -> String {
        "scale_temperature".into()
    }

    fn meaning(&self) -> &'static str {
        "the sense chain's gain follows the die temperature (L3G4200D: up to ±2 % over −40…85 °C)"
    }

    fn identified_by(&self) -> &'static str {
        "each axis's own rate scaled in proportion to the die temperature, within and between runs; a warm-up of several °C separates it from M"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![LinCol::Of(Effect::ScaleTemperature, 0)], vec![])
    }

    fn reported(&self, _: Own, _: f64) -> Option<Reported> {
        Some(Reported::new("sensitivity vs temperature", 1e6, "ppm per °C"))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    fn value(&self, _: Own, p: &Point, a: usize, _: &AxisTerms, cx: &Ctx) -> f64 {
        cx.axis_rate(p, a) * p.temp_c
    }

    /// The datasheet's average change as one σ: what the runs do not see of it biases M. None
    /// when the die read one temperature throughout: its column is then zero at every sample,
    /// and gathering it cost a tenth of a 1-h replay (the smoothed temperature per sample).
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.has(Effect::ScaleTemperature) && cx.temp_moved).then_some(ConsiderBound {
            sigma: DATASHEET_PPM_PER_C,
            source: "sensitivity change vs temperature ±2 % over −40…85 °C (L3G4200D datasheet Table 4)",
        })
    }

    /// When some run shows structure at 1× (each run's amplitude is off M's by its own
    /// temperature) or drifts, and the die's temperature moved.
    fn candidate(&self, s: &Situation) -> bool {
        let seen = s.evidence.orders[1] || s.evidence.drift;
        seen && !s.has(Effect::ScaleTemperature) && (s.temp_spread_c)() >= MIN_TEMPERATURE_SPREAD_C
    }

    fn needs(&self, _: Own) -> Needs {
        Needs { temperature: true, ..Needs::NONE }
    }

    /// Per axis (the column follows the axis's own rate). Its slope in that rate is ΔT, which
    /// this hook cannot see: 0 leaves α·ΔT (1e-3 at 160 ppm/°C over 6 °C) out of the chain-rule
    /// factor of the shared parameters' Jacobians, which sets only how fast a fit converges.
    fn rate_slope(&self, _: u16, _: f64) -> Option<f64> {
        Some(0.0)
    }
}
