//! The sums a pass adds its rows to: per run and axis, the Gram matrix of the columns against the
//! residual ([`Gram`]), the pairs a pass reaches ([`Reach`]), and the blocks that hold rows (a
//! sample's or a cell's) until they are summed, four columns side by side ([`RowBlock`],
//! [`SharedRows`]; the free drift's sparse knots are [`super::knot_split`]'s).

/// Samples summed into a local accumulator before it is added to the run total: rounding error
/// then grows as O(√n) ulp in a long run instead of O(n).
pub(crate) const CHUNK: usize = 1024;

/// Sums of one run (or several) for columns `l`: per axis the Gram matrix, Xᵀe, eᵀe and the
/// count, against the residual e of the model the pass was made at.
#[derive(Debug, Clone, PartialEq)]
pub struct Gram {
    /// Columns.
    pub l: usize,
    /// XᵀX per axis, l×l row-major (full after `symmetrise`).
    pub xtx: [Vec<f64>; 3],
    /// Xᵀe per axis.
    pub xte: [Vec<f64>; 3],
    /// eᵀe per axis, counts².
    pub ete: [f64; 3],
    /// Unclipped samples per axis.
    pub n: [u64; 3],
}

impl Gram {
    /// The sums of columns `keep` (ascending) of `l` columns, from these sums of those columns
    /// alone; every entry of another column is 0.
    pub(super) fn scattered(&self, keep: &[usize], l: usize) -> Self {
        debug_assert_eq!(keep.len(), self.l);
        let mut g = Self { ete: self.ete, n: self.n, ..Self::new(l) };
        for a in 0..3 {
            for (i2, &i) in keep.iter().enumerate() {
                g.xte[a][i] = self.xte[a][i2];
                for (j2, &j) in keep.iter().enumerate() {
                    g.xtx[a][i * l + j] = self.xtx[a][i2 * self.l + j2];
                }
            }
        }
        g
    }

    pub(super) fn new(l: usize) -> Self {
        Self {
            l,
            xtx: std::array::from_fn(|_| vec![0.0; l * l]),
            xte: std::array::from_fn(|_| vec![0.0; l]),
            ete: [0.0; 3],
            n: [0; 3],
        }
    }

    /// Adds the sums of `local` whose rows and columns are all in `rows` (every other entry of
    /// it is zero) and zeroes them in `local`: a chunk touches a few of a long capture's
    /// hundreds of knot columns, and merging and clearing the whole l×l matrix per chunk was
    /// most of a pass (the sums are the same, bit for bit).
    pub(super) fn drain_rows(&mut self, local: &mut Gram, rows: &[usize]) {
        let l = self.l;
        for a in 0..3 {
            for &r in rows {
                self.xte[a][r] += std::mem::take(&mut local.xte[a][r]);
                for &c in rows.iter().filter(|&&c| c >= r) {
                    self.xtx[a][r * l + c] += std::mem::take(&mut local.xtx[a][r * l + c]);
                }
            }
            self.ete[a] += std::mem::take(&mut local.ete[a]);
            self.n[a] += std::mem::take(&mut local.n[a]);
        }
    }

    /// Adds another set of sums.
    pub fn merge(&mut self, o: &Gram) {
        for a in 0..3 {
            self.xtx[a].iter_mut().zip(&o.xtx[a]).for_each(|(x, y)| *x += y);
            self.xte[a].iter_mut().zip(&o.xte[a]).for_each(|(x, y)| *x += y);
            self.ete[a] += o.ete[a];
            self.n[a] += o.n[a];
        }
    }

    pub(super) fn symmetrise(&mut self) {
        let l = self.l;
        for m in &mut self.xtx {
            for i in 0..l {
                for j in 0..i {
                    m[i * l + j] = m[j * l + i];
                }
            }
        }
    }

    /// The sums of the columns `idx` of these, in that order.
    pub fn restricted(&self, idx: &[usize]) -> Gram {
        let (l, m) = (self.l, idx.len());
        let mut g = Gram::new(m);
        for a in 0..3 {
            for (i, &r) in idx.iter().enumerate() {
                g.xte[a][i] = self.xte[a][r];
                for (j, &c) in idx.iter().enumerate() {
                    g.xtx[a][i * m + j] = self.xtx[a][r * l + c];
                }
            }
        }
        g.ete = self.ete;
        g.n = self.n;
        g
    }

    /// Sum of several.
    pub fn sum<'g>(grams: impl IntoIterator<Item = &'g Gram>) -> Option<Gram> {
        let mut it = grams.into_iter();
        let mut total = it.next()?.clone();
        for g in it {
            total.merge(g);
        }
        Some(total)
    }
}

/// Adds Σ xᵢ·xⱼ over `rows` (each `l` column values) to the upper triangle of the l×l `xtx`,
/// for j < `reach[i]` ([`Reach`]), each sum taking the rows in order (so the sums are the same
/// however the pairs are grouped). Four consecutive columns i with the same reach share their
/// pass over the rows: a 4×4 tile of sums in registers, 16 independent chains, where one row of
/// four sums waited on its own previous add (the fold was 47 % of `host calibrate`). Only the
/// upper triangle of `xtx` is read ([`Gram::drain_rows`], [`Gram::symmetrise`]).
fn add_row_products<'r>(xtx: &mut [f64], l: usize, reach: &[usize], rows: impl Iterator<Item = &'r [f64]> + Clone) {
    const T: usize = 4;
    let mut ii = 0;
    while ii < l {
        let end = reach[ii];
        if ii + T <= end && reach[ii..ii + T].iter().all(|&e| e == end) {
            // The tile on the diagonal sums its lower triangle too, which nothing reads.
            let mut jj = ii;
            while jj + T <= end {
                add_tile(xtx, l, ii, jj, rows.clone());
                jj += T;
            }
            for k in ii..ii + T {
                add_pairs(xtx, l, k, jj..end, rows.clone());
            }
            ii += T;
        } else {
            add_pairs(xtx, l, ii, ii..end, rows.clone());
            ii += 1;
        }
    }
}

/// Adds Σ xᵢ·xⱼ for i = `ii`, j in `js`, four j side by side.
#[inline]
fn add_pairs<'r>(
    xtx: &mut [f64],
    l: usize,
    ii: usize,
    js: std::ops::Range<usize>,
    rows: impl Iterator<Item = &'r [f64]> + Clone,
) {
    let mut jj = js.start;
    while jj < js.end {
        let w = (js.end - jj).min(4);
        let mut acc = [0.0f64; 4];
        acc[..w].copy_from_slice(&xtx[ii * l + jj..ii * l + jj + w]);
        for row in rows.clone() {
            let xi = row[ii];
            for (s, &xj) in acc.iter_mut().zip(&row[jj..jj + w]) {
                *s += xi * xj;
            }
        }
        xtx[ii * l + jj..ii * l + jj + w].copy_from_slice(&acc[..w]);
        jj += w;
    }
}

/// Adds Σ xᵢ·xⱼ for the 4×4 tile i in `ii..ii + 4`, j in `jj..jj + 4`.
#[inline]
fn add_tile<'r>(xtx: &mut [f64], l: usize, ii: usize, jj: usize, rows: impl Iterator<Item = &'r [f64]>) {
    let mut acc = [[0.0f64; 4]; 4];
    for (r, a) in acc.iter_mut().enumerate() {
        a.copy_from_slice(&xtx[(ii + r) * l + jj..(ii + r) * l + jj + 4]);
    }
    for row in rows {
        let xj: &[f64; 4] = row[jj..jj + 4].try_into().expect("four columns");
        let xi: &[f64; 4] = row[ii..ii + 4].try_into().expect("four columns");
        for (a, &x) in acc.iter_mut().zip(xi) {
            for (s, &y) in a.iter_mut().zip(xj) {
                *s += x * y;
            }
        }
    }
    for (r, a) in acc.iter().enumerate() {
        xtx[(ii + r) * l + jj..(ii + r) * l + jj + 4].copy_from_slice(a);
    }
}

/// Rows of one axis's columns and residuals (a sample's, or a cell's: [`super::nodes`]), held
/// until a block is full and then added to the sums column pair by column pair: each sum still
/// takes its rows one after the other, as a per-row update did, but from registers, four
/// columns side by side, rather than through memory, whose store-to-load chain per entry was a
/// third of a plain fit's pass. eᵀe and the counts are the pass's, sample by sample.
pub(super) struct RowBlock {
    l: usize,
    pub(super) x: Vec<f64>,
    pub(super) e: Vec<f64>,
    reach: Vec<usize>,
}

impl RowBlock {
    /// Rows held before they are summed (32 KiB of a 32-column list: the block stays in cache).
    const ROWS: usize = 128;

    pub(super) fn new(reach: &Reach) -> Self {
        let l = reach.0.len();
        Self { l, x: Vec::with_capacity(l * Self::ROWS), e: Vec::with_capacity(Self::ROWS), reach: reach.0.clone() }
    }

    /// A new row with residual `e`: its `l` column values to fill.
    pub(super) fn push(&mut self, e: f64) -> &mut [f64] {
        self.e.push(e);
        let at = self.x.len();
        self.x.resize(at + self.l, 0.0);
        &mut self.x[at..]
    }

    pub(super) fn is_full(&self) -> bool {
        self.e.len() == Self::ROWS
    }

    /// Adds the rows to axis `a` of `g` (upper triangle of XᵀX, and Xᵀe); empties the block.
    pub(super) fn add_to(&mut self, g: &mut Gram, a: usize) {
        if self.e.is_empty() {
            return;
        }
        add_rows(g, a, &self.reach, &self.x, &self.e);
        self.x.clear();
        self.e.clear();
    }
}

impl Gram {
    /// Adds a sample's residual `e` to axis `a`'s eᵀe and count.
    #[inline]
    pub(super) fn add_sample(&mut self, a: usize, e: f64) {
        self.ete[a] += e * e;
        self.n[a] += 1;
    }
}

/// Adds rows `x` (each `g.l` values) with residuals `e` to axis `a`'s XᵀX (the pairs `reach`
/// names, upper triangle) and Xᵀe.
fn add_rows(g: &mut Gram, a: usize, reach: &[usize], x: &[f64], e: &[f64]) {
    let l = g.l;
    add_row_products(&mut g.xtx[a], l, reach, x.chunks_exact(l));
    add_xte(&mut g.xte[a], x.chunks_exact(l), e);
}

/// Adds Σ row·e to `xte`, each sum taking the rows in order.
fn add_xte<'r>(xte: &mut [f64], rows: impl Iterator<Item = &'r [f64]> + Clone, e: &[f64]) {
    for (ii, s) in xte.iter_mut().enumerate() {
        let mut acc = *s;
        for (row, &e) in rows.clone().zip(e) {
            acc += row[ii] * e;
        }
        *s = acc;
    }
}

/// The rows of a plan whose every column is axis-independent ([`ColPlan::all_common`], such as
/// the linear model's): one row of column values per sample (or cell) for the three axes, each
/// with its own residual. While no row has left an axis out since they were last drained, the
/// three axes' XᵀX are the same numbers, so they are summed once and copied rather than three
/// times; otherwise each axis sums the rows it uses, in order, as [`RowBlock`] does.
pub(super) struct SharedRows {
    l: usize,
    reach: Vec<usize>,
    x: Vec<f64>,
    /// Per axis, the rows' residuals.
    e: [Vec<f64>; 3],
    /// Per row, the axes it counts for (a clipped axis leaves it out).
    used: Vec<[bool; 3]>,
    /// Whether a row leaves an axis out.
    clipped: bool,
}

impl SharedRows {
    pub(super) fn new(reach: &Reach) -> Self {
        let rows = RowBlock::ROWS;
        let l = reach.0.len();
        Self {
            l,
            reach: reach.0.clone(),
            x: Vec::with_capacity(l * rows),
            e: std::array::from_fn(|_| Vec::with_capacity(rows)),
            used: Vec::with_capacity(rows),
            clipped: false,
        }
    }

    /// A row of column values `x` with the residual `e[a]` on each axis with `used[a]`.
    pub(super) fn push(&mut self, x: &[f64], e: [f64; 3], used: [bool; 3]) {
        // Element by element: a row is a few values, and `extend_from_slice` of a length known
        // only at run time is a `memcpy` call per row (2 % of a 1-h replay).
        for &v in &x[..self.l] {
            self.x.push(v);
        }
        for (s, e) in self.e.iter_mut().zip(e) {
            s.push(e);
        }
        self.used.push(used);
        self.clipped |= used.contains(&false);
    }

    pub(super) fn is_full(&self) -> bool {
        self.used.len() == RowBlock::ROWS
    }

    /// Adds the rows to `g` (upper triangles) and empties the block. `same`: whether `g`'s
    /// three XᵀX are equal; it stays so unless a row left an axis out.
    pub(super) fn add_to(&mut self, g: &mut Gram, same: &mut bool) {
        let l = self.l;
        if self.used.is_empty() {
            return;
        }
        if self.clipped {
            *same = false;
            for a in 0..3 {
                let rows = || self.x.chunks_exact(l).zip(&self.used).filter(move |(_, used)| used[a]).map(|(r, _)| r);
                add_row_products(&mut g.xtx[a], l, &self.reach, rows());
                let es: Vec<f64> = self.e[a].iter().zip(&self.used).filter(|(_, u)| u[a]).map(|(e, _)| *e).collect();
                add_xte(&mut g.xte[a], rows(), &es);
            }
        } else {
            for a in 0..if *same { 1 } else { 3 } {
                add_row_products(&mut g.xtx[a], l, &self.reach, self.x.chunks_exact(l));
            }
            if *same {
                let [x0, x1, x2] = &mut g.xtx;
                x1.copy_from_slice(x0);
                x2.copy_from_slice(x0);
            }
            for a in 0..3 {
                add_xte(&mut g.xte[a], self.x.chunks_exact(l), &self.e[a]);
            }
        }
        self.x.clear();
        self.e.iter_mut().for_each(Vec::clear);
        self.used.clear();
        self.clipped = false;
    }
}

/// Which column pairs a pass sums: column i with columns j in i..`reach[i]` (and, by symmetry,
/// those with i). Every pair ([`Reach::all`]) for a fit; for candidates scored against a model,
/// the model's columns with every column and each candidate's with its own only
/// ([`Reach::blocks`]): a candidate's test needs no other candidate's columns, and summing
/// every pair of 35-133 candidate columns was 42 % of a calibration's CPU time.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reach(pub(super) Vec<usize>);

impl Reach {
    /// Every pair of `l` columns.
    pub fn all(l: usize) -> Self {
        Self(vec![l; l])
    }

    /// The first `lead` columns (the model's) with every column, then each block of `blocks`
    /// (consecutive column counts: the candidates', in order) with itself.
    pub fn blocks(lead: usize, blocks: impl IntoIterator<Item = usize>) -> Self {
        let mut reach = Vec::new();
        let mut end = lead;
        for b in blocks {
            end += b;
            reach.extend(std::iter::repeat_n(end, b));
        }
        let l = end;
        Self(std::iter::repeat_n(l, lead).chain(reach).collect())
    }

    /// The reach of columns `keep` (ascending) alone: a pair of them is summed where it was.
    pub(super) fn restricted(&self, keep: &[usize]) -> Self {
        Self(keep.iter().map(|&i| keep.partition_point(|&j| j < self.0[i])).collect())
    }

    /// Whether the pair (i, j) is summed.
    #[inline(always)]
    pub(super) fn pairs(&self, i: usize, j: usize) -> bool {
        i.max(j) < self.0[i.min(j)]
    }
}

/// The rows of a [`Gram`] a chunk of the sparse path has touched, so that only they are drained.
pub(super) struct Touched {
    flags: Vec<bool>,
    pub(super) rows: Vec<usize>,
}

impl Touched {
    pub(super) fn new(l: usize) -> Self {
        Self { flags: vec![false; l], rows: Vec::with_capacity(l) }
    }

    #[inline]
    pub(super) fn mark(&mut self, ii: usize) {
        if !self.flags[ii] {
            self.flags[ii] = true;
            self.rows.push(ii);
        }
    }

    pub(super) fn clear(&mut self) {
        let Self { flags, rows } = self;
        rows.drain(..).for_each(|ii| flags[ii] = false);
    }
}
