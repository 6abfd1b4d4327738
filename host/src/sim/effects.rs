//! Named, switchable departures from the ideal rig and sensor.
//!
//! Every effect is off by default, so that the plain simulation matches the calibration model
//! exactly (`v = M ω_s + v_off`, white noise, quantisation). Residual diagnostics are tested by
//! switching on effects the calibration model is not told about. Each effect's `Default` holds
//! its physical default; `Effects::enable` switches one on by name (for the command line).

use serde::{Deserialize, Serialize};

/// The effects in force. `None` = off.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Default)]
#[serde(default, deny_unknown_fields)]
pub struct Effects {
    /// The gyro's internal low-pass filter and/or a pure output delay.
    pub filter_delay: Option<FilterDelay>,
    /// The index plate mounted off θ2 = 0.
    pub index_offset: Option<IndexOffset>,
    /// Offsets drifting with the die temperature during warm-up.
    pub offset_drift: Option<OffsetDrift>,
    /// Motor speed ripple at harmonics of the base-table revolution.
    pub speed_ripple: Option<SpeedRipple>,
    /// Rate-dependent scale factor.
    pub nonlinearity: Option<Nonlinearity>,
    /// Actual gear ratio differing from the 1/1 announced in `Hello`.
    pub gear_ratio_error: Option<GearRatioError>,
    /// Structure outside every model: a θ2 harmonic on one axis.
    pub mystery_harmonic: Option<MysteryHarmonic>,
    /// Earth's rotation, fixed in the lab.
    pub earth_rotation: Option<EarthRotation>,
    /// Periodic transmission error of the magnetic gears.
    pub gear_transmission: Option<GearTransmission>,
    /// Rate bias in proportion to gravity.
    pub g_sensitivity: Option<GSensitivity>,
    /// Sensor-table axis off perpendicular to the base axis.
    pub table_tilt: Option<TableTilt>,
    /// The pose-2 fixture turned about the table axis against pose 1's.
    #[serde(default)]
    pub pose_fixture: Option<PoseFixture>,
    /// A rate random walk of the offset on every axis.
    #[serde(default)]
    pub bias_random_walk: Option<BiasRandomWalk>,
    /// Each sensing axis sampled at its own instant (a delay per axis beyond the common one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis_delay: Option<AxisDelay>,
    /// The rig's time base (the MCU's crystal) off its nominal frequency.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rig_clock: Option<RigClock>,
    /// The base encoder's scale off its shaft's axis: its reading errs once a turn.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoder_eccentricity: Option<EncoderEccentricity>,
    /// The base encoder's scale out of round: its reading errs twice a turn.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoder_ellipticity: Option<EncoderEccentricity>,
    /// The sensor package turned on its mount by the load of its own rotation (no model).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mount_compliance: Option<MountCompliance>,
    /// Sample timestamps more jittery than the firmware's
    /// ([`TimestampJitter::BASELINE_US`]), which it replaces.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timestamp_jitter: Option<TimestampJitter>,
    /// A capture taken on its own: a zero-rate level and a noise draw of its own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub capture_level: Option<CaptureLevel>,
    /// Offset, sensitivity and direction as functions of die temperature (`host simulate
    /// --chamber-c` switches it on; not in [`Effects::NAMES`]: a single session at one
    /// temperature cannot show it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature_dependence: Option<super::thermal::TemperatureDependence>,
}

/// Physical source: a MEMS gyro's proof masses are accelerometers too; typical parts show
/// 0.02-0.1 °/s/g (the L3G4200D datasheet gives no figure). Rows: sensing axes; columns: the
/// specific force along package x, y, z. Default: a mixed matrix of that size.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GSensitivity {
    /// °/s per g.
    pub dps_per_g: [[f64; 3]; 3],
}

impl Default for GSensitivity {
    fn default() -> Self {
        Self { dps_per_g: [[0.05, 0.01, 0.0], [0.0, -0.04, 0.01], [0.02, 0.0, 0.03]] }
    }
}

/// Physical source: the sensor-table bearing is machined and assembled to a fraction of a
/// degree; 0.1-0.5° is typical of such a fixture. Default 0.3°.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TableTilt {
    /// ε, degrees.
    pub tilt_deg: f64,
}

impl Default for TableTilt {
    fn default() -> Self {
        Self { tilt_deg: 0.3 }
    }
}

/// Physical source: a machined pose fixture (a 90° angle block) holds the package to ~0.1°, the
/// size the calibration issue gives for fixtures of such a rig; the part about the table axis
/// z2 looks to the data like an index offset of pose 2's own. Default 0.1°.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PoseFixture {
    /// Rotation of the pose-2 mount about z2, degrees.
    pub z2_deg: f64,
}

impl Default for PoseFixture {
    fn default() -> Self {
        Self { z2_deg: 0.1 }
    }
}

impl PoseFixture {
    /// The mount rotation R_q with the fixture error: Rz(δ)·R2 in pose 2, R1 in pose 1.
    pub fn rotation(&self, pose: crate::geometry::Pose) -> nalgebra::Matrix3<f64> {
        match pose {
            crate::geometry::Pose::One => pose.rotation(),
            crate::geometry::Pose::Two => {
                *nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), self.z2_deg.to_radians()).matrix()
                    * pose.rotation()
            }
        }
    }
}

/// Physical source: the offset of a MEMS gyro wanders as a rate random walk of
/// 0.001-0.005 °/s/√s (the range the realistic-physics issue gives; IEEE Std 952 calls its
/// coefficient K, the +1/2 slope of the Allan deviation). Default 0.002 °/s/√s.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BiasRandomWalk {
    /// K, °/s/√s: the offset's standard deviation grows as K·√t.
    pub k_dps_per_sqrt_s: f64,
}

impl Default for BiasRandomWalk {
    fn default() -> Self {
        Self { k_dps_per_sqrt_s: 0.002 }
    }
}

pub use crate::geometry::EARTH_RATE_RAD_S;

/// Earth's rotation as the lab feels it: vertical component Ω·sin(latitude), horizontal
/// Ω·cos(latitude) towards north, at `heading_deg` from where the base points at θ2 = 0.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EarthRotation {
    /// Latitude, degrees (default 45°, a mid-latitude lab).
    pub latitude_deg: f64,
    /// Azimuth of north from where the base points when θ2 = 0, degrees (default 30°).
    pub heading_deg: f64,
}

impl Default for EarthRotation {
    fn default() -> Self {
        Self { latitude_deg: 45.0, heading_deg: 30.0 }
    }
}

impl EarthRotation {
    /// (vertical, horizontal) rate, °/s.
    pub fn components_dps(&self) -> (f64, f64) {
        let w = EARTH_RATE_RAD_S.to_degrees();
        let lat = self.latitude_deg.to_radians();
        (w * lat.sin(), w * lat.cos())
    }

    /// The lab-fixed rate in the table frame O2 (EXCITER.md eq. 1 conventions: z1 = (sin θ2,
    /// cos θ2, 0), the base's horizontal pair e_z2 and u = z1 × z2 = (cos θ2, −sin θ2, 0)) for a
    /// base heading θ1 (from where it points at θ2 = 0) and table angle θ2, °/s.
    pub fn in_table_frame_dps(&self, theta1_rad: f64, theta2_rad: f64) -> [f64; 3] {
        let (v, h) = self.components_dps();
        let psi = self.heading_deg.to_radians() - theta1_rad;
        let (s2, c2) = theta2_rad.sin_cos();
        let (sp, cp) = psi.sin_cos();
        [v * s2 + h * sp * c2, v * c2 - h * sp * s2, h * cp]
    }
}

/// Physical source: the magnetic gears' torque ripples as poles pass (12 poles, EXCITER.md), so
/// the sensor table lags and leads the ideal 1:1 angle at 12× and 24× the base's turn against the
/// ground, plus a once-per-turn eccentricity. Default sizes: 0.03° at 12× and 0.01° at 24× (a
/// few % of a pole pitch's 30° lost to compliance, of the order magnetic-gear makers quote for
/// transmission error). A once-per-turn eccentricity is left out of the default: at 1× it
/// tilts the fitted axes as much as it ripples θ2' (the runs of two poses do not separate it).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GearTransmission {
    /// (order, amplitude in degrees, phase in rad) of each harmonic of θ1.
    pub harmonics: [(u32, f64, f64); 2],
}

impl Default for GearTransmission {
    fn default() -> Self {
        Self { harmonics: [(12, 0.03, 0.7), (24, 0.01, -1.2)] }
    }
}

impl GearTransmission {
    /// Angle error of the sensor table, rad, and its derivative with respect to θ1.
    pub fn error_rad(&self, theta1_rad: f64) -> (f64, f64) {
        self.harmonics.iter().fold((0.0, 0.0), |(e, de), &(n, a_deg, ph)| {
            let nf = f64::from(n);
            let (s, c) = (nf * theta1_rad + ph).sin_cos();
            (e + a_deg.to_radians() * s, de + a_deg.to_radians() * nf * c)
        })
    }
}

/// Output delay. Physical source: the L3G4200D's digital low-pass filter (CTRL_REG1 BW bits;
/// cut-off from datasheet Table 21) delays the output by ~√2/(2π·fc) at low frequency, i.e.
/// 2.0 ms at 110 Hz and 7.5 ms at 30 Hz; at 0.5 Hz 5 ms is a 0.9° phase shift (EXCITER.md), the
/// size of the tilts being measured.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FilterDelay {
    /// Apply a Butterworth low-pass at the Table-21 cut-off of the configured ODR/bandwidth
    /// (default: on). Its actual group delay at each run's drive frequency is reported in the
    /// truth.
    pub lowpass: bool,
    /// Additional pure delay of the output, ms (default 0): an exactly known delay for tests.
    pub pure_delay_ms: f64,
    /// The low-pass's order, 2 (default: the usual biquad) or 3 (`crate::sim::filter`).
    #[serde(default = "FilterDelay::default_order")]
    pub order: u8,
    /// A cut-off, Hz, in place of the configured bandwidth's (default none): a part whose filter
    /// is not the one its `Hello` declares, as the calibration meets it from the data alone.
    #[serde(default)]
    pub cutoff_hz: Option<f64>,
}

impl Default for FilterDelay {
    fn default() -> Self {
        Self { lowpass: true, pure_delay_ms: 0.0, order: Self::default_order(), cutoff_hz: None }
    }
}

impl FilterDelay {
    /// A pure delay of `delay_ms` without the low-pass.
    pub fn pure_ms(delay_ms: f64) -> Self {
        Self { lowpass: false, pure_delay_ms: delay_ms, ..Self::default() }
    }

    /// The order of the datasheet's usual filter.
    fn default_order() -> u8 {
        2
    }
}

/// Physical source: the shield plate is glued to the base by hand, so its centre is not exactly
/// at the θ2 the sensor pose was defined for.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct IndexOffset {
    /// True θ2 at the centre of the index pulse, degrees (default 3°, assumed: hand mounting).
    pub offset_deg: f64,
}

impl Default for IndexOffset {
    fn default() -> Self {
        Self { offset_deg: 3.0 }
    }
}

/// Physical source: self-heating after power-up warms the die; the zero-rate level follows the
/// temperature (datasheet Table 4, "zero-rate level change vs temperature", ±0.03 °/s/°C typ.,
/// i.e. 1.7 counts/°C at ±500 °/s). The Temperature messages follow the same temperature.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OffsetDrift {
    /// Temperature rise from power-up to steady state, °C (default 10, assumed: typical
    /// self-heating of a board in a closed rig).
    pub rise_c: f64,
    /// Time constant of the exponential warm-up, s (default 90, assumed: board thermal mass).
    pub tau_s: f64,
    /// Offset change per °C for each axis, °/s/°C (default [0.03, −0.02, 0.04], around the
    /// datasheet's typical ±0.03).
    pub dps_per_c: [f64; 3],
}

impl Default for OffsetDrift {
    fn default() -> Self {
        Self { rise_c: 10.0, tau_s: 90.0, dps_per_c: [0.03, -0.02, 0.04] }
    }
}

/// One harmonic of the base-table revolution.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RippleHarmonic {
    /// Harmonic number (cycles per base-table revolution), ≥ 1.
    pub order: u32,
    /// Relative speed amplitude: θ1' = θ1'_nominal·(1 + Σ amplitude·cos(order·θ1 + phase)).
    pub amplitude: f64,
    /// Phase, rad.
    pub phase_rad: f64,
}

/// Physical source: bearing and shaft eccentricity load the base once and twice per revolution
/// (1×, 2×); the 12-pole magnetic gears (EXCITER.md, "Mechanism") add a detent torque at 12× per
/// revolution. (The maxon RE 30 itself is coreless, hence free of cogging.) The encoder and index
/// follow the rippled motion, so encoder-derived rates carry the ripple.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpeedRipple {
    /// Default: 1× 0.5 %, 2× 0.25 %, 12× 0.1 % (assumed, typical of a small direct-drive table
    /// under a speed loop).
    pub harmonics: [RippleHarmonic; 3],
}

impl Default for SpeedRipple {
    fn default() -> Self {
        Self {
            harmonics: [
                RippleHarmonic { order: 1, amplitude: 0.005, phase_rad: 0.7 },
                RippleHarmonic { order: 2, amplitude: 0.0025, phase_rad: 2.1 },
                RippleHarmonic { order: 12, amplitude: 0.001, phase_rad: 0.0 },
            ],
        }
    }
}

/// Physical source: the sense element and ADC are not perfectly linear (datasheet Table 4,
/// "non-linearity", 0.2 % of full scale typ.) and the drive/sense loop gains differ slightly with
/// the sign of the Coriolis force. Applied per axis to the rate along the axis, `x` in °/s:
/// `y = x·(1 ± asymmetry/2) + quadratic_fs·x·|x|/FS + cubic_fs·x³/FS² + square_fs·x²/FS`, `+`
/// for x > 0. The datasheet gives the size of the bend, not its shape: a chain whose gain grows
/// with the rate's size bends as x·|x|, one that saturates softly as x³; IEEE Std 952's power
/// series has an even x² too.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Nonlinearity {
    /// Added output at full scale, as a fraction of full scale (default 0.002: datasheet
    /// Table 4).
    pub quadratic_fs: f64,
    /// Difference between the positive and negative scale factors, fraction (default 0.004,
    /// assumed).
    pub asymmetry: f64,
    /// Added output at full scale by an odd cubic, as a fraction of full scale (default 0;
    /// `nonlinearity_cubic` switches on 0.002 alone: datasheet Table 4's size in the other
    /// shape).
    #[serde(default)]
    pub cubic_fs: f64,
    /// Added output at full scale by an even square law, as a fraction of full scale (default
    /// 0; `nonlinearity_square` switches on 0.002 alone).
    #[serde(default)]
    pub square_fs: f64,
}

impl Default for Nonlinearity {
    fn default() -> Self {
        Self { quadratic_fs: 0.002, asymmetry: 0.004, cubic_fs: 0.0, square_fs: 0.0 }
    }
}

impl Nonlinearity {
    /// `nonlinearity_cubic`'s and `nonlinearity_square`'s default: that term alone at datasheet
    /// Table 4's 0.2 % of full scale.
    pub const SHAPE_FS: f64 = 0.002;

    /// No bend at all: what `nonlinearity_cubic` and `nonlinearity_square` add their term to.
    const NONE: Self = Self { quadratic_fs: 0.0, asymmetry: 0.0, cubic_fs: 0.0, square_fs: 0.0 };
}

/// Physical source: a magnetic gear slips by whole poles under overload, and a rig built with a
/// different gear pair than documented changes the ratio; the `Hello` still says 1/1.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GearRatioError {
    /// Actual ratio = nominal·(1 + ppm·10⁻⁶) (default +200 ppm, assumed).
    pub ppm: f64,
}

impl Default for GearRatioError {
    fn default() -> Self {
        Self { ppm: 200.0 }
    }
}

/// Physical source: a gyro whose three sense channels share one multiplexed converter samples
/// them in turn, a third of an output period apart (0.42 ms at 800 Hz); one with an ADC per
/// channel still shows the sense resonators' phase mismatch, tens of µs (engineering judgement:
/// no L3G4200D figure). Default: 0, +0.1, −0.05 ms on x, y, z.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AxisDelay {
    /// Delay of each axis's output beyond the common delay, ms.
    pub delay_ms: [f64; 3],
}

impl Default for AxisDelay {
    fn default() -> Self {
        Self { delay_ms: [0.0, 0.1, -0.05] }
    }
}

/// Physical source: the firmware's 8 MHz HSE crystal (`firmware/src/main.rs`) is specified to
/// ±30 ppm at 25 °C plus ±30 ppm over temperature (a typical HC-49 part's datasheet). Every
/// timestamp the rig sends counts its ticks, so a fast clock stretches the rig's time and
/// shrinks every rate derived from it. Default +20 ppm. It stretches what the session sends
/// (samples, index edges, status); the emulated firmware's control ticks (`SimRig`) keep the
/// nominal clock, which moves no recorded timestamp.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RigClock {
    /// Frequency error of the rig's time base, ppm (positive: its µs are short).
    pub error_ppm: f64,
}

impl Default for RigClock {
    fn default() -> Self {
        Self { error_ppm: 20.0 }
    }
}

/// Physical source: the rig stamps each sample when its data-ready interrupt runs, while the
/// gyro sampled, and the encoder was latched, at the data-ready edge itself; the interrupt's
/// latency varies with whatever else the MCU was doing (a higher-priority handler, a flash wait
/// state). Without it the stamps have [`TimestampJitter::BASELINE_US`]; this replaces it.
/// Default 5 µs (engineering judgement: a rig whose sampling shares its MCU with busier
/// handlers; the independent validation captures show 2.9 µs).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TimestampJitter {
    /// Jitter of each sample's timestamp, µs rms.
    pub rms_us: f64,
}

impl TimestampJitter {
    /// The stamps' jitter without the effect, µs rms (assumed: interrupt latency of the
    /// data-ready handler on a Cortex-M at tens of MHz).
    pub const BASELINE_US: f64 = 1.0;
}

impl Default for TimestampJitter {
    fn default() -> Self {
        Self { rms_us: 5.0 }
    }
}

/// Physical source: a capture taken on its own, as the independent validation captures hold
/// one run per file. Between two captures the gyro's zero-rate level moves (the die a fraction
/// of a degree warmer or cooler after the pause, at the L3G4200D's ±0.03 °/s/°C, datasheet
/// Table 4; the offset's walk over it), and the capture's noise is a draw of its own. The
/// level, per axis, is drawn from the seed and the capture's runs (poses, rates, lengths), so
/// the captures of one sensor taken run by run each have theirs, while the sensor is the seed's.
/// Default 0.005 °/s (1σ; engineering judgement: steps of this size stay under the
/// calibration's run-to-run test on 120-s runs, about 0.01 °/s, and are the ones only its σ can
/// carry).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CaptureLevel {
    /// One σ of the capture's level on each axis, °/s.
    pub sigma_dps: f64,
}

impl Default for CaptureLevel {
    fn default() -> Self {
        Self { sigma_dps: 0.005 }
    }
}

/// Physical source: an encoder's scale (disc or ring) mounted e off its shaft's axis reads the
/// angle with an error of (e/r)·sin(θ1 + φ) at scale radius r, the error a single read head
/// cannot see and that dual-head encoders exist to cancel. Default 0.01° (36 arcsec): 3.5 µm
/// off a 20-mm radius, a careful mount (engineering judgement; the Canon R-ISO's own accuracy,
/// a few arcsec, is the scale's alone). The reading errs, not the table: the tables turn as
/// the motor drives them.
///
/// The same struct holds the error twice a turn (`order` 2, `encoder_ellipticity`): a scale
/// ring clamped out of round, or a disc whose lines were ruled on an oval, errs as
/// (ε/2)·sin(2θ1 + φ) at an ellipticity ε of its radius, which a single head sees as well.
/// Default 0.01° as for the eccentricity (engineering judgement).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EncoderEccentricity {
    /// Amplitude of the reading's error, degrees.
    pub amplitude_deg: f64,
    /// Its phase against θ1 = 0, rad.
    pub phase_rad: f64,
    /// Its cycles per turn of θ1: 1 (eccentric) or 2 (elliptical).
    #[serde(default = "EncoderEccentricity::once")]
    pub order: u32,
}

impl Default for EncoderEccentricity {
    fn default() -> Self {
        Self { amplitude_deg: 0.01, phase_rad: 0.3, order: 1 }
    }
}

impl EncoderEccentricity {
    /// `encoder_ellipticity`'s default: 0.01° twice a turn.
    pub const ELLIPTIC: Self = Self { amplitude_deg: 0.01, phase_rad: 1.1, order: 2 };

    fn once() -> u32 {
        1
    }

    /// The reading's error at the base's true `theta1_deg`, degrees.
    pub fn error_deg(&self, theta1_deg: f64) -> f64 {
        self.amplitude_deg * (f64::from(self.order) * theta1_deg.to_radians() + self.phase_rad).sin()
    }
}

/// Out-of-catalogue structure for "unexplained residual" tests: a rate of
/// `amplitude·sin(order·θ2 + phase)` added to one axis, as a sensor-table wobble or a magnetic
/// disturbance from the gears might produce. No calibration model explains it.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MysteryHarmonic {
    /// Axis it appears on, 0..3 (default 0 = x).
    pub axis: usize,
    /// Harmonic of θ2 (default 3).
    pub order: u32,
    /// Amplitude, °/s (default 0.3).
    pub amplitude_dps: f64,
    /// Phase, rad (default 0.4).
    pub phase_rad: f64,
}

impl Default for MysteryHarmonic {
    fn default() -> Self {
        Self { axis: 0, order: 3, amplitude_dps: 0.3, phase_rad: 0.4 }
    }
}

/// Structure outside every model that changes with speed: the sensor package, held by a
/// compliant mount (a PCB on standoffs, an adhesive pad), turns on it under the load of the
/// tables' rotation, by an angle in proportion to |ω2|² (a centripetal load on a linear spring)
/// about an axis fixed in the table. At rest its axes are the truth's; at speed every direction
/// the rig sees is turned, and on this rig |ω2| is the same at every instant of a run, so at one
/// speed it is M. Default: 0.03° at 180 °/s on both tables, about the table's x axis (the size
/// of issue 24's uncatalogued effects, 0.015-0.07°).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MountCompliance {
    /// The turn at θ1' = θ2' = 180 °/s, degrees.
    pub deg_at_180: f64,
    /// The axis it turns about, in the table frame O2 (normalised when used).
    pub axis_table: [f64; 3],
}

impl Default for MountCompliance {
    fn default() -> Self {
        Self { deg_at_180: 0.03, axis_table: [1.0, 0.0, 0.0] }
    }
}

impl MountCompliance {
    /// |ω2|² at θ1' = θ2' = 180 °/s, (°/s)².
    const REFERENCE_LOAD_DPS2: f64 = 2.0 * 180.0 * 180.0;

    /// The package's turn on its mount (table frame) at table rate `omega2_dps`.
    pub fn turn(&self, omega2_dps: &nalgebra::Vector3<f64>) -> nalgebra::Matrix3<f64> {
        let angle_rad = self.deg_at_180.to_radians() * omega2_dps.norm_squared() / Self::REFERENCE_LOAD_DPS2;
        let axis = nalgebra::Unit::new_normalize(nalgebra::Vector3::from(self.axis_table));
        *nalgebra::Rotation3::from_axis_angle(&axis, angle_rad).matrix()
    }
}

/// An effect name or value that `Effects::enable` does not understand.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EffectSpecError(pub String);

impl std::fmt::Display for EffectSpecError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for EffectSpecError {}

impl Effects {
    /// Every physical effect of the realistic rig (issue 10), each at its default size: what
    /// the all-effects bench, the trust matrix's `all` and the golden session switch on. The
    /// other switches (`delay_ms`, `nonlinearity`, `gear_ratio_error`, `mystery_harmonic`,
    /// `mount_compliance`, `temperature_dependence`) stay off.
    pub const REALISTIC: [&'static str; 10] = [
        "filter_delay",
        "index_offset_deg",
        "offset_drift",
        "speed_ripple",
        "earth_rotation",
        "gear_transmission",
        "g_sensitivity",
        "table_tilt",
        "pose_fixture",
        "bias_random_walk",
    ];

    /// Names accepted by [`Effects::enable`], with the meaning of the optional `=value`.
    pub const NAMES: [(&'static str, &'static str); 25] = [
        ("filter_delay", "gyro low-pass at the Table-21 cut-off (no value)"),
        ("filter_order", "gyro low-pass of this Butterworth order, 2 or 3 (default 3)"),
        ("filter_cutoff_hz", "gyro low-pass at this cut-off, not the configured one, Hz (default 35)"),
        ("delay_ms", "pure output delay, ms (default 5)"),
        ("index_offset_deg", "θ2 at the index centre, degrees (default 3)"),
        ("offset_drift", "warm-up temperature rise, °C (default 10)"),
        ("speed_ripple", "1× speed ripple, fraction (default 0.005)"),
        ("nonlinearity", "quadratic term at full scale, fraction (default 0.002)"),
        ("nonlinearity_cubic", "cubic term alone at full scale, fraction (default 0.002)"),
        ("nonlinearity_square", "even square term alone at full scale, fraction (default 0.002)"),
        ("gear_ratio_error", "gear ratio error, ppm (default 200)"),
        ("mystery_harmonic", "3×θ2 harmonic on x, °/s (default 0.3)"),
        ("mount_compliance", "package turned on its mount ∝ |ω2|², degrees at 180 °/s (default 0.03)"),
        ("earth_rotation", "Earth's rotation at this latitude, degrees (default 45)"),
        ("gear_transmission", "magnetic-gear error at 12×, degrees (default 0.03; 24× scales with it)"),
        ("g_sensitivity", "bias from gravity, largest coefficient in °/s/g (default 0.05)"),
        ("table_tilt", "sensor-table axis off perpendicular, degrees (default 0.3)"),
        ("pose_fixture", "pose-2 fixture turned about the table axis, degrees (default 0.1)"),
        ("bias_random_walk", "rate random walk of the offset, °/s/√s (default 0.002)"),
        ("axis_delay", "per-axis delay beyond the common one, y's in ms (default 0.1; x 0, z −y/2)"),
        ("rig_clock", "rig time base's frequency error, ppm (default 20)"),
        ("encoder_eccentricity", "base encoder's reading error once a turn, degrees (default 0.01)"),
        ("encoder_ellipticity", "base encoder's reading error twice a turn, degrees (default 0.01)"),
        ("timestamp_jitter", "jitter of the samples' timestamps, µs rms (default 5; without it 1)"),
        ("capture_level", "this capture's own zero-rate level and noise draw, 1σ °/s per axis (default 0.005)"),
    ];

    /// True when no effect is on.
    pub fn is_none(&self) -> bool {
        *self == Self::default()
    }

    /// Switches on one effect from `name` or `name=value` (see [`Effects::NAMES`]); the value
    /// sets the effect's headline parameter, the others keep their defaults.
    pub fn enable(&mut self, spec: &str) -> Result<(), EffectSpecError> {
        let (name, value) = match spec.split_once('=') {
            Some((n, v)) => {
                let v: f64 =
                    v.trim().parse().map_err(|_| EffectSpecError(format!("effect {spec:?}: value is not a number")))?;
                if !v.is_finite() {
                    return Err(EffectSpecError(format!("effect {spec:?}: value is not finite")));
                }
                (n.trim(), Some(v))
            }
            None => (spec.trim(), None),
        };
        match name {
            "filter_delay" => {
                if value.is_some() {
                    return Err(EffectSpecError("filter_delay takes no value (use delay_ms=…)".into()));
                }
                self.filter_delay.get_or_insert_with(|| FilterDelay::pure_ms(0.0)).lowpass = true;
            }
            "filter_order" => {
                let order = value.unwrap_or(3.0);
                if !super::filter::ORDERS.iter().any(|&o| f64::from(o) == order) {
                    return Err(EffectSpecError(format!(
                        "effect {spec:?}: the low-pass's order is one of {:?}",
                        super::filter::ORDERS
                    )));
                }
                let f = self.filter_delay.get_or_insert_with(|| FilterDelay::pure_ms(0.0));
                (f.lowpass, f.order) = (true, order as u8);
            }
            "filter_cutoff_hz" => {
                let hz = value.unwrap_or(35.0);
                if hz <= 0.0 {
                    return Err(EffectSpecError(format!("effect {spec:?}: a cut-off is above 0 Hz")));
                }
                let f = self.filter_delay.get_or_insert_with(|| FilterDelay::pure_ms(0.0));
                (f.lowpass, f.cutoff_hz) = (true, Some(hz));
            }
            "delay_ms" => {
                let ms = value.unwrap_or(5.0);
                if ms < 0.0 {
                    return Err(EffectSpecError("delay_ms must be ≥ 0".into()));
                }
                self.filter_delay.get_or_insert_with(|| FilterDelay::pure_ms(0.0)).pure_delay_ms = ms;
            }
            "index_offset_deg" => {
                self.index_offset = Some(IndexOffset { offset_deg: value.unwrap_or(IndexOffset::default().offset_deg) })
            }
            "offset_drift" => {
                let mut d = OffsetDrift::default();
                if let Some(v) = value {
                    d.rise_c = v;
                }
                self.offset_drift = Some(d);
            }
            "speed_ripple" => {
                let mut r = SpeedRipple::default();
                if let Some(v) = value {
                    r.harmonics[0].amplitude = v;
                }
                self.speed_ripple = Some(r);
            }
            "nonlinearity" => {
                let mut n = Nonlinearity::default();
                if let Some(v) = value {
                    n.quadratic_fs = v;
                }
                self.nonlinearity = Some(n);
            }
            "nonlinearity_cubic" => {
                let mut n = self.nonlinearity.unwrap_or(Nonlinearity::NONE);
                n.cubic_fs = value.unwrap_or(Nonlinearity::SHAPE_FS);
                self.nonlinearity = Some(n);
            }
            "nonlinearity_square" => {
                let mut n = self.nonlinearity.unwrap_or(Nonlinearity::NONE);
                n.square_fs = value.unwrap_or(Nonlinearity::SHAPE_FS);
                self.nonlinearity = Some(n);
            }
            "gear_ratio_error" => {
                self.gear_ratio_error = Some(GearRatioError { ppm: value.unwrap_or(GearRatioError::default().ppm) })
            }
            "mystery_harmonic" => {
                let mut m = MysteryHarmonic::default();
                if let Some(v) = value {
                    m.amplitude_dps = v;
                }
                self.mystery_harmonic = Some(m);
            }
            "mount_compliance" => {
                let mut m = MountCompliance::default();
                if let Some(v) = value {
                    m.deg_at_180 = v;
                }
                self.mount_compliance = Some(m);
            }
            "earth_rotation" => {
                let mut e = EarthRotation::default();
                if let Some(v) = value {
                    if !(-90.0..=90.0).contains(&v) {
                        return Err(EffectSpecError("earth_rotation latitude must be within ±90°".into()));
                    }
                    e.latitude_deg = v;
                }
                self.earth_rotation = Some(e);
            }
            "g_sensitivity" => {
                let mut g = GSensitivity::default();
                if let Some(v) = value {
                    let scale = v / 0.05;
                    g.dps_per_g = g.dps_per_g.map(|row| row.map(|x| x * scale));
                }
                self.g_sensitivity = Some(g);
            }
            "bias_random_walk" => {
                let k = value.unwrap_or(BiasRandomWalk::default().k_dps_per_sqrt_s);
                if k < 0.0 {
                    return Err(EffectSpecError(format!("bias_random_walk must be ≥ 0 °/s/√s, not {k}")));
                }
                self.bias_random_walk = Some(BiasRandomWalk { k_dps_per_sqrt_s: k })
            }
            "pose_fixture" => {
                self.pose_fixture = Some(PoseFixture { z2_deg: value.unwrap_or(PoseFixture::default().z2_deg) })
            }
            "table_tilt" => {
                self.table_tilt = Some(TableTilt { tilt_deg: value.unwrap_or(TableTilt::default().tilt_deg) })
            }
            "gear_transmission" => {
                let mut g = GearTransmission::default();
                if let Some(v) = value {
                    let scale = v / g.harmonics[0].1;
                    for h in &mut g.harmonics {
                        h.1 *= scale;
                    }
                }
                self.gear_transmission = Some(g);
            }
            "axis_delay" => {
                let y_ms = value.unwrap_or(AxisDelay::default().delay_ms[1]);
                self.axis_delay = Some(AxisDelay { delay_ms: [0.0, y_ms, -0.5 * y_ms] })
            }
            "rig_clock" => {
                self.rig_clock = Some(RigClock { error_ppm: value.unwrap_or(RigClock::default().error_ppm) })
            }
            "encoder_eccentricity" => {
                let mut e = EncoderEccentricity::default();
                e.amplitude_deg = value.unwrap_or(e.amplitude_deg);
                self.encoder_eccentricity = Some(e);
            }
            "encoder_ellipticity" => {
                let mut e = EncoderEccentricity::ELLIPTIC;
                e.amplitude_deg = value.unwrap_or(e.amplitude_deg);
                self.encoder_ellipticity = Some(e);
            }
            "timestamp_jitter" => {
                let rms_us = value.unwrap_or(TimestampJitter::default().rms_us);
                if rms_us < 0.0 {
                    return Err(EffectSpecError(format!("effect {spec:?}: a jitter is at least 0 µs")));
                }
                self.timestamp_jitter = Some(TimestampJitter { rms_us });
            }
            "capture_level" => {
                let sigma_dps = value.unwrap_or(CaptureLevel::default().sigma_dps);
                if sigma_dps < 0.0 {
                    return Err(EffectSpecError(format!("effect {spec:?}: a level's σ is at least 0 °/s")));
                }
                self.capture_level = Some(CaptureLevel { sigma_dps });
            }
            _ => {
                let known: Vec<&str> = Self::NAMES.iter().map(|(n, _)| *n).collect();
                return Err(EffectSpecError(format!("unknown effect {name:?}; known: {}", known.join(", "))));
            }
        }
        Ok(())
    }

    /// Actual gear ratio for a nominal one.
    pub fn true_gear_ratio(&self, nominal: f64) -> f64 {
        nominal * (1.0 + self.gear_ratio_error.map_or(0.0, |g| g.ppm * 1e-6))
    }

    /// θ2 at the index centre, rad.
    pub fn index_offset_rad(&self) -> f64 {
        self.index_offset.map_or(0.0, |o| o.offset_deg.to_radians())
    }

    /// Pure output delay, s.
    pub fn pure_delay_s(&self) -> f64 {
        self.filter_delay.map_or(0.0, |f| f.pure_delay_ms * 1e-3)
    }

    /// Each axis's delay beyond the common one, s.
    pub fn axis_delay_s(&self) -> [f64; 3] {
        self.axis_delay.map_or([0.0; 3], |d| d.delay_ms.map(|ms| ms * 1e-3))
    }

    /// The samples' timestamp jitter, µs rms.
    pub fn timestamp_jitter_us(&self) -> f64 {
        self.timestamp_jitter.map_or(TimestampJitter::BASELINE_US, |j| j.rms_us)
    }

    /// The rig's timer ticks per true µs (1 + its frequency error).
    pub fn rig_clock_rate(&self) -> f64 {
        1.0 + self.rig_clock.map_or(0.0, |c| c.error_ppm * 1e-6)
    }

    /// The low-pass filter, when on: its order and cut-off (`configured_hz` unless the effect
    /// sets its own).
    pub fn lowpass(&self, configured_hz: f64) -> Option<(u8, f64)> {
        let f = self.filter_delay.filter(|f| f.lowpass)?;
        Some((f.order, f.cutoff_hz.unwrap_or(configured_hz)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enable_parses_names_and_values() {
        let mut e = Effects::default();
        assert!(e.is_none());
        e.enable("delay_ms=5").unwrap();
        assert_eq!(e.filter_delay, Some(FilterDelay::pure_ms(5.0)));
        e.enable("filter_delay").unwrap();
        assert_eq!(e.filter_delay, Some(FilterDelay { lowpass: true, pure_delay_ms: 5.0, ..FilterDelay::default() }));
        e.enable("filter_order").unwrap();
        e.enable("filter_cutoff_hz=40").unwrap();
        assert_eq!(e.lowpass(50.0), Some((3, 40.0)));
        assert_eq!(Effects::default().lowpass(50.0), None);
        e.enable("gear_ratio_error=-50").unwrap();
        assert_eq!(e.true_gear_ratio(1.0), 1.0 - 50e-6);
        e.enable("index_offset_deg").unwrap();
        assert!((e.index_offset_rad() - 3f64.to_radians()).abs() < 1e-15);
        for (name, _) in Effects::NAMES {
            e.enable(name).unwrap();
        }
        assert!(e.enable("warp_drive").is_err());
        assert!(e.enable("delay_ms=abc").is_err());
        assert!(e.enable("delay_ms=-1").is_err());
        assert!(e.enable("filter_delay=3").is_err());
        assert_eq!(
            e.enable("filter_order=4").unwrap_err().to_string(),
            "effect \"filter_order=4\": the low-pass's order is one of [2, 3]"
        );
        assert!(e.enable("filter_cutoff_hz=0").is_err());
    }

    #[test]
    fn effects_round_trip_through_json() {
        let mut e = Effects::default();
        for (name, _) in Effects::NAMES {
            e.enable(name).unwrap();
        }
        let json = serde_json::to_string(&e).unwrap();
        let back: Effects = serde_json::from_str(&json).unwrap();
        assert_eq!(back, e);
        let none: Effects = serde_json::from_str("{}").unwrap();
        assert!(none.is_none());
    }
}
