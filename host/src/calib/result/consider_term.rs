//! What the consider covariance reports: each catalogued effect the runs do not separate, its
//! plausible size with its source, and the σ it adds to the sensitivities and directions
//! ([`crate::calib::analysis::consider`] computes them).

use crate::calib::result::derived::derive;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// What a covariance `added` to the 12 base parameters (`CalReport` order) adds at `params`:
/// each sensitivity's σ, ppm of the sensitivity (k, its row of M's norm), and each direction's σ,
/// degrees. What a consider term and a model-choice term report.
pub fn added_sigmas(params: &[f64; 12], added: &DMatrix<f64>, nominal: f64) -> ([f64; 3], [f64; 3]) {
    let (axes, _) = derive(params, added, nominal);
    let k_ppm = axes.each_ref().map(|ax| ax.k_counts_per_dps.sigma / ax.k_counts_per_dps.value * 1e6);
    let direction_deg = axes.map(|ax| ax.s.iter().map(|e| e.sigma.powi(2)).sum::<f64>().sqrt().to_degrees());
    (k_ppm, direction_deg)
}

/// One parameter of a considered effect.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConsideredParam {
    /// What.
    pub name: String,
    /// Its plausible size, one σ.
    pub sigma: f64,
    /// Unit.
    pub unit: String,
}

/// One catalogued effect the runs do not separate, and what it costs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConsiderTerm {
    /// The effect's key, as `--consider KEY=SIGMA` names it (`g_sensitivity`, …).
    pub effect: String,
    /// The effect's name, as the notes print it.
    #[serde(default)]
    pub name: String,
    /// Its parameters' plausible sizes.
    pub params: Vec<ConsideredParam>,
    /// Where those sizes come from.
    pub source: String,
    /// σ it adds to each sensitivity, ppm (alone; the terms add in quadrature).
    pub k_sigma_ppm: [f64; 3],
    /// σ it adds to each axis direction, degrees.
    pub direction_sigma_deg: [f64; 3],
    /// Directions (whitened) the runs do not separate, of the effect's parameters.
    pub unseparated: usize,
    /// The least of those directions' information λ (the squared signal-to-noise of an effect
    /// of plausible size along it; [`SEPARATED_SNR2`] separates it). Near 0: these runs cannot
    /// see it at all; between: longer runs of the same design would separate it.
    #[serde(default)]
    pub least_seen: f64,
    /// The runs that would separate it.
    pub removed_by: String,
}

/// A step's near tie: an alternative to the effect the loop took, about as likely given the
/// data, that the final model lacks. Where two effects' signatures are nearly alike in these
/// runs, the one taken may be the wrong one, and M moves with the choice; the spread of M over
/// the alternatives, each at its Akaike weight, is carried in σ
/// ([`crate::calib::analysis::model_choice`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelChoiceTerm {
    /// The effect taken at that step (its key).
    pub taken: String,
    /// The alternative (its key).
    pub alternative: String,
    /// Its Akaike weight among the step's candidates (the one taken and its alternatives).
    pub weight: f64,
    /// σ it adds to each sensitivity, ppm.
    pub k_sigma_ppm: [f64; 3],
    /// σ it adds to each axis direction, degrees.
    pub direction_sigma_deg: [f64; 3],
}
