//! A periodic angle error of the sensor table.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
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
/// to θ2': parameter k = 2·(pose index) + (0 for a, 1 for b).
pub struct TableHarmonic(pub u32);

/// The pose and whether it is b (the sine in speed) of parameter `k`.
fn of(k: u8) -> (Pose, bool) {
    (Pose::ALL[usize::from(k / 2)], k % 2 == 1)
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
        "the sensor table's angle departs periodically from what encoder and index imply (magnetic-gear pole pass, eccentricity, compliance); its derivative ripples θ2'; a remount can re-seat the gear, so each pose has its own phase"
    }

    fn identified_by(&self) -> &'static str {
        "the same ripple in every axis and speed of a pose, in proportion to M R_qᵀ; its phase holds while the table stays engaged"
    }

    fn kind(&self) -> Kind {
        Kind::Other
    }

    fn params(&self, layout: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        let effect = Effect::TableHarmonic(self.0);
        let shared = layout
            .poses
            .iter()
            .flat_map(|&pose| {
                let i = Pose::ALL.iter().position(|&q| q == pose).unwrap_or(0) as u8;
                [0, 1].map(|q| SharedPar { effect, k: 2 * i + q })
            })
            .collect();
        (vec![], shared)
    }

    fn reported(&self, own: Own, _: f64) -> Option<Reported> {
        let Own::Shared(k) = own else { return None };
        let (pose, quadrature) = of(k);
        let n = self.0;
        Some(Reported::new(
            format!("table-speed ripple {n}× {}, {pose}", if quadrature { "sin" } else { "cos" }),
            1e6,
            "ppm of θ2'",
        ))
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, k: u8, value: f64, s: &mut Shifts) {
        let (pose, quadrature) = of(k);
        let i = match s.ripple.iter().position(|h| h.0 == self.0 && h.1 == pose) {
            Some(i) => i,
            None => {
                s.ripple.push((self.0, pose, 0.0, 0.0));
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
        let Own::Shared(k) = own else { return 0.0 };
        let (pose, quadrature) = of(k);
        if pose != p.pose {
            return 0.0;
        }
        let n = f64::from(self.0);
        let (sn, cn) = p.mesh_sin_cos[self.0 as usize];
        let (edge_s, edge_c) = cx.index_edge[p.run].harmonic[self.0 as usize];
        if quadrature {
            -t.e2 * (cn - edge_c) / n + t.ez * p.rate2_dps * sn
        } else {
            t.e2 * (sn - edge_s) / n + t.ez * p.rate2_dps * cn
        }
    }

    /// None: over whole turns a harmonic of θ2 above the first is orthogonal to M's columns.
    fn consider(&self, _: Own, _: &ConsiderCtx) -> Option<ConsiderBound> {
        None
    }

    /// When the residual shows its order.
    fn candidate(&self, s: &Situation) -> bool {
        s.evidence.orders.get(self.0 as usize) == Some(&true) && !s.has(Effect::TableHarmonic(self.0))
    }
}
