//! An error of the base encoder's angle once (eccentric scale) or twice (elliptical scale) a
//! turn.

use super::terms::{
    along_gradient, shift_vector, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Needs, Own, Point,
    Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// Largest encoder error either parameter may take, rad: 0.5°, a scale 0.3 mm off the axis of a
/// 35-mm shaft; a larger "error" is not the encoder's (engineering judgement).
const MAX_ECCENTRICITY_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// Plausible size of either parameter, arcsec (the reported unit): 36″ = 0.01°, the angle a
/// scale 5 µm off its shaft's axis makes at a code radius of 30 mm (5e-6 / 0.03 rad), a
/// modular encoder's usual mounting tolerance (engineering judgement).
const PLAUSIBLE_ERROR_ARCSEC: f64 = 36.0;

/// The base encoder's scale off its shaft's axis (order 1), or out of round (order 2): it reads
/// θ1 + δ(θ1), δ = a·sin nθ1 − b·(cos nθ1 − 1) with θ1 counted from θ2 = 0 (the index, less any
/// index offset, which fixes δ there), so the base angle and rate the kinematics take from it
/// are off by δ and by θ1'·δ'(θ1), and θ2, geared to the base, by δ. The sensor table itself
/// turns evenly. The encoder does not move between poses: one pair (a, b), rad, for every run.
///
/// Twice a turn the error ripples θ1' at 2×, which times the in-plane sinusoid makes a 1× part
/// (M takes it up) and a 3× line (which separates it at any speed). Unmodelled, 0.01° and 0.03°
/// of it were flagged on every seed of the default design on the simulator, 8.6-52σ off had
/// they been believed.
///
/// An angle error of θ2 alone is a sensor-table eccentricity ([`super::table_harmonic`] at 1×),
/// which ripples θ2' with it. The encoder's error also ripples θ1', which multiplies the
/// in-plane sinusoid every axis sees: at 1× of a 1:1 gear that puts a constant and a 2× line
/// into the in-plane rate. The constant, θ1'·δ'·(sin θ2, cos θ2) averaged, is a fixed rate in
/// the table plane in proportion to speed, which M takes up as a turn of every direction: on
/// the simulator 0.01° of eccentricity left the directions 0.011° off at exit 0 (18σ), 0.05°
/// 0.07° off (89σ), with the table's eccentricity and a pose fixture fitted in its place.
pub struct EncoderError(pub u8);

impl EncoderError {
    /// The catalogue's name for this order.
    fn effect(&self) -> Effect {
        if self.0 == 1 {
            Effect::EncoderEccentricity
        } else {
            Effect::EncoderEllipticity
        }
    }
}

impl Behaviour for EncoderError {
    fn name(&self) -> String {
        match self.0 {
            1 => "base-encoder eccentricity (angle error at 1× of θ1)".into(),
            n => format!("base-encoder ellipticity (angle error at {n}× of θ1)"),
        }
    }

    fn key(&self) -> String {
        match self.0 {
            1 => "encoder_eccentricity".into(),
            _ => "encoder_ellipticity".into(),
        }
    }

    fn meaning(&self) -> &'static str {
        if self.0 == 1 {
            "the base encoder's scale sits off its shaft's axis, so the base angle it reads is off once a turn and the rate it reads ripples with it, while the tables turn evenly; θ2, geared to the base, inherits the angle error"
        } else {
            "the base encoder's scale is out of round, so the base angle it reads is off twice a turn and the rate it reads ripples with it, while the tables turn evenly; θ2, geared to the base, inherits the angle error"
        }
    }

    fn identified_by(&self) -> &'static str {
        if self.0 == 1 {
            "the ripple it puts on θ1' beside the angle error: a constant and a 2× line in the in-plane rate that a sensor-table eccentricity does not make, with one phase for every pose"
        } else {
            "the ripple it puts on θ1' beside the angle error: a 3× line in the in-plane rate that a sensor-table harmonic at 2× does not make, with one phase for every pose"
        }
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![], (0..2).map(|k| SharedPar { effect: self.effect(), k }).collect())
    }

    fn reported(&self, own: Own, _: f64) -> Option<Reported> {
        let Own::Shared(k) = own else { return None };
        let part = if k == 0 { "sin" } else { "cos" };
        Some(Reported::new(
            format!("base-encoder angle error {}× {part}", self.0),
            180.0 / std::f64::consts::PI * 3600.0,
            "arcsec",
        ))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        Some(Bound { lo: -MAX_ECCENTRICITY_RAD, hi: MAX_ECCENTRICITY_RAD, what: "encoder eccentricity", unit: "rad" })
    }

    fn shift(&self, k: u8, value: f64, s: &mut Shifts) {
        s.encoder_rad[usize::from(self.0) - 1][usize::from(k)] = value;
    }

    /// θ2 moves by −ratio·∂δ/∂(a, b), as a shift of the index-referenced angle does
    /// (`t.d_shift`); θ1' by −θ1'_read·∂δ'/∂(a, b), which the output follows as
    /// [`AxisTerms::per_theta1_rate`]. δ is taken at the angle the encoder read, as the chain
    /// takes it ([`Point::encoder_read`]): at the corrected angle the two terms, which nearly
    /// cancel (450 and 360 counts/rad for a sum of 93 on the trust bench's rig), would be 1e-5
    /// rad, 3.5e-4 of their sum, off.
    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        along_gradient(t, self.gradient_factor(own, p, cx))
    }

    fn gradient_factor(&self, own: Own, p: &Point, _: &Ctx) -> Option<[f64; 3]> {
        let Own::Shared(k) = own else { return None };
        if p.theta1_rate_dps == 0.0 {
            return Some([0.0; 3]);
        }
        let ratio = p.rate2_dps / p.theta1_rate_dps;
        let read = &p.encoder_read;
        // The output follows θ1' as u·ω_s/θ1' (AxisTerms::per_theta1_rate).
        let along_rate = read.rate_dps / p.theta1_rate_dps;
        let n = f64::from(self.0);
        let (s, c) = read.sin_cos[usize::from(self.0) - 1];
        let (on_shift, on_rate) =
            if k == 0 { (-ratio * s, -along_rate * n * c) } else { (-ratio * (1.0 - c), -along_rate * n * s) };
        let shift = shift_vector(p);
        Some(std::array::from_fn(|i| on_shift * shift[i] + on_rate * p.omega[i]))
    }

    fn needs(&self, _: Own) -> Needs {
        Needs { encoder: true, ..Needs::NONE }
    }

    /// Its 2× line (3× for order 2) separates it at any speed or direction, but only as far as
    /// the runs are long: on 20-s runs in both directions 0.01° of eccentricity passed every
    /// test and left M 4.3σ off at exit 0 (the trust bench, `180,-180@20`, seed 44). So where
    /// the test cannot see a plausible size, that size is carried in σ
    /// ([`crate::calib::analysis::consider`]); on the default design's 120-s runs it sees it.
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        (!cx.has(self.effect())).then_some(ConsiderBound {
            sigma: PLAUSIBLE_ERROR_ARCSEC,
            source: "a modular encoder's scale mounted 5 µm off a shaft of 30-mm code radius (or as far out of round), engineering judgement",
        })
    }

    /// When the residual shows structure at 1× or at the ripple's line (2×, or 3× for order 2).
    /// The angle error at n× of θ1 ripples the in-plane sinusoid into lines at (n ± 1)×.
    fn turn_multiple(&self) -> u32 {
        u32::from(self.0) + 1
    }

    fn candidate(&self, s: &Situation) -> bool {
        let line = usize::from(self.0) + 1;
        (s.evidence.orders[1] || s.evidence.orders[line]) && !s.has(self.effect())
    }
}

/// The base encoder's angle error at the angle `theta1_rad` it read, δ = Σ a·sin nθ1 −
/// b·(cos nθ1 − 1) over its orders n = 1, 2 (`orders[n − 1]` = (a, b), rad;
/// [`crate::calib::effects::terms::Shifts::encoder_rad`]), and its slope dδ/dθ1.
#[inline]
pub fn encoder_error(orders: [[f64; 2]; 2], theta1_rad: f64) -> (f64, f64) {
    let (mut d, mut slope) = (0.0, 0.0);
    for (n, [a, b]) in (1..).zip(orders) {
        if a == 0.0 && b == 0.0 {
            continue;
        }
        let (s, c) = (f64::from(n) * theta1_rad).sin_cos();
        d += a * s - b * (c - 1.0);
        slope += f64::from(n) * (a * c + b * s);
    }
    (d, slope)
}
