//! One frame: `COBS(postcard((seq, msg)) ++ crc32c_le) ++ 0x00`.
//!
//! postcard gives a compact, documented encoding (varints, zigzag) that both sides derive from the
//! same types; COBS makes 0x00 a frame delimiter that can never occur inside a frame, so a reader
//! that starts anywhere in the stream, or loses bytes, resynchronises at the next 0x00; the
//! CRC-32C (Castagnoli) catches corruption that COBS alone would pass.

use crc::{Crc, Table, CRC_32_ISCSI};
use serde::{de::DeserializeOwned, Serialize};

/// CRC-32C: poly 0x1EDC6F41, init 0xFFFFFFFF, reflected in and out, xorout 0xFFFFFFFF,
/// check("123456789") = 0xE3069283. Chosen over CRC-32/ISO-HDLC for its larger Hamming distance
/// on short messages (Koopman, "32-bit CRCs", DSN 2002). This is the byte-table form (1 KiB),
/// which the firmware uses: its flash budget is 64 KiB and it checks only the host's few
/// commands. [`crc32c`] is what both sides call.
pub const CRC32C: Crc<u32, Table<1>> = Crc::<u32, Table<1>>::new(&CRC_32_ISCSI);

/// The [`CRC32C`] of `bytes`. The host (feature `std`) replays hour-long captures, a CRC per
/// ~28-byte frame, so it uses the `crc32c` crate, which runs the CPU's CRC32 instruction (SSE 4.2,
/// ARMv8) where present and a table otherwise: 3 % of a 1-hour replay with slice-by-16 tables.
/// The two agree on every input (`tests/wire.rs`).
#[inline]
pub fn crc32c(bytes: &[u8]) -> u32 {
    #[cfg(feature = "std")]
    {
        crc32c::crc32c(bytes)
    }
    #[cfg(not(feature = "std"))]
    {
        CRC32C.checksum(bytes)
    }
}

/// Largest postcard payload (sequence number plus message) of any message, with margin.
pub const MAX_PAYLOAD_LEN: usize = 48;

/// Largest frame on the wire: payload, 4 CRC bytes, COBS overhead, the 0x00 delimiter.
pub const MAX_FRAME_LEN: usize = cobs::max_encoding_length(MAX_PAYLOAD_LEN + 4) + 1;

/// Why a frame could not be encoded or decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// More bytes than [`MAX_FRAME_LEN`] before a delimiter.
    TooLong,
    /// Bytes that end without a delimiter (end of a truncated capture).
    Truncated,
    /// Not valid COBS.
    Cobs,
    /// Fewer bytes than a sequence number, a message tag and a CRC.
    TooShort,
    /// CRC mismatch.
    Crc {
        /// CRC carried by the frame.
        received: u32,
        /// CRC computed over the payload.
        computed: u32,
    },
    /// CRC good but the payload is not a valid message (unknown variant from a newer peer, or a
    /// bug); also returned when bytes remain after the message.
    Message,
    /// The output buffer is too small (encoding only).
    BufferTooSmall,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FrameError::TooLong => write!(f, "frame longer than {MAX_FRAME_LEN} bytes"),
            FrameError::Truncated => write!(f, "truncated frame (no delimiter before end of data)"),
            FrameError::Cobs => write!(f, "invalid COBS encoding"),
            FrameError::TooShort => write!(f, "frame too short"),
            FrameError::Crc { received, computed } => {
                write!(f, "CRC mismatch (received {received:#010x}, computed {computed:#010x})")
            }
            FrameError::Message => write!(f, "CRC valid but message undecodable"),
            FrameError::BufferTooSmall => write!(f, "output buffer too small"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for FrameError {}

/// Encodes `(seq, msg)` as one complete frame, delimiter included, into `out`; returns its length.
pub fn encode_frame<M: Serialize>(seq: u16, msg: &M, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; MAX_PAYLOAD_LEN + 4];
    let n = postcard::to_slice(&(seq, msg), &mut raw[..MAX_PAYLOAD_LEN]).map_err(|_| FrameError::BufferTooSmall)?.len();
    let crc = crc32c(&raw[..n]);
    raw[n..n + 4].copy_from_slice(&crc.to_le_bytes());
    let len = cobs::try_encode(&raw[..n + 4], out).map_err(|_| FrameError::BufferTooSmall)?;
    *out.get_mut(len).ok_or(FrameError::BufferTooSmall)? = 0;
    Ok(len + 1)
}

/// Decodes one frame's COBS bytes (delimiter removed) into `(seq, msg)`, using `scratch` for
/// the decoded bytes.
pub fn decode_frame<M: DeserializeOwned>(
    cobs_bytes: &[u8],
    scratch: &mut [u8; MAX_FRAME_LEN],
) -> Result<(u16, M), FrameError> {
    let n = cobs_decode(cobs_bytes, scratch)?;
    // seq (≥ 1 byte) + variant (≥ 1 byte) + CRC (4 bytes)
    if n < 6 {
        return Err(FrameError::TooShort);
    }
    let (payload, crc_bytes) = scratch[..n].split_at(n - 4);
    let received = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
    let computed = crc32c(payload);
    if received != computed {
        return Err(FrameError::Crc { received, computed });
    }
    match postcard::take_from_bytes::<(u16, M)>(payload) {
        Ok((decoded, [])) => Ok(decoded),
        _ => Err(FrameError::Message),
    }
}

/// COBS decoding by whole blocks. Hand-rolled because the `cobs` crate (still our encoder, and the
/// reference this is tested against) decodes byte by byte at ~12 instructions per byte, the
/// largest cost of replaying a capture; a frame here is 2-3 blocks, each one `copy_from_slice`.
/// `src` holds no 0x00 (the stream decoder split at them).
fn cobs_decode(src: &[u8], dst: &mut [u8]) -> Result<usize, FrameError> {
    let (mut i, mut n) = (0usize, 0usize);
    while i < src.len() {
        let code = usize::from(src[i]);
        let end = i + code;
        // A block runs past the frame: the frame was cut short or its code byte is corrupt.
        let block = src.get(i + 1..end).ok_or(FrameError::Cobs)?;
        dst.get_mut(n..n + block.len()).ok_or(FrameError::TooLong)?.copy_from_slice(block);
        n += block.len();
        i = end;
        // A code below 0xFF means a zero followed, except after the frame's last block.
        if code < 0xFF && i < src.len() {
            *dst.get_mut(n).ok_or(FrameError::TooLong)? = 0;
            n += 1;
        }
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Agrees with the `cobs` crate on every input it accepts, and rejects what it rejects.
    #[test]
    fn block_decoder_matches_the_cobs_crate() {
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng
        };
        for len in 0..(MAX_PAYLOAD_LEN + 4) {
            for _ in 0..200 {
                // Zero-rich payloads exercise short blocks.
                let raw: heapless_vec::Bytes =
                    (0..len).map(|_| if next() % 4 == 0 { 0 } else { next() as u8 }).collect();
                let mut enc = [0u8; MAX_FRAME_LEN];
                let m = cobs::encode(raw.as_slice(), &mut enc);
                let mut out = [0u8; MAX_FRAME_LEN];
                let got = cobs_decode(&enc[..m], &mut out).unwrap();
                assert_eq!(&out[..got], raw.as_slice());
                // Corrupt one code byte: both decoders must agree on accept/reject, and on the bytes.
                let mut bad = enc;
                let at = (next() as usize) % m.max(1);
                bad[at] = (next() as u8) | 1;
                let mut a = [0u8; 256];
                let mut b = [0u8; 256];
                let ours = cobs_decode(&bad[..m], &mut a).map(|n| a[..n].to_vec());
                let theirs = cobs::decode(&bad[..m], &mut b).map(|r| b[..r.frame_size()].to_vec());
                assert_eq!(ours.is_ok(), theirs.is_ok(), "{:?}", &bad[..m]);
                if let (Ok(x), Ok(y)) = (ours, theirs) {
                    assert_eq!(x, y);
                }
            }
        }
    }

    /// A fixed-capacity byte vector for the no_std test above.
    mod heapless_vec {
        pub struct Bytes {
            buf: [u8; 64],
            len: usize,
        }
        impl Bytes {
            pub fn as_slice(&self) -> &[u8] {
                &self.buf[..self.len]
            }
        }
        impl FromIterator<u8> for Bytes {
            fn from_iter<I: IntoIterator<Item = u8>>(it: I) -> Self {
                let mut b = Bytes { buf: [0; 64], len: 0 };
                for x in it {
                    b.buf[b.len] = x;
                    b.len += 1;
                }
                b
            }
        }
    }
}
