//! Frame writer: numbers and encodes rig messages exactly as the firmware does.

use protocol::{encode_frame, RigMsg, MAX_FRAME_LEN};
use std::io::{self, Write};

/// Encodes each message with the next sequence number (wrapping u16, starting at 0 at power-up)
/// and writes the frame. Counts frames for the `Counters` message.
pub struct FrameWriter<W: Write> {
    out: W,
    seq: u16,
    frames: u32,
    bytes: u64,
    buf: [u8; MAX_FRAME_LEN],
}

impl<W: Write> FrameWriter<W> {
    /// A writer whose first frame gets sequence number 0.
    pub fn new(out: W) -> Self {
        Self { out, seq: 0, frames: 0, bytes: 0, buf: [0; MAX_FRAME_LEN] }
    }

    /// Encodes and writes one frame.
    pub fn send(&mut self, msg: &RigMsg) -> io::Result<()> {
        // Every RigMsg fits MAX_PAYLOAD_LEN by the protocol's construction; a failure is a bug.
        let n = encode_frame(self.seq, msg, &mut self.buf)
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, format!("encoding {msg:?}: {e}")))?;
        self.out.write_all(&self.buf[..n])?;
        self.seq = self.seq.wrapping_add(1);
        self.frames = self.frames.wrapping_add(1);
        self.bytes += n as u64;
        Ok(())
    }

    /// Frames sent so far (wrapping, as in `Counters::frames_sent`).
    pub fn frames_sent(&self) -> u32 {
        self.frames
    }

    /// Bytes written so far.
    pub fn bytes_written(&self) -> u64 {
        self.bytes
    }

    /// The underlying writer.
    pub fn get_mut(&mut self) -> &mut W {
        &mut self.out
    }

    /// Returns the underlying writer.
    pub fn into_inner(self) -> W {
        self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::{Event, RunStopped, StreamDecoder};

    #[test]
    fn frames_carry_consecutive_sequence_numbers_and_decode() {
        let mut w = FrameWriter::new(Vec::new());
        for tag in 0..5u8 {
            w.send(&RigMsg::RunStopped(RunStopped { t_us: 7, run_tag: tag })).unwrap();
        }
        assert_eq!(w.frames_sent(), 5);
        let bytes = w.into_inner();
        let mut seqs = Vec::new();
        StreamDecoder::new().feed::<RigMsg>(&bytes, |ev| match ev {
            Event::Frame { seq, msg: RigMsg::RunStopped(r), .. } => seqs.push((seq, r.run_tag)),
            other => panic!("{other:?}"),
        });
        assert_eq!(seqs, (0..5).map(|i| (i as u16, i as u8)).collect::<Vec<_>>());
    }
}
