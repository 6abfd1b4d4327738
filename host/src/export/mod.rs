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
        let noise = serde_json::from_str::<serde_json::Value>(text)
            .ok()
            .and_then(|v| serde_json::from_value(v.get("noise")?.clone()).ok());
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
    /// reproduce the double-precision correction to the rounding of the result alone.
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

    /// The export in `format`.
    pub fn render(&self, format: Format) -> String {
        match format {
            Format::C => c::render(self),
            Format::Rust => rust::render(self),
            Format::Kalibr => kalibr::render(self),
            Format::Json => table::render_json(self),
            Format::Csv => table::render_csv(self),
        }
    }
}

/// One row of the correction split in two: `hi` holds at most 7 significant bits on a grid of
/// quantum `2^q` shared by the row, so that with raw counts (|v| ≤ 2¹⁵) every product
/// `hi_j · v_j` and every partial sum `Σ hi_j v_j − b_hi` is a multiple of the quantum below
/// 2²⁴ quanta: exact in `f32`, whatever the compiler's contraction or order. `lo` is the
/// remainder (≤ half a quantum, 2⁻⁸ of the largest coefficient), whose rounding errors are 2⁻⁸
/// smaller again. The sum of the two parts is then rounded once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplitRow {
    /// High parts of the row of `(K S)⁻¹`, °/s per count (exact in f32).
    pub m_hi: [f64; 3],
    /// Low parts, °/s per count.
    pub m_lo: [f64; 3],
    /// High part of `(K S)⁻¹ v_off`, °/s (exact in f32).
    pub b_hi: f64,
    /// Low part, °/s.
    pub b_lo: f64,
}

/// The three rows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplitRows {
    /// Row i gives axis i.
    pub rows: [SplitRow; 3],
}

/// Significant bits of the high parts: 7 bits × 15-bit counts = 22 bits per product, three of
/// them and the offset stay below f32's 24-bit significand.
const HI_BITS: i32 = 7;

fn split_row(m: [f64; 3], b: f64) -> SplitRow {
    let largest = m.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let e = largest.log2().ceil() as i32;
    let quantum = 2f64.powi(e - HI_BITS);
    let hi = |v: f64| (v / quantum).round() * quantum;
    let m_hi = m.map(hi);
    // b is bounded by the offsets (|v_off| ≪ 2¹⁵ counts), so b_hi stays well below 2²⁴ quanta.
    let b_hi = hi(b);
    SplitRow { m_hi, m_lo: std::array::from_fn(|j| m[j] - m_hi[j]), b_hi, b_lo: b - b_hi }
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
