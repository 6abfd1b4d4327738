//! Kinematics of the tables: the motor's speed profile, the encoder and the index plate.
//!
//! Simulated time `t_s` is the rig's microsecond timer (seconds since power-up); every other
//! clock is expressed against it. θ1 is the base-table angle (θ1 = 0 at power-up, positive
//! counter-clockwise, the encoder counting up); θ2 = ratio·θ1 + θ2₀ is the sensor table's angle
//! relative to the base, defined as 0 at the centre of the shield plate when the plate is
//! mounted as designed (the `index_offset` effect moves the plate, not the definition).

use super::effects::SpeedRipple;
use protocol::Edge;
use std::f64::consts::TAU;

/// One setpoint change: a linear ramp from `rate0_dps` to `target_dps` over `ramp_s`, then
/// constant speed. The speed loop is taken to track the ramp (the RE 30's mechanical time
/// constant, 3 ms in the maxon catalogue, is negligible next to a 1-2 s ramp).
#[derive(Debug, Clone, Copy)]
struct Segment {
    t0_s: f64,
    theta0_deg: f64,
    rate0_dps: f64,
    target_dps: f64,
    ramp_s: f64,
}

impl Segment {
    fn accel_dps2(&self) -> f64 {
        if self.ramp_s > 0.0 {
            (self.target_dps - self.rate0_dps) / self.ramp_s
        } else {
            0.0
        }
    }

    /// Nominal (ripple-free) angle and rate at `t_s` ≥ `t0_s`.
    fn at(&self, t_s: f64) -> (f64, f64) {
        let dt = t_s - self.t0_s;
        let a = self.accel_dps2();
        if dt < self.ramp_s {
            (self.theta0_deg + self.rate0_dps * dt + 0.5 * a * dt * dt, self.rate0_dps + a * dt)
        } else {
            let r = self.ramp_s;
            let theta_end = self.theta0_deg + self.rate0_dps * r + 0.5 * a * r * r;
            (theta_end + self.target_dps * (dt - r), self.target_dps)
        }
    }
}

/// Base-table angle and rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaseState {
    /// θ1, degrees (continuous, unwrapped).
    pub theta1_deg: f64,
    /// θ1', °/s.
    pub theta1_rate_dps: f64,
    /// Ramp setpoint (ripple-free), °/s.
    pub setpoint_dps: f64,
}

/// The motor's history of setpoints, with optional speed ripple.
#[derive(Debug, Clone)]
pub struct Motor {
    segments: Vec<Segment>,
    ripple: Option<SpeedRipple>,
}

impl Motor {
    /// A motor at rest at θ1 = 0 from t = 0.
    pub fn new(ripple: Option<SpeedRipple>) -> Self {
        Self {
            segments: vec![Segment { t0_s: 0.0, theta0_deg: 0.0, rate0_dps: 0.0, target_dps: 0.0, ramp_s: 0.0 }],
            ripple,
        }
    }

    /// Starts a ramp to `target_dps` at `t_s`, lasting `ramp_s`, from the current speed.
    /// `t_s` must not precede the previous setpoint change.
    pub fn set_target(&mut self, t_s: f64, target_dps: f64, ramp_s: f64) {
        let last = self.segments.last().expect("never empty");
        assert!(t_s >= last.t0_s, "setpoint changes must be in time order");
        let (theta0_deg, rate0_dps) = last.at(t_s);
        self.segments.push(Segment { t0_s: t_s, theta0_deg, rate0_dps, target_dps, ramp_s });
    }

    /// State at `t_s` (any time ≥ 0; before 0 the table was at rest).
    pub fn state(&self, t_s: f64) -> BaseState {
        // Evaluations are almost always in the newest segment: search from the end.
        let seg = self.segments.iter().rev().find(|s| s.t0_s <= t_s).unwrap_or(&self.segments[0]);
        let (theta_nom_deg, rate_nom_dps) = seg.at(t_s.max(seg.t0_s));
        let rate_nom_dps = if t_s < seg.t0_s { 0.0 } else { rate_nom_dps };
        let (mut theta1_deg, mut theta1_rate_dps) = (theta_nom_deg, rate_nom_dps);
        if let Some(r) = &self.ripple {
            // θ1 = θn + Σ (a/h)·sin(h·θn + φ) makes θ1' = θn'·(1 + Σ a·cos(h·θn + φ)) exactly.
            let th = theta_nom_deg.to_radians();
            let (mut dtheta_rad, mut drate) = (0.0, 0.0);
            for h in &r.harmonics {
                let n = f64::from(h.order.max(1));
                let (s, c) = (n * th + h.phase_rad).sin_cos();
                dtheta_rad += h.amplitude / n * s;
                drate += h.amplitude * c;
            }
            theta1_deg += dtheta_rad.to_degrees();
            theta1_rate_dps *= 1.0 + drate;
        }
        BaseState { theta1_deg, theta1_rate_dps, setpoint_dps: rate_nom_dps }
    }

    /// θ1 only, degrees.
    pub fn theta1_deg(&self, t_s: f64) -> f64 {
        self.state(t_s).theta1_deg
    }
}

/// The quadrature encoder on the base table.
#[derive(Debug, Clone, Copy)]
pub struct Encoder {
    /// Counts per revolution after x4 decoding.
    pub counts_per_rev: u32,
    /// Counter value at θ1 = 0.
    pub start_counts: u32,
    /// Its scale's errors, if any: eccentric (once a turn), elliptical (twice).
    pub errors: [Option<super::effects::EncoderEccentricity>; 2],
}

impl Encoder {
    /// Unwrapped count at `theta1_deg` (the counter changes on each quadrature edge, so the count
    /// is the floor of the angle in counts).
    pub fn counts(&self, theta1_deg: f64) -> i64 {
        let read_deg = theta1_deg + self.errors.iter().flatten().map(|e| e.error_deg(theta1_deg)).sum::<f64>();
        protocol::units::counts_from_deg(read_deg, self.counts_per_rev).floor() as i64
    }

    /// The register value: unwrapped count plus the start value, modulo 2³².
    pub fn register(&self, theta1_deg: f64) -> u32 {
        (i64::from(self.start_counts) + self.counts(theta1_deg)) as u32
    }
}

/// The shield plate on the base seen by the photo-interrupter on the sensor table: blocked (1)
/// while θ2 is within ±width/2 of the plate centre (mod 360°).
#[derive(Debug, Clone, Copy)]
pub struct IndexPlate {
    /// θ2 at the plate centre, rad (0 unless the `index_offset` effect is on).
    pub centre_rad: f64,
    /// Angular width of the plate, rad.
    pub width_rad: f64,
}

/// One index edge found in an interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeCrossing {
    /// Time of the edge, s.
    pub t_s: f64,
    /// Which edge.
    pub edge: Edge,
}

impl IndexPlate {
    /// Edges in `(t_a, t_b]`, in time order, appended to `out`. `theta2` gives θ2 (rad) at a
    /// time and must be monotonic over the interval (true between two gyro samples).
    pub fn crossings(
        &self,
        t_a: f64,
        t_b: f64,
        theta2_a: f64,
        theta2_b: f64,
        theta2: impl Fn(f64) -> f64,
        out: &mut Vec<EdgeCrossing>,
    ) {
        if theta2_a == theta2_b {
            return;
        }
        let first = out.len();
        let increasing = theta2_b > theta2_a;
        let (lo, hi) = if increasing { (theta2_a, theta2_b) } else { (theta2_b, theta2_a) };
        for (base, is_leading) in
            [(self.centre_rad - 0.5 * self.width_rad, true), (self.centre_rad + 0.5 * self.width_rad, false)]
        {
            // A boundary b is crossed when θ2 ≥ b changes truth value over the interval.
            let n_lo = ((lo - base) / TAU).floor() as i64;
            let n_hi = ((hi - base) / TAU).ceil() as i64;
            for n in n_lo..=n_hi {
                let b = base + n as f64 * TAU;
                if (theta2_a >= b) == (theta2_b >= b) {
                    continue;
                }
                let t_s = bisect(t_a, t_b, |t| theta2(t) >= b, increasing);
                // Entering the plate is the rising edge: the leading boundary going up, the
                // trailing one going down.
                let edge = if is_leading == increasing { Edge::Rising } else { Edge::Falling };
                out.push(EdgeCrossing { t_s, edge });
            }
        }
        out[first..].sort_by(|x, y| x.t_s.total_cmp(&y.t_s));
    }
}

/// Time in `(a, b]` at which `above(t)` switches (to true if `rising`, else to false), to 1 ns.
/// A plain bisection: root-finding crates (`roots`, `argmin`) want a continuous function's sign
/// change, and this is a boolean predicate.
fn bisect(mut a: f64, mut b: f64, above: impl Fn(f64) -> bool, rising: bool) -> f64 {
    while b - a > 1e-9 {
        let m = 0.5 * (a + b);
        if above(m) == rising {
            b = m;
        } else {
            a = m;
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_then_constant_speed_integrates_exactly() {
        let mut m = Motor::new(None);
        m.set_target(1.0, 180.0, 1.5);
        let s = m.state(1.75);
        // 180 °/s over 1.5 s: 120 °/s².
        assert!((s.theta1_rate_dps - 90.0).abs() < 1e-12);
        assert!((s.theta1_deg - 0.5 * 120.0 * 0.75 * 0.75).abs() < 1e-9);
        // After the ramp: 135° covered during it, then 180 °/s.
        let s = m.state(4.5);
        assert!((s.theta1_deg - (135.0 + 180.0 * 2.0)).abs() < 1e-9);
        assert_eq!(s.theta1_rate_dps, 180.0);
        assert_eq!(m.state(0.5).theta1_deg, 0.0);
        // Stopping from full speed ramps down over the same time.
        m.set_target(10.0, 0.0, 1.5);
        let end = m.state(20.0);
        assert_eq!(end.theta1_rate_dps, 0.0);
        assert!((end.theta1_deg - (m.theta1_deg(10.0) + 135.0)).abs() < 1e-9);
    }

    #[test]
    fn ripple_rate_is_the_derivative_of_the_rippled_angle() {
        let mut m = Motor::new(Some(SpeedRipple::default()));
        m.set_target(0.0, 180.0, 1.0);
        for k in 0..200 {
            let t = 2.0 + k as f64 * 0.0137;
            let h = 1e-6;
            let d = (m.theta1_deg(t + h) - m.theta1_deg(t - h)) / (2.0 * h);
            let r = m.state(t).theta1_rate_dps;
            assert!((d - r).abs() < 1e-4, "t = {t}: {d} vs {r}");
        }
    }

    #[test]
    fn encoder_floors_and_wraps() {
        let e = Encoder { counts_per_rev: 324_000, start_counts: u32::MAX - 1, errors: [None; 2] };
        assert_eq!(e.counts(1.0), 900);
        assert_eq!(e.counts(-1e-9), -1);
        assert_eq!(e.register(0.0), u32::MAX - 1);
        assert_eq!(e.register(360.0 / 324_000.0 * 2.5), 0);
    }

    /// An eccentric scale's reading errs by its amplitude once a turn: 0.05° is 45 counts of
    /// 324 000 a turn, at its peak a quarter turn before the phase's zero.
    #[test]
    fn an_eccentric_encoder_errs_once_a_turn() {
        use crate::sim::effects::EncoderEccentricity;
        let ecc = EncoderEccentricity { amplitude_deg: 0.05, phase_rad: 0.0, order: 1 };
        let plain = Encoder { counts_per_rev: 324_000, start_counts: 0, errors: [None; 2] };
        let off = Encoder { errors: [Some(ecc), None], ..plain };
        for (theta1_deg, err_counts) in [(0.0, 0i64), (90.0, 45), (180.0, 0), (270.0, -45), (450.0, 45)] {
            // Within the count either reading floors to.
            let diff = off.counts(theta1_deg) - plain.counts(theta1_deg);
            assert!((diff - err_counts).abs() <= 1, "at {theta1_deg}°: {diff} counts");
        }
        // Elliptical: twice a turn, and the two add.
        let ell = EncoderEccentricity { order: 2, ..ecc };
        let both = Encoder { errors: [Some(ecc), Some(ell)], ..plain };
        for (theta1_deg, err_counts) in [(45.0, 32i64 + 45), (90.0, 45), (135.0, 32 - 45), (180.0, 0)] {
            let diff = both.counts(theta1_deg) - plain.counts(theta1_deg);
            assert!((diff - err_counts).abs() <= 1, "at {theta1_deg}°: {diff} counts");
        }
    }

    #[test]
    fn plate_edges_straddle_the_centre_in_both_directions() {
        let plate = IndexPlate { centre_rad: 0.3, width_rad: 4f64.to_radians() };
        for rate in [1.0, -1.0] {
            let th = |t: f64| rate * t;
            let mut out = Vec::new();
            let dt = 0.01;
            for k in 0..2000 {
                let (a, b) = (k as f64 * dt - 10.0, (k + 1) as f64 * dt - 10.0);
                plate.crossings(a, b, th(a), th(b), th, &mut out);
            }
            // 20 rad of travel: 3 or 4 plate passages, alternating rising/falling.
            assert!(out.len() >= 6 && out.len() % 2 == 0, "{out:?}");
            for w in out.windows(2) {
                assert_ne!(w[0].edge, w[1].edge);
            }
            let first_rising = out.iter().position(|e| e.edge == Edge::Rising).unwrap();
            let pair = &out[first_rising..first_rising + 2];
            let mid = th(0.5 * (pair[0].t_s + pair[1].t_s)).rem_euclid(TAU);
            assert!((mid - 0.3).abs() < 1e-8, "{mid}");
            // The pulse lasts the plate width.
            let width = (th(pair[1].t_s) - th(pair[0].t_s)).abs();
            assert!((width - 4f64.to_radians()).abs() < 1e-8, "{width}");
        }
    }
}
