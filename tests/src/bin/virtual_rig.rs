//! The virtual rig: the firmware's portable core driving the simulated exciter, on a
//! pseudo-terminal, so the host's live path can run without hardware.
//!
//! ```text
//! virtual_rig [--speedup N | --lockstep] [--ideal-gyro] [--duration SECONDS]
//! ```
//!
//! `--lockstep` hands the clock to the client (tests): simulated time only advances when a line
//! `step <ns> <bytes>` arrives on standard input; the rig first waits until it has received
//! `<bytes>` bytes from the host in total (everything the client wrote before asking), runs `<ns>`
//! of simulated time, then answers `at <now_ns> <bytes>` on standard output, `<bytes>` being
//! the total it has queued to the pty so far. A client that reads the pty up to that total has
//! seen exactly what the rig said until then, however loaded the machine: no wall-clock race.
//!
//! Prints the pty's device path (e.g. `/dev/pts/7`) as the first line on stdout, then serves
//! until killed (or until `--duration` seconds of simulated time). Simulated time runs `N` times
//! faster than the wall clock (default 1). The gyro is mounted in the pose named by each run's
//! tag (1 or 2, the host's encoding): the "automatic mount" of `host calibrate --yes`. Unless
//! `--ideal-gyro`, the simulated gyro carries the imperfection printed on stderr, for the host
//! to find.

use e2e::{VIRTUAL_GYRO_KS as DUT_KS, VIRTUAL_GYRO_OFFSET_DPS as DUT_OFFSET_DPS};
use firmware::plant::l3g4200d_model::L3g4200dModel;
use firmware::plant::{Plant, Pose};
use firmware::virtual_rig::{VirtualRig, Wire};
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

struct Args {
    speedup: f64,
    lockstep: bool,
    ideal: bool,
    duration_s: Option<f64>,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args { speedup: 1.0, lockstep: false, ideal: false, duration_s: None };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = |name: &str| {
            it.next()
                .and_then(|v| v.parse::<f64>().ok())
                .filter(|v| *v > 0.0)
                .ok_or(format!("{name} needs a positive number"))
        };
        match a.as_str() {
            "--speedup" => args.speedup = value("--speedup")?,
            "--duration" => args.duration_s = Some(value("--duration")?),
            "--ideal-gyro" => args.ideal = true,
            "--lockstep" => args.lockstep = true,
            other => return Err(format!("unknown argument {other}")),
        }
    }
    Ok(args)
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    let (mut master, slave) = TTYPort::pair().expect("cannot allocate a pseudo-terminal");
    let path = slave.name().expect("pty slave has a name");
    master.set_timeout(Duration::from_millis(0)).ok();

    let mut plant = Plant::prototype();
    if !args.ideal {
        plant.sensor_ks = DUT_KS;
        plant.sensor_offset_dps = DUT_OFFSET_DPS;
        eprintln!("virtual gyro: K S = {DUT_KS:?}, offset = {DUT_OFFSET_DPS:?} °/s");
    }
    let vr = VirtualRig::new(plant, L3g4200dModel::new(), 0);
    println!("{path}");
    std::io::stdout().flush().ok();

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
    };
    if args.lockstep {
        lockstep(&mut server);
    } else {
        let start = Instant::now();
        let end_ns = args.duration_s.map(|s| (s * 1e9) as u64);
        loop {
            server.read_host();
            server.run_chunk(u64::MAX);
            server.write_host();
            if end_ns.is_some_and(|end| server.vr.now_ns() >= end) {
                break;
            }
            // Pace simulated time against the wall clock.
            let due = Duration::from_secs_f64(server.vr.now_ns() as f64 * 1e-9 / args.speedup);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
    }
    let c = server.vr.rig.counters(server.vr.timer_us(server.vr.now_ns()));
    eprintln!("virtual rig done: {c:?}, {} bytes dropped at the pty", server.dropped);
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
}

impl Server {
    fn read_host(&mut self) {
        let mut rx = [0u8; 4096];
        loop {
            match self.master.read(&mut rx) {
                Ok(0) => return,
                Ok(n) => {
                    self.wire.to_rig.extend(&rx[..n]);
                    self.received += n as u64;
                }
                Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock) => return,
                Err(e) if e.raw_os_error() == Some(5) => return, // EIO: no host has the pty open
                Err(e) => panic!("pty read: {e}"),
            }
        }
    }

    /// Runs one USB-like poll period of simulated time, or up to `limit_ns` if sooner.
    fn run_chunk(&mut self, limit_ns: u64) {
        let next = (self.vr.now_ns() + CHUNK_NS).min(limit_ns);
        self.vr.run_until(next, &mut self.wire, |_| {});
        let tag = self.vr.rig.run_tag();
        if tag != self.mounted_tag {
            if let Some(pose) = tag.and_then(Pose::from_run_tag) {
                self.vr.plant.pose = pose;
            }
            self.mounted_tag = tag;
        }
        self.queued += self.wire.from_rig.len() as u64;
        self.backlog.append(&mut self.wire.from_rig);
        if self.backlog.len() > PTY_BACKLOG {
            let excess = self.backlog.len() - PTY_BACKLOG;
            self.dropped += excess as u64;
            self.queued -= excess as u64;
            self.backlog.truncate(PTY_BACKLOG);
        }
    }

    fn write_host(&mut self) {
        while !self.backlog.is_empty() {
            match self.master.write(&self.backlog) {
                Ok(n) if n > 0 => {
                    self.backlog.drain(..n);
                }
                Ok(_) => return,
                Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock) => return,
                Err(e) if e.raw_os_error() == Some(5) => return,
                Err(e) => panic!("pty write: {e}"),
            }
        }
    }
}

/// Simulated time on the client's command (module documentation).
fn lockstep(server: &mut Server) {
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
        server.read_host();
        server.write_host();
        let line = match rx.recv_timeout(Duration::from_micros(200)) {
            Ok(line) => line,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => continue,
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return,
        };
        let mut words = line.split_whitespace();
        let (Some("step"), Some(Ok(ns)), Some(Ok(bytes)), None) =
            (words.next(), words.next().map(str::parse::<u64>), words.next().map(str::parse::<u64>), words.next())
        else {
            eprintln!("error: expected `step <ns> <bytes>` on standard input, got {line:?}");
            std::process::exit(2);
        };
        // The client wrote `bytes` in total before asking: wait until the pty delivered them.
        let waiting_since = Instant::now();
        while server.received < bytes {
            server.write_host();
            server.read_host();
            if waiting_since.elapsed() > LOCKSTEP_RX_TIMEOUT {
                eprintln!("error: the host said it sent {bytes} bytes, the pty delivered {}", server.received);
                std::process::exit(1);
            }
            std::thread::sleep(Duration::from_micros(100));
        }
        let end = server.vr.now_ns() + ns;
        while server.vr.now_ns() < end {
            server.run_chunk(end);
            server.write_host();
        }
        if writeln!(out, "at {} {}", server.vr.now_ns(), server.queued).and_then(|()| out.flush()).is_err() {
            return;
        }
    }
}
