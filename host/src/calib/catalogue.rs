//! The effects the closed loop may add to the linear model `v = M R_qᵀ ω2 + v_off`, each with
//! what it means physically and what in the runs makes it identifiable. The maths of each lives
//! in [`super::extended`]; the decision to add one in [`super::selection`].

use serde::{Deserialize, Serialize};
use std::fmt;

/// Highest harmonic of the sensor-table rate fitted sample by sample (diagnostics and the
/// transmission-error model): the 12-pole magnetic gears (EXCITER.md, "Mechanism") pass a pole
/// pair 12 times a turn, so their transmission error sits at 12× and its overtone at 24×; 32
/// leaves margin above both. 32× at 0.5 Hz is 16 Hz, inside every L3G4200D bandwidth (≥ 12.5 Hz
/// only at 100 Hz ODR). Harmonics above it are searched in the residual spectrum up to what the
/// sample rate resolves (`diagnostics`).
pub const MAX_HARMONIC_ORDER: usize = 32;

/// Harmonics of the sensor-table rate in the catalogue: 1× (a once-per-turn eccentricity of the
/// sensor table's angle, as an angle error it is not the linear model's 1× term) up to
/// [`MAX_HARMONIC_ORDER`].
pub const HARMONIC_ORDERS: std::ops::RangeInclusive<u32> = 1..=MAX_HARMONIC_ORDER as u32;

/// Pole pairs passed per relative turn by the 12-pole magnetic gears (EXCITER.md).
pub const GEAR_POLE_PASS_ORDER: u32 = 12;

/// One catalogued effect.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    /// The gyro output lags the encoder by τ: v(t) = f(kinematics at t − τ). Shifts θ2 by −θ2'·τ,
    /// so it differs from an index offset only between runs at different θ2'.
    Delay,
    /// The index plate is δ off θ2 = 0: θ2_true = θ2_index + δ, the same shift at every speed.
    IndexOffset,
    /// A delay and an index offset together when the runs share one θ2' and cannot tell them
    /// apart: one phase δ − θ2'·τ.
    Phase,
    /// Offsets settling exponentially after power-up (warm-up): b + c·exp(−t/T), T fitted.
    DriftWarmUp,
    /// Offsets drifting as a quadratic in time.
    DriftPolynomial,
    /// Offsets following the die temperature (OUT_TEMP, smoothed), linearly.
    DriftTemperature,
    /// Scale depending on the rate along the axis: |r| (asymmetry between the signs) and r·|r|
    /// (odd quadratic non-linearity).
    RateScale,
    /// The sensor table lags the base by an angle proportional to speed (the magnetic gears'
    /// compliance under drag): θ2 moves by −θ1'·c, while the transmission error, a function of the
    /// base angle, does not. Only the transmission error's phase tells it from a gyro delay.
    GearLag,
    /// The gyro's low-pass filter beyond its delay: H(jω) ≈ e^{−jωτ}(1 − κω²), the gain lost at the
    /// table frequency (1st order: κ = τ²/2; 2nd-order Butterworth: κ ≈ 0).
    FilterGain,
    /// Earth's rotation, fixed in the lab, seen through θ1 and θ2: its component along the base
    /// axis adds to θ1' (a scale error that shrinks with speed), its horizontal component turns
    /// with the base. Three components, °/s.
    EarthRotation,
    /// g-sensitivity: a bias in proportion to the specific force, here gravity, which turns in the
    /// sensor frame with θ2 at the table's own frequency (so it bends directions), three
    /// coefficients per axis, °/s per g.
    GSensitivity,
    /// The sensor-table axis z2 not perpendicular to the base axis z1 by ε: θ1' then has a part
    /// θ1'·sin ε along z2, which adds to θ2' in proportion to speed.
    TableTilt,
    /// Earth's rotation with its vertical part known from the latitude the user gave: only the
    /// two horizontal components (the heading) are fitted.
    EarthRotationAtLatitude,
    /// Earth's rotation with only its two horizontal components fitted, in a model with
    /// g-sensitivity and no latitude: the vertical part turns in the sensor frame exactly as
    /// gravity does (both lie along the base axis), so it is a g-sensitivity along M's rows,
    /// ≤ Ω/g = 0.0042 °/s/g, and that term holds it; the sensitivities and directions do not
    /// depend on which of the two holds it.
    EarthRotationHorizontal,
    /// A periodic angle error of the sensor table at n× θ2 that encoder and index cannot see
    /// (magnetic-gear pole pass, eccentricity), with its derivative in θ2'; seen by every axis
    /// through M R_qᵀ, one coefficient pair per pose.
    TableHarmonic(u32),
    /// The pose-2 fixture turned about the table axis z2 against pose 1's (the operator
    /// re-mounts the sensor between poses): an index offset of pose 2's own. Relative, since a
    /// rotation common to both poses turns every axis alike and no run can see it. Its tilts
    /// about x2 and y2 trade off against the per-pose 1× transmission term on the outside
    /// validation capture (0.13° of direction error), so they are not fitted.
    PoseFixture,
    /// Offsets that wander with no assumed shape (a rate random walk on top of a warm-up that
    /// lags the die temperature): linear between knots about this many seconds apart, one
    /// continuous curve through the runs of a pose that follow each other on one clock
    /// (`extended::Stretch`), a level of its own after a remount or a gap.
    DriftKnots(u16),
}

/// Knot spacings of the free drift model tried, s. The longest leaves one level and slope per
/// 2-min run; the shortest follows a random walk of 0.005 °/s/√s (the top of issue 10's range)
/// to its interpolation error K·√(T/6) ≈ 6 m°/s over 10 s, a third of the 10-s-mean test's 3σ at
/// the L3G4200D's 0.03 °/s/√Hz, and is still 5 turns of the table at 0.25 Hz, so the knots
/// cannot follow the table-rate signal.
pub const DRIFT_KNOT_SPACINGS_S: [u16; 3] = [40, 20, 10];

impl Effect {
    /// Short name as printed.
    pub fn name(self) -> String {
        match self {
            Effect::Delay => "delay between gyro and encoder".into(),
            Effect::IndexOffset => "index offset".into(),
            Effect::Phase => "phase (delay and index offset combined)".into(),
            Effect::DriftWarmUp => "offset drift: exponential warm-up in time".into(),
            Effect::DriftPolynomial => "offset drift: quadratic in time".into(),
            Effect::DriftTemperature => "offset drift: linear in temperature".into(),
            Effect::RateScale => "rate-dependent scale (non-linearity, asymmetry)".into(),
            Effect::EarthRotation => "Earth rotation".into(),
            Effect::GSensitivity => "g-sensitivity (bias from gravity)".into(),
            Effect::TableTilt => "sensor-table axis not perpendicular to the base axis".into(),
            Effect::EarthRotationAtLatitude => "Earth rotation (vertical from the latitude)".into(),
            Effect::EarthRotationHorizontal => "Earth rotation (horizontal; vertical held by the g-sensitivity)".into(),
            Effect::FilterGain => "gyro low-pass gain at the table frequency".into(),
            Effect::GearLag => "magnetic-gear lag growing with speed".into(),
            Effect::TableHarmonic(n) if n % GEAR_POLE_PASS_ORDER == 0 => {
                format!("magnetic-gear transmission error at {n}× (pole pass)")
            }
            Effect::TableHarmonic(1) => "sensor-table eccentricity (transmission error at 1×)".into(),
            Effect::TableHarmonic(n) => format!("table-speed ripple at {n}× the sensor-table rate"),
            Effect::PoseFixture => "pose-2 fixture turned about the table axis against pose 1".into(),
            Effect::DriftKnots(t) => format!("offset drift: free, linear between knots {t} s apart"),
        }
    }

    /// A short machine-friendly key (JSON, tests).
    pub fn key(self) -> String {
        match self {
            Effect::Delay => "delay".into(),
            Effect::IndexOffset => "index_offset".into(),
            Effect::Phase => "phase".into(),
            Effect::DriftWarmUp => "drift_warm_up".into(),
            Effect::DriftPolynomial => "drift_polynomial".into(),
            Effect::DriftTemperature => "drift_temperature".into(),
            Effect::RateScale => "rate_scale".into(),
            Effect::EarthRotation => "earth_rotation".into(),
            Effect::GSensitivity => "g_sensitivity".into(),
            Effect::TableTilt => "table_tilt".into(),
            Effect::EarthRotationAtLatitude => "earth_rotation_at_latitude".into(),
            Effect::EarthRotationHorizontal => "earth_rotation_horizontal".into(),
            Effect::FilterGain => "filter_gain".into(),
            Effect::GearLag => "gear_lag".into(),
            Effect::TableHarmonic(n) => format!("table_harmonic_{n}"),
            Effect::PoseFixture => "pose_fixture".into(),
            Effect::DriftKnots(t) => format!("drift_knots_{t}s"),
        }
    }

    /// Whether it is one of the mutually exclusive offset-drift models.
    pub fn is_drift(self) -> bool {
        matches!(self, Effect::DriftWarmUp | Effect::DriftPolynomial | Effect::DriftTemperature | Effect::DriftKnots(_))
    }

    /// Whether it is one of the forms of Earth's rotation (at most one is in a model).
    pub fn is_earth(self) -> bool {
        matches!(self, Effect::EarthRotation | Effect::EarthRotationAtLatitude | Effect::EarthRotationHorizontal)
    }

    /// For a drift model, the time or temperature its fitted offset (the constant column's
    /// coefficient) holds at; None for the effects that leave the offset constant.
    pub fn offset_reference(self) -> Option<&'static str> {
        match self {
            Effect::DriftWarmUp => Some("the warmed-up level (t → ∞ of the exponential)"),
            Effect::DriftPolynomial => Some("the middle of the capture's time span, less half the quadratic term"),
            Effect::DriftTemperature => Some("the capture's mean die temperature"),
            Effect::DriftKnots(_) => Some("the first used sample of the first run (each pose has its own level)"),
            Effect::Delay
            | Effect::IndexOffset
            | Effect::Phase
            | Effect::RateScale
            | Effect::GearLag
            | Effect::FilterGain
            | Effect::EarthRotation
            | Effect::GSensitivity
            | Effect::TableTilt
            | Effect::EarthRotationAtLatitude
            | Effect::EarthRotationHorizontal
            | Effect::TableHarmonic(_)
            | Effect::PoseFixture => None,
        }
    }

    /// What it means physically, as the report says it.
    pub fn meaning(self) -> &'static str {
        match self {
            Effect::Delay => {
                "the gyro's low-pass filter delays its output (≈√2/(2π·f_c): 2 ms at 110 Hz, 7.5 ms at 30 Hz)"
            }
            Effect::IndexOffset => "the index shield plate is mounted off the θ2 the poses are defined for",
            Effect::Phase => "a delay, an index offset, or both",
            Effect::DriftWarmUp => "the zero-rate level follows the die as it warms up after power-up",
            Effect::DriftPolynomial => "the zero-rate level wanders slowly",
            Effect::DriftTemperature => "the zero-rate level follows the die temperature",
            Effect::DriftKnots(_) => {
                "the zero-rate level wanders in a way no single curve follows (a warm-up lagging the die temperature, a rate random walk of 0.001-0.005 °/s/√s): one continuous level through the runs of a pose, where the gyro stays powered and mounted, and a new one after each remount"
            }
            Effect::RateScale => "the sense chain is not linear, or its gain differs with the sign of the rate",
            Effect::GSensitivity => {
                "the MEMS proof masses feel gravity as a rate bias (typically 0.02-0.1 °/s/g); gravity turns with θ2 in the sensor frame"
            }
            Effect::TableTilt => {
                "the sensor table's axis is built a fraction of a degree off 90° to the base axis (0.1-0.5° is typical of such a rig)"
            }
            Effect::GearLag => {
                "the sensor table trails the base by an angle that grows with speed, so the gears' pole-pass error reaches it later than the base angle says"
            }
            Effect::FilterGain => {
                "the gyro's low-pass filter attenuates the table-rate sinusoid as well as delaying it (a 1st-order filter with 5 ms of delay loses 120 ppm at 0.5 Hz)"
            }
            Effect::EarthRotation | Effect::EarthRotationAtLatitude | Effect::EarthRotationHorizontal => {
                "the lab turns with the Earth at 15.041 °/h (IERS: 7.292115e-5 rad/s); at 180 °/s its vertical part alone is ≈ 13 ppm of θ1'"
            }
            Effect::TableHarmonic(_) => {
                "the sensor table's angle departs periodically from what encoder and index imply (magnetic-gear pole pass, eccentricity, compliance); its derivative ripples θ2'; a remount can re-seat the gear, so each pose has its own phase"
            }
            Effect::PoseFixture => {
                "the second pose's fixture holds the package turned a fraction of a degree about z2 off the nominal Ry(−90°)·R1 (machined fixtures: ~0.1°); to the data it is an index offset of pose 2's own"
            }
        }
    }

    /// What separates it from the rest of the model.
    pub fn identified_by(self) -> &'static str {
        match self {
            Effect::Delay | Effect::IndexOffset => {
                "runs at two speeds or in both directions (the delay's phase scales with θ2', the index offset's does not)"
            }
            Effect::Phase => "nothing more: a second speed or direction is needed to split it",
            Effect::DriftKnots(_) => {
                "its slow change within runs and its continuity from run to run in one pose; where runs at different rates share it, the constant rate terms (θ2'·M R_qᵀ e_z2, a table tilt's) step between runs and it does not, otherwise the directions and sensitivities rest on the table-rate sinusoids alone"
            }
            Effect::DriftWarmUp | Effect::DriftPolynomial | Effect::DriftTemperature => {
                "its slow change within and between runs; runs in both directions separate the offset from the constant θ2' term without relying on it"
            }
            Effect::RateScale => "the harmonics it makes in proportion to each axis's own rate",
            Effect::GSensitivity => {
                "runs at two speeds: the bias does not scale with θ1', a direction or sensitivity does"
            }
            Effect::TableTilt => {
                "runs at two speeds or directions: its part of θ2' scales with θ1', an offset does not"
            }
            Effect::GearLag => {
                "a transmission error seen at two speeds: its phase against the base angle shifts with speed, the gyro delay's does not"
            }
            Effect::FilterGain => {
                "runs at two speeds: the loss grows with the square of the frequency, a sensitivity does not"
            }
            Effect::EarthRotationAtLatitude => {
                "the base angle θ1: the horizontal part turns with it; the vertical part is Ω·sin(latitude), given"
            }
            Effect::EarthRotationHorizontal => {
                "the base angle θ1: the horizontal part turns with it; the vertical part cannot be told from a g-sensitivity along M's rows, which holds it"
            }
            Effect::EarthRotation => {
                "runs at two speeds or in both directions (its vertical part does not scale with θ1', a sensitivity does); the horizontal part turns with the base angle θ1"
            }
            Effect::TableHarmonic(_) => {
                "the same ripple in every axis and speed of a pose, in proportion to M R_qᵀ; its phase holds while the table stays engaged"
            }
            Effect::PoseFixture => {
                "two poses: the 1× phases of pose 2 at every speed turn by the same angle against pose 1's; a rotation common to both poses is not seen (it bounds the extrinsic angles)"
            }
        }
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}
