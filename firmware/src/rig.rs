//! The rig's portable core: every interrupt of the firmware hands its data to one method here,
//! and everything the rig says goes out through the [`Link`]. No hardware, no clock reads: time
//! arrives as `t_us` (TIM5, 1 MHz, wrapping) with each event.

use crate::index::IndexTracker;
use crate::l3g4200d::{self, L3g4200d, Measurement};
use crate::link::Link;
use crate::pwm::{MotorCommand, PwmModulator};
use crate::speed_loop::{Gains, SpeedLoop, LOOP_HZ};
use crate::supervisor::{Supervisor, NOMINAL_PERIOD_US};
use crate::{FIRMWARE_VERSION, GEAR_RATIO};
use embedded_hal::spi::SpiDevice;
use protocol::{
    motor_faults, sample_status, Counters, Fault, FaultReport, GyroConfig, Hello, MotorStatus, RigMsg, RunStopped,
    Sample, Temperature, ENCODER_COUNTS_PER_REV, PROTOCOL_VERSION, TIMESTAMP_HZ,
};

/// No host frame for this long during a run stops the motor (protocol: [`protocol::Command::Heartbeat`]).
pub use protocol::timing::HOST_LINK_TIMEOUT_US;

/// No data-ready for this long is a silent gyro: five periods at the slowest ODR (100 Hz).
pub const GYRO_SILENT_US: u32 = 50_000;

/// Consecutive failed or stale reads (data-ready seen, STATUS_REG ZYXDA clear) that make a dead
/// bus: a MISO stuck low reads all zeros, so a dead bus shows up as stale data, not as an error;
/// a MISO stuck high reads all 0xFF ([`crate::l3g4200d::Measurement::bus_stuck_high`]), counted
/// as a failed read. Eight is 10 ms at 800 Hz (80 ms at 100 Hz): engineering judgement, long
/// enough that a single glitched transfer never trips a run, short against the table's
/// dynamics (it turns ≤ 3.6° in 10 ms at 360 °/s).
pub const GYRO_BAD_READS: u8 = 8;

/// A run ends once the ramp is at zero and the table has moved at most one count per period
/// (≤ 1000 cps, 1.1 °/s) for this many periods (50 ms).
pub const STOPPED_PERIODS: u16 = (LOOP_HZ / 20) as u16;

/// The watchdog is fed only while the lowest-priority task (USB) still runs: it must have run
/// within this long, µs. It runs every loop period (the control task pends it), so 20 ms is 20
/// missed periods: a hung USB task, not a busy one.
pub const TASK_ALIVE_US: i32 = 20_000;

/// Measured loop periods outside this range, µs, are not believed (the nominal one is used).
const MIN_PERIOD_US: i32 = 200;
const MAX_PERIOD_US: i32 = 10_000;

/// Loop periods between [`MotorStatus`] frames ([`protocol::timing::MOTOR_STATUS_HZ`]).
pub const MOTOR_STATUS_PERIODS: u32 = LOOP_HZ / protocol::timing::MOTOR_STATUS_HZ;

/// Loop periods between [`Counters`] and [`Temperature`] frames ([`protocol::timing::COUNTERS_HZ`]).
pub const COUNTERS_PERIODS: u32 = LOOP_HZ / protocol::timing::COUNTERS_HZ;

/// Microseconds from `since` to `now` on the wrapping TIM5 clock, negative when `since` is later
/// (an event stamped by a preempting task after `now` was read). Valid for spans under 35 min.
pub fn elapsed_us(now: u32, since: u32) -> i32 {
    now.wrapping_sub(since) as i32
}

/// What this firmware says of itself in [`Hello`], with `gyro` the settings in force: the one
/// place for it (the host's batch simulator announces the same).
pub fn hello(gyro: GyroConfig) -> Hello {
    Hello {
        protocol_version: PROTOCOL_VERSION,
        firmware: FIRMWARE_VERSION,
        gyro,
        encoder_counts_per_rev: ENCODER_COUNTS_PER_REV,
        gear_ratio: GEAR_RATIO,
        timestamp_hz: TIMESTAMP_HZ,
    }
}

/// The gyro as the command handler sees it: something that can be (re)configured.
pub trait GyroControl {
    /// Checks the gyro is there and applies `config`.
    fn apply(&mut self, config: GyroConfig) -> Result<(), Fault>;
}

impl<SPI: SpiDevice> GyroControl for L3g4200d<SPI> {
    fn apply(&mut self, config: GyroConfig) -> Result<(), Fault> {
        self.init(config).map_err(|e| match e {
            l3g4200d::Error::WrongDevice(who_am_i) => Fault::GyroAbsent { who_am_i },
            l3g4200d::Error::Spi(_) => Fault::GyroSpi,
        })
    }
}

/// Run state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Run {
    /// Motor off.
    Idle,
    /// Ramping to, or holding, the commanded speed.
    Running { tag: u8 },
    /// Ramping down after a Stop.
    Stopping { tag: u8 },
    /// A static run: motor off, samples framed by RunStarted/RunStopped (a Start at 0 m°/s).
    Static { tag: u8 },
}

impl Run {
    pub(crate) fn tag(self) -> Option<u8> {
        match self {
            Run::Idle => None,
            Run::Running { tag } | Run::Stopping { tag } | Run::Static { tag } => Some(tag),
        }
    }
}

/// The portable core of the firmware.
pub struct Rig {
    pub(crate) link: Link,
    pub(crate) gyro_config: GyroConfig,
    /// A gyro fault in force: refuses runs until a ConfigureGyro succeeds (or samples resume,
    /// for [`Fault::GyroSilent`]).
    pub(crate) gyro_fault: Option<Fault>,
    /// Why the MCU last restarted, if that is a fault ([`Fault::WatchdogReset`]): repeated after
    /// every Hello, so a host that connects later still learns it.
    pub(crate) reset_fault: Option<Fault>,
    pub(crate) run: Run,
    pub(crate) speed_loop: SpeedLoop,
    pub(crate) supervisor: Supervisor,
    modulator: PwmModulator,
    pub(crate) motor_faults: u8,
    pub(crate) last_host_us: u32,
    index: IndexTracker,
    applied: MotorCommand,
    last_encoder: Option<u32>,
    /// Length of the period that just ended, s, measured on TIM5 (nominally 1 / LOOP_HZ).
    period_s: f32,
    last_tick_us: Option<u32>,
    last_usb_us: u32,
    status_window_encoder: u32,
    periods: u32,
    stopped_periods: u16,
    pub(crate) last_sample_us: u32,
    bad_reads: u8,
    samples_read: u32,
    gyro_overruns: u32,
    spi_errors: u32,
    temperature: Option<Temperature>,
}

impl Rig {
    /// A rig at rest, before power-up reporting.
    pub const fn new(gyro_config: GyroConfig) -> Self {
        Self {
            link: Link::new(),
            gyro_config,
            gyro_fault: None,
            reset_fault: None,
            run: Run::Idle,
            speed_loop: SpeedLoop::new(Gains::RE30_GP32),
            supervisor: Supervisor::new(),
            modulator: PwmModulator::new(),
            motor_faults: 0,
            last_host_us: 0,
            index: IndexTracker::new(),
            applied: MotorCommand::OFF,
            last_encoder: None,
            period_s: 1.0 / LOOP_HZ as f32,
            last_tick_us: None,
            last_usb_us: 0,
            status_window_encoder: 0,
            periods: 0,
            stopped_periods: 0,
            last_sample_us: 0,
            bad_reads: 0,
            samples_read: 0,
            gyro_overruns: 0,
            spi_errors: 0,
            temperature: None,
        }
    }

    /// Power-up report: Hello, then the gyro probe's fault if any, then a watchdog reset if
    /// that is why the MCU restarted.
    pub fn power_up(&mut self, t_us: u32, gyro_probe: Result<(), Fault>, watchdog_reset: bool) {
        self.last_host_us = t_us;
        self.last_sample_us = t_us;
        self.last_usb_us = t_us;
        self.send_hello();
        if let Err(fault) = gyro_probe {
            self.gyro_fault = Some(fault);
            self.report(t_us, fault);
        }
        if watchdog_reset {
            self.reset_fault = Some(Fault::WatchdogReset);
            self.report(t_us, Fault::WatchdogReset);
        }
    }

    /// One speed-loop period ([`LOOP_HZ`]): `encoder` is the TIM2 count now. Returns what the
    /// bridge must do until the next period.
    pub fn control_tick(&mut self, t_us: u32, encoder: u32) -> MotorCommand {
        let delta = encoder.wrapping_sub(self.last_encoder.unwrap_or(encoder)) as i32;
        if self.last_encoder.is_none() {
            self.status_window_encoder = encoder;
        }
        self.last_encoder = Some(encoder);
        // Δcount/Δt: the period as measured, not as assumed; an implausible one (a stalled or
        // restarted timer) falls back to the nominal period.
        let period_us = match self.last_tick_us.map(|last| elapsed_us(t_us, last)) {
            Some(d) if (MIN_PERIOD_US..=MAX_PERIOD_US).contains(&d) => d as u32,
            _ => NOMINAL_PERIOD_US,
        };
        self.period_s = period_us as f32 * 1e-6;
        self.last_tick_us = Some(t_us);

        // Signed differences: a higher-priority task (data-ready, USB) may stamp its event a tick
        // after the time this tick was given, which unsigned would make ≈ 4 295 s of silence.
        if self.gyro_fault.is_none() && elapsed_us(t_us, self.last_sample_us) > GYRO_SILENT_US as i32 {
            self.gyro_failed(t_us, Fault::GyroSilent);
        }
        if self.run.tag().is_some() {
            if elapsed_us(t_us, self.last_host_us) > HOST_LINK_TIMEOUT_US as i32 {
                self.trip(t_us, Fault::HostLinkLost);
            } else if let Some(fault) = self.supervisor.check(self.applied.duty(), delta, period_us) {
                self.trip(t_us, fault);
            }
        }
        self.applied = match self.run {
            Run::Idle | Run::Static { .. } => MotorCommand::OFF,
            Run::Running { .. } => self.drive(delta),
            Run::Stopping { tag } => {
                let cmd = self.drive(delta);
                self.stopped_periods = match (self.speed_loop.at_target(), delta.abs() <= 1) {
                    (true, true) => self.stopped_periods + 1,
                    _ => 0,
                };
                if self.stopped_periods >= STOPPED_PERIODS {
                    self.motor_off();
                    self.run = Run::Idle;
                    self.link.send(&RigMsg::RunStopped(RunStopped { t_us, run_tag: tag }));
                    MotorCommand::OFF
                } else {
                    cmd
                }
            }
        };

        self.periods = self.periods.wrapping_add(1);
        if self.periods % MOTOR_STATUS_PERIODS == 0 {
            self.send_motor_status(t_us, encoder);
        }
        if self.periods % COUNTERS_PERIODS == 0 {
            if let Some(t) = self.temperature.take() {
                self.link.send(&RigMsg::Temperature(t));
            }
            let counters = self.counters(t_us);
            self.link.send(&RigMsg::Counters(counters));
        }
        self.applied
    }

    /// A data-ready edge: `t_us` and `encoder` as latched by TIM5 and TIM2 input capture, and
    /// the burst read that followed. Returns `Some(MotorCommand::OFF)` when this read ended a
    /// run (a dead bus trips it): the platform must apply it at once, in the data-ready
    /// interrupt, rather than at the next control tick up to a loop period later.
    pub fn data_ready<E>(&mut self, t_us: u32, encoder: u32, read: Result<Measurement, E>) -> Option<MotorCommand> {
        let running = self.run.tag().is_some();
        self.last_sample_us = t_us;
        if self.gyro_fault == Some(Fault::GyroSilent) {
            self.gyro_fault = None;
        }
        let fresh = match read {
            // A MISO stuck high reads 0xFF everywhere, which passes for a fresh sample with
            // every overrun bit set: counted as a failed read, never streamed as a sample.
            Ok(m) if m.bus_stuck_high() => {
                self.spi_errors = self.spi_errors.wrapping_add(1);
                false
            }
            Ok(m) => {
                self.samples_read = self.samples_read.wrapping_add(1);
                let mut status = 0;
                if m.overrun() {
                    status |= sample_status::OVERRUN;
                    self.gyro_overruns = self.gyro_overruns.wrapping_add(1);
                }
                if !m.fresh() {
                    status |= sample_status::STALE;
                }
                self.temperature = Some(Temperature { t_us, raw: m.temp_raw });
                self.link.send(&RigMsg::Sample(Sample { t_us, encoder, rate_counts: m.rate_counts, status }));
                m.fresh()
            }
            Err(_) => {
                self.spi_errors = self.spi_errors.wrapping_add(1);
                false
            }
        };
        self.bad_reads = if fresh { 0 } else { self.bad_reads.saturating_add(1) };
        if self.bad_reads >= GYRO_BAD_READS && self.gyro_fault.is_none() {
            self.gyro_failed(t_us, Fault::GyroSpi);
        }
        (running && self.run.tag().is_none()).then_some(MotorCommand::OFF)
    }

    /// An index edge: time and count latched by capture, level read after it, and whether the
    /// capture register was overwritten before it was read.
    pub fn index_edge(&mut self, t_us: u32, encoder: u32, level_after: bool, overcaptured: bool) {
        if let Some(edge) = self.index.capture(t_us, encoder, level_after, overcaptured) {
            self.link.send(&RigMsg::Index(edge));
        }
    }

    /// Bytes from the host: each command is executed and acknowledged.
    pub fn receive(&mut self, t_us: u32, bytes: &[u8], gyro: &mut impl GyroControl) {
        // Byte by byte: a byte completes at most one frame, and executing it sends through the
        // same link that decodes.
        for byte in bytes {
            let mut received = None;
            self.link.receive(core::slice::from_ref(byte), |r| received = Some(r));
            if let Some(r) = received {
                self.last_host_us = t_us;
                self.execute(t_us, r, gyro);
            }
        }
    }

    /// The link, for the transport to drain.
    pub fn link(&mut self) -> &mut Link {
        &mut self.link
    }

    /// Health counters now.
    pub fn counters(&self, t_us: u32) -> Counters {
        Counters {
            t_us,
            frames_sent: self.link.frames_sent(),
            queue_drops: self.link.queue_drops(),
            samples_read: self.samples_read,
            gyro_overruns: self.gyro_overruns,
            spi_errors: self.spi_errors,
            rx_errors: self.link.rx_errors(),
        }
    }

    /// Tag of the run in progress.
    pub fn run_tag(&self) -> Option<u8> {
        self.run.tag()
    }

    /// The speed loop: where it is heading and how fast it ramps there. A simulated drive that
    /// follows it (the host's `SimRig`) turns the table the way this firmware commands it.
    pub fn speed_loop(&self) -> &SpeedLoop {
        &self.speed_loop
    }

    /// [`motor_faults`] bits since the last start.
    pub fn motor_faults(&self) -> u8 {
        self.motor_faults
    }

    /// Gyro fault in force.
    pub fn gyro_fault(&self) -> Option<Fault> {
        self.gyro_fault
    }

    /// Gyro settings in force.
    pub fn gyro_config(&self) -> GyroConfig {
        self.gyro_config
    }

    /// The USB (lowest-priority) task ran at `t_us`.
    pub fn usb_task_ran(&mut self, t_us: u32) {
        self.last_usb_us = t_us;
    }

    /// Whether the control task may feed the watchdog at `t_us`: only while the USB task still
    /// runs ([`TASK_ALIVE_US`]). Fed unconditionally from the 1 kHz interrupt, the watchdog
    /// would never catch a hung USB task (a host link that silently died with the motor on).
    pub fn watchdog_may_feed(&self, t_us: u32) -> bool {
        elapsed_us(t_us, self.last_usb_us) <= TASK_ALIVE_US
    }

    /// Whether the platform must read (and discard) the gyro's outputs now: the gyro is silent
    /// while its DRDY line is high, so a data-ready edge was missed (the capture was not armed,
    /// or was overrun) and the line stays high until the outputs are read; after the read, the
    /// next sample raises an edge and its data-ready clears the fault.
    pub fn needs_drdy_release(&self, drdy_high: bool) -> bool {
        drdy_high && self.gyro_fault == Some(Fault::GyroSilent)
    }

    /// Index edges rejected as chatter ([`crate::index::INDEX_CHATTER_COUNTS`]).
    pub fn index_chatter(&self) -> u32 {
        self.index.chatter()
    }

    /// Index edges seen and known lost.
    pub fn index_edges(&self) -> (u32, u32) {
        (self.index.edges(), self.index.missed())
    }

    fn drive(&mut self, delta: i32) -> MotorCommand {
        let duty = self.speed_loop.update_over(delta, self.period_s);
        self.modulator.drive(duty)
    }

    pub(crate) fn send_hello(&mut self) {
        self.link.send(&RigMsg::Hello(hello(self.gyro_config)));
    }

    fn send_motor_status(&mut self, t_us: u32, encoder: u32) {
        let travelled = encoder.wrapping_sub(self.status_window_encoder) as i32;
        self.status_window_encoder = encoder;
        self.link.send(&RigMsg::Motor(MotorStatus {
            t_us,
            speed_cps: travelled * protocol::timing::MOTOR_STATUS_HZ as i32,
            setpoint_cps: self.speed_loop.setpoint_cps(),
            duty_permille: (self.applied.duty() * 1000.0) as i16,
            faults: self.motor_faults,
            run_tag: self.run.tag().unwrap_or(protocol::run_tag::IDLE),
        }));
    }

    pub(crate) fn report(&mut self, t_us: u32, fault: Fault) {
        self.link.send(&RigMsg::Fault(FaultReport { t_us, fault }));
    }

    fn gyro_failed(&mut self, t_us: u32, fault: Fault) {
        self.gyro_fault = Some(fault);
        if self.run.tag().is_some() {
            self.trip(t_us, fault);
        } else {
            self.report(t_us, fault);
        }
    }

    /// Motor off now, fault reported, run ended.
    fn trip(&mut self, t_us: u32, fault: Fault) {
        self.motor_off();
        self.motor_faults |= match fault {
            Fault::Stall => motor_faults::STALL,
            Fault::OverSpeed => motor_faults::OVER_SPEED,
            Fault::HostLinkLost => motor_faults::HOST_LINK_LOST,
            _ => motor_faults::INTERLOCK,
        };
        self.report(t_us, fault);
        if let Some(run_tag) = self.run.tag() {
            self.link.send(&RigMsg::RunStopped(RunStopped { t_us, run_tag }));
        }
        self.run = Run::Idle;
    }

    pub(crate) fn motor_off(&mut self) {
        self.speed_loop.reset();
        self.supervisor.reset();
        self.modulator.reset();
        self.stopped_periods = 0;
        self.applied = MotorCommand::OFF;
    }
}
