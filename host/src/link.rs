//! A live session with the rig over a serial port: commands out, frames in, and every received
//! byte written to the capture file before it is decoded, so nothing recorded is ever lost.

use anyhow::{bail, Context, Result};
use protocol::{encode_frame, CmdResult, Command, Event, RigMsg, StreamDecoder, MAX_FRAME_LEN};
use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

/// Baud rate requested when opening the port. Ignored by USB CDC-ACM, used by a UART bridge;
/// 921 600 keeps the 800 Hz stream under 27 % load (protocol/README.md, "Link budget").
pub const DEFAULT_BAUD: u32 = 921_600;

/// How long the rig has to acknowledge a command.
pub const ACK_TIMEOUT: Duration = Duration::from_secs(2);

/// Interval between heartbeats: the rig stops the motor after 2 s without a host frame; 4 Hz
/// leaves margin for a loaded host and for simulated rigs running faster than real time.
pub const HEARTBEAT_INTERVAL: Duration = Duration::from_millis(250);

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
    last_tx: Instant,
    buf: Vec<u8>,
}

impl<P: Read + Write> Link<P> {
    /// Wraps an open port; `name` is used in error messages.
    pub fn new(port: P, name: impl Into<String>) -> Self {
        Self {
            port,
            name: name.into(),
            tx_seq: 0,
            rx: StreamDecoder::new(),
            record: None,
            last_tx: Instant::now(),
            buf: vec![0; 4096],
        }
    }

    /// Port name, for messages.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Starts writing every received byte to `sink` (flushed per read), replacing any previous sink.
    pub fn record_to(&mut self, sink: Option<Box<dyn Write>>) -> Result<()> {
        if let Some(mut old) = self.record.take() {
            old.flush().context("flushing capture")?;
        }
        self.record = sink;
        Ok(())
    }

    /// Sends one command; returns its sequence number.
    pub fn send(&mut self, cmd: &Command) -> Result<u16> {
        let seq = self.tx_seq;
        self.tx_seq = self.tx_seq.wrapping_add(1);
        let mut frame = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(seq, cmd, &mut frame).expect("every command fits in a frame");
        self.port
            .write_all(&frame[..n])
            .and_then(|()| self.port.flush())
            .with_context(|| format!("writing to {}", self.name))?;
        self.last_tx = Instant::now();
        Ok(seq)
    }

    /// Sends a heartbeat if the link has been quiet for [`HEARTBEAT_INTERVAL`].
    pub fn keep_alive(&mut self) -> Result<()> {
        if self.last_tx.elapsed() >= HEARTBEAT_INTERVAL {
            self.send(&Command::Heartbeat)?;
        }
        Ok(())
    }

    /// Reads what is available (waiting at most the port's timeout), records it, and passes every
    /// decoded message to `on_msg`. Returns the number of bytes read (0 on a timeout).
    pub fn poll(&mut self, mut on_msg: impl FnMut(&RigMsg)) -> Result<usize> {
        let n = match self.port.read(&mut self.buf) {
            Ok(0) => bail!("{} closed (the rig was disconnected?)", self.name),
            Ok(n) => n,
            Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted) => {
                return Ok(0)
            }
            Err(e) => return Err(e).with_context(|| format!("reading from {}", self.name)),
        };
        if let Some(rec) = self.record.as_mut() {
            rec.write_all(&self.buf[..n]).and_then(|()| rec.flush()).context("writing capture")?;
        }
        self.rx.feed::<RigMsg>(&self.buf[..n], |ev| {
            if let Event::Frame { msg, .. } = ev {
                on_msg(&msg)
            }
        });
        Ok(n)
    }

    /// Sends `cmd` and waits for its acknowledgement, passing every other message to `on_msg`.
    pub fn command(&mut self, cmd: &Command, mut on_msg: impl FnMut(&RigMsg)) -> Result<()> {
        let seq = self.send(cmd)?;
        let deadline = Instant::now() + ACK_TIMEOUT;
        let mut result = None;
        while result.is_none() {
            if Instant::now() > deadline {
                bail!(
                    "no answer from the rig on {} within {} s (command {})",
                    self.name,
                    ACK_TIMEOUT.as_secs(),
                    command_name(cmd)
                );
            }
            self.poll(|m| match m {
                RigMsg::Ack(a) if a.cmd_seq == seq => result = Some(a.result),
                other => on_msg(other),
            })?;
        }
        match result {
            Some(CmdResult::Ok) => Ok(()),
            Some(r) => bail!("the rig on {} refused {}: {r:?}", self.name, command_name(cmd)),
            None => unreachable!("loop exits only with a result"),
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
    }
}
