//! Photo-interrupter index: turns hardware captures into [`IndexEdge`]s.
//!
//! Time (TIM5) and encoder count (TIM2) of each edge are latched by timer input capture, so they
//! are exact to one tick whatever the interrupt latency. Only the edge's direction comes from
//! software: the pin level read in the capture interrupt. The plate blocks the beam for tens of
//! milliseconds at any speed the rig runs (≈ 10° of a turn at ≤ 1 Hz), so a level read
//! microseconds after the edge is the level the edge led to.
//!
//! A slow photo-interrupter edge can chatter (several crossings of the input threshold within a
//! few hundred µs). The capture inputs filter out glitches shorter than 12 µs
//! ([`INDEX_FILTER_US`]); what still chatters is rejected here: an edge less than
//! [`INDEX_CHATTER_COUNTS`] of table angle after the last accepted edge is not an index edge (the
//! plate is ≈ 10° long, so its two real edges are ≈ 9 000 counts apart).

use protocol::{Edge, IndexEdge};

/// Encoder counts (0.1°, 300 µs at 0.5 Hz) within which a further index edge is chatter.
pub const INDEX_CHATTER_COUNTS: u32 = 90;

/// Glitches the index capture inputs ignore, µs: ICxF = 1111 (8 samples at f_DTS/32) with
/// CKD = ÷4, f_DTS = 21 MHz: 8 × 32 / 21 MHz = 12.2 µs, alike on TIM2 and TIM5
/// ([`crate::input_filter::INDEX_FILTER_NS`]).
pub const INDEX_FILTER_US: f32 = crate::input_filter::INDEX_FILTER_NS as f32 / 1e3;

/// Builds index edges, rejects chatter and counts edges that went missing. The counts are totals
/// since reset that wrap modulo 2^32, like every counter of the protocol's `Counters` (readers
/// take differences): at the fastest rate, 2 edges per turn at 1 Hz, 68 years to wrap.
#[derive(Debug, Default, Clone)]
pub struct IndexTracker {
    last: Option<Edge>,
    last_encoder: Option<u32>,
    edges: u32,
    missed: u32,
    chatter: u32,
}

impl IndexTracker {
    /// Nothing seen yet.
    pub const fn new() -> Self {
        Self { last: None, last_encoder: None, edges: 0, missed: 0, chatter: 0 }
    }

    /// One capture: timestamp and encoder count latched by the timers, and the input level
    /// (true = beam blocked) after the edge. `overcaptured` is the timer's CCxOF flag: another
    /// edge was captured over this one before it was read. `None`: chatter, rejected.
    pub fn capture(&mut self, t_us: u32, encoder: u32, level_after: bool, overcaptured: bool) -> Option<IndexEdge> {
        if let Some(last) = self.last_encoder {
            // Either direction of rotation: the angle travelled since the last accepted edge.
            if (encoder.wrapping_sub(last) as i32).unsigned_abs() < INDEX_CHATTER_COUNTS {
                self.chatter = self.chatter.wrapping_add(1);
                return None;
            }
        }
        self.last_encoder = Some(encoder);
        let edge = if level_after { Edge::Rising } else { Edge::Falling };
        // Edges alternate; two alike in a row mean one was lost in between.
        if self.last == Some(edge) || overcaptured {
            self.missed = self.missed.wrapping_add(1);
        }
        self.last = Some(edge);
        self.edges = self.edges.wrapping_add(1);
        Some(IndexEdge { t_us, encoder, edge })
    }

    /// Edges rejected as chatter.
    pub fn chatter(&self) -> u32 {
        self.chatter
    }

    /// Edges captured.
    pub fn edges(&self) -> u32 {
        self.edges
    }

    /// Edges known to be lost.
    pub fn missed(&self) -> u32 {
        self.missed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn captures_pass_through_and_polarity_follows_the_level() {
        let mut ix = IndexTracker::new();
        let e = ix.capture(u32::MAX, 7, true, false);
        assert_eq!(e, Some(IndexEdge { t_us: u32::MAX, encoder: 7, edge: Edge::Rising }));
        assert_eq!(ix.capture(55_000, 9_007, false, false).unwrap().edge, Edge::Falling);
        assert_eq!((ix.edges(), ix.missed()), (2, 0));
    }

    /// Issue 28: the counters wrap explicitly (a plain `+=` panics on overflow in a debug build
    /// and wraps silently in a release one).
    #[test]
    fn the_counters_wrap() {
        let mut ix = IndexTracker { edges: u32::MAX, missed: u32::MAX, chatter: u32::MAX, ..IndexTracker::new() };
        ix.capture(0, 0, true, true);
        ix.capture(1, 10, false, false);
        assert_eq!((ix.edges(), ix.missed(), ix.chatter()), (0, 0, 0));
    }

    #[test]
    fn repeated_polarity_or_overcapture_counts_a_lost_edge() {
        let mut ix = IndexTracker::new();
        ix.capture(0, 0, true, false);
        ix.capture(1, 9_000, true, false);
        assert_eq!(ix.missed(), 1);
        ix.capture(2, 18_000, false, true);
        assert_eq!((ix.edges(), ix.missed()), (3, 2));
    }

    /// B4: a slow edge that crosses the threshold several times within a few hundred µs gives
    /// one index edge, the first crossing, in either direction of rotation and across the
    /// counter's wrap; the next real edge (the plate's other end) still comes through.
    #[test]
    fn chatter_within_a_tenth_of_a_degree_is_one_edge() {
        for (start, step) in [(1_000u32, 1i32), (u32::MAX - 20, 1), (500, -1)] {
            let at = |counts: i32| start.wrapping_add_signed(step * counts);
            let mut ix = IndexTracker::new();
            let first = ix.capture(10, at(0), true, false).unwrap();
            assert_eq!((first.encoder, first.edge), (at(0), Edge::Rising));
            // Bounces: falling, rising, falling, rising within 60 counts (≈ 0.2 ms at 0.5 Hz).
            for (k, level) in [(15, false), (30, true), (45, false), (60, true)] {
                assert_eq!(ix.capture(10 + k as u32, at(k), level, false), None, "bounce at {k}");
            }
            // The plate's trailing edge, ≈ 10° on.
            let trailing = ix.capture(30_000, at(9_000), false, false).unwrap();
            assert_eq!(trailing.edge, Edge::Falling);
            assert_eq!((ix.edges(), ix.missed(), ix.chatter()), (2, 0, 4));
        }
    }
}
