//! The engine: the linear model extended by catalogue effects ([`super::effects`]), fitted
//! jointly over the three axes.
//!
//! Each effect adds per-axis linear columns (drift, rate-dependent scale) and/or parameters shared
//! by all axes that move the kinematics (delay, index offset, table-speed ripple, the warm-up time
//! constant); the engine knows them only through [`super::effects::Behaviour`]. The shared ones make the model non-linear; it is fitted by Gauss-Newton on all
//! parameters at once, each iteration one pass over the cached kinematics that accumulates, per
//! run and axis, the Gram matrix of [linear columns | Jacobian columns of the shared parameters]
//! against the current residual. The covariance of the converged fit is the inverse of the joint
//! normal matrix, so the uncertainty of a delay or an index offset flows into that of M.
//!
//! The same accumulation over the union of the model's columns and every candidate's gives the
//! linearised fit of any candidate model from one pass (see [`super::selection`]).
//!
//! Gauss-Newton is written here rather than taken from `levenberg-marquardt` or `argmin`: those
//! want the residual vector and Jacobian in memory (samples × parameters, millions of rows),
//! where this accumulates the normal equations run by run and reuses them for every candidate;
//! the linear algebra is nalgebra's.

use super::axes::{is_clipped, AXES};
use super::effects::terms::{decay, dot, AxisTerms, Ctx, IndexEdge, Needs, Own, Shifts};
use super::effects::{Effect, MAX_DELAY_S, MAX_HARMONIC_ORDER};
use super::error::CalError;
use super::kinematics::{temperature_at, KinSample, KinSamples, Kinematics, RunKinematics};
use super::layout::Layout;
use crate::geometry::Pose;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

pub use super::effects::terms::{Bound, Col, LinCol, Point, Reported, SharedPar};
pub use super::effects::DRIFT_KNOT_SPACINGS_S;

/// Span of the moving average that smooths OUT_TEMP, s. The register counts whole °C; during
/// warm-up it steps every few seconds, so 20 s turns the steps into a ramp, and it is 10× the
/// table period at 0.5 Hz, so it cannot follow table-synchronous structure.
pub const TEMPERATURE_SMOOTHING_S: f64 = 20.0;

/// Smallest reciprocal condition number of the diagonally scaled joint normal matrix accepted:
/// 1e-13 leaves ~3 significant digits of f64's 16 in the worst-determined combination.
const MIN_RCOND: f64 = 1e-13;

/// Samples summed into a local accumulator before it is added to the run total: rounding error
/// then grows as O(√n) ulp in a long run instead of O(n).
const CHUNK: usize = 1024;

/// Gauss-Newton iterations at most; a converging fit needs 2–4 (the effects are small angles).
const MAX_ITERATIONS: usize = 12;

/// A Gauss-Newton step smaller than this many σ in every parameter ends the iteration: the
/// remaining error is then 1 % of the statistical one.
const CONVERGED_SIGMAS: f64 = 0.01;

/// Which kinematic samples of a run the loop uses: those clear of the run's ends and gaps by
/// [`MAX_DELAY_S`], i.e. one index range per stretch between gaps (a handful per run), held as
/// ranges rather than a flag per sample (issue 7's memory bar: a 4-hour capture has 11.5 M).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ValidSamples {
    /// Ascending, disjoint, non-empty index ranges.
    ranges: Vec<std::ops::Range<usize>>,
}

impl ValidSamples {
    /// Whether sample `i` is used.
    pub fn contains(&self, i: usize) -> bool {
        let k = self.ranges.partition_point(|r| r.end <= i);
        self.ranges.get(k).is_some_and(|r| r.contains(&i))
    }

    /// The used samples' indices, ascending.
    pub fn indices(&self) -> impl Iterator<Item = usize> + '_ {
        self.ranges.iter().flat_map(|r| r.clone())
    }

    /// The used samples' indices in `lo..hi`, ascending.
    pub fn indices_in(&self, lo: usize, hi: usize) -> impl Iterator<Item = usize> + '_ {
        let k = self.ranges.partition_point(|r| r.end <= lo);
        self.ranges[k..].iter().take_while(move |r| r.start < hi).flat_map(move |r| r.start.max(lo)..r.end.min(hi))
    }

    /// The first used sample.
    pub fn first(&self) -> Option<usize> {
        self.ranges.first().map(|r| r.start)
    }

    /// The last used sample.
    pub fn last(&self) -> Option<usize> {
        self.ranges.last().map(|r| r.end - 1)
    }

    /// Samples used.
    pub fn len(&self) -> usize {
        self.ranges.iter().map(|r| r.len()).sum()
    }

    /// Whether no sample is used.
    pub fn is_empty(&self) -> bool {
        self.ranges.is_empty()
    }

    /// Samples at times `t_s(0..n)` (s, ascending) whose spacing beyond `gap_s` is a gap, each
    /// used when at least `guard` samples lie between it and the run's ends or a gap: stretch
    /// [a, b] between gaps gives [a + guard, b − guard].
    fn of(n: usize, t_s: impl Fn(usize) -> f64, gap_s: f64, guard: usize) -> Self {
        let mut ranges = Vec::new();
        let mut a = 0;
        for b in 0..n {
            if b + 1 == n || t_s(b + 1) - t_s(b) > gap_s {
                if b >= a + 2 * guard {
                    ranges.push(a + guard..b - guard + 1);
                }
                a = b + 1;
            }
        }
        Self { ranges }
    }
}

/// Per-run data the loop adds to the kinematics.
#[derive(Debug, Clone)]
pub struct RunData {
    /// Which kinematic samples are used (clear of the run's ends and gaps by [`MAX_DELAY_S`]).
    pub valid: ValidSamples,
    /// Samples used.
    pub n_valid: usize,
    /// Time of the first and last used sample, s.
    pub span_s: (f64, f64),
}

/// The cached kinematics and what the loop derives from them once.
#[derive(Debug, Clone)]
pub struct LoopData {
    /// Kinematics of every run.
    pub kin: Kinematics,
    /// Per run.
    pub runs: Vec<RunData>,
    /// Time of the first sample, s (origin of the warm-up exponential).
    pub t0_s: f64,
    /// Middle and half-span of the capture, s (for the polynomial drift).
    pub t_mid_s: f64,
    /// Half-span, s.
    pub t_half_s: f64,
    /// The poses the runs are in, in order of first appearance.
    pub poses: Vec<Pose>,
    /// What the effects' columns depend on.
    pub layout: Layout,
    /// Mean die temperature over every sample, OUT_TEMP counts: the smoothed temperature is
    /// reckoned from it ([`RunTemperatures`]).
    pub temp_mean_counts: f64,
    /// Spread of the smoothed die temperature over every sample, °C, once asked for
    /// ([`LoopData::temp_spread_c`]).
    temp_spread_c: std::sync::OnceLock<f64>,
}

/// The smoothed die temperature at one run's samples, °C from the capture mean: the moving
/// average over [`TEMPERATURE_SMOOTHING_S`] of OUT_TEMP interpolated at each sample (falling 1
/// count per °C, datasheet Table 5), rounded to f32. Computed as the samples are visited, from
/// running sums of which only the 2h + 2 a window spans are kept (a ring), rather than held per
/// sample (4 bytes each, 44 MiB at 4 hours: issue 7's memory bar). Every pass visits a run's
/// samples forward, which costs one interpolation per sample; going back restarts the run.
#[derive(Debug, Clone)]
pub struct RunTemperatures<'a> {
    run: &'a RunKinematics,
    temp_mean_counts: f64,
    /// Half-width of the moving average, samples.
    h: usize,
    /// Running sums: the sum of the first k interpolated readings at `prefix[k % prefix.len()]`.
    prefix: Vec<f64>,
    /// Readings summed so far.
    filled: usize,
    /// `filled % prefix.len()`, stepped rather than divided (three divisions per sample
    /// otherwise).
    slot: usize,
    sum: f64,
    /// Where `temperature_at` stands in the run's readings.
    cursor: usize,
}

impl<'a> RunTemperatures<'a> {
    /// The temperatures of `run`, from the mean over the capture, `temp_mean_counts`.
    pub fn new(run: &'a RunKinematics, temp_mean_counts: f64) -> Self {
        let dt = 1.0 / run.sample_rate_hz;
        let h = ((TEMPERATURE_SMOOTHING_S / 2.0) / dt).round() as usize;
        Self { run, temp_mean_counts, h, prefix: vec![0.0; 2 * h + 2], filled: 0, slot: 0, sum: 0.0, cursor: 0 }
    }

    /// At kept sample `i`, °C from the capture mean.
    pub fn at(&mut self, i: usize) -> f32 {
        let ring_len = self.prefix.len();
        let (a, b) = (i.saturating_sub(self.h), (i + self.h + 1).min(self.run.samples.len()));
        if a + ring_len <= self.filled {
            *self = Self::new(self.run, self.temp_mean_counts);
        }
        let next = |slot: usize| if slot + 1 == ring_len { 0 } else { slot + 1 };
        while self.filled < b {
            let t_us = self.run.samples.get(self.filled).t_us();
            let t = temperature_at(&self.run.temperatures, t_us, &mut self.cursor);
            self.sum += if t.is_finite() { f64::from(t) } else { self.temp_mean_counts };
            self.filled += 1;
            self.slot = next(self.slot);
            self.prefix[self.slot] = self.sum;
        }
        // Visited forward, b is the last reading summed and, a whole window away, a is the slot
        // after it (b − a = 2h + 1 = ring_len − 1).
        let b_slot = if b == self.filled { self.slot } else { b % ring_len };
        let a_slot = if b - a + 1 == ring_len { next(b_slot) } else { a % ring_len };
        // OUT_TEMP falls 1 count per °C (datasheet Table 5).
        let mean = (self.prefix[b_slot] - self.prefix[a_slot]) / (b - a) as f64;
        (-(mean - self.temp_mean_counts)) as f32
    }
}

impl LoopData {
    /// Marks usable samples and smooths the temperature.
    pub fn new(kin: Kinematics) -> Self {
        let mut runs = Vec::with_capacity(kin.runs.len());
        let (mut t_lo, mut t_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut temp_sum, mut temp_n) = (0.0, 0usize);
        for r in &kin.runs {
            if let (Some(a), Some(b)) = (r.samples.first(), r.samples.last()) {
                t_lo = t_lo.min(a.t_s());
                t_hi = t_hi.max(b.t_s());
            }
            for t in r.temperatures_counts() {
                if t.is_finite() {
                    temp_sum += f64::from(t);
                    temp_n += 1;
                }
            }
        }
        let temp_mean = if temp_n > 0 { temp_sum / temp_n as f64 } else { 0.0 };
        for r in &kin.runs {
            let s = &r.samples;
            let dt = 1.0 / r.sample_rate_hz;
            let guard = (MAX_DELAY_S / dt).ceil() as usize + 1;
            // A gap is any spacing beyond 1.5 nominal periods (a dropped or excluded sample).
            let gap = 1.5 * dt;
            let valid = ValidSamples::of(s.len(), |i| s.get(i).t_s(), gap, guard);
            let n_valid = valid.len();
            let first = valid.first().map_or(0.0, |i| s.get(i).t_s());
            let last = valid.last().map_or(first, |i| s.get(i).t_s());
            runs.push(RunData { valid, n_valid, span_s: (first, last) });
        }
        let mut poses: Vec<Pose> = Vec::new();
        for r in &kin.runs {
            if !poses.contains(&r.pose) {
                poses.push(r.pose);
            }
        }
        let run_poses: Vec<Pose> = kin.runs.iter().map(|r| r.pose).collect();
        let spans: Vec<(f64, f64)> = runs.iter().map(|r| r.span_s).collect();
        let layout = Layout::new(poses.clone(), &run_poses, &spans);
        Self {
            kin,
            runs,
            t0_s: t_lo,
            t_mid_s: 0.5 * (t_lo + t_hi),
            t_half_s: (0.5 * (t_hi - t_lo)).max(1e-9),
            poses,
            layout,
            temp_mean_counts: temp_mean,
            temp_spread_c: std::sync::OnceLock::new(),
        }
    }

    /// Spread of the smoothed die temperature over every sample, °C: a sweep over every
    /// sample, made the first time a candidate rule asks (only the temperature drift's does,
    /// and only once the residual drifts), not for every calibration.
    pub fn temp_spread_c(&self) -> f64 {
        *self.temp_spread_c.get_or_init(|| {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for r in &self.kin.runs {
                let mut temps = RunTemperatures::new(r, self.temp_mean_counts);
                for i in 0..r.samples.len() {
                    let t = f64::from(temps.at(i));
                    lo = lo.min(t);
                    hi = hi.max(t);
                }
            }
            hi - lo
        })
    }
}

/// A model: its effects, columns and current parameter values.
#[derive(Debug, Clone)]
pub struct Model {
    /// Effects added, in order.
    pub effects: Vec<Effect>,
    /// Per-axis linear columns.
    pub lin: Vec<LinCol>,
    /// Shared parameters.
    pub shared: Vec<SharedPar>,
    /// Coefficients of `lin`, per axis.
    pub beta: [Vec<f64>; 3],
    /// Values of `shared`.
    pub theta: Vec<f64>,
    /// Unit axis directions (rows of M normalised) that define the rate along each axis for the
    /// rate-dependent scale, updated every iteration.
    pub s_hat: [Vector3<f64>; 3],
    /// Earth's vertical rate when it is known (from a latitude) rather than fitted, °/s.
    pub earth_vertical_known_dps: f64,
    /// What of the data the effects' columns depend on.
    pub layout: Layout,
}

impl Model {
    /// The linear model of EXCITER.md eq. 6 with all coefficients 0, for data in both poses.
    pub fn base() -> Self {
        Self::base_for(&Pose::ALL)
    }

    /// The linear model for `data`.
    pub fn for_data(data: &LoopData) -> Self {
        Self { layout: data.layout.clone(), ..Self::base_for(&data.poses) }
    }

    /// The linear model for data holding `poses` (and no free drift).
    pub fn base_for(poses: &[Pose]) -> Self {
        Self {
            effects: Vec::new(),
            lin: vec![LinCol::Omega(0), LinCol::Omega(1), LinCol::Omega(2), LinCol::One],
            shared: Vec::new(),
            beta: std::array::from_fn(|_| vec![0.0; 4]),
            theta: Vec::new(),
            s_hat: std::array::from_fn(|a| Vector3::ith(a, 1.0)),
            earth_vertical_known_dps: 0.0,
            layout: Layout { poses: poses.to_vec(), ..Layout::default() },
        }
    }

    /// Columns of the model: linear then shared.
    pub fn cols(&self) -> Vec<Col> {
        self.lin.iter().map(|&c| Col::Lin(c)).chain(self.shared.iter().map(|&p| Col::Shared(p))).collect()
    }

    /// Value of a shared parameter, if in the model.
    pub fn theta_of(&self, p: SharedPar) -> Option<f64> {
        self.shared.iter().position(|&q| q == p).map(|i| self.theta[i])
    }

    /// Coefficient of a linear column on an axis, if in the model.
    pub fn beta_of(&self, axis: usize, c: LinCol) -> Option<f64> {
        self.lin.iter().position(|&q| q == c).map(|i| self.beta[axis][i])
    }

    /// M, counts per °/s.
    pub fn m(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|a, k| self.beta_of(a, LinCol::Omega(k)).unwrap_or(0.0))
    }

    /// The model with `effect` added, its linear coefficients and shared parameters set from
    /// `init_lin` (per axis, one per new linear column) and `init_shared`.
    pub fn with(&self, effect: Effect, init_lin: [Vec<f64>; 3], init_shared: Vec<f64>) -> Self {
        let (lin, shared) = effect.params(&self.layout);
        let mut m = self.clone();
        m.effects.push(effect);
        m.lin.extend(lin);
        for (b, init) in m.beta.iter_mut().zip(init_lin) {
            b.extend(init);
        }
        m.shared.extend(shared);
        m.theta.extend(init_shared);
        m
    }

    /// The model with `effect` taken out (its columns and parameters), the rest as fitted.
    pub fn without(&self, effect: Effect) -> Self {
        let (lin, shared) = effect.params(&self.layout);
        let mut m = self.clone();
        m.effects.retain(|&e| e != effect);
        let keep_lin: Vec<bool> = self.lin.iter().map(|c| !lin.contains(c)).collect();
        let keep =
            |v: &Vec<f64>, k: &[bool]| v.iter().zip(k).filter(|(_, &k)| k).map(|(&x, _)| x).collect::<Vec<f64>>();
        for b in &mut m.beta {
            *b = keep(b, &keep_lin);
        }
        m.lin.retain(|c| !lin.contains(c));
        let keep_shared: Vec<bool> = self.shared.iter().map(|p| !shared.contains(p)).collect();
        m.theta = keep(&self.theta, &keep_shared);
        m.shared.retain(|p| !shared.contains(p));
        m
    }

    /// Whether shared parameter `p` only shapes its effect's linear columns and these are all 0
    /// (a warm-up's time constant while its amplitude is 0): its Jacobian is then 0, and the
    /// effect is absent whatever its value.
    pub fn shapes_only_zero_columns(&self, p: SharedPar) -> bool {
        let mut own = self.lin.iter().enumerate().filter(|(_, c)| matches!(c, LinCol::Of(e, _) if *e == p.effect));
        let mut any = false;
        let all_zero = own.all(|(i, _)| {
            any = true;
            (0..3).all(|a| self.beta[a][i] == 0.0)
        });
        any && all_zero
    }

    fn update_directions(&mut self) {
        let m = self.m();
        for a in 0..3 {
            let row = Vector3::new(m[(a, 0)], m[(a, 1)], m[(a, 2)]);
            if row.norm() > 0.0 {
                self.s_hat[a] = row.normalize();
            }
        }
    }
}

/// The kinematic chain's inputs at a model's values: each shared parameter's effect sets its own.
fn shifts_of(m: &Model) -> Shifts {
    let mut s = Shifts::nominal(m.earth_vertical_known_dps);
    for (&p, &v) in m.shared.iter().zip(&m.theta) {
        p.effect.behaviour(|b| b.shift(p.k, v, &mut s));
    }
    s
}

/// θ2 and θ1' at `t_i − delay` by linear interpolation between the neighbouring samples (the
/// sample is valid, so they exist within [`MAX_DELAY_S`]).
fn interpolate(s: &KinSamples, i: usize, delay_s: f64) -> (f64, f64) {
    let si = s.get(i);
    if delay_s == 0.0 {
        return (si.theta2_rad(), si.theta1_rate_dps());
    }
    let target = si.t_s() - delay_s;
    let mut j = i;
    let mut sj = si;
    if delay_s > 0.0 {
        while j > 0 && sj.t_s() > target {
            j -= 1;
            sj = s.get(j);
        }
    } else {
        while j + 1 < s.len() && s.get(j + 1).t_s() <= target {
            j += 1;
        }
        sj = s.get(j);
    }
    let k = (j + 1).min(s.len() - 1);
    let sk = s.get(k);
    let span = sk.t_s() - sj.t_s();
    let w = if span > 0.0 { ((target - sj.t_s()) / span).clamp(0.0, 1.0) } else { 0.0 };
    (
        sj.theta2_rad() + w * (sk.theta2_rad() - sj.theta2_rad()),
        sj.theta1_rate_dps() + w * (sk.theta1_rate_dps() - sj.theta1_rate_dps()),
    )
}

/// The knot columns of one stretch and spacing of the free drift within a column list.
#[derive(Debug, Clone)]
struct KnotGroup {
    stretch: usize,
    spacing_s: u16,
    /// Index of the spacing in [`DRIFT_KNOT_SPACINGS_S`], whose knot position each point carries.
    spacing_index: Option<usize>,
    /// Where knot k sits in the column list, if it is there (the first stretch's first knot is
    /// the offset's).
    at: Vec<Option<usize>>,
}

/// How a pass evaluates a dense column, resolved once per column list: the base model's
/// columns are direct reads of the point, and a column with one value for all three axes (a
/// linear column that does not depend on the axis's own rate) is evaluated once per sample, not
/// once per axis. Matching on the `LinCol` itself at every sample read its payload back across
/// two stores (a store-forwarding stall): a fifth of a plain fit's pass and a tenth of the
/// diagnostics'.
#[derive(Debug, Clone, Copy)]
enum Kernel {
    /// Component k of ω_s.
    Omega(usize),
    /// The constant.
    One,
    /// Another axis-independent linear column.
    Common(LinCol),
    /// A column whose value differs between axes (a shared parameter's Jacobian or a column
    /// that depends on the axis's own rate).
    PerAxis(Col),
}

impl Kernel {
    fn of(c: Col) -> Self {
        match c {
            Col::Lin(LinCol::Omega(k)) => Kernel::Omega(k),
            Col::Lin(LinCol::One) => Kernel::One,
            Col::Lin(l) if l.is_common() => Kernel::Common(l),
            c => Kernel::PerAxis(c),
        }
    }
}

/// A column list split for evaluation sample by sample: the columns every sample has, and the
/// free drift's knots. A sample lies under at most two knots of a grid, so a pass evaluates those
/// two, not the dozens a long capture has: evaluating every knot at every sample made the
/// cost of a calibration grow faster than its length (issue 7).
#[derive(Debug, Clone, Default)]
struct ColPlan {
    /// (position in the list, column) of every column but the knots.
    dense: Vec<(usize, Col)>,
    /// How each of `dense` is evaluated.
    kernels: Vec<Kernel>,
    knots: Vec<KnotGroup>,
    /// Whether `dense` holds a shared parameter's column.
    has_shared: bool,
    /// Whether every column has one value for all three axes (no knot, no per-axis column):
    /// the plain linear model's passes.
    all_common: bool,
}

impl ColPlan {
    fn of(cols: impl Iterator<Item = Col>) -> Self {
        let mut plan = Self::default();
        for (j, c) in cols.enumerate() {
            let Col::Lin(LinCol::DriftKnot { stretch, knot, spacing_s }) = c else {
                plan.has_shared |= matches!(c, Col::Shared(_));
                plan.dense.push((j, c));
                plan.kernels.push(Kernel::of(c));
                continue;
            };
            let stretch = usize::from(stretch);
            let g = match plan.knots.iter().position(|g| g.stretch == stretch && g.spacing_s == spacing_s) {
                Some(g) => g,
                None => {
                    plan.knots.push(KnotGroup {
                        stretch,
                        spacing_s,
                        spacing_index: DRIFT_KNOT_SPACINGS_S.iter().position(|&d| d == spacing_s),
                        at: Vec::new(),
                    });
                    plan.knots.len() - 1
                }
            };
            let at = &mut plan.knots[g].at;
            let k = usize::from(knot);
            if at.len() <= k {
                at.resize(k + 1, None);
            }
            at[k] = Some(j);
        }
        plan.all_common = plan.knots.is_empty() && !plan.kernels.iter().any(|k| matches!(k, Kernel::PerAxis(_)));
        plan
    }
}

/// sin and cos of n× the gear mesh's angle, index n (`Point::mesh_sin_cos`).
type MeshHarmonics = [(f64, f64); MAX_HARMONIC_ORDER + 1];

/// The sensor table's transmission error in pose `pose` at the mesh angle's harmonics `mesh`: the effective
/// θ2 from the index-referenced `theta2_rad`, the factor on θ2' and its derivative in the mesh
/// angle (each harmonic n: angle (a sin nθ − b cos nθ)/n, rate factor 1 + a cos nθ + b sin nθ),
/// the angle less the error the run's index pulse saw (`edge`).
#[inline]
fn transmission(sh: &Shifts, pose: Pose, theta2_rad: f64, mesh: &MeshHarmonics, edge: &IndexEdge) -> (f64, f64, f64) {
    let (mut th_eff, mut ripple, mut dripple) = (theta2_rad - edge.shift_rad, 1.0, 0.0);
    for &(n, _, a, b) in sh.ripple.iter().filter(|h| h.1 == pose) {
        let nf = f64::from(n);
        let (sn, cn) = mesh[n as usize];
        th_eff += (a * sn - b * cn) / nf;
        ripple += a * cn + b * sn;
        dripple += nf * (b * cn - a * sn);
    }
    (th_eff, ripple, dripple)
}

/// ∂ω_s/∂e_k of the pose-2 fixture's turn e, ω_s = R2ᵀ·exp(−[e]×)·v with `v` = ω2 + κ·ω̈2 in
/// the table frame and `rt` = R2ᵀ: exp([e + δ]×) = exp([J·δ]×)·exp([e]×) to first order in δ, J
/// the left Jacobian of the rotation, I + b·[e]× + c·[e]×², so the column is
/// R2ᵀ·exp(−[e]×)·(v × J·e_k). `turn` = [a, b] of [`rodrigues`], c = (1 − a)/θ².
#[inline]
fn fixture_jacobian(rt: &[[f64; 3]; 3], v: &[f64; 3], e: &[f64; 3], [a, b]: [f64; 2]) -> [[f64; 3]; 3] {
    let t2 = e.iter().map(|x| x * x).sum::<f64>();
    // c's series below 1e-4 rad, as for a and b.
    let c = if t2 < 1e-8 { 1.0 / 6.0 - t2 / 120.0 } else { (1.0 - a) / t2 };
    std::array::from_fn(|k| {
        let unit: [f64; 3] = std::array::from_fn(|j| if j == k { 1.0 } else { 0.0 });
        let w = turn(e, &cross(v, &turn(e, &unit, 1.0, (b, c))), -1.0, (a, b));
        std::array::from_fn(|i| rt[i][0] * w[0] + rt[i][1] * w[1] + rt[i][2] * w[2])
    })
}

/// Evaluates columns and predictions at samples for one model.
pub struct Evaluator<'a> {
    data: &'a LoopData,
    model: &'a Model,
    shifts: Shifts,
    /// R_qᵀ of each run, as plain arrays (the per-sample arithmetic stays free of generic
    /// matrix code, which the test profile does not optimise).
    rot_t: Vec<[[f64; 3]; 3]>,
    /// Axis directions for the rate-scale columns.
    s_hat: [[f64; 3]; 3],
    /// ∂f/∂ω_s pieces per axis: the row of M, and the model's columns that depend on the axis's
    /// own rate with their coefficients (their slope adds to it along the axis).
    m_rows: [[f64; 3]; 3],
    rate_cols: Vec<(Effect, u16, [f64; 3])>,
    /// Per stretch and knot spacing of [`DRIFT_KNOT_SPACINGS_S`]: the first knot's time, s, and
    /// knots per second.
    knot_grid: Vec<[(f64, f64); DRIFT_KNOT_SPACINGS_S.len()]>,
    /// Per run, the transmission error where its index pulse ties θ2 to 0.
    index_edge: Vec<IndexEdge>,
    /// The harmonic orders of the gear mesh's angle the model and the pass use.
    mesh_orders: Vec<usize>,
    /// sin θ/θ and (1 − cos θ)/θ² of the pose-2 fixture's turn θ = |e| (Rodrigues' formula).
    fixture_turn: [f64; 2],
    /// The model's linear columns, split for [`Evaluator::predict`].
    lin_plan: ColPlan,
    /// The coefficients of `lin_plan.dense` on the three axes.
    lin_beta: Vec<[f64; 3]>,
    /// Whether the points need the base's heading θ1 (a sine and cosine per sample): only Earth's
    /// horizontal components turn with it.
    needs_heading: bool,
    /// Whether the points need the pose-2 fixture's Jacobian.
    needs_fixture: bool,
    /// Whether the model moves no angle or rate and the pass needs no shared column's
    /// Jacobian: the points are then eq. 1-2 alone ([`Evaluator::plain_point`]), which is every
    /// pass of a calibration whose residual the linear model already explains.
    plain: bool,
    /// Whether the points need the die temperature: only the temperature drift's column uses it,
    /// and computing it for every point of every pass made the 1-h replay ~9 % slower.
    needs_temperature: bool,
    /// Whether a column is a free-drift knot: only those read a point's place on the knot grids.
    needs_knots: bool,
    /// The smoothed temperatures of the run the last point was in (every pass visits a run's
    /// samples forward, and each run after the other).
    temperatures: std::cell::RefCell<Option<RunTemperatures<'a>>>,
}

impl<'a> Evaluator<'a> {
    /// An evaluator at the model's current values, for the model's own columns, whose points
    /// carry the die temperature whether a column needs it or not (the diagnostics test the
    /// residual against it, the drift table reports it).
    pub fn new(data: &'a LoopData, model: &'a Model) -> Self {
        Self { needs_temperature: true, ..Self::for_columns(data, model, &model.cols()) }
    }

    /// An evaluator at the model's current values whose points serve `cols` (and the model's
    /// own columns): what no column needs, a point leaves out (NaN), so a pass pays only for
    /// the Jacobians it uses.
    pub fn for_columns(data: &'a LoopData, model: &'a Model, cols: &[Col]) -> Self {
        let needs = model.cols().iter().chain(cols).fold(Needs::NONE, |n, c| n.or(c.needs()));
        let plain = model.shared.is_empty()
            && model.earth_vertical_known_dps == 0.0
            && !cols.iter().any(|c| matches!(c, Col::Shared(_)));
        let m = model.m();
        let rate_cols = model
            .lin
            .iter()
            .filter_map(|&c| match c {
                LinCol::Of(e, k) if !c.is_common() => {
                    Some((e, k, std::array::from_fn(|a| model.beta_of(a, c).unwrap_or(0.0))))
                }
                _ => None,
            })
            .collect();
        let lin_plan = ColPlan::of(model.lin.iter().map(|&c| Col::Lin(c)));
        let lin_beta = lin_plan.dense.iter().map(|&(j, _)| model.beta.each_ref().map(|b| b[j])).collect();
        let shifts = shifts_of(model);
        let index_edge = data
            .kin
            .runs
            .iter()
            .map(|rk| {
                let ripple = shifts.ripple.iter().filter(|h| h.1 == rk.pose).map(|&(n, _, a, b)| (n, a, b));
                IndexEdge::new(rk.plate_half_width_rad, rk.steady_rate_dps.to_radians(), shifts.gear_lag_s, ripple)
            })
            .collect();
        let mut mesh_orders: Vec<usize> = shifts.ripple.iter().map(|h| h.0 as usize).collect();
        mesh_orders.extend(cols.iter().filter_map(|c| match c {
            Col::Shared(SharedPar { effect: Effect::TableHarmonic(n), .. }) => Some(*n as usize),
            _ => None,
        }));
        mesh_orders.sort_unstable();
        mesh_orders.dedup();
        Self {
            data,
            model,
            fixture_turn: rodrigues(&shifts.fixture_rad),
            shifts,
            index_edge,
            mesh_orders,

            rot_t: data
                .kin
                .runs
                .iter()
                .map(|r| std::array::from_fn(|i| std::array::from_fn(|j| r.rot_t[(i, j)])))
                .collect(),
            s_hat: model.s_hat.map(|v| [v[0], v[1], v[2]]),
            m_rows: std::array::from_fn(|a| [m[(a, 0)], m[(a, 1)], m[(a, 2)]]),
            rate_cols,
            knot_grid: (0..data.layout.stretches.len())
                .map(|st| std::array::from_fn(|k| data.layout.knot_grid(st, DRIFT_KNOT_SPACINGS_S[k])))
                .collect(),
            lin_plan,
            lin_beta,
            needs_heading: needs.heading,
            needs_fixture: needs.fixture,
            plain,
            needs_temperature: needs.temperature,
            needs_knots: model
                .lin
                .iter()
                .map(|&c| Col::Lin(c))
                .chain(cols.iter().copied())
                .any(|c| matches!(c, Col::Lin(LinCol::DriftKnot { .. }))),
            temperatures: Default::default(),
        }
    }

    /// The smoothed die temperature at sample `i` of run `r`, °C from the capture mean, if the
    /// model or pass reads it (NaN otherwise, as a point has it then).
    fn temperature_c(&self, r: usize, i: usize) -> f32 {
        let mut t = f32::NAN;
        self.temperatures_c(r, i..i + 1, std::slice::from_mut(&mut t));
        t
    }

    /// [`Evaluator::temperature_c`] of samples `range` of run `r`, into `out`.
    fn temperatures_c(&self, r: usize, range: std::ops::Range<usize>, out: &mut [f32]) {
        if !self.needs_temperature {
            return;
        }
        let rk = &self.data.kin.runs[r];
        let mut temps = self.temperatures.borrow_mut();
        let temps = match &mut *temps {
            Some(t) if std::ptr::eq(t.run, rk) => t,
            other => other.insert(RunTemperatures::new(rk, self.data.temp_mean_counts)),
        };
        for (t, i) in out.iter_mut().zip(range) {
            *t = temps.at(i);
        }
    }

    /// The kinematics at sample `i` of run `r`.
    #[inline]
    pub fn point(&self, r: usize, i: usize) -> Point {
        self.point_with(r, i, self.data.kin.runs[r].samples.get(i))
    }

    /// [`Evaluator::point`] of sample `s`, sample `i` of run `r` (a pass reads its counts too).
    #[inline]
    pub fn point_with(&self, r: usize, i: usize, s: KinSample) -> Point {
        if self.plain {
            let sin_cos = libm::sincos(s.theta2_rad());
            self.plain_point(r, SampleInputs { s, sin_cos, temp_c: self.temperature_c(r, i) })
        } else {
            self.full_point(r, i, s)
        }
    }

    /// [`Evaluator::point`] of a model that moves angles or rates, or of a pass that wants the
    /// shared parameters' Jacobians.
    #[inline(never)]
    fn full_point(&self, r: usize, i: usize, s: KinSample) -> Point {
        let rk = &self.data.kin.runs[r];
        let sh = &self.shifts;
        let (theta2, rate1) = interpolate(&rk.samples, i, sh.delay_s);
        let th = theta2 + sh.theta2_offset_rad;
        // The transmission error is periodic in the mesh angle, which moves with the table
        // against the index (1:1 gears): the index-referenced θ2, lagging by the gear lag. The
        // index offset does not move it (the error is tied to the gear, not to where θ2 = 0 is).
        let theta1_rate_rad_s = rate1.to_radians();
        let mesh_sin_cos = self.mesh_harmonics(theta2 + sh.gear_lag_s * theta1_rate_rad_s);
        let (th_eff, ripple, dripple) = transmission(sh, rk.pose, th, &mesh_sin_cos, &self.index_edge[r]);
        let rate2 = rk.gear_ratio * rate1;
        let rate2_eff = rate2 * ripple;
        let rt = &self.rot_t[r];
        // The pose-2 fixture turned by e: R2 → exp([e]×)·R2, so a table-frame vector v reaches
        // the package as R2ᵀ·exp(−[e]×)·v, exactly ([`rodrigues`]): to first order only, a 1° turn
        // left e²/2 = 150 ppm to a spurious table tilt (97 ppm, 3.8σ off on the trust bench).
        let (e, [a, b]) = if rk.pose == Pose::Two { (sh.fixture_rad, self.fixture_turn) } else { ([0.0; 3], [0.0; 2]) };
        let to_package = |v: &[f64; 3]| -> [f64; 3] {
            let f = turn(&e, v, -1.0, (a, b));
            std::array::from_fn(|i| rt[i][0] * f[0] + rt[i][1] * f[1] + rt[i][2] * f[2])
        };
        // ω2 (EXCITER.md eq. 1) and its derivative in θ2, taken to the package frame.
        // The `libm` crate's sincos, as the plain point's: a quarter cheaper than glibc's here.
        let (se, ce) = libm::sincos(th_eff);
        // A table axis tilted by ε from perpendicular puts θ1'·sin ε along z2 and scales the
        // in-plane part by cos ε: 1 − ε²/2 is 14 ppm at 0.3°, which every sensitivity would take.
        let (sin_tilt, cos_tilt) = sh.tilt_sin_cos;
        let rate1_in_plane = rate1 * cos_tilt;
        let w2 = protocol::exciter::table_rate(rate1_in_plane, (se, ce), rate2_eff + rate1 * sin_tilt);
        let mut dw2 = [rate1_in_plane * ce, -rate1_in_plane * se, 0.0];
        // ω̈ of the table motion at steady speed (Earth's part is 1e-5 of it): the θ1' sinusoid
        // turns at θ2', so its second derivative is −θ2'²·(θ1' sin θ2, θ1' cos θ2, 0).
        let w2_rad_s = rate2.to_radians();
        let w2_ddot = [-w2_rad_s * w2_rad_s * w2[0], -w2_rad_s * w2_rad_s * w2[1], 0.0];
        let d_filter = to_package(&w2_ddot);
        let filter_dw2 = dw2;
        // Earth's rate in the table frame O2, per unit of each component (module docs of
        // `earth_basis`), added to ω2.
        // The base's heading in the lab: the sensor table is geared to a shaft fixed to the
        // ground (EXCITER.md, "Mechanism"), so θ2 = ratio·θ1_lab + const and the index fixes the
        // heading for every run, while the encoder's count restarts with each capture.
        // (Each angle's sine and cosine once: they were 4 of the 5 libm calls a point made.)
        // Without a horizontal Earth term in the pass the heading multiplies zeros only.
        let (s1, c1) = if self.needs_heading { (theta2 / rk.gear_ratio).sin_cos() } else { (0.0, 0.0) };
        let basis = earth_basis((s1, c1), (se, ce));
        let [ev, en, ew] = sh.earth_dps;
        let w2: [f64; 3] = std::array::from_fn(|i| w2[i] + ev * basis[0][i] + en * basis[1][i] + ew * basis[2][i]);
        // The lab-fixed rate turns with θ2 too: ∂(basis)/∂θ2.
        let d_basis = [[ce, -se, 0.0], [s1 * se, s1 * ce, 0.0], [-c1 * se, -c1 * ce, 0.0]];
        for (i, d) in dw2.iter_mut().enumerate() {
            *d += ev * d_basis[0][i] + en * d_basis[1][i] + ew * d_basis[2][i];
        }
        let d_earth = if self.needs_heading {
            [to_package(&basis[0]), to_package(&basis[1]), to_package(&basis[2])]
        } else {
            [to_package(&basis[0]), [f64::NAN; 3], [f64::NAN; 3]]
        };
        let d_fixture = match (self.needs_fixture, rk.pose) {
            (false, _) => [[f64::NAN; 3]; 3],
            (true, Pose::Two) => fixture_jacobian(
                rt,
                &std::array::from_fn(|i| w2[i] + sh.filter_s2 * w2_ddot[i]),
                &sh.fixture_rad,
                self.fixture_turn,
            ),
            (true, _) => [[0.0; 3]; 3],
        };
        let omega = to_package(&w2);
        let omega: [f64; 3] = std::array::from_fn(|i| omega[i] + sh.filter_s2 * d_filter[i]);
        // The filter's ω̈ term turns with θ2 as the sinusoid does, scaled by −κ·θ2'².
        let filter_scale = 1.0 - sh.filter_s2 * w2_rad_s * w2_rad_s;
        let d_theta2: [f64; 3] = {
            let (a, b) = (to_package(&filter_dw2), to_package(&dw2));
            std::array::from_fn(|i| filter_scale * a[i] + (b[i] - a[i]))
        };
        let d_rate2 = to_package(&[0.0, 0.0, 1.0]);
        Point {
            omega,
            d_theta2,
            d_rate2,
            theta2_rad: th,
            rate2_dps: rate2,
            rate2_eff_dps: rate2_eff,
            dtheta_eff: ripple,
            drate_eff_dps: rate2 * dripple,
            mesh_sin_cos,
            pose: rk.pose,
            d_earth,
            d_filter,
            d_fixture,
            d_tilt: to_package(&[-rate1 * sin_tilt * se, -rate1 * sin_tilt * ce, 0.0]),
            cos_tilt,
            theta1_rate_rad_s,
            theta1_rate_dps: rate1,
            ..self.when(r, i, s.t_s())
        }
    }

    /// A point with only where the sample lies in time set (its run, times, temperature and
    /// place on the knot grids), every kinematic field NaN: what every point shares.
    #[inline]
    fn when(&self, r: usize, i: usize, t_s: f64) -> Point {
        let mut p = self.of_run(r, t_s);
        self.refresh_when(t_s, self.temperature_c(r, i), &mut p);
        p
    }

    /// A point of run `r` with every field NaN but its run's and the time `t_s`.
    #[inline]
    fn of_run(&self, r: usize, t_s: f64) -> Point {
        let nan3 = [f64::NAN; 3];
        Point {
            omega: nan3,
            d_theta2: nan3,
            d_rate2: nan3,
            theta2_rad: f64::NAN,
            rate2_dps: f64::NAN,
            rate2_eff_dps: f64::NAN,
            dtheta_eff: f64::NAN,
            drate_eff_dps: f64::NAN,
            t_rel_s: f64::NAN,
            t_scaled: f64::NAN,
            temp_c: f64::NAN,
            mesh_sin_cos: [(f64::NAN, f64::NAN); MAX_HARMONIC_ORDER + 1],
            pose: self.data.kin.runs[r].pose,
            d_earth: [nan3; 3],
            d_filter: nan3,
            d_fixture: [nan3; 3],
            d_tilt: nan3,
            cos_tilt: f64::NAN,
            theta1_rate_rad_s: f64::NAN,
            theta1_rate_dps: f64::NAN,
            run: r,
            t_s,
            stretch: self.data.layout.run_stretch[r],
            knot_x: [f64::NAN; DRIFT_KNOT_SPACINGS_S.len()],
        }
    }

    /// The fields of [`Evaluator::when`] that change from sample to sample of a run
    /// (`temp_c` is [`Evaluator::temperature_c`] of the sample).
    #[inline]
    fn refresh_when(&self, t_s: f64, temp_c: f32, p: &mut Point) {
        p.t_rel_s = t_s - self.data.t0_s;
        p.t_scaled = (t_s - self.data.t_mid_s) / self.data.t_half_s;
        p.temp_c = f64::from(temp_c);
        p.t_s = t_s;
        if self.needs_knots {
            let grid = &self.knot_grid[p.stretch];
            p.knot_x = std::array::from_fn(|k| (t_s - grid[k].0) * grid[k].1);
        }
    }

    /// [`Evaluator::point`] of a model that moves no angle or rate, when no shared column is
    /// wanted: ω_s of eq. 1-2 and gravity's direction, each the same number the full point
    /// gives (every shift it would add is an exact zero); the Jacobians of the shared
    /// parameters are NaN. A third of a plain pass's time was spent on them.
    #[inline]
    fn plain_point(&self, r: usize, inputs: SampleInputs) -> Point {
        let mut p = Point { dtheta_eff: 1.0, drate_eff_dps: 0.0, cos_tilt: 1.0, ..self.of_run(r, inputs.s.t_s()) };
        self.refresh_plain(inputs, &mut p);
        p
    }

    /// The fields of [`Evaluator::plain_point`] that change from sample to sample of a run
    /// (`p` holds one of the run's plain points).
    #[inline]
    fn refresh_plain(&self, SampleInputs { s, sin_cos: (se, ce), temp_c }: SampleInputs, p: &mut Point) {
        let r = p.run;
        let rk = &self.data.kin.runs[r];
        let (th, rate1) = (s.theta2_rad(), s.theta1_rate_dps());
        let rate2 = rk.gear_ratio * rate1;
        let rt = &self.rot_t[r];
        let to_package =
            |v: &[f64; 3]| -> [f64; 3] { std::array::from_fn(|i| rt[i][0] * v[0] + rt[i][1] * v[1] + rt[i][2] * v[2]) };
        p.omega = to_package(&protocol::exciter::table_rate(rate1, (se, ce), rate2));
        p.theta2_rad = th;
        p.rate2_dps = rate2;
        p.rate2_eff_dps = rate2;
        p.d_earth[0] = to_package(&earth_basis((0.0, 0.0), (se, ce))[0]);
        p.theta1_rate_rad_s = rate1.to_radians();
        p.theta1_rate_dps = rate1;
        self.refresh_when(s.t_s(), temp_c, p);
    }

    /// Sample `i` of run `r` and its [`Evaluator::point`], through the `cursor` a pass keeps
    /// from sample to sample: a plain point of the same run is refreshed in place rather than
    /// built whole (a point is ~450 bytes, most of them NaN or the run's in a plain pass;
    /// building it per sample cost a 1-h replay 5 %), and its θ2's sine and cosine come from a
    /// batch computed ahead ([`super::sincos`]).
    #[inline(always)]
    pub fn visit<'c>(&self, r: usize, i: usize, cursor: &'c mut Cursor) -> (KinSample, &'c Point) {
        let samples = &self.data.kin.runs[r].samples;
        if !self.plain {
            let s = samples.get(i);
            return (s, cursor.point.insert(self.full_point(r, i, s)));
        }
        let inputs = cursor.ahead.at(self, r, samples, i);
        let p = cursor.point.get_or_insert_with(|| self.plain_point(r, inputs));
        if p.run == r {
            self.refresh_plain(inputs, p);
        } else {
            *p = self.plain_point(r, inputs);
        }
        (inputs.s, p)
    }

    /// θ2 at sample `i` of run `r` as [`Evaluator::point`] gives it (`Point::theta2_rad`),
    /// without the rest of the point (the diagnostics' second pass needs only this).
    pub fn theta2_at(&self, r: usize, i: usize) -> f64 {
        interpolate(&self.data.kin.runs[r].samples, i, self.shifts.delay_s).0 + self.shifts.theta2_offset_rad
    }

    /// Rate along axis `a`, °/s.
    #[inline]
    pub fn axis_rate(&self, p: &Point, a: usize) -> f64 {
        dot(&self.s_hat[a], &p.omega)
    }

    /// sin and cos of the harmonics of mesh angle `mesh_rad` that the model and the pass use
    /// (NaN for the others): one `sincos` per order, or the recurrence of [`harmonics_of`] when
    /// more than a few orders are in use (a candidate pass over every order).
    #[inline]
    fn mesh_harmonics(&self, mesh_rad: f64) -> MeshHarmonics {
        if self.mesh_orders.len() > 4 {
            return harmonics_of(mesh_rad);
        }
        let mut h = [(f64::NAN, f64::NAN); MAX_HARMONIC_ORDER + 1];
        for &n in &self.mesh_orders {
            h[n] = libm::sincos(n as f64 * mesh_rad);
        }
        h
    }

    /// What of the model an effect's column reads.
    #[inline]
    fn cx(&self) -> Ctx<'_> {
        Ctx {
            shifts: &self.shifts,
            index_edge: &self.index_edge,
            s_hat: &self.s_hat,
            lin: &self.model.lin,
            beta: &self.model.beta,
        }
    }

    /// A linear column's value on axis `a`.
    #[inline]
    pub fn lin_value(&self, c: LinCol, p: &Point, a: usize) -> f64 {
        match c {
            LinCol::Omega(k) => p.omega[k],
            LinCol::One => 1.0,
            LinCol::Of(e, k) => self.effect_value(e, Own::Lin(k), p, a, &AxisTerms::UNUSED),
            LinCol::DriftExpFixed(t) => decay(p.t_rel_s, t),
            LinCol::DriftKnot { stretch, knot, spacing_s } => {
                if p.stretch != usize::from(stretch) {
                    return 0.0;
                }
                let x = match DRIFT_KNOT_SPACINGS_S.iter().position(|&d| d == spacing_s) {
                    Some(k) => p.knot_x[k],
                    None => {
                        let (t0, per_s) = self.data.layout.knot_grid(p.stretch, spacing_s);
                        (p.t_s - t0) * per_s
                    }
                };
                (1.0 - (x - f64::from(knot)).abs()).max(0.0)
            }
        }
    }

    /// The model's output on axis `a`, counts.
    #[inline]
    pub fn predict(&self, p: &Point, a: usize) -> f64 {
        let mut common = Vec::new();
        self.predict3(p, &mut common)[a]
    }

    /// The model's output on every axis, counts (the axis-independent columns once; `common`
    /// is scratch space a pass reuses from sample to sample).
    #[inline]
    pub fn predict3(&self, p: &Point, common: &mut Vec<f64>) -> [f64; 3] {
        self.common_values(p, &self.lin_plan, common);
        self.predict3_with(p, common)
    }

    /// [`Evaluator::predict3`] with the model's axis-independent column values at `p` given
    /// (`common_values` of `lin_plan`). The three axes side by side: each axis's terms are
    /// added in the column order, as one axis at a time did, but the plan is walked once.
    #[inline]
    fn predict3_with(&self, p: &Point, common: &[f64]) -> [f64; 3] {
        let mut sum = [0.0; 3];
        if self.lin_plan.all_common {
            for (beta, &v) in self.lin_beta.iter().zip(common) {
                for (s, b) in sum.iter_mut().zip(beta) {
                    *s += b * v;
                }
            }
            return sum;
        }
        for ((kernel, beta), &v) in self.lin_plan.kernels.iter().zip(&self.lin_beta).zip(common) {
            match *kernel {
                Kernel::PerAxis(Col::Lin(lc)) => {
                    for (a, s) in sum.iter_mut().enumerate() {
                        *s += beta[a] * self.lin_value(lc, p, a);
                    }
                }
                Kernel::PerAxis(Col::Shared(_)) => {}
                _ => {
                    for (s, b) in sum.iter_mut().zip(beta) {
                        *s += b * v;
                    }
                }
            }
        }
        if !self.lin_plan.knots.is_empty() {
            let beta = &self.model.beta;
            self.for_each_knot(&self.lin_plan, p, |j, w| {
                for (s, b) in sum.iter_mut().zip(beta) {
                    *s += b[j] * w;
                }
            });
        }
        sum
    }

    /// The values at `p` of `plan`'s axis-independent columns, by position in `plan.dense`
    /// (0 for the others).
    #[inline]
    fn common_values(&self, p: &Point, plan: &ColPlan, out: &mut Vec<f64>) {
        out.clear();
        out.extend(plan.kernels.iter().map(|k| match *k {
            Kernel::Omega(k) => p.omega[k],
            Kernel::One => 1.0,
            Kernel::Common(lc) => self.lin_value(lc, p, 0),
            Kernel::PerAxis(_) => 0.0,
        }));
    }

    /// The knots of `plan` under point `p`, with their hat functions' values (the
    /// [`LinCol::DriftKnot`] arm of [`Evaluator::lin_value`], for the two that can be non-zero).
    #[inline]
    fn for_each_knot(&self, plan: &ColPlan, p: &Point, mut f: impl FnMut(usize, f64)) {
        for g in plan.knots.iter().filter(|g| g.stretch == p.stretch) {
            let x = match g.spacing_index {
                Some(k) => p.knot_x[k],
                None => {
                    let (t0, per_s) = self.data.layout.knot_grid(p.stretch, g.spacing_s);
                    (p.t_s - t0) * per_s
                }
            };
            let below = x.floor();
            for k in [below, below + 1.0] {
                let w = (1.0 - (x - k).abs()).max(0.0);
                if k < 0.0 || w == 0.0 {
                    continue;
                }
                if let Some(&Some(j)) = g.at.get(k as usize) {
                    f(j, w);
                }
            }
        }
    }

    /// ∂(output of axis a)/∂ω_s, counts per °/s.
    #[inline]
    fn gradient(&self, p: &Point, a: usize) -> [f64; 3] {
        let r = self.axis_rate(p, a);
        let mut g = 0.0;
        for &(e, k, beta) in &self.rate_cols {
            g += beta[a] * e.behaviour(|b| b.rate_slope(k, r)).unwrap_or(0.0);
        }
        std::array::from_fn(|i| self.m_rows[a][i] + self.s_hat[a][i] * g)
    }

    /// The per-axis factors of the shared columns at `p`.
    #[inline]
    fn axis_terms(&self, p: &Point, a: usize) -> AxisTerms {
        let u = self.gradient(p, a);
        let (e2, ez) = (dot(&u, &p.d_theta2), dot(&u, &p.d_rate2));
        AxisTerms { u, e2, ez, d_shift: e2 * p.dtheta_eff + ez * p.drate_eff_dps }
    }

    /// A column's value on axis `a` at `p`; knots are evaluated through [`ColPlan`].
    #[inline]
    fn column_value(&self, c: Col, p: &Point, a: usize, t: &AxisTerms) -> f64 {
        match c {
            Col::Lin(lc) => self.lin_value(lc, p, a),
            Col::Shared(sp) => self.effect_value(sp.effect, Own::Shared(sp.k), p, a, t),
        }
    }

    /// An effect's column at `p` on axis `a` (`Behaviour::value`). Kept out of line: the
    /// dispatch over every effect would stop the base columns' arms of [`Evaluator::lin_value`]
    /// from being inlined into the passes.
    #[inline(never)]
    fn effect_value(&self, e: Effect, own: Own, p: &Point, a: usize, t: &AxisTerms) -> f64 {
        e.behaviour(|b| b.value(own, p, a, t, &self.cx()))
    }

    /// Fills `out[a * cols.len() + j]` with column j on axis a.
    pub fn fill(&self, p: &Point, cols: &[Col], out: &mut [f64]) {
        let l = cols.len();
        for a in 0..3 {
            let t = self.axis_terms(p, a);
            for (j, &c) in cols.iter().enumerate() {
                out[a * l + j] = self.column_value(c, p, a, &t);
            }
        }
    }

    /// Every column of a knot-free `plan` on axis `a` at `p`, by position: what
    /// [`Evaluator::fill`] gives. `common` holds `plan`'s axis-independent values at `p`
    /// (`common_values`).
    fn fill_dense(&self, p: &Point, plan: &ColPlan, a: usize, common: &[f64], out: &mut [f64]) {
        let t = if plan.has_shared { self.axis_terms(p, a) } else { AxisTerms::UNUSED };
        for ((kernel, &v), x) in plan.kernels.iter().zip(common).zip(out.iter_mut()) {
            *x = match *kernel {
                Kernel::PerAxis(c) => self.column_value(c, p, a, &t),
                _ => v,
            };
        }
    }
}

/// A lab-fixed rate in the table frame O2, per unit of its components: along the base axis z1
/// (vertical), and the two horizontal directions where the base points at θ2 = 0 and 90° on.
/// EXCITER.md eq. 1 puts z1 at (sin θ2, cos θ2, 0) in O2; the base's horizontal pair there is
/// e_z2 = (0, 0, 1) and u = z1 × z2 = (cos θ2, −sin θ2, 0), right-handed as (e_z2, u, z1). A
/// lab-fixed horizontal vector at azimuth ψ lies at ψ − θ1 in the base frame, cos(ψ−θ1)·e_z2 +
/// sin(ψ−θ1)·u; expanding in cos ψ and sin ψ gives the two horizontal columns. θ1 is the
/// base's heading, θ2/ratio (the ground-geared table ties it to the index), θ2 the table angle.
/// Takes (sin, cos) of θ1 and of θ2.
#[inline]
fn earth_basis((s1, c1): (f64, f64), (s2, c2): (f64, f64)) -> [[f64; 3]; 3] {
    [[s2, c2, 0.0], [-s1 * c2, s1 * s2, c1], [c1 * c2, -c1 * s2, s1]]
}

/// a × b.
#[inline]
fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// w ± p·e × w + q·e × (e × w): exp(±[e]×)·w with (p, q) = (a, b) of [`rodrigues`], or the
/// rotation's left Jacobian J·w (`sign` 1) with (b, (1 − a)/θ²).
#[inline]
fn turn(e: &[f64; 3], w: &[f64; 3], sign: f64, (p, q): (f64, f64)) -> [f64; 3] {
    let ew = cross(e, w);
    let eew = cross(e, &ew);
    std::array::from_fn(|i| w[i] + sign * p * ew[i] + q * eew[i])
}

/// sin θ/θ and (1 − cos θ)/θ² of the rotation vector `e` (θ = |e|): exp([e]×) = I + a·[e]× +
/// b·[e]×². Their series below 1e-4 rad, where the quotients lose digits.
fn rodrigues(e: &[f64; 3]) -> [f64; 2] {
    let t2 = e.iter().map(|x| x * x).sum::<f64>();
    if t2 < 1e-8 {
        return [1.0 - t2 / 6.0, 0.5 - t2 / 24.0];
    }
    let t = t2.sqrt();
    [t.sin() / t, (1.0 - t.cos()) / t2]
}

/// sin and cos of n·θ for n = 0..=MAX_HARMONIC_ORDER (one sin_cos): orders 2-4 from double and
/// triple angles, then four interleaved angle-addition recurrences h[n] = h[n−4]·h[4], which the
/// CPU runs side by side (a single chain of 32 dependent rotations was 16 % of `host calibrate`);
/// the rounding grows by an ulp per step, ~1e-14 at 32×. Only the diagnostics need all of them,
/// so the fit's passes do not pay for them.
pub fn harmonics_of(theta_rad: f64) -> [(f64, f64); MAX_HARMONIC_ORDER + 1] {
    const { assert!(MAX_HARMONIC_ORDER >= 4) };
    let (s1, c1) = theta_rad.sin_cos();
    let (s2, c2) = (2.0 * s1 * c1, c1 * c1 - s1 * s1);
    let (s3, c3) = (s2 * c1 + c2 * s1, c2 * c1 - s2 * s1);
    let (s4, c4) = (2.0 * s2 * c2, c2 * c2 - s2 * s2);
    let mut h = [(0.0, 1.0); MAX_HARMONIC_ORDER + 1];
    h[1..=4].copy_from_slice(&[(s1, c1), (s2, c2), (s3, c3), (s4, c4)]);
    for n in 5..=MAX_HARMONIC_ORDER {
        let (sp, cp) = h[n - 4];
        h[n] = (sp * c4 + cp * s4, cp * c4 - sp * s4);
    }
    h
}

/// Sums of one run (or several) for columns `l`: per axis the Gram matrix, Xᵀe, eᵀe and the
/// count, against the residual e of the model the pass was made at.
#[derive(Debug, Clone, PartialEq)]
pub struct Gram {
    /// Columns.
    pub l: usize,
    /// XᵀX per axis, l×l row-major (full after `symmetrise`).
    pub xtx: [Vec<f64>; 3],
    /// Xᵀe per axis.
    pub xte: [Vec<f64>; 3],
    /// eᵀe per axis, counts².
    pub ete: [f64; 3],
    /// Unclipped samples per axis.
    pub n: [u64; 3],
}

impl Gram {
    fn new(l: usize) -> Self {
        Self {
            l,
            xtx: std::array::from_fn(|_| vec![0.0; l * l]),
            xte: std::array::from_fn(|_| vec![0.0; l]),
            ete: [0.0; 3],
            n: [0; 3],
        }
    }

    /// Adds the sums of `local` whose rows and columns are all in `rows` (every other entry of
    /// it is zero) and zeroes them in `local`: a chunk touches a few of a long capture's
    /// hundreds of knot columns, and merging and clearing the whole l×l matrix per chunk was
    /// most of a pass (the sums are the same, bit for bit).
    fn drain_rows(&mut self, local: &mut Gram, rows: &[usize]) {
        let l = self.l;
        for a in 0..3 {
            for &r in rows {
                self.xte[a][r] += std::mem::take(&mut local.xte[a][r]);
                for &c in rows.iter().filter(|&&c| c >= r) {
                    self.xtx[a][r * l + c] += std::mem::take(&mut local.xtx[a][r * l + c]);
                }
            }
            self.ete[a] += std::mem::take(&mut local.ete[a]);
            self.n[a] += std::mem::take(&mut local.n[a]);
        }
    }

    /// Adds another set of sums.
    pub fn merge(&mut self, o: &Gram) {
        for a in 0..3 {
            self.xtx[a].iter_mut().zip(&o.xtx[a]).for_each(|(x, y)| *x += y);
            self.xte[a].iter_mut().zip(&o.xte[a]).for_each(|(x, y)| *x += y);
            self.ete[a] += o.ete[a];
            self.n[a] += o.n[a];
        }
    }

    fn symmetrise(&mut self) {
        let l = self.l;
        for m in &mut self.xtx {
            for i in 0..l {
                for j in 0..i {
                    m[i * l + j] = m[j * l + i];
                }
            }
        }
    }

    /// Sum of several.
    pub fn sum<'g>(grams: impl IntoIterator<Item = &'g Gram>) -> Option<Gram> {
        let mut it = grams.into_iter();
        let mut total = it.next()?.clone();
        for g in it {
            total.merge(g);
        }
        Some(total)
    }
}

/// Adds Σ xᵢ·xⱼ over `rows` (each `l` column values) to the upper triangle of the l×l `xtx`,
/// for j < `reach[i]` ([`Reach`]), each sum taking the rows in order (so the sums are the same
/// however the pairs are grouped). Four consecutive columns i with the same reach share their
/// pass over the rows: a 4×4 tile of sums in registers, 16 independent chains, where one row of
/// four sums waited on its own previous add (the fold was 47 % of `host calibrate`). Only the
/// upper triangle of `xtx` is read ([`Gram::drain_rows`], [`Gram::symmetrise`]).
fn add_row_products<'r>(xtx: &mut [f64], l: usize, reach: &[usize], rows: impl Iterator<Item = &'r [f64]> + Clone) {
    const T: usize = 4;
    let mut ii = 0;
    while ii < l {
        let end = reach[ii];
        if ii + T <= end && reach[ii..ii + T].iter().all(|&e| e == end) {
            // The tile on the diagonal sums its lower triangle too, which nothing reads.
            let mut jj = ii;
            while jj + T <= end {
                add_tile(xtx, l, ii, jj, rows.clone());
                jj += T;
            }
            for k in ii..ii + T {
                add_pairs(xtx, l, k, jj..end, rows.clone());
            }
            ii += T;
        } else {
            add_pairs(xtx, l, ii, ii..end, rows.clone());
            ii += 1;
        }
    }
}

/// Adds Σ xᵢ·xⱼ for i = `ii`, j in `js`, four j side by side.
#[inline]
fn add_pairs<'r>(
    xtx: &mut [f64],
    l: usize,
    ii: usize,
    js: std::ops::Range<usize>,
    rows: impl Iterator<Item = &'r [f64]> + Clone,
) {
    let mut jj = js.start;
    while jj < js.end {
        let w = (js.end - jj).min(4);
        let mut acc = [0.0f64; 4];
        acc[..w].copy_from_slice(&xtx[ii * l + jj..ii * l + jj + w]);
        for row in rows.clone() {
            let xi = row[ii];
            for (s, &xj) in acc.iter_mut().zip(&row[jj..jj + w]) {
                *s += xi * xj;
            }
        }
        xtx[ii * l + jj..ii * l + jj + w].copy_from_slice(&acc[..w]);
        jj += w;
    }
}

/// Adds Σ xᵢ·xⱼ for the 4×4 tile i in `ii..ii + 4`, j in `jj..jj + 4`.
#[inline]
fn add_tile<'r>(xtx: &mut [f64], l: usize, ii: usize, jj: usize, rows: impl Iterator<Item = &'r [f64]>) {
    let mut acc = [[0.0f64; 4]; 4];
    for (r, a) in acc.iter_mut().enumerate() {
        a.copy_from_slice(&xtx[(ii + r) * l + jj..(ii + r) * l + jj + 4]);
    }
    for row in rows {
        let xj: &[f64; 4] = row[jj..jj + 4].try_into().expect("four columns");
        let xi: &[f64; 4] = row[ii..ii + 4].try_into().expect("four columns");
        for (a, &x) in acc.iter_mut().zip(xi) {
            for (s, &y) in a.iter_mut().zip(xj) {
                *s += x * y;
            }
        }
    }
    for (r, a) in acc.iter().enumerate() {
        xtx[(ii + r) * l + jj..(ii + r) * l + jj + 4].copy_from_slice(a);
    }
}

/// Rows of one axis's columns and residuals, held until a block is full and then added to the
/// sums column pair by column pair: each sum still takes its rows one after the other, as a
/// per-row update did (the same sums bit for bit but for the sign of an exact zero), but from
/// registers, four columns side by side, rather than through memory, whose store-to-load
/// chain per entry was a third of a plain fit's pass.
struct RowBlock {
    l: usize,
    x: Vec<f64>,
    e: Vec<f64>,
    reach: Vec<usize>,
}

impl RowBlock {
    /// Rows held before they are summed (32 KiB of a 32-column list: the block stays in cache).
    const ROWS: usize = 128;

    fn new(reach: &Reach) -> Self {
        let l = reach.0.len();
        Self { l, x: Vec::with_capacity(l * Self::ROWS), e: Vec::with_capacity(Self::ROWS), reach: reach.0.clone() }
    }

    /// A new row with residual `e`: its `l` column values to fill.
    fn push(&mut self, e: f64) -> &mut [f64] {
        self.e.push(e);
        let at = self.x.len();
        self.x.resize(at + self.l, 0.0);
        &mut self.x[at..]
    }

    fn is_full(&self) -> bool {
        self.e.len() == Self::ROWS
    }

    /// Adds the rows to axis `a` of `g` (upper triangle) and empties the block.
    fn add_to(&mut self, g: &mut Gram, a: usize) {
        let l = self.l;
        if self.e.is_empty() {
            return;
        }
        add_row_products(&mut g.xtx[a], l, &self.reach, self.x.chunks_exact(l));
        let xte = &mut g.xte[a];
        for ii in 0..l {
            let mut s = xte[ii];
            for (row, &e) in self.x.chunks_exact(l).zip(&self.e) {
                s += row[ii] * e;
            }
            xte[ii] = s;
        }
        for &e in &self.e {
            g.ete[a] += e * e;
        }
        g.n[a] += self.e.len() as u64;
        self.x.clear();
        self.e.clear();
    }
}

/// The rows of a plan whose every column is axis-independent ([`ColPlan::all_common`], such as
/// the linear model's): one row of column values per sample for the three axes, each with its
/// own residual. While no clipped sample has entered the sums since they were last drained, the
/// three axes' XᵀX are the same numbers, so they are summed once and copied rather than three
/// times; otherwise each axis sums the rows it uses, in order, as
/// [`RowBlock`] does.
struct SharedRows {
    l: usize,
    reach: Vec<usize>,
    x: Vec<f64>,
    e: Vec<[f64; 3]>,
    /// Per row, the axes it counts for (a clipped axis leaves it out).
    used: Vec<[bool; 3]>,
    /// Whether a row leaves an axis out.
    clipped: bool,
}

impl SharedRows {
    fn new(reach: &Reach) -> Self {
        let rows = RowBlock::ROWS;
        let l = reach.0.len();
        Self {
            l,
            reach: reach.0.clone(),
            x: Vec::with_capacity(l * rows),
            e: Vec::with_capacity(rows),
            used: Vec::with_capacity(rows),
            clipped: false,
        }
    }

    /// A row of column values `x` with the residual `e[a]` on each axis with `used[a]`.
    fn push(&mut self, x: &[f64], e: [f64; 3], used: [bool; 3]) {
        // Element by element: a row is a few values, and `extend_from_slice` of a length known
        // only at run time is a `memcpy` call per row (2 % of a 1-h replay).
        for &v in &x[..self.l] {
            self.x.push(v);
        }
        self.e.push(e);
        self.used.push(used);
        self.clipped |= used.contains(&false);
    }

    fn is_full(&self) -> bool {
        self.e.len() == RowBlock::ROWS
    }

    /// Adds the rows to `g` (upper triangles) and empties the block. `same`: whether `g`'s
    /// three XᵀX are equal; it stays so unless a row left an axis out.
    fn add_to(&mut self, g: &mut Gram, same: &mut bool) {
        let l = self.l;
        if self.e.is_empty() {
            return;
        }
        *same &= !self.clipped;
        let axes = if *same { 1 } else { 3 };
        for a in 0..axes {
            let rows = self.x.chunks_exact(l).zip(&self.used).filter(move |(_, used)| used[a]).map(|(row, _)| row);
            add_row_products(&mut g.xtx[a], l, &self.reach, rows);
        }
        if *same {
            let [x0, x1, x2] = &mut g.xtx;
            x1.copy_from_slice(x0);
            x2.copy_from_slice(x0);
        }
        for a in 0..3 {
            let xte = &mut g.xte[a];
            for ii in 0..l {
                let mut s = xte[ii];
                for ((row, e), used) in self.x.chunks_exact(l).zip(&self.e).zip(&self.used) {
                    if used[a] {
                        s += row[ii] * e[a];
                    }
                }
                xte[ii] = s;
            }
            for (e, used) in self.e.iter().zip(&self.used) {
                if used[a] {
                    g.ete[a] += e[a] * e[a];
                    g.n[a] += 1;
                }
            }
        }
        self.x.clear();
        self.e.clear();
        self.used.clear();
        self.clipped = false;
    }
}

/// What a pass keeps from sample to sample for [`Evaluator::visit`].
#[derive(Debug, Clone, Default)]
pub struct Cursor {
    point: Option<Point>,
    ahead: Ahead,
}

/// Samples read ahead, per batch.
const AHEAD: usize = 64;

/// What a plain point takes from its sample: the sample, `libm::sincos` of its θ2 and its
/// smoothed temperature ([`Evaluator::temperature_c`]).
#[derive(Debug, Clone, Copy)]
struct SampleInputs {
    s: KinSample,
    sin_cos: (f64, f64),
    temp_c: f32,
}

/// [`SampleInputs`] of samples `start..start + samples.len()` of run `run`, computed a batch at
/// a time: the sines batched are 2-3× cheaper than a call each, and the temperature's moving
/// average, stepped through 64 samples, no longer stalls each sample's point on its division.
#[derive(Debug, Clone)]
struct Ahead {
    run: usize,
    start: usize,
    samples: Vec<KinSample>,
    theta2_rad: [f64; AHEAD],
    sin: [f64; AHEAD],
    cos: [f64; AHEAD],
    temp_c: [f32; AHEAD],
}

impl Default for Ahead {
    fn default() -> Self {
        let none = [f64::NAN; AHEAD];
        Self {
            run: usize::MAX,
            start: 0,
            samples: Vec::with_capacity(AHEAD),
            theta2_rad: none,
            sin: none,
            cos: none,
            temp_c: [f32::NAN; AHEAD],
        }
    }
}

impl Ahead {
    /// The inputs of sample `i` of run `run` (whose samples are `samples`), as `ev` takes them.
    #[inline(always)]
    fn at(&mut self, ev: &Evaluator, run: usize, samples: &KinSamples, i: usize) -> SampleInputs {
        if run != self.run || i < self.start || i - self.start >= self.samples.len() {
            self.read(ev, run, samples, i);
        }
        let k = i - self.start;
        SampleInputs { s: self.samples[k], sin_cos: (self.sin[k], self.cos[k]), temp_c: self.temp_c[k] }
    }

    /// The batch from sample `i` of run `run`.
    #[inline(never)]
    fn read(&mut self, ev: &Evaluator, run: usize, samples: &KinSamples, i: usize) {
        let end = (i + AHEAD).min(samples.len());
        self.samples.clear();
        self.samples.extend((i..end).map(|j| samples.get(j)));
        let n = self.samples.len();
        for (th, s) in self.theta2_rad.iter_mut().zip(&self.samples) {
            *th = s.theta2_rad();
        }
        super::sincos::sincos_into(&self.theta2_rad[..n], &mut self.sin[..n], &mut self.cos[..n]);
        ev.temperatures_c(run, i..end, &mut self.temp_c[..n]);
        (self.run, self.start) = (run, i);
    }
}

/// Which column pairs a pass sums: column i with columns j in i..`reach[i]` (and, by symmetry,
/// those with i). Every pair ([`Reach::all`]) for a fit; for candidates scored against a model,
/// the model's columns with every column and each candidate's with its own only
/// ([`Reach::blocks`]): a candidate's test needs no other candidate's columns, and summing
/// every pair of 35-133 candidate columns was 42 % of a calibration's CPU time.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reach(Vec<usize>);

impl Reach {
    /// Every pair of `l` columns.
    pub fn all(l: usize) -> Self {
        Self(vec![l; l])
    }

    /// The first `lead` columns (the model's) with every column, then each block of `blocks`
    /// (consecutive column counts: the candidates', in order) with itself.
    pub fn blocks(lead: usize, blocks: impl IntoIterator<Item = usize>) -> Self {
        let mut reach = Vec::new();
        let mut end = lead;
        for b in blocks {
            end += b;
            reach.extend(std::iter::repeat_n(end, b));
        }
        let l = end;
        Self(std::iter::repeat_n(l, lead).chain(reach).collect())
    }

    /// Whether the pair (i, j) is summed.
    #[inline(always)]
    fn pairs(&self, i: usize, j: usize) -> bool {
        i.max(j) < self.0[i.min(j)]
    }
}

/// The rows of a [`Gram`] a chunk of the sparse path has touched, so that only they are drained.
struct Touched {
    flags: Vec<bool>,
    rows: Vec<usize>,
}

impl Touched {
    fn new(l: usize) -> Self {
        Self { flags: vec![false; l], rows: Vec::with_capacity(l) }
    }

    #[inline]
    fn mark(&mut self, ii: usize) {
        if !self.flags[ii] {
            self.flags[ii] = true;
            self.rows.push(ii);
        }
    }

    fn clear(&mut self) {
        let Self { flags, rows } = self;
        rows.drain(..).for_each(|ii| flags[ii] = false);
    }
}

impl Gram {
    /// One sample of axis `a` with residual `e`: the sums of its non-zero knots `knots`
    /// (position, value) with themselves and with the other columns (values `row`, paired
    /// through `split`), for the pairs `reach` names; the other columns' own sums are
    /// [`KnotSplit`]'s.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn add_knots(
        &mut self,
        a: usize,
        knots: &[(usize, f64)],
        (split, row): (&KnotSplit, &[f64]),
        e: f64,
        reach: &Reach,
        touched: &mut Touched,
    ) {
        let l = self.l;
        let g = &mut self.xtx[a];
        for (k, &(jk, wk)) in knots.iter().enumerate() {
            touched.mark(jk);
            self.xte[a][jk] += wk * e;
            for &(p, at) in &split.pairs[jk] {
                g[at] += row[p] * wk;
            }
            for &(jj, wj) in &knots[k..] {
                if reach.pairs(jk, jj) {
                    g[jk.min(jj) * l + jk.max(jj)] += wk * wj;
                }
            }
        }
    }
}

/// The sums of a plan with free-drift knots. Its other columns ([`ColPlan::dense`]) are non-zero
/// at nearly every sample: they are summed a block of rows at a time, as the plan without knots
/// is ([`RowBlock`]), into a Gram of their own that a chunk's end adds to the pass's. The knots,
/// 2 of dozens per sample, are summed sample by sample against the rest. Every sum still takes
/// the samples in order. Summed together pair by pair through memory, sample by sample, the
/// two were half of `host calibrate`'s time once the drift had knots.
struct KnotSplit {
    /// Position of each of the plan's other columns in the pass's list (increasing).
    map: Vec<usize>,
    /// Per position in the pass's list (empty but for knots): the other columns the knot is
    /// summed with, as (index into `map`, index of the pair's sum in the upper triangle).
    pairs: Vec<Vec<(usize, usize)>>,
    blocks: [RowBlock; 3],
    /// Their sums since the chunk began.
    sums: Gram,
    knots: Vec<(usize, f64)>,
    any: bool,
}

impl KnotSplit {
    fn new(plan: &ColPlan, reach: &Reach) -> Self {
        let map: Vec<usize> = plan.dense.iter().map(|d| d.0).collect();
        let own = Reach(map.iter().map(|&c| map.partition_point(|&q| q < reach.0[c])).collect());
        let l = reach.0.len();
        let mut pairs = vec![Vec::new(); l];
        for &j in plan.knots.iter().flat_map(|g| g.at.iter().flatten()) {
            pairs[j] = map
                .iter()
                .enumerate()
                .filter(|&(_, &i)| reach.pairs(i, j))
                .map(|(p, &i)| (p, i.min(j) * l + i.max(j)))
                .collect();
        }
        Self {
            blocks: std::array::from_fn(|_| RowBlock::new(&own)),
            sums: Gram::new(map.len()),
            map,
            pairs,
            knots: Vec::new(),
            any: false,
        }
    }

    /// Sample `p` on axis `a` with residual `e` (`common` as for [`Evaluator::fill_dense`]).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn add(
        &mut self,
        ev: &Evaluator,
        (p, plan, common): (&Point, &ColPlan, &[f64]),
        a: usize,
        e: f64,
        local: &mut Gram,
        reach: &Reach,
        touched: &mut Touched,
    ) {
        let mut knots = std::mem::take(&mut self.knots);
        knots.clear();
        ev.for_each_knot(plan, p, |j, w| knots.push((j, w)));
        let row = self.blocks[a].push(e);
        ev.fill_dense(p, plan, a, common, row);
        let row = &self.blocks[a].x[self.blocks[a].x.len() - self.map.len()..];
        local.add_knots(a, &knots, (self, row), e, reach, touched);
        self.knots = knots;
        if self.blocks[a].is_full() {
            self.blocks[a].add_to(&mut self.sums, a);
        }
        self.any = true;
    }

    /// At a chunk's end: the other columns' sums into `local`, their rows marked `touched`.
    fn flush(&mut self, local: &mut Gram, touched: &mut Touched) {
        for (a, b) in self.blocks.iter_mut().enumerate() {
            b.add_to(&mut self.sums, a);
        }
        if !std::mem::take(&mut self.any) {
            return;
        }
        let (m, l) = (self.map.len(), local.l);
        for a in 0..3 {
            for (p, &i) in self.map.iter().enumerate() {
                local.xte[a][i] += std::mem::take(&mut self.sums.xte[a][p]);
                for (q, &j) in self.map.iter().enumerate().skip(p) {
                    local.xtx[a][i * l + j] += std::mem::take(&mut self.sums.xtx[a][p * m + q]);
                }
            }
            local.ete[a] += std::mem::take(&mut self.sums.ete[a]);
            local.n[a] += std::mem::take(&mut self.sums.n[a]);
        }
        for &i in &self.map {
            touched.mark(i);
        }
    }
}

/// One pass: per-run sums of `cols` against the residual of `model` (clipped samples left out of
/// their axis), every column pair.
pub fn accumulate(data: &LoopData, model: &Model, cols: &[Col]) -> Vec<Gram> {
    accumulate_pairs(data, model, cols, &Reach::all(cols.len()))
}

/// [`accumulate`] of the pairs `reach` names; every other entry of XᵀX is 0.
pub fn accumulate_pairs(data: &LoopData, model: &Model, cols: &[Col], reach: &Reach) -> Vec<Gram> {
    let ev = Evaluator::for_columns(data, model, cols);
    let l = cols.len();
    debug_assert_eq!(reach.0.len(), l);
    let plan = ColPlan::of(cols.iter().copied());
    let (mut common, mut model_common) = (Vec::with_capacity(l), Vec::new());
    // Without knots every column is in `plan.dense`, in column order.
    let dense = plan.knots.is_empty();
    debug_assert!(!dense || plan.dense.iter().enumerate().all(|(k, d)| d.0 == k));
    let mut block: [RowBlock; 3] = std::array::from_fn(|_| RowBlock::new(reach));
    let mut shared = SharedRows::new(reach);
    // A fit's pass and a step's lead with the model's own columns: their axis-independent values
    // are then the plan's first ones, computed once per sample rather than twice.
    let model_leads = ev.lin_plan.dense.len() <= plan.dense.len()
        && ev.lin_plan.dense.iter().zip(&plan.dense).all(|(m, c)| m.1 == c.1);
    // A model whose coefficients are all zero (the linear fit's one pass, from zero) predicts
    // an exact 0 at every sample: Σ 0·x over finite columns.
    let predicts_zero = model.beta.iter().flatten().all(|&b| b == 0.0);
    data.kin
        .runs
        .iter()
        .enumerate()
        .map(|(r, rk)| {
            let mut total = Gram::new(l);
            let mut local = Gram::new(l);
            let mut touched = Touched::new(l);
            let all_rows: Vec<usize> = (0..l).collect();
            let valid = &data.runs[r].valid;
            let mut cursor = Cursor::default();
            let mut split = (!dense).then(|| KnotSplit::new(&plan, reach));
            for start in (0..rk.samples.len()).step_by(CHUNK) {
                let end = (start + CHUNK).min(rk.samples.len());
                // `local` was drained: its three XᵀX are equal (zero).
                let mut same = true;
                for i in valid.indices_in(start, end) {
                    let (s, p) = ev.visit(r, i, &mut cursor);
                    ev.common_values(p, &plan, &mut common);
                    let pred = if predicts_zero {
                        [0.0; 3]
                    } else if model_leads {
                        ev.predict3_with(p, &common[..ev.lin_plan.dense.len()])
                    } else {
                        ev.common_values(p, &ev.lin_plan, &mut model_common);
                        ev.predict3_with(p, &model_common)
                    };
                    if plan.all_common {
                        let used = s.rate_counts.map(|c| !is_clipped(c));
                        let e: [f64; 3] = std::array::from_fn(|a| f64::from(s.rate_counts[a]) - pred[a]);
                        shared.push(&common, e, used);
                        if shared.is_full() {
                            shared.add_to(&mut local, &mut same);
                        }
                        continue;
                    }
                    for (a, &count) in s.rate_counts.iter().enumerate() {
                        if is_clipped(count) {
                            continue;
                        }
                        let e = f64::from(count) - pred[a];
                        // Each pair goes to the upper triangle (`symmetrise` fills the rest).
                        if dense {
                            // Every column at every sample, in column order, the rows summed a
                            // block at a time.
                            ev.fill_dense(p, &plan, a, &common, block[a].push(e));
                            if block[a].is_full() {
                                block[a].add_to(&mut local, a);
                            }
                            continue;
                        }
                        // With knots: the rest a block at a time, the knots sample by sample.
                        if let Some(split) = split.as_mut() {
                            split.add(&ev, (p, &plan, &common), a, e, &mut local, reach, &mut touched);
                        }
                    }
                }
                for (a, b) in block.iter_mut().enumerate() {
                    b.add_to(&mut local, a);
                }
                shared.add_to(&mut local, &mut same);
                if let Some(split) = split.as_mut() {
                    split.flush(&mut local, &mut touched);
                }
                total.drain_rows(&mut local, if dense { &all_rows } else { &touched.rows });
                touched.clear();
            }
            total.symmetrise();
            total
        })
        .collect()
}

/// Which accumulated columns a joint solve uses: per-axis linear ones and shared ones, as
/// indices into the accumulation's columns.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Selection {
    /// Per-axis linear columns.
    pub lin: Vec<usize>,
    /// Shared parameters.
    pub shared: Vec<usize>,
}

impl Selection {
    /// Parameters: 3 × linear + shared.
    pub fn len(&self) -> usize {
        3 * self.lin.len() + self.shared.len()
    }

    /// Whether it selects nothing.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Columns axis `a` sees, with the index of their parameter.
    fn axis_columns(&self, a: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        let nl = self.lin.len();
        self.lin
            .iter()
            .enumerate()
            .map(move |(p, &c)| (a * nl + p, c))
            .chain(self.shared.iter().enumerate().map(move |(q, &c)| (3 * nl + q, c)))
    }
}

/// A solved joint (linearised) least-squares problem: the step from the model the sums were
/// taken at.
#[derive(Debug, Clone)]
pub struct JointSolution {
    /// Step of every parameter: axis-major linear ones, then shared.
    pub delta: DVector<f64>,
    /// Covariance of the parameters (the inverse weighted normal matrix).
    pub cov: DMatrix<f64>,
    /// Weighted residual sum of squares after the step.
    pub chi2: f64,
    /// Residual sum of squares per axis after the step, counts².
    pub rss: [f64; 3],
    /// Samples per axis.
    pub n: [u64; 3],
}

/// Solves the weighted joint problem (`weights[a]` = 1/variance of axis a's noise).
pub fn solve_joint(g: &Gram, sel: &Selection, weights: [f64; 3]) -> Option<JointSolution> {
    let np = sel.len();
    let (a_mat, b) = normal_equations(g, sel, weights);
    let (scaled, d, rcond) = scaled_rcond(&a_mat);
    if rcond < MIN_RCOND {
        return None;
    }
    let inv_scaled = scaled.cholesky()?.inverse();
    let cov = DMatrix::from_fn(np, np, |i, j| inv_scaled[(i, j)] * d[i] * d[j]);
    let delta = &cov * &b;
    let rss = residual_after(g, sel, &delta);
    let chi2 = (0..3).map(|a| weights[a] * rss[a]).sum();
    Some(JointSolution { delta, cov, chi2, rss, n: g.n })
}

/// The weighted normal equations of a selection: XᵀWX and XᵀWe over the three axes, parameters
/// in the selection's order (axis-major linear ones, then shared).
pub fn normal_equations(g: &Gram, sel: &Selection, weights: [f64; 3]) -> (DMatrix<f64>, DVector<f64>) {
    let np = sel.len();
    let l = g.l;
    let mut a_mat = DMatrix::<f64>::zeros(np, np);
    let mut b = DVector::<f64>::zeros(np);
    for (a, &w) in weights.iter().enumerate() {
        let cols: Vec<(usize, usize)> = sel.axis_columns(a).collect();
        for &(pi, ci) in &cols {
            b[pi] += w * g.xte[a][ci];
            for &(pj, cj) in &cols {
                a_mat[(pi, pj)] += w * g.xtx[a][ci * l + cj];
            }
        }
    }
    (a_mat, b)
}

/// A symmetric normal matrix scaled to unit diagonal, the scale, and the reciprocal condition
/// number of the scaled matrix (0 when a diagonal entry is not positive: a column never excited).
fn scaled_rcond(a_mat: &DMatrix<f64>) -> (DMatrix<f64>, DVector<f64>, f64) {
    let np = a_mat.nrows();
    let d = DVector::from_fn(np, |i, _| {
        let v = a_mat[(i, i)];
        if v > 0.0 {
            1.0 / v.sqrt()
        } else {
            0.0
        }
    });
    let scaled = DMatrix::from_fn(np, np, |i, j| a_mat[(i, j)] * d[i] * d[j]);
    if d.iter().any(|&v| v == 0.0) {
        return (scaled, d, 0.0);
    }
    let eig = scaled.clone().symmetric_eigenvalues();
    let rcond = if eig.max() > 0.0 { (eig.min() / eig.max()).max(0.0) } else { 0.0 };
    (scaled, d, rcond)
}

/// Residual sum of squares per axis of the sums `g` after the step `delta` (of a solve with the
/// same selection, possibly on other runs: a held-out prediction).
pub fn residual_after(g: &Gram, sel: &Selection, delta: &DVector<f64>) -> [f64; 3] {
    let l = g.l;
    std::array::from_fn(|a| {
        let cols: Vec<(usize, usize)> = sel.axis_columns(a).collect();
        let mut rss = g.ete[a];
        for &(pi, ci) in &cols {
            rss -= 2.0 * delta[pi] * g.xte[a][ci];
            for &(pj, cj) in &cols {
                rss += delta[pi] * g.xtx[a][ci * l + cj] * delta[pj];
            }
        }
        rss.max(0.0)
    })
}

/// A model fitted to convergence.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The model at the solution.
    pub model: Model,
    /// Per-run sums of the model's columns at the last linearisation point.
    pub per_run: Vec<Gram>,
    /// The last solve (its `delta` is the final, negligible, step; `cov` the covariance).
    pub solution: JointSolution,
    /// Gauss-Newton passes made.
    pub passes: usize,
}

impl Fitted {
    /// The selection of all the model's columns.
    pub fn selection(&self) -> Selection {
        full_selection(&self.model)
    }

    /// Index of a parameter in `solution.delta`/`cov`: linear column `c` of axis `a`.
    pub fn lin_index(&self, a: usize, c: LinCol) -> Option<usize> {
        let nl = self.model.lin.len();
        self.model.lin.iter().position(|&q| q == c).map(|p| a * nl + p)
    }

    /// Index of a shared parameter in `solution.delta`/`cov`.
    pub fn shared_index(&self, p: SharedPar) -> Option<usize> {
        let nl = self.model.lin.len();
        self.model.shared.iter().position(|&q| q == p).map(|q| 3 * nl + q)
    }

    /// Why the fit is not an estimate, if a bounded parameter ended at its bound: there the
    /// data pushed it further than the model allows, so its value and σ mean nothing.
    pub fn at_bound(&self) -> Option<String> {
        for (&p, &v) in self.model.shared.iter().zip(&self.model.theta) {
            let Some(Bound { lo, hi, what, unit }) = p.bound() else {
                continue;
            };
            // A bound is reached when the value sits within 1e-9 of the range of it.
            let tol = 1e-9 * (hi - lo);
            if v <= lo + tol || v >= hi - tol {
                return Some(format!("the {what} ended at its bound ({v} {unit}, allowed {lo} to {hi})"));
            }
        }
        None
    }

    /// 1-σ of a parameter by its index.
    pub fn sigma(&self, index: usize) -> f64 {
        self.solution.cov[(index, index)].max(0.0).sqrt()
    }
}

/// All columns of a model, in `Model::cols` order.
pub fn full_selection(m: &Model) -> Selection {
    let nl = m.lin.len();
    Selection { lin: (0..nl).collect(), shared: (nl..nl + m.shared.len()).collect() }
}

/// Applies a step to a model.
pub fn apply_step(m: &mut Model, sel_lin: usize, delta: &DVector<f64>, frozen: &[bool]) {
    let nl = sel_lin;
    for a in 0..3 {
        for p in 0..nl {
            m.beta[a][p] += delta[a * nl + p];
        }
    }
    let mut q = 0;
    for (k, th) in m.theta.iter_mut().enumerate() {
        if frozen[k] {
            continue;
        }
        *th += delta[3 * nl + q];
        q += 1;
    }
    for (p, th) in m.shared.iter().zip(m.theta.iter_mut()) {
        if let Some(b) = p.bound() {
            *th = th.clamp(b.lo, b.hi);
        }
    }
    m.update_directions();
}

/// Fits a model by Gauss-Newton from its current values. Shared parameters whose Jacobian is
/// zero at the start (a warm-up time constant while its amplitude is 0) are held for the first
/// pass.
pub fn fit(data: &LoopData, start: Model, weights: [f64; 3]) -> Result<Fitted, CalError> {
    let mut model = start;
    let cols = model.cols();
    let nl = model.lin.len();
    let linear_only = model.shared.is_empty() && model.lin.iter().all(|c| c.is_common());
    for pass in 1..=MAX_ITERATIONS {
        let per_run = accumulate(data, &model, &cols);
        let total = Gram::sum(&per_run).ok_or(CalError::NoRuns)?;
        let frozen: Vec<bool> = model.shared.iter().map(|&p| model.shapes_only_zero_columns(p)).collect();
        let sel = Selection {
            lin: (0..nl).collect(),
            shared: (0..model.shared.len()).filter(|&k| !frozen[k]).map(|k| nl + k).collect(),
        };
        let solution = solve_joint(&total, &sel, weights).ok_or_else(|| singular(&model, &total, data))?;
        let converged = !frozen.contains(&true)
            && (0..solution.delta.len()).all(|i| {
                let sd = solution.cov[(i, i)].max(0.0).sqrt();
                solution.delta[i].abs() <= CONVERGED_SIGMAS * sd
            });
        apply_step(&mut model, nl, &solution.delta, &frozen);
        if converged || (linear_only && pass == 1) || pass == MAX_ITERATIONS {
            // The sums were taken before the (negligible, or exact linear) last step: the
            // solution describes the model as it now is.
            return Ok(Fitted { model, per_run, solution, passes: pass });
        }
    }
    unreachable!("the loop returns at MAX_ITERATIONS")
}

/// The error for a joint system that cannot be solved: an axis whose own base columns (ω_s and
/// the offset) are singular, because the runs do not excite every rate direction or every one of
/// its samples is clipped; otherwise the runs do not separate the model's parameters.
fn singular(model: &Model, total: &Gram, data: &LoopData) -> CalError {
    let base: Vec<usize> = [LinCol::Omega(0), LinCol::Omega(1), LinCol::Omega(2), LinCol::One]
        .iter()
        .filter_map(|c| model.lin.iter().position(|q| q == c))
        .collect();
    for (a, &axis) in AXES.iter().enumerate() {
        if total.n[a] == 0 {
            return CalError::AxisClipped { axis, samples: data.runs.iter().map(|r| r.n_valid).sum() };
        }
    }
    for (a, &axis) in AXES.iter().enumerate() {
        let block = DMatrix::from_fn(base.len(), base.len(), |i, j| total.xtx[a][base[i] * total.l + base[j]]);
        let (_, _, rcond) = scaled_rcond(&block);
        if rcond < MIN_RCOND {
            return CalError::Singular { axis, rcond };
        }
    }
    CalError::Unidentifiable { effects: model.effects.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_past_a_bound_stops_at_it() {
        let base = Model::base_for(&[Pose::One, Pose::Two]);
        let m = base.with(Effect::Delay, Default::default(), vec![0.0]).with(
            Effect::DriftWarmUp,
            std::array::from_fn(|_| vec![0.0]),
            vec![600.0],
        );
        let delay = SharedPar { effect: Effect::Delay, k: 0 };
        let tau = SharedPar { effect: Effect::DriftWarmUp, k: 0 };
        let tau_range = tau.bound().map(|b| (b.lo, b.hi)).unwrap();
        assert_eq!(tau_range, (1.0, 1e5));
        let nl = m.lin.len();
        for (step, delay_s, tau_s) in [(1.0, MAX_DELAY_S, tau_range.1), (-1.0, -MAX_DELAY_S, tau_range.0)] {
            let mut moved = m.clone();
            let mut delta = DVector::zeros(3 * nl + 2);
            delta[3 * nl] = step;
            delta[3 * nl + 1] = step * 1e9;
            apply_step(&mut moved, nl, &delta, &[false, false]);
            assert_eq!(moved.theta_of(delay), Some(delay_s));
            assert_eq!(moved.theta_of(tau), Some(tau_s));
        }
        // The angles and rates are bounded by the data alone.
        assert_eq!(SharedPar { effect: Effect::IndexOffset, k: 0 }.bound(), None);
        assert_eq!(delay.bound().map(|b| (b.what, b.unit)), Some(("delay", "s")));
    }

    #[test]
    fn effect_parameters_are_reported_in_their_units() {
        let r = SharedPar { effect: Effect::Delay, k: 0 }.reported();
        assert_eq!((r.name.as_str(), r.scale, r.unit), ("delay τ", 1e3, "ms"));
        // Parameter 3 of a harmonic is pose 2's sine.
        let r = SharedPar { effect: Effect::TableHarmonic(12), k: 3 }.reported();
        assert_eq!(r.name, "table-speed ripple 12× sin, pose 2");
        // r·|r| per (°/s)² at 500 °/s full scale is 5e4 % of full scale per unit.
        let r = LinCol::Of(Effect::RateScale, 1).reported(500.0).unwrap();
        assert_eq!((r.scale, r.unit), (5e4, "% of full scale"));
        let r = LinCol::Of(Effect::GSensitivity, 1).reported(500.0).unwrap();
        assert_eq!(r.name, "g-sensitivity along package y");
        // The base columns are M and the offsets, the knots the drift table: not effect parameters.
        for c in [LinCol::Omega(0), LinCol::One, LinCol::DriftKnot { stretch: 0, knot: 1, spacing_s: 40 }] {
            assert_eq!(c.reported(500.0), None);
        }
    }

    /// The ranges mark exactly the samples the per-sample rule marks (clear of both ends and of
    /// every gap by `guard` samples), and their queries agree with the flags.
    #[test]
    fn valid_ranges_match_the_per_sample_rule() {
        let flags = |t: &[f64], gap: f64, guard: usize| -> Vec<bool> {
            let n = t.len();
            (0..n)
                .map(|i| {
                    let before = (0..=i).rev().find(|&j| j > 0 && t[j] - t[j - 1] > gap).unwrap_or(0);
                    let after = (i..n).find(|&j| j + 1 < n && t[j + 1] - t[j] > gap).unwrap_or(usize::MAX);
                    i >= before + guard && i + guard < n && after.saturating_sub(i) >= guard
                })
                .collect()
        };
        // Gaps after samples 9, 12 (a stretch too short to use) and 40; one right at the end.
        let mut t: Vec<f64> = Vec::new();
        let mut now = 0.0;
        for i in 0..60 {
            t.push(now);
            now += if [9, 12, 40, 58].contains(&i) { 5.0 } else { 1.0 };
        }
        for guard in [0, 1, 2, 3, 30] {
            let v = ValidSamples::of(t.len(), |i| t[i], 1.5, guard);
            let f = flags(&t, 1.5, guard);
            let expected: Vec<usize> = (0..t.len()).filter(|&i| f[i]).collect();
            assert_eq!(v.indices().collect::<Vec<_>>(), expected, "guard {guard}");
            assert_eq!(v.len(), expected.len());
            assert_eq!((v.first(), v.last()), (expected.first().copied(), expected.last().copied()));
            for (i, &fi) in f.iter().enumerate() {
                assert_eq!(v.contains(i), fi, "guard {guard}, sample {i}");
            }
            for (lo, hi) in [(0, 60), (5, 15), (11, 12), (20, 50), (59, 60)] {
                let want: Vec<usize> = expected.iter().copied().filter(|&i| i >= lo && i < hi).collect();
                assert_eq!(v.indices_in(lo, hi).collect::<Vec<_>>(), want, "guard {guard}, {lo}..{hi}");
            }
        }
        assert!(ValidSamples::of(t.len(), |i| t[i], 1.5, 30).is_empty());
    }
}
