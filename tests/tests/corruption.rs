//! Damaged captures: every lost byte and frame is accounted for exactly, at its offset, and the
//! calibration from what remains is still right.

use e2e::{assert_within_3_sigma, committed, frames};
use host::calib::{self, CalOptions};
use host::capture::{decode, RunOrigin};
use host::geometry::Pose;
use protocol::{FrameError, RigMsg, StreamDecoder};

/// Frame indices hit by the damage: spread over both runs, away from run boundaries.
fn victims(n_frames: usize, count: usize) -> Vec<usize> {
    (0..count).map(|k| 50 + k * (n_frames - 100) / count).collect()
}

fn calibrates_to_truth(bytes: &[u8], context: &str) {
    let (_, truth) = committed("demo");
    let cap = decode(bytes);
    let report = calib::calibrate(&cap.runs, &CalOptions::default()).expect(context);
    assert_within_3_sigma(&report, &truth, context);
}

#[test]
fn flipped_bits_cost_exactly_the_frames_they_hit() {
    let (clean, _) = committed("demo");
    let f = frames(&clean);
    let hit = victims(f.len(), 40);
    let mut bytes = clean.clone();
    for &k in &hit {
        let (start, len) = f[k];
        let i = start + len / 2;
        // Flip a bit without making a 0x00 (which would split the frame into two errors).
        let mask = if bytes[i] == 0x01 { 0x02 } else { 0x01 };
        bytes[i] ^= mask;
    }
    let cap = decode(&bytes);
    let loss = &cap.loss;
    assert_eq!(loss.errors.len(), hit.len());
    for (e, &k) in loss.errors.iter().zip(&hit) {
        assert_eq!((e.offset, e.len), (f[k].0 as u64, f[k].1 as u64));
        assert!(matches!(e.error, FrameError::Crc { .. } | FrameError::Cobs), "{e:?}");
    }
    assert_eq!(loss.frames_missing(), hit.len() as u64);
    assert_eq!(loss.frames_ok, (f.len() - hit.len()) as u64);
    assert_eq!(loss.bytes_skipped(), hit.iter().map(|&k| f[k].1 as u64).sum::<u64>());
    calibrates_to_truth(&bytes, "40 flipped bits");
}

#[test]
fn dropped_bytes_cost_exactly_the_frames_they_hit() {
    let (clean, _) = committed("demo");
    let f = frames(&clean);
    let hit = victims(f.len(), 25);
    let mut bytes = clean.clone();
    // Remove from the back so earlier offsets stay valid.
    for &k in hit.iter().rev() {
        bytes.remove(f[k].0 + 2);
    }
    let cap = decode(&bytes);
    assert_eq!(cap.loss.errors.len(), hit.len());
    for (n, (e, &k)) in cap.loss.errors.iter().zip(&hit).enumerate() {
        // Each earlier removal shifts the offset by one byte.
        assert_eq!((e.offset, e.len), ((f[k].0 - n) as u64, (f[k].1 - 1) as u64));
    }
    assert_eq!(cap.loss.frames_missing(), hit.len() as u64);
    calibrates_to_truth(&bytes, "25 dropped bytes");
}

#[test]
fn a_garbage_burst_between_frames_is_one_located_error_and_loses_no_frame() {
    let (clean, _) = committed("demo");
    let f = frames(&clean);
    let at = f[3000].0; // a frame boundary
    let garbage: Vec<u8> = (0..500u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8 | 1).collect();
    let mut bytes = clean[..at].to_vec();
    bytes.extend(&garbage);
    bytes.push(0); // the burst ends with a zero, as line noise eventually does
    bytes.extend(&clean[at..]);
    let cap = decode(&bytes);
    assert_eq!(cap.loss.errors.len(), 1);
    let e = cap.loss.errors[0];
    assert_eq!((e.offset, e.len, e.error), (at as u64, 500, FrameError::TooLong));
    assert_eq!(cap.loss.frames_missing(), 0);
    assert_eq!(cap.loss.frames_ok, f.len() as u64);
}

#[test]
fn a_truncated_capture_reports_its_tail_and_calibrates_from_the_rest() {
    let (clean, _) = committed("demo");
    let f = frames(&clean);
    // Cut 80 % of the way through, in the middle of a frame of pose 2.
    let k = f.len() * 4 / 5;
    let cut = f[k].0 + 4;
    let cap = decode(&clean[..cut]);
    assert_eq!(cap.loss.errors.len(), 1);
    assert_eq!(
        cap.loss.errors[0],
        host::capture::StreamError { offset: f[k].0 as u64, len: 4, error: FrameError::Truncated }
    );
    assert_eq!(cap.runs.len(), 2);
    assert!(cap.runs[0].stopped && !cap.runs[1].stopped, "pose 2 ends with the data, not with RunStopped");
    calibrates_to_truth(&clean[..cut], "truncated");
}

#[test]
fn a_lost_run_start_is_recovered_from_the_motor_status() {
    let (clean, _) = committed("demo");
    let f = frames(&clean);
    // Find pose 2's RunStarted frame and destroy it.
    let mut dec = StreamDecoder::new();
    let mut start_of_pose2 = None;
    dec.feed::<RigMsg>(&clean, |ev| {
        if let protocol::Event::Frame { offset, msg: RigMsg::RunStarted(rs), .. } = ev {
            if rs.run_tag == Pose::Two.run_tag() {
                start_of_pose2 = Some(offset as usize);
            }
        }
    });
    let at = start_of_pose2.expect("pose 2 starts");
    let len = f.iter().find(|(s, _)| *s == at).unwrap().1;
    let mut bytes = clean.clone();
    bytes[at + 1] ^= 0x40;
    let cap = decode(&bytes);
    assert_eq!(cap.loss.errors.len(), 1);
    assert_eq!((cap.loss.errors[0].offset, cap.loss.errors[0].len), (at as u64, len as u64));
    assert_eq!(cap.runs.len(), 2);
    let run = &cap.runs[1];
    assert_eq!((run.pose, run.origin, run.commanded_rate_dps()), (Pose::Two, RunOrigin::Recovered, 180.0));
    // Samples between the lost start and the first motor status (≤ 0.1 s) are orphaned and
    // counted, never silently attributed.
    assert!(cap.loss.orphan_samples > 0 && cap.loss.orphan_samples <= 81, "{}", cap.loss.orphan_samples);
    calibrates_to_truth(&bytes, "lost RunStarted");
}

/// F5: one flipped bit in each `Hello` no longer makes the capture unusable: the runs open with
/// the protocol's rig constants and their own `RunStarted` gyro settings, the loss report says
/// so, and the calibration is still right.
#[test]
fn a_lost_hello_leaves_the_runs_usable() {
    let (clean, _) = committed("demo");
    let mut bytes = clean.clone();
    let mut hit = 0;
    let mut scratch = [0u8; protocol::MAX_FRAME_LEN];
    for (start, len) in frames(&clean) {
        if let Ok((_, RigMsg::Hello(_))) =
            protocol::frame::decode_frame::<RigMsg>(&clean[start..start + len], &mut scratch)
        {
            let i = start + len / 2;
            bytes[i] ^= if bytes[i] == 0x01 { 0x02 } else { 0x01 };
            hit += 1;
        }
    }
    assert!(hit >= 1);
    let cap = decode(&bytes);
    assert!(cap.hello.is_none() && cap.loss.hello_assumed);
    assert_eq!(cap.runs.len(), decode(&clean).runs.len());
    assert_eq!(cap.loss.errors.len(), hit);
    let text = host::inspect::inspect("demo.cap", &cap).to_string();
    assert!(text.contains("the Hello was lost"), "{text}");
    calibrates_to_truth(&bytes, "demo with its Hello lost");
}

/// F8: garbage costs bounded memory: the first `MAX_LOSS_RECORDS` bad stretches are listed,
/// the rest only counted, and every byte is still accounted for.
#[test]
fn garbage_is_summarised_beyond_the_cap() {
    use host::capture::MAX_LOSS_RECORDS;
    // 4 MiB of xorshift noise: ≈ 16 000 zero bytes, so ≈ 16 000 bad stretches.
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    let noise: Vec<u8> = (0..4 << 20)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect();
    let cap = host::capture::decode_reader(&noise[..]).unwrap();
    let l = &cap.loss;
    assert_eq!(l.errors.len(), MAX_LOSS_RECORDS);
    assert!(l.error_count() > 10 * MAX_LOSS_RECORDS as u64, "{} stretches", l.error_count());
    // Every byte but the 0x00 delimiters is skipped.
    let zeros = noise.iter().filter(|&&b| b == 0).count() as u64;
    assert_eq!((l.bytes_skipped() + zeros, l.frames_ok), (noise.len() as u64, 0));
    let json = serde_json::to_string(&host::inspect::inspect("noise", &cap)).unwrap();
    assert!(json.len() < 200_000, "inspect --json is {} bytes", json.len());
}

/// Issue 24, item 3: 1000 bits flipped at random (xorshift64*, seeds 1-20) all over the demo
/// capture, calibrated as `host calibrate --replay` does (the closed loop). Each flip costs its
/// frame, and at ≈ 1 frame in 16 lost the gaps leave the fit a few dozen samples per run: what
/// comes out is either refused (exit 1) or flagged (exit 3), never certified (exit 0) off the
/// truth. |z| as `../shared/validation/check.py` reckons it (21 values).
#[test]
fn a_thousand_flipped_bits_never_certify_a_calibration_off_the_truth() {
    use host::calib::result::truth_check::max_z_against_m;
    use host::calib::{close_loop, LoopOptions, Verdict};
    let (clean, truth) = committed("demo");
    let mut certified_off = Vec::new();
    for seed in 1..=20u64 {
        let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut bytes = clean.clone();
        for _ in 0..1000 {
            x ^= x >> 12;
            x ^= x << 25;
            x ^= x >> 27;
            let bit = (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) % (bytes.len() as u64 * 8);
            bytes[(bit / 8) as usize] ^= 1 << (bit % 8);
        }
        let cap = decode(&bytes);
        let (exit, z, what) = match close_loop(&cap.runs, &LoopOptions::default(), None) {
            Ok(r) => {
                let exit = if r.verdict() == Verdict::AtNoiseFloor { 0 } else { 3 };
                (exit, max_z_against_m(r.final_report(), &truth.m_counts_per_dps), format!("{:?}", r.verdict()))
            }
            Err(e) => (1, f64::NAN, e.to_string()),
        };
        eprintln!("seed {seed:2}: {} frames lost: exit {exit}, max |z| {z:.1}: {what}", cap.loss.frames_missing());
        if exit == 0 && (z.is_nan() || z > 4.0) {
            certified_off.push((seed, z));
        }
    }
    assert!(certified_off.is_empty(), "certified off the truth (seed, max |z|): {certified_off:?}");
}
