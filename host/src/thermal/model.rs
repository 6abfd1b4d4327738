//! The thermal model: offset, sensitivity and direction of each axis as polynomials in die
//! temperature, fitted to the calibrations made at each chamber setpoint.

use super::poly::{self, HeldOut, Point, PolyFit};
use super::{Quantity, SetpointCal, ThermalError};
use crate::calib::{Calibration, Estimate};
use nalgebra::DMatrix;
use protocol::FullScale;
use serde::{Deserialize, Serialize};

/// Temperature the polynomials are expanded about, °C (the datasheet's 25 °C: L3G4200D Table 4).
pub const REFERENCE_C: f64 = 25.0;

/// σ of a setpoint's die temperature, °C: OUT_TEMP reads whole degrees (datasheet Table 5,
/// 1 LSB/°C), and at a settled setpoint every reading rounds the same way, so the mean keeps the
/// rounding error, uniform within ±0.5 °C: 1/√12 (GUM 4.3.7).
pub const TEMP_SIGMA_C: f64 = 0.288_675_134_594_812_9;

/// How far outside the setpoints' die temperatures a query is still answered, °C: half an
/// OUT_TEMP step, the register's own rounding (a reading at the range's end may round out).
pub const RANGE_MARGIN_C: f64 = 0.5;

/// One setpoint's value of one quantity beside the model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// Die temperature of the setpoint, °C (model scale).
    pub die_c: f64,
    /// The setpoint's own calibration.
    pub measured: Estimate,
    /// The model at that temperature (all setpoints).
    pub model: Estimate,
    /// (measured − model) / the point's effective σ.
    pub z: f64,
    /// The model fitted without this setpoint, at its temperature.
    pub held_out: HeldOut,
}

/// One quantity of one axis as a polynomial in `T − reference_c`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    /// Axis, 'x', 'y' or 'z'.
    pub axis: char,
    /// Which quantity.
    pub quantity: Quantity,
    /// Order chosen (weighted PRESS, `poly::choose_order`).
    pub order: usize,
    /// Weighted PRESS of each order tried, from 0.
    pub press: Vec<f64>,
    /// Coefficients of `(T − reference_c)^d`, constant first, each with its σ.
    pub coef: Vec<Estimate>,
    /// Their covariance (rows).
    pub cov: Vec<Vec<f64>>,
    /// χ² of the setpoints against the curve, and its degrees of freedom.
    pub chi2: f64,
    /// Degrees of freedom of `chi2`.
    pub dof: usize,
    /// Factor the covariance was scaled by: √(χ²/dof) when above 1 (the Particle Data Group's
    /// scale factor for inconsistent inputs), else 1.
    pub scale_factor: f64,
    /// Each setpoint beside the curve.
    pub points: Vec<CurvePoint>,
}

impl Curve {
    /// The curve's value and σ at `temp_c`.
    pub fn at(&self, reference_c: f64, temp_c: f64) -> Estimate {
        let x = temp_c - reference_c;
        let coef: Vec<f64> = self.coef.iter().map(|c| c.value).collect();
        let a = poly::powers(x, self.order);
        let cov = DMatrix::from_fn(self.order + 1, self.order + 1, |r, c| self.cov[r][c]);
        Estimate::from_variance(poly::eval(&coef, x), (a.transpose() * cov * &a)[(0, 0)])
    }

    /// The curve's slope at `temp_c`, per °C.
    pub fn slope_at(&self, reference_c: f64, temp_c: f64) -> f64 {
        let coef: Vec<f64> = self.coef.iter().map(|c| c.value).collect();
        poly::slope(&coef, temp_c - reference_c)
    }

    /// Name for tables, e.g. "x offset [counts]".
    pub fn label(&self) -> String {
        format!("{} {}", self.axis, self.quantity.label())
    }
}

/// A setpoint's identity in the model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SetpointSummary {
    /// Chamber setpoint, °C.
    pub setpoint_c: f64,
    /// Mean OUT_TEMP over the setpoint's runs, LSB.
    pub out_temp_mean_lsb: f64,
    /// Die temperature on the model's scale, °C.
    pub die_c: f64,
}

/// The thermal model, as `calibration.json` holds it (its `thermal` section).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ThermalModel {
    /// Temperature the polynomials are expanded about, °C.
    pub reference_c: f64,
    /// Die temperature from the OUT_TEMP register: `temp_c = out_temp_at_0c − raw`. OUT_TEMP's
    /// offset is not specified (datasheet Table 5), so it is anchored on the chamber: the
    /// setpoints' mean die temperature is their mean setpoint. The die's self-heating (a few °C)
    /// is inside this constant; every use through OUT_TEMP (`host apply`, the exports) is
    /// unaffected by it.
    pub out_temp_at_0c: f64,
    /// Die temperatures the model holds for, °C: the setpoints' range (± [`RANGE_MARGIN_C`]).
    pub range_c: [f64; 2],
    /// σ of each setpoint's die temperature, °C.
    pub temp_sigma_c: f64,
    /// Full scale of every setpoint's runs.
    pub full_scale: FullScale,
    /// The setpoints, coldest first.
    pub setpoints: Vec<SetpointSummary>,
    /// Per axis: offset, sensitivity, and the direction's two components off its own axis.
    pub curves: Vec<Curve>,
}

impl ThermalModel {
    /// Fits every quantity of every axis over the setpoints, each at the order its data support.
    pub fn fit(setpoints: &[SetpointCal]) -> Result<Self, ThermalError> {
        Self::fit_with(setpoints, None)
    }

    /// Fits with the orders of `orders` (curve by curve), or chosen from the data when `None`.
    pub fn fit_with(setpoints: &[SetpointCal], orders: Option<&[usize]>) -> Result<Self, ThermalError> {
        let mut sp: Vec<&SetpointCal> = setpoints.iter().collect();
        sp.sort_by(|a, b| a.setpoint_c.total_cmp(&b.setpoint_c));
        let full_scale = super::check_setpoints(&sp)?;
        let n = sp.len() as f64;
        let out_temp_at_0c = sp.iter().map(|s| s.setpoint_c + s.out_temp_mean_lsb).sum::<f64>() / n;
        let summaries: Vec<SetpointSummary> = sp
            .iter()
            .map(|s| SetpointSummary {
                setpoint_c: s.setpoint_c,
                out_temp_mean_lsb: s.out_temp_mean_lsb,
                die_c: out_temp_at_0c - s.out_temp_mean_lsb,
            })
            .collect();
        let mut curves = Vec::with_capacity(12);
        for (c, (axis, quantity)) in Quantity::all().enumerate() {
            let points: Vec<Point> = sp
                .iter()
                .zip(&summaries)
                .map(|(s, sum)| {
                    let e = s.value(axis, quantity);
                    Point { x: sum.die_c - REFERENCE_C, sigma_x: TEMP_SIGMA_C, y: e.value, sigma_y: e.sigma }
                })
                .collect();
            let order = orders.and_then(|o| o.get(c).copied());
            curves.push(curve(axis, quantity, &points, &summaries, order)?);
        }
        let lo = summaries.iter().map(|s| s.die_c).fold(f64::INFINITY, f64::min);
        let hi = summaries.iter().map(|s| s.die_c).fold(f64::NEG_INFINITY, f64::max);
        Ok(Self {
            reference_c: REFERENCE_C,
            out_temp_at_0c,
            range_c: [lo - RANGE_MARGIN_C, hi + RANGE_MARGIN_C],
            temp_sigma_c: TEMP_SIGMA_C,
            full_scale,
            setpoints: summaries,
            curves,
        })
    }

    /// The orders of the curves, in order.
    pub fn orders(&self) -> Vec<usize> {
        self.curves.iter().map(|c| c.order).collect()
    }

    /// Die temperature on the model's scale for an OUT_TEMP reading, °C.
    pub fn temp_c_from_raw(&self, raw: i8) -> f64 {
        self.temp_c_from_raw_mean(f64::from(raw))
    }

    /// Die temperature on the model's scale for a mean of OUT_TEMP readings, °C.
    pub fn temp_c_from_raw_mean(&self, raw_mean: f64) -> f64 {
        self.out_temp_at_0c - raw_mean
    }

    /// Refuses a temperature outside the calibrated range: never extrapolated.
    pub fn check_range(&self, temp_c: f64) -> Result<(), ThermalError> {
        if temp_c.is_finite() && (self.range_c[0]..=self.range_c[1]).contains(&temp_c) {
            Ok(())
        } else {
            Err(ThermalError::OutOfRange { temp_c, range_c: self.range_c })
        }
    }

    /// The quantity's curve for an axis.
    pub fn curve(&self, axis: usize, quantity: Quantity) -> &Curve {
        let i = Quantity::all().position(|q| q == (axis, quantity)).expect("every (axis, quantity) has a curve");
        &self.curves[i]
    }

    /// Each curve's value at `temp_c` (inside the range).
    pub fn values_at(&self, temp_c: f64) -> Result<Vec<Estimate>, ThermalError> {
        self.check_range(temp_c)?;
        Ok(self.curves.iter().map(|c| c.at(self.reference_c, temp_c)).collect())
    }

    /// The calibration at `temp_c` (inside the range).
    pub fn calibration_at(&self, temp_c: f64) -> Result<Calibration, ThermalError> {
        let values: Vec<f64> = self.values_at(temp_c)?.iter().map(|e| e.value).collect();
        let (m, offset) = super::m_and_offset(&values);
        Calibration::new(format!("thermal model at {temp_c:.2} °C"), self.full_scale, m, offset)
            .map_err(|_| ThermalError::Singular { temp_c })
    }

    /// Rate vector (°/s) for a reading (counts; a register reads whole ones) at `temp_c`, with
    /// each component's σ from the curves' σ at that temperature (first order; the curves taken
    /// as independent).
    pub fn rate_at(&self, raw: [f64; 3], temp_c: f64) -> Result<([f64; 3], [f64; 3]), ThermalError> {
        self.rate_at_reading(raw, temp_c, 0.0)
    }

    /// [`Self::rate_at`] for a temperature known to `temp_sigma_c` (OUT_TEMP's rounding: the
    /// model's own `temp_sigma_c`), which widens each curve by its slope.
    pub fn rate_at_reading(
        &self,
        raw: [f64; 3],
        temp_c: f64,
        temp_sigma_c: f64,
    ) -> Result<([f64; 3], [f64; 3]), ThermalError> {
        let est = self.values_at(temp_c)?;
        let x: Vec<f64> = est.iter().map(|e| e.value).collect();
        let var = est.iter().zip(&self.curves).map(|(e, c)| {
            let widen = c.slope_at(self.reference_c, temp_c) * temp_sigma_c;
            e.sigma * e.sigma + widen * widen
        });
        let cov = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(x.len(), var));
        let f = |p: &[f64]| super::rate_from_values(p, raw).to_vec();
        let (rate, var) = crate::calib::result::derived::delta_method(f, &x, &cov);
        Ok(([rate[0], rate[1], rate[2]], [0, 1, 2].map(|i| var[(i, i)].max(0.0).sqrt())))
    }
}

/// One curve: the order chosen (or given), the fit, each setpoint beside it.
fn curve(
    axis: usize,
    quantity: Quantity,
    points: &[Point],
    summaries: &[SetpointSummary],
    order: Option<usize>,
) -> Result<Curve, ThermalError> {
    let label = || format!("{} {}", crate::calib::result::axes::AXES[axis], quantity.label());
    let choice = poly::choose_order(points).ok_or(ThermalError::TooFewSetpoints { found: points.len() })?;
    // A given order (a refit without one setpoint keeps the full model's) needs only its
    // coefficients' worth of points; a chosen one keeps a held-out degree of freedom.
    let order = order.map_or(choice.order, |o| o.min(points.len() - 1));
    let fit = poly::fit(points, order).map_err(|e| ThermalError::Fit { curve: label(), reason: e.to_string() })?;
    let held = poly::held_out(points, order).ok_or(ThermalError::TooFewSetpoints { found: points.len() })?;
    let dof = points.len() - (order + 1);
    let scale_factor = if dof > 0 { (fit.chi2 / dof as f64).sqrt().max(1.0) } else { 1.0 };
    let cov = &fit.cov * (scale_factor * scale_factor);
    let scaled = PolyFit { cov: cov.clone(), ..fit.clone() };
    let points_out = points
        .iter()
        .zip(summaries)
        .zip(held)
        .enumerate()
        .map(|(j, ((p, s), held_out))| {
            let model = Estimate::from_variance(poly::eval(&fit.coef, p.x), poly::value_variance(&scaled, p.x));
            CurvePoint {
                die_c: s.die_c,
                measured: Estimate { value: p.y, sigma: p.sigma_y },
                model,
                z: (p.y - model.value) / fit.sigma_eff[j],
                held_out,
            }
        })
        .collect();
    Ok(Curve {
        axis: crate::calib::result::axes::AXES[axis],
        quantity,
        order,
        press: choice.press,
        coef: (0..=order).map(|d| Estimate::from_variance(fit.coef[d], cov[(d, d)])).collect(),
        cov: (0..=order).map(|r| (0..=order).map(|c| cov[(r, c)]).collect()).collect(),
        chi2: fit.chi2,
        dof,
        scale_factor,
        points: points_out,
    })
}
