//! Offsets that wander with no assumed shape.

use super::terms::{
    AxisTerms, Bound, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Own, Point, Reported, SharedPar, Shifts, Situation,
};
use super::{Behaviour, Effect, Layout, DRIFT_KNOT_SPACINGS_S};

/// One σ of the offset's rate random walk that the consider covariance carries while no free
/// drift is fitted, °/s/√s ([`DriftKnots`]'s `consider`).
pub const RANDOM_WALK_DPS_PER_SQRT_S: f64 = 0.003;

/// Offsets that wander with no assumed shape (a rate random walk on top of a warm-up that lags
/// the die temperature): linear between knots about this many seconds apart, one continuous
/// curve through the runs of a pose that follow each other on one clock (`layout::Stretch`), a
/// level of its own after a remount or a gap. Its columns are the hat functions of the knots
/// ([`LinCol::DriftKnot`]), which the engine evaluates itself (two per sample, of dozens).
pub struct DriftKnots(pub u16);

impl Behaviour for DriftKnots {
    fn name(&self) -> String {
        format!("offset drift: free, linear between knots {} s apart", self.0)
    }

    fn key(&self) -> String {
        format!("drift_knots_{}s", self.0)
    }

    fn meaning(&self) -> &'static str {
        "the zero-rate level wanders in a way no single curve follows (a warm-up lagging the die temperature, a rate random walk of 0.001-0.005 °/s/√s): one continuous level through the runs of a pose, where the gyro stays powered and mounted, and a new one after each remount"
    }

    fn identified_by(&self) -> &'static str {
        "its slow change within runs and its continuity from run to run in one pose; where runs at different rates share it, the constant rate terms (θ2'·M R_qᵀ e_z2, a table tilt's) step between runs and it does not, otherwise the directions and sensitivities rest on the table-rate sinusoids alone"
    }

    fn kind(&self) -> Kind {
        Kind::Drift {
            offset_reference: "the first used sample of the first run (each pose has its own level)",
            free: true,
        }
    }

    /// Every knot of every stretch but the first stretch's first, whose level is the offset
    /// column's (the hats of a stretch sum to 1, so one knot overall must go for the offset to
    /// stay identifiable). The reported offset is therefore the level at the first used sample
    /// of the first run.
    fn params(&self, layout: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        let spacing_s = self.0;
        let knots =
            (0..layout.stretches.len())
                .flat_map(|s| {
                    (0..=layout.intervals(s, spacing_s))
                        .filter(move |&k| s > 0 || k > 0)
                        .map(move |k| LinCol::DriftKnot { stretch: s as u16, knot: k as u16, spacing_s })
                })
                .collect();
        (knots, vec![])
    }

    /// The knots are reported as the drift table, not as parameters.
    fn reported(&self, _: Own, _: f64) -> Option<Reported> {
        None
    }

    fn bound(&self, _: u8) -> Option<Bound> {
        None
    }

    fn shift(&self, _: u8, _: f64, _: &mut Shifts) {}

    /// Never called: it owns no [`LinCol::Of`] column.
    fn value(&self, _: Own, _: &Point, _: usize, _: &AxisTerms, _: &Ctx) -> f64 {
        0.0
    }

    /// The rate random walk every MEMS offset has, while the model holds no knots this fine: the
    /// finest spacing's knots, each step between neighbours K·√T (T the spacing). A drift curve
    /// (a warm-up, a polynomial) never follows a walk, and in short runs the walk's wander is
    /// not slow against the table's turn: 0.0034 °/s/√s under a fitted warm-up left 0.005° in a
    /// direction at 20-s runs (max |z| 4.6). K = 0.003 °/s/√s, the middle of MEMS gyros'
    /// 0.001-0.005 (IEEE Std 952's rate random walk; the L3G4200D datasheet gives none),
    /// engineering judgement. The knots' columns are levels; the consider covariance takes the
    /// bound on their steps ([`Behaviour::considered_as_walk`]).
    fn consider(&self, _: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        let finest = DRIFT_KNOT_SPACINGS_S.iter().copied().min().unwrap_or(self.0);
        let held = cx.current.iter().any(|e| matches!(e, Effect::DriftKnots(sp) if *sp <= self.0));
        (self.0 == finest && !held).then(|| ConsiderBound {
            sigma: RANDOM_WALK_DPS_PER_SQRT_S * f64::from(self.0).sqrt(),
            source: "rate random walk of a MEMS gyro's offset, 0.001-0.005 °/s/√s (IEEE Std 952; none in the L3G4200D datasheet), 0.003 taken (engineering judgement)",
        })
    }

    fn considered_as_walk(&self) -> Option<String> {
        Some(format!("offset step over {} s", self.0))
    }

    fn size_read_from_data(&self) -> Option<&'static str> {
        Some("as large as the residual's own wander allows")
    }

    /// On top of a drift curve whose residual still drifts (a random walk, a warm-up that lags
    /// the die), as a drift model of its own, or in place of coarser knots whose residual still
    /// drifts (a random walk three times the default left run offsets between 40-s knots,
    /// flagged on both seeds of the trust bench's default-design cell). It replaces what it
    /// holds (`selection::replaced_by_free_drift`).
    /// An offset drifts over seconds to minutes, not with the turn.
    fn turn_multiple(&self) -> u32 {
        0
    }

    fn candidate(&self, s: &Situation) -> bool {
        s.evidence.drift && !s.current.iter().any(|e| matches!(e, Effect::DriftKnots(sp) if *sp <= self.0))
    }
}
