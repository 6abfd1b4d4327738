//! L3G4200D settings as they travel on the wire, with the datasheet numbers behind them.
//!
//! Source: ST L3G4200D datasheet, Doc ID 17116 Rev 3 (2010): Table 4 (sensitivity), Table 21
//! (ODR and bandwidth), CTRL_REG1 and CTRL_REG4 register descriptions.

use serde::{Deserialize, Serialize};

/// Full-scale range (CTRL_REG4 FS[1:0]).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "std", derive(PartialOrd, Ord))]
pub enum FullScale {
    /// ±250 °/s, 8.75 m°/s per LSB.
    Dps250,
    /// ±500 °/s, 17.50 m°/s per LSB: the default, because pose 1 at 0.5 Hz peaks at 251 °/s.
    Dps500,
    /// ±2000 °/s, 70 m°/s per LSB.
    Dps2000,
}

impl FullScale {
    /// Nominal sensitivity in micro-degrees per second per LSB (datasheet Table 4, "So").
    pub const fn udps_per_lsb(self) -> u32 {
        match self {
            FullScale::Dps250 => 8_750,
            FullScale::Dps500 => 17_500,
            FullScale::Dps2000 => 70_000,
        }
    }

    /// Range in degrees per second.
    pub const fn range_dps(self) -> u16 {
        match self {
            FullScale::Dps250 => 250,
            FullScale::Dps500 => 500,
            FullScale::Dps2000 => 2000,
        }
    }

    /// CTRL_REG4 FS[1:0] field value (bits 5:4).
    pub const fn fs_bits(self) -> u8 {
        match self {
            FullScale::Dps250 => 0b00,
            FullScale::Dps500 => 0b01,
            FullScale::Dps2000 => 0b10,
        }
    }
}

/// Output data rate (CTRL_REG1 DR[1:0]).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Odr {
    /// 100 Hz.
    Hz100,
    /// 200 Hz.
    Hz200,
    /// 400 Hz.
    Hz400,
    /// 800 Hz: the default.
    Hz800,
}

impl Odr {
    /// Nominal rate in Hz. Nominal only: the rig timestamps every sample, and the timestamps are
    /// the truth.
    pub const fn hz(self) -> u16 {
        match self {
            Odr::Hz100 => 100,
            Odr::Hz200 => 200,
            Odr::Hz400 => 400,
            Odr::Hz800 => 800,
        }
    }

    /// CTRL_REG1 DR[1:0] field value (bits 7:6).
    pub const fn dr_bits(self) -> u8 {
        match self {
            Odr::Hz100 => 0b00,
            Odr::Hz200 => 0b01,
            Odr::Hz400 => 0b10,
            Odr::Hz800 => 0b11,
        }
    }
}

/// Bandwidth selection (CTRL_REG1 BW[1:0]); its cut-off depends on the ODR.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Bandwidth {
    /// BW = 00.
    Bw0,
    /// BW = 01.
    Bw1,
    /// BW = 10.
    Bw2,
    /// BW = 11.
    Bw3,
}

impl Bandwidth {
    /// CTRL_REG1 BW[1:0] field value (bits 5:4).
    pub const fn bw_bits(self) -> u8 {
        match self {
            Bandwidth::Bw0 => 0b00,
            Bandwidth::Bw1 => 0b01,
            Bandwidth::Bw2 => 0b10,
            Bandwidth::Bw3 => 0b11,
        }
    }

    /// Low-pass cut-off in tenths of a hertz (datasheet Table 21, "DR and BW configuration").
    pub const fn cutoff_dhz(self, odr: Odr) -> u16 {
        match (odr, self) {
            (Odr::Hz100, Bandwidth::Bw0) => 125,
            (Odr::Hz100, _) => 250,
            (Odr::Hz200, Bandwidth::Bw0) => 125,
            (Odr::Hz200, Bandwidth::Bw1) => 250,
            (Odr::Hz200, Bandwidth::Bw2) => 500,
            (Odr::Hz200, Bandwidth::Bw3) => 700,
            (Odr::Hz400, Bandwidth::Bw0) => 200,
            (Odr::Hz400, Bandwidth::Bw1) => 250,
            (Odr::Hz400, Bandwidth::Bw2) => 500,
            (Odr::Hz400, Bandwidth::Bw3) => 1100,
            (Odr::Hz800, Bandwidth::Bw0) => 300,
            (Odr::Hz800, Bandwidth::Bw1) => 350,
            (Odr::Hz800, Bandwidth::Bw2) => 500,
            (Odr::Hz800, Bandwidth::Bw3) => 1100,
        }
    }
}

/// Everything that sets the meaning of a raw sample.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GyroConfig {
    /// Full-scale range.
    pub full_scale: FullScale,
    /// Output data rate.
    pub odr: Odr,
    /// Low-pass bandwidth selection.
    pub bandwidth: Bandwidth,
}

impl GyroConfig {
    /// The rig's default: ±500 °/s, 800 Hz, BW = 11 (110 Hz cut-off).
    pub const DEFAULT: GyroConfig =
        GyroConfig { full_scale: FullScale::Dps500, odr: Odr::Hz800, bandwidth: Bandwidth::Bw3 };
}

impl Default for GyroConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}
