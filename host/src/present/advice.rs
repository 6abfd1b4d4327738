//! The loop's advice in words: the runs it asks for, the notes on the final model, and an Earth
//! rate the Earth cannot have.

use super::PlusMinus;
use crate::calib::analysis::closure::{Ask, EarthExcess, Note};
use crate::calib::analysis::consider::SEPARATED_SNR2;
use crate::calib::analysis::consistency::Consistency;
use crate::calib::result::consider_term::{ConsiderTerm, ModelChoiceTerm};

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
        Note::SpeedChangeUnchecked { rate_dps } => format!(
            "Not checked: whether M changes with speed. Every run turns at {rate_dps:.0} °/s, where a sensitivity or direction that changes with speed (a non-linearity in the rate vector's magnitude, a package turning on a compliant mount) is part of M, and no σ carries it: no datasheet bounds it. Runs at a second speed check it (--rates-dps 180,90,-180)."
        ),
        Note::SpeedChangeHeldByGravity { rates_dps } => {
            let rates: Vec<String> = rates_dps.iter().map(|r| format!("{r:+.0}")).collect();
            format!(
                "Not told apart: a g-sensitivity and a change of M with speed. At {} °/s the g-sensitivity (∝ 1) and M (∝ θ2') together take up any change of M that grows with the square of the speed (a non-linearity in the rate vector's magnitude, a package turning on a compliant mount), so the runs' agreement does not rule it out and no σ carries it: the calibration is flagged. Runs in the other direction tell them apart (--rates-dps 180,90,-180).",
                rates.join(", ")
            )
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
        Note::HeldByPrior { name, estimate, bound, prior_sigma, unit, identified_by } => format!(
            "{name}: these runs do not bound it within the {bound:.3} {unit} it can at most be (another term of the model shares its shape), so its physical size holds it (0 ± {prior_sigma:.2} {unit}), not a free fit, whose σ would be the runs' blindness: {:.2} {unit}, carried in every σ and in cov. Runs that separate it: {identified_by}; where other terms share its shape, runs at three signed speeds (--rates-dps 180,90,-180) tell them apart.",
            PlusMinus(*estimate)
        ),
        Note::Unseparated(t) => unseparated(t),
        Note::ModelChoice(t) => model_choice(t),
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

/// `v` to four significant digits, no exponent (a plausible size, not a measurement).
fn four_digits(v: f64) -> String {
    let decimals = if v == 0.0 || !v.is_finite() { 0 } else { (3 - v.abs().log10().floor() as i32).max(0) as usize };
    format!("{v:.decimals$}")
}

/// The least information λ of a consider term's directions for which longer runs are advised.
const LEAST_SEEN_FOR_LONGER: f64 = 0.25;

/// A consider term in words: the effect, its plausible size and source, what it costs, and the
/// runs that would remove it.
fn unseparated(t: &ConsiderTerm) -> String {
    let sizes: Vec<String> =
        t.params.iter().map(|p| format!("{} {} {}", p.name, four_digits(p.sigma), p.unit)).collect();
    let sizes = if t.params.iter().all(|p| p.sigma == t.params[0].sigma && p.unit == t.params[0].unit) {
        format!("{} {} each of {}", four_digits(t.params[0].sigma), t.params[0].unit, t.params.len())
    } else {
        sizes.join(", ")
    };
    // Information grows with rig time: where these runs see the effect at all (λ ≥ 0.25, a
    // judgement: beyond 100× the rig time no one runs), the same design longer separates it.
    let longer = if (LEAST_SEEN_FOR_LONGER..SEPARATED_SNR2).contains(&t.least_seen) {
        format!(
            "; these runs see it at λ = {:.1} of the {SEPARATED_SNR2:.0} that separates it, so the same runs {:.0}× as long would",
            t.least_seen,
            (SEPARATED_SNR2 / t.least_seen).ceil()
        )
    } else {
        String::new()
    };
    format!(
        "{} is not separated by these runs: at a plausible size (1σ: {sizes}; {}) it adds up to {:.1} ppm to a sensitivity's σ and {:.4}° to a direction's, carried in every σ and in cov. Runs that remove it: {}{longer}.",
        t.name,
        t.source,
        worst(t.k_sigma_ppm),
        worst(t.direction_sigma_deg),
        t.removed_by
    )
}

/// The largest of a term's three per-axis figures.
fn worst(v: [f64; 3]) -> f64 {
    v.into_iter().fold(0.0, f64::max)
}

/// A step's near tie the final model lacks, in words.
fn model_choice(t: &ModelChoiceTerm) -> String {
    format!(
        "Model choice: the loop took {} where {} would also explain the residual (Akaike weight {:.3} of that step's candidates): these runs do not tell them clearly apart, and M moves with the choice. That move at its weight adds up to {:.1} ppm to a sensitivity's σ and {:.4}° to a direction's, carried in every σ and in cov. Longer runs, or runs in the other direction, tell the two apart.",
        t.taken,
        t.alternative,
        t.weight,
        worst(t.k_sigma_ppm),
        worst(t.direction_sigma_deg)
    )
}

/// Runs at different speeds that want different M, in words: all their elements together,
/// and each group whose axes turned together.
pub fn disagreement(c: &Consistency) -> String {
    let groups: Vec<String> = c
        .groups
        .iter()
        .map(|g| {
            format!(
                "the runs at {:+.0} °/s against those at {:+.0} °/s: {} differs by {:+.1} ppm of the sensitivity ({:.1}σ)",
                g.rate_dps, g.reference_rate_dps, g.element, g.max_ppm, g.max_z
            )
        })
        .collect();
    let turns: Vec<String> = c
        .turns
        .iter()
        .filter(|t| t.significant())
        .map(|t| {
            let [x, y, z] = t.turn_deg;
            format!(
                " The runs at {:+.0} °/s see the sensor turned by {:.4}° against those at {:+.0} °/s (about the table's x, y, z: {x:+.4}°, {y:+.4}°, {z:+.4}°; χ² = {:.1} for {} degrees of freedom against {:.1}): a mount, fixture or bearing that gives with speed; the turn at rest is not known.",
                t.rate_dps,
                (x * x + y * y + z * z).sqrt(),
                t.reference_rate_dps,
                t.chi2,
                t.dof,
                t.threshold
            )
        })
        .collect();
    let within = if c.chi2 > c.threshold { "" } else { ", within chance" };
    format!(
        "The runs disagree about M.{} M's elements between the groups: χ² = {:.1} for {} degrees of freedom against {:.1} ({:.1}σ{within}); {}. An effect that changes with speed and that no catalogued effect explains is in M.",
        turns.concat(),
        c.chi2,
        c.dof,
        c.threshold,
        c.significance_sigma,
        groups.join("; ")
    )
}

#[cfg(test)]
mod tests {
    use super::disagreement;
    use crate::calib::analysis::consistency::{Consistency, GroupDifference, GroupTurn};

    /// A turn past its threshold with the elements within chance: the turn first, then the
    /// elements' test, said to be within chance, in exactly these words.
    #[test]
    fn a_turn_is_said_before_the_elements_test() {
        let c = Consistency {
            chi2: 42.1,
            dof: 18,
            threshold: 45.7,
            significance_sigma: 3.1,
            groups: vec![GroupDifference {
                rate_dps: 90.0,
                reference_rate_dps: 180.0,
                delta_m: [[0.0; 3]; 3],
                delta_m_sigma: [[1.0; 3]; 3],
                max_z: 3.8,
                max_ppm: 82.1,
                element: "m_z.omega_x".into(),
            }],
            turns: vec![GroupTurn {
                rate_dps: 90.0,
                reference_rate_dps: 180.0,
                turn_deg: [-0.0058, 0.0003, 0.0004],
                turn_sigma_deg: [0.001; 3],
                chi2: 42.4,
                dof: 3,
                threshold: 18.6,
            }],
        };
        assert!(c.disagrees());
        assert_eq!(
            disagreement(&c),
            "The runs disagree about M. The runs at +90 °/s see the sensor turned by 0.0058° against \
             those at +180 °/s (about the table's x, y, z: -0.0058°, +0.0003°, +0.0004°; χ² = 42.4 for 3 \
             degrees of freedom against 18.6): a mount, fixture or bearing that gives with speed; the \
             turn at rest is not known. M's elements between the groups: χ² = 42.1 for 18 degrees of \
             freedom against 45.7 (3.1σ, within chance); the runs at +90 °/s against those at +180 °/s: \
             m_z.omega_x differs by +82.1 ppm of the sensitivity (3.8σ). An effect that changes with \
             speed and that no catalogued effect explains is in M."
        );
    }
}
