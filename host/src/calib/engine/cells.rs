//! Cells: a pass may sum a few consecutive samples into one row before it forms their
//! cross-products. A cell of m samples enters as (Σx)/√m against (Σe)/√m, so XᵀX and Xᵀe are
//! those of the cells' means, each weighted by its count: the least-squares problem of the cell
//! means, which is unbiased for any model linear in its columns (a mean of the model is the
//! model of the mean columns) and loses only the information of the columns' variation within a
//! cell. Over a cell of T s that is (2π·f·T)²/12 of a column at f Hz; over [`CELL_S`], 8e-5 at the
//! tables' 0.5 Hz and 2 % at the 8 Hz of a 16-pole gear's mesh. eᵀe and the counts stay those of
//! the samples.
//!
//! Within a cell the chain is evaluated at a few nodes only (three in a short cell, five in a
//! long one), and the columns and the model's output summed over the samples through the
//! polynomial through them ([`super::nodes`]): what a pass costs falls by about the samples per
//! node (four at 800 Hz in short cells, eight in long ones), and its cross-products by the
//! cell's size. A pass's cells are long where none of its columns varies fast enough to lose
//! more than [`CELL_INFORMATION_LOSS`] of its information in them (each effect states its
//! fastest line, [`crate::calib::effects::Behaviour::turn_multiple`]).

/// The span of a short cell, s: 10 ms, a twelfth of the period of a 16-pole gear's mesh at the
/// default rig's speed (8 Hz at 180 °/s). An engineering judgement: the information a cell loses
/// (see the module's doc) stays below 1e-4 for M's columns and 2 % for a pole pass's; the
/// catalogue's highest harmonics lose more (19 % at 48×, 24 Hz), which widens their own σ and
/// leaves them unbiased. Its three nodes are 5 ms apart.
pub const CELL_S: f64 = 0.01;

/// The span of a long cell, s: four short cells, with five nodes 10 ms apart (a quartic through
/// them: about 0.03·(ω·h)⁵ of a column at ω rad/s between nodes h s apart, 1e-9 of M's columns
/// at the tables' 0.5 Hz, so the model's output, and with it eᵀe, is as exact as in a short
/// cell). A pass takes long cells when none of its columns loses more than
/// [`CELL_INFORMATION_LOSS`] in them.
pub const LONG_CELL_S: f64 = 0.04;

/// The most information a long cell may take from any column of its pass, (2π·f·T)²/12 at the
/// column's fastest line f: 2 %, which widens that column's σ by 1 % and its test's noise by as
/// much (an engineering judgement: short cells take 2-19 % from the gear meshes). M's own columns
/// lose 1.3e-3 at 0.5 Hz.
pub const CELL_INFORMATION_LOSS: f64 = 0.02;

/// How a pass sums its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cells {
    /// Every sample its own row, the chain evaluated at each.
    Exact,
    /// Samples summed over cells, the chain evaluated at a few nodes of each: long cells where
    /// every column of the pass varies slowly enough, short ones elsewhere.
    Span,
}

/// The cells of one run in one pass: their samples and the intervals between their nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellForm {
    /// Samples per cell (1: sample by sample).
    pub size: usize,
    /// Intervals between a cell's nodes, equally spaced by sample (2: a quadratic through three).
    pub intervals: usize,
}

impl CellForm {
    /// Short cells ([`CELL_S`]) at `sample_rate_hz`: what the diagnostics' walk takes.
    pub fn short(sample_rate_hz: f64) -> Self {
        Self { size: ((CELL_S * sample_rate_hz).floor() as usize).max(1), intervals: 2 }
    }
}

impl Cells {
    /// The cells at `sample_rate_hz` for a pass whose fastest column varies at `fastest_hz`.
    pub fn form(self, sample_rate_hz: f64, fastest_hz: f64) -> CellForm {
        match self {
            Cells::Exact => CellForm { size: 1, intervals: 0 },
            Cells::Span if information_lost(fastest_hz, LONG_CELL_S) <= CELL_INFORMATION_LOSS => {
                let size = ((LONG_CELL_S * sample_rate_hz).floor() as usize).max(1);
                CellForm { size, intervals: 4.min(size) }
            }
            Cells::Span => CellForm::short(sample_rate_hz),
        }
    }
}

/// The share of a column's information at `f_hz` that its means over `span_s` lose.
fn information_lost(f_hz: f64, span_s: f64) -> f64 {
    (std::f64::consts::TAU * f_hz * span_s).powi(2) / 12.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At 800 Hz a short cell is eight samples, a long one 32 with nodes eight apart; a pass
    /// takes long cells up to a fastest line of 1.95 Hz (2 % lost over 40 ms), which at 180 °/s
    /// is 3.9× the turn.
    #[test]
    fn a_pass_takes_long_cells_only_where_its_columns_vary_slowly() {
        let long = CellForm { size: 32, intervals: 4 };
        let short = CellForm { size: 8, intervals: 2 };
        assert_eq!(Cells::Span.form(800.0, 1.5), long);
        assert_eq!(Cells::Span.form(800.0, 1.94), long);
        assert_eq!(Cells::Span.form(800.0, 1.96), short);
        assert_eq!(Cells::Span.form(800.0, 12.0), short);
        assert_eq!(Cells::Span.form(50.0, 12.0), CellForm { size: 1, intervals: 2 });
        assert_eq!(Cells::Span.form(50.0, 0.5), CellForm { size: 2, intervals: 2 });
        assert_eq!(Cells::Exact.form(800.0, 0.5).size, 1);
        assert!((information_lost(0.5, LONG_CELL_S) - 1.316e-3).abs() < 1e-6);
    }
}
