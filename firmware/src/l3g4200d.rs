//! L3G4200D three-axis gyroscope driver over an embedded-hal 1.0 [`SpiDevice`].
//!
//! In the style of japaric's `l3gd20`: a thin typed layer over the register map, nothing more.
//! Every number comes from ST's datasheet, Doc ID 17116 Rev 3 (2010): §5.2 "SPI bus interface"
//! for the framing, §7 "Register mapping" (Table 18) and §8 "Register description" for the bits.

use embedded_hal::spi::{Operation, SpiDevice};
use protocol::GyroConfig;

/// The value WHO_AM_I must read (§8.1).
pub const DEVICE_ID: u8 = 0xD3;

/// Register addresses (§7, Table 18).
pub mod reg {
    /// Device identification, read-only, 0xD3.
    pub const WHO_AM_I: u8 = 0x0F;
    /// DR, BW, power-down, axis enables.
    pub const CTRL_REG1: u8 = 0x20;
    /// High-pass filter mode and cut-off.
    pub const CTRL_REG2: u8 = 0x21;
    /// Interrupt routing: INT1 and INT2/DRDY.
    pub const CTRL_REG3: u8 = 0x22;
    /// Block data update, endianness, full scale.
    pub const CTRL_REG4: u8 = 0x23;
    /// Reboot, FIFO, high-pass enable, output selection.
    pub const CTRL_REG5: u8 = 0x24;
    /// Die temperature, −1 LSB/°C.
    pub const OUT_TEMP: u8 = 0x26;
    /// Data-available and overrun flags.
    pub const STATUS_REG: u8 = 0x27;
    /// First of the six output bytes (X, Y, Z; low byte first).
    pub const OUT_X_L: u8 = 0x28;
}

/// First SPI byte: bit 7 RW (1 = read), bit 6 MS (1 = auto-increment the address), §5.2.1.
const READ: u8 = 0x80;
const AUTO_INCREMENT: u8 = 0x40;

/// CTRL_REG1 (§8.2): PD = 1 is normal mode; Zen, Xen, Yen enable the three axes.
const CTRL1_PD: u8 = 1 << 3;
const CTRL1_XYZ_EN: u8 = 0b111;
/// CTRL_REG3 (§8.4): I2_DRDY routes data-ready to the INT2/DRDY pin, active high, push-pull.
const CTRL3_I2_DRDY: u8 = 1 << 3;
/// CTRL_REG4 (§8.5): BDU = 1 so the low and high bytes of one axis always come from one sample.
const CTRL4_BDU: u8 = 1 << 7;
/// CTRL_REG5 Out_Sel = 10: the output registers take the data after the second low-pass filter,
/// so CTRL_REG1.BW sets the bandwidth (datasheet Figure 18, Table 33). With 00 (the reset value)
/// LPF2 is bypassed and the bandwidth setting does nothing.
const CTRL5_OUT_SEL_LPF2: u8 = 0x02;

/// STATUS_REG bits (§8.9).
pub mod status {
    /// ZYXOR: new X, Y, Z data overwrote data that had not been read.
    pub const ZYXOR: u8 = 1 << 7;
    /// ZYXDA: new X, Y, Z data available.
    pub const ZYXDA: u8 = 1 << 3;
}

/// Bytes of one burst read: OUT_TEMP, STATUS_REG, then OUT_X_L ..= OUT_Z_H.
const BURST_LEN: usize = 8;

/// Driver errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<E> {
    /// The bus reported an error.
    Spi(E),
    /// WHO_AM_I read this instead of [`DEVICE_ID`]: another chip, or no chip at all.
    WrongDevice(u8),
}

impl<E> From<E> for Error<E> {
    fn from(e: E) -> Self {
        Error::Spi(e)
    }
}

/// One burst read, everything the rig needs from a data-ready edge.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Measurement {
    /// OUT_TEMP, −1 LSB/°C with an unspecified offset (Table 5).
    pub temp_raw: i8,
    /// STATUS_REG as read, before the output bytes (see [`status`]).
    pub status: u8,
    /// OUT_X, OUT_Y, OUT_Z in counts (two's complement, little-endian on the bus with BLE = 0).
    pub rate_counts: [i16; 3],
}

impl Measurement {
    /// ZYXOR: at least one sample was lost inside the gyro before this one.
    pub fn overrun(&self) -> bool {
        self.status & status::ZYXOR != 0
    }

    /// ZYXDA: the output registers held a sample not read before.
    pub fn fresh(&self) -> bool {
        self.status & status::ZYXDA != 0
    }

    /// Every byte of the burst read 0xFF: a MISO line stuck high (or no chip driving it against
    /// a pull-up). A real sample reads so only if OUT_TEMP, STATUS_REG and all three outputs
    /// are 0xFF at once (−1 LSB on every axis, every overrun bit set): with the datasheet's rate
    /// noise (≈ 18 LSB RMS at ±500 °/s and 800 Hz) never twice in a row, let alone
    /// [`crate::rig::GYRO_BAD_READS`] times.
    pub fn bus_stuck_high(&self) -> bool {
        self.temp_raw == -1 && self.status == 0xFF && self.rate_counts == [-1; 3]
    }
}

/// CTRL_REG1 ..= CTRL_REG5 for `config`, in register order.
pub fn control_registers(config: GyroConfig) -> [u8; 5] {
    [
        config.odr.dr_bits() << 6 | config.bandwidth.bw_bits() << 4 | CTRL1_PD | CTRL1_XYZ_EN,
        0x00, // CTRL_REG2: high-pass filter unused (CTRL_REG5 HPen = 0).
        CTRL3_I2_DRDY,
        CTRL4_BDU | config.full_scale.fs_bits() << 4,
        CTRL5_OUT_SEL_LPF2, // CTRL_REG5: no FIFO, no high-pass; output after LPF2 (Out_Sel = 1x).
    ]
}

/// An L3G4200D on an SPI device (SPI mode 3, ≤ 10 MHz, §5.2).
pub struct L3g4200d<SPI> {
    spi: SPI,
}

impl<SPI: SpiDevice> L3g4200d<SPI> {
    /// Wraps the device; does no I/O (call [`L3g4200d::init`]).
    pub const fn new(spi: SPI) -> Self {
        Self { spi }
    }

    /// Checks WHO_AM_I, writes the whole configuration, then reads (and discards) the outputs.
    /// Safe to call again to reconfigure.
    ///
    /// The discarded read matters after a warm reset: the sensor keeps its power across an MCU
    /// reset (watchdog, panic, debugger), and its DRDY stays high until the outputs are read, so
    /// the rising edge the capture is armed for would never come. Call it after arming the
    /// capture: the next sample then raises a fresh edge.
    pub fn init(&mut self, config: GyroConfig) -> Result<(), Error<SPI::Error>> {
        let id = self.who_am_i()?;
        if id != DEVICE_ID {
            return Err(Error::WrongDevice(id));
        }
        self.configure(config)?;
        self.read()?;
        Ok(())
    }

    /// Reads WHO_AM_I.
    pub fn who_am_i(&mut self) -> Result<u8, SPI::Error> {
        self.read_register(reg::WHO_AM_I)
    }

    /// Writes CTRL_REG1 ..= CTRL_REG5 in one auto-increment burst.
    pub fn configure(&mut self, config: GyroConfig) -> Result<(), SPI::Error> {
        let regs = control_registers(config);
        let mut frame = [0u8; 6];
        frame[0] = AUTO_INCREMENT | reg::CTRL_REG1;
        frame[1..].copy_from_slice(&regs);
        self.spi.write(&frame)
    }

    /// Reads OUT_TEMP, STATUS_REG and the six output bytes in one auto-increment burst, so the
    /// status describes exactly the sample read with it.
    pub fn read(&mut self) -> Result<Measurement, SPI::Error> {
        let mut buf = [0u8; BURST_LEN];
        self.spi.transaction(&mut [
            Operation::Write(&[READ | AUTO_INCREMENT | reg::OUT_TEMP]),
            Operation::Read(&mut buf),
        ])?;
        let axis = |i: usize| i16::from_le_bytes([buf[2 + 2 * i], buf[3 + 2 * i]]);
        Ok(Measurement { temp_raw: buf[0] as i8, status: buf[1], rate_counts: [axis(0), axis(1), axis(2)] })
    }

    /// Reads OUT_TEMP alone.
    pub fn temperature(&mut self) -> Result<i8, SPI::Error> {
        Ok(self.read_register(reg::OUT_TEMP)? as i8)
    }

    /// Reads STATUS_REG alone.
    pub fn status(&mut self) -> Result<u8, SPI::Error> {
        self.read_register(reg::STATUS_REG)
    }

    /// Reads one register.
    pub fn read_register(&mut self, address: u8) -> Result<u8, SPI::Error> {
        let mut value = [0u8];
        self.spi.transaction(&mut [Operation::Write(&[READ | address]), Operation::Read(&mut value)])?;
        Ok(value[0])
    }

    /// The SPI device, for a model to be inspected in tests.
    pub fn spi_mut(&mut self) -> &mut SPI {
        &mut self.spi
    }

    /// Gives the SPI device back.
    pub fn release(self) -> SPI {
        self.spi
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction as T};
    use protocol::{Bandwidth, FullScale, Odr};

    fn read_reg(addr: u8, value: u8) -> [T<u8>; 4] {
        [T::transaction_start(), T::write(0x80 | addr), T::read(value), T::transaction_end()]
    }

    #[test]
    fn init_checks_identity_then_writes_default_config_in_one_burst() {
        let mut expect = read_reg(0x0F, 0xD3).to_vec();
        // 800 Hz (DR=11), BW=11, PD, XYZ: 0xFF; DRDY on INT2: 0x08; BDU + ±500 °/s: 0x90.
        expect.extend([
            T::transaction_start(),
            T::write_vec(vec![0x60, 0xFF, 0x00, 0x08, 0x90, 0x02]),
            T::transaction_end(),
            // The discarded burst read that releases a DRDY left high by a warm reset.
            T::transaction_start(),
            T::write(0xE6),
            T::read_vec(vec![0; 8]),
            T::transaction_end(),
        ]);
        let mut spi = Mock::new(&expect);
        let mut gyro = L3g4200d::new(spi.clone());
        assert_eq!(gyro.init(GyroConfig::DEFAULT), Ok(()));
        spi.done();
    }

    #[test]
    fn other_configs_encode_their_fields() {
        let cfg = GyroConfig { full_scale: FullScale::Dps2000, odr: Odr::Hz100, bandwidth: Bandwidth::Bw1 };
        // DR=00 BW=01 PD XYZ = 0x1F; BDU | FS=10 = 0xA0.
        assert_eq!(control_registers(cfg), [0x1F, 0x00, 0x08, 0xA0, 0x02]);
        let cfg = GyroConfig { full_scale: FullScale::Dps250, odr: Odr::Hz200, bandwidth: Bandwidth::Bw2 };
        assert_eq!(control_registers(cfg), [0x6F, 0x00, 0x08, 0x80, 0x02]);
    }

    /// B3: with CTRL_REG5 = 0x00 the output bypasses LPF2 and the bandwidth code does nothing;
    /// Out_Sel = 1x (0x02) puts LPF2 in the path for every configuration, high-pass off.
    #[test]
    fn every_config_reads_through_the_second_low_pass_filter() {
        for full_scale in [FullScale::Dps250, FullScale::Dps500, FullScale::Dps2000] {
            for odr in [Odr::Hz100, Odr::Hz200, Odr::Hz400, Odr::Hz800] {
                for bandwidth in [Bandwidth::Bw0, Bandwidth::Bw1, Bandwidth::Bw2, Bandwidth::Bw3] {
                    let ctrl5 = control_registers(GyroConfig { full_scale, odr, bandwidth })[4];
                    assert_eq!(ctrl5 & 0b11, 0b10, "Out_Sel selects LPF2");
                    assert_eq!(ctrl5 & 0x10, 0, "HPen off");
                }
            }
        }
    }

    #[test]
    fn wrong_identity_is_reported_and_nothing_is_written() {
        let mut spi = Mock::new(&read_reg(0x0F, 0xD4));
        let mut gyro = L3g4200d::new(spi.clone());
        assert_eq!(gyro.init(GyroConfig::DEFAULT), Err(Error::WrongDevice(0xD4)));
        spi.done();
    }

    #[test]
    fn burst_read_decodes_temperature_status_and_little_endian_axes() {
        let mut spi = Mock::new(&[
            T::transaction_start(),
            T::write(0xE6),
            T::read_vec(vec![0xE7, 0x88, 0x34, 0x12, 0xFF, 0xFF, 0x00, 0x80]),
            T::transaction_end(),
        ]);
        let mut gyro = L3g4200d::new(spi.clone());
        let m = gyro.read().unwrap();
        assert_eq!(m.temp_raw, -25);
        assert_eq!(m.rate_counts, [0x1234, -1, i16::MIN]);
        assert!(m.overrun());
        assert!(m.fresh());
        spi.done();
    }

    #[test]
    fn single_register_reads() {
        let mut expect = read_reg(0x26, 0x05).to_vec();
        expect.extend(read_reg(0x27, 0x08));
        let mut spi = Mock::new(&expect);
        let mut gyro = L3g4200d::new(spi.clone());
        assert_eq!(gyro.temperature(), Ok(5));
        assert_eq!(gyro.status(), Ok(status::ZYXDA));
        spi.done();
    }
}
