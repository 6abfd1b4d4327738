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

/// A run's gyro samples in order, however they are held: read from any position onwards.
pub trait Samples {
    /// Samples held.
    fn len(&self) -> usize;

    /// Whether none is held.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The samples from index `start` (at most `len`) to the end, in order.
    fn iter_from(&self, start: usize) -> impl Iterator<Item = RunSample> + '_;
}

impl Samples for [RunSample] {
    fn len(&self) -> usize {
        <[RunSample]>::len(self)
    }

    fn iter_from(&self, start: usize) -> impl Iterator<Item = RunSample> + '_ {
        self[start..].iter().copied()
    }
}

/// Samples a [`PackedSamples`] block holds: one absolute (time, count) per 32 samples is 0.5
/// bytes a sample, and reaching sample `i` from its block's start costs at most 31 steps.
const PACKED_BLOCK: usize = 32;

/// Step marking a sample stored whole in `PackedSamples::escapes`.
const ESCAPED_STEP: u16 = u16::MAX;

/// One sample as [`PackedSamples`] holds it, 12 bytes: time and encoder count as steps from the
/// previous sample, the raw gyro output and status.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PackedSample {
    /// Time since the previous sample, µs (0 at a block's start), or [`ESCAPED_STEP`].
    dt_us: u16,
    /// Encoder count since the previous sample.
    de_counts: i16,
    /// Raw gyro output, counts.
    rate_counts: [i16; 3],
    /// `protocol::sample_status` bits.
    status: u8,
}

/// A run's samples packed while a long capture is replayed, 12.5 bytes a sample instead of
/// [`RunSample`]'s 24 (issue 7's memory bar: an hour's run is 2.9 M samples). Time and encoder
/// count are the capture's exact integers, as steps from the sample before (a gyro sample is
/// 1.25-10 ms after the last one, the table turns at most a few hundred counts in that time),
/// with every [`PACKED_BLOCK`]-th sample's values whole; a step that does not fit (a gap, time
/// running back, a jump of the count) is stored whole beside. Every sample read back is the one
/// pushed, bit for bit.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PackedSamples {
    packed: Vec<PackedSample>,
    /// (t_us, encoder count) of each block's first sample.
    bases: Vec<(i64, i64)>,
    /// (index, t_us, encoder count) of the samples whose steps do not fit, by index (never a
    /// block's first sample: its base holds it).
    escapes: Vec<(usize, i64, i64)>,
    /// (t_us, encoder count) of the last sample pushed.
    last: (i64, i64),
}

impl PackedSamples {
    /// Appends a sample.
    pub fn push(&mut self, s: RunSample) {
        let i = self.packed.len();
        let (dt, de) = (s.t_us.wrapping_sub(self.last.0), s.encoder.wrapping_sub(self.last.1));
        self.last = (s.t_us, s.encoder);
        let (dt_us, de_counts) = if i.is_multiple_of(PACKED_BLOCK) {
            self.bases.push((s.t_us, s.encoder));
            (0, 0)
        } else if let (true, Ok(de)) = ((0..i64::from(ESCAPED_STEP)).contains(&dt), i16::try_from(de)) {
            (dt as u16, de)
        } else {
            self.escapes.push((i, s.t_us, s.encoder));
            (ESCAPED_STEP, 0)
        };
        self.packed.push(PackedSample { dt_us, de_counts, rate_counts: s.rate_counts, status: s.status });
    }

    /// Feeds the samples to `h` as they are packed, which is one-to-one with the samples: two
    /// words a sample, without unpacking them (unpacking was ~1 % of a 1-h replay).
    fn digest(&self, h: &mut impl std::hash::Hasher) {
        for p in &self.packed {
            let [x, y, z] = p.rate_counts.map(|c| u64::from(c as u16));
            h.write_u64(u64::from(p.dt_us) | u64::from(p.de_counts as u16) << 16 | x << 32 | y << 48);
            h.write_u64(z | u64::from(p.status) << 16);
        }
        for &(t_us, encoder) in &self.bases {
            h.write_i64(t_us);
            h.write_i64(encoder);
        }
        for &(i, t_us, encoder) in &self.escapes {
            h.write_usize(i);
            h.write_i64(t_us);
            h.write_i64(encoder);
        }
    }

    /// The samples unpacked.
    pub fn to_vec(&self) -> Vec<RunSample> {
        self.iter_from(0).collect()
    }
}

impl Samples for PackedSamples {
    fn len(&self) -> usize {
        self.packed.len()
    }

    fn iter_from(&self, start: usize) -> impl Iterator<Item = RunSample> + '_ {
        let block = start - start % PACKED_BLOCK;
        let mut at = (0, 0);
        let mut escape = self.escapes.partition_point(|e| e.0 < block);
        (block..self.packed.len())
            .map(move |i| {
                let p = &self.packed[i];
                at = if i.is_multiple_of(PACKED_BLOCK) {
                    self.bases[i / PACKED_BLOCK]
                } else if p.dt_us == ESCAPED_STEP {
                    escape += 1;
                    (self.escapes[escape - 1].1, self.escapes[escape - 1].2)
                } else {
                    (at.0 + i64::from(p.dt_us), at.1 + i64::from(p.de_counts))
                };
                RunSample { t_us: at.0, encoder: at.1, rate_counts: p.rate_counts, status: p.status }
            })
            .skip(start - block)
    }
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
        let mut packed = PackedSamples::default();
        self.samples.iter().for_each(|&s| packed.push(s));
        self.fingerprint_with(&packed)
    }

    /// [`Run::fingerprint`] with the run's samples held elsewhere (packed, in a replay that
    /// decodes run by run): the same digest of the same samples.
    pub fn fingerprint_with(&self, samples: &PackedSamples) -> u64 {
        use std::hash::{BuildHasher, Hash, Hasher};
        // Only compared within one process (never stored), so any fixed seed does.
        let mut h = foldhash::fast::FixedState::with_seed(0).build_hasher();
        (self.pose.number(), self.rate_mdps, self.direction.sign(), samples.len()).hash(&mut h);
        samples.digest(&mut h);
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
    /// Whether the open run's samples go to `open_packed` (a replay run by run,
    /// [`decode_reader_by_run`]) instead of its `samples`.
    packing: bool,
    /// The open run's samples, when packing.
    open_packed: PackedSamples,
    /// Runs closed while packing, with their samples, until [`decode_reader_by_run`] takes them.
    closed: Vec<(Run, PackedSamples)>,
}

impl CaptureDecoder {
    /// A decoder that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds bytes.
    pub fn feed(&mut self, bytes: &[u8]) {
        // The stream is taken out for the call so each event is handled as it is decoded:
        // collecting them first copied every one twice.
        let mut stream = std::mem::take(&mut self.stream);
        stream.feed::<RigMsg>(bytes, |ev| self.on_event(ev));
        self.stream = stream;
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
        self.end();
        self.capture
    }

    /// [`CaptureDecoder::finish`] without giving up the decoder (a packing one still holds the
    /// last run in `closed`).
    fn end(&mut self) {
        if let Some(Event::Error { offset, len, error }) = self.stream.finish::<RigMsg>() {
            self.capture.loss.push_error(StreamError { offset, len, error });
        }
        self.close_run(false);
        self.capture.loss.bytes = self.stream.position();
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
                    Some(_) if self.packing => self.open_packed.push(sample),
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
            if self.packing {
                self.closed.push((run, std::mem::take(&mut self.open_packed)));
            } else {
                self.capture.runs.push(run);
            }
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

/// Decodes a capture from a reader run by run, for a long replay: while a run is read its
/// samples are held packed ([`PackedSamples`], half the size of [`RunSample`]s), and as soon as
/// it closes `on_run` gets it with them; the capture keeps the run `on_run` returns, in stream
/// order. Turning each run's samples into something smaller there (or dropping them) means the
/// samples of one run at most are held at a time, whatever the capture's length. Everything
/// else (losses, faults, `Hello`) is what [`decode_reader`] gives.
pub fn decode_reader_by_run(
    mut reader: impl std::io::Read,
    mut on_run: impl FnMut(Run, PackedSamples) -> Run,
) -> std::io::Result<Capture> {
    let mut dec = CaptureDecoder { packing: true, ..CaptureDecoder::new() };
    let mut buf = vec![0u8; 1 << 20];
    loop {
        match reader.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => dec.feed(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        }
        for (run, samples) in dec.closed.drain(..) {
            dec.capture.runs.push(on_run(run, samples));
        }
    }
    dec.end();
    for (run, samples) in dec.closed.drain(..) {
        dec.capture.runs.push(on_run(run, samples));
    }
    Ok(dec.capture)
}

/// Decodes a whole capture held in memory.
pub fn decode(bytes: &[u8]) -> Capture {
    let mut dec = CaptureDecoder::new();
    dec.feed(bytes);
    dec.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The packed sample stays 12 bytes: a long replay holds a whole run of them.
    #[test]
    fn packed_sample_is_12_bytes() {
        assert_eq!(std::mem::size_of::<PackedSample>(), 12);
    }

    /// Packing is exact: every sample read back, from any start, is the one pushed, whether its
    /// step fits or it is stored whole (a gap, time running back, a jump of the count, a block's
    /// first sample after a jump).
    #[test]
    fn packed_samples_read_back_exactly() {
        let mut pushed = Vec::new();
        let (mut t_us, mut encoder) = ((1i64 << 32) - 5_000, -5_000_000i64);
        for i in 0..1000i64 {
            t_us += match i {
                100 => 70_000,
                200 => -3,
                320 | 321 => 10_000_000,
                _ => 1250,
            };
            encoder += match i {
                400 => 40_000,
                401 => -40_000,
                _ => 202 - i % 5,
            };
            let status = (i % 3) as u8;
            pushed.push(RunSample { t_us, encoder, rate_counts: [i as i16, -(i as i16), i16::MAX - i as i16], status });
        }
        let mut packed = PackedSamples::default();
        pushed.iter().for_each(|&s| packed.push(s));
        assert_eq!(Samples::len(&packed), pushed.len());
        assert!(!packed.escapes.is_empty() && packed.escapes.len() <= 6, "{:?}", packed.escapes);
        assert_eq!(packed.to_vec(), pushed);
        for start in [0, 1, 31, 32, 33, 100, 101, 320, 321, 322, 401, 999, 1000] {
            assert_eq!(packed.iter_from(start).collect::<Vec<_>>(), pushed[start..], "from {start}");
        }
    }

    /// A capture decoded run by run is the capture decoded whole, losses included, each run's
    /// samples handed over with it: on a clean capture, one with corrupted bytes and one cut
    /// short.
    #[test]
    fn decoding_run_by_run_gives_the_same_capture() {
        let clean = crate::sim::simulate(&crate::sim::SimConfig::standard(3, 4.0)).expect("simulates").bytes;
        let mut corrupted = clean.clone();
        for k in (clean.len() / 7..clean.len()).step_by(clean.len() / 5) {
            corrupted[k] ^= 0x5a;
        }
        let cut = &clean[..clean.len() * 2 / 3];
        for bytes in [&clean[..], &corrupted[..], cut] {
            let whole = decode(bytes);
            let mut handed = Vec::new();
            let by_run = decode_reader_by_run(bytes, |mut run, samples| {
                assert!(run.samples.is_empty());
                handed.push(run.fingerprint_with(&samples));
                run.samples = samples.to_vec();
                run
            })
            .expect("reads from memory");
            assert!(whole.runs.len() >= 2, "{} runs", whole.runs.len());
            assert_eq!(handed, whole.runs.iter().map(Run::fingerprint).collect::<Vec<_>>());
            assert_eq!(format!("{by_run:?}"), format!("{whole:?}"));
        }
    }
}
