//! One session's own temperature coefficients, from its warm-up: the closed loop fits the
//! offsets (`drift_temperature`) and the sensitivities (`scale_temperature`) linearly in the die
//! temperature when a session's OUT_TEMP spans enough and its residual calls for them. This
//! module shows them with the span they were estimated over (and hold over only), says in one
//! line when the span was too small and what span would be needed, and puts them beside a
//! thermal model's slopes at a setpoint's temperature.

use super::model::ThermalModel;
use super::Quantity;
use crate::calib::effects::terms::LinCol;
use crate::calib::{Effect, Estimate, LoopReport};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// Key of the warm-up coefficients in `calibration.json`.
pub const CALIBRATION_KEY: &str = "warm_up_temperature_coefficients";

/// Key, in a thermal session's `calibration.json`, of each setpoint's warm-up coefficients
/// beside the model's slopes there.
pub const BESIDE_MODEL_KEY: &str = "warm_up_beside_thermal_model";

/// The datasheet's typical zero-rate level change, °/s/°C (L3G4200D Table 4, "zero-rate level
/// change vs. temperature", ±0.03 typ.): the size the span needed is reckoned for.
pub const DATASHEET_OFFSET_DPS_PER_C: f64 = 0.03;

/// The datasheet's sensitivity change, ±2 % over −40…85 °C (L3G4200D Table 4): 160 ppm/°C on
/// average, the size the span needed is reckoned for.
pub const DATASHEET_SENSITIVITY_PPM_PER_C: f64 = 2e4 / 125.0;

/// A datasheet-sized coefficient counts as resolved at this many σ (a 3σ detection).
pub const RESOLVED_AT_SIGMA: f64 = 3.0;

/// Smallest spread of the smoothed die temperature at which the loop tries the offsets'
/// temperature drift, °C: `MIN_TEMPERATURE_SPREAD_C` of `calib/effects/drift_temperature.rs`
/// (private there), repeated here to say what a session would need.
pub const LOOP_MIN_SPREAD_OFFSET_C: f64 = 0.5;

/// Smallest spread at which the loop tries the sensitivities' temperature dependence, °C:
/// `MIN_TEMPERATURE_SPREAD_C` of `calib/effects/scale_temperature.rs` (private there).
pub const LOOP_MIN_SPREAD_SENSITIVITY_C: f64 = 1.0;

/// √12: a slope over a span S uniformly covered is known to σ_level·√12/S (the standard
/// deviation of a uniform spread is S/√12), the first-order reckoning of the span needed.
const SQRT_12: f64 = 3.464_101_615_137_754_6;

/// Die-temperature spans a session would need for each coefficient, °C: a datasheet-sized
/// coefficient resolved at [`RESOLVED_AT_SIGMA`] with this session's σ of the level, at least
/// the loop's own threshold.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SpanNeeded {
    /// For the offsets' coefficients, °C.
    pub offset_c: f64,
    /// For the sensitivities' coefficients, °C.
    pub sensitivity_c: f64,
}

/// One session's temperature coefficients from its own warm-up, as `calibration.json` holds
/// them (its [`CALIBRATION_KEY`] section).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WarmUp {
    /// Die-temperature span of the runs' OUT_TEMP readings, °C (1 LSB/°C, datasheet Table 5).
    pub die_span_c: f64,
    /// Lowest and highest OUT_TEMP reading, LSB (the register falls as the die warms).
    pub out_temp_range_lsb: [i8; 2],
    /// Mean OUT_TEMP of the runs, LSB: where the loop's temperature columns are zero, so the
    /// offsets and sensitivities of the calibration hold there.
    pub reference_out_temp_lsb: f64,
    /// Per axis (x, y, z) the offset's change with die temperature, °/s per °C of each sensing
    /// axis, with σ; `None` when the loop's model does not hold it.
    pub offset_dps_per_c: Option<[Estimate; 3]>,
    /// Per axis the sensitivity's relative change with die temperature, ppm per °C, with σ;
    /// `None` when the loop's model does not hold it.
    pub sensitivity_ppm_per_c: Option<[Estimate; 3]>,
    /// Spans that would resolve datasheet-sized coefficients with this session's σ.
    pub span_needed_c: SpanNeeded,
    /// The loop's model of the offsets' drift when it is not the one linear in temperature
    /// (which alone gives an offset coefficient per °C), with the drift models' BIC.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset_drift_instead: Option<String>,
    /// Where the coefficients hold, in words.
    pub validity: String,
}

impl WarmUp {
    /// From the loop's final model and the runs' OUT_TEMP readings; `None` without a reading.
    pub fn of(lr: &LoopReport, out_temp_raw: &[i8]) -> Option<Self> {
        let lo = *out_temp_raw.iter().min()?;
        let hi = *out_temp_raw.iter().max()?;
        let mean = out_temp_raw.iter().map(|&r| f64::from(r)).sum::<f64>() / out_temp_raw.len() as f64;
        let span = f64::from(hi) - f64::from(lo);
        let rep = lr.final_report();
        // The worst axis's σ of each level: the offset in °/s, the sensitivity in ppm.
        let worst = |f: &dyn Fn(usize) -> f64| (0..3).map(f).fold(0.0, f64::max);
        let k = |a: usize| rep.axes[a].k_counts_per_dps;
        let level_dps = worst(&|a| rep.axes[a].offset_counts.sigma / k(a).value);
        // The consider terms' part of k's σ is a bias common to the session, not noise a span
        // averages: only the rest sets how well a slope is known (the offsets' is not stated).
        let consider_ppm = |a: usize| rep.consider.iter().map(|t| t.k_sigma_ppm[a].powi(2)).sum::<f64>();
        let level_ppm = worst(&|a| ((1e6 * k(a).sigma / k(a).value).powi(2) - consider_ppm(a)).max(0.0).sqrt());
        let needed = |level: f64, size: f64, floor: f64| (RESOLVED_AT_SIGMA * SQRT_12 * level / size).max(floor);
        let span_needed_c = SpanNeeded {
            offset_c: needed(level_dps, DATASHEET_OFFSET_DPS_PER_C, LOOP_MIN_SPREAD_OFFSET_C),
            sensitivity_c: needed(level_ppm, DATASHEET_SENSITIVITY_PPM_PER_C, LOOP_MIN_SPREAD_SENSITIVITY_C),
        };
        Some(Self {
            die_span_c: span,
            out_temp_range_lsb: [lo, hi],
            reference_out_temp_lsb: mean,
            offset_dps_per_c: per_axis(lr, Effect::DriftTemperature),
            sensitivity_ppm_per_c: per_axis(lr, Effect::ScaleTemperature),
            span_needed_c,
            offset_drift_instead: other_drift(lr),
            validity: format!(
                "this session's own, from its warm-up; valid only over its die temperatures, OUT_TEMP {lo}…{hi} LSB (a span of {span:.0} °C), not extrapolated",
            ),
        })
    }

    /// Whether the loop fitted either coefficient.
    pub fn estimated(&self) -> bool {
        self.offset_dps_per_c.is_some() || self.sensitivity_ppm_per_c.is_some()
    }

    /// What the summary says: the coefficients with their span, or one line saying why there
    /// are none.
    pub fn text(&self) -> String {
        let [lo, hi] = self.out_temp_range_lsb;
        let need = self.span_needed_c;
        if !self.estimated() {
            return if self.die_span_c < need.offset_c.min(need.sensitivity_c) {
                format!(
                    "Warm-up temperature coefficients: not estimated, the die-temperature span was too small: {:.0} °C (OUT_TEMP {lo}…{hi} LSB) where about {:.1} °C would be needed for the offsets and {:.1} °C for the sensitivities ({}σ on the datasheet's typical {} °/s/°C and {:.0} ppm/°C with this session's σ).\n",
                    self.die_span_c, need.offset_c, need.sensitivity_c, RESOLVED_AT_SIGMA, DATASHEET_OFFSET_DPS_PER_C, DATASHEET_SENSITIVITY_PPM_PER_C
                )
            } else {
                format!(
                    "Warm-up temperature coefficients: not estimated: the die spanned {:.0} °C (OUT_TEMP {lo}…{hi} LSB), but the residual did not call for an offset or sensitivity following it.\n",
                    self.die_span_c
                )
            };
        }
        let mut o = format!("Warm-up temperature coefficients ({}):\n", self.validity);
        let rows = [
            ("offset", "°/s/°C", self.offset_dps_per_c, 5, need.offset_c),
            ("sensitivity", "ppm/°C", self.sensitivity_ppm_per_c, 1, need.sensitivity_c),
        ];
        for (what, unit, e, digits, needed) in rows {
            match e {
                Some(e) => {
                    let v: Vec<String> = ["x", "y", "z"]
                        .iter()
                        .zip(e)
                        .map(|(a, e)| format!("{a} {:+.digits$} ± {:.digits$}", e.value, e.sigma))
                        .collect();
                    let _ = writeln!(o, "  {what} [{unit}]: {}", v.join(", "));
                }
                None => {
                    let why = match (&self.offset_drift_instead, what) {
                        _ if self.die_span_c < needed => format!("a span of about {needed:.1} °C would be needed"),
                        (Some(drift), "offset") => format!("the loop modelled the offsets' drift as {drift}"),
                        _ => "the residual did not call for it".to_string(),
                    };
                    let _ = writeln!(o, "  {what}: not in the loop's model ({why})");
                }
            }
        }
        o
    }

    /// The report's section: the coefficients in a table, or the one line.
    pub fn html_section(&self) -> String {
        use crate::report::html::escape;
        let mut o = String::from("<section class=\"warm-up\">\n<h2>Temperature coefficients from the warm-up</h2>\n");
        let text = self.text();
        let mut lines = text.lines();
        let _ = writeln!(o, "<p>{}</p>", escape(lines.next().unwrap_or_default()));
        if self.estimated() {
            o.push_str("<table>\n<tr><th>axis</th><th>offset [°/s/°C]</th><th>sensitivity [ppm/°C]</th></tr>\n");
            let cell = |e: Option<[Estimate; 3]>, a: usize, digits: usize| {
                e.map_or("—".to_string(), |e| format!("{:+.digits$} ± {:.digits$}", e[a].value, e[a].sigma))
            };
            for (a, name) in ["x", "y", "z"].iter().enumerate() {
                let _ = writeln!(
                    o,
                    "<tr><td>{name}</td><td>{}</td><td>{}</td></tr>",
                    escape(&cell(self.offset_dps_per_c, a, 5)),
                    escape(&cell(self.sensitivity_ppm_per_c, a, 1))
                );
            }
            o.push_str("</table>\n");
            for l in lines.filter(|l| l.contains("not in the loop's model")) {
                let _ = writeln!(o, "<p>{}</p>", escape(l.trim()));
            }
        }
        o.push_str("</section>\n");
        o
    }
}

/// The loop's per-axis coefficients of a temperature effect, in its reported unit (°/s per °C
/// for the offsets, ppm per °C for the sensitivities), if its final model holds the effect.
fn per_axis(lr: &LoopReport, effect: Effect) -> Option<[Estimate; 3]> {
    let last = lr.steps.last()?;
    if !last.effects.contains(&effect) {
        return None;
    }
    let name = LinCol::Of(effect, 0).reported(f64::from(lr.final_report().gyro.full_scale.range_dps()))?.name;
    let find = |axis: &str| {
        let full = format!("{name}, {axis}");
        last.effect_params.iter().find(|p| p.name == full).map(|p| p.estimate)
    };
    Some([find("x")?, find("y")?, find("z")?])
}

/// The drift model of the loop's final model when it is not the offsets' drift linear in
/// temperature, named with its BIC and, when it was fitted, the temperature drift's.
fn other_drift(lr: &LoopReport) -> Option<String> {
    let last = lr.steps.last()?;
    let drift = last.effects.iter().copied().find(|e| e.is_drift() && *e != Effect::DriftTemperature)?;
    let choices = lr.steps.iter().flat_map(|s| &s.drift_choice);
    let bic = |e: Effect| choices.clone().filter(|c| c.effect == e).map(|c| c.bic).next_back();
    Some(match (bic(drift), bic(Effect::DriftTemperature)) {
        (Some(b), Some(t)) => {
            format!("{} (BIC {b:.1} against {t:.1} for the drift linear in temperature)", drift.name())
        }
        _ => drift.name(),
    })
}

/// One warm-up coefficient of one setpoint's session beside the thermal model's slope at that
/// setpoint's die temperature, in the warm-up's unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BesideModel {
    /// Chamber setpoint, °C.
    pub setpoint_c: f64,
    /// Its die temperature on the model's scale, °C.
    pub die_c: f64,
    /// Axis, 'x', 'y' or 'z'.
    pub axis: char,
    /// "offset [°/s/°C]" or "sensitivity [ppm/°C]".
    pub quantity: String,
    /// The session's own coefficient.
    pub warm_up: Estimate,
    /// The model's slope there (its σ from the curve's covariance).
    pub model_slope: Estimate,
    /// (warm-up − model) / √(σ² + σ²): the two are independent (one session's within-run
    /// change against the setpoints' levels).
    pub z: f64,
}

/// Each setpoint's warm-up coefficients (`(setpoint °C, its calibration.json)`) beside the
/// model's slopes at its die temperature: the offset's slope over the sensitivity (counts/°C to
/// °/s/°C) and the sensitivity's relative slope (ppm/°C). Setpoints without coefficients, or
/// outside the model's range (left out of the fit), give none.
pub fn beside_model(model: &ThermalModel, setpoints: &[(f64, serde_json::Value)]) -> Vec<BesideModel> {
    let mut out = Vec::new();
    for (setpoint_c, cal) in setpoints {
        let Some(w) = cal.get(CALIBRATION_KEY).and_then(|v| serde_json::from_value::<WarmUp>(v.clone()).ok()) else {
            continue;
        };
        let Some(s) = model.setpoints.iter().find(|s| s.setpoint_c == *setpoint_c) else { continue };
        for axis in 0..3 {
            let k = model.curve(axis, Quantity::SensitivityCountsPerDps).at(model.reference_c, s.die_c).value;
            let rows = [
                (Quantity::OffsetCounts, "offset [°/s/°C]", w.offset_dps_per_c, 1.0),
                (Quantity::SensitivityCountsPerDps, "sensitivity [ppm/°C]", w.sensitivity_ppm_per_c, 1e6),
            ];
            for (q, label, coef, scale) in rows {
                let Some(coef) = coef else { continue };
                let slope = model.curve(axis, q).slope_estimate_at(model.reference_c, s.die_c).scaled(scale / k);
                let own = coef[axis];
                out.push(BesideModel {
                    setpoint_c: *setpoint_c,
                    die_c: s.die_c,
                    axis: crate::calib::result::axes::AXES[axis],
                    quantity: label.to_string(),
                    warm_up: own,
                    model_slope: slope,
                    z: (own.value - slope.value) / own.sigma.hypot(slope.sigma),
                });
            }
        }
    }
    out
}

/// The comparison as text for the thermal summary (empty when no setpoint's loop fitted a
/// warm-up coefficient).
pub fn beside_model_text(rows: &[BesideModel]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut o = String::from(
        "Warm-up coefficients of a setpoint's own session beside the model's slope at its die temperature:\n",
    );
    for r in rows {
        let d = if r.quantity.starts_with("offset") { 5 } else { 1 };
        let _ = writeln!(
            o,
            "  {:>6} °C (die {:.1} °C) {} {:<22} warm-up {:+.d$} ± {:.d$}   model {:+.d$} ± {:.d$}   z {:+.2}",
            r.setpoint_c,
            r.die_c,
            r.axis,
            r.quantity,
            r.warm_up.value,
            r.warm_up.sigma,
            r.model_slope.value,
            r.model_slope.sigma,
            r.z
        );
    }
    o
}
