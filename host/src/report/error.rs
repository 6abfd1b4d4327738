//! Why a figure could not be drawn: shared by the charting layer (`chart`, `scale`) and the
//! figures built on it (`plots`), so that no two of them import each other.

/// Why a figure could not be drawn.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlotError {
    /// No series has a drawable point (all empty, NaN, or ≤ 0 on a log axis).
    #[error("nothing to plot: every series is empty or NaN (or ≤ 0, for a log axis)")]
    NoFiniteData,
    /// An explicit range that is empty, reversed, not finite, or ≤ 0 on a log axis.
    #[error("invalid {axis} range [{lo}, {hi}]{}", if *log { " for a log axis" } else { "" })]
    InvalidRange {
        /// "x" or "y".
        axis: &'static str,
        /// Lower end as given.
        lo: f64,
        /// Upper end as given.
        hi: f64,
        /// Whether the axis is logarithmic.
        log: bool,
    },
    /// A per-point companion vector (band bound, bar values…) of the wrong length.
    #[error("series \"{series}\": {what} has {got} values for {expected} points")]
    LengthMismatch {
        /// Series label.
        series: String,
        /// Which vector.
        what: &'static str,
        /// Length it should have.
        expected: usize,
        /// Length it has.
        got: usize,
    },
    /// A figure too small to hold legible text, or absurdly large.
    #[error("figure size {width}×{height} px is outside 240…8000 × 160…8000 px")]
    InvalidSize {
        /// Width asked for, px.
        width: u32,
        /// Height asked for, px.
        height: u32,
    },
    /// The SVG backend failed (it writes to a string, so this indicates a plotters bug).
    #[error("SVG backend: {0}")]
    Backend(String),
}
