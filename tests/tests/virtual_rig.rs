//! The virtual rig on a real pseudo-terminal: protocol commands in, valid frames out. The rig runs
//! in lockstep with this test (`virtual_rig --lockstep`): simulated time, not the wall clock, so
//! a loaded machine only makes the test slower.

use e2e::LockstepRig;
use protocol::{
    encode_frame, Ack, CmdResult, Command, Direction, Edge, Event, GyroConfig, RigMsg, SeqTracker, StartRun,
    StreamDecoder, MAX_FRAME_LEN,
};
use std::io::{Read, Write};

/// Heartbeat spacing, simulated ns: well inside the rig's 2 s link timeout.
const HEARTBEAT_NS: u64 = 100_000_000;

struct Rig {
    port: LockstepRig,
    decoder: StreamDecoder,
    seq: SeqTracker,
    next_cmd: u16,
    frames: Vec<RigMsg>,
    errors: Vec<String>,
    missing: u64,
}

impl Rig {
    fn spawn() -> Rig {
        Rig {
            port: LockstepRig::spawn(env!("CARGO_BIN_EXE_virtual_rig"), &[]),
            decoder: StreamDecoder::new(),
            seq: SeqTracker::new(),
            next_cmd: 1,
            frames: Vec::new(),
            errors: Vec::new(),
            missing: 0,
        }
    }

    fn send(&mut self, cmd: Command) -> u16 {
        let seq = self.next_cmd;
        self.next_cmd += 1;
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(seq, &cmd, &mut buf).unwrap();
        self.port.write_all(&buf[..n]).unwrap();
        seq
    }

    /// Reads for `sim_s` simulated seconds, heartbeating every 100 ms of simulated time.
    fn pump(&mut self, sim_s: f64) {
        let until = self.port.now_ns() + (sim_s * 1e9) as u64;
        let mut beat = self.port.now_ns();
        let mut buf = [0u8; 4096];
        while self.port.now_ns() < until {
            if self.port.now_ns() >= beat + HEARTBEAT_NS {
                self.send(Command::Heartbeat);
                beat = self.port.now_ns();
            }
            match self.port.read(&mut buf) {
                Ok(n) => {
                    let (frames, errors, seq, missing) =
                        (&mut self.frames, &mut self.errors, &mut self.seq, &mut self.missing);
                    self.decoder.feed::<RigMsg>(&buf[..n], |e| match e {
                        Event::Frame { seq: s, msg, .. } => {
                            *missing += u64::from(seq.observe(s));
                            frames.push(msg);
                        }
                        Event::Error { offset, error, .. } => errors.push(format!("{offset}: {error}")),
                    });
                }
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => panic!("read: {e}"),
            }
        }
    }

    fn ack(&self, seq: u16) -> Option<CmdResult> {
        self.frames.iter().find_map(|m| match m {
            RigMsg::Ack(Ack { cmd_seq, result }) if *cmd_seq == seq => Some(*result),
            _ => None,
        })
    }
}

#[test]
fn virtual_rig_speaks_the_protocol_over_a_pty() {
    let mut rig = Rig::spawn();
    let identify = rig.send(Command::Identify);
    let configure = rig.send(Command::ConfigureGyro(GyroConfig::DEFAULT));
    rig.pump(0.5);
    assert_eq!(rig.ack(identify), Some(CmdResult::Ok));
    assert_eq!(rig.ack(configure), Some(CmdResult::Ok));
    assert!(matches!(rig.frames.iter().find(|m| matches!(m, RigMsg::Hello(_))),
        Some(RigMsg::Hello(h)) if h.encoder_counts_per_rev == 324_000 && h.gyro == GyroConfig::DEFAULT));

    let start = rig.send(Command::Start(StartRun { rate_mdps: 180_000, direction: Direction::Ccw, run_tag: 1 }));
    rig.pump(8.0);
    let stop = rig.send(Command::Stop);
    rig.pump(3.0);

    assert!(rig.errors.is_empty(), "invalid bytes on the wire: {:?}", rig.errors);
    assert_eq!(rig.missing, 0, "sequence gaps");
    assert_eq!(rig.ack(start), Some(CmdResult::Ok));
    assert_eq!(rig.ack(stop), Some(CmdResult::Ok));
    let msgs = &rig.frames;
    assert!(msgs.iter().any(|m| matches!(m, RigMsg::RunStarted(r) if r.run_tag == 1 && r.rate_mdps == 180_000)));
    assert!(msgs.iter().any(|m| matches!(m, RigMsg::RunStopped(r) if r.run_tag == 1)));
    assert!(msgs
        .iter()
        .any(|m| matches!(m, RigMsg::Motor(ms) if ms.run_tag == 1 && (ms.speed_cps - 162_000).abs() <= 162)));

    // Samples: timestamps at the gyro's real rate, and the z-ish mean rate of pose 1 at speed.
    let samples: Vec<_> = msgs
        .iter()
        .filter_map(|m| match m {
            RigMsg::Sample(s) => Some(*s),
            _ => None,
        })
        .collect();
    assert!(samples.len() > 8_000, "{} samples", samples.len());
    let periods: Vec<u32> = samples.windows(2).map(|w| w[1].t_us.wrapping_sub(w[0].t_us)).collect();
    assert!(periods.iter().all(|p| (1_234..=1_236).contains(p)), "periods 1235 ± 1 µs (809.6 Hz)");
    // At 180 °/s every pose-1 axis carries θ2'/√3 = 103.9 °/s of mean rate (5 940 counts at
    // 17.5 m°/s) plus a ±147 °/s sinusoid; the imperfect virtual gyro shifts it by a few %.
    let at_speed = &samples[samples.len() / 2..samples.len() / 2 + 1_619]; // ≈ 2 s = one turn
    for axis in 0..3 {
        let mean = at_speed.iter().map(|s| f64::from(s.rate_counts[axis])).sum::<f64>() / at_speed.len() as f64;
        assert!((mean - 5_940.0).abs() < 600.0, "axis {axis} mean {mean} counts");
    }
    let edges: Vec<_> = msgs
        .iter()
        .filter_map(|m| match m {
            RigMsg::Index(e) => Some(*e),
            _ => None,
        })
        .collect();
    assert!(edges.iter().filter(|e| e.edge == Edge::Rising).count() >= 3, "{} index edges", edges.len());
    let counters: Vec<_> = msgs
        .iter()
        .filter_map(|m| match m {
            RigMsg::Counters(c) => Some(*c),
            _ => None,
        })
        .collect();
    assert!(counters.len() >= 10, "counters at 1 Hz over ≈ 11.5 s: {}", counters.len());
    let last = counters.last().unwrap();
    assert_eq!((last.queue_drops, last.rx_errors, last.spi_errors), (0, 0, 0));
    assert!(msgs.iter().any(|m| matches!(m, RigMsg::Temperature(t) if t.raw == 20)));
    assert!(!msgs.iter().any(|m| matches!(m, RigMsg::Fault(_))));
}
