//! The calibration a user applies to raw readings: ω = M⁻¹ (v − v_off) (EXCITER.md eq. 7),
//! stored as JSON.

use nalgebra::{Matrix3, Vector3};
use protocol::FullScale;
use serde::{Deserialize, Serialize};

/// Why a calibration file was rejected.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationFileError {
    /// Not valid JSON of the expected shape.
    #[error("calibration JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// M cannot be inverted.
    #[error("calibration matrix m_counts_per_dps is singular, cannot invert it")]
    Singular,
}

/// The stored form: what the JSON holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct CalibrationFile {
    model: String,
    full_scale: FullScale,
    m_counts_per_dps: [[f64; 3]; 3],
    offset_counts: [f64; 3],
}

/// M and offsets, ready to convert raw counts to a rate vector in the package frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "CalibrationFile", into = "CalibrationFile")]
pub struct Calibration {
    /// Model the numbers belong to.
    pub model: String,
    /// Full scale the counts were recorded at; counts at another full scale mean other rates.
    pub full_scale: FullScale,
    /// M = K S, counts per °/s; row i is axis i.
    pub m_counts_per_dps: [[f64; 3]; 3],
    /// Offsets, counts.
    pub offset_counts: [f64; 3],
    m_inv: Matrix3<f64>,
}

impl TryFrom<CalibrationFile> for Calibration {
    type Error = CalibrationFileError;
    fn try_from(f: CalibrationFile) -> Result<Self, Self::Error> {
        Calibration::new(f.model, f.full_scale, f.m_counts_per_dps, f.offset_counts)
    }
}

impl From<Calibration> for CalibrationFile {
    fn from(c: Calibration) -> Self {
        CalibrationFile {
            model: c.model,
            full_scale: c.full_scale,
            m_counts_per_dps: c.m_counts_per_dps,
            offset_counts: c.offset_counts,
        }
    }
}

impl Calibration {
    /// A calibration; fails if M is singular.
    pub fn new(
        model: String,
        full_scale: FullScale,
        m_counts_per_dps: [[f64; 3]; 3],
        offset_counts: [f64; 3],
    ) -> Result<Self, CalibrationFileError> {
        let m = Matrix3::from_fn(|i, j| m_counts_per_dps[i][j]);
        let m_inv = m.try_inverse().ok_or(CalibrationFileError::Singular)?;
        Ok(Self { model, full_scale, m_counts_per_dps, offset_counts, m_inv })
    }

    /// Rate vector in the package frame, °/s, from one raw reading.
    pub fn apply(&self, raw_counts: [i16; 3]) -> [f64; 3] {
        let v = Vector3::from_fn(|i, _| f64::from(raw_counts[i]) - self.offset_counts[i]);
        (self.m_inv * v).into()
    }

    /// Pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("plain numbers and strings always serialise")
    }

    /// Parses the JSON written by [`Calibration::to_json`] (or the same fields inside any object).
    pub fn from_json(text: &str) -> Result<Self, CalibrationFileError> {
        Ok(serde_json::from_str(text)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tilted, scaled, offset sensor: raw counts of a known rate come back as that rate, to
    /// the rounding of counts to integers (≤ 0.5 count / 57 counts per °/s ≈ 0.009 °/s per axis,
    /// amplified by at most ‖M⁻¹‖·‖M‖ ≈ 1.1 here).
    #[test]
    fn apply_recovers_a_known_rate_vector() {
        let m = [[57.3, 0.9, -0.4], [-0.6, 56.8, 1.1], [0.3, -0.7, 58.0]];
        let off = [12.0, -30.5, 4.25];
        let cal = Calibration::new("linear: v = K S ω + v_off".into(), FullScale::Dps500, m, off).unwrap();
        let w = Vector3::new(120.0, -45.5, 200.25);
        let v = Matrix3::from_fn(|i, j| m[i][j]) * w + Vector3::from(off);
        let raw = [v.x.round() as i16, v.y.round() as i16, v.z.round() as i16];
        let back = cal.apply(raw);
        for i in 0..3 {
            assert!((back[i] - w[i]).abs() < 0.011, "{back:?} vs {w:?}");
        }
        let again = Calibration::from_json(&cal.to_json()).unwrap();
        assert_eq!(again, cal);
        assert_eq!(again.apply(raw), back);
    }

    #[test]
    fn singular_matrix_is_rejected_from_json() {
        let text = r#"{"model":"m","full_scale":"Dps500","m_counts_per_dps":[[1,0,0],[1,0,0],[0,0,1]],"offset_counts":[0,0,0]}"#;
        let err = Calibration::from_json(text).unwrap_err();
        assert!(err.to_string().contains("singular"), "{err}");
    }
}
