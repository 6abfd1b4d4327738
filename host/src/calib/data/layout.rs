//! How a capture's runs lie in time and pose: what the effects' columns depend on (a parameter
//! set per pose; the stretches of runs the free drift follows as one continuous curve, and its
//! knot grids on them).

use crate::geometry::Pose;

/// Intervals between knots over `span_s` at nominal spacing `spacing_s`: the span divided
/// evenly, at least one.
fn knot_intervals(span_s: (f64, f64), spacing_s: u16) -> usize {
    (((span_s.1 - span_s.0) / f64::from(spacing_s.max(1))).round() as usize).max(1)
}

/// Longest gap between two runs of one pose that the free drift bridges, s: the gyro stays
/// powered and mounted between them, so its offset is continuous, and a random walk of
/// 0.005 °/s/√s (the top of issue 10's range) strays from the straight line across the gap by
/// K·√(T/6) ≈ 0.011 °/s, what the 40-s knots allow within a run. Runs further apart, or in
/// another pose (a remount handles the package), start a stretch of their own.
pub const MAX_BRIDGED_GAP_S: f64 = 30.0;

/// Runs one after another in one pose and on one clock, whose offset the free drift follows as
/// one continuous curve.
#[derive(Debug, Clone, PartialEq)]
pub struct Stretch {
    /// The runs (indices into the data's runs), in time order.
    pub runs: std::ops::Range<usize>,
    /// Time of the first and last used sample of the stretch, s.
    pub span_s: (f64, f64),
    /// Longest gap between its runs, s (0 for one run).
    pub max_gap_s: f64,
}

/// What of the data an effect's columns depend on: the poses present (a parameter set per
/// pose) and the stretches of runs the free drift follows continuously.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Layout {
    /// Poses, in order of first appearance.
    pub poses: Vec<Pose>,
    /// Consecutive runs of one pose on one clock, each gap at most [`MAX_BRIDGED_GAP_S`].
    pub stretches: Vec<Stretch>,
    /// Per run, its stretch.
    pub run_stretch: Vec<usize>,
    /// Per run, the first and last used sample's time, s.
    pub run_spans_s: Vec<(f64, f64)>,
}

impl Layout {
    /// The layout of runs in pose `poses_of_runs[r]` whose used samples span `spans_s[r]` (each
    /// capture's clock starts at 0, so a run starting before the previous one ended is on
    /// another clock).
    pub fn new(poses: Vec<Pose>, poses_of_runs: &[Pose], spans_s: &[(f64, f64)]) -> Self {
        let mut stretches: Vec<Stretch> = Vec::new();
        let mut run_stretch = Vec::with_capacity(spans_s.len());
        for (r, &(a, b)) in spans_s.iter().enumerate() {
            match stretches.last_mut() {
                Some(s)
                    if poses_of_runs[r - 1] == poses_of_runs[r]
                        && a > s.span_s.1
                        && a - s.span_s.1 <= MAX_BRIDGED_GAP_S =>
                {
                    s.runs.end = r + 1;
                    s.max_gap_s = s.max_gap_s.max(a - s.span_s.1);
                    s.span_s.1 = b;
                }
                _ => stretches.push(Stretch { runs: r..r + 1, span_s: (a, b), max_gap_s: 0.0 }),
            }
            run_stretch.push(stretches.len() - 1);
        }
        Self { poses, stretches, run_stretch, run_spans_s: spans_s.to_vec() }
    }

    /// Whether knot `knot` of stretch `s` on the grid of spacing `spacing_s` has support in run
    /// `r` only: the level of that run alone, which no other run can tell.
    pub fn knot_only_in_run(&self, s: usize, knot: u16, spacing_s: u16, r: usize) -> bool {
        if self.run_stretch.get(r) != Some(&s) {
            return false;
        }
        let (lo, hi) = self.knot_support_s(s, knot, spacing_s);
        self.stretches[s].runs.clone().filter(|&q| q != r).all(|q| {
            let (a, b) = self.run_spans_s[q];
            b <= lo || a >= hi
        })
    }

    /// Intervals between knots of stretch `s` at nominal spacing `spacing_s`: the span divided
    /// evenly, at least one, and longer than the longest gap between its runs. Two knots then
    /// never sit on a gap's two edges (which would leave the levels either side free, a level
    /// per run again): a gap lies inside an interval, held by samples on both sides, or around
    /// a knot that both sides share.
    pub fn intervals(&self, s: usize, spacing_s: u16) -> usize {
        let st = &self.stretches[s];
        let n = knot_intervals(st.span_s, spacing_s);
        if st.max_gap_s > 0.0 {
            let longer_than_gap = ((st.span_s.1 - st.span_s.0) / st.max_gap_s).ceil() as usize;
            n.min(longer_than_gap.saturating_sub(1)).max(1)
        } else {
            n
        }
    }

    /// The knot grid of stretch `s` at nominal spacing `spacing_s`: its first knot's time, s,
    /// and knots per second.
    pub fn knot_grid(&self, s: usize, spacing_s: u16) -> (f64, f64) {
        let (a, b) = self.stretches[s].span_s;
        (a, self.intervals(s, spacing_s) as f64 / (b - a).max(1e-9))
    }

    /// Where knot `knot` of stretch `s` is non-zero, s.
    pub fn knot_support_s(&self, s: usize, knot: u16, spacing_s: u16) -> (f64, f64) {
        let (t0, per_s) = self.knot_grid(s, spacing_s);
        let t = t0 + f64::from(knot) / per_s;
        (t - 1.0 / per_s, t + 1.0 / per_s)
    }

    /// Whether some stretch holds runs at different base-table rates: the free drift's level is
    /// then shared by runs whose constant rate terms (θ2'·M R_qᵀ e_z2, a table tilt's) differ,
    /// so it does not hold those terms.
    pub fn shares_levels_across_rates(&self, rates_dps: &[f64]) -> bool {
        self.stretches.iter().any(|s| s.runs.clone().any(|r| (rates_dps[r] - rates_dps[s.runs.start]).abs() > 1e-9))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::effects::Effect;

    const SPANS: [(f64, f64); 5] = [(1.5, 111.5), (123.5, 233.5), (245.5, 355.5), (367.5, 477.5), (2.0, 100.0)];
    const POSES: [Pose; 5] = [Pose::One, Pose::One, Pose::Two, Pose::Two, Pose::Two];

    #[test]
    fn a_stretch_is_the_runs_of_one_pose_on_one_clock_close_in_time() {
        let l = Layout::new(vec![Pose::One, Pose::Two], &POSES, &SPANS);
        // Runs 1-2 (pose 1, 12 s apart) and 3-4 (pose 2) join; run 5 restarts the clock.
        assert_eq!(l.run_stretch, [0, 0, 1, 1, 2]);
        assert_eq!(l.stretches[0], Stretch { runs: 0..2, span_s: (1.5, 233.5), max_gap_s: 12.0 });
        assert_eq!(l.stretches[2], Stretch { runs: 4..5, span_s: (2.0, 100.0), max_gap_s: 0.0 });
        // A gap beyond MAX_BRIDGED_GAP_S splits.
        let far = [(0.0, 100.0), (100.0 + MAX_BRIDGED_GAP_S + 1.0, 200.0)];
        assert_eq!(Layout::new(vec![Pose::One], &[Pose::One; 2], &far).run_stretch, [0, 1]);
        // Every knot of every stretch but the very first: 232 s at 40 s is 6 intervals, 7 knots.
        assert_eq!(l.intervals(0, 40), 6);
        assert_eq!(Effect::DriftKnots(40).params(&l).0.len(), 6 + 7 + (1 + 2));
    }

    #[test]
    fn knots_are_further_apart_than_a_gap_they_bridge() {
        let l = Layout::new(vec![Pose::One], &[Pose::One; 2], &[(0.0, 100.0), (125.0, 225.0)]);
        // 225 s at 10 s would be 22 intervals; the 25-s gap caps them at 8 (28.125 s each).
        assert_eq!(l.intervals(0, 10), 8);
        assert_eq!(l.knot_grid(0, 10), (0.0, 8.0 / 225.0));
        // Knot 3 (84.4 s) is the first run's alone, knot 5 (140.6 s) the second's; knot 4
        // (112.5 s, in the gap) reaches both, and ties their levels.
        assert!(l.knot_only_in_run(0, 3, 10, 0));
        assert!(l.knot_only_in_run(0, 5, 10, 1));
        assert!(!l.knot_only_in_run(0, 4, 10, 0) && !l.knot_only_in_run(0, 4, 10, 1));
        assert!(!l.knot_only_in_run(0, 1, 10, 1));
        // A gap of exactly two intervals' worth still gets intervals longer than itself.
        let l = Layout::new(vec![Pose::One], &[Pose::One; 2], &[(0.0, 100.0), (125.0, 250.0)]);
        assert_eq!(l.intervals(0, 10), 9);
    }

    #[test]
    fn levels_are_shared_across_rates_only_when_a_stretch_holds_two() {
        let l = Layout::new(vec![Pose::One, Pose::Two], &POSES, &SPANS);
        assert!(l.shares_levels_across_rates(&[180.0, -180.0, 180.0, -180.0, 90.0]));
        assert!(!l.shares_levels_across_rates(&[180.0, 180.0, 90.0, 90.0, 90.0]));
        let apart = Layout::new(vec![Pose::One], &[Pose::One; 2], &[(0.0, 100.0), (0.0, 100.0)]);
        assert!(!apart.shares_levels_across_rates(&[180.0, -180.0]));
    }
}
