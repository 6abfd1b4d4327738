//! The firmware core running the simulated plant in simulated time: what the rtic app does with
//! interrupts, done here by an event loop.
//!
//! - TIM3 update → [`Rig::control_tick`] every 1 ms, with the TIM2 count; the bridge gets the
//!   PWM-quantised duty.
//! - INT2/DRDY rising → TIM5 and TIM2 capture the time and count, then the driver's burst read
//!   against the register-level [`L3g4200dModel`] → [`Rig::data_ready`].
//! - Photo-interrupter edge → captures located inside the physics step → [`Rig::index_edge`].
//! - The host link → [`HostLink`], polled every loop period like the USB interrupt would be.
//!
//! Timer captures are `floor` of the true instant in µs: what a 1 MHz counter latches.

use crate::l3g4200d::L3g4200d;
use crate::plant::l3g4200d_model::L3g4200dModel;
use crate::plant::Plant;
use crate::pwm::MotorCommand;
use crate::rig::Rig;
use crate::speed_loop::LOOP_HZ;
use protocol::GyroConfig;

/// Nanoseconds per loop period.
pub const TICK_NS: u64 = 1_000_000_000 / LOOP_HZ as u64;

/// Longest physics step, ns: 20 µs, ≪ the 5.6 ms mechanical time constant and short enough
/// that the index plate (≈ 28 ms long at 1 Hz) cannot be crossed twice in one step.
pub const MAX_STEP_NS: u64 = 20_000;

/// The host side of the serial link.
pub trait HostLink {
    /// Copies bytes the host has sent into `buf`; returns how many.
    fn receive(&mut self, buf: &mut [u8]) -> usize;
    /// Delivers bytes to the host.
    fn send(&mut self, bytes: &[u8]);
}

/// What the loop looked like at one control tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Probe {
    /// Simulated time, ns since the start.
    pub t_ns: u64,
    /// True base-table speed, counts/s.
    pub speed_cps: f64,
    /// Ramped setpoint, counts/s.
    pub setpoint_cps: i32,
    /// Bridge command as applied (quantised).
    pub motor: MotorCommand,
    /// Encoder counter.
    pub encoder: u32,
}

/// Firmware core + gyro driver + plant, in simulated time.
pub struct VirtualRig {
    /// The mechanics.
    pub plant: Plant,
    /// The gyro driver, over the chip model (reach the chip with `gyro.spi_mut()`).
    pub gyro: L3g4200d<L3g4200dModel>,
    /// The firmware core.
    pub rig: Rig,
    /// Fault injection: this many coming data-ready edges are missed by the capture (as while it
    /// is not armed), leaving DRDY high.
    pub missed_drdy_edges: u32,
    /// Link throughput, bytes per loop period (USB full-speed bulk moves ≥ 1 kB per ms; 0
    /// models a host that stopped reading).
    pub link_bytes_per_tick: usize,
    now_ns: u64,
    t0_us: u32,
    next_tick_ns: u64,
    drdy: bool,
    motor: MotorCommand,
    /// What really happened, for tests to compare the stream against.
    #[cfg(any(test, feature = "sim"))]
    pub truth: Truth,
}

/// Ground truth recorded by the simulation (std only).
#[cfg(any(test, feature = "sim"))]
#[derive(Debug, Default, Clone)]
pub struct Truth {
    /// Index edges: exact instant (ns, fractional), encoder count then, level after.
    pub index_edges: Vec<(f64, u32, bool)>,
    /// Gyro samples: instant (ns), encoder count then, outputs latched.
    pub samples: Vec<(u64, u32, [i16; 3])>,
}

impl VirtualRig {
    /// Powers up: the core probes and configures the gyro and sends its hello. `t0_us` is the
    /// TIM5 count at simulated time 0 (start near 2^32 to exercise the wrap).
    pub fn new(plant: Plant, chip: L3g4200dModel, t0_us: u32) -> Self {
        Self::restarted(plant, chip, t0_us, false)
    }

    /// [`Self::new`], for an MCU whose last reset was (`watchdog_reset`) forced by the watchdog.
    pub fn restarted(plant: Plant, chip: L3g4200dModel, t0_us: u32, watchdog_reset: bool) -> Self {
        let mut gyro = L3g4200d::new(chip);
        let mut rig = Rig::new(GyroConfig::DEFAULT);
        let probe = crate::rig::GyroControl::apply(&mut gyro, GyroConfig::DEFAULT);
        rig.power_up(t0_us, probe, watchdog_reset);
        // The pin as it is: a sensor that kept its power across the reset may hold it high.
        let drdy = gyro.spi_mut().drdy();
        Self {
            plant,
            gyro,
            rig,
            missed_drdy_edges: 0,
            link_bytes_per_tick: 1_024,
            now_ns: 0,
            t0_us,
            next_tick_ns: TICK_NS,
            drdy,
            motor: MotorCommand::OFF,
            #[cfg(any(test, feature = "sim"))]
            truth: Truth::default(),
        }
    }

    /// The prototype plant, a healthy gyro, TIM5 starting 3 s before its wrap.
    pub fn prototype() -> Self {
        Self::new(Plant::prototype(), L3g4200dModel::new(), u32::MAX - 3_000_000)
    }

    /// Simulated time, ns.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    /// TIM5 count at simulated time `t_ns`.
    pub fn timer_us(&self, t_ns: u64) -> u32 {
        self.t0_us.wrapping_add((t_ns / 1_000) as u32)
    }

    /// Runs until `end_ns`, calling `probe` after every control tick.
    pub fn run_until(&mut self, end_ns: u64, host: &mut impl HostLink, mut probe: impl FnMut(&Probe)) {
        while self.now_ns < end_ns {
            let now_s = self.now_ns as f64 * 1e-9;
            let next_sample_ns =
                self.gyro.spi_mut().next_sample_s(now_s).map(|t| libm::round(t * 1e9) as u64).unwrap_or(u64::MAX);
            let next_event = self.next_tick_ns.min(next_sample_ns).min(end_ns);
            self.advance_to(next_event);
            if self.now_ns == next_sample_ns {
                self.gyro_sample();
            }
            if self.now_ns == self.next_tick_ns {
                self.next_tick_ns += TICK_NS;
                self.control_tick(host);
                probe(&Probe {
                    t_ns: self.now_ns,
                    speed_cps: self.plant.speed_cps(),
                    setpoint_cps: self.rig.speed_loop.setpoint_cps(),
                    motor: self.motor,
                    encoder: self.plant.encoder_count(),
                });
            }
        }
    }

    /// Physics up to `t_ns`, reporting index edges on the way.
    fn advance_to(&mut self, t_ns: u64) {
        while self.now_ns < t_ns {
            let step_ns = (t_ns - self.now_ns).min(MAX_STEP_NS);
            let crossing = self.plant.step(step_ns as f64 * 1e-9);
            if let Some(c) = crossing {
                let edge_ns = self.now_ns as f64 + c.fraction * step_ns as f64;
                let t_us = self.timer_us(edge_ns as u64);
                self.rig.index_edge(t_us, c.encoder, c.level, false);
                #[cfg(any(test, feature = "sim"))]
                self.truth.index_edges.push((edge_ns, c.encoder, c.level));
            }
            self.now_ns += step_ns;
        }
    }

    /// The gyro's sample instant: it latches, DRDY rises, the capture ISR reads.
    fn gyro_sample(&mut self) {
        let rates = self.plant.gyro_rates_dps();
        let temp = self.plant.temp_raw;
        self.gyro.spi_mut().latch(rates, temp);
        #[cfg(any(test, feature = "sim"))]
        self.truth.samples.push((self.now_ns, self.plant.encoder_count(), self.gyro.spi_mut().outputs()));
        let drdy = self.gyro.spi_mut().drdy();
        let mut rising = drdy && !self.drdy;
        if rising && self.missed_drdy_edges > 0 {
            self.missed_drdy_edges -= 1;
            rising = false;
        }
        if rising {
            let t_us = self.timer_us(self.now_ns);
            let encoder = self.plant.encoder_count();
            let read = self.gyro.read();
            // A trip here cuts the bridge now, as the firmware's data-ready interrupt does.
            if let Some(off) = self.rig.data_ready(t_us, encoder, read) {
                self.motor = off;
                self.plant.set_drive(off);
            }
        }
        self.drdy = self.gyro.spi_mut().drdy();
    }

    fn control_tick(&mut self, host: &mut impl HostLink) {
        let t_us = self.timer_us(self.now_ns);
        // The USB task's poll of the link, as the rtic app runs it every period.
        self.rig.usb_task_ran(t_us);
        let mut rx = [0u8; 64];
        loop {
            let n = host.receive(&mut rx);
            if n == 0 {
                break;
            }
            self.rig.receive(t_us, &rx[..n], &mut self.gyro);
        }
        let encoder = self.plant.encoder_count();
        let drdy_high = self.gyro.spi_mut().drdy();
        self.motor = self.rig.control_tick(t_us, encoder);
        self.plant.set_drive(self.motor);
        if self.rig.needs_drdy_release(drdy_high) {
            let _ = self.gyro.read();
            self.drdy = self.gyro.spi_mut().drdy();
        }
        let mut budget = self.link_bytes_per_tick;
        let mut tx = [0u8; 256];
        while budget > 0 {
            let want = budget.min(tx.len());
            let n = self.rig.link().tx().pop_into(&mut tx[..want]);
            if n == 0 {
                break;
            }
            host.send(&tx[..n]);
            budget -= n;
        }
    }
}

/// An in-memory host link for tests and the pty bridge.
#[cfg(any(test, feature = "sim"))]
#[derive(Debug, Default)]
pub struct Wire {
    /// Bytes from the host, not yet read by the rig.
    pub to_rig: std::collections::VecDeque<u8>,
    /// Bytes the rig has sent.
    pub from_rig: Vec<u8>,
}

#[cfg(any(test, feature = "sim"))]
impl Wire {
    /// Queues one command frame from the host.
    pub fn command(&mut self, seq: u16, command: &protocol::Command) {
        let mut frame = [0u8; protocol::MAX_FRAME_LEN];
        let n = protocol::encode_frame(seq, command, &mut frame).expect("command fits a frame");
        self.to_rig.extend(&frame[..n]);
    }
}

#[cfg(any(test, feature = "sim"))]
impl HostLink for Wire {
    fn receive(&mut self, buf: &mut [u8]) -> usize {
        let n = buf.len().min(self.to_rig.len());
        for (dst, src) in buf.iter_mut().zip(self.to_rig.drain(..n)) {
            *dst = src;
        }
        n
    }

    fn send(&mut self, bytes: &[u8]) {
        self.from_rig.extend_from_slice(bytes);
    }
}
