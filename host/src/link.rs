//! A live session with the rig over a serial port: commands out, frames in, and every received
//! byte written to the capture file before it is decoded, so nothing recorded is ever lost.

use anyhow::{bail, Context, Result};
use protocol::{encode_frame, timing, CmdResult, Command, Event, RigMsg, StreamDecoder, MAX_FRAME_LEN};
use std::io::{ErrorKind, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Baud rate requested when opening the port. Ignored by USB CDC-ACM, used by a UART bridge;
/// 921 600 keeps the 800 Hz stream under 27 % load (protocol/README.md, "Link budget").
pub const DEFAULT_BAUD: u32 = 921_600;

/// How long one attempt at a command waits for its acknowledgement
/// ([`protocol::timing::ACK_TIMEOUT_MS`]).
pub const ACK_TIMEOUT: Duration = Duration::from_millis(timing::ACK_TIMEOUT_MS as u64);

/// Interval between heartbeats ([`protocol::timing::HEARTBEAT_INTERVAL_MS`]).
pub const HEARTBEAT_INTERVAL: Duration = Duration::from_millis(timing::HEARTBEAT_INTERVAL_MS as u64);

/// Not one byte for this long is a dead link ([`protocol::timing::SILENT_LINK_MS`]).
pub const SILENT_LINK: Duration = Duration::from_millis(timing::SILENT_LINK_MS as u64);

/// What a command came back with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Answer {
    /// The rig's result.
    pub result: CmdResult,
    /// Attempts it took (1 = the first was acknowledged).
    pub attempts: u32,
}

/// Where the link's time comes from: the wall clock for a real rig, the rig's simulated time in
/// tests, so every timeout and heartbeat is measured in the time the rig lives in.
pub trait Clock {
    /// Time since an arbitrary origin.
    fn now(&self) -> Duration;
}

/// The wall clock.
pub struct WallClock(Instant);

impl Default for WallClock {
    fn default() -> Self {
        Self(Instant::now())
    }
}

impl Clock for WallClock {
    fn now(&self) -> Duration {
        self.0.elapsed()
    }
}

/// Anything a [`Link`] can talk through: a serial port, or a lockstep virtual rig's pty
/// ([`crate::virtual_rig::LockstepPort`]).
pub trait Port: Read + Write {}

impl<T: Read + Write + ?Sized> Port for T {}

/// Opens a serial port by path, with a one-line error that names it.
pub fn open_port(path: &str, baud: u32) -> Result<Box<dyn serialport::SerialPort>> {
    serialport::new(path, baud)
        .timeout(Duration::from_millis(20))
        .open()
        .with_context(|| format!("cannot open serial port {path}"))
}

/// The host end of the link.
pub struct Link<P: Read + Write> {
    port: P,
    name: String,
    tx_seq: u16,
    rx: StreamDecoder,
    record: Option<Box<dyn Write>>,
    /// Where `record` writes, for messages.
    record_name: String,
    clock: Box<dyn Clock>,
    last_tx: Duration,
    last_rx: Duration,
    buf: Vec<u8>,
    interrupt: Option<Arc<AtomicBool>>,
}

impl<P: Read + Write> Link<P> {
    /// Wraps an open port; `name` is used in error messages.
    pub fn new(port: P, name: impl Into<String>) -> Self {
        Self::with_clock(port, name, Box::new(WallClock::default()))
    }

    /// Wraps an open port whose time is `clock`'s.
    pub fn with_clock(port: P, name: impl Into<String>, clock: Box<dyn Clock>) -> Self {
        let last_tx = clock.now();
        Self {
            port,
            name: name.into(),
            tx_seq: 0,
            rx: StreamDecoder::new(),
            record: None,
            record_name: String::new(),
            clock,
            last_tx,
            last_rx: last_tx,
            buf: vec![0; 4096],
            interrupt: None,
        }
    }

    /// Makes every wait for an acknowledgement give up as soon as `flag` is set (Ctrl-C,
    /// SIGTERM, SIGHUP), instead of after its retries.
    pub fn watch_interrupt(&mut self, flag: Arc<AtomicBool>) {
        self.interrupt = Some(flag);
    }

    /// The port itself.
    pub fn port_mut(&mut self) -> &mut P {
        &mut self.port
    }

    /// The link's time now.
    pub fn now(&self) -> Duration {
        self.clock.now()
    }

    /// Port name, for messages.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Starts writing every received byte to `sink` (flushed per read), replacing any previous sink.
    pub fn record_to(&mut self, sink: Option<Box<dyn Write>>) -> Result<()> {
        self.record_to_named(sink, "the capture")
    }

    /// [`Self::record_to`], `name` (the file's path) said in every error of the sink, so a full
    /// disk names the file it could not write.
    pub fn record_to_named(&mut self, sink: Option<Box<dyn Write>>, name: impl Into<String>) -> Result<()> {
        if let Some(mut old) = self.record.take() {
            old.flush().with_context(|| format!("cannot write the capture {}", self.record_name))?;
        }
        self.record = sink;
        self.record_name = name.into();
        Ok(())
    }

    /// Sends one command; returns its sequence number.
    pub fn send(&mut self, cmd: &Command) -> Result<u16> {
        let seq = self.tx_seq;
        self.tx_seq = self.tx_seq.wrapping_add(1);
        let mut frame = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(seq, cmd, &mut frame).expect("every command fits in a frame");
        self.port.write_all(&frame[..n]).and_then(|()| self.port.flush()).map_err(|e| self.link_error(e, "writing"))?;
        self.last_tx = self.clock.now();
        Ok(seq)
    }

    /// Sends a heartbeat if the link has been quiet for [`HEARTBEAT_INTERVAL`].
    pub fn keep_alive(&mut self) -> Result<()> {
        if self.clock.now().saturating_sub(self.last_tx) >= HEARTBEAT_INTERVAL {
            self.send(&Command::Heartbeat)?;
        }
        Ok(())
    }

    /// Reads what is available (waiting at most the port's timeout), records it, and passes every
    /// decoded message to `on_msg`. Returns the number of bytes read (0 on a timeout). Fails when
    /// the link has been silent for [`SILENT_LINK`], naming the link and the rig, not the gyro.
    pub fn poll(&mut self, mut on_msg: impl FnMut(&RigMsg)) -> Result<usize> {
        let n = match self.port.read(&mut self.buf) {
            Ok(0) => bail!("{} closed (the rig was disconnected?)", self.name),
            Ok(n) => n,
            Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted) => {
                // Checked only after a read found nothing: a host that was itself descheduled
                // does not call a link dead without looking first.
                if self.clock.now().saturating_sub(self.last_rx) > SILENT_LINK {
                    bail!(
                        "the link to the rig on {} is silent: not one byte for {} s (check the cable, the rig's \
                         power and that no other program holds the port)",
                        self.name,
                        SILENT_LINK.as_secs_f64()
                    );
                }
                return Ok(0);
            }
            Err(e) => return Err(self.link_error(e, "reading")),
        };
        self.last_rx = self.clock.now();
        if let Some(rec) = self.record.as_mut() {
            if let Err(e) = rec.write_all(&self.buf[..n]).and_then(|()| rec.flush()) {
                // Recording stops (the file keeps what was written), the link does not: the
                // caller still has a table to stop, and heartbeats to send while it ramps down.
                self.record = None;
                return Err(e).with_context(|| format!("cannot write the capture {}", self.record_name));
            }
        }
        self.rx.feed::<RigMsg>(&self.buf[..n], |ev| {
            if let Event::Frame { msg, .. } = ev {
                on_msg(&msg)
            }
        });
        Ok(n)
    }

    /// A failed read or write on the port, in words a bench engineer can act on: a pulled USB
    /// cable or a rig that lost power shows as a hang-up (`BrokenPipe` from the serial port's
    /// poll, `EIO` from the tty, `ENXIO`/`ENODEV` once the device node is gone).
    fn link_error(&self, e: std::io::Error, doing: &str) -> anyhow::Error {
        let gone = matches!(e.kind(), ErrorKind::BrokenPipe | ErrorKind::UnexpectedEof | ErrorKind::ConnectionReset)
            || matches!(e.raw_os_error(), Some(5 | 6 | 19));
        if gone {
            anyhow::anyhow!(
                "the link to the rig on {} was lost ({doing} failed: {e}): check the cable and the rig's power, then start again",
                self.name
            )
        } else {
            anyhow::anyhow!("{doing} {} failed: {e}", self.name)
        }
    }

    /// Forgets how long the link has been quiet (after a deliberate pause in reading).
    pub fn reset_silence(&mut self) {
        self.last_rx = self.clock.now();
    }

    /// Sends `cmd` and waits for its acknowledgement, heartbeating meanwhile (a run may be in
    /// progress), and sends it again up to [`timing::COMMAND_ATTEMPTS`] times if no answer comes
    /// within [`ACK_TIMEOUT`]. Every other message goes to `on_msg`. Returns the rig's result,
    /// refusals included: a repeated command may be refused because its first attempt worked
    /// (a repeated `Start` is `Busy`), which only the caller can judge.
    pub fn request(&mut self, cmd: &Command, mut on_msg: impl FnMut(&RigMsg)) -> Result<Answer> {
        for attempt in 1..=timing::COMMAND_ATTEMPTS {
            let seq = self.send(cmd)?;
            let deadline = self.clock.now() + ACK_TIMEOUT;
            loop {
                let mut result = None;
                self.poll(|m| match m {
                    RigMsg::Ack(a) if a.cmd_seq == seq => result = Some(a.result),
                    other => on_msg(other),
                })?;
                if let Some(result) = result {
                    return Ok(Answer { result, attempts: attempt });
                }
                if self.interrupt.as_ref().is_some_and(|f| f.load(Ordering::SeqCst)) {
                    bail!("interrupted while waiting for the rig to answer {}", command_name(cmd));
                }
                if self.clock.now() > deadline {
                    break;
                }
                self.keep_alive()?;
            }
        }
        bail!(
            "no answer from the rig on {} to {} ({} attempts, {} s each): the link or the rig is down",
            self.name,
            command_name(cmd),
            timing::COMMAND_ATTEMPTS,
            ACK_TIMEOUT.as_secs_f64()
        )
    }

    /// [`Self::request`], and any result but `Ok` is an error.
    pub fn command(&mut self, cmd: &Command, on_msg: impl FnMut(&RigMsg)) -> Result<()> {
        match self.request(cmd, on_msg)?.result {
            CmdResult::Ok => Ok(()),
            r => bail!("the rig on {} refused {}: {r:?}", self.name, command_name(cmd)),
        }
    }
}

/// Short name of a command, for messages.
pub fn command_name(cmd: &Command) -> &'static str {
    match cmd {
        Command::Identify => "Identify",
        Command::Start(_) => "Start",
        Command::Stop => "Stop",
        Command::ConfigureGyro(_) => "ConfigureGyro",
        Command::Heartbeat => "Heartbeat",
        Command::ConfigureDrive(_) => "ConfigureDrive",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A port that answers every read with `read` and swallows every write.
    struct Port(fn() -> std::io::Result<usize>);

    impl Read for Port {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = (self.0)()?;
            buf[..n].fill(0);
            Ok(n)
        }
    }

    impl Write for Port {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// A disk with no space left.
    struct Full;

    impl Write for Full {
        fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
            Err(std::io::Error::from_raw_os_error(28))
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// Issue 28: a full disk names the capture it could not write.
    #[test]
    fn a_full_disk_names_the_capture() {
        let mut link = Link::new(Port(|| Ok(3)), "/dev/ttyACM0");
        link.record_to_named(Some(Box::new(Full)), "/data/pose1-p180dps.cap").unwrap();
        let e = link.poll(|_| {}).unwrap_err();
        assert_eq!(
            format!("{e:#}"),
            "cannot write the capture /data/pose1-p180dps.cap: No space left on device (os error 28)"
        );
        // The link itself goes on (the table must still be stopped), without the capture.
        assert_eq!(link.poll(|_| {}).unwrap(), 3);
    }

    /// Issue 28: a pulled cable (the serial port's hang-up, `EIO` from a tty whose other end
    /// is gone, the device node removed) is said as a lost link on the named port; another
    /// error keeps its own words.
    #[test]
    fn a_pulled_cable_is_a_lost_link_on_the_named_port() {
        let lost = |e: fn() -> std::io::Result<usize>| {
            format!("{:#}", Link::new(Port(e), "/dev/ttyACM0").poll(|_| {}).unwrap_err())
        };
        assert_eq!(
            lost(|| Err(std::io::Error::new(ErrorKind::BrokenPipe, "Broken pipe"))),
            "the link to the rig on /dev/ttyACM0 was lost (reading failed: Broken pipe): check the cable and the rig's power, then start again"
        );
        assert_eq!(
            lost(|| Err(std::io::Error::from_raw_os_error(5))),
            "the link to the rig on /dev/ttyACM0 was lost (reading failed: Input/output error (os error 5)): check the cable and the rig's power, then start again"
        );
        assert_eq!(
            lost(|| Err(std::io::Error::from_raw_os_error(13))),
            "reading /dev/ttyACM0 failed: Permission denied (os error 13)"
        );
    }
}
