//! The simulation engine shared by the batch generator and the live emulator: one powered-up
//! rig with one sensor.
//!
//! The batch generator ([`super::simulate_to`]) runs scripted runs and emits every frame itself,
//! in time order, fast. The live emulator ([`super::SimRig`]) uses only the physics here (the
//! tables' motion, the index edges, the gyro's samples and die temperature) and hands them to the
//! firmware's own core, which decides and says everything ([`Session::mount`] and the methods
//! after it).

use super::effects::Effects;
use super::filter::{Butterworth, Filter3, OVERSAMPLING};
use super::motion::{BaseState, EdgeCrossing, Encoder, IndexPlate, Motor};
use super::sensor::{quantise, SenseChain, SensorTruth, Thermal};
use super::stream::FrameWriter;
use super::thermal::{ChamberStep, TemperatureDependence, ThermalTruth};
use super::truth::{RunTruth, Truth};
use super::SimConfig;
use crate::geometry::{omega2, Pose};
use protocol::{
    timing, units, Counters, Fault, FaultReport, GyroConfig, Hello, IndexEdge, MotorStatus, RigMsg, RunStarted,
    RunStopped, Sample, Temperature, ENCODER_COUNTS_PER_REV,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, StandardNormal};
use std::io::{self, Write};

/// Firmware version the simulator announces: the version of the firmware it emulates.
pub use firmware::FIRMWARE_VERSION;

/// Gear ratio announced in `Hello`: the protocol's (the prototype's 1:1 magnetic gears).
use protocol::GEAR_RATIO;

/// Spread of the gyro's internal clock against the rig timer, ppm, 1 σ (assumed: the L3G4200D
/// runs its ODR from an internal RC-trimmed oscillator; the datasheet gives no tolerance).
pub const ODR_ERROR_SIGMA_PPM: f64 = 300.0;

/// Die temperature at power-up, °C (assumed: lab ambient).
pub const AMBIENT_C: f64 = 25.0;

/// Message periods, s: the protocol's rates (`protocol::timing`; `Temperature` with `Counters`).
const MOTOR_PERIOD_S: f64 = 1.0 / timing::MOTOR_STATUS_HZ as f64;
const TEMPERATURE_PERIOD_S: f64 = 1.0 / timing::COUNTERS_HZ as f64;
const COUNTERS_PERIOD_S: f64 = 1.0 / timing::COUNTERS_HZ as f64;

/// Base-table speed at 100 % PWM duty, °/s (assumed: RE 30 at 24 V through the drive train;
/// only used to fill `MotorStatus::duty_permille` plausibly).
const FULL_DUTY_DPS: f64 = 1080.0;
/// Duty needed to overcome bearing and gear friction, per mille (assumed).
const FRICTION_DUTY_PERMILLE: f64 = 20.0;

/// Die-temperature change after which the sensing chain is recomputed, °C (see `next_sample`).
const CHAIN_STEP_C: f64 = 1e-3;

/// Independent random streams of one seed: the sensor is the same whatever is simulated.
#[derive(Clone, Copy)]
enum Stream {
    Sensor = 0,
    Rig = 1,
    Noise = 2,
    Jitter = 3,
    RandomWalk = 4,
    Effects = 5,
    CaptureLevel = 6,
}

/// The stream [`crate::sim::Effects::drawn`] draws a seed's rig from (`host simulate
/// --drawn-rig`): its own, so the sensor, noise and rig of a seed are the same with and without it.
pub fn effects_rng(seed: u64) -> ChaCha8Rng {
    rng(seed, Stream::Effects)
}

fn rng(seed: u64, stream: Stream) -> ChaCha8Rng {
    salted_rng(seed, stream, 0)
}

/// Streams per chamber setpoint: the setpoints of one programme share the sensor and the rig
/// but not their noise (`salt` is the setpoint's index; 0 is a session without a chamber).
const STREAMS_PER_SALT: u64 = 8;

fn salted_rng(seed: u64, stream: Stream, salt: u32) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(stream as u64 + STREAMS_PER_SALT * u64::from(salt));
    r
}

/// The low-pass cut-off `gyro` configures, Hz (datasheet Table 21).
fn configured_cutoff_hz(gyro: GyroConfig) -> f64 {
    f64::from(gyro.bandwidth.cutoff_dhz(gyro.odr)) / 10.0
}

/// The salt of a capture taken on its own ([`crate::sim::effects::CaptureLevel`]): FNV-1a over
/// its runs (pose, rate, length), above the chamber setpoints' salts (their indices, < 256), so
/// that captures of one sensor with other runs draw other noise and another level.
fn capture_salt(runs: &[super::RunSpec]) -> u32 {
    let mut h: u32 = 0x811c_9dc5;
    for r in runs {
        let pose = [u8::from(r.pose == Pose::Two)];
        for b in pose.into_iter().chain(r.rate_dps.to_bits().to_le_bytes()).chain(r.duration_s.to_bits().to_le_bytes())
        {
            h = (h ^ u32::from(b)).wrapping_mul(0x0100_0193);
        }
    }
    ((h >> 8) | 1) << 8
}

/// The run in progress.
struct ActiveRun {
    pose: Pose,
    run_tag: u8,
    rate_dps: f64,
    start_s: f64,
    chain: SenseChain,
    /// Die temperature the chain's sensitivities and directions are for, °C (temperature
    /// dependence only).
    chain_temp_c: f64,
    lowpass: Option<Filter3>,
    /// Index of the next gyro data-ready on the session-wide lattice.
    next_k: u64,
    /// Everything up to this time has been emitted.
    done_s: f64,
    /// Base-table state at `done_s` (reused by the sample at that data-ready).
    base_done: BaseState,
    theta2_done_rad: f64,
    n_motor: u64,
    n_temperature: u64,
    n_counters: u64,
    samples: u64,
    edges: u64,
}

/// The index edges of one stretch of time and the tables' state at its end.
struct Interval {
    edges: Vec<EdgeCrossing>,
    base: BaseState,
    theta2_rad: f64,
}

/// A run that has ended, for the truth.
#[derive(Debug, Clone, Copy)]
pub struct FinishedRun {
    /// The pose the gyro was in.
    pub pose: Pose,
    /// Base-table rate commanded, °/s, signed.
    pub rate_dps: f64,
    /// `RunStarted`, s.
    pub start_s: f64,
    /// `RunStopped`, s.
    pub end_s: f64,
    /// Gyro samples in the run.
    pub samples: u64,
    /// Index edges in the run.
    pub index_edges: u64,
    /// Ended by a fault.
    pub faulted: bool,
}

/// One powered-up simulated rig.
pub struct Session {
    seed: u64,
    gyro: GyroConfig,
    effects: Effects,
    noise_density: f64,
    spin_up_s: f64,
    plate_width_deg: f64,
    start_t_us: u32,
    sensor: SensorTruth,
    thermal: Thermal,
    motor: Motor,
    encoder: Encoder,
    plate: IndexPlate,
    gear_ratio: f64,
    theta2_start_rad: f64,
    odr_error_ppm: f64,
    /// Time of data-ready 0, s.
    clock_phase_s: f64,
    period_s: f64,
    noise_counts: [f64; 3],
    lowpass_coef: Option<Butterworth>,
    noise_rng: ChaCha8Rng,
    /// The offset's random walk, °/s per axis, and when it was last advanced, s.
    walk_dps: [f64; 3],
    walk_t_s: f64,
    walk_rng: ChaCha8Rng,
    /// This capture's own zero-rate level, °/s per axis (0 unless it is taken on its own).
    level_dps: [f64; 3],
    jitter_rng: ChaCha8Rng,
    jitter: Normal<f64>,
    samples_read: u32,
    run: Option<ActiveRun>,
    runs: Vec<RunTruth>,
    scratch: Vec<EdgeCrossing>,
}

impl Session {
    /// A rig at power-up (t = 0); the caller drives the runs (`cfg.runs` is not read).
    pub fn new(cfg: &SimConfig) -> Self {
        let sensor = SensorTruth::draw(&mut rng(cfg.seed, Stream::Sensor));
        let mut rig = rng(cfg.seed, Stream::Rig);
        let z: f64 = StandardNormal.sample(&mut rig);
        let odr_error_ppm = ODR_ERROR_SIGMA_PPM * z;
        let clock_phase_unit: f64 = rig.random();
        let theta2_start_rad = rig.random_range(0.0..std::f64::consts::TAU);
        // OUT_TEMP offset: arbitrary per part (datasheet Table 5 specifies only the slope).
        let out_temp_at_0c = f64::from(rig.random_range(20i32..60));
        let mut salt = cfg.chamber.map_or(0, |c| c.index);
        let mut level_dps = [0.0; 3];
        if let Some(c) = cfg.effects.capture_level {
            salt += capture_salt(&cfg.runs);
            let mut r = salted_rng(cfg.seed, Stream::CaptureLevel, salt);
            level_dps = std::array::from_fn(|_| c.sigma_dps * Distribution::<f64>::sample(&StandardNormal, &mut r));
        }
        let mut s = Self {
            seed: cfg.seed,
            gyro: cfg.gyro,
            effects: cfg.effects,
            noise_density: cfg.noise_dps_per_sqrt_hz,
            spin_up_s: cfg.spin_up_s,
            plate_width_deg: cfg.index_plate_width_deg,
            start_t_us: cfg.start_t_us,
            sensor,
            thermal: Thermal {
                ambient_c: AMBIENT_C,
                out_temp_at_0c,
                drift: cfg.effects.offset_drift,
                dependence: cfg.effects.temperature_dependence,
                chamber: cfg.chamber,
            },
            motor: Motor::new(cfg.effects.speed_ripple),
            encoder: Encoder {
                counts_per_rev: ENCODER_COUNTS_PER_REV,
                start_counts: cfg.start_encoder,
                errors: [cfg.effects.encoder_eccentricity, cfg.effects.encoder_ellipticity],
            },
            plate: IndexPlate {
                centre_rad: cfg.effects.index_offset_rad(),
                width_rad: cfg.index_plate_width_deg.to_radians(),
            },
            gear_ratio: cfg.effects.true_gear_ratio(f64::from(GEAR_RATIO.num) / f64::from(GEAR_RATIO.den)),
            theta2_start_rad,
            odr_error_ppm,
            clock_phase_s: 0.0,
            period_s: 0.0,
            noise_counts: [0.0; 3],
            lowpass_coef: None,
            noise_rng: salted_rng(cfg.seed, Stream::Noise, salt),
            walk_dps: [0.0; 3],
            walk_t_s: 0.0,
            walk_rng: salted_rng(cfg.seed, Stream::RandomWalk, salt),
            level_dps,
            jitter_rng: salted_rng(cfg.seed, Stream::Jitter, salt),
            jitter: Normal::new(0.0, cfg.effects.timestamp_jitter_us()).expect("finite σ"),
            samples_read: 0,
            run: None,
            runs: Vec::new(),
            scratch: Vec::with_capacity(8),
        };
        s.configure(cfg.gyro);
        s.clock_phase_s = clock_phase_unit * s.period_s;
        s
    }

    /// Applies gyro settings (only between runs).
    pub fn configure(&mut self, gyro: GyroConfig) {
        debug_assert!(self.run.is_none());
        self.gyro = gyro;
        let odr_hz = f64::from(gyro.odr.hz()) * (1.0 + self.odr_error_ppm * 1e-6);
        self.period_s = 1.0 / odr_hz;
        let k = self.sensor.k_counts_per_dps(gyro.full_scale);
        // White noise of density ρ sampled at the ODR: σ = ρ·√(ODR/2) (Nyquist bandwidth).
        let sigma_dps = self.noise_density * (f64::from(gyro.odr.hz()) / 2.0).sqrt();
        self.noise_counts = k.map(|k| k * sigma_dps);
        self.lowpass_coef = self
            .effects
            .lowpass(configured_cutoff_hz(gyro))
            .map(|(order, fc_hz)| Butterworth::lowpass(order, fc_hz, odr_hz * f64::from(OVERSAMPLING)));
    }

    /// The `Hello` message: the firmware's own, for the gyro settings in force.
    pub fn hello(&self) -> Hello {
        firmware::rig::hello(self.gyro)
    }

    /// Timer value at `t_s` (the timer counts whole µs of the rig's own clock).
    pub fn timer_us(&self, t_s: f64) -> u32 {
        (i64::from(self.start_t_us) + (t_s * 1e6 * self.effects.rig_clock_rate()).floor() as i64) as u32
    }

    fn data_ready_s(&self, k: u64) -> f64 {
        self.clock_phase_s + k as f64 * self.period_s
    }

    fn theta2_rad(&self, theta1_deg: f64) -> f64 {
        let error = self.effects.gear_transmission.map_or(0.0, |g| g.error_rad(theta1_deg.to_radians()).0);
        self.gear_ratio * theta1_deg.to_radians() + self.theta2_start_rad + error
    }

    /// θ2' for a base state, °/s (the transmission error's derivative included).
    fn theta2_rate_dps(&self, st: &BaseState) -> f64 {
        let slope = self.effects.gear_transmission.map_or(0.0, |g| g.error_rad(st.theta1_deg.to_radians()).1);
        (self.gear_ratio + slope) * st.theta1_rate_dps
    }

    /// Starts a run at `t_s`: `RunStarted`, then the motor ramps to `rate_dps` (signed).
    pub fn start_run<W: Write>(
        &mut self,
        t_s: f64,
        pose: Pose,
        run_tag: u8,
        rate_dps: f64,
        w: &mut FrameWriter<W>,
    ) -> io::Result<()> {
        assert!(self.run.is_none(), "a run is already in progress");
        w.send(&RigMsg::RunStarted(RunStarted {
            t_us: self.timer_us(t_s),
            run_tag,
            rate_mdps: units::mdps_from_dps(rate_dps),
            direction: units::direction_of(rate_dps),
            gyro: self.gyro,
        }))?;
        self.motor.set_target(t_s, rate_dps, self.spin_up_s);
        self.run = Some(self.new_run(t_s, pose, run_tag, rate_dps));
        Ok(())
    }

    /// The gyro in `pose` from `t_s` on: its sensing chain, its filter settled, the next
    /// data-ready after `t_s`.
    fn new_run(&self, t_s: f64, pose: Pose, run_tag: u8, rate_dps: f64) -> ActiveRun {
        let next_k = ((t_s - self.clock_phase_s) / self.period_s).floor().max(0.0) as u64 + 1;
        let chain_temp_c = self.thermal.temperature_c(t_s);
        let chain = self.chain_at(pose, chain_temp_c);
        let base_done = self.motor.state(t_s);
        let mut run = ActiveRun {
            pose,
            run_tag,
            rate_dps,
            start_s: t_s,
            chain,
            chain_temp_c,
            lowpass: self.lowpass_coef.map(Filter3::new),
            next_k,
            done_s: t_s,
            base_done,
            theta2_done_rad: self.theta2_rad(base_done.theta1_deg),
            n_motor: 0,
            n_temperature: 0,
            n_counters: 0,
            samples: 0,
            edges: 0,
        };
        if let Some(f) = run.lowpass.as_mut() {
            // The gyro has been filtering since power-up: start from the steady state of the
            // input at the first internal tick.
            let t0 = self.data_ready_s(next_k - 1) - self.effects.pure_delay_s();
            f.settle(self.sensed_counts(&run.chain, t0));
        }
        run
    }

    /// The sensing chain of the gyro in `pose` at die temperature `temp_c`.
    fn chain_at(&self, pose: Pose, temp_c: f64) -> SenseChain {
        let mount = self.effects.pose_fixture.map_or_else(|| pose.rotation(), |f| f.rotation(pose));
        let sensor = match &self.thermal.dependence {
            Some(dep) => self.sensor.at_temperature(dep, temp_c),
            None => self.sensor.clone(),
        };
        SenseChain::new(&sensor, &mount, self.gyro.full_scale, &self.effects)
    }

    /// Emits everything up to `t_s` (a run's frames up to its last data-ready ≤ `t_s`).
    pub fn advance_to<W: Write>(&mut self, t_s: f64, w: &mut FrameWriter<W>) -> io::Result<()> {
        while let Some(run) = &self.run {
            let t_k = self.data_ready_s(run.next_k);
            if t_k > t_s {
                break;
            }
            self.emit_interval(t_k, w)?;
            self.emit_sample(w)?;
        }
        Ok(())
    }

    /// Ends the run at `t_s` (`RunStopped`, after an optional fault); the motor ramps down.
    pub fn stop_run<W: Write>(&mut self, t_s: f64, fault: Option<Fault>, w: &mut FrameWriter<W>) -> io::Result<()> {
        self.advance_to(t_s, w)?;
        if self.run.is_none() {
            return Ok(());
        }
        self.emit_interval(t_s, w)?;
        if let Some(fault) = fault {
            w.send(&RigMsg::Fault(FaultReport { t_us: self.timer_us(t_s), fault }))?;
        }
        let run = self.run.take().expect("checked above");
        w.send(&RigMsg::RunStopped(RunStopped { t_us: self.timer_us(t_s), run_tag: run.run_tag }))?;
        self.motor.set_target(t_s, 0.0, self.spin_up_s);
        let done = FinishedRun {
            pose: run.pose,
            rate_dps: run.rate_dps,
            start_s: run.start_s,
            end_s: t_s,
            samples: run.samples,
            index_edges: run.edges,
            faulted: fault.is_some(),
        };
        self.record_run(&done);
        Ok(())
    }

    /// Adds a finished run to the truth.
    pub fn record_run(&mut self, run: &FinishedRun) {
        let drive_hz = (run.rate_dps * self.gear_ratio).abs() / 360.0;
        let filter_ms =
            self.lowpass_coef.map_or(0.0, |c| 1e3 * c.group_delay_s(drive_hz, f64::from(OVERSAMPLING) / self.period_s));
        self.runs.push(RunTruth {
            pose: run.pose,
            rate_dps: run.rate_dps,
            duration_s: run.end_s - run.start_s,
            start_s: run.start_s,
            samples: run.samples,
            index_edges: run.index_edges,
            gyro: self.gyro,
            drive_hz,
            filter_group_delay_ms: filter_ms,
            total_delay_ms: filter_ms + self.effects.pure_delay_s() * 1e3,
            faulted: run.faulted,
        });
    }

    /// Index edges and periodic messages in `(done_s, t_end_s]`, merged in time order.
    fn emit_interval<W: Write>(&mut self, t_end_s: f64, w: &mut FrameWriter<W>) -> io::Result<()> {
        if self.run.is_none() {
            return Ok(());
        }
        let interval = self.open_interval(t_end_s);
        let edges = &interval.edges;
        let mut next_edge = 0;
        loop {
            let run = self.run.as_ref().expect("checked above");
            let periodic = [
                run.start_s + (run.n_motor + 1) as f64 * MOTOR_PERIOD_S,
                run.start_s + (run.n_temperature as f64 + 0.5) * TEMPERATURE_PERIOD_S,
                run.start_s + (run.n_counters + 1) as f64 * COUNTERS_PERIOD_S,
            ];
            let (which, t_p) =
                periodic.iter().copied().enumerate().min_by(|a, b| a.1.total_cmp(&b.1)).expect("three entries");
            let t_e = edges.get(next_edge).map_or(f64::INFINITY, |e| e.t_s);
            if t_e.min(t_p) > t_end_s {
                break;
            }
            if t_e <= t_p {
                let e = edges[next_edge];
                next_edge += 1;
                // Captured by a timer input: exact to the µs tick, no interrupt jitter.
                w.send(&RigMsg::Index(self.index_edge(&e)))?;
                self.run.as_mut().expect("checked above").edges += 1;
            } else {
                let msg = match which {
                    0 => self.motor_status(t_p),
                    1 => RigMsg::Temperature(Temperature {
                        t_us: self.timer_us(t_p),
                        raw: self.thermal.out_temp_raw(t_p),
                    }),
                    _ => RigMsg::Counters(Counters {
                        t_us: self.timer_us(t_p),
                        frames_sent: w.frames_sent(),
                        queue_drops: 0,
                        samples_read: self.samples_read,
                        gyro_overruns: 0,
                        spi_errors: 0,
                        // The batch capture has no host talking to the rig.
                        rx_errors: 0,
                    }),
                };
                w.send(&msg)?;
                let run = self.run.as_mut().expect("checked above");
                match which {
                    0 => run.n_motor += 1,
                    1 => run.n_temperature += 1,
                    _ => run.n_counters += 1,
                }
            }
        }
        self.close_interval(t_end_s, interval);
        Ok(())
    }

    /// The index edges in `(done_s, t_end_s]` and the state at its end (a run is mounted).
    fn open_interval(&mut self, t_end_s: f64) -> Interval {
        let run = self.run.as_ref().expect("a mounted gyro");
        let (t_a, theta2_a) = (run.done_s, run.theta2_done_rad);
        let base = self.motor.state(t_end_s);
        let theta2_rad = self.theta2_rad(base.theta1_deg);
        let mut edges = std::mem::take(&mut self.scratch);
        edges.clear();
        self.plate.crossings(
            t_a,
            t_end_s,
            theta2_a,
            theta2_rad,
            |t| self.theta2_rad(self.motor.theta1_deg(t)),
            &mut edges,
        );
        Interval { edges, base, theta2_rad }
    }

    /// Everything up to `t_end_s` has been said.
    fn close_interval(&mut self, t_end_s: f64, interval: Interval) {
        self.scratch = interval.edges;
        let run = self.run.as_mut().expect("a mounted gyro");
        run.done_s = t_end_s;
        run.base_done = interval.base;
        run.theta2_done_rad = interval.theta2_rad;
    }

    /// An edge as the index capture latches it: timer and encoder at its instant.
    fn index_edge(&self, e: &EdgeCrossing) -> IndexEdge {
        IndexEdge {
            t_us: self.timer_us(e.t_s),
            encoder: self.encoder.register(self.motor.theta1_deg(e.t_s)),
            edge: e.edge,
        }
    }

    fn motor_status(&self, t_s: f64) -> RigMsg {
        let run_tag = self.run.as_ref().map_or(0, |r| r.run_tag);
        let state = self.motor.state(t_s);
        // The firmware measures speed as the encoder difference over one report period.
        let dc =
            self.encoder.counts(state.theta1_deg) - self.encoder.counts(self.motor.theta1_deg(t_s - MOTOR_PERIOD_S));
        let sp = state.setpoint_dps;
        let duty = 1000.0 * sp / FULL_DUTY_DPS + if sp == 0.0 { 0.0 } else { FRICTION_DUTY_PERMILLE * sp.signum() };
        RigMsg::Motor(MotorStatus {
            t_us: self.timer_us(t_s),
            speed_cps: (dc as f64 / MOTOR_PERIOD_S).round() as i32,
            setpoint_cps: units::counts_from_deg(sp, ENCODER_COUNTS_PER_REV).round() as i32,
            duty_permille: duty.round().clamp(-1000.0, 1000.0) as i16,
            faults: 0,
            run_tag,
        })
    }

    /// Sensed counts (before offset, noise, quantisation) at `t_s`.
    fn sensed_counts(&self, chain: &SenseChain, t_s: f64) -> [f64; 3] {
        self.sensed_counts_at(chain, &self.motor.state(t_s))
    }

    /// Sensed counts at `t_s`, each axis at its own instant when the axes are not sampled
    /// together (`Effects::axis_delay`).
    fn sensed_counts_per_axis(&self, chain: &SenseChain, t_s: f64) -> [f64; 3] {
        match self.effects.axis_delay {
            None => self.sensed_counts(chain, t_s),
            Some(_) => {
                let d = self.effects.axis_delay_s();
                std::array::from_fn(|a| self.sensed_counts(chain, t_s - d[a])[a])
            }
        }
    }

    /// Sensed counts for a base-table state.
    fn sensed_counts_at(&self, chain: &SenseChain, st: &BaseState) -> [f64; 3] {
        let theta2 = self.theta2_rad(st.theta1_deg);
        let mut w2 = omega2(st.theta1_rate_dps, theta2, self.theta2_rate_dps(st));
        if let Some(t) = &self.effects.table_tilt {
            // z1 leans by ε towards z2: θ1' gets a part along z2, and its in-plane part, the
            // sinusoid every axis measures, shrinks by cos ε.
            let (sin_tilt, cos_tilt) = t.tilt_deg.to_radians().sin_cos();
            w2[0] *= cos_tilt;
            w2[1] *= cos_tilt;
            w2[2] += st.theta1_rate_dps * sin_tilt;
        }
        if let Some(e) = &self.effects.earth_rotation {
            // The base's heading in the lab: the table is geared to a ground-fixed shaft, so
            // θ2 = ratio·θ1_lab + const; the heading is measured from where θ2 = 0.
            let heading = theta2 / self.gear_ratio;
            w2 += nalgebra::Vector3::from(e.in_table_frame_dps(heading, theta2));
        }
        chain.counts(&w2, theta2)
    }

    /// The sample at data-ready `next_k` (its interval has been emitted).
    fn emit_sample<W: Write>(&mut self, w: &mut FrameWriter<W>) -> io::Result<()> {
        let sample = self.next_sample();
        w.send(&RigMsg::Sample(sample))?;
        self.samples_read = self.samples_read.wrapping_add(1);
        Ok(())
    }

    /// The sample at data-ready `next_k` (its interval has been closed); moves on to the next.
    fn next_sample(&mut self) -> Sample {
        let mut run = self.run.take().expect("a mounted gyro");
        let t_s = self.data_ready_s(run.next_k);
        if self.thermal.dependence.is_some() {
            // The sensitivities and directions follow the die; a thousandth of a °C moves them
            // by < 0.2 ppm, far below any run's σ.
            let temp_c = self.thermal.temperature_c(t_s);
            if (temp_c - run.chain_temp_c).abs() > CHAIN_STEP_C {
                run.chain = self.chain_at(run.pose, temp_c);
                run.chain_temp_c = temp_c;
            }
        }
        let delay_s = self.effects.pure_delay_s();
        let pre = match run.lowpass.as_mut() {
            Some(f) => {
                let t_prev = self.data_ready_s(run.next_k - 1);
                let dt = (t_s - t_prev) / f64::from(OVERSAMPLING);
                let mut y = [0.0; 3];
                for j in 1..=OVERSAMPLING {
                    y = f.step(self.sensed_counts_per_axis(&run.chain, t_prev + f64::from(j) * dt - delay_s));
                }
                y
            }
            None if delay_s == 0.0 && self.effects.axis_delay.is_none() => {
                self.sensed_counts_at(&run.chain, &run.base_done)
            }
            None => self.sensed_counts_per_axis(&run.chain, t_s - delay_s),
        };
        let mut drift = self.thermal.offset_drift_dps(t_s);
        if let Some(w) = self.effects.bias_random_walk {
            // The walk advances by K·√Δt over the time since it last moved, so gaps between
            // runs count as they would on a powered rig.
            let step = w.k_dps_per_sqrt_s * (t_s - self.walk_t_s).max(0.0).sqrt();
            for (d, walk) in drift.iter_mut().zip(&mut self.walk_dps) {
                let z: f64 = StandardNormal.sample(&mut self.walk_rng);
                *walk += step * z;
                *d += *walk;
            }
            self.walk_t_s = t_s;
        }
        let k = self.sensor.k_counts_per_dps(self.gyro.full_scale);
        let mut rate_counts = [0i16; 3];
        for i in 0..3 {
            let z: f64 = StandardNormal.sample(&mut self.noise_rng);
            let offset = k[i] * (self.sensor.offset_dps[i] + self.level_dps[i] + drift[i]);
            rate_counts[i] = quantise(pre[i] + offset + self.noise_counts[i] * z);
        }
        let jitter_us = self.jitter.sample(&mut self.jitter_rng);
        let t_us = (i64::from(self.start_t_us) + (t_s * 1e6 * self.effects.rig_clock_rate() + jitter_us).round() as i64)
            as u32;
        debug_assert_eq!(run.done_s, t_s, "the sample's interval is emitted first");
        let encoder = self.encoder.register(run.base_done.theta1_deg);
        run.samples += 1;
        run.next_k += 1;
        self.run = Some(run);
        Sample { t_us, encoder, rate_counts, status: 0 }
    }

    /// The gyro in `pose` from `t_s` on (the live emulator's mount): it samples from then on, in
    /// a run or not, as the firmware streams every data-ready. The edges up to `t_s` must have
    /// been taken ([`Self::index_edges_until`]).
    pub fn mount(&mut self, t_s: f64, pose: Pose) {
        self.run = Some(self.new_run(t_s, pose, 0, 0.0));
    }

    /// The chamber steps to `setpoint_c` at `t_s` (the live emulator's simulated chamber): the
    /// air ramps from where the die is, the die follows with its lag (its momentum from an
    /// unfinished step is not carried over).
    pub fn set_chamber(&mut self, t_s: f64, setpoint_c: f64, ramp_c_per_min: f64, die_tau_s: f64) {
        let rise_c = self.thermal.drift.map_or(0.0, |d| d.rise_c);
        let from_c = self.thermal.temperature_c(t_s) - rise_c;
        let index = self.thermal.chamber.map_or(0, |c| c.index);
        self.thermal.chamber = Some(ChamberStep {
            ramp_c_per_min,
            die_tau_s,
            capture_after_s: -t_s,
            ..ChamberStep::new(index, from_c, setpoint_c)
        });
    }

    /// The pose the gyro is mounted in.
    pub fn mounted_pose(&self) -> Option<Pose> {
        self.run.as_ref().map(|r| r.pose)
    }

    /// New gyro settings at `t_s`, the gyro staying in its pose (the live emulator, between runs).
    pub fn reconfigure(&mut self, t_s: f64, gyro: GyroConfig) {
        let pose = self.run.take().map(|r| r.pose);
        self.configure(gyro);
        if let Some(pose) = pose {
            self.mount(t_s, pose);
        }
    }

    /// The drive ramps from its speed at `t_s` to `target_dps` at `ramp_dps2` (the firmware's
    /// speed loop decides both; the tables follow its ramp).
    pub fn drive_to(&mut self, t_s: f64, target_dps: f64, ramp_dps2: f64) {
        let from_dps = self.motor.state(t_s).setpoint_dps;
        let ramp_s = if ramp_dps2 > 0.0 { (target_dps - from_dps).abs() / ramp_dps2 } else { 0.0 };
        self.motor.set_target(t_s, target_dps, ramp_s);
    }

    /// The next data-ready of the mounted gyro, s.
    pub fn next_data_ready_s(&self) -> Option<f64> {
        self.run.as_ref().map(|r| self.data_ready_s(r.next_k))
    }

    /// Index edges up to `t_s`, each as the capture latches it.
    pub fn index_edges_until(&mut self, t_s: f64, mut on_edge: impl FnMut(IndexEdge)) {
        let Some(run) = self.run.as_ref() else { return };
        if t_s <= run.done_s {
            return;
        }
        let interval = self.open_interval(t_s);
        for e in &interval.edges {
            on_edge(self.index_edge(e));
        }
        self.run.as_mut().expect("checked above").edges += interval.edges.len() as u64;
        self.close_interval(t_s, interval);
    }

    /// The sample at the next data-ready (its edges taken first) and the die temperature
    /// (OUT_TEMP) then.
    pub fn sample(&mut self) -> (Sample, i8) {
        let t_s = self.next_data_ready_s().expect("a mounted gyro");
        (self.next_sample(), self.thermal.out_temp_raw(t_s))
    }

    /// The encoder register at `t_s`.
    pub fn encoder_at(&self, t_s: f64) -> u32 {
        self.encoder.register(self.motor.theta1_deg(t_s))
    }

    /// Samples and index edges since the gyro was mounted.
    pub fn mounted_counts(&self) -> (u64, u64) {
        self.run.as_ref().map_or((0, 0), |r| (r.samples, r.edges))
    }

    /// The truth so far: the sensor for the current gyro settings and the finished runs.
    pub fn truth(&self) -> Truth {
        let fs = self.gyro.full_scale;
        let m = self.sensor.m_counts_per_dps(fs);
        let (k, offset) = (self.sensor.k_counts_per_dps(fs), self.sensor.offset_counts(fs));
        let truth = Truth {
            seed: self.seed,
            m_counts_per_dps: [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[(r, c)])),
            k_counts_per_dps: k,
            s: self.sensor.s.map(|v| [v[0], v[1], v[2]]),
            tilt_deg: self.sensor.tilt_deg,
            offset_counts: std::array::from_fn(|i| offset[i] + k[i] * self.level_dps[i]),
            noise_dps_per_sqrt_hz: self.noise_density,
            noise_counts_per_sample: self.noise_counts,
            gyro: self.gyro,
            odr_hz_actual: 1.0 / self.period_s,
            odr_error_ppm: self.odr_error_ppm,
            timestamp_jitter_us: self.effects.timestamp_jitter_us(),
            encoder_counts_per_rev: ENCODER_COUNTS_PER_REV,
            gear_ratio_nominal: f64::from(GEAR_RATIO.num) / f64::from(GEAR_RATIO.den),
            gear_ratio: self.gear_ratio,
            index_offset_deg: self.effects.index_offset.map_or(0.0, |o| o.offset_deg),
            index_plate_width_deg: self.plate_width_deg,
            start_t_us: self.start_t_us,
            start_encoder: self.encoder.start_counts,
            ambient_c: self.thermal.ambient_c,
            out_temp_at_0c: self.thermal.out_temp_at_0c,
            lowpass_cutoff_hz: self.effects.lowpass(configured_cutoff_hz(self.gyro)).map(|(_, fc_hz)| fc_hz),
            effects: self.effects,
            runs: self.runs.clone(),
            thermal: None,
        };
        match self.thermal.dependence {
            Some(dep) => self.at_mean_temperature(truth, dep),
            None => truth,
        }
    }

    /// The truth at the runs' mean die temperature, with the reference values and coefficients
    /// in its thermal section.
    fn at_mean_temperature(&self, mut truth: Truth, dep: TemperatureDependence) -> Truth {
        let fs = self.gyro.full_scale;
        let die_mean_c = self.mean_die_c();
        let at = self.sensor.at_temperature(&dep, die_mean_c);
        let m = at.m_counts_per_dps(fs);
        let k_ref = self.sensor.k_counts_per_dps(fs);
        let change = dep.offset_change_dps(die_mean_c);
        truth.thermal = Some(ThermalTruth {
            dependence: dep,
            m_ref_counts_per_dps: truth.m_counts_per_dps,
            offset_ref_counts: truth.offset_counts,
            k_ref_counts_per_dps: truth.k_counts_per_dps,
            s_ref: truth.s,
            chamber: self.thermal.chamber,
            die_mean_c,
        });
        truth.m_counts_per_dps = [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[(r, c)]));
        truth.k_counts_per_dps = at.k_counts_per_dps(fs);
        truth.s = at.s.map(|v| [v[0], v[1], v[2]]);
        truth.tilt_deg = at.tilt_deg;
        truth.offset_counts = [0, 1, 2].map(|i| truth.offset_counts[i] + k_ref[i] * change[i]);
        truth
    }

    /// Mean die temperature over the finished runs, °C (sampled every second, by duration).
    fn mean_die_c(&self) -> f64 {
        let (mut sum, mut n) = (0.0, 0.0);
        for r in &self.runs {
            let steps = (r.duration_s.ceil() as u64).max(1);
            for j in 0..steps {
                let t = r.start_s + (j as f64 + 0.5) * r.duration_s / steps as f64;
                sum += self.thermal.temperature_c(t);
                n += 1.0;
            }
        }
        if n > 0.0 {
            sum / n
        } else {
            self.thermal.temperature_c(0.0)
        }
    }
}
