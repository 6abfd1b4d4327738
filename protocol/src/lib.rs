//! The exciter's wire protocol: the single source of truth shared by the firmware and the host.
//!
//! Every frame on the wire is `COBS(postcard((seq, msg)) ++ crc32c_le) ++ 0x00`; see
//! `protocol/README.md` for the byte-exact specification and test vectors. The crate is `no_std`
//! and allocation-free so the firmware can use it unchanged; the `std` feature only adds
//! conveniences for the host.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]

pub mod decoder;
pub mod frame;
pub mod gyro;
pub mod msg;

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
