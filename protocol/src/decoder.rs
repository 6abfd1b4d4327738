//! Streaming decoder: bytes in, frames and located errors out, in constant memory.

use crate::frame::{decode_frame, FrameError, MAX_FRAME_LEN};
use serde::de::DeserializeOwned;

/// What the decoder found in the stream.
#[derive(Debug, Clone, PartialEq)]
pub enum Event<M> {
    /// A valid frame.
    Frame {
        /// Byte offset of the frame's first byte in the stream.
        offset: u64,
        /// Sender's sequence number.
        seq: u16,
        /// The message.
        msg: M,
    },
    /// Bytes that did not form a valid frame; they are skipped.
    Error {
        /// Byte offset of the first skipped byte.
        offset: u64,
        /// Number of bytes skipped, delimiter excluded.
        len: u64,
        /// Why.
        error: FrameError,
    },
}

/// Splits a byte stream at 0x00 delimiters and decodes each frame. It never panics on any input;
/// every byte that is not part of a valid frame is reported once, with its offset.
pub struct StreamDecoder {
    buf: [u8; MAX_FRAME_LEN],
    scratch: [u8; MAX_FRAME_LEN],
    len: usize,
    /// Bytes of the current frame beyond the buffer (a frame that is too long).
    overflow: u64,
    /// Stream offset of the current frame's first byte.
    start: u64,
    /// Stream offset of the next byte to be pushed.
    pos: u64,
}

impl Default for StreamDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl StreamDecoder {
    /// A decoder at stream offset 0.
    pub const fn new() -> Self {
        Self { buf: [0; MAX_FRAME_LEN], scratch: [0; MAX_FRAME_LEN], len: 0, overflow: 0, start: 0, pos: 0 }
    }

    /// Stream offset of the next byte to be pushed (the count of bytes seen).
    pub fn position(&self) -> u64 {
        self.pos
    }

    /// Feeds bytes; calls `on_event` for every frame or error completed by them.
    pub fn feed<M: DeserializeOwned>(&mut self, mut data: &[u8], mut on_event: impl FnMut(Event<M>)) {
        while !data.is_empty() {
            match memchr::memchr(0, data) {
                // The whole frame is in `data`: decode it from there, without buffering.
                Some(i) if self.len == 0 && self.overflow == 0 => {
                    self.pos += i as u64 + 1;
                    if let Some(ev) = self.decode(&data[..i]) {
                        on_event(ev);
                    }
                    data = &data[i + 1..];
                }
                Some(i) => {
                    self.append(&data[..i]);
                    self.pos += 1; // the delimiter
                    if let Some(ev) = self.finish_frame() {
                        on_event(ev);
                    }
                    data = &data[i + 1..];
                }
                None => {
                    self.append(data);
                    data = &[];
                }
            }
        }
    }

    /// Reports bytes left without a delimiter at the end of the stream as
    /// [`FrameError::Truncated`] and resets the frame buffer.
    pub fn finish<M>(&mut self) -> Option<Event<M>> {
        let len = self.len as u64 + self.overflow;
        let offset = self.start;
        self.len = 0;
        self.overflow = 0;
        self.start = self.pos;
        (len > 0).then_some(Event::Error { offset, len, error: FrameError::Truncated })
    }

    fn append(&mut self, bytes: &[u8]) {
        let room = MAX_FRAME_LEN - self.len;
        let take = bytes.len().min(room);
        self.buf[self.len..self.len + take].copy_from_slice(&bytes[..take]);
        self.len += take;
        self.overflow += (bytes.len() - take) as u64;
        self.pos += bytes.len() as u64;
    }

    fn finish_frame<M: DeserializeOwned>(&mut self) -> Option<Event<M>> {
        let offset = self.start;
        let len = self.len as u64 + self.overflow;
        let overflow = self.overflow;
        let n = self.len;
        self.len = 0;
        self.overflow = 0;
        if overflow > 0 {
            self.start = self.pos;
            return Some(Event::Error { offset, len, error: FrameError::TooLong });
        }
        let frame = self.buf;
        self.decode(&frame[..n])
    }

    /// Decodes one complete frame (delimiter already counted in `pos`) that began at `start`.
    fn decode<M: DeserializeOwned>(&mut self, frame: &[u8]) -> Option<Event<M>> {
        let offset = self.start;
        self.start = self.pos;
        if frame.is_empty() {
            // Back-to-back delimiters are allowed (a sender may emit one to resynchronise).
            return None;
        }
        if frame.len() > MAX_FRAME_LEN {
            return Some(Event::Error { offset, len: frame.len() as u64, error: FrameError::TooLong });
        }
        Some(match decode_frame::<M>(frame, &mut self.scratch) {
            Ok((seq, msg)) => Event::Frame { offset, seq, msg },
            Err(error) => Event::Error { offset, len: frame.len() as u64, error },
        })
    }
}

/// Counts frames lost between valid frames from their sequence numbers (wrapping u16).
#[derive(Debug, Default, Clone, Copy)]
pub struct SeqTracker {
    last: Option<u16>,
}

impl SeqTracker {
    /// A tracker that has seen nothing.
    pub const fn new() -> Self {
        Self { last: None }
    }

    /// Records `seq`; returns how many frames are missing just before it. A gap of 2^15 or more
    /// is taken as a sender restart (sequence reset), not a loss, and returns 0.
    pub fn observe(&mut self, seq: u16) -> u16 {
        let missing = match self.last {
            Some(last) => {
                let gap = seq.wrapping_sub(last).wrapping_sub(1);
                if gap >= 0x8000 {
                    0
                } else {
                    gap
                }
            }
            None => 0,
        };
        self.last = Some(seq);
        missing
    }
}
