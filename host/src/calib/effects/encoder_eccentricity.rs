//! A once-per-turn error of the base encoder's angle.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout};

/// Largest encoder error either parameter may take, rad: 0.5°, a scale 0.3 mm off the axis of a
/// 35-mm shaft; a larger "error" is not the encoder's (engineering judgement).
const MAX_ECCENTRICITY_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// The base encoder's scale off its shaft's axis (or its lines unevenly spaced once a turn): it
/// reads θ1 + δ(θ1), δ = a·sin θ1 − b·(cos θ1 − 1) with θ1 counted from θ2 = 0 (the index, less
/// any index offset, which fixes δ there), so the base angle and rate the kinematics take from it are off by δ and
/// by θ1'·δ'(θ1), and θ2, geared to the base, by δ. The sensor table itself turns evenly. The
/// encoder does not move between poses: one pair (a, b), rad, for every run.
///
/// An angle error of θ2 alone is a sensor-table eccentricity ([`super::table_harmonic`] at 1×),
/// which ripples θ2' with it. The encoder's error also ripples θ1', which multiplies the
/// in-plane sinusoid every axis sees: at 1× of a 1:1 gear that puts a constant and a 2× line
/// into the in-plane rate. The constant, θ1'·δ'·(sin θ2, cos θ2) averaged, is a fixed rate in
/// the table plane in proportion to speed, which M takes up as a turn of every direction: on
/// the simulator 0.01° of eccentricity left the directions 0.011° off at exit 0 (18σ), 0.05°
/// 0.07° off (89σ), with the table's eccentricity and a pose fixture fitted in its place.
pub struct EncoderEccentricity;

impl Behaviour for EncoderEccentricity {
    fn name(&self) -> String {
        "base-encoder eccentricity (angle error at 1× of θ1)".into()
    }

    fn key(&self) -> String {
        "encoder_eccentricity".into()
    }

    fn meaning(&self) -> &'static str {
        "the base encoder's scale sits off its shaft's axis, so the base angle it reads is off once a turn and the rate it reads ripples with it, while the tables turn evenly; θ2, geared to the base, inherits the angle error"
    }

    fn identified_by(&self) -> &'static str {
        "the ripple it puts on θ1' beside the angle error: a constant and a 2× line in the in-plane rate that a sensor-table eccentricity does not make, with one phase for every pose"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, _: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        (vec![], (0..2).map(|k| SharedPar { effect: Effect::EncoderEccentricity, k }).collect())
    }

    fn reported(&self, own: Own, _: f64) -> Option<Reported> {
        let Own::Shared(k) = own else { return None };
        let part = if k == 0 { "sin" } else { "cos" };
        Some(Reported::new(
            format!("base-encoder angle error 1× {part}"),
            180.0 / std::f64::consts::PI * 3600.0,
            "arcsec",
        ))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        Some(Bound { lo: -MAX_ECCENTRICITY_RAD, hi: MAX_ECCENTRICITY_RAD, what: "encoder eccentricity", unit: "rad" })
    }

    fn shift(&self, k: u8, value: f64, s: &mut Shifts) {
        s.encoder_rad[usize::from(k)] = value;
    }

    /// θ2 moves by −ratio·∂δ/∂(a, b), as a shift of the index-referenced angle does
    /// (`t.d_shift`); θ1' by −θ1'_read·∂δ'/∂(a, b), which the output follows as
    /// [`AxisTerms::per_theta1_rate`]. δ is taken at
    /// the angle the encoder read, as the chain takes it: the point holds the corrected angle, and
    /// the two terms nearly cancel (450 and 360 counts/rad for a sum of 93 on the trust bench's
    /// rig), so the 1e-5 rad between the angles was 3.5e-4 of the sum.
    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        let Own::Shared(k) = own else { return 0.0 };
        if p.theta1_rate_dps == 0.0 {
            return 0.0;
        }
        let ratio = p.rate2_dps / p.theta1_rate_dps;
        let [a, b] = cx.shifts.encoder_rad;
        // The angle read, from the corrected one: δ at the corrected angle is O(δ²) off.
        let (s0, c0) = (p.theta2_rad / ratio).sin_cos();
        let (s, c) = (p.theta2_rad / ratio + a * s0 - b * (c0 - 1.0)).sin_cos();
        let rate_read_dps = p.theta1_rate_dps / (1.0 - (a * c + b * s));
        let along_rate = t.per_theta1_rate(p) * rate_read_dps;
        if k == 0 {
            -t.d_shift * ratio * s - along_rate * c
        } else {
            -t.d_shift * ratio * (1.0 - c) - along_rate * s
        }
    }

    /// None: its 2× line separates it at any speed or direction, so no design leaves it to a
    /// bound.
    fn consider(&self, _: Own, _: &ConsiderCtx) -> Option<ConsiderBound> {
        None
    }

    /// When the residual shows structure at 1× or 2× of the table.
    fn candidate(&self, s: &Situation) -> bool {
        (s.evidence.orders[1] || s.evidence.orders[2]) && !s.has(Effect::EncoderEccentricity)
    }
}
