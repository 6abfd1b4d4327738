//! Cells: a pass may sum a few consecutive samples into one row before it forms their
//! cross-products. A cell of m samples enters as (Σx)/√m against (Σe)/√m, so XᵀX and Xᵀe are
//! those of the cells' means, each weighted by its count: the least-squares problem of the cell
//! means, which is unbiased for any model linear in its columns (a mean of the model is the
//! model of the mean columns) and loses only the information of the columns' variation within a
//! cell. Over a cell of T s that is (2π·f·T)²/12 of a column at f Hz; over [`CELL_S`], 8e-5 at the
//! tables' 0.5 Hz and 2 % at the 8 Hz of a 16-pole gear's mesh. eᵀe and the counts stay those of
//! the samples.
//!
//! Within a cell the chain is evaluated at three nodes only, and the columns and the model's
//! output summed over the samples through the quadratic through them ([`super::nodes`]): what a
//! pass costs falls by about the cell's size (eight samples at 800 Hz).

/// The span of a cell, s: 10 ms, a twelfth of the period of a 16-pole gear's mesh at the default
/// rig's speed (8 Hz at 180 °/s). An engineering judgement: the information a cell loses (see
/// the module's doc) stays below 1e-4 for M's columns and 2 % for a pole pass's; the catalogue's
/// highest harmonics lose more (19 % at 48×, 24 Hz), which widens their own σ and leaves them
/// unbiased.
pub const CELL_S: f64 = 0.01;

/// How a pass sums its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cells {
    /// Every sample its own row, the chain evaluated at each.
    Exact,
    /// Samples summed over [`CELL_S`], the chain evaluated at three nodes of each cell.
    Span,
}

impl Cells {
    /// Samples per cell at `sample_rate_hz` (at least one).
    pub fn rows(self, sample_rate_hz: f64) -> usize {
        match self {
            Cells::Exact => 1,
            Cells::Span => ((CELL_S * sample_rate_hz).floor() as usize).max(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_rig_sums_eight_samples() {
        assert_eq!(Cells::Span.rows(800.0), 8);
        assert_eq!(Cells::Span.rows(50.0), 1);
        assert_eq!(Cells::Exact.rows(800.0), 1);
    }
}
