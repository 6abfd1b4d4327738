//! The effects the closed loop may add to the linear model `v = M R_qᵀ ω2 + v_off`, one type per
//! effect, each in its own file behind [`Behaviour`]: what it means physically and what makes it
//! identifiable, its parameters (names, units, bounds), its contribution to the output and its
//! Jacobian per sample, where its shared parameters enter the exciter's kinematics, and when the
//! loop tries it. The engine ([`crate::calib::engine`]) and the selection ([`crate::calib::analysis::selection`]) know
//! effects only through this trait.
//!
//! Adding an effect is a file here and a line in the `registry!` below (with its `mod` line): the
//! registry makes the [`Effect`] enum and its dispatch, and the trait has no default for
//! anything an effect must say, so the compiler names what a new one forgot. An effect whose
//! shared parameters move the kinematics uses the chain's inputs ([`terms::Shifts`]: a time
//! shift, an angle shift, a gear lag, a ripple, a tilt, a lab-fixed rate, a filter curvature, a
//! fixture rotation); one that needs a new kind of input to eq. 1 adds it there and in the chain.

pub mod terms;

mod axis_delay;
mod delay;
mod drift_knots;
mod drift_polynomial;
mod drift_temperature;
mod drift_warm_up;
mod earth;
mod encoder_eccentricity;
mod filter_gain;
mod g_sensitivity;
mod gear_lag;
mod index_offset;
mod phase;
mod pose_fixture;
mod rate_power;
mod rate_scale;
mod rig_clock;
mod scale_temperature;
mod stretch_level;
mod table_harmonic;
mod table_tilt;

pub use delay::MAX_DELAY_S;
pub use drift_warm_up::DRIFT_TAU_RANGE_S;
pub use encoder_eccentricity::encoder_error;
pub use rate_power::RATE_POWERS;
pub use table_harmonic::{GEAR_POLE_PASS_ORDER, HARMONIC_ORDERS};
pub use terms::DRIFT_KNOT_SPACINGS_S;

use crate::calib::data::layout::Layout;
use serde::{Deserialize, Serialize};
use std::fmt;
use terms::{
    AxisTerms, Col, ConsiderBound, ConsiderCtx, Ctx, Kind, LinCol, Needs, Own, Point, Reported, SharedPar, Shifts,
    Situation, Trial,
};

/// Highest harmonic of the sensor-table rate fitted sample by sample (diagnostics and the
/// transmission-error model): the 12-pole magnetic gears (EXCITER.md, "Mechanism") pass a pole
/// pair 12 times a turn, so their transmission error sits at 12× and its overtone at 24×. Gears
/// of other pole counts put them elsewhere (16 poles: 16× and 32×; 20: 40×); 48 holds a 24-pole
/// gear's overtone (engineering judgement: more poles than that make the error too fine to
/// matter). 48× at 0.5 Hz is 24 Hz, below every L3G4200D cut-off at 800 Hz ODR (Table 21: 30 Hz
/// and up). A 20-pole gear's 40× line, beyond the 32 this was, flagged every capture of it
/// (`a_twenty_pole_gears_overtone_is_fitted`); the passes cost the same (CPU ratio 0.997 on
/// `realistic-2speed-s101`). Harmonics above it are searched in the residual spectrum up to
/// what the sample rate resolves (`diagnostics`).
pub const MAX_HARMONIC_ORDER: usize = 48;

/// One effect's physics and maths.
pub trait Behaviour {
    /// Short name as printed.
    fn name(&self) -> String;

    /// A short machine-friendly key (JSON, tests).
    fn key(&self) -> String;

    /// What it means physically, as the report says it.
    fn meaning(&self) -> &'static str;

    /// What separates it from the rest of the model (the runs it needs).
    fn identified_by(&self) -> &'static str;

    /// Its family.
    fn kind(&self) -> Kind;

    /// Its per-axis linear columns and its shared parameters, for data laid out as `layout`.
    fn params(&self, layout: &Layout) -> (Vec<LinCol>, Vec<SharedPar>);

    /// How parameter `p` is reported (None for columns reported otherwise, such as the free
    /// drift's knots); `full_scale_dps` is the gyro's range.
    fn reported(&self, p: Own, full_scale_dps: f64) -> Option<Reported>;

    /// The range shared parameter `k` is held in, if any.
    fn bound(&self, k: u8) -> Option<Bound>;

    /// What physics says of shared parameter `k`'s size (None, the default: only the data
    /// bound it): the largest it can be and a zero-mean Gaussian prior. A fit whose runs cannot
    /// bound it within that size (its σ from the data alone larger) holds it by the prior from
    /// then on ([`crate::calib::engine::Model::prior_held`]): its value and σ then describe
    /// the Earth, say, not the runs' blindness to it, which a free fit carries into M's σ.
    fn prior(&self, k: u8) -> Option<terms::PhysicalPrior> {
        let _ = k;
        None
    }

    /// The runs shared parameter `k` can move the output in, when not all (None, the default):
    /// a pass leaves its column out of the sums of every other run, where it is zero.
    fn scope(&self, k: u8) -> Option<terms::RunScope> {
        let _ = k;
        None
    }

    /// Sets the kinematic chain's input that shared parameter `k` is, at `value` (nothing for an
    /// effect that acts on the output, [`Behaviour::on_output`]).
    fn shift(&self, k: u8, value: f64, s: &mut Shifts);

    /// Whether it acts on the output rather than on the chain's inputs, linearly in its shared
    /// parameters: the prediction adds Σ_k θ_k·`value(Own::Shared(k))` on each axis, so its
    /// Jacobian is its column exactly, and the engine needs no input of its own for it.
    fn on_output(&self) -> bool {
        false
    }

    /// The value at `p` on axis `a` of linear column `Own::Lin(k)`, or of shared parameter
    /// `Own::Shared(k)`'s Jacobian, ∂(output)/∂θ_k, given the axis's chain-rule factors `t`
    /// (unused, NaN, for a linear column).
    fn value(&self, own: Own, p: &Point, a: usize, t: &AxisTerms, cx: &Ctx) -> f64;

    /// Where shared parameter `own`'s Jacobian on every axis is that axis's gradient
    /// `t.u` = ∂(output)/∂ω_s against one vector of the package frame, ∂ω_s/∂θ_k: that vector at
    /// `p`, so that a pass takes it once for the three axes (`value` is then `t.u` · it,
    /// [`terms::along_gradient`]). None (the default): `value` is taken axis by axis.
    fn gradient_factor(&self, _own: Own, _p: &Point, _cx: &Ctx) -> Option<[f64; 3]> {
        None
    }

    /// Whether the loop tries it now.
    fn candidate(&self, s: &Situation) -> bool;

    /// While it is not in the model (`cx.current`), how large parameter `own` may plausibly be
    /// (None: it cannot bias M or the offsets, or another term of the model already holds it).
    /// Where the runs cannot separate it, that size is carried in the calibration's σ.
    fn consider(&self, own: Own, cx: &ConsiderCtx) -> Option<ConsiderBound>;

    /// Why its fitted values cannot be the physics it stands for, given the fit (`fitted(p)`: a
    /// shared parameter's value and σ, when the model has it): a value the data put beyond
    /// what the effect can physically be, by more than their noise, says it soaks up something
    /// else, and its fit is refused. None (the default) when nothing bounds it but the data.
    fn beyond_physics(&self, fitted: &dyn Fn(SharedPar) -> Option<(f64, f64)>) -> Option<String> {
        let _ = fitted;
        None
    }

    /// Whether its linear columns are the levels of a walk, each stretch's first level held by
    /// the offsets: [`Behaviour::consider`] then bounds the steps between neighbouring levels,
    /// which the walk takes independently, and this names one step. None for every other effect.
    fn considered_as_walk(&self) -> Option<String> {
        None
    }

    /// Whether the size [`Behaviour::consider`] gives is a scale the data bound rather than a
    /// size of its own, and how the notes say it: the consider covariance then takes it times
    /// the 95 % upper bound the residual's own sight of the parameters puts on that scale (a
    /// walk's steps, the levels between stretches: many parameters each seen a little, none
    /// of which a test speaks for). None (the default) for a size taken as it is.
    fn size_read_from_data(&self) -> Option<&'static str> {
        None
    }

    /// Where parameter `own`, at value p (its fitted unit), also scales every sensitivity by
    /// −f·p² beyond what its column (the first derivative at the model's values) carries: the
    /// factor f. The consider covariance then carries that second-order scale from the
    /// parameter's posterior where the runs do not separate it (a table tilt's 1 − cos ε).
    /// None (the default): the effect is linear enough in its parameters at their plausible size.
    fn scale_per_square(&self, own: Own) -> Option<f64> {
        let _ = own;
        None
    }

    /// What of a point parameter `own` needs beyond eq. 1-2.
    fn needs(&self, own: Own) -> Needs {
        let _ = own;
        Needs::NONE
    }

    /// For a linear column that depends on the axis's own rate r (°/s), ∂(column)/∂r at `r`
    /// (the output's gradient in ω_s then has a part along the axis); None for the others.
    fn rate_slope(&self, k: u16, r_dps: f64) -> Option<f64> {
        let _ = (k, r_dps);
        None
    }

    /// The highest multiple of the turn rate (the faster of the base's and the sensor table's)
    /// at which its columns and its Jacobians vary appreciably: how long a pass's cells may be
    /// ([`crate::calib::engine::cells`]). By default 2: a lab-fixed quantity seen through both
    /// turns varies at the sum of their rates, twice the turn rate on a 1:1 gear.
    fn turn_multiple(&self) -> u32 {
        2
    }

    /// The forms it is tried in: by default its own columns, once.
    fn trials(&self, layout: &Layout) -> Vec<Trial> {
        let (lin, shared) = self.params(layout);
        vec![Trial {
            cols: lin.into_iter().map(Col::Lin).chain(shared.into_iter().map(Col::Shared)).collect(),
            held_at: None,
        }]
    }
}

pub use terms::Bound;

/// Declares the catalogue: one line per effect, `Variant => constructor` or, for an effect with
/// a parameter, `Variant(x: type in values) => constructor using x`, where `values` are those
/// the loop tries. The order is the order candidates are listed in.
macro_rules! registry {
    ($( $(#[$m:meta])* $v:ident $(($x:ident : $t:ident in $vals:expr))? => $ctor:expr ),* $(,)?) => {
        /// One catalogued effect (its physics: the type the registry maps it to).
        #[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum Effect {
            $( $(#[$m])* $v $(($t))? ),*
        }

        impl Effect {
            /// Calls `f` with the effect's behaviour.
            #[inline]
            pub fn behaviour<R>(self, f: impl FnOnce(&dyn Behaviour) -> R) -> R {
                match self {
                    $( Effect::$v $(($x))? => f(&$ctor) ),*
                }
            }

            /// Every effect the loop may try, in the order candidates are listed.
            pub fn catalogue() -> Vec<Effect> {
                let mut out = Vec::new();
                $( out.extend(registry!(@each $v $(, $vals)?)); )*
                out
            }
        }
    };
    (@each $v:ident) => { [Effect::$v] };
    (@each $v:ident, $vals:expr) => { $vals.into_iter().map(Effect::$v) };
}

registry! {
    /// [`delay::Delay`].
    Delay => delay::Delay,
    /// [`axis_delay::AxisDelay`].
    AxisDelay => axis_delay::AxisDelay,
    /// [`index_offset::IndexOffset`].
    IndexOffset => index_offset::IndexOffset,
    /// [`phase::Phase`].
    Phase => phase::Phase,
    /// [`drift_warm_up::DriftWarmUp`].
    DriftWarmUp => drift_warm_up::DriftWarmUp,
    /// [`drift_polynomial::DriftPolynomial`].
    DriftPolynomial => drift_polynomial::DriftPolynomial,
    /// [`drift_temperature::DriftTemperature`].
    DriftTemperature => drift_temperature::DriftTemperature,
    /// [`drift_knots::DriftKnots`], knots this many seconds apart.
    DriftKnots(spacing_s: u16 in DRIFT_KNOT_SPACINGS_S) => drift_knots::DriftKnots(spacing_s),
    /// [`gear_lag::GearLag`].
    GearLag => gear_lag::GearLag,
    /// [`filter_gain::FilterGain`].
    FilterGain => filter_gain::FilterGain,
    /// [`table_tilt::TableTilt`].
    TableTilt => table_tilt::TableTilt,
    /// [`pose_fixture::PoseFixture`].
    PoseFixture => pose_fixture::PoseFixture,
    /// [`g_sensitivity::GSensitivity`].
    GSensitivity => g_sensitivity::GSensitivity,
    /// [`rate_scale::RateScale`].
    RateScale => rate_scale::RateScale,
    /// [`rate_power::RatePower`], the rate to this power.
    RatePower(power: u8 in RATE_POWERS) => rate_power::RatePower(power),
    /// [`scale_temperature::ScaleTemperature`].
    ScaleTemperature => scale_temperature::ScaleTemperature,
    /// [`rig_clock::RigClock`].
    RigClock => rig_clock::RigClock,
    /// [`stretch_level::StretchLevel`].
    StretchLevel => stretch_level::StretchLevel,
    /// [`encoder_eccentricity::EncoderError`] once a turn.
    EncoderEccentricity => encoder_eccentricity::EncoderError(1),
    /// [`encoder_eccentricity::EncoderError`] twice a turn.
    EncoderEllipticity => encoder_eccentricity::EncoderError(2),
    /// [`table_harmonic::TableHarmonic`] at this multiple of θ2.
    TableHarmonic(order: u32 in HARMONIC_ORDERS) => table_harmonic::TableHarmonic(order),
    /// [`earth::Earth`], all three components fitted.
    EarthRotation => earth::Earth(earth::Form::Fitted),
    /// [`earth::Earth`], the vertical part from the latitude the user gave.
    EarthRotationAtLatitude => earth::Earth(earth::Form::AtLatitude),
    /// [`earth::Earth`], the vertical part held by the g-sensitivity.
    EarthRotationHorizontal => earth::Earth(earth::Form::Horizontal),
}

impl Effect {
    /// Short name as printed.
    pub fn name(self) -> String {
        self.behaviour(|b| b.name())
    }

    /// A short machine-friendly key (JSON, tests).
    pub fn key(self) -> String {
        self.behaviour(|b| b.key())
    }

    /// What it means physically, as the report says it.
    pub fn meaning(self) -> &'static str {
        self.behaviour(|b| b.meaning())
    }

    /// [`Behaviour::turn_multiple`].
    pub fn turn_multiple(self) -> u32 {
        self.behaviour(|b| b.turn_multiple())
    }

    /// What separates it from the rest of the model.
    pub fn identified_by(self) -> &'static str {
        self.behaviour(|b| b.identified_by())
    }

    /// Its family.
    pub fn kind(self) -> Kind {
        self.behaviour(|b| b.kind())
    }

    /// Whether it is one of the mutually exclusive offset-drift models.
    pub fn is_drift(self) -> bool {
        matches!(self.kind(), Kind::Drift { .. })
    }

    /// Whether it is the free drift.
    pub fn is_free_drift(self) -> bool {
        matches!(self.kind(), Kind::Drift { free: true, .. })
    }

    /// Whether it is one of the forms of Earth's rotation (at most one is in a model).
    pub fn is_earth(self) -> bool {
        self.kind() == Kind::Earth
    }

    /// For a drift model, the time or temperature its fitted offset (the constant column's
    /// coefficient) holds at; None for the effects that leave the offset constant.
    pub fn offset_reference(self) -> Option<&'static str> {
        match self.kind() {
            Kind::Drift { offset_reference, .. } => Some(offset_reference),
            Kind::Earth | Kind::Other => None,
        }
    }

    /// Its columns for data laid out as `layout`.
    pub fn params(self, layout: &Layout) -> (Vec<LinCol>, Vec<SharedPar>) {
        self.behaviour(|b| b.params(layout))
    }

    /// Its plausible size while the model lacks it ([`Behaviour::consider`]).
    pub fn consider(self, own: Own, cx: &ConsiderCtx) -> Option<ConsiderBound> {
        self.behaviour(|b| b.consider(own, cx))
    }

    /// [`Behaviour::scale_per_square`].
    pub fn scale_per_square(self, own: Own) -> Option<f64> {
        self.behaviour(|b| b.scale_per_square(own))
    }

    /// [`Behaviour::considered_as_walk`].
    pub fn considered_as_walk(self) -> Option<String> {
        self.behaviour(|b| b.considered_as_walk())
    }

    /// [`Behaviour::size_read_from_data`].
    pub fn size_read_from_data(self) -> Option<&'static str> {
        self.behaviour(|b| b.size_read_from_data())
    }

    /// [`Behaviour::beyond_physics`].
    pub fn beyond_physics(self, fitted: &dyn Fn(SharedPar) -> Option<(f64, f64)>) -> Option<String> {
        self.behaviour(|b| b.beyond_physics(fitted))
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;

    fn layout() -> Layout {
        Layout::new(vec![Pose::One, Pose::Two], &[Pose::One, Pose::Two], &[(0.0, 100.0), (0.0, 100.0)])
    }

    /// Every effect's parameters belong to it, every shared one has a name and unit, and keys
    /// are unique (they name effects in loop.json).
    #[test]
    fn every_effect_owns_and_names_its_parameters() {
        let all = Effect::catalogue();
        let earth = [Effect::EarthRotation, Effect::EarthRotationAtLatitude, Effect::EarthRotationHorizontal];
        assert_eq!(all.len(), 18 + earth.len() + RATE_POWERS.len() + DRIFT_KNOT_SPACINGS_S.len() + MAX_HARMONIC_ORDER);
        let mut keys: Vec<String> = all.iter().map(|e| e.key()).collect();
        keys.sort();
        keys.dedup();
        assert_eq!(keys.len(), all.len());
        for e in all {
            let (lin, shared) = e.params(&layout());
            assert!(!lin.is_empty() || !shared.is_empty(), "{e:?} has no parameter");
            for p in shared {
                assert_eq!(p.effect, e);
                let r = p.reported();
                assert!(!r.unit.is_empty() && !r.name.contains("parameter"), "{e:?}: {r:?}");
            }
            for c in lin {
                match c {
                    LinCol::Of(owner, _) => {
                        assert_eq!(owner, e);
                        assert!(c.reported(500.0).is_some(), "{e:?}: {c:?}");
                    }
                    LinCol::DriftKnot { .. } => assert!(e.is_free_drift()),
                    LinCol::Omega(_) | LinCol::One | LinCol::DriftExpFixed(_) => panic!("{e:?} owns a base column"),
                }
            }
        }
    }
}
