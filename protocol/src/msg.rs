//! Message types. Field order is wire order: never reorder, only append new enum variants.

use crate::gyro::GyroConfig;
use serde::{Deserialize, Serialize};

/// Firmware version, semantic.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Version {
    /// Major.
    pub major: u8,
    /// Minor.
    pub minor: u8,
    /// Patch.
    pub patch: u8,
}

/// Turns of the sensor table (θ2) per turn of the base table (θ1), as a fraction.
/// The prototype's magnetic gears are 1:1 (EXCITER.md, "Mechanism").
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GearRatio {
    /// Numerator.
    pub num: u16,
    /// Denominator.
    pub den: u16,
}

/// Rotation direction of the base table, seen from above (+z1 up).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Counter-clockwise: positive θ1' and, through the gears, positive θ2'.
    Ccw,
    /// Clockwise: negative rates.
    Cw,
}

impl Direction {
    /// +1 for counter-clockwise, −1 for clockwise.
    pub const fn sign(self) -> i32 {
        match self {
            Direction::Ccw => 1,
            Direction::Cw => -1,
        }
    }
}

/// Sent on power-up, on [`Command::Identify`] and after every configuration change: everything
/// needed to interpret the rest of the stream.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hello {
    /// [`crate::PROTOCOL_VERSION`] of the sender.
    pub protocol_version: u16,
    /// Firmware version.
    pub firmware: Version,
    /// Gyro settings in force.
    pub gyro: GyroConfig,
    /// Base-table encoder counts per revolution after quadrature decoding.
    pub encoder_counts_per_rev: u32,
    /// Sensor-table turns per base-table turn.
    pub gear_ratio: GearRatio,
    /// Tick rate of every `t_us` field, in Hz.
    pub timestamp_hz: u32,
}

/// Bits of [`Sample::status`].
pub mod sample_status {
    /// The gyro reported a data overrun (STATUS_REG ZYXOR): at least one sample was overwritten
    /// inside the gyro before it was read.
    pub const OVERRUN: u8 = 0x01;
    /// Data-ready was seen but STATUS_REG ZYXDA was clear: the data read may be stale.
    pub const STALE: u8 = 0x02;
}

/// One gyro sample, read on its data-ready edge.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    /// Data-ready timestamp, µs, wrapping.
    pub t_us: u32,
    /// Base-table encoder count latched at that same instant, wrapping modulo 2^32.
    pub encoder: u32,
    /// Raw OUT_X, OUT_Y, OUT_Z, two's complement counts.
    pub rate_counts: [i16; 3],
    /// [`sample_status`] bits.
    pub status: u8,
}

/// Edge of the photo-interrupter signal (1 while the shield plate blocks it).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Edge {
    /// 0 → 1: the plate starts to block.
    Rising,
    /// 1 → 0: the plate clears.
    Falling,
}

/// One edge of the sensor-table index, captured by timer hardware.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct IndexEdge {
    /// Timestamp of the edge, µs, wrapping.
    pub t_us: u32,
    /// Base-table encoder count at the edge, wrapping.
    pub encoder: u32,
    /// Which edge.
    pub edge: Edge,
}

/// Gyro die temperature, at least once a second.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct Temperature {
    /// Timestamp of the read, µs, wrapping.
    pub t_us: u32,
    /// OUT_TEMP register: −1 LSB/°C with an unspecified offset (datasheet Table 5).
    pub raw: i8,
}

/// Bits of [`MotorStatus::faults`].
pub mod motor_faults {
    /// Driven, but the encoder did not move.
    pub const STALL: u8 = 0x01;
    /// Measured speed beyond the over-speed limit.
    pub const OVER_SPEED: u8 = 0x02;
    /// No frame from the host for too long.
    pub const HOST_LINK_LOST: u8 = 0x04;
    /// Driver enable dropped by a fault elsewhere (gyro, watchdog).
    pub const INTERLOCK: u8 = 0x08;
}

/// Speed loop state, at 10 Hz while running.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct MotorStatus {
    /// Timestamp, µs, wrapping.
    pub t_us: u32,
    /// Measured base-table speed, encoder counts per second (signed).
    pub speed_cps: i32,
    /// Setpoint after the ramp, counts per second (signed).
    pub setpoint_cps: i32,
    /// PWM duty, per mille, signed by direction.
    pub duty_permille: i16,
    /// [`motor_faults`] bits.
    pub faults: u8,
    /// Tag of the run in progress, 0 when idle: lets a reader that lost the [`RunStarted`] frame
    /// still attribute the samples that follow.
    pub run_tag: u8,
}

/// Health counters since power-up, at 1 Hz.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Timestamp, µs, wrapping.
    pub t_us: u32,
    /// Frames handed to the link.
    pub frames_sent: u32,
    /// Frames dropped because the transmit queue was full (each lost sample is counted here).
    pub queue_drops: u32,
    /// Samples read from the gyro.
    pub samples_read: u32,
    /// Samples the gyro flagged as overrun.
    pub gyro_overruns: u32,
    /// SPI transactions that failed.
    pub spi_errors: u32,
    /// Frames from the host that failed to decode.
    pub rx_errors: u32,
}

/// Result of a host command.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CmdResult {
    /// Done.
    Ok,
    /// A parameter is out of range.
    InvalidArgument,
    /// Not allowed while a run is in progress (stop first).
    Busy,
    /// The rig is in a fault state; the fault was reported separately.
    Faulted,
}

/// Acknowledges one host command.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ack {
    /// Sequence number of the host frame being answered.
    pub cmd_seq: u16,
    /// Outcome.
    pub result: CmdResult,
}

/// Marks the start of a run in the stream, so that every capture says which run (and pose) its
/// samples belong to.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunStarted {
    /// Timestamp, µs, wrapping.
    pub t_us: u32,
    /// Host-chosen tag, echoed verbatim; the host puts the sensor pose in it.
    pub run_tag: u8,
    /// Commanded base-table speed, milli-degrees per second (unsigned); 0: a static run.
    pub rate_mdps: u32,
    /// Commanded direction.
    pub direction: Direction,
    /// Gyro settings in force for the run.
    pub gyro: GyroConfig,
}

/// Why the rig stopped a run or refused to start.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// WHO_AM_I did not read 0xD3.
    GyroAbsent {
        /// What it read instead.
        who_am_i: u8,
    },
    /// SPI transfers to the gyro keep failing.
    GyroSpi,
    /// Data-ready stopped arriving while running.
    GyroSilent,
    /// The encoder did not move while the motor was driven.
    Stall,
    /// Speed beyond the limit.
    OverSpeed,
    /// No frame from the host for too long.
    HostLinkLost,
    /// The previous reset came from the independent watchdog.
    WatchdogReset,
}

/// A fault, reported once when it happens; the motor is off.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct FaultReport {
    /// Timestamp, µs, wrapping.
    pub t_us: u32,
    /// What went wrong.
    pub fault: Fault,
}

/// Marks the end of a run (by command or by fault).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunStopped {
    /// Timestamp, µs, wrapping.
    pub t_us: u32,
    /// Tag of the run that ended.
    pub run_tag: u8,
}

/// Everything the rig sends. Variant order is wire order (postcard varint discriminant).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum RigMsg {
    /// 0: identity and configuration.
    Hello(Hello),
    /// 1: one gyro sample.
    Sample(Sample),
    /// 2: an index edge.
    Index(IndexEdge),
    /// 3: gyro temperature.
    Temperature(Temperature),
    /// 4: speed loop state.
    Motor(MotorStatus),
    /// 5: health counters.
    Counters(Counters),
    /// 6: command acknowledgement.
    Ack(Ack),
    /// 7: a run began.
    RunStarted(RunStarted),
    /// 8: a run ended.
    RunStopped(RunStopped),
    /// 9: a fault.
    Fault(FaultReport),
}

/// Start a run: ramp the base table to a speed in a direction, or, with `rate_mdps` 0, a static
/// run: the motor stays off (bridge disabled) and the run only frames the samples, for noise
/// figures (protocol/README.md, "Runs").
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct StartRun {
    /// Base-table speed, milli-degrees per second (180 000 = 0.5 Hz); 0: a static run.
    pub rate_mdps: u32,
    /// Direction (echoed, and without effect, in a static run).
    pub direction: Direction,
    /// Echoed in [`RunStarted::run_tag`].
    pub run_tag: u8,
}

impl StartRun {
    /// A static run (motor off) tagged `run_tag`.
    pub const fn static_run(run_tag: u8) -> Self {
        Self { rate_mdps: 0, direction: Direction::Ccw, run_tag }
    }

    /// Whether this asks for a static run.
    pub const fn is_static(&self) -> bool {
        self.rate_mdps == 0
    }
}

/// The drive train the speed loop is designed for: what differs between rigs built to the same
/// design (the gearhead, the tables' inertia, the bridge supply); the motor is the RE 30. The rig
/// recomputes its gains from it (firmware `speed_loop::Drive`). Integers in named units, so the
/// wire stays exact; the limits are [`drive_limits`].
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct DriveConfig {
    /// Gearhead reduction, motor turns per base-table turn, × 1000 (66 000 = 66:1).
    pub gear_ratio_milli: u32,
    /// Inertia of everything the gearhead turns (tables, magnetic gears, counterweight, gyro),
    /// about the base-table axis, g·cm² (120 000 = 0.012 kg·m²); the rotor's own is added by
    /// the rig.
    pub load_inertia_gcm2: u32,
    /// Bridge supply, mV.
    pub supply_mv: u32,
}

impl DriveConfig {
    /// The prototype: GP 32 C 66:1, 0.012 kg·m² of load, 24 V (firmware README, "Measured").
    pub const PROTOTYPE: DriveConfig =
        DriveConfig { gear_ratio_milli: 66_000, load_inertia_gcm2: 120_000, supply_mv: 24_000 };

    /// From SI units: ratio, kg·m², V (rounded to the wire's units; NaN or negative → 0, which
    /// [`Self::in_limits`] refuses).
    pub fn from_si(gear_ratio: f64, load_inertia_kgm2: f64, supply_v: f64) -> Self {
        // `as` saturates and maps NaN to 0; + ½ rounds a non-negative value (no libm in no_std).
        let round = |v: f64| (v + 0.5) as u32;
        DriveConfig {
            gear_ratio_milli: round(gear_ratio * 1e3),
            load_inertia_gcm2: round(load_inertia_kgm2 * 1e7),
            supply_mv: round(supply_v * 1e3),
        }
    }

    /// Whether every field is inside [`drive_limits`] (the rig may still refuse a drive that
    /// cannot reach its over-speed limit, protocol/README.md "Drive").
    pub fn in_limits(&self) -> bool {
        use drive_limits::*;
        GEAR_RATIO_MILLI.contains(&self.gear_ratio_milli)
            && LOAD_INERTIA_GCM2.contains(&self.load_inertia_gcm2)
            && SUPPLY_MV.contains(&self.supply_mv)
    }
}

/// What a [`DriveConfig`] may say.
pub mod drive_limits {
    use core::ops::RangeInclusive;
    /// Gearhead reductions, × 1000: direct drive to 500:1.
    pub const GEAR_RATIO_MILLI: RangeInclusive<u32> = 1_000..=500_000;
    /// Load inertia, g·cm²: 0.0001 to 1 kg·m² (the prototype's tables are 0.012).
    pub const LOAD_INERTIA_GCM2: RangeInclusive<u32> = 1_000..=10_000_000;
    /// Bridge supply, mV: 6 to 48 V (the RE 30 #310007 is a 24 V winding).
    pub const SUPPLY_MV: RangeInclusive<u32> = 6_000..=48_000;
}

/// Everything the host sends. Variant order is wire order.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// 0: answer with [`Hello`] (then the ack).
    Identify,
    /// 1: start a run.
    Start(StartRun),
    /// 2: ramp down and stop; ends the run.
    Stop,
    /// 3: set the gyro; refused with [`CmdResult::Busy`] during a run.
    ConfigureGyro(GyroConfig),
    /// 4: keeps the link alive; the rig stops the motor after 2 s without any host frame.
    Heartbeat,
    /// 5: the drive train the speed loop is designed for (volatile: a reset restores
    /// [`DriveConfig::PROTOTYPE`]); refused with [`CmdResult::Busy`] during a run and
    /// [`CmdResult::InvalidArgument`] outside the limits.
    ConfigureDrive(DriveConfig),
}
