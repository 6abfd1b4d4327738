//! What an effect is written in terms of: the columns and parameters it owns, the kinematics
//! at one sample ([`Point`]) and the chain-rule factors of one axis there ([`AxisTerms`]), the
//! inputs of the exciter's kinematic chain that its shared parameters set ([`Shifts`]), and what
//! the loop knows when it chooses candidates ([`Situation`]).

use super::{Effect, MAX_HARMONIC_ORDER};
use crate::geometry::Pose;

/// Knot spacings of the free drift model tried, s. The longest leaves one level and slope per
/// 2-min run; the shortest follows a random walk of 0.005 °/s/√s (the top of issue 10's range)
/// to its interpolation error K·√(T/6) ≈ 6 m°/s over 10 s, a third of the 10-s-mean test's 3σ at
/// the L3G4200D's 0.03 °/s/√Hz, and is still 5 turns of the table at 0.25 Hz, so the knots
/// cannot follow the table-rate signal. Every point carries its place on each of these grids.
pub const DRIFT_KNOT_SPACINGS_S: [u16; 3] = [40, 20, 10];

/// A per-axis linear column (every axis has the same kinds, each its own coefficient).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LinCol {
    /// Component k of ω_s = R_qᵀ ω2, °/s (the base model).
    Omega(usize),
    /// 1 (offset; the base model).
    One,
    /// Linear column `k` of an effect, evaluated by the effect ([`super::Behaviour::value`]).
    Of(Effect, u16),
    /// exp(−t/T) with a fixed T, s, t from the first sample: the warm-up tried at a grid value
    /// of its time constant before that is fitted.
    DriftExpFixed(f64),
    /// The hat function of knot `knot` of stretch `stretch` (index into `Layout::stretches`) on
    /// the grid of `Effect::DriftKnots(spacing_s)`: 1 at the knot, falling linearly to 0 at its
    /// neighbours, 0 in every other stretch. The engine evaluates these itself: a sample lies
    /// under two of the dozens a long capture has.
    DriftKnot {
        /// Stretch index.
        stretch: u16,
        /// Knot index within the stretch, from 0 at its first used sample.
        knot: u16,
        /// Nominal knot spacing, s.
        spacing_s: u16,
    },
}

impl LinCol {
    /// Its name and reported unit per °/s of the axis's sensitivity (the coefficient is fitted
    /// in counts), for the columns an effect adds; None for the base model's (reported as M and
    /// the offsets), the free drift's knots (reported as the drift table) and the candidate
    /// warm-ups' fixed time constants (never in a fitted model). `full_scale_dps` is the gyro's
    /// range, the natural unit of a non-linearity.
    pub fn reported(self, full_scale_dps: f64) -> Option<Reported> {
        match self {
            LinCol::Of(e, k) => e.behaviour(|b| b.reported(Own::Lin(k), full_scale_dps)),
            LinCol::Omega(_) | LinCol::One | LinCol::DriftExpFixed(_) | LinCol::DriftKnot { .. } => None,
        }
    }

    /// Whether it is part of the offset (the constant or a drift term).
    pub fn is_offset(self) -> bool {
        match self {
            LinCol::One | LinCol::DriftExpFixed(_) | LinCol::DriftKnot { .. } => true,
            LinCol::Of(e, _) => e.is_drift(),
            LinCol::Omega(_) => false,
        }
    }

    /// Whether it has one value for all three axes (it does not depend on the axis's own rate).
    pub fn is_common(self) -> bool {
        match self {
            LinCol::Of(e, k) => e.behaviour(|b| b.rate_slope(k, 1.0).is_none()),
            LinCol::Omega(_) | LinCol::One | LinCol::DriftExpFixed(_) | LinCol::DriftKnot { .. } => true,
        }
    }
}

/// A parameter shared by all axes: parameter `k` of an effect (its meaning is the effect's).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SharedPar {
    /// The effect.
    pub effect: Effect,
    /// Which of its parameters.
    pub k: u8,
}

impl SharedPar {
    /// The range the fit holds it in, if any (most are small angles and rates that the data
    /// bounds by itself).
    pub fn bound(self) -> Option<Bound> {
        self.effect.behaviour(|b| b.bound(self.k))
    }

    /// What physics says of its size, when it does ([`super::Behaviour::prior`]).
    pub fn prior(self) -> Option<PhysicalPrior> {
        self.effect.behaviour(|b| b.prior(self.k))
    }

    /// The runs it can move the output in, when not all ([`super::Behaviour::scope`]).
    pub fn scope(self) -> Option<RunScope> {
        self.effect.behaviour(|b| b.scope(self.k))
    }

    /// Its name and reported unit.
    pub fn reported(self) -> Reported {
        self.effect
            .behaviour(|b| b.reported(Own::Shared(self.k), 0.0))
            .unwrap_or_else(|| Reported::new(format!("{} parameter {}", self.effect.key(), self.k), 1.0, ""))
    }
}

/// Any column of the accumulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Col {
    /// Per-axis linear.
    Lin(LinCol),
    /// Jacobian of a shared parameter.
    Shared(SharedPar),
}

impl Col {
    /// The highest multiple of the turn rate at which it varies ([`super::Behaviour::turn_multiple`]):
    /// ω_s (eq. 2: θ1'·z1 turning with θ2, θ2'·z2 fixed) at the turn rate, the offset and the
    /// drift's knots and fixed warm-ups not with the turn.
    pub fn turn_multiple(self) -> u32 {
        match self {
            Col::Lin(LinCol::Omega(_)) => 1,
            Col::Lin(LinCol::One | LinCol::DriftExpFixed(_) | LinCol::DriftKnot { .. }) => 0,
            Col::Lin(LinCol::Of(e, _)) | Col::Shared(SharedPar { effect: e, .. }) => e.turn_multiple(),
        }
    }

    /// Whether it can be non-zero in run `run`, of pose `pose`.
    pub fn in_run(self, run: usize, pose: Pose) -> bool {
        match self {
            Col::Shared(p) => p.scope().is_none_or(|s| s.applies(run, pose)),
            Col::Lin(_) => true,
        }
    }

    /// What of a point it needs beyond eq. 1-2.
    pub fn needs(self) -> Needs {
        match self {
            Col::Lin(LinCol::Of(e, k)) => e.behaviour(|b| b.needs(Own::Lin(k))),
            Col::Shared(p) => p.effect.behaviour(|b| b.needs(Own::Shared(p.k))),
            Col::Lin(_) => Needs::NONE,
        }
    }
}

/// One of an effect's own parameters: linear column `k` or shared parameter `k`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Own {
    /// Per-axis linear column.
    Lin(u16),
    /// Shared parameter.
    Shared(u8),
}

/// A range a fitted parameter is held in, beyond which the model stops describing the rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bound {
    /// Lowest value, in the parameter's unit.
    pub lo: f64,
    /// Highest value.
    pub hi: f64,
    /// What the parameter is, as an error message says it.
    pub what: &'static str,
    /// Its unit.
    pub unit: &'static str,
}

/// What physics says of a parameter's size, in its fitted unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicalPrior {
    /// The largest it can be: runs that bound it no better (1σ) have not seen it.
    pub bound: f64,
    /// σ of the zero-mean Gaussian prior that then holds it.
    pub sigma: f64,
}

/// How a parameter is reported: its name, the factor from its fitted unit to the reported one,
/// and the reported unit.
#[derive(Debug, Clone, PartialEq)]
pub struct Reported {
    /// Name.
    pub name: String,
    /// Reported value per fitted value.
    pub scale: f64,
    /// Reported unit.
    pub unit: &'static str,
}

impl Reported {
    /// Name, scale and unit.
    pub fn new(name: impl Into<String>, scale: f64, unit: &'static str) -> Self {
        Self { name: name.into(), scale, unit }
    }
}

/// Which family an effect belongs to, for the rules that treat families alike.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// An offset-drift model (they are alternatives: at most one curve, or the free drift).
    Drift {
        /// The time or temperature its fitted offset (the constant column's coefficient) holds at.
        offset_reference: &'static str,
        /// Whether it is the free drift, whose absence is not θ = 0 (its knots hold each run's
        /// level): it is never dropped again, and replaces a curve.
        free: bool,
    },
    /// A form of Earth's rotation (at most one in a model; known physics, never dropped).
    Earth,
    /// Anything else.
    Other,
}

/// What of a point a column needs beyond eq. 1-2 (each costs a pass time, so a point computes
/// it only for the columns that read it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Needs {
    /// The base's heading θ1 (`Point::d_earth[1..]`).
    pub heading: bool,
    /// The pose-2 fixture's Jacobian (`Point::d_fixture`).
    pub fixture: bool,
    /// The smoothed die temperature (`Point::temp_c`).
    pub temperature: bool,
    /// The base encoder's reading (`Point::encoder_read`).
    pub encoder: bool,
}

impl Needs {
    /// Nothing beyond eq. 1-2.
    pub const NONE: Needs = Needs { heading: false, fixture: false, temperature: false, encoder: false };

    /// Either's needs.
    pub fn or(self, o: Needs) -> Needs {
        Needs {
            heading: self.heading || o.heading,
            fixture: self.fixture || o.fixture,
            temperature: self.temperature || o.temperature,
            encoder: self.encoder || o.encoder,
        }
    }
}

/// The base encoder's reading at a point, before the model's correction of it: what the
/// encoder's error columns are functions of ([`super::encoder_eccentricity`]), taken once per
/// point rather than once per column and axis (six sines and cosines a point where they were
/// 6 % of a realistic replay).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EncoderRead {
    /// θ1' as read, °/s.
    pub rate_dps: f64,
    /// sin and cos of n× θ1 as read, index n − 1 (the eccentricity's order 1 and the
    /// ellipticity's 2).
    pub sin_cos: [(f64, f64); 2],
}

impl EncoderRead {
    /// Not taken: no column of the pass needs it.
    pub const NAN: EncoderRead = EncoderRead { rate_dps: f64::NAN, sin_cos: [(f64::NAN, f64::NAN); 2] };

    /// The reading at θ1 = `theta1_read_rad` turning at `rate_dps`.
    #[inline]
    pub fn at(theta1_read_rad: f64, rate_dps: f64) -> Self {
        let (s, c) = libm::sincos(theta1_read_rad);
        Self { rate_dps, sin_cos: [(s, c), (2.0 * s * c, c * c - s * s)] }
    }
}

/// The inputs of the exciter's kinematic chain that shared parameters set, derived from a
/// model once per pass (each effect's [`super::Behaviour::shift`] writes its own). The chain
/// (`engine::chain::Evaluator::point`) applies them in the rig's order: the delay to the time, the
/// index shifts and the gear lag to the angles, the ripple to the table's angle and speed, the
/// tilt and Earth's rate to ω2, the filter's curvature to the output, the fixture to the frame.
#[derive(Debug, Clone)]
pub struct Shifts {
    /// Delay of the gyro behind the encoder, s.
    pub delay_s: f64,
    /// Shift of θ2 (index offset, phase), rad.
    pub theta2_offset_rad: f64,
    /// The warm-up's time constant, s.
    pub drift_tau_s: f64,
    /// Earth's rate: vertical, and the two horizontal components, °/s.
    pub earth_dps: [f64; 3],
    /// Filter curvature κ, s².
    pub filter_s2: f64,
    /// Gear lag c, s.
    pub gear_lag_s: f64,
    /// sin and cos of the table tilt ε (once per evaluator, not per sample).
    pub tilt_sin_cos: (f64, f64),
    /// Pose-2 fixture rotation about x2, y2, z2, rad.
    pub fixture_rad: [f64; 3],
    /// (n, runs it applies to, a, b) of each ripple harmonic's pair.
    pub ripple: Vec<(u32, RunScope, f64, f64)>,
    /// The base encoder's angle error at 1× and 2× of θ1, (a, b) of each order n's part of
    /// δ = Σ a·sin nθ1 − b·(cos nθ1 − 1), rad.
    pub encoder_rad: [[f64; 2]; 2],
}

impl Shifts {
    /// No shift: the nominal kinematics, with Earth's vertical rate `earth_vertical_dps` when it
    /// is known rather than fitted.
    pub fn nominal(earth_vertical_dps: f64) -> Self {
        Self {
            delay_s: 0.0,
            theta2_offset_rad: 0.0,
            drift_tau_s: 1.0,
            earth_dps: [earth_vertical_dps, 0.0, 0.0],
            filter_s2: 0.0,
            gear_lag_s: 0.0,
            tilt_sin_cos: 0.0f64.sin_cos(),
            fixture_rad: [0.0; 3],
            ripple: Vec::new(),
            encoder_rad: [[0.0; 2]; 2],
        }
    }
}

/// The runs a parameter can move the output in (a table harmonic's pair: one pose's runs, or one
/// run): its column is zero in every other run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunScope {
    /// Every run of a pose.
    Pose(Pose),
    /// One run.
    Run(usize),
}

impl RunScope {
    /// Whether it applies to run `run`, in pose `pose`.
    #[inline]
    pub fn applies(self, run: usize, pose: Pose) -> bool {
        match self {
            RunScope::Pose(q) => q == pose,
            RunScope::Run(r) => r == run,
        }
    }
}

/// Kinematics at one sample under a model's shared parameters.
#[derive(Debug, Clone, Copy)]
pub struct Point {
    /// ω_s, °/s.
    pub omega: [f64; 3],
    /// ∂ω_s/∂θ2, °/s per rad.
    pub d_theta2: [f64; 3],
    /// ∂ω_s/∂θ2' = R_qᵀ e_z2.
    pub d_rate2: [f64; 3],
    /// θ2 before the table-speed ripple, rad (index offset, phase and delay applied).
    pub theta2_rad: f64,
    /// θ2' before ripple, °/s.
    pub rate2_dps: f64,
    /// θ2' with ripple, °/s.
    pub rate2_eff_dps: f64,
    /// ∂θ2_eff/∂θ2 through the ripple's angle term (1 without ripple).
    pub dtheta_eff: f64,
    /// ∂θ2'_eff/∂θ2 through the ripple's speed term, °/s per rad.
    pub drate_eff_dps: f64,
    /// Time from the capture's first sample, s.
    pub t_rel_s: f64,
    /// Time scaled to [−1, 1].
    pub t_scaled: f64,
    /// Smoothed temperature from the capture mean, °C (NaN unless a column needs it, or the
    /// evaluator is `Evaluator::new`'s).
    pub temp_c: f64,
    /// sin and cos of n× the gear mesh's angle (index-referenced θ2 with the gear lag: the
    /// transmission error's argument), index n, for the harmonic orders the model and the pass
    /// use (NaN for the others): each once per sample, not once per column and axis.
    pub mesh_sin_cos: [(f64, f64); MAX_HARMONIC_ORDER + 1],
    /// The base encoder's reading (NaN unless a column needs it, [`Needs::encoder`]).
    pub encoder_read: EncoderRead,
    /// The run's pose (the transmission error has a parameter set per pose).
    pub pose: Pose,
    /// ∂ω_s/∂(Earth's vertical, north-at-zero, west-at-zero rate), package frame; the first is
    /// also gravity's direction (both lie along the base axis z1).
    /// Horizontal parts NaN unless a column needs them ([`Needs::heading`]).
    pub d_earth: [[f64; 3]; 3],
    /// ω̈ in the package frame, °/s³ (∂ω_s/∂κ).
    pub d_filter: [f64; 3],
    /// ∂ω_s/∂(pose-2 fixture rotation about x2, y2, z2), °/s per rad (zero outside pose 2).
    /// NaN unless a column needs it ([`Needs::fixture`]).
    pub d_fixture: [[f64; 3]; 3],
    /// ∂ω_s/∂ε through the in-plane part's cos ε, °/s per rad.
    pub d_tilt: [f64; 3],
    /// cos ε of the table tilt.
    pub cos_tilt: f64,
    /// θ1', rad/s.
    pub theta1_rate_rad_s: f64,
    /// θ1', °/s.
    pub theta1_rate_dps: f64,
    /// θ1'' (the motor's speed ripple, as the encoder's rates give it), °/s²; NaN in a plain
    /// point.
    pub theta1_accel_dps2: f64,
    /// The run's index in the data.
    pub run: usize,
    /// The sample's time on its capture's clock, s.
    pub t_s: f64,
    /// The run's stretch (`Layout::stretches`).
    pub stretch: usize,
    /// Where the sample lies on the free drift's knot grid of each of
    /// [`DRIFT_KNOT_SPACINGS_S`] in its stretch, in intervals from the first knot (computed once
    /// per sample: the knots are dozens of columns).
    pub knot_x: [f64; DRIFT_KNOT_SPACINGS_S.len()],
}

/// What a shared column's value on one axis is made of, per sample: the chain rule's factors
/// from the output back to the kinematics.
#[derive(Debug, Clone, Copy)]
pub struct AxisTerms {
    /// ∂(output)/∂ω_s, counts per °/s.
    pub u: [f64; 3],
    /// ∂(output)/∂θ2, counts per rad.
    pub e2: f64,
    /// ∂(output)/∂θ2', counts per °/s.
    pub ez: f64,
    /// Moving θ2 (before ripple) moves the rippled angle and speed too.
    pub d_shift: f64,
}

impl AxisTerms {
    /// For a pass with no shared column, which reads none of them.
    pub const UNUSED: AxisTerms = AxisTerms { u: [f64::NAN; 3], e2: f64::NAN, ez: f64::NAN, d_shift: f64::NAN };

    /// ∂(output)/∂θ1' at `p`, counts per °/s: u·ω_s/θ1', every table term being in proportion
    /// to θ1' (Earth's 1e-5 of it is left out); 0 at rest.
    pub fn per_theta1_rate(&self, p: &Point) -> f64 {
        if p.theta1_rate_dps == 0.0 {
            return 0.0;
        }
        dot(&self.u, &p.omega) / p.theta1_rate_dps
    }
}

/// What of the model an effect's column reads besides the point: the kinematic chain's inputs,
/// the axis directions and the linear coefficients.
#[derive(Debug, Clone, Copy)]
pub struct Ctx<'a> {
    /// The chain's inputs at the model's values.
    pub shifts: &'a Shifts,
    /// Per run, the transmission error where its index pulse ties θ2 to 0.
    pub index_edge: &'a [IndexEdge],
    /// Unit axis directions (rows of M normalised).
    pub s_hat: &'a [[f64; 3]; 3],
    /// The model's linear columns.
    pub lin: &'a [LinCol],
    /// Their coefficients, per axis.
    pub beta: &'a [Vec<f64>; 3],
}

/// The transmission error as a run's index pulse sees it. The pulse's edges are where the sensor
/// table really is at ±h (h half the plate's width) and their midpoint is where the
/// index-referenced θ2 is 0, so the table's true angle there is 0 plus the mean of the error at
/// the two edges, not the error at the midpoint: the effective θ2 is the index-referenced one plus
/// the error at the sample less that mean. For a harmonic n of the gear mesh's angle (θ2 + c·θ1',
/// c the gear lag), angle error (a·sin nθ − b·cos nθ)/n, the mean over θ = ±h + L is
/// cos(nh)·(a·sin nL − b·cos nL)/n with L = c·θ1'. Without it a 12-pole gear's error of 0.03°
/// and a 4° plate put θ2 = 0 up to 0.0026° off, the same in every run of a direction: a turn
/// of M the loop's tests cannot see (4 σ of a direction on the default session).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IndexEdge {
    /// Per harmonic order n (index n): cos(nh)·sin(nL), cos(nh)·cos(nL).
    pub harmonic: [(f64, f64); MAX_HARMONIC_ORDER + 1],
    /// The model's transmission error as the pulse sees it, rad.
    pub shift_rad: f64,
    /// Its derivative in the gear lag, rad/s.
    pub dshift_dlag: f64,
}

impl IndexEdge {
    /// For a run with plate half-width `half_width_rad` at base rate `theta1_rate_rad_s`, under
    /// the ripple harmonics `(n, a, b)` of its pose and gear lag `gear_lag_s`.
    pub fn new(
        half_width_rad: f64,
        theta1_rate_rad_s: f64,
        gear_lag_s: f64,
        ripple: impl Iterator<Item = (u32, f64, f64)>,
    ) -> Self {
        let l_rad = gear_lag_s * theta1_rate_rad_s;
        let harmonic = std::array::from_fn(|n| {
            let nf = n as f64;
            let (s, c) = (nf * l_rad).sin_cos();
            let w = (nf * half_width_rad).cos();
            (w * s, w * c)
        });
        let mut edge = Self { harmonic, shift_rad: 0.0, dshift_dlag: 0.0 };
        for (n, a, b) in ripple {
            let (s, c) = edge.harmonic[n as usize];
            edge.shift_rad += (a * s - b * c) / f64::from(n);
            edge.dshift_dlag += (a * c + b * s) * theta1_rate_rad_s;
        }
        edge
    }
}

impl Ctx<'_> {
    /// Rate along axis `a`, °/s.
    #[inline]
    pub fn axis_rate(&self, p: &Point, a: usize) -> f64 {
        dot(&self.s_hat[a], &p.omega)
    }

    /// Coefficient of linear column `c` on axis `a` (0 when not in the model).
    pub fn beta(&self, a: usize, c: LinCol) -> f64 {
        self.lin.iter().position(|&q| q == c).map_or(0.0, |i| self.beta[a][i])
    }
}

/// Which effects the residual points to: an effect is tried only if the structure it makes was
/// found (the loop traces the residual to effects; an effect too weak to show in any run's
/// diagnostics cannot bias the calibration beyond its noise either). Broadband structure alone
/// (not white, RMS excess) points to every effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Evidence {
    /// 1× harmonic in some run: phase (delay, index offset).
    pub phase: bool,
    /// Run offsets, drift in time, or temperature dependence.
    pub drift: bool,
    /// Harmonics 2× and up, or dependence on the rate magnitude.
    pub rate_scale: bool,
    /// Per harmonic order 0..=MAX_HARMONIC_ORDER, whether it was significant somewhere.
    pub orders: [bool; super::MAX_HARMONIC_ORDER + 1],
}

/// What the loop knows when it chooses the candidates of a step.
#[derive(Clone, Copy)]
pub struct Situation<'a> {
    /// The effects in the model.
    pub current: &'a [Effect],
    /// What the diagnostics found.
    pub evidence: Evidence,
    /// Whether the runs hold two distinct signed θ2' (speeds or directions).
    pub separates_delay_and_index: bool,
    /// The runs' distinct signed θ2', °/s (speeds and directions, each once).
    pub distinct_rates_dps: &'a [f64],
    /// Whether the free drift leaves the constant rate terms to the model
    /// (`selection::free_drift_keeps_constant_rates`).
    pub free_drift_keeps_constant_rates: bool,
    /// Poses in the data.
    pub poses: usize,
    /// Spread of the smoothed die temperature over the capture, °C: a sweep over every sample,
    /// so asked for only by the rule that needs it.
    pub temp_spread_c: &'a dyn Fn() -> f64,
}

impl Situation<'_> {
    /// Whether `e` is in the model.
    pub fn has(&self, e: Effect) -> bool {
        self.current.contains(&e)
    }

    /// [`separates_rate_powers`] of the runs' rates.
    pub fn separates_rate_powers(&self, powers: &[i32]) -> bool {
        separates_rate_powers(self.distinct_rates_dps, powers)
    }

    /// Whether a vector fixed to the base turns in the model: the g-sensitivity's gravity, or
    /// Earth's vertical rate fitted.
    pub fn has_base_vector(&self) -> bool {
        self.has(Effect::GSensitivity) || self.has(Effect::EarthRotation)
    }

    /// Whether a drift model is in.
    pub fn has_drift(&self) -> bool {
        self.current.iter().any(|e| e.is_drift())
    }

    /// Whether the free drift is in.
    pub fn has_free_drift(&self) -> bool {
        self.current.iter().any(|e| e.is_free_drift())
    }

    /// Whether a delay, an index offset or their combined phase is in.
    pub fn phase_modelled(&self) -> bool {
        self.has(Effect::Delay) || self.has(Effect::IndexOffset) || self.has(Effect::Phase)
    }
}

/// One form a candidate is tried in: its columns, and for an effect whose one shared parameter
/// is first tried on a grid (the warm-up's T), the grid value, held for the first pass.
#[derive(Debug, Clone)]
pub struct Trial {
    /// The columns in the accumulation.
    pub cols: Vec<Col>,
    /// The grid value, if any.
    pub held_at: Option<f64>,
}

/// exp(−t/τ), 0 beyond 700 time constants: exp would return 1e-304 or a subnormal there, and
/// glibc takes a slow path for the underflow (6 % of a 1-h calibration, from the warm-up
/// candidates' short τ late in a long capture).
#[inline]
pub fn decay(t_s: f64, tau_s: f64) -> f64 {
    let x = t_s / tau_s;
    if x > 700.0 {
        0.0
    } else {
        (-x).exp()
    }
}

/// ∂ω_s/∂θ2 (before ripple) through the rippled angle and speed: the vector whose product with
/// an axis's gradient is [`AxisTerms::d_shift`].
#[inline]
pub fn shift_vector(p: &Point) -> [f64; 3] {
    std::array::from_fn(|i| p.dtheta_eff * p.d_theta2[i] + p.drate_eff_dps * p.d_rate2[i])
}

/// A shared column from its gradient factor ([`super::Behaviour::gradient_factor`]): `t.u` ·
/// `factor`, 0 where it has none.
#[inline]
pub fn along_gradient(t: &AxisTerms, factor: Option<[f64; 3]>) -> f64 {
    factor.map_or(0.0, |f| dot(&t.u, &f))
}

/// x · y.
#[inline]
pub fn dot(x: &[f64; 3], y: &[f64; 3]) -> f64 {
    x[0] * y[0] + x[1] * y[1] + x[2] * y[2]
}

/// How large an effect may plausibly be when the runs cannot measure it: one standard
/// uncertainty of each of its parameters, in the parameter's reported unit
/// ([`super::Behaviour::reported`]), with where that figure comes from. It enters the
/// calibration's covariance as a consider parameter (`calib::analysis::consider`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConsiderBound {
    /// One standard uncertainty, reported unit.
    pub sigma: f64,
    /// Its source: a datasheet table, physics, or a stated engineering judgement.
    pub source: &'static str,
}

/// Whether runs at the distinct signed θ2' `rates_dps` (°/s) tell apart effects whose part
/// turning with θ2 grows as these powers of θ2' (M's signal: 1; a vector fixed to the base,
/// gravity's or Earth's vertical rate: 0; the filter's droop κθ2'²·θ1': 3): the rates' powers,
/// a row per rate, have full column rank. At one speed in both directions r³ is r times a
/// constant; at two speeds in one direction 1, r and r³ are three shapes over two values.
pub fn separates_rate_powers(rates_dps: &[f64], powers: &[i32]) -> bool {
    let top = rates_dps.iter().fold(0.0f64, |m, r| m.max(r.abs()));
    if rates_dps.len() < powers.len() || top <= 0.0 {
        return false;
    }
    let m = nalgebra::DMatrix::from_fn(rates_dps.len(), powers.len(), |i, j| (rates_dps[i] / top).powi(powers[j]));
    let sv = m.singular_values();
    let largest = sv.max();
    // Rank to 1e-6 of the largest singular value: the rates are known to better than 1e-4
    // (the encoder's count over a run), and a shape that close to the others is no shape.
    sv.iter().all(|&v| v > 1e-6 * largest)
}

/// What an effect's [`super::Behaviour::consider`] may look at.
#[derive(Debug, Clone, Copy)]
pub struct ConsiderCtx<'a> {
    /// The effects in the final model.
    pub current: &'a [Effect],
    /// The gyro's configured low-pass cut-off, Hz.
    pub cutoff_hz: f64,
    /// The gyro's full scale, °/s.
    pub full_scale_dps: f64,
    /// The model's fitted delay between gyro and encoder, s, if it holds one.
    pub delay_s: Option<f64>,
    /// Whether the die's temperature readings changed over the capture
    /// ([`crate::calib::engine::LoopData::temp_moved`]).
    pub temp_moved: bool,
}

impl ConsiderCtx<'_> {
    /// Whether `e` is in the model.
    pub fn has(&self, e: Effect) -> bool {
        self.current.contains(&e)
    }
}

#[cfg(test)]
mod tests {
    use super::{Effect, Evidence, IndexEdge, Situation};

    /// The error at mesh angle θ of harmonics (n, a, b), rad: Σ (a·sin nθ − b·cos nθ)/n.
    fn error_rad(harmonics: &[(u32, f64, f64)], theta_rad: f64) -> f64 {
        harmonics
            .iter()
            .map(|&(n, a, b)| {
                (a * (f64::from(n) * theta_rad).sin() - b * (f64::from(n) * theta_rad).cos()) / f64::from(n)
            })
            .sum()
    }

    /// The shift is the mean of the error at the two edges, ±h + c·θ1', and its derivative in the
    /// gear lag c matches a central difference (to 1e-6 of it: the difference's own O(step²) error
    /// at 24× is ~5e-7).
    #[test]
    fn the_index_edge_shift_is_the_mean_error_at_the_plate_edges() {
        let harmonics = [(12, 4e-3, -1e-3), (24, 1e-3, 2e-3), (1, -5e-4, 3e-4)];
        let (h_rad, rate_rad_s, lag_s) = (3f64.to_radians(), -std::f64::consts::PI, 2e-3);
        let edge = IndexEdge::new(h_rad, rate_rad_s, lag_s, harmonics.iter().copied());
        let at = |lag: f64| {
            (error_rad(&harmonics, h_rad + lag * rate_rad_s) + error_rad(&harmonics, -h_rad + lag * rate_rad_s)) / 2.0
        };
        assert!((edge.shift_rad - at(lag_s)).abs() < 1e-15, "{} against {}", edge.shift_rad, at(lag_s));
        let step = 1e-5;
        let numeric = (at(lag_s + step) - at(lag_s - step)) / (2.0 * step);
        assert!(
            (edge.dshift_dlag - numeric).abs() <= 1e-6 * numeric.abs().max(1e-12),
            "{} against {numeric}",
            edge.dshift_dlag
        );
        // No ripple: no shift, whatever the plate.
        let none = IndexEdge::new(h_rad, rate_rad_s, lag_s, std::iter::empty());
        assert_eq!((none.shift_rad, none.dshift_dlag), (0.0, 0.0));
    }

    /// The situation of a model holding `current` on runs at `rates` (°/s, distinct).
    fn situation<'a>(rates: &'a [f64], current: &'a [Effect]) -> Situation<'a> {
        fn no_spread() -> f64 {
            0.0
        }
        Situation {
            current,
            evidence: Evidence {
                phase: false,
                drift: false,
                rate_scale: false,
                orders: [false; super::super::MAX_HARMONIC_ORDER + 1],
            },
            separates_delay_and_index: true,
            distinct_rates_dps: rates,
            free_drift_keeps_constant_rates: true,
            poses: 2,
            temp_spread_c: &no_spread,
        }
    }

    /// Which designs tell the filter's droop (θ2'³) from M (θ2') and a base-fixed vector (1),
    /// and which effects are such a vector.
    #[test]
    fn rate_powers_are_told_apart_by_enough_distinct_rates() {
        let apart = |rates: &[f64], powers: &[i32]| situation(rates, &[]).separates_rate_powers(powers);
        let (droop, with_base) = ([1, 3], [0, 1, 3]);
        assert!(apart(&[360.0, 180.0], &droop));
        assert!(!apart(&[360.0, -360.0], &droop), "at ±r, r³ is r·r²");
        assert!(!apart(&[360.0], &droop));
        assert!(!apart(&[360.0, 180.0], &with_base), "three shapes over two rates");
        assert!(!apart(&[360.0, -360.0, 720.0, -720.0][..2], &with_base));
        assert!(apart(&[360.0, 180.0, -360.0], &with_base));
        assert!(apart(&[360.0, -360.0, 720.0, -720.0], &with_base));
        assert!(situation(&[], &[Effect::GSensitivity]).has_base_vector());
        assert!(situation(&[], &[Effect::EarthRotation]).has_base_vector());
        assert!(!situation(&[], &[Effect::EarthRotationHorizontal, Effect::FilterGain]).has_base_vector());
    }
}
