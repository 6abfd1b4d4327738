//! A scripted host around the virtual rig: sends commands, keeps the link alive, decodes every
//! byte the rig sends and refuses any that is not a valid frame.
#![allow(dead_code)]

use firmware::virtual_rig::{Probe, VirtualRig, Wire};
use protocol::{Ack, CmdResult, Command, Event, Fault, RigMsg, SeqTracker, StreamDecoder};

pub const MS: u64 = 1_000_000;
pub const S: u64 = 1_000_000_000;

pub struct Session {
    pub vr: VirtualRig,
    pub wire: Wire,
    /// Every frame, with the simulated time (ns) of the control tick that delivered it.
    pub frames: Vec<(u64, u16, RigMsg)>,
    pub probes: Vec<Probe>,
    /// Frames missing according to the sequence numbers.
    pub seq_gaps: u64,
    /// Send a Heartbeat every 500 ms.
    pub heartbeat: bool,
    next_seq: u16,
    decoder: StreamDecoder,
    seq: SeqTracker,
    decoded_upto: usize,
}

impl Session {
    pub fn new(vr: VirtualRig) -> Self {
        Self {
            vr,
            wire: Wire::default(),
            frames: Vec::new(),
            probes: Vec::new(),
            seq_gaps: 0,
            heartbeat: true,
            next_seq: 100,
            decoder: StreamDecoder::new(),
            seq: SeqTracker::new(),
            decoded_upto: 0,
        }
    }

    pub fn prototype() -> Self {
        Self::new(VirtualRig::prototype())
    }

    /// Queues a command; returns its sequence number.
    pub fn command(&mut self, command: Command) -> u16 {
        let seq = self.next_seq;
        self.next_seq = seq.wrapping_add(1);
        self.wire.command(seq, &command);
        seq
    }

    /// Runs for `ns` of simulated time.
    pub fn run(&mut self, ns: u64) {
        let end = self.vr.now_ns() + ns;
        while self.vr.now_ns() < end {
            let chunk_end = (self.vr.now_ns() + 500 * MS).min(end);
            if self.heartbeat {
                self.command(Command::Heartbeat);
            }
            let probes = &mut self.probes;
            let mut wire = std::mem::take(&mut self.wire);
            let frames_before = self.frames.len();
            self.vr.run_until(chunk_end, &mut wire, |p| probes.push(*p));
            self.wire = wire;
            self.decode(frames_before);
        }
    }

    fn decode(&mut self, _from: usize) {
        let now = self.vr.now_ns();
        let bytes = &self.wire.from_rig[self.decoded_upto..];
        self.decoded_upto = self.wire.from_rig.len();
        let frames = &mut self.frames;
        let seq = &mut self.seq;
        let gaps = &mut self.seq_gaps;
        self.decoder.feed::<RigMsg>(bytes, |e| match e {
            Event::Frame { seq: s, msg, .. } => {
                *gaps += u64::from(seq.observe(s));
                frames.push((now, s, msg));
            }
            Event::Error { offset, error, .. } => panic!("invalid frame at byte {offset}: {error}"),
        });
    }

    pub fn msgs(&self) -> impl Iterator<Item = &RigMsg> {
        self.frames.iter().map(|(_, _, m)| m)
    }

    pub fn ack_for(&self, seq: u16) -> Option<CmdResult> {
        self.msgs().find_map(|m| match m {
            RigMsg::Ack(Ack { cmd_seq, result }) if *cmd_seq == seq => Some(*result),
            _ => None,
        })
    }

    pub fn faults(&self) -> Vec<Fault> {
        self.msgs()
            .filter_map(|m| match m {
                RigMsg::Fault(f) => Some(f.fault),
                _ => None,
            })
            .collect()
    }

    /// Position in `frames` of the first message matching `pred`.
    pub fn position(&self, pred: impl Fn(&RigMsg) -> bool) -> Option<usize> {
        self.frames.iter().position(|(_, _, m)| pred(m))
    }

    /// Unwraps a wrapping µs timestamp relative to the rig's t0.
    pub fn unwrap_us(&self, t_us: u32) -> u64 {
        u64::from(t_us.wrapping_sub(self.vr.timer_us(0)))
    }
}
