//! The thermal model as text: each curve's order and coefficients, and every setpoint's own
//! calibration beside the model's value there.

use super::model::ThermalModel;
use std::fmt::Write as _;

/// Digits worth printing for a value with σ `sigma`: two significant digits of σ.
fn decimals(sigma: f64) -> usize {
    if sigma > 0.0 && sigma.is_finite() {
        (1.0 - sigma.log10().floor()).clamp(0.0, 12.0) as usize
    } else {
        6
    }
}

/// The summary `host calibrate --replay <thermal folder>` prints.
pub fn text(model: &ThermalModel) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Thermal model: {} setpoints, die {:.1}…{:.1} °C (valid range {:.1}…{:.1} °C; die °C = {:.1} − OUT_TEMP), polynomials in (T − {} °C)",
        model.setpoints.len(),
        model.setpoints.first().map_or(f64::NAN, |s| s.die_c),
        model.setpoints.last().map_or(f64::NAN, |s| s.die_c),
        model.range_c[0],
        model.range_c[1],
        model.out_temp_at_0c,
        model.reference_c,
    );
    for line in exclusions(model) {
        let _ = writeln!(out, "{line}");
    }
    let _ = writeln!(out, "Order by held-out setpoint (smallest weighted PRESS); z = (setpoint − model)/σ");
    for c in &model.curves {
        let d = decimals(c.points.iter().map(|p| p.measured.sigma).fold(f64::INFINITY, f64::min));
        let coef: Vec<String> =
            c.coef.iter().enumerate().map(|(k, e)| format!("c{k} {:.*e} ± {:.1e}", 3, e.value, e.sigma)).collect();
        let press: Vec<String> = c.press.iter().map(|p| format!("{p:.1}")).collect();
        let _ = writeln!(
            out,
            "  {:<24} order {} (PRESS {}), χ²/dof {:.2}/{}{}{}: {}",
            c.label(),
            c.order,
            press.join(" | "),
            c.chi2,
            c.dof,
            if c.scale_factor > 1.0 { format!(", σ × {:.2}", c.scale_factor) } else { String::new() },
            if c.between_sigma > 0.0 {
                format!(", between sessions ± {:.1e}", c.between_sigma)
            } else {
                String::new()
            },
            coef.join(", ")
        );
        for p in &c.points {
            let _ = writeln!(
                out,
                "      {:>7.2} °C  setpoint {:>+.*} ± {:.*}   model {:>+.*} ± {:.*}   z {:>+5.2}   held out {:>+.*} (z {:>+5.2})",
                p.die_c,
                d,
                p.measured.value,
                d,
                p.measured.sigma,
                d,
                p.model.value,
                d,
                p.model.sigma,
                p.z,
                d,
                p.held_out.predicted,
                p.held_out.z
            );
        }
    }
    out
}

/// What the fit left out or took in spite of the setpoints' verdicts
/// ([`super::model::split_by_noise_floor`]), a line each; none when every setpoint reached the
/// noise floor.
pub fn exclusions(model: &ThermalModel) -> Vec<String> {
    let mut out: Vec<String> = model
        .excluded
        .iter()
        .map(|s| {
            format!(
                "Left out of the fit: setpoint {} °C (die {:.1} °C): its calibration did not reach the noise floor (exit 3; its folder says what it left), so its values are not trusted; the model's range is the other setpoints'.",
                s.setpoint_c, s.die_c
            )
        })
        .collect();
    if !model.not_at_floor_in_fit.is_empty() {
        let list: Vec<String> = model.not_at_floor_in_fit.iter().map(|c| format!("{c} °C")).collect();
        out.push(format!(
            "DO NOT TRUST THIS MODEL: setpoint(s) {} did not reach the noise floor and are in the fit, as leaving them out would leave fewer than {} setpoints.",
            list.join(", "),
            super::MIN_SETPOINTS
        ));
    }
    out
}
