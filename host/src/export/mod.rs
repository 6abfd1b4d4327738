//! Exports a calibration into forms a user's firmware or toolchain embeds: a C99 header, a Rust
//! `const`, Kalibr's IMU YAML, flat JSON and CSV. Every export holds the same correction,
//! `ω = (K S)⁻¹ (v − v_off)` (the correction of `calib::apply`), and the sensor's identity where known.

mod c;
mod kalibr;
mod rust;
mod table;

use crate::calib::{CalReport, Calibration};
use crate::provenance::Provenance;
use anyhow::{Context, Result};
use nalgebra::{Matrix3, Vector3};
use protocol::GyroConfig;

/// The key of the fitted g-sensitivity in `calibration.json` (written by `host calibrate`).
pub const G_SENSITIVITY_KEY: &str = "g_sensitivity_dps_per_g";

/// Output format of `host export`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// C99 header with `gyrocal_apply`.
    C,
    /// Rust source with a `const` item (no_std).
    Rust,
    /// Kalibr IMU YAML.
    Kalibr,
    /// Flat JSON.
    Json,
    /// CSV, one parameter per line.
    Csv,
}

/// A calibration and what is known about it, ready to export.
#[derive(Debug, Clone)]
pub struct Export {
    /// The correction.
    pub calibration: Calibration,
    /// (K S)⁻¹, °/s per count; row i gives axis i of the rate.
    pub m_inv_dps_per_count: [[f64; 3]; 3],
    /// Gyro settings the calibration holds for (from the report, else from the provenance).
    pub gyro: Option<GyroConfig>,
    /// 1-σ of M (counts per °/s) and of the offsets (counts), when the file is a full report.
    pub sigma: Option<Sigmas>,
    /// Sensor, date, captures, when the file carries them.
    pub provenance: Option<Provenance>,
    /// Noise figures, when the calibration had a static stretch.
    pub noise: Option<crate::allan::NoiseReport>,
    /// The fitted g-sensitivity, when the calibration's model holds it: row i is gyro axis i's
    /// bias per g of specific force along package x, y, z, °/s per g (`calibration.json`'s
    /// `g_sensitivity_dps_per_g`).
    pub g_sensitivity_dps_per_g: Option<[[f64; 3]; 3]>,
}

/// 1-σ uncertainties from the report's covariance diagonal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sigmas {
    /// σ of each element of M, counts per °/s.
    pub m_counts_per_dps: [[f64; 3]; 3],
    /// σ of each offset, counts.
    pub offset_counts: [f64; 3],
}

impl Export {
    /// Reads `calibrate`'s JSON (full report, with or without provenance) or a bare calibration.
    pub fn from_json(text: &str) -> Result<Self> {
        let provenance = Provenance::from_calibration_json(text);
        let value = serde_json::from_str::<serde_json::Value>(text).ok();
        let field = |key: &str| value.as_ref().and_then(|v| v.get(key)).cloned();
        let noise = field("noise").and_then(|n| serde_json::from_value(n).ok());
        let g_sensitivity_dps_per_g = match field(G_SENSITIVITY_KEY) {
            None => None,
            Some(g) => {
                Some(serde_json::from_value(g).with_context(|| format!("{G_SENSITIVITY_KEY} is not 3×3 numbers"))?)
            }
        };
        let (calibration, gyro, sigma) = match serde_json::from_str::<CalReport>(text) {
            Ok(report) => {
                // cov is in param_names order: m_x (3), b_x, m_y (3), b_y, m_z (3), b_z.
                let sd =
                    |p: usize| report.cov.get(p).and_then(|row| row.get(p)).map_or(f64::NAN, |v| v.max(0.0).sqrt());
                let sigma = Sigmas {
                    m_counts_per_dps: std::array::from_fn(|i| std::array::from_fn(|j| sd(4 * i + j))),
                    offset_counts: std::array::from_fn(|i| sd(4 * i + 3)),
                };
                (report.calibration(), Some(report.gyro), Some(sigma))
            }
            Err(report_err) => {
                let looks_like_report =
                    serde_json::from_str::<serde_json::Value>(text).is_ok_and(|v| v.get("axes").is_some());
                if looks_like_report {
                    return Err(report_err).context("a calibration report that does not read back");
                }
                let cal = Calibration::from_json(text).context("neither a calibration report nor a calibration")?;
                (cal, provenance.as_ref().and_then(|p| p.gyro), None)
            }
        };
        let m = Matrix3::from_fn(|i, j| calibration.m_counts_per_dps[i][j]);
        let inv = m.try_inverse().context("M is singular")?;
        Ok(Self {
            m_inv_dps_per_count: std::array::from_fn(|i| std::array::from_fn(|j| inv[(i, j)])),
            calibration,
            gyro,
            sigma,
            provenance,
            noise,
            g_sensitivity_dps_per_g,
        })
    }

    /// (K S)⁻¹ v_off, °/s: the offset expressed as a rate. The exports apply
    /// `ω = (K S)⁻¹ v − (K S)⁻¹ v_off`: in single precision this saves the rounding of
    /// `v − v_off` (a fractional offset from a count near full scale rounds to 2⁻⁸ counts).
    pub fn offset_rate_dps(&self) -> [f64; 3] {
        let inv = Matrix3::from_fn(|i, j| self.m_inv_dps_per_count[i][j]);
        (inv * Vector3::from(self.calibration.offset_counts)).into()
    }

    /// The split of each row of `(K S)⁻¹` and of `(K S)⁻¹ v_off` that lets single precision
    /// reproduce the double-precision correction ([`SplitRow`]).
    pub fn split(&self) -> SplitRows {
        let b = self.offset_rate_dps();
        let rows = std::array::from_fn(|i| split_row(self.m_inv_dps_per_count[i], b[i]));
        SplitRows { rows }
    }

    /// Sensor serial, or `unknown`.
    pub fn serial(&self) -> &str {
        self.provenance.as_ref().and_then(|p| p.identity.sensor_serial.as_deref()).unwrap_or("unknown")
    }

    /// Calibration date-time (UTC), or `unknown`.
    pub fn date(&self) -> &str {
        self.provenance.as_ref().map_or("unknown", |p| p.calibrated_utc.as_str())
    }

    /// The export in `format`. The single-precision exports (C, Rust) refuse offsets beyond
    /// [`MAX_OFFSET_COUNTS`], where their exactness argument ends.
    pub fn render(&self, format: Format) -> Result<String> {
        if matches!(format, Format::C | Format::Rust) {
            for (axis, v) in ['x', 'y', 'z'].iter().zip(self.calibration.offset_counts) {
                if v.abs() >= MAX_OFFSET_COUNTS {
                    anyhow::bail!(
                        "offset {axis} is {v} counts, beyond the ±{MAX_OFFSET_COUNTS} counts the single-precision \
                         exports carry exactly (a zero-rate level that large is a broken sensor)"
                    );
                }
            }
        }
        Ok(match format {
            Format::C => c::render(self),
            Format::Rust => rust::render(self),
            Format::Kalibr => kalibr::render(self),
            Format::Json => table::render_json(self),
            Format::Csv => table::render_csv(self),
        })
    }
}

/// One row of the correction split in three, for the single-precision exports (C, Rust).
///
/// Why: a Cortex-M4F has a single-precision FPU only (`double` is emulated in software), and a
/// `float` result cannot hold a rate to 1e-5 °/s above 256 °/s (half its ulp is 1.5e-5 °/s
/// there, 6.1e-5 °/s at 2000 °/s), so the exports give the rate as an unevaluated sum of two
/// floats, `hi + lo`, computed with float operations only, plus the float nearest to that sum.
///
/// How: with `2^e` ≥ the row's largest coefficient, `hi` lies on the grid `2^(e−7)` (|hi| ≤ 128
/// steps) and `mid` on `2^(e−14)` (|mid| ≤ 64 steps), `lo` is the f32 remainder (|lo| ≤ 2^(e−15)).
/// With raw counts |v| ≤ 2¹⁵ every product `hi_j v_j` is at most 2²² steps and every partial sum
/// of `Σ hi_j v_j − b_hi` stays below 2²⁴ steps while |v_off| < [`MAX_OFFSET_COUNTS`]: exact in
/// f32, whatever the order or an FMA contraction; the same for `mid`. Only the `lo` sum rounds:
/// its terms are ≤ 2^e, so its error is ≤ 15·2^(e−24) (four roundings of γ₄ on ≤ 3·2^e, and the
/// f32 rounding of each `lo`). The two exact sums are added by TwoSum (Knuth; exact) and the `lo`
/// sum joins the low word (one more rounding, ≤ 2⁻²⁴ of it). So `hi + lo` is within
/// [`SplitRow::bound_dps`] = 2^(e−19) of `(K S)⁻¹ v − (K S)⁻¹ v_off`: 2.4e-7 °/s for an L3G4200D
/// at ±2000 °/s (70 m°/s per count, e = −3), over the whole int16 range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplitRow {
    /// High parts of the row of `(K S)⁻¹`, °/s per count (exact in f32).
    pub m_hi: [f64; 3],
    /// Middle parts, °/s per count (exact in f32).
    pub m_mid: [f64; 3],
    /// Low parts, °/s per count.
    pub m_lo: [f64; 3],
    /// `(K S)⁻¹ v_off` on the same grids, °/s: high part (exact in f32)…
    pub b_hi: f64,
    /// …middle part (exact in f32)…
    pub b_mid: f64,
    /// …and the remainder.
    pub b_lo: f64,
    /// The row's exponent `e`: 2^e ≥ its largest coefficient.
    pub exponent: i32,
}

impl SplitRow {
    /// The proven bound on `|hi + lo − exact|`, °/s (see [`SplitRow`]).
    pub fn bound_dps(&self) -> f64 {
        2f64.powi(self.exponent - 19)
    }
}

/// The three rows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplitRows {
    /// Row i gives axis i.
    pub rows: [SplitRow; 3],
}

/// Steps of each of the high and middle grids below the one above: 7 bits × 15-bit counts = 22
/// bits per product; three of them and the offset stay below f32's 24-bit significand.
const SPLIT_BITS: i32 = 7;

/// The largest offset, counts, for which the split's high sums stay exact (3·2²² + 3·128·2¹³
/// < 2²⁴ steps). The L3G4200D's zero-rate level is ±75 °/s at most (datasheet, ±2000 °/s),
/// ≈ 1070 counts; an offset near this limit is a broken sensor, not a calibration.
pub const MAX_OFFSET_COUNTS: f64 = 8192.0;

fn split_row(m: [f64; 3], b: f64) -> SplitRow {
    let largest = m.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let exponent = largest.log2().ceil() as i32;
    let on_grid = |v: f64, bits: i32| {
        let step = 2f64.powi(exponent - bits);
        (v / step).round() * step
    };
    let m_hi = m.map(|v| on_grid(v, SPLIT_BITS));
    let m_mid: [f64; 3] = std::array::from_fn(|j| on_grid(m[j] - m_hi[j], 2 * SPLIT_BITS));
    let b_hi = on_grid(b, SPLIT_BITS);
    let b_mid = on_grid(b - b_hi, 2 * SPLIT_BITS);
    SplitRow {
        m_hi,
        m_mid,
        m_lo: std::array::from_fn(|j| m[j] - m_hi[j] - m_mid[j]),
        b_hi,
        b_mid,
        b_lo: b - b_hi - b_mid,
        exponent,
    }
}

/// An `f32` literal that reads back as exactly the `f32` nearest to `v` (Rust's shortest
/// round-trip form, with an exponent, valid in both C and Rust).
pub(crate) fn f32_literal(v: f64) -> String {
    format!("{:e}", v as f32)
}

/// A string safe inside a C or Rust string literal and a comment: printable ASCII without `"`,
/// `\` or `*/`; anything else becomes `?`.
pub(crate) fn sanitise(s: &str) -> String {
    let out: String =
        s.chars().map(|c| if c.is_ascii_graphic() && c != '"' && c != '\\' || c == ' ' { c } else { '?' }).collect();
    out.replace("*/", "*?")
}

#[cfg(test)]
mod tests;
