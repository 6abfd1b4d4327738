//! The stream decoder under damage: exact loss accounting, resynchronisation, never a panic.

use proptest::prelude::*;
use protocol::*;

fn sample(i: u32) -> RigMsg {
    RigMsg::Sample(Sample {
        t_us: i.wrapping_mul(1250),
        encoder: i.wrapping_mul(202),
        rate_counts: [i as i16, -(i as i16), 7],
        status: 0,
    })
}

/// `n` frames with sequence numbers from 0, and the byte offset of each.
fn stream(n: u32) -> (Vec<u8>, Vec<u64>) {
    let mut bytes = Vec::new();
    let mut offsets = Vec::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    for i in 0..n {
        offsets.push(bytes.len() as u64);
        let len = encode_frame(i as u16, &sample(i), &mut buf).unwrap();
        bytes.extend_from_slice(&buf[..len]);
    }
    (bytes, offsets)
}

fn decode_all(bytes: &[u8], chunk: usize) -> Vec<Event<RigMsg>> {
    let mut dec = StreamDecoder::new();
    let mut events = Vec::new();
    for c in bytes.chunks(chunk.max(1)) {
        dec.feed::<RigMsg>(c, |e| events.push(e));
    }
    events.extend(dec.finish());
    events
}

#[test]
fn a_capture_that_starts_mid_frame_loses_only_that_tail() {
    let (frames, offsets) = stream(4);
    // Start 5 bytes into frame 0, as a recorder attached to a running rig would.
    let bytes = &frames[5..];
    let ev = decode_all(bytes, 7);
    let tail = offsets[1] - 5 - 1;
    assert!(matches!(ev[0], Event::Error { offset: 0, len, .. } if len == tail), "{:?}", ev[0]);
    assert!(matches!(ev[1], Event::Frame { offset, seq: 1, .. } if offset == tail + 1));
    assert_eq!(ev.len(), 4);
}

#[test]
fn garbage_glued_to_a_frame_costs_that_frame_and_no_other() {
    let (frames, offsets) = stream(3);
    let mut bytes = vec![0x55, 0x13, 0x37];
    bytes.extend(&frames);
    let ev = decode_all(&bytes, 7);
    assert_eq!(ev.len(), 3);
    assert!(matches!(ev[0], Event::Error { offset: 0, len, .. } if len == 3 + offsets[1] - 1), "{:?}", ev[0]);
    assert!(matches!(ev[1], Event::Frame { seq: 1, .. }));
}

#[test]
fn a_flipped_bit_costs_exactly_its_frame() {
    let (mut bytes, offsets) = stream(10);
    let target = offsets[4] as usize + 6;
    bytes[target] ^= 0x10;
    let ev = decode_all(&bytes, 64);
    let errors: Vec<_> = ev.iter().filter(|e| matches!(e, Event::Error { .. })).collect();
    assert_eq!(errors.len(), 1);
    assert!(
        matches!(errors[0], Event::Error { offset, error: FrameError::Crc { .. }, .. } if *offset == offsets[4]),
        "{:?}",
        errors[0]
    );
    let mut seq = SeqTracker::new();
    let missing: u32 = ev
        .iter()
        .filter_map(|e| match e {
            Event::Frame { seq: s, .. } => Some(u32::from(seq.observe(*s))),
            _ => None,
        })
        .sum();
    assert_eq!(missing, 1);
}

#[test]
fn a_dropped_delimiter_costs_two_frames_and_says_so() {
    let (mut bytes, offsets) = stream(6);
    let delimiter = offsets[3] as usize - 1;
    bytes.remove(delimiter);
    let ev = decode_all(&bytes, 5);
    let frames = ev.iter().filter(|e| matches!(e, Event::Frame { .. })).count();
    assert_eq!(frames, 4);
    assert!(matches!(ev[2], Event::Error { offset, .. } if offset == offsets[2]), "{:?}", ev[2]);
}

#[test]
fn a_truncated_stream_reports_its_tail() {
    let (bytes, offsets) = stream(5);
    let cut = offsets[4] as usize + 5;
    let ev = decode_all(&bytes[..cut], 3);
    assert_eq!(ev.len(), 5);
    assert_eq!(ev[4], Event::Error { offset: offsets[4], len: 5, error: FrameError::Truncated });
}

#[test]
fn an_overlong_run_without_delimiter_is_skipped_in_constant_memory() {
    let (frames, _) = stream(2);
    let mut bytes = vec![0xAB; 10_000];
    bytes.extend(&frames);
    let ev = decode_all(&bytes, 1000);
    // The garbage and the first frame share one delimiter-less run: one error, then frame 1.
    let first = frames.iter().position(|&b| b == 0).unwrap() as u64;
    assert_eq!(ev[0], Event::Error { offset: 0, len: 10_000 + first, error: FrameError::TooLong });
    assert!(matches!(ev[1], Event::Frame { seq: 1, .. }));
    assert_eq!(ev.len(), 2);
}

#[test]
fn sequence_numbers_wrap_without_a_false_loss() {
    let mut t = SeqTracker::new();
    assert_eq!(t.observe(65_534), 0);
    assert_eq!(t.observe(65_535), 0);
    assert_eq!(t.observe(0), 0);
    assert_eq!(t.observe(3), 2);
}

#[test]
fn commands_round_trip() {
    let cmds = [
        Command::Identify,
        Command::Start(StartRun { rate_mdps: 90_000, direction: Direction::Cw, run_tag: 2 }),
        Command::Stop,
        Command::ConfigureGyro(GyroConfig::DEFAULT),
        Command::Heartbeat,
    ];
    let mut bytes = Vec::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    for (i, c) in cmds.iter().enumerate() {
        let n = encode_frame(i as u16, c, &mut buf).unwrap();
        bytes.extend_from_slice(&buf[..n]);
    }
    let mut got = Vec::new();
    StreamDecoder::new().feed::<Command>(&bytes, |e| got.push(e));
    let decoded: Vec<Command> = got
        .into_iter()
        .map(|e| match e {
            Event::Frame { msg, .. } => msg,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(decoded, cmds);
}

/// Bytes in frames, in errors and in delimiters add up to the stream length.
fn accounted(bytes: &[u8], ev: &[Event<RigMsg>]) -> u64 {
    let delimiters = bytes.iter().filter(|&&b| b == 0).count() as u64;
    let in_events: u64 = ev
        .iter()
        .map(|e| match e {
            Event::Frame { offset, .. } => bytes[*offset as usize..].iter().position(|&b| b == 0).unwrap() as u64,
            Event::Error { len, .. } => *len,
        })
        .sum();
    delimiters + in_events
}

proptest! {
    /// Bit flips: never a panic, every byte accounted for exactly once, every frame whose bytes
    /// and preceding delimiter were untouched decodes, and any frame that decodes is the original.
    #[test]
    fn flips_cost_only_the_frames_they_hit(
        n in 1u32..60,
        flips in prop::collection::vec((any::<prop::sample::Index>(), 1u8..=255), 0..8),
        chunk in 1usize..80,
    ) {
        let (clean, offsets) = stream(n);
        let mut bytes = clean.clone();
        let mut touched = vec![false; clean.len()];
        for (at, mask) in flips {
            let i = at.index(bytes.len());
            bytes[i] ^= mask;
            touched[i] = true;
        }
        let ev = decode_all(&bytes, chunk);
        prop_assert_eq!(accounted(&bytes, &ev), bytes.len() as u64);
        for (k, &start) in offsets.iter().enumerate() {
            let start = start as usize;
            let end = offsets.get(k + 1).map_or(clean.len(), |&o| o as usize);
            let lead_ok = start == 0 || !touched[start - 1];
            if lead_ok && !touched[start..end].iter().any(|&t| t) {
                let found = ev.iter().any(|e| matches!(e, Event::Frame { offset, seq, .. }
                    if *offset as usize == start && u32::from(*seq) == k as u32));
                prop_assert!(found, "intact frame {} at {} not decoded", k, start);
            }
        }
        for e in &ev {
            if let Event::Frame { seq, msg, .. } = e {
                prop_assert_eq!(msg, &sample(u32::from(*seq)));
            }
        }
    }

    /// Inserted and removed bytes: never a panic, every byte accounted for, no false frame.
    #[test]
    fn insertions_and_removals_are_accounted_for(
        n in 1u32..60,
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<bool>(), any::<u8>()), 1..8),
        chunk in 1usize..80,
    ) {
        let (mut bytes, _) = stream(n);
        for (at, insert, value) in edits {
            let i = at.index(bytes.len());
            if insert { bytes.insert(i, value) } else { bytes.remove(i); }
            if bytes.is_empty() { break; }
        }
        let ev = decode_all(&bytes, chunk);
        prop_assert_eq!(accounted(&bytes, &ev), bytes.len() as u64);
        for e in &ev {
            if let Event::Frame { seq, msg, .. } = e {
                prop_assert_eq!(msg, &sample(u32::from(*seq)));
            }
        }
    }

    /// Arbitrary bytes never panic the decoder.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..2000), chunk in 1usize..300) {
        let ev = decode_all(&bytes, chunk);
        prop_assert_eq!(accounted(&bytes, &ev), bytes.len() as u64);
    }
}
