//! Exports a calibration into forms a user's firmware or toolchain embeds: a C99 header, a Rust
//! `const`, Kalibr's IMU YAML, flat JSON and CSV. Every export holds the same correction,
//! `ω = (K S)⁻¹ (v − v_off)` (the correction of `calib::result::apply`), and the sensor's identity where known.

mod c;
mod kalibr;
mod rust;
mod table;
mod temperature;

pub use temperature::{ThermalRow, ThermalTable};

use crate::calib::{CalReport, Calibration};
use crate::provenance::Provenance;
use anyhow::{Context, Result};
use nalgebra::{Matrix3, Vector3};
use protocol::GyroConfig;

/// The key of the fitted g-sensitivity in `calibration.json` (written by `host calibrate`).
pub const G_SENSITIVITY_KEY: &str = "g_sensitivity_dps_per_g";

/// The key of the offset drift model in `calibration.json` (written by `host calibrate`).
pub const DRIFT_MODEL_KEY: &str = "drift_model";

/// OUT_TEMP's slope, LSB per °C: it falls one count per °C (L3G4200D datasheet, Table 5; the
/// calibration's own temperature column uses the same, `calib::engine::loop_data`).
pub const OUT_TEMP_LSB_PER_C: f64 = -1.0;

/// The offset drift of the final model, in the form a firmware can evaluate.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DriftModel {
    /// Warm-up after power-up: the offsets are `v_off + c exp(−t/T)`, t from the session's first
    /// sample (taken as power-up), `v_off` the warmed-up level.
    WarmUp {
        /// c per axis, counts.
        amplitude_counts: [f64; 3],
        /// T, s.
        tau_s: f64,
    },
    /// The offsets follow the die temperature: `v_off + β ΔT`, ΔT the die temperature from the
    /// session's mean, °C.
    Temperature {
        /// β per axis, counts per °C.
        counts_per_c: [f64; 3],
        /// The session's mean OUT_TEMP reading, LSB: where ΔT = 0.
        reference_out_temp_lsb: f64,
    },
    /// A drift that describes the session's own time span only (a polynomial over the capture, or
    /// the free drift between knots): no firmware can evaluate it at another time.
    SessionOnly {
        /// The model's name.
        model: String,
        /// What the exported offsets are, then.
        offsets_are: String,
    },
}

impl DriftModel {
    /// The drift of the loop's final model (`None` without one). The loop reports drift terms
    /// in °/s of each sensing axis (its coefficient over |row of M|, `calib::analysis::closure`), so
    /// counts are that times |row of M|. `out_temp_mean_lsb` is the runs' mean OUT_TEMP.
    pub fn of(lr: &crate::calib::LoopReport, out_temp_mean_lsb: Option<f64>) -> Option<Self> {
        use crate::calib::Effect;
        let last = lr.steps.last()?;
        let drift = last
            .effects
            .iter()
            .copied()
            .find(|e| e.is_free_drift())
            .or_else(|| last.effects.iter().copied().find(|e| e.is_drift()))?;
        let m = lr.final_report().m_counts_per_dps;
        let k: [f64; 3] = std::array::from_fn(|a| Vector3::from(m[a]).norm());
        let param = |name: &str| last.effect_params.iter().find(|p| p.name == name).map(|p| p.estimate.value);
        let per_axis = |name: &str| -> Option<[f64; 3]> {
            let v = [param(&format!("{name}, x"))?, param(&format!("{name}, y"))?, param(&format!("{name}, z"))?];
            Some(std::array::from_fn(|a| v[a] * k[a]))
        };
        let portable = match drift {
            Effect::DriftWarmUp => per_axis("warm-up drift at the first sample")
                .zip(param("warm-up time constant T"))
                .map(|(amplitude_counts, tau_s)| DriftModel::WarmUp { amplitude_counts, tau_s }),
            Effect::DriftTemperature => per_axis("offset vs temperature").zip(out_temp_mean_lsb).map(
                |(counts_per_c, reference_out_temp_lsb)| DriftModel::Temperature {
                    counts_per_c,
                    reference_out_temp_lsb,
                },
            ),
            _ => None,
        };
        Some(portable.unwrap_or_else(|| DriftModel::SessionOnly {
            model: drift.name(),
            offsets_are: drift.offset_reference().unwrap_or("the session's mean").to_string(),
        }))
    }
}

/// What the drift and the g-sensitivity add to the offsets, in the package frame's rate: the
/// single-precision exports subtract these from `(K S)⁻¹ v − (K S)⁻¹ v_off`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateTerms {
    /// `(K S)⁻¹ c` of the warm-up, °/s at t = 0 (zero without a warm-up model).
    pub warm_up_dps: [f64; 3],
    /// The warm-up's T, s (1 without a warm-up model, where it multiplies zero).
    pub warm_up_tau_s: f64,
    /// `(K S)⁻¹ β` of the temperature drift, °/s per °C (zero without one).
    pub temperature_dps_per_c: [f64; 3],
    /// The OUT_TEMP reading where the temperature drift is zero, LSB.
    pub reference_out_temp_lsb: f64,
    /// `(K S)⁻¹ diag(|row of M|) G`, °/s per g of specific force along package x, y, z (zero
    /// without a fitted g-sensitivity).
    pub g_dps_per_g: [[f64; 3]; 3],
}

/// The inputs besides the raw reading that the drift and the g-sensitivity need.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inputs {
    /// Seconds since power-up (the warm-up's t).
    pub t_s: f64,
    /// The die temperature as OUT_TEMP, LSB (averaged as the firmware likes).
    pub out_temp_lsb: f64,
    /// Specific force along package x, y, z, g, as an accelerometer reads it (+1 g up at rest);
    /// `None`: no accelerometer, the g-sensitivity is not applied.
    pub specific_force_g: Option<[f64; 3]>,
}

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
    /// The offset drift, when the calibration's model holds one (`calibration.json`'s
    /// `drift_model`).
    pub drift: Option<DriftModel>,
    /// The thermal model, when the calibration is a thermal session's (`calibration.json`'s
    /// `thermal`): the C and Rust exports then take the OUT_TEMP reading as an input.
    pub thermal: Option<crate::thermal::ThermalModel>,
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
        let drift = match field(DRIFT_MODEL_KEY) {
            None => None,
            Some(d) => {
                Some(serde_json::from_value(d).with_context(|| format!("{DRIFT_MODEL_KEY} does not read back"))?)
            }
        };
        let thermal = match field(crate::thermal::CALIBRATION_KEY) {
            None => None,
            Some(t) => Some(serde_json::from_value(t).context("its thermal section is not a thermal model")?),
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
            drift,
            thermal,
        })
    }

    /// The drift and g-sensitivity terms in the package frame's rate ([`RateTerms`]).
    pub fn rate_terms(&self) -> RateTerms {
        let inv = Matrix3::from_fn(|i, j| self.m_inv_dps_per_count[i][j]);
        let rate = |counts: [f64; 3]| -> [f64; 3] { (inv * Vector3::from(counts)).into() };
        let mut t = RateTerms {
            warm_up_dps: [0.0; 3],
            warm_up_tau_s: 1.0,
            temperature_dps_per_c: [0.0; 3],
            reference_out_temp_lsb: 0.0,
            g_dps_per_g: [[0.0; 3]; 3],
        };
        match &self.drift {
            Some(DriftModel::WarmUp { amplitude_counts, tau_s }) => {
                t.warm_up_dps = rate(*amplitude_counts);
                t.warm_up_tau_s = *tau_s;
            }
            Some(DriftModel::Temperature { counts_per_c, reference_out_temp_lsb }) => {
                t.temperature_dps_per_c = rate(*counts_per_c);
                t.reference_out_temp_lsb = *reference_out_temp_lsb;
            }
            Some(DriftModel::SessionOnly { .. }) | None => {}
        }
        if let Some(g) = self.g_sensitivity_dps_per_g {
            let m = &self.calibration.m_counts_per_dps;
            let k = Matrix3::from_diagonal(&Vector3::from_fn(|a, _| Vector3::from(m[a]).norm()));
            let gp = inv * k * Matrix3::from_fn(|i, j| g[i][j]);
            t.g_dps_per_g = std::array::from_fn(|i| std::array::from_fn(|j| gp[(i, j)]));
        }
        t
    }

    /// The rate with the drift and the g-sensitivity applied, °/s, in double precision: the
    /// reference the exports' `apply_with` is held to. `v = K S ω + v_off + d + diag(k) G f`,
    /// so `ω = (K S)⁻¹ (v − v_off) − (K S)⁻¹ d − (K S)⁻¹ diag(k) G f`.
    pub fn apply_with(&self, raw: [i16; 3], inputs: &Inputs) -> [f64; 3] {
        let base = self.calibration.apply(raw);
        let terms = self.terms_dps(inputs, true);
        std::array::from_fn(|i| base[i] - terms[i])
    }

    /// [`Self::apply_with`] for a thermal calibration at an OUT_TEMP reading: the thermal model's
    /// rate there ([`ThermalTable::apply`], `host apply --temp-c`) less the warm-up and the
    /// g-sensitivity terms of the base calibration ([`RateTerms`]); the session's linear
    /// temperature drift is not applied, the model's offset curves being the temperature
    /// dependence. The reference of the thermal exports' `gyrocal_apply_with`.
    pub fn apply_thermal_with(
        &self,
        table: &ThermalTable,
        raw: [i16; 3],
        out_temp_lsb: i8,
        inputs: &Inputs,
    ) -> Result<[f64; 3], crate::thermal::ThermalError> {
        let base = table.apply(raw, out_temp_lsb)?;
        let terms = self.terms_dps(inputs, false);
        Ok(std::array::from_fn(|i| base[i] - terms[i]))
    }

    /// What the drift (its temperature part only with `temperature_drift`) and the
    /// g-sensitivity add to the rate, °/s.
    fn terms_dps(&self, inputs: &Inputs, temperature_drift: bool) -> [f64; 3] {
        let t = self.rate_terms();
        let decay = (-inputs.t_s / t.warm_up_tau_s).exp();
        let dtemp_c =
            if temperature_drift { (inputs.out_temp_lsb - t.reference_out_temp_lsb) / OUT_TEMP_LSB_PER_C } else { 0.0 };
        let f = inputs.specific_force_g.unwrap_or([0.0; 3]);
        std::array::from_fn(|i| {
            let g: f64 = (0..3).map(|j| t.g_dps_per_g[i][j] * f[j]).sum();
            t.warm_up_dps[i] * decay + t.temperature_dps_per_c[i] * dtemp_c + g
        })
    }

    /// The thermal model tabulated for the C and Rust exports, when the calibration has one.
    pub fn thermal_table(&self) -> Result<Option<ThermalTable>> {
        self.thermal.clone().map(|m| ThermalTable::of(m, MAX_OFFSET_COUNTS)).transpose()
    }

    /// What the C and Rust exports leave out, one line each (ASCII), for their header.
    pub fn left_out(&self) -> Vec<String> {
        let mut out = Vec::new();
        let thermal = self.thermal.is_some();
        match &self.drift {
            None => out.push("offset drift: none in this calibration's model (the drift terms are zero)".into()),
            Some(DriftModel::SessionOnly { model, offsets_are }) => out.push(format!(
                "offset drift: '{model}' describes the calibration session's own time span only and is not \
                 exported (the drift terms are zero); the offsets are those at {offsets_are}"
            )),
            Some(DriftModel::WarmUp { .. }) if thermal => {}
            Some(DriftModel::WarmUp { .. }) => {
                out.push("offset drift with die temperature (this calibration's drift model is the warm-up)".into())
            }
            Some(DriftModel::Temperature { .. }) if thermal => out.push(
                "the base session's linear offset drift with die temperature: the thermal model's offset curves \
                 replace it"
                    .into(),
            ),
            Some(DriftModel::Temperature { .. }) => {
                out.push("offset warm-up in time (this calibration's drift model is the die temperature)".into())
            }
        }
        if self.g_sensitivity_dps_per_g.is_none() {
            out.push("g-sensitivity: not in this calibration's model (its terms are zero)".into());
        }
        if thermal {
            out.push(
                "the change with temperature of the warm-up and g-sensitivity terms: they are the base session's \
                 (the setpoint nearest 25 °C)"
                    .into(),
            );
            out.push("non-linearity: not modelled".into());
        } else {
            out.push("sensitivity and direction changing with temperature, non-linearity: not modelled".into());
        }
        out.push("uncertainties: 1-sigma in calibration.json, k = 2 on report.html's certificate".into());
        out.push("noise figures (ARW, bias instability, RRW): calibration.json and report.html".into());
        out.into_iter().map(|l| sanitise(&l)).collect()
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
        split_rows(self.m_inv_dps_per_count, self.calibration.offset_counts)
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
            Format::C => match self.thermal_table()? {
                None => c::render(self),
                Some(table) => c::render_thermal(self, &table),
            },
            Format::Rust => match self.thermal_table()? {
                None => rust::render(self),
                Some(table) => rust::render_thermal(self, &table),
            },
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

/// The split of `(K S)⁻¹` and of `(K S)⁻¹ v_off` for single precision ([`SplitRow`]).
pub fn split_rows(m_inv_dps_per_count: [[f64; 3]; 3], offset_counts: [f64; 3]) -> SplitRows {
    let inv = Matrix3::from_fn(|i, j| m_inv_dps_per_count[i][j]);
    let b: [f64; 3] = (inv * Vector3::from(offset_counts)).into();
    SplitRows { rows: std::array::from_fn(|i| split_row(m_inv_dps_per_count[i], b[i])) }
}

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

/// ASCII spellings of the symbols the provenance and the model name use ("±500 °/s" becomes
/// "+-500 deg/s"), so that the C header says them rather than `?`.
const ASCII_SPELLINGS: [(char, &str); 16] = [
    ('°', "deg"),
    ('±', "+-"),
    ('ω', "omega"),
    ('θ', "theta"),
    ('τ', "tau"),
    ('σ', "sigma"),
    ('µ', "u"),
    ('μ', "u"),
    ('√', "sqrt"),
    ('×', "x"),
    ('·', "*"),
    ('−', "-"),
    ('–', "-"),
    ('—', "-"),
    ('…', "..."),
    ('⁻', "^-"),
];

/// The comment that opens a generated file: sensor, date, generator, model, `lines`, provenance
/// and what the export leaves out, each line begun with `first` (the first) or `rest`, ASCII.
pub(crate) fn header_comment(e: &Export, format: &str, lines: &[String], (first, rest): (&str, &str)) -> String {
    use std::fmt::Write as _;
    let mut o = String::new();
    let (serial, date) = (sanitise(e.serial()), sanitise(e.date()));
    let _ = writeln!(o, "{first}Gyro calibration of sensor {serial}, computed {date}.");
    let _ = writeln!(
        o,
        "{rest}Generated by `host export --format {format}` (host {}); do not edit.",
        crate::provenance::HOST_VERSION
    );
    let _ = writeln!(o, "{rest}Model: {}", sanitise(&e.calibration.model));
    for line in lines {
        let _ = writeln!(o, "{rest}{line}");
    }
    if let Some(p) = &e.provenance {
        for line in p.to_string().lines() {
            let _ = writeln!(o, "{rest}{}", sanitise(line));
        }
    }
    let _ = writeln!(o, "{rest}Left out:");
    for line in e.left_out() {
        let _ = writeln!(o, "{rest}  - {line}");
    }
    o
}

/// A string safe inside a C or Rust string literal and a comment: printable ASCII without `"`,
/// `\` or `*/`. The symbols of [`ASCII_SPELLINGS`] are spelled out (superscript digits as `^n`);
/// anything else becomes `?`.
pub(crate) fn sanitise(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if let Some((_, ascii)) = ASCII_SPELLINGS.iter().find(|(u, _)| *u == c) {
            out.push_str(ascii);
        } else if let Some(d) = "⁰¹²³⁴⁵⁶⁷⁸⁹".chars().position(|u| u == c) {
            if !out.ends_with('-') && !out.ends_with(|p: char| p.is_ascii_digit()) || !out.contains('^') {
                out.push('^');
            }
            out.push_str(&d.to_string());
        } else if c == '"' || c == '\\' || !(c.is_ascii_graphic() || c == ' ') {
            out.push('?');
        } else {
            out.push(c);
        }
    }
    out.replace("*/", "*?")
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod thermal_tests;
