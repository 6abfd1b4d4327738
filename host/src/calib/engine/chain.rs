//! The kinematic chain (EXCITER.md eq. 1-2) with every effect's inputs, written once: per sample,
//! the rate the sensor sees, and each column's value or Jacobian ([`Evaluator`]).

use crate::calib::data::kinematics::{KinSample, KinSamples};
use crate::calib::effects::terms::{decay, dot, AxisTerms, Ctx, EncoderRead, IndexEdge, Needs, Own, Shifts};
use crate::calib::effects::{encoder_error, Effect, MAX_HARMONIC_ORDER};
use crate::geometry::Pose;

use super::loop_data::LoopData;
use super::model::{shifts_of, Model};
use crate::calib::effects::terms::{Col, LinCol, Point, SharedPar};
use crate::calib::effects::DRIFT_KNOT_SPACINGS_S;

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

/// θ2 and θ1' as the tables turned, from the encoder's (`theta2`, `rate1_dps`) and its angle
/// error δ(θ1) with θ1 = θ2/ratio ([`encoder_error`], the effect's own): θ2 less ratio·δ, θ1'
/// less θ1'·δ'.
#[inline]
fn encoder_corrected(orders: [[f64; 2]; 2], ratio: f64, theta2: f64, rate1_dps: f64) -> (f64, f64) {
    if orders == [[0.0; 2]; 2] {
        return (theta2, rate1_dps);
    }
    let (d, d_slope) = encoder_error(orders, theta2 / ratio);
    (theta2 - ratio * d, rate1_dps * (1.0 - d_slope))
}

/// θ1'' at sample `i`, °/s²: the rates' central difference over the span of their own windows
/// (`window` samples), so that it is as smooth as they are. Consecutive samples' rates differ by
/// the encoder's quantisation through their weights' change: 7.5 °/s² rms over 1.25 ms at
/// 800 Hz, a seventh of a 0.6 % ripple at 8 Hz and 180 °/s (54 °/s²), noise a fit of the column
/// would read as signal; over 20 ms it is 1.2 °/s², and a ripple at 8 Hz keeps sin x/x = 96 %
/// of itself (x = 2π·8 Hz·10 ms).
fn rate_slope_dps2(s: &KinSamples, i: usize, window: usize) -> f64 {
    let h = window / 2;
    let (a, b) = (s.get(i.saturating_sub(h)), s.get((i + h).min(s.len() - 1)));
    let span_s = b.t_s() - a.t_s();
    if span_s > 0.0 {
        (b.theta1_rate_dps() - a.theta1_rate_dps()) / span_s
    } else {
        0.0
    }
}

/// The sample nearest `delay_samples` samples before sample `i` (after it for a negative
/// delay), within a run of `len`: where the kinematics a delayed output follows were read, for
/// what `interpolate` does not carry (θ1''). Half a sample's error in its time is 0.6 ms at
/// 800 Hz, 2° of a ripple at 8 Hz.
fn delayed(i: usize, delay_samples: f64, len: usize) -> usize {
    let shift = delay_samples.round();
    if shift >= 0.0 {
        i.saturating_sub(shift as usize)
    } else {
        (i + (-shift) as usize).min(len.saturating_sub(1))
    }
}

/// The knot columns of one stretch and spacing of the free drift within a column list.
#[derive(Debug, Clone)]
pub(super) struct KnotGroup {
    stretch: usize,
    spacing_s: u16,
    /// Index of the spacing in [`DRIFT_KNOT_SPACINGS_S`], whose knot position each point carries.
    spacing_index: Option<usize>,
    /// Where knot k sits in the column list, if it is there (the first stretch's first knot is
    /// the offset's).
    pub(super) at: Vec<Option<usize>>,
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
pub(super) struct ColPlan {
    /// (position in the list, column) of every column but the knots.
    pub(super) dense: Vec<(usize, Col)>,
    /// How each of `dense` is evaluated.
    kernels: Vec<Kernel>,
    /// (position in `dense`, column) of the columns whose value differs between axes.
    per_axis: Vec<(usize, Col)>,
    pub(super) knots: Vec<KnotGroup>,
    /// Whether `dense` holds a shared parameter's column.
    has_shared: bool,
    /// Whether every column has one value for all three axes (no knot, no per-axis column):
    /// the plain linear model's passes.
    pub(super) all_common: bool,
}

impl ColPlan {
    pub(super) fn of(cols: impl Iterator<Item = Col>) -> Self {
        let mut plan = Self::default();
        for (j, c) in cols.enumerate() {
            let Col::Lin(LinCol::DriftKnot { stretch, knot, spacing_s }) = c else {
                plan.has_shared |= matches!(c, Col::Shared(_));
                let kernel = Kernel::of(c);
                if let Kernel::PerAxis(c) = kernel {
                    plan.per_axis.push((plan.dense.len(), c));
                }
                plan.dense.push((j, c));
                plan.kernels.push(kernel);
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
        plan.all_common = plan.knots.is_empty() && plan.per_axis.is_empty();
        plan
    }
}

/// sin and cos of n× the gear mesh's angle, index n (`Point::mesh_sin_cos`).
type MeshHarmonics = [(f64, f64); MAX_HARMONIC_ORDER + 1];

/// The sensor table's transmission error of a run whose ripple harmonics are `ripple` (n, a, b),
/// at the mesh angle's harmonics `mesh`: the effective θ2 from the index-referenced
/// `theta2_rad`, the factor on θ2' and its derivative in the mesh angle (each harmonic n: angle
/// (a sin nθ − b cos nθ)/n, rate factor 1 + a cos nθ + b sin nθ), the angle less the error the
/// run's index pulse saw (`edge`).
#[inline]
fn transmission(
    ripple: &[(u32, f64, f64)],
    theta2_rad: f64,
    mesh: &MeshHarmonics,
    edge: &IndexEdge,
) -> (f64, f64, f64) {
    let (mut th_eff, mut factor, mut dfactor) = (theta2_rad - edge.shift_rad, 1.0, 0.0);
    for &(n, a, b) in ripple {
        let nf = f64::from(n);
        let (sn, cn) = mesh[n as usize];
        th_eff += (a * sn - b * cn) / nf;
        factor += a * cn + b * sn;
        dfactor += nf * (b * cn - a * sn);
    }
    (th_eff, factor, dfactor)
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
    /// The shared parameters of the effects that act on the output ([`crate::calib::effects::Behaviour::on_output`]),
    /// with their values.
    output_pars: Vec<(SharedPar, f64)>,
    /// Per stretch and knot spacing of [`DRIFT_KNOT_SPACINGS_S`]: the first knot's time, s, and
    /// knots per second.
    knot_grid: Vec<[(f64, f64); DRIFT_KNOT_SPACINGS_S.len()]>,
    /// Per run, the transmission error where its index pulse ties θ2 to 0.
    index_edge: Vec<IndexEdge>,
    /// Per run, the ripple harmonics (n, a, b) that apply to it (`Shifts::ripple`, taken apart
    /// once rather than filtered at every point).
    run_ripple: Vec<Vec<(u32, f64, f64)>>,
    /// The harmonic orders of the gear mesh's angle the model and the pass use.
    mesh_orders: Vec<usize>,
    /// sin θ/θ and (1 − cos θ)/θ² of the pose-2 fixture's turn θ = |e| (Rodrigues' formula).
    fixture_turn: [f64; 2],
    /// The model's linear columns, split for [`Evaluator::predict`].
    pub(super) lin_plan: ColPlan,
    /// The coefficients of `lin_plan.dense` on the three axes.
    lin_beta: Vec<[f64; 3]>,
    /// Whether the points need the base's heading θ1 (a sine and cosine per sample): only Earth's
    /// horizontal components turn with it.
    needs_heading: bool,
    /// Whether the points need the pose-2 fixture's Jacobian.
    needs_fixture: bool,
    /// Whether the points need the base encoder's reading (its error's columns).
    needs_encoder: bool,
    /// Whether the model moves no angle or rate and the pass needs no shared column's
    /// Jacobian: the points are then eq. 1-2 alone ([`Evaluator::plain_point`]), which is every
    /// pass of a calibration whose residual the linear model already explains.
    plain: bool,
    /// Whether the points need the die temperature: only the temperature drift's column uses it,
    /// and computing it for every point of every pass made the 1-h replay ~9 % slower.
    needs_temperature: bool,
    /// Whether a column is a free-drift knot: only those read a point's place on the knot grids.
    needs_knots: bool,
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
        let run_ripple: Vec<Vec<(u32, f64, f64)>> = (data.kin.runs.iter().enumerate())
            .map(|(r, rk)| {
                let of_run = shifts.ripple.iter().filter(|h| h.1.applies(r, rk.pose));
                of_run.map(|&(n, _, a, b)| (n, a, b)).collect()
            })
            .collect();
        let index_edge = (data.kin.runs.iter().zip(&run_ripple))
            .map(|(rk, ripple)| {
                let (half_width, rate) = (rk.plate_half_width_rad, rk.steady_rate_dps.to_radians());
                IndexEdge::new(half_width, rate, shifts.gear_lag_s, ripple.iter().copied())
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
            run_ripple,
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
            output_pars: model
                .shared
                .iter()
                .zip(&model.theta)
                .filter(|(p, _)| p.effect.behaviour(|b| b.on_output()))
                .map(|(&p, &v)| (p, v))
                .collect(),
            knot_grid: (0..data.layout.stretches.len())
                .map(|st| std::array::from_fn(|k| data.layout.knot_grid(st, DRIFT_KNOT_SPACINGS_S[k])))
                .collect(),
            lin_plan,
            lin_beta,
            needs_heading: needs.heading,
            needs_fixture: needs.fixture,
            needs_encoder: needs.encoder,
            plain,
            needs_temperature: needs.temperature,
            needs_knots: model
                .lin
                .iter()
                .map(|&c| Col::Lin(c))
                .chain(cols.iter().copied())
                .any(|c| matches!(c, Col::Lin(LinCol::DriftKnot { .. }))),
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
    pub(super) fn temperatures_c(&self, r: usize, range: std::ops::Range<usize>, out: &mut [f32]) {
        if !self.needs_temperature {
            return;
        }
        if !self.data.temp_moved {
            // Every reading the same: the smoothed temperature is the capture mean at every
            // sample, 0 °C from it.
            out.fill(0.0);
            return;
        }
        let grid = self.data.temperature_grid(r);
        for (t, i) in out.iter_mut().zip(range) {
            *t = grid.at(i);
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

    /// sin and cos of the base's heading in the lab at the index-referenced table angle
    /// `theta2_rad`: the sensor table is geared to a shaft fixed to the ground (EXCITER.md,
    /// "Mechanism"), so θ2 = ratio·θ1_lab + const and the index fixes the heading for every
    /// run, while the encoder's count restarts with each capture. (0, 0) where no column needs
    /// it: without a horizontal Earth term in the pass the heading multiplies zeros only.
    /// (Each angle's sine and cosine once: they were 4 of the 5 libm calls a point made.)
    #[inline]
    fn heading_sin_cos(&self, theta2_rad: f64, ratio: f64) -> (f64, f64) {
        if self.needs_heading {
            (theta2_rad / ratio).sin_cos()
        } else {
            (0.0, 0.0)
        }
    }

    /// The base encoder's reading at the angle `theta1_read_rad` it read, turning at
    /// `rate1_dps` as read, where a column needs it ([`Point::encoder_read`]).
    #[inline]
    fn encoder_read(&self, theta1_read_rad: f64, rate1_dps: f64) -> EncoderRead {
        if self.needs_encoder {
            EncoderRead::at(theta1_read_rad, rate1_dps)
        } else {
            EncoderRead::NAN
        }
    }

    /// A table-frame vector of run `r` in the package frame. The pose-2 fixture turned by e:
    /// R2 → exp([e]×)·R2, so a table-frame vector v reaches the package as R2ᵀ·exp(−[e]×)·v,
    /// exactly ([`rodrigues`]): to first order only, a 1° turn left e²/2 = 150 ppm to a spurious
    /// table tilt (97 ppm, 3.8σ off on the trust bench). Without a turn (pose 1, or no fixture in
    /// the model) exp(0)·v is v: its two cross products per vector, a dozen vectors a point, were
    /// 2 % of a calibration.
    #[inline]
    fn to_package(&self, r: usize) -> impl Fn(&[f64; 3]) -> [f64; 3] + '_ {
        let rt = &self.rot_t[r];
        let (e, [a, b]) = if self.data.kin.runs[r].pose == Pose::Two {
            (self.shifts.fixture_rad, self.fixture_turn)
        } else {
            ([0.0; 3], [0.0; 2])
        };
        let turned = e != [0.0; 3];
        move |v: &[f64; 3]| -> [f64; 3] {
            let f = if turned { turn(&e, v, -1.0, (a, b)) } else { *v };
            std::array::from_fn(|i| rt[i][0] * f[0] + rt[i][1] * f[1] + rt[i][2] * f[2])
        }
    }

    /// [`Evaluator::point`] of a model that moves angles or rates, or of a pass that wants the
    /// shared parameters' Jacobians.
    #[inline(never)]
    fn full_point(&self, r: usize, i: usize, s: KinSample) -> Point {
        let rk = &self.data.kin.runs[r];
        let sh = &self.shifts;
        let (theta2, rate1) = interpolate(&rk.samples, i, sh.delay_s);
        let theta2_read = theta2 + sh.theta2_offset_rad;
        let encoder_read = self.encoder_read(theta2_read / rk.gear_ratio, rate1);
        let (th, rate1) = encoder_corrected(sh.encoder_rad, rk.gear_ratio, theta2_read, rate1);
        let theta2 = th - sh.theta2_offset_rad;
        // The transmission error is periodic in the mesh angle, which moves with the table
        // against the index (1:1 gears): the index-referenced θ2, lagging by the gear lag. The
        // index offset does not move it (the error is tied to the gear, not to where θ2 = 0 is).
        let theta1_rate_rad_s = rate1.to_radians();
        let mesh_sin_cos = self.mesh_harmonics(theta2 + sh.gear_lag_s * theta1_rate_rad_s);
        let (th_eff, ripple, dripple) = transmission(&self.run_ripple[r], th, &mesh_sin_cos, &self.index_edge[r]);
        let rate2 = rk.gear_ratio * rate1;
        let rate2_eff = rate2 * ripple;
        let rt = &self.rot_t[r];
        let to_package = self.to_package(r);
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
        let (s1, c1) = self.heading_sin_cos(theta2, rk.gear_ratio);
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
            encoder_read,
            pose: rk.pose,
            d_earth,
            d_filter,
            d_fixture,
            d_tilt: to_package(&[-rate1 * sin_tilt * se, -rate1 * sin_tilt * ce, 0.0]),
            cos_tilt,
            theta1_rate_rad_s,
            theta1_rate_dps: rate1,
            theta1_accel_dps2: rate_slope_dps2(
                &rk.samples,
                delayed(i, sh.delay_s * rk.sample_rate_hz, rk.samples.len()),
                rk.rate_window_samples,
            ),
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
            encoder_read: EncoderRead::NAN,
            pose: self.data.kin.runs[r].pose,
            d_earth: [nan3; 3],
            d_filter: nan3,
            d_fixture: [nan3; 3],
            d_tilt: nan3,
            cos_tilt: f64::NAN,
            theta1_rate_rad_s: f64::NAN,
            theta1_rate_dps: f64::NAN,
            theta1_accel_dps2: f64::NAN,
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
    /// batch computed ahead ([`crate::calib::engine::sincos`]).
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
    /// (NaN for the others): one `sincos` and each order's power of it ([`harmonic_power`]), or
    /// the recurrence of [`harmonics_of`] when more than a few orders are in use (a candidate
    /// pass over every order).
    #[inline]
    fn mesh_harmonics(&self, mesh_rad: f64) -> MeshHarmonics {
        if self.mesh_orders.len() > 4 {
            return harmonics_of(mesh_rad);
        }
        let mut h = [(f64::NAN, f64::NAN); MAX_HARMONIC_ORDER + 1];
        if !self.mesh_orders.is_empty() {
            let first = libm::sincos(mesh_rad);
            for &n in &self.mesh_orders {
                h[n] = harmonic_power(first, n);
            }
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
    pub(super) fn predict3_with(&self, p: &Point, common: &[f64]) -> [f64; 3] {
        let mut sum = self.predict3_terms(p, common);
        if !self.output_pars.is_empty() {
            for (a, s) in sum.iter_mut().enumerate() {
                let t = self.axis_terms(p, a);
                for &(sp, theta) in &self.output_pars {
                    *s += theta * self.effect_value(sp.effect, Own::Shared(sp.k), p, a, &t);
                }
            }
        }
        sum
    }

    /// The model's linear terms at `p` ([`Evaluator::predict3_with`] before the effects that act
    /// on the output).
    #[inline]
    fn predict3_terms(&self, p: &Point, common: &[f64]) -> [f64; 3] {
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
    /// (0 for the others), then, for each of its per-axis shared columns in order (a linear
    /// column has none), the vector whose product with an axis's gradient is the column on that
    /// axis ([`crate::calib::effects::Behaviour::gradient_factor`]; NaN where it has none): what
    /// [`Evaluator::fill_dense`] reads.
    #[inline]
    pub(super) fn common_values(&self, p: &Point, plan: &ColPlan, out: &mut Vec<f64>) {
        out.clear();
        out.extend(plan.kernels.iter().map(|k| match *k {
            Kernel::Omega(k) => p.omega[k],
            Kernel::One => 1.0,
            Kernel::Common(lc) => self.lin_value(lc, p, 0),
            Kernel::PerAxis(_) => 0.0,
        }));
        for &(_, c) in &plan.per_axis {
            if let Col::Shared(sp) = c {
                out.extend(self.gradient_factor(sp.effect, Own::Shared(sp.k), p).unwrap_or([f64::NAN; 3]));
            }
        }
    }

    /// The knots of `plan` under point `p`, with their hat functions' values (the
    /// [`LinCol::DriftKnot`] arm of [`Evaluator::lin_value`], for the two that can be non-zero).
    #[inline]
    pub(super) fn for_each_knot(&self, plan: &ColPlan, p: &Point, f: impl FnMut(usize, f64)) {
        self.knots_at(plan, p.stretch, p.t_s, Some(&p.knot_x), f);
    }

    /// [`Evaluator::for_each_knot`] at time `t_s` of stretch `stretch`, whose places on the
    /// standard grids are `knot_x` if known (a point's), else reckoned here.
    #[inline]
    pub(super) fn knots_at(
        &self,
        plan: &ColPlan,
        stretch: usize,
        t_s: f64,
        knot_x: Option<&[f64; DRIFT_KNOT_SPACINGS_S.len()]>,
        mut f: impl FnMut(usize, f64),
    ) {
        for g in plan.knots.iter().filter(|g| g.stretch == stretch) {
            let x = match (g.spacing_index, knot_x) {
                (Some(k), Some(x)) => x[k],
                _ => self.knot_place(g, t_s),
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

    /// Where time `t_s` sits on group `g`'s grid, in knot spacings from its first knot.
    #[inline]
    fn knot_place(&self, g: &KnotGroup, t_s: f64) -> f64 {
        let (t0, per_s) = match g.spacing_index {
            Some(k) => self.knot_grid[g.stretch][k],
            None => self.data.layout.knot_grid(g.stretch, g.spacing_s),
        };
        (t_s - t0) * per_s
    }

    /// Whether every knot of `plan` in stretch `stretch` is a straight line in time from
    /// `t_first_s` to `t_last_s` (no corner strictly between them): then a sum of n samples'
    /// knot values there is n times the knots' values at the samples' mean time.
    #[inline]
    pub(super) fn knots_straight(&self, plan: &ColPlan, stretch: usize, t_first_s: f64, t_last_s: f64) -> bool {
        plan.knots
            .iter()
            .filter(|g| g.stretch == stretch)
            .all(|g| self.knot_place(g, t_first_s).floor() == self.knot_place(g, t_last_s).floor())
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

    /// An effect's column at `p` as a vector against the axes' gradients
    /// (`Behaviour::gradient_factor`), out of line as [`Evaluator::effect_value`].
    #[inline(never)]
    fn gradient_factor(&self, e: Effect, own: Own, p: &Point) -> Option<[f64; 3]> {
        e.behaviour(|b| b.gradient_factor(own, p, &self.cx()))
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
    /// [`Evaluator::fill`] gives. `common` holds `plan`'s axis-independent values at `p` and its
    /// per-axis columns' gradient factors (`common_values`).
    pub(super) fn fill_dense(&self, p: &Point, plan: &ColPlan, a: usize, common: &[f64], out: &mut [f64]) {
        let t = if plan.has_shared { self.axis_terms(p, a) } else { AxisTerms::UNUSED };
        // The axis-independent values copied whole, then the per-axis ones over them: a match
        // per column and axis was a fifth of a candidates' pass, most of its columns common.
        let (values, factors) = common.split_at(out.len());
        out.copy_from_slice(values);
        let mut factors = factors.chunks_exact(3);
        for &(i, c) in &plan.per_axis {
            // A shared column has its slot among the factors; NaN: no factor, taken per axis.
            let factor = match c {
                Col::Shared(_) => factors.next().filter(|f| !f[0].is_nan()),
                Col::Lin(_) => None,
            };
            out[i] = match factor {
                Some(f) => dot(&t.u, &[f[0], f[1], f[2]]),
                None => self.column_value(c, p, a, &t),
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

/// sin and cos of n·θ from those of θ (`first`), as the n-th power of e^{iθ} by squaring: at
/// most 2·log2(n) complex products, ~1e-15 of rounding at 32×, where `sincos(n·θ)` of the
/// mesh's harmonics (its argument reduced from hundreds of radians) was 2 % of a realistic
/// calibration's instructions.
#[inline]
fn harmonic_power((s1, c1): (f64, f64), n: usize) -> (f64, f64) {
    let mul = |(sa, ca): (f64, f64), (sb, cb): (f64, f64)| (sa * cb + ca * sb, ca * cb - sa * sb);
    let (mut acc, mut base, mut k) = ((0.0, 1.0), (s1, c1), n);
    while k > 0 {
        if k & 1 == 1 {
            acc = mul(acc, base);
        }
        k >>= 1;
        if k > 0 {
            base = mul(base, base);
        }
    }
    acc
}

/// sin and cos of n·θ for n = 0..=MAX_HARMONIC_ORDER (one sin_cos): orders 2-4 from double and
/// triple angles, then four interleaved angle-addition recurrences h[n] = h[n−4]·h[4], which the
/// CPU runs side by side (a single chain of 32 dependent rotations was 16 % of `host calibrate`);
/// the rounding grows by an ulp per step, ~1e-14 at 32×. Only a pass with many orders in use
/// takes them all ([`Evaluator::mesh_harmonics`]).
fn harmonics_of(theta_rad: f64) -> [(f64, f64); MAX_HARMONIC_ORDER + 1] {
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
pub(super) struct SampleInputs {
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
        crate::calib::engine::sincos::sincos_into(&self.theta2_rad[..n], &mut self.sin[..n], &mut self.cos[..n]);
        ev.temperatures_c(run, i..end, &mut self.temp_c[..n]);
        (self.run, self.start) = (run, i);
    }
}

#[cfg(test)]
mod tests {
    use super::{harmonic_power, harmonics_of, MAX_HARMONIC_ORDER};

    /// A power of e^{iθ} is within 1e-14 of sin nθ, cos nθ at every order, and order 0 is (0, 1).
    #[test]
    fn a_harmonics_power_matches_direct_evaluation() {
        for theta in [0.0, 0.3, -2.0, 5.5, 1e-9] {
            for n in 0..=MAX_HARMONIC_ORDER {
                let (s, c) = harmonic_power(libm::sincos(theta), n);
                let (ds, dc) = libm::sincos(n as f64 * theta);
                assert!((s - ds).abs() < 1e-14 && (c - dc).abs() < 1e-14, "θ {theta}, order {n}: {s} {c}");
            }
        }
        assert_eq!(harmonic_power((0.6, 0.8), 0), (0.0, 1.0));
    }

    /// The interleaved recurrences stay within 1e-13 of sin nθ, cos nθ up to the last order.
    #[test]
    fn the_recurrences_match_direct_evaluation() {
        // (Angles a few radians: at large θ the direct sin(nθ) carries the rounding of nθ.)
        for theta in [0.0, 0.3, -2.0, 5.5] {
            let h = harmonics_of(theta);
            assert_eq!(h.len(), MAX_HARMONIC_ORDER + 1);
            for (n, &(s, c)) in h.iter().enumerate() {
                let (ds, dc) = (n as f64 * theta).sin_cos();
                assert!((s - ds).abs() < 1e-13 && (c - dc).abs() < 1e-13, "θ {theta}, order {n}: {s} {c}");
            }
        }
    }
}
