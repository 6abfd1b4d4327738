//! The simulated rig: a physics model of the two-table exciter and its L3G4200D that emits
//! exactly the bytes the firmware sends, plus the truth to check a calibration against.
//!
//! Users run it to learn the tool and to plan a rig; the tests run it to check the calibration
//! end to end. A capture is: `Hello`, then per run `RunStarted`, the motor's spin-up ramp and
//! constant speed with `Sample` frames at the gyro's (slightly wrong) ODR, `Index` edges,
//! `Temperature` (1 Hz), `MotorStatus` (10 Hz), `Counters` (1 Hz), and `RunStopped`.
//!
//! Conventions (see `motion`): simulated time is the rig's µs timer; θ1 = 0 at power-up; θ2 = 0
//! at the centre of the index plate (the midpoint of its rising and falling edges) unless the
//! `index_offset` effect moves the plate. Spin-up samples are emitted, as the real rig streams
//! them: the host must take rates from the encoder, not assume constant speed.
//!
//! Everything is deterministic for a seed, with independent random streams for the sensor, the
//! rig, the noise and the timestamp jitter: one seed is one sensor whatever the runs.

mod drawn;
pub use drawn::MAX_DRAWN_SCALE;
pub mod effects;
mod filter;
mod motion;
mod rig;
mod sensor;
mod session;
mod stream;
pub mod thermal;
mod truth;

#[cfg(test)]
mod tests;

pub use effects::{
    AxisDelay, EarthRotation, EffectSpecError, Effects, FilterDelay, GSensitivity, GearRatioError, GearTransmission,
    IndexOffset, MysteryHarmonic, Nonlinearity, OffsetDrift, PoseFixture, RigClock, RippleHarmonic, SpeedRipple,
    TableTilt,
};
pub use rig::{serve, Port, SimRig};
pub use sensor::NOISE_DENSITY_DPS_PER_SQRT_HZ;
pub use session::{effects_rng, FIRMWARE_VERSION};
pub use stream::FrameWriter;
pub use truth::{RunTruth, Truth};

use crate::geometry::Pose;
use protocol::GyroConfig;
use serde::{Deserialize, Serialize};
use session::Session;
use std::io::{self, Write};

/// One run: the operator mounts `pose`, the rig spins at `rate_dps` for `duration_s`.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    /// Sensor pose.
    pub pose: Pose,
    /// Base-table rate θ1', °/s; the sign is the direction (positive = counter-clockwise).
    pub rate_dps: f64,
    /// From `RunStarted` to `RunStopped`, s, spin-up included.
    pub duration_s: f64,
}

/// A simulated session: one power-up, one sensor, several runs.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// Seed of every random draw.
    pub seed: u64,
    /// Runs in order (ignored by [`SimRig`], where the host commands the runs).
    pub runs: Vec<RunSpec>,
    /// Gyro settings.
    pub gyro: GyroConfig,
    /// White rate noise density, °/s/√Hz (datasheet: 0.03).
    pub noise_dps_per_sqrt_hz: f64,
    /// Departures from the ideal model (all off by default).
    pub effects: Effects,
    /// Duration of the motor's linear speed ramp, on start and on stop, s.
    pub spin_up_s: f64,
    /// Idle time before each run (operator remounting the sensor; the motor ramps down), s.
    pub gap_s: f64,
    /// Timer value at power-up, µs (wraps after 2³² µs; set near `u32::MAX` to test wrapping).
    pub start_t_us: u32,
    /// Encoder register at power-up.
    pub start_encoder: u32,
    /// Angular width of the index shield plate, degrees (assumed: "a few degrees").
    pub index_plate_width_deg: f64,
    /// The chamber step before this session (`host simulate --chamber-c`): the die's
    /// temperature follows it; absent, the die starts at the lab's 25 °C.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chamber: Option<thermal::ChamberStep>,
}

/// Default ramp time, s (assumed: a gentle ramp that keeps the magnetic gears from slipping).
pub const DEFAULT_SPIN_UP_S: f64 = 1.5;
/// Default idle time before a run, s (assumed; longer than the ramp so the table is at rest).
pub const DEFAULT_GAP_S: f64 = 2.0;
/// Default shield-plate width, degrees (assumed: EXCITER.md says only that a plate is seen once
/// per revolution).
pub const DEFAULT_INDEX_PLATE_WIDTH_DEG: f64 = 4.0;
/// Rate of [`SimConfig::standard`]: 0.5 Hz, the paper's first run (EXCITER.md).
pub const STANDARD_RATE_DPS: f64 = 180.0;

/// The longest simulated run, s. Engineering judgement: 6 h is enough for an Allan deviation to
/// τ ≈ 2 000 s with ten clusters (bias instability of a MEMS gyro lies at τ of 10-1 000 s), and
/// writes ≈ 400 MB (the stream's ≈ 18.5 kB/s, protocol/README.md "Link budget"); beyond it a typo
/// (`--duration 1e12`) would fill the disk.
pub const MAX_RUN_S: f64 = 21_600.0;

impl SimConfig {
    /// Pose 1 then pose 2, each at +180 °/s (0.5 Hz) for `duration_s`, datasheet noise, default
    /// gyro settings, no effects.
    pub fn standard(seed: u64, duration_s: f64) -> Self {
        Self::with_runs(
            seed,
            Pose::ALL.iter().map(|&pose| RunSpec { pose, rate_dps: STANDARD_RATE_DPS, duration_s }).collect(),
        )
    }

    /// Default settings with the given runs.
    pub fn with_runs(seed: u64, runs: Vec<RunSpec>) -> Self {
        Self {
            seed,
            runs,
            gyro: GyroConfig::DEFAULT,
            noise_dps_per_sqrt_hz: NOISE_DENSITY_DPS_PER_SQRT_HZ,
            effects: Effects::default(),
            spin_up_s: DEFAULT_SPIN_UP_S,
            gap_s: DEFAULT_GAP_S,
            start_t_us: 0,
            start_encoder: 0,
            index_plate_width_deg: DEFAULT_INDEX_PLATE_WIDTH_DEG,
            chamber: None,
        }
    }

    /// Checks that every number is usable; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let check = |ok: bool, field: &str, requirement: &str| {
            if ok {
                Ok(())
            } else {
                Err(ConfigError { field: field.to_string(), requirement: requirement.to_string() })
            }
        };
        check(
            self.noise_dps_per_sqrt_hz.is_finite() && self.noise_dps_per_sqrt_hz >= 0.0,
            "noise_dps_per_sqrt_hz",
            "must be finite and ≥ 0",
        )?;
        check(self.spin_up_s.is_finite() && self.spin_up_s >= 0.0, "spin_up_s", "must be finite and ≥ 0")?;
        check(self.gap_s.is_finite() && self.gap_s >= 0.0, "gap_s", "must be finite and ≥ 0")?;
        check(
            self.index_plate_width_deg > 0.0 && self.index_plate_width_deg < 180.0,
            "index_plate_width_deg",
            "must be in (0, 180)",
        )?;
        for (i, r) in self.runs.iter().enumerate() {
            // The simulator must not promise what the firmware refuses: each run is the Start the
            // host would send for it, judged by the firmware's own validation.
            let max_dps = protocol::units::dps_from_mdps(protocol::MAX_RATE_MDPS);
            check(
                r.rate_dps.is_finite() && firmware::commands::setpoint_cps(&start_for(r)).is_ok(),
                &format!("runs[{i}].rate_dps"),
                &format!("must be within ±{max_dps} °/s, the rig's limit (0: a static run, for noise figures)"),
            )?;
            check(
                r.duration_s.is_finite() && r.duration_s > 0.0 && r.duration_s <= MAX_RUN_S,
                &format!("runs[{i}].duration_s"),
                &format!("must be > 0 and at most {MAX_RUN_S} s (6 h: ≈ 400 MB of capture per run)"),
            )?;
        }
        let e = &self.effects;
        if let Some(f) = e.filter_delay {
            check(f.pure_delay_ms.is_finite() && f.pure_delay_ms >= 0.0, "filter_delay.pure_delay_ms", "must be ≥ 0")?;
        }
        if let Some(d) = e.offset_drift {
            check(
                d.tau_s.is_finite() && d.tau_s > 0.0 && d.rise_c.is_finite(),
                "offset_drift",
                "needs tau_s > 0 and a finite rise_c",
            )?;
        }
        if let Some(c) = self.chamber {
            check(
                c.is_valid(),
                "chamber",
                "needs finite temperatures, ramp_c_per_min > 0, die_tau_s > 0, capture_after_s ≥ 0",
            )?;
        }
        if let Some(d) = e.temperature_dependence {
            check(d.is_finite(), "temperature_dependence", "needs finite coefficients")?;
        }
        if let Some(m) = e.mystery_harmonic {
            check(m.axis < 3, "mystery_harmonic.axis", "must be 0, 1 or 2")?;
        }
        if let Some(r) = e.speed_ripple {
            check(
                r.harmonics.iter().map(|h| h.amplitude.abs()).sum::<f64>() < 0.5,
                "speed_ripple",
                "amplitudes must sum below 0.5",
            )?;
        }
        Ok(())
    }

    /// Gyro samples the runs will produce, approximately (for progress bars and buffer sizes).
    pub fn expected_samples(&self) -> u64 {
        let s: f64 = self.runs.iter().map(|r| r.duration_s).sum();
        (s * f64::from(self.gyro.odr.hz())).round() as u64
    }
}

/// The `Start` command that asks the rig for `run` (the host's session sends the same).
fn start_for(run: &RunSpec) -> protocol::StartRun {
    protocol::StartRun {
        rate_mdps: protocol::units::mdps_from_dps(run.rate_dps),
        direction: protocol::units::direction_of(run.rate_dps),
        run_tag: run.pose.run_tag(),
    }
}

/// A simulation setting that cannot be simulated: which field, and what it must be.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field} {requirement}")]
pub struct ConfigError {
    /// The field, as in the JSON (`runs[1].duration_s`).
    pub field: String,
    /// What it must be.
    pub requirement: String,
}

/// A simulated capture held in memory.
#[derive(Debug, Clone)]
pub struct SimOutput {
    /// The bytes the rig would have sent.
    pub bytes: Vec<u8>,
    /// What was simulated.
    pub truth: Truth,
}

/// Bytes of one `Sample` frame, roughly (for buffer sizing).
const SAMPLE_FRAME_BYTES: u64 = 30;

/// Simulates a whole session into memory; an unusable configuration is refused, naming the
/// field.
pub fn simulate(cfg: &SimConfig) -> Result<SimOutput, ConfigError> {
    cfg.validate()?;
    let mut bytes = Vec::with_capacity((cfg.expected_samples() * SAMPLE_FRAME_BYTES) as usize + 4096);
    let truth = simulate_to(cfg, &mut bytes).expect("a valid config, written to a Vec");
    Ok(SimOutput { bytes, truth })
}

/// Simulates a whole session, streaming the bytes to `out` (buffered internally), so that long
/// captures need not be held in memory. An invalid configuration is an `InvalidInput` error.
pub fn simulate_to(cfg: &SimConfig, out: &mut impl Write) -> io::Result<Truth> {
    cfg.validate().map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e))?;
    let mut w = FrameWriter::new(io::BufWriter::with_capacity(1 << 16, out));
    let mut session = Session::new(cfg);
    w.send(&protocol::RigMsg::Hello(session.hello()))?;
    let mut t_s = 0.0;
    for run in &cfg.runs {
        t_s += cfg.gap_s;
        session.start_run(t_s, run.pose, run.pose.run_tag(), run.rate_dps, &mut w)?;
        t_s += run.duration_s;
        session.stop_run(t_s, None, &mut w)?;
    }
    w.into_inner().flush()?;
    Ok(session.truth())
}
