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
    /// σ added to every setpoint's value, independently, for what moves between sessions
    /// beyond their own σ (a gyro's bias instability), estimated over the curves of its kind
    /// (Paule-Mandel, `model::between_session_sigma`); 0 when they scatter no more than their σ.
    #[serde(default)]
    pub between_sigma: f64,
    /// The coefficients' response to the part of the setpoints' σ common to all of them, per
    /// unit of it (`poly::PolyFit::common_response`): their covariance with another
    /// calibration of the same rig.
    #[serde(default)]
    pub common_response: Vec<f64>,
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

    /// The curve's covariance at `temp_c` with a value whose σ shares `common_sigma` with the
    /// setpoints' common part (another session on the same rig).
    pub fn common_covariance(&self, reference_c: f64, temp_c: f64, common_sigma: f64) -> f64 {
        let a = poly::powers(temp_c - reference_c, self.order);
        self.common_response.iter().zip(a.iter()).map(|(g, x)| g * x).sum::<f64>() * common_sigma
    }

    /// The curve's slope at `temp_c`, per °C.
    pub fn slope_at(&self, reference_c: f64, temp_c: f64) -> f64 {
        let coef: Vec<f64> = self.coef.iter().map(|c| c.value).collect();
        poly::slope(&coef, temp_c - reference_c)
    }

    /// The curve's slope at `temp_c`, per °C, with its σ from the coefficients' covariance.
    pub fn slope_estimate_at(&self, reference_c: f64, temp_c: f64) -> Estimate {
        let x = temp_c - reference_c;
        let g = nalgebra::DVector::from_fn(
            self.order + 1,
            |d, _| if d == 0 { 0.0 } else { d as f64 * x.powi(d as i32 - 1) },
        );
        let cov = DMatrix::from_fn(self.order + 1, self.order + 1, |r, c| self.cov[r][c]);
        Estimate::from_variance(self.slope_at(reference_c, temp_c), (g.transpose() * cov * &g)[(0, 0)])
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
    /// Setpoints left out of the fit because their own calibration did not reach the noise
    /// floor ([`SetpointCal::at_noise_floor`], rule in [`split_by_noise_floor`]); their die
    /// temperature on the model's scale. The range is the fitted setpoints'.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub excluded: Vec<SetpointSummary>,
    /// Setpoints in the fit although their calibration did not reach the noise floor: left
    /// out, fewer than [`super::MIN_SETPOINTS`] would remain. Such a model is not to be trusted.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub not_at_floor_in_fit: Vec<f64>,
}

/// The setpoints the model is fitted to, those left out, and those fitted though not at the
/// noise floor. Rule: a setpoint whose own calibration left structure above the noise floor
/// (its loop's verdict, exit 3: "must not be trusted") is left out of the fit, while at least
/// [`super::MIN_SETPOINTS`] at the floor remain; otherwise every setpoint is fitted and the
/// model says it rests on them. Not a σ inflated by the residual's RMS over the floor (a Birge
/// ratio, Birge 1932, Phys. Rev. 40, 207): that ratio scales σ for a scatter the σ did not
/// hold, assuming the values right on average, whereas structure no modelled effect explains
/// biases the values by an amount the residual's size does not give (seed 6's −20 °C setpoint
/// of the thermal bench: 49σ off in an offset, docs/thermal.md).
pub fn split_by_noise_floor<'a>(sp: &[&'a SetpointCal]) -> (Vec<&'a SetpointCal>, Vec<&'a SetpointCal>, Vec<f64>) {
    let (at, off): (Vec<&SetpointCal>, Vec<&SetpointCal>) = sp.iter().partition(|s| s.at_noise_floor);
    if at.len() >= super::MIN_SETPOINTS {
        (at, off, Vec::new())
    } else {
        (sp.to_vec(), Vec::new(), off.iter().map(|s| s.setpoint_c).collect())
    }
}

impl ThermalModel {
    /// Fits every quantity of every axis over the setpoints, each at the order its data support.
    pub fn fit(setpoints: &[SetpointCal]) -> Result<Self, ThermalError> {
        Self::fit_with(setpoints, None)
    }

    /// Fits with the orders of `orders` (curve by curve), or chosen from the data when `None`.
    pub fn fit_with(setpoints: &[SetpointCal], orders: Option<&[usize]>) -> Result<Self, ThermalError> {
        let mut all: Vec<&SetpointCal> = setpoints.iter().collect();
        all.sort_by(|a, b| a.setpoint_c.total_cmp(&b.setpoint_c));
        let full_scale = super::check_setpoints(&all)?;
        let (sp, left_out, not_at_floor_in_fit) = split_by_noise_floor(&all);
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
        let measured: Vec<Vec<Measured>> = Quantity::all()
            .map(|(axis, q)| {
                sp.iter()
                    .zip(&summaries)
                    .map(|(s, sum)| Measured {
                        x: sum.die_c - REFERENCE_C,
                        value: s.value(axis, q),
                        common: s.common(axis, q),
                    })
                    .collect()
            })
            .collect();
        let (orders, between) = orders_and_between(&measured, orders)?;
        let mut curves = Vec::with_capacity(12);
        for (c, (axis, quantity)) in Quantity::all().enumerate() {
            let b = between[kind(quantity)];
            let points = points_of(&measured[c], b);
            let values: Vec<Estimate> = measured[c].iter().map(|m| m.value).collect();
            curves.push(curve(axis, quantity, &points, &values, &summaries, orders[c], b)?);
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
            excluded: left_out
                .iter()
                .map(|s| SetpointSummary {
                    setpoint_c: s.setpoint_c,
                    out_temp_mean_lsb: s.out_temp_mean_lsb,
                    die_c: out_temp_at_0c - s.out_temp_mean_lsb,
                })
                .collect(),
            not_at_floor_in_fit,
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

/// One curve at its order: the fit, each setpoint (its own `measured` value) beside it.
fn curve(
    axis: usize,
    quantity: Quantity,
    points: &[Point],
    measured: &[Estimate],
    summaries: &[SetpointSummary],
    order: usize,
    between_sigma: f64,
) -> Result<Curve, ThermalError> {
    let label = || format!("{} {}", crate::calib::result::axes::AXES[axis], quantity.label());
    let choice = poly::choose_order(points).ok_or(ThermalError::TooFewSetpoints { found: points.len() })?;
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
            let own = measured[j];
            let model = Estimate::from_variance(poly::eval(&fit.coef, p.x), poly::value_variance(&scaled, p.x));
            CurvePoint { die_c: s.die_c, measured: own, model, z: (p.y - model.value) / fit.sigma_eff[j], held_out }
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
        between_sigma,
        common_response: fit.common_response.iter().copied().collect(),
        points: points_out,
    })
}

/// One setpoint's value of one quantity as the fit takes it.
struct Measured {
    /// Die temperature from the reference, °C.
    x: f64,
    /// Its calibration's value and σ.
    value: Estimate,
    /// The part of that σ common to every setpoint.
    common: f64,
}

/// Quantities that share one between-session σ: offsets (counts), sensitivities (counts per
/// °/s), direction components (unit vector); the same physics moves each kind on every axis.
fn kind(q: Quantity) -> usize {
    match q {
        Quantity::OffsetCounts => 0,
        Quantity::SensitivityCountsPerDps => 1,
        Quantity::DirectionNext | Quantity::DirectionOther => 2,
    }
}

/// The points of one curve: independent σ (its calibration's, less the common part, plus the
/// between-session σ `between`), the common part kept apart.
fn points_of(measured: &[Measured], between: f64) -> Vec<Point> {
    measured
        .iter()
        .map(|m| Point {
            x: m.x,
            sigma_x: TEMP_SIGMA_C,
            y: m.value.value,
            sigma_y: ((m.value.sigma.powi(2) - m.common.powi(2)).max(0.0) + between * between).sqrt(),
            sigma_common: m.common,
        })
        .collect()
}

/// Rounds of choosing the orders and estimating the between-session σ for them: each round's
/// σ changes the held-out misses the orders are chosen by; they settle in two or three.
const BETWEEN_ROUNDS: usize = 4;

/// The curves' orders (given, or chosen by weighted PRESS) and the between-session σ of each
/// kind of quantity, estimated for those orders and chosen with them.
fn orders_and_between(
    measured: &[Vec<Measured>],
    given: Option<&[usize]>,
) -> Result<(Vec<usize>, [f64; 3]), ThermalError> {
    let kinds: Vec<usize> = Quantity::all().map(|(_, q)| kind(q)).collect();
    let mut between = [0.0; 3];
    let mut orders = vec![0; measured.len()];
    for _ in 0..BETWEEN_ROUNDS {
        for (c, m) in measured.iter().enumerate() {
            // A given order (a refit without one setpoint keeps the full model's) needs only its
            // coefficients' worth of points; a chosen one keeps a held-out degree of freedom.
            orders[c] = match given.and_then(|o| o.get(c).copied()) {
                Some(o) => o.min(m.len() - 1),
                None => {
                    let points = points_of(m, between[kinds[c]]);
                    poly::choose_order(&points).ok_or(ThermalError::TooFewSetpoints { found: m.len() })?.order
                }
            };
        }
        let next = [0, 1, 2].map(|k| {
            let curves: Vec<(&[Measured], usize)> =
                (0..measured.len()).filter(|&c| kinds[c] == k).map(|c| (measured[c].as_slice(), orders[c])).collect();
            between_session_sigma(&curves)
        });
        if next == between {
            break;
        }
        between = next;
    }
    Ok((orders, between))
}

/// Bisection steps of [`between_session_sigma`]: the bracket shrinks by 2⁻⁶⁰, to the double's
/// resolution.
const BISECTION_STEPS: usize = 60;

/// The σ to add, independently, to every point of some curves (each at its order) so that their
/// χ² sum to their degrees of freedom: the Paule-Mandel estimator of the between-study variance
/// (Paule & Mandel 1982, J. Res. NBS 87, 377; its generalised Q statistic set to its expectation,
/// DerSimonian & Kacker 2007, Contemp. Clin. Trials 28, 105), here between the sessions of the
/// setpoints. 0 when the points scatter no more than their σ. Pooled over the axes: one
/// curve's two or three degrees of freedom say little of it alone.
fn between_session_sigma(curves: &[(&[Measured], usize)]) -> f64 {
    let dof: usize = curves.iter().map(|(m, o)| m.len().saturating_sub(o + 1)).sum();
    let q = |b: f64| -> Option<f64> {
        curves.iter().map(|(m, o)| poly::fit(&points_of(m, b), *o).ok().map(|f| f.chi2)).sum()
    };
    if dof == 0 || q(0.0).is_none_or(|c| c <= dof as f64) {
        return 0.0;
    }
    let mut hi = curves.iter().flat_map(|(m, _)| m.iter().map(|p| p.value.sigma)).fold(0.0, f64::max);
    if hi <= 0.0 || hi.is_nan() {
        return 0.0;
    }
    let mut lo = 0.0;
    while q(hi).is_some_and(|c| c > dof as f64) && hi.is_finite() {
        lo = hi;
        hi *= 2.0;
    }
    for _ in 0..BISECTION_STEPS {
        let mid = 0.5 * (lo + hi);
        match q(mid) {
            Some(c) if c > dof as f64 => lo = mid,
            _ => hi = mid,
        }
    }
    hi
}
