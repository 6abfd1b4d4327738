//! One frame: `COBS(postcard((seq, msg)) ++ crc32c_le) ++ 0x00`.
//!
//! postcard gives a compact, documented encoding (varints, zigzag) that both sides derive from the
//! same types; COBS makes 0x00 a frame delimiter that can never occur inside a frame, so a reader
//! that starts anywhere in the stream, or loses bytes, resynchronises at the next 0x00; the
//! CRC-32C (Castagnoli) catches corruption that COBS alone would pass.

use crc::{Crc, CRC_32_ISCSI};
use serde::{de::DeserializeOwned, Serialize};

/// CRC-32C: poly 0x1EDC6F41, init 0xFFFFFFFF, reflected in and out, xorout 0xFFFFFFFF,
/// check("123456789") = 0xE3069283. Chosen over CRC-32/ISO-HDLC for its larger Hamming distance
/// on short messages (Koopman, "32-bit CRCs", DSN 2002).
pub const CRC32C: Crc<u32> = Crc::<u32>::new(&CRC_32_ISCSI);

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
    let n = postcard::to_slice(&(seq, msg), &mut raw[..MAX_PAYLOAD_LEN])
        .map_err(|_| FrameError::BufferTooSmall)?
        .len();
    let crc = CRC32C.checksum(&raw[..n]);
    raw[n..n + 4].copy_from_slice(&crc.to_le_bytes());
    let len = cobs::try_encode(&raw[..n + 4], out).map_err(|_| FrameError::BufferTooSmall)?;
    *out.get_mut(len).ok_or(FrameError::BufferTooSmall)? = 0;
    Ok(len + 1)
}

/// Decodes one frame's COBS bytes (delimiter removed) in place into `(seq, msg)`.
pub fn decode_frame<M: DeserializeOwned>(cobs_bytes: &mut [u8]) -> Result<(u16, M), FrameError> {
    let n = cobs::decode_in_place(cobs_bytes).map_err(|_| FrameError::Cobs)?;
    // seq (≥ 1 byte) + variant (≥ 1 byte) + CRC (4 bytes)
    if n < 6 {
        return Err(FrameError::TooShort);
    }
    let (payload, crc_bytes) = cobs_bytes[..n].split_at(n - 4);
    let received = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
    let computed = CRC32C.checksum(payload);
    if received != computed {
        return Err(FrameError::Crc { received, computed });
    }
    match postcard::take_from_bytes::<(u16, M)>(payload) {
        Ok((decoded, [])) => Ok(decoded),
        _ => Err(FrameError::Message),
    }
}
