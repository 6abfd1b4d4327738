//! A live rig emulator for the host's live path: answers host commands like the firmware and
//! streams runs as they happen, in simulated time that the caller (or [`serve`]) advances.

use super::session::Session;
use super::stream::FrameWriter;
use super::truth::Truth;
use super::SimConfig;
use crate::geometry::Pose;
use protocol::{Ack, CmdResult, Command, Event, Fault, RigMsg, StreamDecoder};
use std::io::{self, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The firmware stops the motor after this long without any host frame, s
/// (`protocol::Command::Heartbeat`).
pub const HOST_LINK_TIMEOUT_S: f64 = 2.0;

/// Highest speed a `Start` may ask for, m°/s (assumed over-speed limit: 2 rev/s, well inside
/// the ±500 °/s range at pose 1 only up to ~360 °/s, but the rig itself allows it).
pub const MAX_RATE_MDPS: u32 = 720_000;

/// A simulated rig that speaks the protocol. One sensor (from the seed) for its whole life, so a
/// live calibration can be checked against [`SimRig::truth`].
pub struct SimRig {
    session: Session,
    out: FrameWriter<Vec<u8>>,
    decoder: StreamDecoder,
    now_s: f64,
    last_host_s: f64,
    events: Vec<Event<Command>>,
}

impl SimRig {
    /// Powers the rig up at simulated time 0; like the firmware it sends `Hello` at once.
    /// `cfg.runs` is ignored: the host commands the runs.
    ///
    /// # Panics
    /// If `cfg.validate()` fails.
    pub fn new(cfg: &SimConfig) -> Self {
        if let Err(e) = cfg.validate() {
            panic!("invalid SimConfig: {e}");
        }
        let mut rig = Self {
            session: Session::new(cfg),
            out: FrameWriter::new(Vec::new()),
            decoder: StreamDecoder::new(),
            now_s: 0.0,
            last_host_s: 0.0,
            events: Vec::new(),
        };
        let hello = RigMsg::Hello(rig.session.hello());
        rig.send(&hello);
        rig
    }

    /// Simulated time, s since power-up.
    pub fn now_s(&self) -> f64 {
        self.now_s
    }

    /// Whether a run is in progress.
    pub fn running(&self) -> bool {
        self.session.running()
    }

    /// The sensor and the runs finished so far.
    pub fn truth(&self) -> Truth {
        self.session.truth()
    }

    /// Bytes produced since the last call.
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(self.out.get_mut())
    }

    fn send(&mut self, msg: &RigMsg) {
        self.out.send(msg).expect("writing to a Vec cannot fail");
    }

    /// Advances simulated time to `t_s` (no-op if not later), streaming the run in progress and
    /// stopping it with a `HostLinkLost` fault if the host has been silent too long.
    pub fn advance_to(&mut self, t_s: f64) {
        if t_s <= self.now_s {
            return;
        }
        let deadline = self.last_host_s + HOST_LINK_TIMEOUT_S;
        if self.session.running() && deadline <= t_s {
            self.session
                .stop_run(deadline, Some(Fault::HostLinkLost), &mut self.out)
                .expect("writing to a Vec cannot fail");
        }
        self.session.advance_to(t_s, &mut self.out).expect("writing to a Vec cannot fail");
        self.now_s = t_s;
    }

    /// Host bytes received at the current simulated time; every command is answered at once.
    pub fn receive(&mut self, bytes: &[u8]) {
        let mut events = std::mem::take(&mut self.events);
        self.decoder.feed::<Command>(bytes, |ev| events.push(ev));
        for ev in events.drain(..) {
            match ev {
                Event::Frame { seq, msg, .. } => {
                    self.last_host_s = self.now_s;
                    let result = self.execute(msg);
                    self.send(&RigMsg::Ack(Ack { cmd_seq: seq, result }));
                }
                Event::Error { .. } => self.session.count_rx_error(),
            }
        }
        self.events = events;
    }

    /// Carries out one command, sending any frames it causes before the acknowledgement.
    fn execute(&mut self, cmd: Command) -> CmdResult {
        let t_s = self.now_s;
        let w = &mut self.out;
        let ok = |r: io::Result<()>| {
            r.expect("writing to a Vec cannot fail");
            CmdResult::Ok
        };
        match cmd {
            Command::Identify => ok(w.send(&RigMsg::Hello(self.session.hello()))),
            Command::Heartbeat => CmdResult::Ok,
            Command::Start(start) => {
                let Some(pose) = Pose::from_run_tag(start.run_tag) else {
                    return CmdResult::InvalidArgument;
                };
                if start.rate_mdps == 0 || start.rate_mdps > MAX_RATE_MDPS {
                    return CmdResult::InvalidArgument;
                }
                if self.session.running() {
                    return CmdResult::Busy;
                }
                // The simulated operator has mounted the pose the run tag names.
                let rate_dps = f64::from(start.rate_mdps) / 1000.0 * f64::from(start.direction.sign());
                ok(self.session.start_run(t_s, pose, start.run_tag, rate_dps, w))
            }
            Command::Stop => ok(self.session.stop_run(t_s, None, w)),
            Command::ConfigureGyro(gyro) => {
                if self.session.running() {
                    return CmdResult::Busy;
                }
                self.session.configure(gyro);
                ok(w.send(&RigMsg::Hello(self.session.hello())))
            }
        }
    }
}

/// A byte port: a serial port, a pty, a socket.
pub trait Port: Read + Write {}
impl<T: Read + Write + ?Sized> Port for T {}

/// Serves `rig` on `port` until `stop` is set: simulated time follows the wall clock × `speedup`
/// (10 runs a 10 s run in about 1 s), host bytes are fed to the rig as they arrive, and the rig's
/// bytes are written as they are produced. `port` reads must return within a few ms when idle
/// (a read timeout: `serialport::SerialPort::set_timeout`, or `WouldBlock`); `Ok(0)` counts as
/// idle, not as the end of the stream.
pub fn serve(port: &mut dyn Port, rig: &mut SimRig, speedup: f64, stop: &AtomicBool) -> io::Result<()> {
    let wall0 = Instant::now();
    let sim0 = rig.now_s();
    let now = |rig_now: f64| (sim0 + wall0.elapsed().as_secs_f64() * speedup).max(rig_now);
    let mut buf = [0u8; 1024];
    while !stop.load(Ordering::Relaxed) {
        rig.advance_to(now(rig.now_s()));
        write_patiently(port, &rig.take_output(), stop)?;
        match port.read(&mut buf) {
            Ok(0) => std::thread::sleep(Duration::from_millis(1)),
            Ok(n) => {
                rig.advance_to(now(rig.now_s()));
                rig.receive(&buf[..n]);
            }
            Err(e) if is_idle(&e) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

fn is_idle(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

/// Writes all of `bytes`, retrying while the port is momentarily full, unless `stop` is set.
fn write_patiently(port: &mut dyn Port, mut bytes: &[u8], stop: &AtomicBool) -> io::Result<()> {
    while !bytes.is_empty() {
        match port.write(bytes) {
            Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
            Ok(n) => bytes = &bytes[n..],
            Err(e) if is_idle(&e) => {
                if stop.load(Ordering::Relaxed) {
                    return Ok(());
                }
            }
            Err(e) => return Err(e),
        }
    }
    Ok(())
}
