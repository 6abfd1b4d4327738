//! `thermal.html`: each quantity of each axis against die temperature, the model's curve in its
//! ±1σ band with every setpoint's own calibration as a point, and the numbers as text.

use super::model::{Curve, ThermalModel};
use super::warm_up::BesideModel;
use crate::report::html::Document;
use crate::report::plots::{line_plot, PlotSpec, Series};

/// Points along each curve.
const CURVE_POINTS: usize = 61;

/// One figure: the curve in its band and the setpoints.
fn figure(model: &ThermalModel, c: &Curve) -> Result<String, crate::report::plots::PlotError> {
    let [lo, hi] = model.range_c;
    let xs: Vec<f64> = (0..CURVE_POINTS).map(|i| lo + (hi - lo) * i as f64 / (CURVE_POINTS - 1) as f64).collect();
    let at: Vec<_> = xs.iter().map(|&t| c.at(model.reference_c, t)).collect();
    let line = xs.iter().zip(&at).map(|(&t, e)| (t, e.value)).collect();
    let lower = at.iter().map(|e| e.value - e.sigma).collect();
    let upper = at.iter().map(|e| e.value + e.sigma).collect();
    let points = c.points.iter().map(|p| (p.die_c, p.measured.value)).collect();
    let spec = PlotSpec::new(
        format!("{} (order {})", c.label(), c.order),
        "die temperature [°C]",
        c.quantity.label().to_string(),
    )
    .with_x_range(lo, hi);
    line_plot(
        &spec,
        &[Series::with_band("model ±1σ", line, lower, upper, 0), Series::points("setpoint calibration", points, 1)],
    )
}

/// The page.
pub fn html(model: &ThermalModel, beside: &[BesideModel]) -> String {
    let mut doc = Document::new("Gyro calibration over temperature");
    doc.paragraph(format!(
        "{} setpoints; the model holds for die temperatures {:.1}…{:.1} °C (die °C = {:.1} − OUT_TEMP) and is not extrapolated beyond.",
        model.setpoints.len(),
        model.range_c[0],
        model.range_c[1],
        model.out_temp_at_0c
    ));
    for line in super::present::exclusions(model) {
        doc.paragraph(line);
    }
    for c in &model.curves {
        doc.figure_result(
            figure(model, c),
            format!("{}: the model (line, ±1σ band) and each setpoint's own calibration (points)", c.label()),
        );
    }
    if !beside.is_empty() {
        let rows = beside
            .iter()
            .map(|r| {
                vec![
                    format!("{}", r.setpoint_c),
                    format!("{:.1}", r.die_c),
                    r.axis.to_string(),
                    r.quantity.clone(),
                    format!("{:+.6} ± {:.6}", r.warm_up.value, r.warm_up.sigma),
                    format!("{:+.6} ± {:.6}", r.model_slope.value, r.model_slope.sigma),
                    format!("{:+.2}", r.z),
                ]
            })
            .collect();
        doc.table(
            "A setpoint's own warm-up coefficients (its session's die-temperature span only) beside the model's slope at its die temperature",
            &["setpoint °C", "die °C", "axis", "quantity", "warm-up", "model slope", "z"],
            rows,
        );
    }
    doc.preformatted(super::present::text(model));
    doc.render()
}
