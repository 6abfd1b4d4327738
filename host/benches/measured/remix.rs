//! Another sensor seen through a capture we did not write (`validation_remix` bench): every
//! gyro sample's counts mixed by a 3 × 3 matrix A and given fresh noise, every other frame as it
//! was. Whatever the independent model put into the counts (M·ω, the offsets, their drift, Earth,
//! the gears' and the motor's rate errors as the axes see them, the noise) is then A times it, so
//! the capture is that of a sensor whose M is A·M and whose offsets are A·v_off, on the same rig
//! in the same runs: the truth moves exactly, and the tool sees a sensor, a noise draw and
//! cross-axis terms it was never shown. What does not move exactly: a part of the counts that is
//! not the same linear map of ω on every axis, such as a filter or delay that differs between the
//! axes (which A then mixes), and the rounding to counts (0.29 counts rms, under the 3 of fresh
//! noise).

use nalgebra::{Matrix3, Vector3};
use protocol::decoder::{Event, StreamDecoder};
use protocol::frame::{encode_frame, MAX_FRAME_LEN};
use protocol::msg::RigMsg;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde_json::{json, Value};

/// A remix: the matrix A the counts go through, and the σ of the noise added to each, counts.
#[derive(Debug, Clone, PartialEq)]
pub struct Remix {
    pub a: Matrix3<f64>,
    pub noise_counts: f64,
    /// Seeds the noise (each capture's from it and the capture's name).
    pub seed: u64,
    /// Each run cut to its first this many seconds (from its first sample after `RunStarted`),
    /// or whole.
    pub cut_s: Option<f64>,
}

/// Where a capture's run stands while it is cut ([`Remix::cut_s`]).
#[derive(Debug, Default)]
struct Cut {
    /// The run's first sample's time, µs, once a run has started and sent one.
    first_us: Option<u32>,
    /// The first dropped sample's time, µs, once the run is past the cut.
    cut_at_us: Option<u32>,
    /// Frames dropped so far: later frames' sequence numbers close the gap, so the decoder
    /// counts no loss.
    dropped: u16,
}

impl Cut {
    /// Whether the frame `msg` is kept, with a `RunStopped` moved to the cut.
    fn keep(&mut self, cut_s: f64, msg: &mut RigMsg) -> bool {
        match msg {
            RigMsg::RunStarted(_) => (self.first_us, self.cut_at_us) = (None, None),
            RigMsg::RunStopped(stop) => {
                stop.t_us = self.cut_at_us.unwrap_or(stop.t_us);
                (self.first_us, self.cut_at_us) = (None, None);
                return true;
            }
            RigMsg::Sample(s) => {
                let first = *self.first_us.get_or_insert(s.t_us);
                if self.cut_at_us.is_none() && f64::from(s.t_us.wrapping_sub(first)) >= cut_s * 1e6 {
                    self.cut_at_us = Some(s.t_us);
                }
            }
            _ => {}
        }
        let keep = self.cut_at_us.is_none();
        self.dropped = self.dropped.wrapping_add(u16::from(!keep));
        keep
    }
}

/// Spread of A's diagonal about 1: ±3 %, of the order of a MEMS gyro's part-to-part sensitivity
/// spread (engineering judgement: the L3G4200D's datasheet, Table 4, gives the typical value and
/// its ±2 % change over temperature, no initial tolerance).
pub const SCALE_SPREAD: f64 = 0.03;

/// Spread of A's off-diagonal terms, rad: ±1°, the cross-axis sensitivity a MEMS gyro's
/// datasheet allows (±2 % ≈ 1.1°; engineering judgement, none in the L3G4200D's).
pub const CROSS_SPREAD_RAD: f64 = 0.0175;

/// Noise added to each count, σ: 3 counts, a quarter of the independent captures' own noise
/// (12.4 counts rms, 0.22 °/s, on `realistic-2speed-s101`): a fresh draw on top of theirs that
/// raises the floor by 3 %.
pub const NOISE_COUNTS: f64 = 3.0;

impl Remix {
    /// The remix of seed `seed`: A's diagonal uniform within 1 ± [`SCALE_SPREAD`], its other
    /// terms within ±[`CROSS_SPREAD_RAD`], [`NOISE_COUNTS`] of noise.
    pub fn drawn(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let a = Matrix3::from_fn(|i, j| {
            let u: f64 = rng.random_range(-1.0..=1.0);
            if i == j {
                1.0 + SCALE_SPREAD * u
            } else {
                CROSS_SPREAD_RAD * u
            }
        });
        Self { a, noise_counts: NOISE_COUNTS, seed, cut_s: None }
    }

    /// The capture `bytes` (named `name`, which seeds its noise with [`Remix::seed`]) with every
    /// sample's counts remixed, rounded and held to the i16 range, and how many counts that held.
    /// Every other frame is re-encoded as it was, with its sequence number (less the frames a
    /// cut dropped before it). Bytes that were not a valid frame are an error: a remix of a
    /// damaged capture would not be one of the sensor.
    pub fn capture(&self, name: &str, bytes: &[u8]) -> Result<(Vec<u8>, u64), String> {
        let name_hash =
            name.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3));
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ name_hash);
        let noise = Normal::new(0.0, self.noise_counts).map_err(|e| format!("noise σ {}: {e}", self.noise_counts))?;
        let (mut out, mut clipped, mut bad) = (Vec::with_capacity(bytes.len() + bytes.len() / 8), 0u64, None);
        let mut frame = [0u8; MAX_FRAME_LEN + 1];
        let mut decoder = StreamDecoder::new();
        let mut cut = Cut::default();
        decoder.feed::<RigMsg>(bytes, |ev| match ev {
            Event::Frame { seq, mut msg, .. } => {
                if self.cut_s.is_some_and(|c| !cut.keep(c, &mut msg)) {
                    return;
                }
                let msg = match msg {
                    RigMsg::Sample(mut s) => {
                        let x = self.a * Vector3::from(s.rate_counts.map(f64::from));
                        for (c, v) in s.rate_counts.iter_mut().zip(x.iter()) {
                            let r = (v + noise.sample(&mut rng)).round();
                            let held = r.clamp(f64::from(i16::MIN), f64::from(i16::MAX));
                            clipped += u64::from(held != r);
                            *c = held as i16;
                        }
                        RigMsg::Sample(s)
                    }
                    other => other,
                };
                match encode_frame(seq.wrapping_sub(cut.dropped), &msg, &mut frame) {
                    Ok(n) => out.extend_from_slice(&frame[..n]),
                    Err(e) => {
                        bad.get_or_insert(format!("re-encoding frame {seq}: {e:?}"));
                    }
                }
            }
            Event::Error { offset, len, error } => {
                bad.get_or_insert(format!("{len} bytes at offset {offset} are no frame: {error:?}"));
            }
        });
        if let Some(Event::Error { offset, len, .. }) = decoder.finish::<RigMsg>() {
            bad.get_or_insert(format!("{len} bytes at offset {offset} end without a delimiter"));
        }
        bad.map_or(Ok((out, clipped)), |why| Err(format!("{name}: {why}")))
    }

    /// The truth (`truth.json` of `../shared/validation`: `sensor.M`, `k`, `S`, `v_off`) of the
    /// remixed sensor: M' = A·M, v_off' = A·v_off, k' the rows' norms, S' the rows over them.
    /// The rest is kept, with the remix beside it (`remix.a`, `remix.noise_counts`, `remix.seed`).
    pub fn truth(&self, truth: &Value) -> Result<Value, String> {
        let rows = m_true(truth)?;
        let m = Matrix3::from_fn(|i, j| rows[i][j]);
        let v = Vector3::from_fn(|i, _| truth["sensor"]["v_off"][i].as_f64().unwrap_or(f64::NAN));
        if v.iter().any(|x| !x.is_finite()) {
            return Err("truth: sensor.v_off is not 3 numbers".into());
        }
        let (m2, v2) = (self.a * m, self.a * v);
        let rows: Vec<Vec<f64>> = m2.row_iter().map(|r| r.iter().copied().collect()).collect();
        let k: Vec<f64> = m2.row_iter().map(|r| r.norm()).collect();
        let dirs: Vec<Vec<f64>> = m2.row_iter().map(|r| r.normalize().iter().copied().collect()).collect();
        let mut out = truth.clone();
        out["sensor"]["M"] = json!(rows);
        out["sensor"]["k"] = json!(k);
        out["sensor"]["S"] = json!(dirs);
        out["sensor"]["v_off"] = json!(v2.iter().collect::<Vec<_>>());
        let a: Vec<Vec<f64>> = self.a.row_iter().map(|r| r.iter().copied().collect()).collect();
        out["remix"] = json!({ "a": a, "noise_counts": self.noise_counts, "seed": self.seed, "cut_s": self.cut_s });
        Ok(out)
    }
}

/// M of a truth file, `sensor.M`.
pub fn m_true(truth: &Value) -> Result<[[f64; 3]; 3], String> {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = truth["sensor"]["M"][i][j].as_f64().ok_or("truth: sensor.M is not 3 × 3 numbers")?;
        }
    }
    Ok(m)
}

/// Every frame of a capture, in order, or where it is damaged.
pub fn frames(name: &str, bytes: &[u8]) -> Result<Vec<(u16, RigMsg)>, String> {
    let (mut out, mut bad) = (Vec::new(), None);
    let mut decoder = StreamDecoder::new();
    decoder.feed::<RigMsg>(bytes, |ev| match ev {
        Event::Frame { seq, msg, .. } => out.push((seq, msg)),
        Event::Error { offset, len, error } => {
            bad.get_or_insert(format!("{name}: {len} bytes at offset {offset} are no frame: {error:?}"));
        }
    });
    bad.map_or(Ok(out), Err)
}

/// An effect grown `gain` times in a capture we did not write: `base + gain·(with − base)` per
/// count, every other frame `base`'s. `with` must hold `base`'s frames at the same times, the
/// same rig and noise draw with one effect added (`clean-s101` and `gsens-1speed-s101` of
/// `../shared/validation` are such a pair), so the difference is that effect's counts (and the
/// two roundings, at most 0.41 counts rms, times the gain). Its truth is `with`'s for an effect
/// that leaves M alone (a bias: g-sensitivity, Earth's rate).
pub fn grown(name: &str, base: &[u8], with: &[u8], gain: f64) -> Result<Vec<u8>, String> {
    let (base, with) = (frames(name, base)?, frames(name, with)?);
    if base.len() != with.len() {
        return Err(format!("{name}: {} frames against {} in its twin", with.len(), base.len()));
    }
    let mut out = Vec::with_capacity(base.len() * 24);
    let mut frame = [0u8; MAX_FRAME_LEN + 1];
    for (i, ((seq, b), (_, w))) in base.iter().zip(&with).enumerate() {
        let msg = match (b, w) {
            (RigMsg::Sample(sb), RigMsg::Sample(sw)) if sb.t_us == sw.t_us => {
                let mut s = *sb;
                for ((c, &cb), &cw) in s.rate_counts.iter_mut().zip(&sb.rate_counts).zip(&sw.rate_counts) {
                    let v = f64::from(cb) + gain * (f64::from(cw) - f64::from(cb));
                    *c = v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
                }
                RigMsg::Sample(s)
            }
            (RigMsg::Sample(_), _) | (_, RigMsg::Sample(_)) => {
                return Err(format!("{name}: frame {i} is not the same sample in both"));
            }
            _ => *b,
        };
        let n = encode_frame(*seq, &msg, &mut frame).map_err(|e| format!("{name}: re-encoding frame {seq}: {e:?}"))?;
        out.extend_from_slice(&frame[..n]);
    }
    Ok(out)
}
