//! The exciter's wire protocol: the single source of truth shared by the firmware and the host.
//!
//! Every frame on the wire is `COBS(postcard((seq, msg)) ++ crc32c_le) ++ 0x00`; see
//! `protocol/README.md` for the byte-exact specification and test vectors. The crate is `no_std`
//! and allocation-free so the firmware can use it unchanged; the `std` feature only adds
//! conveniences for the host.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]

pub mod decoder;
pub mod exciter;
pub mod frame;
pub mod gyro;
pub mod msg;
pub mod units;

pub use decoder::{Event, SeqTracker, StreamDecoder};
pub use frame::{encode_frame, FrameError, MAX_FRAME_LEN, MAX_PAYLOAD_LEN};
pub use gyro::{Bandwidth, FullScale, GyroConfig, Odr};
pub use msg::*;

/// Wire protocol version carried in [`Hello`]. Bumped on any change to the byte layout of an
/// existing message; adding a new enum variant at the end is compatible and does not bump it.
pub const PROTOCOL_VERSION: u16 = 1;

/// Rate of the rig's timestamp clock: every `t_us` field counts microseconds (32 bits, so it
/// wraps every 2^32 µs = 71.6 min; the host unwraps it).
pub const TIMESTAMP_HZ: u32 = 1_000_000;

/// Base-table encoder resolution after x4 quadrature decoding: Canon R-ISO, 81 000 pulses/rev
/// (EXCITER.md, "Parts in the prototype").
pub const ENCODER_COUNTS_PER_REV: u32 = 4 * 81_000;

/// Sensor-table turns per base-table turn of this rig design: the magnetic gears are 1:1
/// (EXCITER.md, "Mechanism"). Also sent in [`Hello`]; a host that lost the `Hello` assumes it.
pub const GEAR_RATIO: GearRatio = GearRatio { num: 1, den: 1 };

/// Highest base-table rate a `Start` may ask for: 360 °/s (1 Hz), twice the paper's 0.5 Hz drive;
/// the rig refuses more with `InvalidArgument`. Pose 1 then peaks at 502 °/s (EXCITER.md: 251 °/s
/// at 0.5 Hz), so above 0.5 Hz the host must select the ±2000 °/s range.
pub const MAX_RATE_MDPS: u32 = 360_000;

/// What a run tag means (protocol/README.md, "Field meanings"): the rig echoes any tag; the
/// host, and a rig that mounts the gyro by itself (the virtual rig), read it as the pose.
pub mod run_tag {
    /// `Motor.run_tag` while no run is in progress.
    pub const IDLE: u8 = 0;
    /// The gyro in pose 1 (EXCITER.md: on the 54.74° wedge, turned 45° about z).
    pub const POSE_1: u8 = 1;
    /// The gyro in pose 2 (pose 1 turned −90° about the sensor table's y axis).
    pub const POSE_2: u8 = 2;
}

/// The link's timing, one place for both ends (protocol/README.md, "Link timing").
pub mod timing {
    /// Rig: no host frame for this long during a run (spin-up, recording or ramp-down) stops
    /// the motor with [`crate::Fault::HostLinkLost`]. The host must send a frame at least this
    /// often for as long as the motor turns, so a ramp-down after `Stop` needs heartbeats too.
    pub const HOST_LINK_TIMEOUT_US: u32 = 2_000_000;

    /// Host: spacing of [`crate::Command::Heartbeat`] when it has nothing else to send: 8 per
    /// link timeout, margin for a loaded host and for lost frames.
    pub const HEARTBEAT_INTERVAL_MS: u32 = 250;

    /// Host: how long one attempt at a command waits for its [`crate::Ack`] before the command
    /// is sent again (every command is idempotent or recognisably repeated, README "Commands").
    pub const ACK_TIMEOUT_MS: u32 = 1_000;

    /// Host: attempts at a command before the rig is declared unreachable.
    pub const COMMAND_ATTEMPTS: u32 = 3;

    /// Host: the link is dead (cable, power, USB) when not one byte arrives for this long; an
    /// idle rig streams samples, `Motor` and `Counters` continuously.
    pub const SILENT_LINK_MS: u32 = 2_000;

    /// Host: no gyro sample for this long while other frames arrive is a silent gyro.
    pub const SAMPLE_TIMEOUT_MS: u32 = 2_000;

    /// Host: how long a run may take to reach its speed.
    pub const SPIN_UP_TIMEOUT_MS: u32 = 20_000;

    /// Rig: `Motor` reports per second, during runs and while idle; `speed_cps` is measured over
    /// one report interval.
    pub const MOTOR_STATUS_HZ: u32 = 10;

    /// Rig: `Counters` reports per second, each followed by the latest `Temperature` (if a
    /// sample was read since the last one).
    pub const COUNTERS_HZ: u32 = 1;

    /// Host: how long, after the `Stop` is acknowledged, the rig may take to report the motor
    /// stopped (`RunStopped`, or a `Motor` status with run tag 0 if that frame was lost). A
    /// ramp-down from the fastest rate takes 4 s.
    pub const STOP_TIMEOUT_MS: u32 = 10_000;
}
