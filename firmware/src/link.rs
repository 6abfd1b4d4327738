//! The rig's end of the wire: numbers and frames outgoing messages into the [`TxQueue`], decodes
//! incoming bytes into host commands. Transport-agnostic: USB CDC on the board, USART1 under
//! QEMU, a pseudo-terminal in the virtual rig.

use crate::tx_queue::{TxQueue, TX_QUEUE_BYTES};
use protocol::{encode_frame, Command, Event, RigMsg, StreamDecoder, MAX_FRAME_LEN};

/// One frame from the host.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Received {
    /// The host's sequence number, echoed in the [`protocol::Ack`].
    pub seq: u16,
    /// The command.
    pub command: Command,
}

/// Outgoing sequence numbering, framing and the transmit queue; incoming frame decoding.
pub struct Link {
    tx: TxQueue<TX_QUEUE_BYTES>,
    /// Sequence number of the next frame. It advances for dropped frames too, so the host can
    /// see each loss as a gap.
    next_seq: u16,
    decoder: StreamDecoder,
    rx_errors: u32,
}

impl Default for Link {
    fn default() -> Self {
        Self::new()
    }
}

impl Link {
    /// A link with nothing sent or received.
    pub const fn new() -> Self {
        Self { tx: TxQueue::new(), next_seq: 0, decoder: StreamDecoder::new(), rx_errors: 0 }
    }

    /// Frames `msg` and queues it; a full queue drops it (counted in the queue).
    pub fn send(&mut self, msg: &RigMsg) {
        let seq = self.next_seq;
        self.next_seq = seq.wrapping_add(1);
        let mut frame = [0u8; MAX_FRAME_LEN];
        match encode_frame(seq, msg, &mut frame) {
            Ok(len) => {
                let _ = self.tx.push_frame(&frame[..len]);
            }
            // Every RigMsg fits MAX_FRAME_LEN (protocol tests); were one not to, it is lost and
            // counted like a queue drop rather than sent truncated.
            Err(_) => self.tx.count_drop(),
        }
    }

    /// Decodes `bytes` from the host; calls `on_command` for each valid command frame and counts
    /// the rest as receive errors.
    pub fn receive(&mut self, bytes: &[u8], mut on_command: impl FnMut(Received)) {
        let rx_errors = &mut self.rx_errors;
        self.decoder.feed::<Command>(bytes, |event| match event {
            Event::Frame { seq, msg, .. } => on_command(Received { seq, command: msg }),
            Event::Error { .. } => *rx_errors = rx_errors.wrapping_add(1),
        });
    }

    /// The transmit queue, to be drained by the transport.
    pub fn tx(&mut self) -> &mut TxQueue<TX_QUEUE_BYTES> {
        &mut self.tx
    }

    /// Frames queued for the host.
    pub fn frames_sent(&self) -> u32 {
        self.tx.frames_queued()
    }

    /// Frames dropped on a full queue.
    pub fn queue_drops(&self) -> u32 {
        self.tx.frames_dropped()
    }

    /// Host frames that failed to decode.
    pub fn rx_errors(&self) -> u32 {
        self.rx_errors
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::{decoder::Event, Ack, CmdResult};

    fn drain(link: &mut Link) -> Vec<(u16, RigMsg)> {
        let mut bytes = vec![0u8; TX_QUEUE_BYTES];
        let n = link.tx().pop_into(&mut bytes);
        let mut out = Vec::new();
        StreamDecoder::new().feed::<RigMsg>(&bytes[..n], |e| match e {
            Event::Frame { seq, msg, .. } => out.push((seq, msg)),
            Event::Error { error, .. } => panic!("bad frame: {error}"),
        });
        out
    }

    #[test]
    fn frames_are_numbered_and_dropped_frames_leave_a_gap() {
        let mut link = Link::new();
        let ack = RigMsg::Ack(Ack { cmd_seq: 7, result: CmdResult::Ok });
        let mut offered = 0u16;
        while link.queue_drops() == 0 {
            link.send(&ack);
            offered += 1;
        }
        let first = drain(&mut link);
        assert_eq!(first.len(), usize::from(offered) - 1);
        assert!(first.iter().enumerate().all(|(i, (seq, m))| *seq == i as u16 && *m == ack));
        link.send(&ack);
        // The dropped frame's number is skipped: the host counts it as missing.
        assert_eq!(drain(&mut link), vec![(offered, ack)]);
        assert_eq!(link.frames_sent(), u32::from(offered));
    }

    #[test]
    fn commands_are_decoded_and_garbage_is_counted() {
        let mut link = Link::new();
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(42, &Command::Heartbeat, &mut buf).unwrap();
        let mut bytes = vec![1, 2, 3, 0];
        bytes.extend_from_slice(&buf[..n]);
        let mut got = Vec::new();
        link.receive(&bytes, |r| got.push(r));
        assert_eq!(got, vec![Received { seq: 42, command: Command::Heartbeat }]);
        assert_eq!(link.rx_errors(), 1);
    }
}
