//! The loop's advice in words: the runs it asks for, the notes on the final model, and an Earth
//! rate the Earth cannot have.

use super::PlusMinus;
use crate::calib::closure::{Ask, EarthExcess, Note};

/// A run the data cannot do without, as the operator is asked for it.
pub fn ask(a: &Ask) -> String {
    match a {
        Ask::SecondSpeed { rate_dps } => format!(
            "A delay and an index offset cannot be told apart: every run turns at θ1' = {rate_dps:+.1} °/s, so only their combined phase δ − θ2'·τ was fitted. It corrects these runs, but not a run at another speed. Run again at a second speed, e.g. --rates-dps 180,90, or in both directions, --rates-dps 180,-180."
        ),
        Ask::BothDirectionsForDrift => "The offset drifts, and all runs turn one way: the offset and the constant θ2'·M R_qᵀ e_z2 term are separated only through the drift model and the speeds. Runs in both directions (--rates-dps 180,-180) separate them directly.".into(),
        Ask::BothDirectionsForGSensitivity => "g-sensitivity is in the model and every run turns one way: its gravity term turns with θ2 like the signal, and only the speeds (1/θ1') tell the two apart, which costs every sensitivity and direction σ. In runs in both directions (--rates-dps 180,-180) the term keeps its sign while the signal's flips, which separates them directly (on the simulator, 4-8× smaller σ).".into(),
    }
}

/// A note on the final model, in words.
pub fn note(n: &Note) -> String {
    match n {
        Note::DelayAndIndexSeparable => {
            "Delay and index offset are separable here: the runs turn at more than one θ2' (speed or direction)."
                .into()
        }
        Note::OffsetReference { drift, run_label, t_s, at_start_counts } => {
            let at_start: Vec<String> = at_start_counts.iter().map(|v| format!("{v:+.2}")).collect();
            format!(
                "The offsets reported are those of {} ({}); at the first sample of {run_label} (t = {t_s:.1} s) the model gives x/y/z = {} counts; calibration.json's `drift` holds the modelled offset every 10 s of every run.",
                drift.offset_reference().unwrap_or("the drift model's reference"),
                drift.name(),
                at_start.join(" / ")
            )
        }
        Note::EarthAtLatitude { latitude_deg, vertical_dph, horizontal_dph, expected_horizontal_dph } => format!(
            "Earth rotation at latitude {latitude_deg}°: vertical {vertical_dph:.2} °/h taken as known; horizontal fitted {:.2} °/h against Ω·cos(latitude) = {expected_horizontal_dph:.2} °/h ({:+.1}σ).",
            PlusMinus(*horizontal_dph),
            horizontal_dph.z(*expected_horizontal_dph)
        ),
        Note::EarthFitted { vertical_dph, horizontal_dph, total_dph } => format!(
            "Earth rotation fitted: vertical {:.2} °/h, horizontal {:.2} °/h, together {total_dph:.2} °/h against 15.041 °/h. --latitude-deg gives its vertical part instead of fitting it.",
            PlusMinus(*vertical_dph),
            PlusMinus(*horizontal_dph)
        ),
        Note::EarthHorizontalOnly { horizontal_dph, vertical_max_dps_per_g } => format!(
            "Earth rotation: horizontal part fitted {:.2} °/h (at most 15.041 °/h); its vertical part turns in the sensor frame as gravity does, so the g-sensitivity holds it (at most Ω/g = {vertical_max_dps_per_g:.4} °/s/g along M's rows), which leaves the sensitivities and directions unbiased. --latitude-deg gives the vertical part and separates the two.",
            PlusMinus(*horizontal_dph)
        ),
        Note::EarthNotModelled { type_b_ppm } => format!(
            "Earth rotation is not in the model (no --latitude-deg, and the test did not find it): every sensitivity's σ includes {type_b_ppm:.1} ppm for it (up to 15.041 °/h against the slowest run's θ1', uniform). Give the lab's latitude to remove it."
        ),
    }
}

/// An Earth rate larger than the Earth turns, in words.
pub fn earth_excess(e: &EarthExcess) -> String {
    format!(
        "Earth rotation fitted at {:.1} °/h, {:.1}σ more than the Earth turns (15.041 °/h): the term is holding another effect the runs cannot tell from it (g-sensitivity, a table tilt); give --latitude-deg, or add runs in both directions.",
        PlusMinus(e.total_dph),
        e.excess_sigma
    )
}
