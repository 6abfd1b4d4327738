//! The virtual rig: the firmware's portable core driving the simulated exciter, on a
//! pseudo-terminal, so the host's live path can run without hardware.
//!
//! ```text
//! virtual_rig [--speedup N] [--ideal-gyro] [--duration SECONDS]
//! ```
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
use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

/// Simulated time per exchange with the pty: one USB-like poll every 2 ms.
const CHUNK_NS: u64 = 2_000_000;
/// Bytes the rig may have waiting for a host that is not reading before they are dropped,
/// like a CDC endpoint nobody polls.
const PTY_BACKLOG: usize = 64 * 1024;

struct Args {
    speedup: f64,
    ideal: bool,
    duration_s: Option<f64>,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args { speedup: 1.0, ideal: false, duration_s: None };
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
    let mut vr = VirtualRig::new(plant, L3g4200dModel::new(), 0);
    println!("{path}");
    std::io::stdout().flush().ok();

    // Keep the slave open: when the host closes its end, reads on the master then see no
    // hang-up, and the host can reopen.
    let _slave = slave;
    let mut wire = Wire::default();
    let mut backlog: Vec<u8> = Vec::new();
    let mut dropped = 0u64;
    let mut mounted_tag = None;
    let start = Instant::now();
    let end_ns = args.duration_s.map(|s| (s * 1e9) as u64);
    let mut rx = [0u8; 4096];
    loop {
        match master.read(&mut rx) {
            Ok(n) => wire.to_rig.extend(&rx[..n]),
            Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock) => {}
            Err(e) if e.raw_os_error() == Some(5) => {} // EIO: no host has the pty open
            Err(e) => panic!("pty read: {e}"),
        }
        let next = vr.now_ns() + CHUNK_NS;
        vr.run_until(next, &mut wire, |_| {});
        let tag = vr.rig.run_tag();
        if tag != mounted_tag {
            if let Some(pose) = tag.and_then(Pose::from_run_tag) {
                vr.plant.pose = pose;
            }
            mounted_tag = tag;
        }
        backlog.append(&mut wire.from_rig);
        if backlog.len() > PTY_BACKLOG {
            dropped += (backlog.len() - PTY_BACKLOG) as u64;
            backlog.truncate(PTY_BACKLOG);
        }
        match master.write(&backlog) {
            Ok(n) => {
                backlog.drain(..n);
            }
            Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock) => {}
            Err(e) if e.raw_os_error() == Some(5) => {}
            Err(e) => panic!("pty write: {e}"),
        }
        if end_ns.is_some_and(|end| vr.now_ns() >= end) {
            break;
        }
        // Pace simulated time against the wall clock.
        let due = Duration::from_secs_f64(vr.now_ns() as f64 * 1e-9 / args.speedup);
        if let Some(wait) = due.checked_sub(start.elapsed()) {
            std::thread::sleep(wait);
        }
    }
    let c = vr.rig.counters(vr.timer_us(vr.now_ns()));
    eprintln!("virtual rig done: {c:?}, {dropped} bytes dropped at the pty");
}
