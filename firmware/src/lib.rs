//! Portable core of the exciter firmware: everything that decides, counts or speaks the protocol,
//! as plain Rust that builds for the MCU and for the host alike. The rtic app in `main.rs` only
//! moves register values into [`rig::Rig`] and its answers back out to the pins.
//!
//! With the `plant` feature (implied by `sim` and `qemu`, and in tests) the crate also carries the
//! simulated plant ([`plant`]) and the [`virtual_rig`] that runs this core against it in simulated
//! time; both are `no_std`, so the QEMU image runs them on the MCU.
#![cfg_attr(not(any(test, feature = "sim")), no_std)]
#![deny(missing_docs)]

pub mod commands;
pub mod index;
pub mod input_filter;
pub mod l3g4200d;
pub mod link;
pub mod pwm;
pub mod rig;
pub mod safe_state;
pub mod speed_loop;
pub mod supervisor;
pub mod tx_queue;

#[cfg(any(test, feature = "plant"))]
pub mod plant;
#[cfg(any(test, feature = "plant"))]
pub mod virtual_rig;

use protocol::Version;

/// This firmware's version, as reported in [`protocol::Hello`]; must match `Cargo.toml`.
pub const FIRMWARE_VERSION: Version = Version { major: 0, minor: 1, patch: 0 };

/// Sensor-table turns per base-table turn ([`protocol::GEAR_RATIO`]).
pub use protocol::GEAR_RATIO;

/// `x` limited to `±bound`. Not `f32::clamp`: its panic message formats floats, which would
/// pull ≈ 23 KiB of core's float formatting into the image.
#[inline]
pub(crate) fn limit(x: f32, bound: f32) -> f32 {
    x.max(-bound).min(bound)
}

#[cfg(test)]
mod tests {
    #[test]
    fn firmware_version_matches_the_package() {
        let v = super::FIRMWARE_VERSION;
        assert_eq!(format!("{}.{}.{}", v.major, v.minor, v.patch), env!("CARGO_PKG_VERSION"));
    }
}
