//! A periodic angle error of the sensor table.

use super::terms::{
    along_gradient, AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, RunScope,
    SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout, MAX_HARMONIC_ORDER};
use crate::geometry::Pose;

/// Harmonics of the sensor-table rate in the catalogue: 1× (a once-per-turn eccentricity of the
/// sensor table's angle, as an angle error it is not the linear model's 1× term) up to
/// [`MAX_HARMONIC_ORDER`].
pub const HARMONIC_ORDERS: std::ops::RangeInclusive<u32> = 1..=MAX_HARMONIC_ORDER as u32;

/// Pole pairs passed per relative turn by the 12-pole magnetic gears (EXCITER.md).
pub const GEAR_POLE_PASS_ORDER: u32 = 12;

/// A periodic angle error of the sensor table at n× θ2 that encoder and index cannot see
/// (magnetic-gear pole pass, eccentricity), with its derivative in θ2': θ2' → θ2'(1 + a·cos nθ +
/// b·sin nθ) with the matching angle ripple, θ the gear mesh's angle; seen by every axis through
/// M R_qᵀ. The ripple is tied to the gear mesh, whose phase against the index holds while the
/// table stays engaged; a remount can re-seat it, so each pose has its own pair (a, b), relative
/// to θ2'.
///
/// The gyro's low-pass sees the line at n times the table's frequency, where the model's filter
/// (a delay and a gain curvature, exact at the table's own frequency) is only its first terms:
/// a 2nd-order Butterworth at 30 Hz turns a line at 16 Hz 3.2° past its group delay and damps
/// it by 3.8 %, at 8 Hz by 0.4° and 0.2 %. What each run's output shows of one pose's error
/// then differs with the run's speed and direction, and one pair per pose leaves lines in some
/// runs (a drawn rig on the default design with the L3G4200D's 30-Hz setting was flagged on 2
/// seeds of 4, its answer right). So every order above the first has its own pair in each run
/// (parameter k = 2·run + (0 for a, 1 for b), the first [`MAX_RUNS_OWN_PAIR`] runs); the first,
/// at the table's own frequency, keeps one pair per pose (k = 2·pose + …).
pub struct TableHarmonic(pub u32);

/// Runs whose harmonics above the first have a pair of their own: parameter k of [`SharedPar`] is
/// a byte. A session of more runs leaves the later runs' lines unmodelled, for the diagnostics to
/// see.
pub const MAX_RUNS_OWN_PAIR: usize = 128;

impl TableHarmonic {
    /// The runs parameter `k` applies to and whether it is b (the sine in speed).
    fn of(&self, k: u8) -> (RunScope, bool) {
        let i = usize::from(k / 2);
        let scope = if self.0 == 1 { RunScope::Pose(Pose::ALL[i]) } else { RunScope::Run(i) };
        (scope, k % 2 == 1)
    }
}

impl Behaviour for TableHarmonic {
    fn name(&self) -> String {
        match self.0 {
            n if n % GEAR_POLE_PASS_ORDER == 0 => format!("magnetic-gear transmission error at {n}× (pole pass)"),
            1 => "sensor-table eccentricity (transmission error at 1×)".into(),
            n => format!("table-speed ripple at {n}× the sensor-table rate"),
        }
    }

    fn key(&self) -> String {
        format!("table_harmonic_{}", self.0)
    }

    fn meaning(&self) -> &'static str {
        "the sensor table's angle departs periodically from what encoder and index imply (magnetic-gear pole pass, eccentricity, compliance); its derivative ripples θ2'; a remount can re-seat the gear, so each pose has its own phase, and above the first order each run its own (the gyro's low-pass sees the line at the run's speed)"
    }

    fn identified_by(&self) -> &'static str {
        "the same ripple in every axis of a run, in proportion to M R_qᵀ; at the first order in every speed of a pose, whose phase holds while the table stays engaged"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, layout: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        let effect = Effect::TableHarmonic(self.0);
        let groups: Vec<u8> = if self.0 == 1 {
            layout.poses.iter().map(|&pose| Pose::ALL.iter().position(|&q| q == pose).unwrap_or(0) as u8).collect()
        } else {
            (0..layout.run_stretch.len().min(MAX_RUNS_OWN_PAIR) as u8).collect()
        };
        let shared = groups.into_iter().flat_map(|i| [0, 1].map(|q| SharedPar { effect, k: 2 * i + q })).collect();
        (vec![], shared)
    }

    fn reported(&self, own: Own, _: f64) -> Option<Reported> {
        let Own::Shared(k) = own else { return None };
        let (scope, quadrature) = self.of(k);
        let n = self.0;
        let which = match scope {
            RunScope::Pose(pose) => format!("{pose}"),
            RunScope::Run(r) => format!("run {}", r + 1),
        };
        Some(Reported::new(
            format!("table-speed ripple {n}× {}, {which}", if quadrature { "sin" } else { "cos" }),
            1e6,
            "ppm of θ2'",
        ))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn scope(&self, k: u8) -> Option<RunScope> {
        Some(self.of(k).0)
    }

    fn shift(&self, k: u8, value: f64, s: &mut Shifts) {
        let (scope, quadrature) = self.of(k);
        let i = match s.ripple.iter().position(|h| h.0 == self.0 && h.1 == scope) {
            Some(i) => i,
            None => {
                s.ripple.push((self.0, scope, 0.0, 0.0));
                s.ripple.len() - 1
            }
        };
        if quadrature {
            s.ripple[i].3 = value;
        } else {
            s.ripple[i].2 = value;
        }
    }

    /// The angle's part less what the index pulse saw of it ([`super::terms::IndexEdge`]).
    fn value(&self, own: Own, p: &Point, _: usize, t: &AxisTerms, cx: &Ctx) -> f64 {
        along_gradient(t, self.gradient_factor(own, p, cx))
    }

    fn gradient_factor(&self, own: Own, p: &Point, cx: &Ctx) -> Option<[f64; 3]> {
        let Own::Shared(k) = own else { return None };
        let (scope, quadrature) = self.of(k);
        if !scope.applies(p.run, p.pose) {
            return Some([0.0; 3]);
        }
        let n = f64::from(self.0);
        let (sn, cn) = p.mesh_sin_cos[self.0 as usize];
        let (edge_s, edge_c) = cx.index_edge[p.run].harmonic[self.0 as usize];
        let (along_theta2, along_rate2) =
            if quadrature { (-(cn - edge_c) / n, p.rate2_dps * sn) } else { ((sn - edge_s) / n, p.rate2_dps * cn) };
        Some(std::array::from_fn(|i| along_theta2 * p.d_theta2[i] + along_rate2 * p.d_rate2[i]))
    }

    /// None: over whole turns a harmonic of θ2 above the first is orthogonal to M's columns.
    fn consider(&self, _: Own, _: &ConsiderCtx) -> Option<ConsiderBound> {
        None
    }

    /// The angle error at n× of θ2 ripples the in-plane sinusoid into lines at (n ± 1)×.
    fn turn_multiple(&self) -> u32 {
        self.0 + 1
    }

    /// An order above the first when the residual shows its line. The first always (one pair
    /// per pose, cheap to score): its 2× line is weak on short runs while the turn of the axes
    /// it makes is not, and the loop's score of its columns sees it where the diagnostics'
    /// line does not. Gated by that line, 0.01° of it on 20-s runs at ±180 °/s or 180, 90 °/s
    /// passed untried and left M 4.3-6.6σ off at exit 0 on 3 of 12 simulated sensors
    /// (`docs/trust.md`).
    fn candidate(&self, s: &Situation) -> bool {
        (self.0 == 1 || s.evidence.orders.get(self.0 as usize) == Some(&true)) && !s.has(Effect::TableHarmonic(self.0))
    }
}
