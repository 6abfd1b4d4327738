//! A calibration's thermal model in the single-precision exports (C, Rust): the correction
//! tabulated per OUT_TEMP reading, each row split as the fixed exports' rows are.
//!
//! Why a table: OUT_TEMP is an integer register (1 LSB/°C, L3G4200D datasheet Table 5), so the
//! only temperatures a firmware can ask for are the readings inside the calibrated range: one row
//! per °C, 92 for setpoints −20…70 °C. The host evaluates the model at each reading's die
//! temperature with [`ThermalModel::calibration_at`] (what `host apply --temp-c` uses; die °C =
//! `out_temp_at_0c − OUT_TEMP`, [`ThermalModel::temp_c_from_raw`]), and each row is split into
//! float parts ([`super::SplitRow`]), so every row agrees with the host to 2^(e−19) °/s over all
//! of int16. Evaluating the polynomials and inverting K S in float on the target could not: a
//! float's relative rounding (6e-8) is already 3.4e-5 °/s at the 573 °/s an int16 reading spans
//! at ±500 °/s, three times the 1e-5 °/s, and `double` is emulated in software on a
//! Cortex-M4F. The cost is flash: 36 floats per reading, 13 KB for 92 readings.

use super::{split_rows, SplitRows};
use crate::calib::Calibration;
use crate::thermal::{ThermalError, ThermalModel};
use anyhow::{bail, Context, Result};
use nalgebra::Matrix3;

/// Floats per row of the exported table: the three parts of `(K S)⁻¹` (3 × 9) and of the
/// offsets as a rate (3 × 3).
pub const FLOATS_PER_ROW: usize = 36;

/// The calibration at one OUT_TEMP reading.
#[derive(Debug, Clone)]
pub struct ThermalRow {
    /// The OUT_TEMP reading, LSB.
    pub out_temp_lsb: i8,
    /// Its die temperature on the model's scale, °C.
    pub temp_c: f64,
    /// The model's calibration there.
    pub calibration: Calibration,
    /// Its (K S)⁻¹, °/s per count.
    pub m_inv_dps_per_count: [[f64; 3]; 3],
    /// Its rows split for single precision.
    pub split: SplitRows,
}

/// The thermal model and its rows, one per OUT_TEMP reading inside the calibrated range, in
/// increasing OUT_TEMP (decreasing die temperature).
#[derive(Debug, Clone)]
pub struct ThermalTable {
    /// The model, as `calibration.json`'s `thermal` section holds it.
    pub model: ThermalModel,
    /// One row per reading, contiguous.
    pub rows: Vec<ThermalRow>,
}

impl ThermalTable {
    /// Evaluates `model` at every OUT_TEMP reading (i8) whose die temperature is inside its range;
    /// refuses a model whose range holds no reading, a singular M or an offset the split cannot
    /// carry exactly (`max_offset_counts`).
    pub fn of(model: ThermalModel, max_offset_counts: f64) -> Result<Self> {
        let mut rows = Vec::new();
        for out_temp_lsb in i8::MIN..=i8::MAX {
            let temp_c = model.temp_c_from_raw(out_temp_lsb);
            if model.check_range(temp_c).is_err() {
                continue;
            }
            let calibration = model.calibration_at(temp_c).context("thermal model")?;
            let m = Matrix3::from_fn(|i, j| calibration.m_counts_per_dps[i][j]);
            let inv =
                m.try_inverse().with_context(|| format!("the thermal model's M at {temp_c:.2} °C is singular"))?;
            if let Some(v) = calibration.offset_counts.iter().find(|v| v.abs() >= max_offset_counts) {
                bail!(
                    "the thermal model's offset at {temp_c:.2} °C is {v} counts, beyond the ±{max_offset_counts} \
                     counts the single-precision exports carry exactly"
                );
            }
            let m_inv_dps_per_count = std::array::from_fn(|i| std::array::from_fn(|j| inv[(i, j)]));
            let split = split_rows(m_inv_dps_per_count, calibration.offset_counts);
            rows.push(ThermalRow { out_temp_lsb, temp_c, calibration, m_inv_dps_per_count, split });
        }
        if rows.is_empty() {
            bail!(
                "the thermal model's range {:.2}…{:.2} °C holds no OUT_TEMP reading (die °C = {:.3} − OUT_TEMP)",
                model.range_c[0],
                model.range_c[1],
                model.out_temp_at_0c
            );
        }
        Ok(Self { model, rows })
    }

    /// The lowest and the highest OUT_TEMP reading of the table, LSB.
    pub fn out_temp_range_lsb(&self) -> [i8; 2] {
        [self.rows[0].out_temp_lsb, self.rows[self.rows.len() - 1].out_temp_lsb]
    }

    /// The die temperatures of the table's first and last reading, °C, coldest first.
    pub fn temp_range_c(&self) -> [f64; 2] {
        [self.rows[self.rows.len() - 1].temp_c, self.rows[0].temp_c]
    }

    /// The largest split bound of any row, °/s ([`super::SplitRow::bound_dps`]).
    pub fn bound_dps(&self) -> f64 {
        self.rows.iter().flat_map(|r| r.split.rows.iter().map(super::SplitRow::bound_dps)).fold(0.0, f64::max)
    }

    /// Bytes of the exported table (f32 rows).
    pub fn table_bytes(&self) -> usize {
        self.rows.len() * FLOATS_PER_ROW * std::mem::size_of::<f32>()
    }

    /// The model's calibration at an OUT_TEMP reading's die temperature: what `host apply
    /// --temp-c` uses at that temperature. Outside the range: the model's own refusal.
    pub fn calibration_at_reading(&self, out_temp_lsb: i8) -> Result<Calibration, ThermalError> {
        self.model.calibration_at(self.model.temp_c_from_raw(out_temp_lsb))
    }

    /// The rate in double precision for a reading at an OUT_TEMP reading, °/s: the reference the
    /// exports are held to.
    pub fn apply(&self, raw: [i16; 3], out_temp_lsb: i8) -> Result<[f64; 3], ThermalError> {
        Ok(self.calibration_at_reading(out_temp_lsb)?.apply(raw))
    }
}

/// The thermal exports' lines on the correction and its validity range, for their header
/// comment (ASCII).
pub fn header_lines(t: &ThermalTable) -> Vec<String> {
    let [min_lsb, max_lsb] = t.out_temp_range_lsb();
    let [cold_c, warm_c] = t.temp_range_c();
    let m = &t.model;
    let setpoints: Vec<String> = m.setpoints.iter().map(|s| format!("{}", s.setpoint_c)).collect();
    let orders: Vec<String> = m.curves.iter().map(|c| c.order.to_string()).collect();
    [
        "rate_dps = (K S)^-1(T) (raw - v_off(T)), in the package frame, at the die temperature".to_string(),
        format!(
            "  T = {:.4} - temp_raw deg C, temp_raw the OUT_TEMP reading (the thermal model's scale).",
            m.out_temp_at_0c
        ),
        format!(
            "Thermal model: setpoints {} deg C; offset, k and direction per axis as polynomials in T - {} deg C \
             of orders {} (x, y, z; calibration.json's thermal section).",
            setpoints.join(", "),
            m.reference_c,
            orders.join(" ")
        ),
        format!(
            "Valid for temp_raw {min_lsb}..{max_lsb} LSB only: die {cold_c:.2}..{warm_c:.2} deg C, inside the model's \
             range {:.2}..{:.2} deg C (the setpoints' die temperatures +- half an OUT_TEMP step).",
            m.range_c[0], m.range_c[1]
        ),
        "Outside it the functions return an out-of-range error: the thermal model is never extrapolated.".to_string(),
        format!(
            "The table holds the model's calibration at each of the {} readings ({} bytes of float).",
            t.rows.len(),
            t.table_bytes()
        ),
    ]
    .iter()
    .map(|l| super::sanitise(l))
    .collect()
}
