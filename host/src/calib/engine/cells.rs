//! Cells: a pass may sum a few consecutive samples into one row before it forms their
//! cross-products. A cell of m samples enters the sums as (Σx)/√m against (Σe)/√m, so XᵀX and Xᵀe
//! are those of the cells' means, each weighted by its count: the least-squares problem of the
//! cell means, which is unbiased for any model linear in its columns (a mean of the model is the
//! model of the mean columns) and loses only the information of the columns' variation within a
//! cell. Over a cell of T s that is (2π·f·T)²/12 of a column at f Hz; over [`CELL_S`], 8e-5 at the
//! tables' 0.5 Hz and 2 % at the 8 Hz of a 16-pole gear's mesh. eᵀe and the counts stay those of the samples.
//!
//! What a pass then costs in cross-products falls by the cell's size (eight at 800 Hz); the chain
//! is still evaluated at every sample.

/// The span of a cell, s: 10 ms, a twelfth of the period of the highest harmonic the catalogue
/// models at the default rig's speed (a 16-pole gear at 180 °/s meshes at 8 Hz). An engineering
/// judgement: the information a cell loses (see the module's doc) stays below 2 % for every
/// column and below 1e-4 for M's.
pub const CELL_S: f64 = 0.01;

/// How a pass sums its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cells {
    /// Every sample its own row: the fits' sums, from which the reported figures come.
    Exact,
    /// Samples summed over [`CELL_S`]: candidates' scores and consider terms, which rank and
    /// bound rather than report.
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

/// Scratch for the cells of a block of rows.
#[derive(Debug, Default)]
pub(super) struct CellRows {
    /// Samples per cell.
    pub size: usize,
    x: Vec<f64>,
    e: Vec<f64>,
}

impl CellRows {
    pub fn new(size: usize) -> Self {
        Self { size: size.max(1), x: Vec::new(), e: Vec::new() }
    }

    /// The cells of `rows` (each `l` values) and their residuals `e`: see [`CellRows::rows_of`].
    pub fn of<'s>(&'s mut self, x: &'s [f64], e: &'s [f64], l: usize) -> (&'s [f64], &'s [f64]) {
        if self.size == 1 || l == 0 {
            return (x, e);
        }
        let size = self.size;
        Self::residuals(size, e, &mut self.e);
        let x = Self::sum_rows(size, x, l, &mut self.x);
        (x, &self.e)
    }

    /// The cells of `x` (rows of `l` values): consecutive `size` rows each (the last may be
    /// shorter), summed and scaled by 1/√m for their m rows; the rows themselves when a cell is
    /// one row.
    pub fn rows_of<'s>(&'s mut self, x: &'s [f64], l: usize) -> &'s [f64] {
        if self.size == 1 || l == 0 {
            return x;
        }
        Self::sum_rows(self.size, x, l, &mut self.x)
    }

    fn sum_rows<'s>(size: usize, x: &[f64], l: usize, out: &'s mut Vec<f64>) -> &'s [f64] {
        out.clear();
        for rows in x.chunks(l * size) {
            let scale = ((rows.len() / l) as f64).sqrt().recip();
            let at = out.len();
            out.extend_from_slice(&rows[..l]);
            for row in rows[l..].chunks_exact(l) {
                out[at..].iter_mut().zip(row).for_each(|(s, v)| *s += v);
            }
            out[at..].iter_mut().for_each(|s| *s *= scale);
        }
        out
    }

    /// The residuals of the cells of `size` rows whose residuals are `e`, scaled as
    /// [`CellRows::rows_of`] scales their rows, into `out`.
    pub fn residuals(size: usize, e: &[f64], out: &mut Vec<f64>) {
        out.clear();
        out.extend(e.chunks(size.max(1)).map(|es| es.iter().sum::<f64>() * (es.len() as f64).sqrt().recip()));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three cells of 3, 3 and 1 rows: each the sum of its rows over √m, and the Gram of the
    /// cells that of the cell means weighted by their counts.
    #[test]
    fn a_cell_is_its_rows_sum_over_the_root_of_its_count() {
        let x: Vec<f64> = (0..14).map(f64::from).collect(); // 7 rows of 2
        let e = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
        let mut cells = CellRows::new(3);
        let (cx, ce) = cells.of(&x, &e, 2);
        let r3 = 3f64.sqrt();
        let want_x = [6.0 / r3, 9.0 / r3, 24.0 / r3, 27.0 / r3, 12.0, 13.0];
        let want_e = [6.0 / r3, 15.0 / r3, 7.0];
        for (g, w) in cx.iter().zip(&want_x).chain(ce.iter().zip(&want_e)) {
            assert!((g - w).abs() < 1e-12, "{g} against {w}");
        }
        assert_eq!((cx.len(), ce.len()), (6, 3));
        // Σ over cells of (Σx)²/m for column 0: 3·2² + 3·8² + 1·12² = 348.
        let gram00: f64 = cx.chunks_exact(2).map(|r| r[0] * r[0]).sum();
        assert!((gram00 - 348.0).abs() < 1e-9, "{gram00}");
    }

    #[test]
    fn a_one_row_cell_is_the_row() {
        let (x, e) = ([1.0, 2.0, 3.0, 4.0], [0.5, -0.5]);
        let mut cells = CellRows::new(1);
        let (cx, ce) = cells.of(&x, &e, 2);
        assert_eq!((cx, ce), (&x[..], &e[..]));
    }

    #[test]
    fn the_default_rig_sums_eight_samples() {
        assert_eq!(Cells::Span.rows(800.0), 8);
        assert_eq!(Cells::Span.rows(50.0), 1);
        assert_eq!(Cells::Exact.rows(800.0), 1);
    }
}
