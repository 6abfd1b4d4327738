//! Photo-interrupter index: turns hardware captures into [`IndexEdge`]s.
//!
//! Time (TIM5) and encoder count (TIM2) of each edge are latched by timer input capture, so they
//! are exact to one tick whatever the interrupt latency. Only the edge's direction comes from
//! software: the pin level read in the capture interrupt. The plate blocks the beam for tens of
//! milliseconds at any speed the rig runs (≈ 10° of a turn at ≤ 1 Hz), so a level read
//! microseconds after the edge is the level the edge led to.

use protocol::{Edge, IndexEdge};

/// Builds index edges and counts edges that went missing.
#[derive(Debug, Default, Clone)]
pub struct IndexTracker {
    last: Option<Edge>,
    edges: u32,
    missed: u32,
}

impl IndexTracker {
    /// Nothing seen yet.
    pub const fn new() -> Self {
        Self { last: None, edges: 0, missed: 0 }
    }

    /// One capture: timestamp and encoder count latched by the timers, and the input level
    /// (true = beam blocked) after the edge. `overcaptured` is the timer's CCxOF flag: another
    /// edge was captured over this one before it was read.
    pub fn capture(&mut self, t_us: u32, encoder: u32, level_after: bool, overcaptured: bool) -> IndexEdge {
        let edge = if level_after { Edge::Rising } else { Edge::Falling };
        // Edges alternate; two alike in a row mean one was lost in between.
        if self.last == Some(edge) || overcaptured {
            self.missed += 1;
        }
        self.last = Some(edge);
        self.edges += 1;
        IndexEdge { t_us, encoder, edge }
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
        assert_eq!(e, IndexEdge { t_us: u32::MAX, encoder: 7, edge: Edge::Rising });
        assert_eq!(ix.capture(55_000, 9_007, false, false).edge, Edge::Falling);
        assert_eq!((ix.edges(), ix.missed()), (2, 0));
    }

    #[test]
    fn repeated_polarity_or_overcapture_counts_a_lost_edge() {
        let mut ix = IndexTracker::new();
        ix.capture(0, 0, true, false);
        ix.capture(1, 1, true, false);
        assert_eq!(ix.missed(), 1);
        ix.capture(2, 2, false, true);
        assert_eq!((ix.edges(), ix.missed()), (3, 2));
    }
}
