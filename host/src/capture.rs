//! A capture decoded into runs: the wire stream, unwrapped in time and encoder count, split at
//! `RunStarted` / `RunStopped`, with every lost or corrupt byte accounted for.

use crate::geometry::Pose;
use protocol::{
    Counters, Direction, Event, FaultReport, FrameError, GyroConfig, Hello, IndexEdge, MotorStatus, RigMsg, RunStarted,
    SeqTracker, StreamDecoder,
};
use serde::Serialize;

/// One gyro sample, unwrapped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunSample {
    /// Data-ready time, µs since the first timestamp of the capture.
    pub t_us: i64,
    /// Base-table encoder count at that instant, unwrapped (continues across runs).
    pub encoder: i64,
    /// Raw gyro output, counts.
    pub rate_counts: [i16; 3],
    /// `protocol::sample_status` bits.
    pub status: u8,
}

/// One index edge, unwrapped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunIndexEdge {
    /// Edge time, µs since the first timestamp of the capture.
    pub t_us: i64,
    /// Encoder count at the edge, unwrapped.
    pub encoder: i64,
    /// Rising (plate starts to block) or falling.
    pub edge: protocol::Edge,
}

/// One temperature reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunTemperature {
    /// µs since the first timestamp of the capture.
    pub t_us: i64,
    /// OUT_TEMP counts (−1 LSB/°C, unknown offset).
    pub raw: i8,
}

/// How a run's identity was established.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum RunOrigin {
    /// From its `RunStarted` frame.
    Started,
    /// Its `RunStarted` frame was lost; pose from the motor status run tag, commanded rate from
    /// the largest setpoint reported, gyro settings from the last `Hello`.
    Recovered,
}

/// Samples and events between one `RunStarted` and the matching `RunStopped` (or the end of data).
#[derive(Debug, Clone)]
pub struct Run {
    /// Rig identity and settings in force.
    pub hello: Hello,
    /// Pose, from the run tag.
    pub pose: Pose,
    /// Commanded base-table speed, m°/s.
    pub rate_mdps: u32,
    /// Commanded direction.
    pub direction: Direction,
    /// Gyro settings for the run.
    pub gyro: GyroConfig,
    /// How the run was identified.
    pub origin: RunOrigin,
    /// Byte offset in the capture where the run begins.
    pub offset: u64,
    /// Gyro samples in arrival order.
    pub samples: Vec<RunSample>,
    /// Index edges in arrival order.
    pub index: Vec<RunIndexEdge>,
    /// Temperature readings.
    pub temperatures: Vec<RunTemperature>,
    /// Motor status reports (t_us unwrapped, as i64, in `.0`).
    pub motor: Vec<(i64, MotorStatus)>,
    /// Counters reports.
    pub counters: Vec<(i64, Counters)>,
    /// Faults reported during the run.
    pub faults: Vec<(i64, FaultReport)>,
    /// Whether the run ended with `RunStopped` (false: the capture ended or was cut).
    pub stopped: bool,
}

/// The magnitude of a motor status's ramped setpoint, m°/s.
fn setpoint_mdps(m: &MotorStatus, hello: &Hello) -> u32 {
    use protocol::units::{deg_from_counts, mdps_from_dps};
    mdps_from_dps(deg_from_counts(f64::from(m.setpoint_cps), hello.encoder_counts_per_rev))
}

impl Run {
    /// Signed commanded base-table rate, °/s.
    pub fn commanded_rate_dps(&self) -> f64 {
        protocol::units::signed_dps(self.rate_mdps, self.direction)
    }

    /// Duration covered by the samples, s.
    pub fn duration_s(&self) -> f64 {
        match (self.samples.first(), self.samples.last()) {
            (Some(a), Some(b)) => (b.t_us - a.t_us) as f64 * 1e-6,
            _ => 0.0,
        }
    }

    /// A digest of the run's content (samples, index edges, settings): two runs with the same
    /// fingerprint are the same data given twice, never two recordings (the gyro's noise alone
    /// makes every recording different).
    pub fn fingerprint(&self) -> u64 {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (self.pose.number(), self.rate_mdps, self.direction.sign(), self.samples.len()).hash(&mut h);
        for s in &self.samples {
            (s.t_us, s.encoder, s.rate_counts, s.status).hash(&mut h);
        }
        for e in &self.index {
            (e.t_us, e.encoder).hash(&mut h);
        }
        h.finish()
    }

    /// A one-line label such as `pose 1, +180.0 °/s`.
    pub fn label(&self) -> String {
        format!("{}, {:+.1} °/s", self.pose, self.commanded_rate_dps())
    }
}

/// A stretch of the stream that did not decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct StreamError {
    /// Byte offset of the first bad byte.
    pub offset: u64,
    /// Bytes skipped.
    pub len: u64,
    /// Why, as text.
    #[serde(serialize_with = "ser_display")]
    pub error: FrameError,
}

fn ser_display<S: serde::Serializer, T: std::fmt::Display>(v: &T, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(v)
}

/// Frames missing between two valid frames, from the sequence numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct SeqGap {
    /// Byte offset of the first frame after the gap.
    pub offset: u64,
    /// Frames missing.
    pub missing: u64,
}

/// Bad stretches and sequence gaps recorded one by one; beyond this, only counted, so memory
/// stays bounded however much garbage a capture holds (1 GiB of noise would otherwise make
/// millions of records).
pub const MAX_LOSS_RECORDS: usize = 1_000;

/// Everything lost or damaged in a capture.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LossReport {
    /// Bytes read.
    pub bytes: u64,
    /// Valid frames.
    pub frames_ok: u64,
    /// Corrupt or truncated stretches, in stream order.
    pub errors: Vec<StreamError>,
    /// Sequence-number gaps, in stream order.
    pub seq_gaps: Vec<SeqGap>,
    /// Samples that arrived outside any identifiable run (dropped from calibration).
    pub orphan_samples: u64,
    /// Bad stretches beyond the first [`MAX_LOSS_RECORDS`]: how many, and their bytes.
    pub more_errors: u64,
    /// Bytes in the bad stretches beyond the cap.
    pub more_bytes_skipped: u64,
    /// Sequence gaps beyond the first [`MAX_LOSS_RECORDS`]: how many, and the frames missing.
    pub more_seq_gaps: u64,
    /// Frames missing in the gaps beyond the cap.
    pub more_frames_missing: u64,
    /// No `Hello` was read before a run began (lost on the line): the rig's constants were taken
    /// from the protocol ([`assumed_hello`]) and the run's gyro settings from its `RunStarted`.
    pub hello_assumed: bool,
}

impl LossReport {
    /// Frames missing according to sequence numbers.
    pub fn frames_missing(&self) -> u64 {
        self.seq_gaps.iter().map(|g| g.missing).sum::<u64>() + self.more_frames_missing
    }

    /// Bytes that did not belong to a valid frame.
    pub fn bytes_skipped(&self) -> u64 {
        self.errors.iter().map(|e| e.len).sum::<u64>() + self.more_bytes_skipped
    }

    /// Bad stretches, recorded or only counted.
    pub fn error_count(&self) -> u64 {
        self.errors.len() as u64 + self.more_errors
    }

    /// Sequence gaps, recorded or only counted.
    pub fn seq_gap_count(&self) -> u64 {
        self.seq_gaps.len() as u64 + self.more_seq_gaps
    }

    fn push_error(&mut self, e: StreamError) {
        if self.errors.len() < MAX_LOSS_RECORDS {
            self.errors.push(e);
        } else {
            self.more_errors += 1;
            self.more_bytes_skipped += e.len;
        }
    }

    fn push_gap(&mut self, g: SeqGap) {
        if self.seq_gaps.len() < MAX_LOSS_RECORDS {
            self.seq_gaps.push(g);
        } else {
            self.more_seq_gaps += 1;
            self.more_frames_missing += g.missing;
        }
    }

    /// True when nothing was lost or damaged.
    pub fn is_clean(&self) -> bool {
        self.error_count() == 0 && self.seq_gap_count() == 0 && self.orphan_samples == 0 && !self.hello_assumed
    }
}

/// A decoded capture.
#[derive(Debug, Clone, Default)]
pub struct Capture {
    /// Last `Hello` seen (None if the capture holds none).
    pub hello: Option<Hello>,
    /// Runs in stream order.
    pub runs: Vec<Run>,
    /// Faults reported outside any run (a watchdog reset, a gyro fault while idle), µs on the
    /// capture's clock; at most [`MAX_LOSS_RECORDS`].
    pub faults: Vec<(i64, FaultReport)>,
    /// Loss accounting.
    pub loss: LossReport,
}

/// Unwraps a wrapping 32-bit counter into i64 by signed differences, tolerating slightly
/// out-of-order values (an index edge reported after the samples that follow it).
#[derive(Debug, Clone, Copy, Default)]
struct Unwrapper {
    last_raw: u32,
    last: i64,
    started: bool,
}

impl Unwrapper {
    fn unwrap(&mut self, raw: u32) -> i64 {
        if !self.started {
            self.started = true;
            self.last_raw = raw;
            self.last = 0;
            return 0;
        }
        let delta = i64::from(raw.wrapping_sub(self.last_raw) as i32);
        let value = self.last + delta;
        if delta > 0 {
            self.last_raw = raw;
            self.last = value;
        }
        value
    }
}

/// Incremental capture decoder: feed bytes as they arrive (live) or all at once (replay).
#[derive(Default)]
pub struct CaptureDecoder {
    stream: StreamDecoder,
    seq: SeqTracker,
    clock: Unwrapper,
    encoder: Unwrapper,
    capture: Capture,
    open: Option<Run>,
    /// Scratch buffer reused across `feed` calls.
    events: Vec<Event<RigMsg>>,
}

impl CaptureDecoder {
    /// A decoder that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds bytes.
    pub fn feed(&mut self, bytes: &[u8]) {
        let mut events = std::mem::take(&mut self.events);
        self.stream.feed::<RigMsg>(bytes, |ev| events.push(ev));
        for ev in events.drain(..) {
            self.on_event(ev);
        }
        self.events = events;
    }

    /// The run in progress, if any (for progress display).
    pub fn current_run(&self) -> Option<&Run> {
        self.open.as_ref()
    }

    /// What has been decoded so far, the open run included (without closing it).
    pub fn snapshot(&self) -> &Capture {
        &self.capture
    }

    /// Ends the stream: reports a trailing partial frame and closes the open run.
    pub fn finish(mut self) -> Capture {
        if let Some(Event::Error { offset, len, error }) = self.stream.finish::<RigMsg>() {
            self.capture.loss.push_error(StreamError { offset, len, error });
        }
        self.close_run(false);
        self.capture.loss.bytes = self.stream.position();
        self.capture
    }

    fn on_event(&mut self, ev: Event<RigMsg>) {
        match ev {
            Event::Error { offset, len, error } => self.capture.loss.push_error(StreamError { offset, len, error }),
            Event::Frame { offset, seq, msg } => {
                self.capture.loss.frames_ok += 1;
                let missing = self.seq.observe(seq);
                if missing > 0 {
                    self.capture.loss.push_gap(SeqGap { offset, missing: u64::from(missing) });
                }
                self.on_msg(offset, msg);
            }
        }
    }

    fn encoder(&mut self, raw: u32) -> i64 {
        self.encoder.unwrap(raw)
    }

    fn on_msg(&mut self, offset: u64, msg: RigMsg) {
        match msg {
            RigMsg::Hello(h) => self.capture.hello = Some(h),
            RigMsg::RunStarted(rs) => {
                self.close_run(false);
                self.clock.unwrap(rs.t_us);
                self.open_run(offset, rs, RunOrigin::Started);
            }
            RigMsg::RunStopped(rs) => {
                self.clock.unwrap(rs.t_us);
                self.close_run(true);
            }
            RigMsg::Sample(s) => {
                let sample = RunSample {
                    t_us: self.clock.unwrap(s.t_us),
                    encoder: self.encoder(s.encoder),
                    rate_counts: s.rate_counts,
                    status: s.status,
                };
                match self.open.as_mut() {
                    Some(run) => run.samples.push(sample),
                    None => self.capture.loss.orphan_samples += 1,
                }
            }
            RigMsg::Index(IndexEdge { t_us, encoder, edge }) => {
                let e = RunIndexEdge { t_us: self.clock.unwrap(t_us), encoder: self.encoder(encoder), edge };
                if let Some(run) = self.open.as_mut() {
                    run.index.push(e);
                }
            }
            RigMsg::Temperature(t) => {
                let t_us = self.clock.unwrap(t.t_us);
                if let Some(run) = self.open.as_mut() {
                    run.temperatures.push(RunTemperature { t_us, raw: t.raw });
                }
            }
            RigMsg::Motor(m) => {
                let t_us = self.clock.unwrap(m.t_us);
                if self.open.is_none() && m.run_tag != 0 {
                    self.recover_run(offset, t_us, &m);
                }
                if let Some(run) = self.open.as_mut() {
                    if run.origin == RunOrigin::Recovered {
                        // The lost RunStarted carried the commanded rate; the ramped setpoint
                        // reaches it once the ramp is over.
                        let mdps = setpoint_mdps(&m, &run.hello);
                        if mdps > run.rate_mdps {
                            run.rate_mdps = mdps;
                            run.direction = if m.setpoint_cps < 0 { Direction::Cw } else { Direction::Ccw };
                        }
                    }
                    run.motor.push((t_us, m));
                }
            }
            RigMsg::Counters(c) => {
                let t_us = self.clock.unwrap(c.t_us);
                if let Some(run) = self.open.as_mut() {
                    run.counters.push((t_us, c));
                }
            }
            RigMsg::Fault(f) => {
                let t_us = self.clock.unwrap(f.t_us);
                match self.open.as_mut() {
                    Some(run) => run.faults.push((t_us, f)),
                    None if self.capture.faults.len() < MAX_LOSS_RECORDS => self.capture.faults.push((t_us, f)),
                    None => {}
                }
            }
            RigMsg::Ack(_) => {}
        }
    }

    fn open_run(&mut self, offset: u64, rs: RunStarted, origin: RunOrigin) {
        let Some(pose) = Pose::from_run_tag(rs.run_tag) else {
            return;
        };
        let hello = match self.capture.hello {
            Some(h) => h,
            None => {
                self.capture.loss.hello_assumed = true;
                assumed_hello(rs.gyro)
            }
        };
        self.open = Some(Run {
            hello,
            pose,
            rate_mdps: rs.rate_mdps,
            direction: rs.direction,
            gyro: rs.gyro,
            origin,
            offset,
            samples: Vec::new(),
            index: Vec::new(),
            temperatures: Vec::new(),
            motor: Vec::new(),
            counters: Vec::new(),
            faults: Vec::new(),
            stopped: false,
        });
    }

    /// Opens a run whose `RunStarted` was lost, from a motor status that names it.
    fn recover_run(&mut self, offset: u64, _t_us: i64, m: &MotorStatus) {
        let hello = self.capture.hello.unwrap_or_else(|| assumed_hello(GyroConfig::DEFAULT));
        let rate_mdps = setpoint_mdps(m, &hello);
        let rs = RunStarted {
            t_us: m.t_us,
            run_tag: m.run_tag,
            rate_mdps,
            direction: if m.setpoint_cps < 0 { Direction::Cw } else { Direction::Ccw },
            gyro: hello.gyro,
        };
        self.open_run(offset, rs, RunOrigin::Recovered);
    }

    fn close_run(&mut self, stopped: bool) {
        if let Some(mut run) = self.open.take() {
            run.stopped = stopped;
            self.capture.runs.push(run);
        }
    }
}

/// What a run assumes of the rig when the capture's `Hello` was lost: the protocol's constants
/// (encoder resolution, timestamp rate, gear ratio: every rig of this design has them), the
/// gyro settings given (a `RunStarted` carries its own), firmware version 0.0.0 (unknown).
pub fn assumed_hello(gyro: GyroConfig) -> Hello {
    Hello {
        protocol_version: protocol::PROTOCOL_VERSION,
        firmware: protocol::Version { major: 0, minor: 0, patch: 0 },
        gyro,
        encoder_counts_per_rev: protocol::ENCODER_COUNTS_PER_REV,
        gear_ratio: protocol::GEAR_RATIO,
        timestamp_hz: protocol::TIMESTAMP_HZ,
    }
}

/// Decodes a capture from a reader in 1 MiB chunks, so an hour-long capture (160 MB) is never
/// held in memory as bytes.
pub fn decode_reader(mut reader: impl std::io::Read) -> std::io::Result<Capture> {
    let mut dec = CaptureDecoder::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        match reader.read(&mut buf) {
            Ok(0) => return Ok(dec.finish()),
            Ok(n) => dec.feed(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
}

/// Decodes a whole capture held in memory.
pub fn decode(bytes: &[u8]) -> Capture {
    let mut dec = CaptureDecoder::new();
    dec.feed(bytes);
    dec.finish()
}
