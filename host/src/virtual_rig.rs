//! `host virtual-rig`: the firmware's portable core (`firmware::rig`) driving the simulated
//! exciter (`firmware::plant`), on a pseudo-terminal, so the live session can be tried, and
//! tested, without hardware.
//!
//! ```text
//! host virtual-rig [--speedup N | --lockstep [--chamber]] [--ideal-gyro] [--noiseless-gyro] [--duration SECONDS]
//!                  [--loss P] [--garbage-every S] [--drop KIND:N]... [--seed N] [--watchdog-reset]
//! ```
//!
//! A hostile line, for the host to survive: `--loss P` drops each byte, both ways, with
//! probability P; `--garbage-every S` sends a burst of 8-64 random bytes every S seconds of
//! simulated time (between frames); `--drop KIND:N` drops the Nth frame (from 1) of a kind the
//! rig sends (`Hello`, `Ack`, `RunStarted`, `RunStopped`, `Sample`, `Motor`, `Index`,
//! `Counters`, `Temperature`, `Fault`), repeatable. `--seed` fixes the randomness (default 1).
//! `--watchdog-reset` starts the rig as after a watchdog reset (it reports `WatchdogReset`).
//! `--chamber` (lockstep) puts the rig in a simulated thermal chamber ([`VirtualChamber`]), set
//! by `chamber <setpoint_c>` lines on standard input between the `step` lines.
//! Every command but `Heartbeat` that reaches the rig intact is logged on standard error,
//! `virtual rig: received Stop (seq 12) at 14.210 s` (simulated time), and so is every `Fault`
//! and `RunStopped` the rig sends, before the line may lose it (`virtual rig: sent Fault
//! HostLinkLost at 9.001 s`, `virtual rig: sent RunStopped (run tag 1) at 9.001 s`).
//!
//! `--lockstep` hands the clock to the client (tests): simulated time only advances when a line
//! `step <ns> <bytes>` arrives on standard input; the rig first waits until it has received
//! `<bytes>` bytes from the host in total (everything the client wrote before asking), runs `<ns>`
//! of simulated time, then answers `at <now_ns> <bytes>` on standard output, `<bytes>` being
//! the total it has queued to the pty so far. A client that reads the pty up to that total has
//! seen exactly what the rig said until then, however loaded the machine: no wall-clock race.
//! [`LockstepPort`] is that client; `host calibrate --port PTY --lockstep-clock SOCKET` (a
//! hidden option, for tests) runs the live session through it, the control lines relayed by
//! whoever listens on the Unix socket.
//!
//! Prints the pty's device path (e.g. `/dev/pts/7`) as the first line on stdout, then serves
//! until killed (or until `--duration` seconds of simulated time). Simulated time runs `N` times
//! faster than the wall clock (default 1). The gyro is mounted in the pose named by each run's
//! tag (1 or 2, the host's encoding): the "automatic mount" of `host calibrate --yes`. Unless
//! `--ideal-gyro`, the simulated gyro carries the imperfection printed on stderr, for the host
//! to find. Unless `--noiseless-gyro`, it has the L3G4200D's datasheet rate noise (seeded by
//! `--seed`); without it, the table-speed jitter of the speed loop, which the encoder cannot
//! resolve, stands above the gyro's 1-LSB rounding and the calibration finds it unexplained.

use crate::link::command_name;
use anyhow::{bail, Context, Result};
use firmware::plant::l3g4200d_model::L3g4200dModel;
use firmware::plant::{Plant, Pose};
use firmware::virtual_rig::{VirtualRig, Wire};
use protocol::frame::decode_frame;
use protocol::{Command, RigMsg, StreamDecoder, MAX_FRAME_LEN};
use serialport::{SerialPort, TTYPort};
use std::io::{BufRead, ErrorKind, Read, Write};
use std::time::{Duration, Instant};

/// Simulated time per exchange with the pty: one USB-like poll every 2 ms.
const CHUNK_NS: u64 = 2_000_000;
/// Bytes the rig may have waiting for a host that is not reading before they are dropped,
/// like a CDC endpoint nobody polls.
const PTY_BACKLOG: usize = 64 * 1024;
/// Lockstep: how long the bytes a client announced may take to come through the pty (only a
/// broken client waits this long).
const LOCKSTEP_RX_TIMEOUT: Duration = Duration::from_secs(60);

/// The bench's options.
#[derive(clap::Args, Debug, Clone)]
pub struct Options {
    /// Simulated seconds per wall second.
    #[arg(long, default_value_t = 1.0, value_parser = positive)]
    pub speedup: f64,
    /// Simulated time on the client's command (`step <ns> <bytes>` lines on standard input).
    #[arg(long, conflicts_with = "speedup")]
    pub lockstep: bool,
    /// A perfect gyro instead of the imperfect device under test.
    #[arg(long)]
    pub ideal_gyro: bool,
    /// A gyro without its datasheet rate noise (outputs are the rates rounded to an LSB).
    #[arg(long)]
    pub noiseless_gyro: bool,
    /// Stop after this many seconds of simulated time.
    #[arg(long, value_parser = positive)]
    pub duration: Option<f64>,
    /// Drop each byte, both ways, with this probability.
    #[arg(long, default_value_t = 0.0, value_parser = probability)]
    pub loss: f64,
    /// A burst of 8-64 random bytes every this many seconds of simulated time.
    #[arg(long, value_parser = positive)]
    pub garbage_every: Option<f64>,
    /// Drop the Nth frame (from 1) of a kind the rig sends, KIND:N, e.g. Ack:2 (repeatable).
    #[arg(long = "drop", value_parser = parse_drop)]
    pub drops: Vec<(String, u32)>,
    /// Seed of the line's randomness.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Start as after a watchdog reset (the rig reports WatchdogReset).
    #[arg(long)]
    pub watchdog_reset: bool,
    /// A thermal chamber around the rig (lockstep only): the die starts at the lab's 25 °C and
    /// follows the chamber set by `chamber <setpoint_c>` lines on standard input; the gyro's
    /// offset, sensitivity, direction and OUT_TEMP follow the die (`VirtualChamber`).
    #[arg(long, requires = "lockstep")]
    pub chamber: bool,
}

fn positive(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("{s:?} is not a positive number")),
    }
}

fn probability(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..1.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?} is not a probability in [0, 1)")),
    }
}

fn parse_drop(spec: &str) -> Result<(String, u32), String> {
    let (kind, n) = spec.split_once(':').ok_or(format!("{spec:?}: expected KIND:N"))?;
    let n: u32 = n.parse().ok().filter(|n| *n > 0).ok_or(format!("{spec:?}: N counts from 1"))?;
    if !KINDS.contains(&kind) {
        return Err(format!("{spec:?}: unknown kind {kind:?} (one of {})", KINDS.join(", ")));
    }
    Ok((kind.to_string(), n))
}

/// The virtual rig's device under test (unless `--ideal-gyro`): sensitivities 0.97, 1.02, 1.05;
/// axes tilted by ≈ 1-2° from the package axes. Row i is k_i s_iᵀ (EXCITER.md eq. 6).
pub const VIRTUAL_GYRO_KS: [[f64; 3]; 3] =
    [[0.969_8, 0.017_0, -0.005_1], [-0.012_2, 1.019_7, 0.026_7], [0.018_3, -0.009_2, 1.049_8]];

/// The virtual rig's zero-rate offsets, °/s.
pub const VIRTUAL_GYRO_OFFSET_DPS: [f64; 3] = [1.2, -0.8, 2.5];

/// OUT_TEMP at a die of 0 °C in the virtual chamber, LSB: the register's offset is not specified
/// (L3G4200D datasheet Table 5, −1 LSB/°C); any value inside the simulator's 20…60 does.
pub const CHAMBER_OUT_TEMP_AT_0C: f64 = 40.0;

/// The lab's temperature, where the virtual chamber's die starts, °C (the datasheet's 25 °C).
pub const CHAMBER_START_C: f64 = 25.0;

/// `--chamber`: the die follows the chamber through the simulator's air ramp and first-order
/// lag (`sim::thermal::ChamberStep`, 2 °C/min and 180 s), and the gyro's offset, sensitivity and
/// direction follow the die with the simulator's datasheet-sized tempcos
/// (`sim::thermal::TemperatureDependence::default`, about the die's 25 °C values).
#[derive(Debug, Clone)]
pub struct VirtualChamber {
    step: crate::sim::thermal::ChamberStep,
    /// When the chamber was last set, ns of rig time.
    set_at_ns: u64,
    dependence: crate::sim::thermal::TemperatureDependence,
    /// The gyro at 25 °C: rows k_i s_iᵀ and offsets, °/s.
    ks_25c: [[f64; 3]; 3],
    offset_25c_dps: [f64; 3],
}

impl VirtualChamber {
    /// A chamber at the lab's temperature around a gyro whose 25 °C values are the plant's.
    pub fn new(plant: &Plant) -> Self {
        Self {
            step: crate::sim::thermal::ChamberStep::new(0, CHAMBER_START_C, CHAMBER_START_C),
            set_at_ns: 0,
            dependence: crate::sim::thermal::TemperatureDependence::default(),
            ks_25c: plant.sensor_ks,
            offset_25c_dps: plant.sensor_offset_dps,
        }
    }

    /// The die temperature at `now_ns`, °C.
    pub fn die_c(&self, now_ns: u64) -> f64 {
        self.step.die_c(now_ns.saturating_sub(self.set_at_ns) as f64 * 1e-9)
    }

    /// Sets the chamber at `now_ns`: its air ramps from the die's temperature then (the air and
    /// the die are taken as equal at that moment: exact once settled).
    pub fn set(&mut self, setpoint_c: f64, now_ns: u64) {
        let from_c = self.die_c(now_ns);
        self.step = crate::sim::thermal::ChamberStep::new(self.step.index + 1, from_c, setpoint_c);
        self.set_at_ns = now_ns;
    }

    /// The gyro at the die's temperature now: OUT_TEMP, offsets and K S of the plant.
    pub fn apply(&self, now_ns: u64, plant: &mut Plant) {
        use nalgebra::Vector3;
        let die_c = self.die_c(now_ns);
        let out_temp = (CHAMBER_OUT_TEMP_AT_0C - die_c).round().clamp(f64::from(i8::MIN), f64::from(i8::MAX));
        plant.temp_raw = out_temp as i8;
        let d = &self.dependence;
        let offset = d.offset_change_dps(die_c);
        let factor = d.sensitivity_factor(die_c);
        for i in 0..3 {
            let row = Vector3::from(self.ks_25c[i]);
            let k = row.norm();
            let s = d.direction(i, &(row / k), die_c);
            plant.sensor_ks[i] = (s * k * factor[i]).into();
            plant.sensor_offset_dps[i] = self.offset_25c_dps[i] + offset[i];
        }
    }
}

/// Serves the virtual rig on a new pty until killed, `--duration` is over, or (lockstep)
/// standard input ends. Prints the pty path as the first line of standard output.
pub fn serve(opts: &Options) -> Result<()> {
    let (mut master, slave) = TTYPort::pair().context("cannot allocate a pseudo-terminal")?;
    let path = slave.name().context("the pty has no device name")?;
    master.set_timeout(Duration::from_millis(0)).ok();
    never_block(&master)?;

    let mut plant = Plant::prototype();
    if !opts.ideal_gyro {
        plant.sensor_ks = VIRTUAL_GYRO_KS;
        plant.sensor_offset_dps = VIRTUAL_GYRO_OFFSET_DPS;
        eprintln!("virtual gyro: K S = {VIRTUAL_GYRO_KS:?}, offset = {VIRTUAL_GYRO_OFFSET_DPS:?} °/s");
    }
    let chip = if opts.noiseless_gyro { L3g4200dModel::new() } else { L3g4200dModel::with_noise(opts.seed) };
    let chamber = opts.chamber.then(|| VirtualChamber::new(&plant));
    let vr = VirtualRig::restarted(plant, chip, 0, opts.watchdog_reset);
    println!("{path}");
    std::io::stdout().flush().ok();
    let line = LineFaults {
        loss: opts.loss,
        garbage_every_ns: opts.garbage_every.map(|s| (s * 1e9) as u64),
        drops: opts.drops.clone(),
        seed: opts.seed,
    };

    // Keep the slave open: when the host closes its end, reads on the master then see no
    // hang-up, and the host can reopen.
    let _slave = slave;
    let mut server = Server {
        vr,
        master,
        wire: Wire::default(),
        backlog: Vec::new(),
        dropped: 0,
        received: 0,
        queued: 0,
        mounted_tag: None,
        line: Line::new(line),
        commands: StreamDecoder::new(),
        chamber,
    };
    if opts.lockstep {
        lockstep(&mut server)?;
    } else {
        let start = Instant::now();
        let end_ns = opts.duration.map(|s| (s * 1e9) as u64);
        loop {
            server.read_host()?;
            server.run_chunk(u64::MAX);
            server.write_host()?;
            if end_ns.is_some_and(|end| server.vr.now_ns() >= end) {
                break;
            }
            // Pace simulated time against the wall clock.
            let due = Duration::from_secs_f64(server.vr.now_ns() as f64 * 1e-9 / opts.speedup);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
    }
    let c = server.vr.rig.counters(server.vr.timer_us(server.vr.now_ns()));
    eprintln!("virtual rig done: {c:?}, {} bytes dropped at the pty", server.dropped);
    Ok(())
}

/// The rig and its end of the pty.
struct Server {
    vr: VirtualRig,
    master: TTYPort,
    wire: Wire,
    /// Bytes for the host not yet taken by the pty.
    backlog: Vec<u8>,
    dropped: u64,
    /// Bytes received from the host, in total.
    received: u64,
    /// Bytes queued for the host (not dropped), in total.
    queued: u64,
    mounted_tag: Option<u8>,
    line: Line,
    /// The host's frames as the rig receives them, for the command log.
    commands: StreamDecoder,
    /// `--chamber`: the thermal chamber around the rig.
    chamber: Option<VirtualChamber>,
}

impl Server {
    fn read_host(&mut self) -> Result<()> {
        let mut rx = [0u8; 4096];
        loop {
            match self.master.read(&mut rx) {
                Ok(0) => return Ok(()),
                Ok(n) => {
                    self.received += n as u64;
                    let line = &mut self.line;
                    let kept: Vec<u8> = rx[..n].iter().copied().filter(|_| !line.lose()).collect();
                    self.log_commands(&kept);
                    self.wire.to_rig.extend(kept);
                }
                Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock) => return Ok(()),
                Err(e) if e.raw_os_error() == Some(5) => return Ok(()), // EIO: no host has the pty open
                Err(e) => return Err(e).context("reading the pty"),
            }
        }
    }

    /// Runs one USB-like poll period of simulated time, or up to `limit_ns` if sooner.
    fn run_chunk(&mut self, limit_ns: u64) {
        let next = (self.vr.now_ns() + CHUNK_NS).min(limit_ns);
        if let Some(c) = &self.chamber {
            c.apply(self.vr.now_ns(), &mut self.vr.plant);
        }
        self.vr.run_until(next, &mut self.wire, |_| {});
        let tag = self.vr.rig.run_tag();
        if tag != self.mounted_tag {
            if let Some(pose) = tag.and_then(Pose::from_run_tag) {
                self.vr.plant.pose = pose;
            }
            self.mounted_tag = tag;
        }
        let before = self.backlog.len();
        self.line.pass(self.vr.now_ns(), &self.wire.from_rig, &mut self.backlog);
        self.wire.from_rig.clear();
        self.queued += (self.backlog.len() - before) as u64;
        if self.backlog.len() > PTY_BACKLOG {
            let excess = self.backlog.len() - PTY_BACKLOG;
            self.dropped += excess as u64;
            self.queued -= excess as u64;
            self.backlog.truncate(PTY_BACKLOG);
        }
    }

    /// Says on standard error every command but `Heartbeat` that reached the rig intact (after
    /// the line's losses), with the simulated time: how a test sees that `Stop` was sent.
    fn log_commands(&mut self, bytes: &[u8]) {
        let now_s = self.vr.now_ns() as f64 * 1e-9;
        self.commands.feed::<Command>(bytes, |ev| match ev {
            protocol::Event::Frame { msg: Command::Heartbeat, .. } => {}
            protocol::Event::Frame { seq, msg, .. } => {
                eprintln!("virtual rig: received {} (seq {seq}) at {now_s:.3} s", command_name(&msg))
            }
            protocol::Event::Error { .. } => {}
        });
    }

    fn write_host(&mut self) -> Result<()> {
        while !self.backlog.is_empty() {
            match self.master.write(&self.backlog) {
                Ok(n) if n > 0 => {
                    self.backlog.drain(..n);
                }
                Ok(_) => return Ok(()),
                Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock) => return Ok(()),
                Err(e) if e.raw_os_error() == Some(5) => return Ok(()),
                Err(e) => return Err(e).context("writing the pty"),
            }
        }
        Ok(())
    }
}

/// Makes the pty master's reads and writes return at once (`WouldBlock`) rather than wait.
/// `serialport`'s zero timeout only polls before the call: a poll that finds room for one byte
/// is followed by a blocking write of the whole backlog, which waits until a host that is not
/// reading (in lockstep: waiting for the rig's `at`, which this write holds up) makes room.
/// `serialport` has no non-blocking mode, hence rustix's `fcntl` here.
fn never_block(master: &TTYPort) -> Result<()> {
    use rustix::fs::{fcntl_getfl, fcntl_setfl, OFlags};
    use std::os::fd::{AsRawFd, BorrowedFd};
    // SAFETY: `master` owns the descriptor and outlives this borrow (`TTYPort` has no `AsFd`).
    let fd = unsafe { BorrowedFd::borrow_raw(master.as_raw_fd()) };
    fcntl_getfl(fd)
        .and_then(|flags| fcntl_setfl(fd, flags | OFlags::NONBLOCK))
        .context("cannot make the pseudo-terminal non-blocking")
}

/// Simulated time on the client's command (module documentation).
fn lockstep(server: &mut Server) -> Result<()> {
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines() {
            let Ok(line) = line else { return };
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    let mut out = std::io::stdout().lock();
    loop {
        server.read_host()?;
        server.write_host()?;
        let line = match rx.recv_timeout(Duration::from_micros(200)) {
            Ok(line) => line,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => continue,
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return Ok(()),
        };
        let mut words = line.split_whitespace();
        if let Some(rest) = line.strip_prefix("chamber ") {
            set_chamber(server, rest)?;
            continue;
        }
        let (Some("step"), Some(Ok(ns)), Some(Ok(bytes)), None) =
            (words.next(), words.next().map(str::parse::<u64>), words.next().map(str::parse::<u64>), words.next())
        else {
            bail!("expected `step <ns> <bytes>` on standard input, got {line:?}");
        };
        // The client wrote `bytes` in total before asking: wait until the pty delivered them.
        let waiting_since = Instant::now();
        while server.received < bytes {
            server.write_host()?;
            server.read_host()?;
            if waiting_since.elapsed() > LOCKSTEP_RX_TIMEOUT {
                bail!("the client said it sent {bytes} bytes, the pty delivered {}", server.received);
            }
            std::thread::sleep(Duration::from_micros(100));
        }
        let end = server.vr.now_ns() + ns;
        while server.vr.now_ns() < end {
            server.run_chunk(end);
            server.write_host()?;
        }
        if writeln!(out, "at {} {}", server.vr.now_ns(), server.queued).and_then(|()| out.flush()).is_err() {
            return Ok(());
        }
    }
}

/// A `chamber <setpoint_c>` line: the chamber set now (and logged, as the commands are).
fn set_chamber(server: &mut Server, setpoint: &str) -> Result<()> {
    let now_ns = server.vr.now_ns();
    let Some(c) = server.chamber.as_mut() else { bail!("a `chamber` line needs --chamber") };
    let setpoint_c: f64 = setpoint
        .trim()
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite())
        .with_context(|| format!("expected `chamber <setpoint_c>` on standard input, got `chamber {setpoint}`"))?;
    c.set(setpoint_c, now_ns);
    eprintln!("virtual rig: chamber set to {setpoint_c} °C at {:.3} s", now_ns as f64 * 1e-9);
    Ok(())
}

/// Frame kinds `--drop` knows, as the rig's messages are named.
const KINDS: [&str; 10] =
    ["Hello", "Ack", "RunStarted", "RunStopped", "Sample", "Motor", "Index", "Counters", "Temperature", "Fault"];

fn kind(msg: &RigMsg) -> &'static str {
    match msg {
        RigMsg::Hello(_) => "Hello",
        RigMsg::Ack(_) => "Ack",
        RigMsg::RunStarted(_) => "RunStarted",
        RigMsg::RunStopped(_) => "RunStopped",
        RigMsg::Sample(_) => "Sample",
        RigMsg::Motor(_) => "Motor",
        RigMsg::Index(_) => "Index",
        RigMsg::Counters(_) => "Counters",
        RigMsg::Temperature(_) => "Temperature",
        RigMsg::Fault(_) => "Fault",
    }
}

/// What makes the line hostile (module documentation).
#[derive(Debug, Clone)]
struct LineFaults {
    loss: f64,
    garbage_every_ns: Option<u64>,
    drops: Vec<(String, u32)>,
    seed: u64,
}

impl Default for LineFaults {
    fn default() -> Self {
        Self { loss: 0.0, garbage_every_ns: None, drops: Vec::new(), seed: 1 }
    }
}

/// The line between rig and host.
struct Line {
    faults: LineFaults,
    rng: u64,
    /// Bytes of the rig's frame in progress.
    frame: Vec<u8>,
    /// Frames seen per kind.
    seen: std::collections::HashMap<&'static str, u32>,
    next_garbage_ns: u64,
}

impl Line {
    fn new(faults: LineFaults) -> Self {
        let rng = faults.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let next_garbage_ns = faults.garbage_every_ns.unwrap_or(u64::MAX);
        Self { faults, rng, frame: Vec::new(), seen: Default::default(), next_garbage_ns }
    }

    /// xorshift64*: deterministic for a seed, good enough to scatter losses.
    fn next(&mut self) -> u64 {
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Whether to lose the next byte.
    fn lose(&mut self) -> bool {
        self.faults.loss > 0.0 && (self.next() >> 11) as f64 * (1.0 / (1u64 << 53) as f64) < self.faults.loss
    }

    /// Passes what the rig sent at `now_ns` to `out`, through the line's faults.
    fn pass(&mut self, now_ns: u64, bytes: &[u8], out: &mut Vec<u8>) {
        for &b in bytes {
            self.frame.push(b);
            if b != 0 {
                continue;
            }
            let frame = std::mem::take(&mut self.frame);
            let mut scratch = [0u8; MAX_FRAME_LEN];
            if let Ok((_, msg)) = decode_frame::<RigMsg>(&frame[..frame.len() - 1], &mut scratch) {
                let k = kind(&msg);
                // What ends a run, logged as the rig sends it (before the line may lose it): how
                // a test sees a trip the host never heard of.
                let now_s = now_ns as f64 * 1e-9;
                match msg {
                    RigMsg::Fault(f) => eprintln!("virtual rig: sent Fault {:?} at {now_s:.3} s", f.fault),
                    RigMsg::RunStopped(r) => {
                        eprintln!("virtual rig: sent RunStopped (run tag {}) at {now_s:.3} s", r.run_tag)
                    }
                    _ => {}
                }
                let n = self.seen.entry(k).or_insert(0);
                *n += 1;
                let n = *n;
                if self.faults.drops.iter().any(|(dk, dn)| dk == k && *dn == n) {
                    eprintln!("virtual rig: dropped {k} #{n}");
                    continue;
                }
            }
            for &b in &frame {
                if !self.lose() {
                    out.push(b);
                }
            }
            if now_ns >= self.next_garbage_ns {
                self.next_garbage_ns = now_ns + self.faults.garbage_every_ns.unwrap_or(u64::MAX);
                let len = 8 + (self.next() % 57) as usize;
                for _ in 0..len {
                    let byte = self.next() as u8;
                    out.push(byte);
                }
            }
        }
    }
}

/// Simulated time per lockstep step: 5 ms, like a host polling its port every few milliseconds.
pub const LOCKSTEP_STEP_NS: u64 = 5_000_000;

/// The client's end of a rig in `--lockstep` (module documentation): its pty, plus the control
/// channel that steps simulated time. Simulated time advances only when a read finds nothing
/// waiting, so a loaded machine slows the session down but never changes what happens in it:
/// the host's timeouts and heartbeats ([`Self::clock`] as the link's clock) and the rig's link
/// watchdog are measured in the same time.
pub struct LockstepPort {
    control_in: Box<dyn BufRead>,
    control_out: Box<dyn Write>,
    pty: Box<dyn serialport::SerialPort>,
    /// Bytes written to the pty, in total.
    sent: u64,
    /// Bytes read from the pty, in total.
    received: u64,
    /// Read from the pty, not yet returned.
    pending: std::collections::VecDeque<u8>,
    now_ns: std::rc::Rc<std::cell::Cell<u64>>,
    /// Simulated time per step.
    pub step_ns: u64,
}

/// The simulated clock of a [`LockstepPort`], for [`crate::link::Link::with_clock`].
#[derive(Clone)]
pub struct SimClock(std::rc::Rc<std::cell::Cell<u64>>);

impl crate::link::Clock for SimClock {
    fn now(&self) -> Duration {
        Duration::from_nanos(self.0.get())
    }
}

/// How long the pty may take to deliver bytes the rig said it sent: only a dead rig takes this
/// long (a hang guard, not a timing assumption).
const LOCKSTEP_PTY_TIMEOUT: Duration = Duration::from_secs(60);

impl LockstepPort {
    /// Opens the rig's pty `path`; `control_in`/`control_out` carry its `at`/`step` lines.
    pub fn open(path: &str, control_in: Box<dyn BufRead>, control_out: Box<dyn Write>) -> Result<Self> {
        let pty = serialport::new(path, 115_200)
            .timeout(Duration::from_millis(50))
            .open()
            .with_context(|| format!("cannot open the virtual rig's pty {path}"))?;
        Ok(Self {
            control_in,
            control_out,
            pty,
            sent: 0,
            received: 0,
            pending: Default::default(),
            now_ns: Default::default(),
            step_ns: LOCKSTEP_STEP_NS,
        })
    }

    /// Opens the rig's pty `path`, the control lines going through the Unix socket `socket`
    /// (where a test relays them to the rig's standard input and output, and so knows the
    /// simulated time the host lives in).
    pub fn connect(path: &str, socket: &std::path::Path) -> Result<Self> {
        let stream = std::os::unix::net::UnixStream::connect(socket)
            .with_context(|| format!("cannot connect to the lockstep clock {}", socket.display()))?;
        let reader = std::io::BufReader::new(stream.try_clone().context("cloning the lockstep socket")?);
        Self::open(path, Box::new(reader), Box::new(stream))
    }

    /// The rig's simulated time.
    pub fn clock(&self) -> SimClock {
        SimClock(self.now_ns.clone())
    }

    /// Simulated time now, ns.
    pub fn now_ns(&self) -> u64 {
        self.now_ns.get()
    }

    /// Advances the rig by `ns` once it has received everything written so far, and reads all
    /// it sent meanwhile.
    pub fn step(&mut self, ns: u64) -> std::io::Result<()> {
        use std::io::Error;
        writeln!(self.control_out, "step {ns} {}", self.sent)?;
        self.control_out.flush()?;
        let mut line = String::new();
        if self.control_in.read_line(&mut line)? == 0 {
            return Err(Error::new(ErrorKind::UnexpectedEof, "the virtual rig's lockstep control closed"));
        }
        let mut words = line.split_whitespace();
        let parsed = match (words.next(), words.next(), words.next()) {
            (Some("at"), Some(now), Some(total)) => now.parse::<u64>().ok().zip(total.parse::<u64>().ok()),
            _ => None,
        };
        let Some((now, total)) = parsed else {
            return Err(Error::new(ErrorKind::InvalidData, format!("the virtual rig answered {line:?}")));
        };
        self.now_ns.set(now);
        let mut buf = [0u8; 4096];
        let since = Instant::now();
        while self.received < total {
            if since.elapsed() > LOCKSTEP_PTY_TIMEOUT {
                return Err(Error::new(ErrorKind::TimedOut, "the pty never delivered the virtual rig's bytes"));
            }
            match self.pty.read(&mut buf) {
                Ok(n) => {
                    self.pending.extend(&buf[..n]);
                    self.received += n as u64;
                }
                Err(e) if e.kind() == ErrorKind::TimedOut => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

impl Read for LockstepPort {
    /// Returns what the rig has sent; when nothing is waiting, first runs one step of simulated
    /// time, and times out (`ErrorKind::TimedOut`) if the rig said nothing in it.
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.pending.is_empty() {
            self.step(self.step_ns)?;
        }
        if self.pending.is_empty() {
            return Err(ErrorKind::TimedOut.into());
        }
        let n = buf.len().min(self.pending.len());
        for (d, s) in buf.iter_mut().zip(self.pending.drain(..n)) {
            *d = s;
        }
        Ok(n)
    }
}

impl Write for LockstepPort {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.pty.write(buf)?;
        self.sent += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.pty.flush()
    }
}
