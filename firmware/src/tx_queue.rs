//! Bounded byte queue of whole frames between the producers (sampling, control loop, commands)
//! and the link (USB or UART). A frame goes in whole or not at all: a full queue drops the new
//! frame and counts it, so the host sees the loss in [`protocol::Counters::queue_drops`] and as a
//! gap in the sequence numbers, never as a torn frame.

use heapless::Deque;

/// Transmit buffer size. At 800 Hz a sample frame is ≈ 20 bytes (16 kB/s), so 2 KiB rides out
/// ≈ 120 ms of a stalled link; USB full speed drains it in well under a millisecond.
pub const TX_QUEUE_BYTES: usize = 2048;

/// A frame did not fit and was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dropped;

/// Bounded FIFO of encoded frames, `N` bytes.
pub struct TxQueue<const N: usize> {
    bytes: Deque<u8, N>,
    frames_queued: u32,
    frames_dropped: u32,
}

impl<const N: usize> Default for TxQueue<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> TxQueue<N> {
    /// An empty queue.
    pub const fn new() -> Self {
        Self { bytes: Deque::new(), frames_queued: 0, frames_dropped: 0 }
    }

    /// Appends one encoded frame, or drops it whole (and counts it) if it does not fit.
    pub fn push_frame(&mut self, frame: &[u8]) -> Result<(), Dropped> {
        if N - self.bytes.len() < frame.len() {
            self.count_drop();
            return Err(Dropped);
        }
        for &b in frame {
            // Cannot fail: room was checked above.
            let _ = self.bytes.push_back(b);
        }
        self.frames_queued = self.frames_queued.wrapping_add(1);
        Ok(())
    }

    /// Counts a frame lost before it reached the queue.
    pub fn count_drop(&mut self) {
        self.frames_dropped = self.frames_dropped.wrapping_add(1);
    }

    /// Moves up to `out.len()` bytes, oldest first, into `out`; returns how many.
    pub fn pop_into(&mut self, out: &mut [u8]) -> usize {
        let mut n = 0;
        while n < out.len() {
            match self.bytes.pop_front() {
                Some(b) => {
                    out[n] = b;
                    n += 1;
                }
                None => break,
            }
        }
        n
    }

    /// Bytes waiting.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    /// Nothing waiting.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// Frames accepted since creation (wrapping).
    pub fn frames_queued(&self) -> u32 {
        self.frames_queued
    }

    /// Frames dropped because the queue was full (wrapping).
    pub fn frames_dropped(&self) -> u32 {
        self.frames_dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn full_queue_drops_whole_frames_and_counts_them() {
        let mut q = TxQueue::<10>::new();
        assert_eq!(q.push_frame(&[1, 2, 3, 0]), Ok(()));
        assert_eq!(q.push_frame(&[4, 5, 6, 0]), Ok(()));
        // 2 bytes of room left: a 4-byte frame must not be split.
        assert_eq!(q.push_frame(&[7, 8, 9, 0]), Err(Dropped));
        assert_eq!(q.push_frame(&[7, 0]), Ok(()));
        assert_eq!((q.frames_queued(), q.frames_dropped(), q.len()), (3, 1, 10));
        let mut out = [0u8; 16];
        assert_eq!(q.pop_into(&mut out), 10);
        assert_eq!(&out[..10], &[1, 2, 3, 0, 4, 5, 6, 0, 7, 0]);
        assert!(q.is_empty());
    }

    proptest! {
        /// Whatever the interleaving of pushes and pops, the bytes that come out are exactly the
        /// accepted frames in order, and accepted + dropped = offered.
        #[test]
        fn output_is_the_accepted_frames_in_order(
            ops in proptest::collection::vec((1usize..40, 0usize..50), 1..200)
        ) {
            let mut q = TxQueue::<64>::new();
            let mut expected = Vec::new();
            let mut got = Vec::new();
            for (i, (frame_len, pop_len)) in ops.iter().enumerate() {
                let frame: Vec<u8> = (0..*frame_len).map(|k| (i + k) as u8).collect();
                if q.push_frame(&frame).is_ok() {
                    expected.extend_from_slice(&frame);
                }
                let mut out = vec![0u8; *pop_len];
                let n = q.pop_into(&mut out);
                got.extend_from_slice(&out[..n]);
            }
            let mut rest = [0u8; 64];
            let n = q.pop_into(&mut rest);
            got.extend_from_slice(&rest[..n]);
            prop_assert_eq!(got, expected);
            prop_assert_eq!((q.frames_queued() + q.frames_dropped()) as usize, ops.len());
        }
    }
}
