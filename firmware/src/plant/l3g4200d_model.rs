//! Register-level model of the L3G4200D on its SPI bus, answering byte by byte as the datasheet
//! (Doc ID 17116 Rev 3) says: §5.2 framing (RW, MS auto-increment, 6-bit address), the register
//! map of §7, STATUS_REG data-available/overrun semantics (§8.9), DRDY on INT2 when
//! CTRL_REG3.I2_DRDY is set, ODR from CTRL_REG1.DR and PD, full scale from CTRL_REG4.FS.
//!
//! Its clock is its own: the real sample period is the nominal one off by `odr_error`, which
//! is why the firmware timestamps data-ready instead of trusting the ODR. Rate noise is white, of
//! the datasheet's density, when asked for ([`L3g4200dModel::with_noise`]); the low-pass filter's
//! delay is not modelled.

use crate::l3g4200d::{reg, status, DEVICE_ID};
use embedded_hal::spi::{self, ErrorKind, ErrorType, Operation, SpiDevice};
use libm::round;
#[cfg(feature = "sim")]
use rand_chacha::{rand_core::SeedableRng, ChaCha8Rng};
#[cfg(feature = "sim")]
use rand_distr::{Distribution, StandardNormal};

/// Rate noise density of the L3G4200D, °/s/√Hz (datasheet Table 4, "Rn", typ.). The host's
/// simulator uses the same figure (host::sim::NOISE_DENSITY_DPS_PER_SQRT_HZ).
pub const NOISE_DENSITY_DPS_PER_SQRT_HZ: f64 = 0.03;

/// How the bus misbehaves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusFault {
    /// Healthy.
    None,
    /// The chip sees every transfer, but the MCU's SPI reports an error for each one.
    Error,
    /// MISO stuck low: the chip works and sees every transfer, the MCU reads only zeros.
    MisoStuckLow,
    /// MISO stuck high (shorted to 3.3 V, or the chip gone and the line pulled up): the MCU
    /// reads only 0xFF.
    MisoStuckHigh,
}

/// The error the model's bus reports under [`BusFault::Error`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusError;

impl spi::Error for BusError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Overrun
    }
}

/// A chip's white rate noise: density and the generator it is drawn from.
#[cfg(feature = "sim")]
#[derive(Debug, Clone)]
struct Noise {
    density_dps_per_sqrt_hz: f64,
    rng: ChaCha8Rng,
}

/// Where the current transaction is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Command,
    Data { address: u8, read: bool, increment: bool },
}

/// An L3G4200D.
#[derive(Debug, Clone)]
pub struct L3g4200dModel {
    regs: [u8; 0x40],
    phase: Phase,
    /// Fractional error of the internal oscillator: +0.012 runs 1.2 % fast.
    pub odr_error: f64,
    /// Bus fault injected.
    pub fault: BusFault,
    /// The chip stopped producing data (brown-out, broken INT2 wire).
    pub halted: bool,
    next_sample_s: Option<f64>,
    /// White rate noise (none: a noiseless chip, outputs exactly predictable).
    #[cfg(feature = "sim")]
    noise: Option<Noise>,
    /// Samples produced.
    pub samples: u32,
    /// Samples overwritten before being read (ZYXOR events).
    pub overruns: u32,
}

impl Default for L3g4200dModel {
    fn default() -> Self {
        Self::new()
    }
}

impl L3g4200dModel {
    /// Power-on state (all control registers 0: powered down), WHO_AM_I = 0xD3, 1.2 % fast.
    pub fn new() -> Self {
        let mut regs = [0u8; 0x40];
        regs[usize::from(reg::WHO_AM_I)] = DEVICE_ID;
        Self {
            regs,
            phase: Phase::Command,
            odr_error: 0.012,
            fault: BusFault::None,
            halted: false,
            next_sample_s: None,
            #[cfg(feature = "sim")]
            noise: None,
            samples: 0,
            overruns: 0,
        }
    }

    /// A chip with the datasheet's rate noise ([`NOISE_DENSITY_DPS_PER_SQRT_HZ`]), drawn from
    /// `seed`. Without it the outputs are the rates rounded to an LSB (0.005 °/s rms at ±500 °/s),
    /// some 100 times quieter than the part: table-speed jitter that the encoder cannot resolve
    /// (≈ 0.03 °/s rms at 20-400 Hz from the speed loop, see firmware/README.md) then dominates
    /// the residual of a calibration, where the real part's noise buries it.
    #[cfg(feature = "sim")]
    pub fn with_noise(seed: u64) -> Self {
        let noise =
            Noise { density_dps_per_sqrt_hz: NOISE_DENSITY_DPS_PER_SQRT_HZ, rng: ChaCha8Rng::seed_from_u64(seed) };
        Self { noise: Some(noise), ..Self::new() }
    }

    /// One sample's rate noise per axis, °/s: white at the ODR, σ = ρ·√(ODR/2) (the Nyquist
    /// band; as host::sim does).
    fn noise_dps(&mut self, period_s: f64) -> [f64; 3] {
        #[cfg(feature = "sim")]
        if let Some(n) = self.noise.as_mut() {
            let sigma_dps = n.density_dps_per_sqrt_hz * (0.5 / period_s).sqrt();
            return [0; 3].map(|_| sigma_dps * Distribution::<f64>::sample(&StandardNormal, &mut n.rng));
        }
        let _ = period_s;
        [0.0; 3]
    }

    /// Replaces WHO_AM_I (another chip on the bus).
    pub fn set_who_am_i(&mut self, id: u8) {
        self.regs[usize::from(reg::WHO_AM_I)] = id;
    }

    /// Register value, as the chip holds it.
    pub fn register(&self, address: u8) -> u8 {
        self.regs[usize::from(address & 0x3F)]
    }

    /// Actual sample period, s; `None` while powered down (CTRL_REG1.PD = 0).
    pub fn sample_period_s(&self) -> Option<f64> {
        let ctrl1 = self.regs[usize::from(reg::CTRL_REG1)];
        if ctrl1 & 0x08 == 0 || self.halted {
            return None;
        }
        let nominal_hz = [100.0, 200.0, 400.0, 800.0][usize::from(ctrl1 >> 6)];
        Some(1.0 / (nominal_hz * (1.0 + self.odr_error)))
    }

    /// When the next sample is due, scheduling one period after `now_s` if the chip has just
    /// been powered up.
    pub fn next_sample_s(&mut self, now_s: f64) -> Option<f64> {
        match (self.sample_period_s(), self.next_sample_s) {
            (None, _) => self.next_sample_s = None,
            (Some(period), None) => self.next_sample_s = Some(now_s + period),
            _ => {}
        }
        self.next_sample_s
    }

    /// Latches a sample taken at the due time: `rate_dps` is the angular rate along the three
    /// sensing axes, `temp_raw` the OUT_TEMP value; the chip adds its noise, if it has any.
    pub fn latch(&mut self, rate_dps: [f64; 3], temp_raw: i8) {
        let Some(period) = self.sample_period_s() else {
            return;
        };
        let noise_dps = self.noise_dps(period);
        self.next_sample_s = self.next_sample_s.map(|t| t + period);
        let lsb_dps = match (self.regs[usize::from(reg::CTRL_REG4)] >> 4) & 0b11 {
            0b00 => 8.75e-3,
            0b01 => 17.5e-3,
            _ => 70e-3,
        };
        let status_reg = usize::from(reg::STATUS_REG);
        if self.regs[status_reg] & status::ZYXDA != 0 {
            self.regs[status_reg] |= status::ZYXOR | 0x70;
            self.overruns += 1;
        }
        self.regs[status_reg] |= status::ZYXDA | 0x07;
        for (axis, rate) in rate_dps.iter().enumerate() {
            let counts = round((rate + noise_dps[axis]) / lsb_dps).clamp(i16::MIN.into(), i16::MAX.into()) as i16;
            let at = usize::from(reg::OUT_X_L) + 2 * axis;
            self.regs[at..at + 2].copy_from_slice(&counts.to_le_bytes());
        }
        self.regs[usize::from(reg::OUT_TEMP)] = temp_raw as u8;
        self.samples += 1;
    }

    /// The most recent sample's outputs, counts.
    pub fn outputs(&self) -> [i16; 3] {
        let at = |i: usize| {
            let a = usize::from(reg::OUT_X_L) + 2 * i;
            i16::from_le_bytes([self.regs[a], self.regs[a + 1]])
        };
        [at(0), at(1), at(2)]
    }

    /// Level of the INT2/DRDY pin: data available and routed there (CTRL_REG3.I2_DRDY).
    pub fn drdy(&self) -> bool {
        self.regs[usize::from(reg::CTRL_REG3)] & 0x08 != 0
            && self.regs[usize::from(reg::STATUS_REG)] & status::ZYXDA != 0
    }

    /// One byte on the bus: `mosi` in, the chip's MISO byte out.
    fn clock(&mut self, mosi: u8) -> u8 {
        match self.phase {
            Phase::Command => {
                self.phase = Phase::Data { address: mosi & 0x3F, read: mosi & 0x80 != 0, increment: mosi & 0x40 != 0 };
                0x00
            }
            Phase::Data { address, read, increment } => {
                let miso = if read {
                    self.read(address)
                } else {
                    self.write(address, mosi);
                    0x00
                };
                if increment {
                    self.phase = Phase::Data { address: (address + 1) & 0x3F, read, increment };
                }
                miso
            }
        }
    }

    fn read(&mut self, address: u8) -> u8 {
        let value = self.regs[usize::from(address)];
        // Reading the last output byte completes the sample: data-available and overrun clear,
        // and DRDY falls.
        if address == reg::OUT_X_L + 5 {
            self.regs[usize::from(reg::STATUS_REG)] = 0;
        }
        value
    }

    fn write(&mut self, address: u8, value: u8) {
        // Writable: CTRL_REG1..=CTRL_REG5, REFERENCE, FIFO_CTRL, INT1 configuration (§7).
        let writable = matches!(address, 0x20..=0x25 | 0x2E | 0x30 | 0x32..=0x38);
        if writable {
            self.regs[usize::from(address)] = value;
        }
    }
}

impl ErrorType for L3g4200dModel {
    type Error = BusError;
}

impl SpiDevice for L3g4200dModel {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), BusError> {
        // CS falls: a new command byte is expected.
        self.phase = Phase::Command;
        let stuck = match self.fault {
            BusFault::MisoStuckLow => Some(0x00),
            BusFault::MisoStuckHigh => Some(0xFF),
            _ => None,
        };
        let mut clock = |mosi: u8| {
            let miso = self.clock(mosi);
            stuck.unwrap_or(miso)
        };
        for op in operations.iter_mut() {
            match op {
                Operation::Read(buf) => buf.iter_mut().for_each(|b| *b = clock(0)),
                Operation::Write(buf) => buf.iter().for_each(|&b| {
                    clock(b);
                }),
                Operation::Transfer(read, write) => {
                    for i in 0..read.len().max(write.len()) {
                        let miso = clock(write.get(i).copied().unwrap_or(0));
                        if let Some(r) = read.get_mut(i) {
                            *r = miso;
                        }
                    }
                }
                Operation::TransferInPlace(buf) => buf.iter_mut().for_each(|b| *b = clock(*b)),
                Operation::DelayNs(_) => {}
            }
        }
        match self.fault {
            BusFault::Error => Err(BusError),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::l3g4200d::L3g4200d;
    use protocol::{FullScale, GyroConfig, Odr};

    #[test]
    fn driver_configures_the_model_and_reads_back_a_sample() {
        let mut gyro = L3g4200d::new(L3g4200dModel::new());
        gyro.init(GyroConfig::DEFAULT).unwrap();
        let chip = gyro.spi_mut();
        assert_eq!(chip.register(reg::CTRL_REG1), 0xFF);
        assert_eq!(chip.register(reg::CTRL_REG4), 0x90);
        // 800 Hz, 1.2 % fast.
        let period = chip.sample_period_s().unwrap();
        assert!((period - 1.0 / 809.6).abs() < 1e-12);
        assert!(!chip.drdy());
        chip.latch([100.0, -250.0, 0.01], -3);
        assert!(chip.drdy());
        let m = gyro.read().unwrap();
        // 17.5 m°/s per LSB at ±500 °/s: 100 °/s = 5714.3 → 5714.
        assert_eq!(m.rate_counts, [5714, -14286, 1]);
        assert_eq!((m.temp_raw, m.fresh(), m.overrun()), (-3, true, false));
        assert!(!gyro.spi_mut().drdy(), "reading OUT_Z_H clears data-ready");
        let again = gyro.read().unwrap();
        assert!(!again.fresh());
    }

    #[test]
    #[cfg(feature = "sim")]
    fn noise_has_the_datasheet_density_and_is_reproducible() {
        let draw = |seed| {
            let mut gyro = L3g4200d::new(L3g4200dModel::with_noise(seed));
            gyro.init(GyroConfig::DEFAULT).unwrap();
            (0..20_000)
                .map(|_| {
                    gyro.spi_mut().latch([0.0, 100.0, -100.0], 0);
                    gyro.read().unwrap().rate_counts
                })
                .collect::<Vec<_>>()
        };
        let samples = draw(7);
        assert_eq!(samples, draw(7), "one seed, one noise sequence");
        // 0.03 °/s/√Hz over the 404.8 Hz Nyquist band of 809.6 Hz: 0.6036 °/s, 34.49 LSB of
        // 17.5 m°/s. 20 000 samples know the standard deviation to 0.5 % (1/√(2N)).
        let expected_lsb = 0.03 * (809.6f64 / 2.0).sqrt() / 17.5e-3;
        for (axis, mean_lsb) in [(0, 0.0), (1, 100.0 / 17.5e-3), (2, -100.0 / 17.5e-3)] {
            let v: Vec<f64> = samples.iter().map(|s| f64::from(s[axis])).collect();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt();
            assert!((sd / expected_lsb - 1.0).abs() < 0.03, "axis {axis}: σ {sd:.2} LSB vs {expected_lsb:.2}");
            // The mean to 5 standard errors (0.24 LSB) plus half an LSB of rounding.
            assert!((mean - mean_lsb).abs() < 5.0 * expected_lsb / 141.4 + 0.5, "axis {axis}: mean {mean}");
        }
        let lag1: f64 = samples.windows(2).map(|w| f64::from(w[0][0]) * f64::from(w[1][0])).sum::<f64>()
            / (samples.len() - 1) as f64;
        assert!(lag1.abs() / (expected_lsb * expected_lsb) < 0.03, "white: lag-1 correlation {lag1}");
    }

    #[test]
    fn unread_sample_overwritten_sets_overrun() {
        let mut gyro = L3g4200d::new(L3g4200dModel::new());
        let cfg = GyroConfig { full_scale: FullScale::Dps2000, odr: Odr::Hz100, ..GyroConfig::DEFAULT };
        gyro.init(cfg).unwrap();
        gyro.spi_mut().latch([1.0; 3], 0);
        gyro.spi_mut().latch([1000.0; 3], 0);
        let m = gyro.read().unwrap();
        assert!(m.overrun() && m.fresh());
        assert_eq!(m.rate_counts, [14_286; 3]);
        assert_eq!(gyro.spi_mut().overruns, 1);
    }

    #[test]
    fn faults_as_the_driver_sees_them() {
        let mut chip = L3g4200dModel::new();
        chip.fault = BusFault::MisoStuckLow;
        let mut gyro = L3g4200d::new(chip);
        assert_eq!(gyro.init(GyroConfig::DEFAULT), Err(crate::l3g4200d::Error::WrongDevice(0x00)));
        gyro.spi_mut().fault = BusFault::Error;
        assert_eq!(gyro.who_am_i(), Err(BusError));
        let mut gyro = L3g4200d::new(L3g4200dModel::new());
        // Read-only registers ignore writes.
        SpiDevice::write(gyro.spi_mut(), &[reg::WHO_AM_I, 0x00]).unwrap();
        assert_eq!(gyro.who_am_i(), Ok(DEVICE_ID));
        gyro.spi_mut().set_who_am_i(0xD4);
        assert_eq!(gyro.init(GyroConfig::DEFAULT), Err(crate::l3g4200d::Error::WrongDevice(0xD4)));
    }
}
