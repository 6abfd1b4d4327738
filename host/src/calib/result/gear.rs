//! What the kinematics' reconstruction reports of the rig itself: where each run's index pulse
//! puts θ2 = 0, and the gear ratio measured between the pulses
//! ([`crate::calib::data::kinematics`] computes them).

use super::estimate::Estimate;
use serde::{Deserialize, Serialize};

/// Where θ2 = 0 lies in a run, from its index pulses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(into = "IndexStatsJson", from = "IndexStatsJson")]
pub struct IndexStats {
    /// Complete pulses found (rising edge followed by a falling edge).
    pub pulses: usize,
    /// Pulses rejected as outliers from the line.
    pub rejected: usize,
    /// Encoder count of θ2 = 0 nearest the first pulse.
    pub ref_counts: Estimate,
    /// 1-σ of the reference as a θ2 angle, degrees (through the pooled period).
    pub ref_sigma_deg: f64,
    /// RMS distance of pulse centres from the fitted line, counts.
    pub centre_rms_counts: f64,
    /// Median plate width, counts.
    pub plate_width_counts: f64,
    /// This run's own estimate of the encoder counts per θ2 revolution (NaN with one pulse).
    pub period_counts: Estimate,
}

/// The actual gear ratio θ2'/θ1', from the encoder counts between index pulses of all runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(into = "GearEstimateJson", from = "GearEstimateJson")]
pub struct GearEstimate {
    /// Nominal ratio from `Hello::gear_ratio`.
    pub nominal: f64,
    /// Estimated ratio, used for θ2 and θ2' (`estimated` and `sigma` in the JSON).
    pub ratio: Estimate,
    /// (ratio − nominal)/nominal, parts per million.
    pub deviation_ppm: f64,
}

// The JSON layouts of this module's types (see [`crate::calib::result::estimate::values`] for why).

#[derive(Serialize, Deserialize)]
pub struct IndexStatsJson {
    pulses: usize,
    rejected: usize,
    ref_counts: f64,
    ref_sigma_counts: f64,
    ref_sigma_deg: f64,
    centre_rms_counts: f64,
    plate_width_counts: f64,
    period_counts: f64,
    period_sigma_counts: f64,
}

impl From<IndexStats> for IndexStatsJson {
    fn from(i: IndexStats) -> Self {
        Self {
            pulses: i.pulses,
            rejected: i.rejected,
            ref_counts: i.ref_counts.value,
            ref_sigma_counts: i.ref_counts.sigma,
            ref_sigma_deg: i.ref_sigma_deg,
            centre_rms_counts: i.centre_rms_counts,
            plate_width_counts: i.plate_width_counts,
            period_counts: i.period_counts.value,
            period_sigma_counts: i.period_counts.sigma,
        }
    }
}

impl From<IndexStatsJson> for IndexStats {
    fn from(i: IndexStatsJson) -> Self {
        Self {
            pulses: i.pulses,
            rejected: i.rejected,
            ref_counts: Estimate::new(i.ref_counts, i.ref_sigma_counts),
            ref_sigma_deg: i.ref_sigma_deg,
            centre_rms_counts: i.centre_rms_counts,
            plate_width_counts: i.plate_width_counts,
            period_counts: Estimate::new(i.period_counts, i.period_sigma_counts),
        }
    }
}

#[derive(Serialize, Deserialize)]
pub struct GearEstimateJson {
    nominal: f64,
    estimated: f64,
    sigma: f64,
    deviation_ppm: f64,
}

impl From<GearEstimate> for GearEstimateJson {
    fn from(g: GearEstimate) -> Self {
        Self { nominal: g.nominal, estimated: g.ratio.value, sigma: g.ratio.sigma, deviation_ppm: g.deviation_ppm }
    }
}

impl From<GearEstimateJson> for GearEstimate {
    fn from(g: GearEstimateJson) -> Self {
        Self { nominal: g.nominal, ratio: Estimate::new(g.estimated, g.sigma), deviation_ppm: g.deviation_ppm }
    }
}
