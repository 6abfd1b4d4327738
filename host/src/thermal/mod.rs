//! Calibration over temperature (issue 27): the gyro calibrated at several chamber setpoints,
//! and its offset, sensitivity and direction fitted as polynomials in die temperature.
//!
//! - [`settle`]: when the die has settled at a setpoint (OUT_TEMP's slope, MIL-STD-810H).
//! - [`poly`]: weighted polynomials with the temperature's σ, their order by held-out prediction.
//! - [`model`]: the thermal model from the setpoints' calibrations, queried only in its range.
//! - [`manifest`]: a thermal session's folders, each capture with its setpoint.
//! - [`present`]: the per-setpoint values beside the model, as text.
//! - [`warm_up`]: one session's own warm-up coefficients (the loop's temperature effects), shown
//!   with the span they hold over, and beside a thermal model's slopes.
//!
//! Direction is fitted as the two components of each unit axis `s_i` off its own package axis
//! (the third follows from |s_i| = 1): small, nearly linear in the axis's turn, and with σ from
//! the calibration's own covariance.

pub mod live;
pub mod manifest;
pub mod model;
pub mod plots;
pub mod poly;
pub mod present;
pub mod programme;
pub mod session;
pub mod settle;
pub mod truth_check;
pub mod warm_up;

#[cfg(test)]
mod tests;

pub use model::{Curve, ThermalModel};

use crate::calib::{CalReport, Estimate};
use nalgebra::{Matrix3, Vector3};
use protocol::FullScale;
use serde::{Deserialize, Serialize};

/// Key of the thermal model in `calibration.json`.
pub const CALIBRATION_KEY: &str = "thermal";

/// A quantity of one axis that the model follows over temperature.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// Offset (zero-rate level), counts.
    OffsetCounts,
    /// Sensitivity, counts per °/s.
    SensitivityCountsPerDps,
    /// The direction's component along the next package axis (x→y, y→z, z→x), unit vector.
    DirectionNext,
    /// The direction's component along the other package axis (x→z, y→x, z→y), unit vector.
    DirectionOther,
}

impl Quantity {
    /// The quantities of one axis, in curve order.
    pub const PER_AXIS: [Quantity; 4] =
        [Quantity::OffsetCounts, Quantity::SensitivityCountsPerDps, Quantity::DirectionNext, Quantity::DirectionOther];

    /// Every (axis, quantity) in curve order: axis-major.
    pub fn all() -> impl Iterator<Item = (usize, Quantity)> {
        (0..3).flat_map(|a| Self::PER_AXIS.into_iter().map(move |q| (a, q)))
    }

    /// Name with its unit.
    pub fn label(self) -> &'static str {
        match self {
            Quantity::OffsetCounts => "offset [counts]",
            Quantity::SensitivityCountsPerDps => "k [counts/(°/s)]",
            Quantity::DirectionNext => "s next component",
            Quantity::DirectionOther => "s other component",
        }
    }

    /// The package-axis component of `s_axis` a direction quantity is.
    fn component(self, axis: usize) -> usize {
        match self {
            Quantity::DirectionOther => (axis + 2) % 3,
            _ => (axis + 1) % 3,
        }
    }
}

/// What the thermal model could not do.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ThermalError {
    /// Too few setpoints: a held-out setpoint needs at least three.
    #[error("{found} setpoint(s): a thermal model needs at least 3 (one held out, two to fit a line)")]
    TooFewSetpoints { found: usize },
    /// Two setpoints at the same temperature, or setpoints at different full scales.
    #[error("{0}")]
    Inconsistent(String),
    /// A curve could not be fitted.
    #[error("{curve}: {reason}")]
    Fit { curve: String, reason: String },
    /// A query outside the calibrated range: never extrapolated.
    #[error("{temp_c:.2} °C is outside the calibrated range {:.2}…{:.2} °C: the thermal model is not extrapolated", range_c[0], range_c[1])]
    OutOfRange { temp_c: f64, range_c: [f64; 2] },
    /// M at this temperature cannot be inverted.
    #[error("the thermal model's M at {temp_c:.2} °C is singular")]
    Singular { temp_c: f64 },
}

/// One setpoint's calibration, as the model uses it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetpointCal {
    /// Chamber setpoint, °C.
    pub setpoint_c: f64,
    /// Mean OUT_TEMP over the setpoint's runs, LSB.
    pub out_temp_mean_lsb: f64,
    /// Full scale of its runs.
    pub full_scale: FullScale,
    /// Per axis: offset, sensitivity, direction components (in [`Quantity::PER_AXIS`] order).
    pub values: [[Estimate; 4]; 3],
    /// The part of each value's σ that is the same at every setpoint (same order): the
    /// calibration's consider terms, the catalogued effects its runs do not separate, which are
    /// the same rig at every setpoint ([`common_sigma`]).
    #[serde(default)]
    pub common_sigma: [[f64; 4]; 3],
    /// Whether the setpoint's own calibration reached the noise floor (its loop's verdict, exit
    /// 0 or 4); one that did not (exit 3) is left out of the fit ([`ThermalModel::fit`]).
    #[serde(default = "at_noise_floor_by_default")]
    pub at_noise_floor: bool,
}

/// A setpoint read without its verdict (a file written before the field existed) counts as at
/// the noise floor, as the fit took every setpoint then.
fn at_noise_floor_by_default() -> bool {
    true
}

impl SetpointCal {
    /// From a setpoint's calibration report and the OUT_TEMP readings of its runs; `None`
    /// without a reading.
    pub fn from_report(setpoint_c: f64, report: &CalReport, out_temp_raw: &[i8]) -> Option<Self> {
        if out_temp_raw.is_empty() {
            return None;
        }
        let mean = out_temp_raw.iter().map(|&r| f64::from(r)).sum::<f64>() / out_temp_raw.len() as f64;
        let values = [0, 1, 2].map(|i| {
            let a = &report.axes[i];
            Quantity::PER_AXIS.map(|q| match q {
                Quantity::OffsetCounts => a.offset_counts,
                Quantity::SensitivityCountsPerDps => a.k_counts_per_dps,
                _ => a.s[q.component(i)],
            })
        });
        let common_sigma = common_sigma(report, &values);
        Some(Self {
            setpoint_c,
            out_temp_mean_lsb: mean,
            full_scale: report.gyro.full_scale,
            values,
            common_sigma,
            at_noise_floor: true,
        })
    }

    /// The σ of one quantity of one axis common to every setpoint.
    pub fn common(&self, axis: usize, quantity: Quantity) -> f64 {
        let q = Quantity::PER_AXIS.iter().position(|&p| p == quantity).expect("every quantity is per axis");
        self.common_sigma[axis][q]
    }

    /// The same setpoint with its loop's verdict: `false` when the calibration left structure
    /// above the noise floor.
    pub fn with_noise_floor(self, at_noise_floor: bool) -> Self {
        Self { at_noise_floor, ..self }
    }

    /// One quantity of one axis.
    pub fn value(&self, axis: usize, quantity: Quantity) -> Estimate {
        let q = Quantity::PER_AXIS.iter().position(|&p| p == quantity).expect("every quantity is per axis");
        self.values[axis][q]
    }
}

/// The σ of each value that the report's consider terms give it (the terms add in quadrature,
/// `calib::analysis::consider`), which the setpoints share: the considered effect is the rig's, the same at
/// every setpoint, so the bias it leaves is common to them. The report states each term's σ of
/// the sensitivities (ppm of k) only; its direction σ is the axis's whole (both components
/// together) and the offsets' is not stated, so those stay counted as independent (their
/// curves' constant terms then carry less than the common part, their slopes more).
fn common_sigma(report: &CalReport, values: &[[Estimate; 4]; 3]) -> [[f64; 4]; 3] {
    let mut out = [[0.0; 4]; 3];
    for (axis, row) in out.iter_mut().enumerate() {
        let ppm = report.consider.iter().map(|t| t.k_sigma_ppm[axis].powi(2)).sum::<f64>().sqrt();
        let k = values[axis][1];
        row[1] = (k.value.abs() * ppm * 1e-6).min(k.sigma);
    }
    out
}

/// Fewest setpoints a model is fitted from: one held out and two for a line.
pub const MIN_SETPOINTS: usize = 3;

/// Checks the setpoints (sorted): enough, distinct, one full scale; returns the full scale.
fn check_setpoints(sp: &[&SetpointCal]) -> Result<FullScale, ThermalError> {
    if sp.len() < MIN_SETPOINTS {
        return Err(ThermalError::TooFewSetpoints { found: sp.len() });
    }
    for w in sp.windows(2) {
        if w[0].setpoint_c == w[1].setpoint_c {
            return Err(ThermalError::Inconsistent(format!("setpoint {} °C is given twice", w[0].setpoint_c)));
        }
        if w[0].full_scale != w[1].full_scale {
            return Err(ThermalError::Inconsistent(format!(
                "setpoints {} °C and {} °C were recorded at different full scales",
                w[0].setpoint_c, w[1].setpoint_c
            )));
        }
    }
    Ok(sp[0].full_scale)
}

/// M (rows k_i·s_i) and offsets from the 12 curve values in curve order.
pub fn m_and_offset(values: &[f64]) -> ([[f64; 3]; 3], [f64; 3]) {
    let mut m = [[0.0; 3]; 3];
    let mut offset = [0.0; 3];
    for (i, (row, off)) in m.iter_mut().zip(&mut offset).enumerate() {
        let v = &values[4 * i..4 * i + 4];
        let (next, other) = (Quantity::DirectionNext.component(i), Quantity::DirectionOther.component(i));
        let mut s = [0.0; 3];
        s[next] = v[2];
        s[other] = v[3];
        s[i] = (1.0 - v[2] * v[2] - v[3] * v[3]).max(0.0).sqrt();
        *row = s.map(|c| c * v[1]);
        *off = v[0];
    }
    (m, offset)
}

/// ω = M⁻¹ (raw − offset) from the 12 curve values, raw in counts (zeros if M is singular).
pub fn rate_from_values(values: &[f64], raw_counts: [f64; 3]) -> [f64; 3] {
    let (m, offset) = m_and_offset(values);
    let m = Matrix3::from_fn(|r, c| m[r][c]);
    let v = Vector3::from_fn(|i, _| raw_counts[i] - offset[i]);
    m.try_inverse().map_or([0.0; 3], |inv| (inv * v).into())
}
