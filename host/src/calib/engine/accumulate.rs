//! Accumulation: one pass over the data sums, per run and axis, the Gram matrix of the columns
//! against the residual ([`Gram`]); [`accumulate_pairs`] sums only the pairs a solve reaches,
//! so a candidate's block against the model costs no more than it needs.

use crate::calib::result::axes::is_clipped;

use super::chain::{ColPlan, Cursor, Evaluator};
use super::loop_data::LoopData;
use super::model::Model;
use crate::calib::effects::terms::{Col, Point};

/// Samples summed into a local accumulator before it is added to the run total: rounding error
/// then grows as O(√n) ulp in a long run instead of O(n).
const CHUNK: usize = 1024;

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
    fn new(l: usize) -> Self {
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
    fn drain_rows(&mut self, local: &mut Gram, rows: &[usize]) {
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

    fn symmetrise(&mut self) {
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

/// Rows of one axis's columns and residuals, held until a block is full and then added to the
/// sums column pair by column pair: each sum still takes its rows one after the other, as a
/// per-row update did (the same sums bit for bit but for the sign of an exact zero), but from
/// registers, four columns side by side, rather than through memory, whose store-to-load
/// chain per entry was a third of a plain fit's pass.
struct RowBlock {
    l: usize,
    x: Vec<f64>,
    e: Vec<f64>,
    reach: Vec<usize>,
}

impl RowBlock {
    /// Rows held before they are summed (32 KiB of a 32-column list: the block stays in cache).
    const ROWS: usize = 128;

    fn new(reach: &Reach) -> Self {
        let l = reach.0.len();
        Self { l, x: Vec::with_capacity(l * Self::ROWS), e: Vec::with_capacity(Self::ROWS), reach: reach.0.clone() }
    }

    /// A new row with residual `e`: its `l` column values to fill.
    fn push(&mut self, e: f64) -> &mut [f64] {
        self.e.push(e);
        let at = self.x.len();
        self.x.resize(at + self.l, 0.0);
        &mut self.x[at..]
    }

    fn is_full(&self) -> bool {
        self.e.len() == Self::ROWS
    }

    /// Adds the rows to axis `a` of `g` (upper triangle) and empties the block.
    fn add_to(&mut self, g: &mut Gram, a: usize) {
        let l = self.l;
        if self.e.is_empty() {
            return;
        }
        add_row_products(&mut g.xtx[a], l, &self.reach, self.x.chunks_exact(l));
        let xte = &mut g.xte[a];
        for ii in 0..l {
            let mut s = xte[ii];
            for (row, &e) in self.x.chunks_exact(l).zip(&self.e) {
                s += row[ii] * e;
            }
            xte[ii] = s;
        }
        for &e in &self.e {
            g.ete[a] += e * e;
        }
        g.n[a] += self.e.len() as u64;
        self.x.clear();
        self.e.clear();
    }
}

/// The rows of a plan whose every column is axis-independent ([`ColPlan::all_common`], such as
/// the linear model's): one row of column values per sample for the three axes, each with its
/// own residual. While no clipped sample has entered the sums since they were last drained, the
/// three axes' XᵀX are the same numbers, so they are summed once and copied rather than three
/// times; otherwise each axis sums the rows it uses, in order, as
/// [`RowBlock`] does.
struct SharedRows {
    l: usize,
    reach: Vec<usize>,
    x: Vec<f64>,
    e: Vec<[f64; 3]>,
    /// Per row, the axes it counts for (a clipped axis leaves it out).
    used: Vec<[bool; 3]>,
    /// Whether a row leaves an axis out.
    clipped: bool,
}

impl SharedRows {
    fn new(reach: &Reach) -> Self {
        let rows = RowBlock::ROWS;
        let l = reach.0.len();
        Self {
            l,
            reach: reach.0.clone(),
            x: Vec::with_capacity(l * rows),
            e: Vec::with_capacity(rows),
            used: Vec::with_capacity(rows),
            clipped: false,
        }
    }

    /// A row of column values `x` with the residual `e[a]` on each axis with `used[a]`.
    fn push(&mut self, x: &[f64], e: [f64; 3], used: [bool; 3]) {
        // Element by element: a row is a few values, and `extend_from_slice` of a length known
        // only at run time is a `memcpy` call per row (2 % of a 1-h replay).
        for &v in &x[..self.l] {
            self.x.push(v);
        }
        self.e.push(e);
        self.used.push(used);
        self.clipped |= used.contains(&false);
    }

    fn is_full(&self) -> bool {
        self.e.len() == RowBlock::ROWS
    }

    /// Adds the rows to `g` (upper triangles) and empties the block. `same`: whether `g`'s
    /// three XᵀX are equal; it stays so unless a row left an axis out.
    fn add_to(&mut self, g: &mut Gram, same: &mut bool) {
        let l = self.l;
        if self.e.is_empty() {
            return;
        }
        *same &= !self.clipped;
        let axes = if *same { 1 } else { 3 };
        for a in 0..axes {
            let rows = self.x.chunks_exact(l).zip(&self.used).filter(move |(_, used)| used[a]).map(|(row, _)| row);
            add_row_products(&mut g.xtx[a], l, &self.reach, rows);
        }
        if *same {
            let [x0, x1, x2] = &mut g.xtx;
            x1.copy_from_slice(x0);
            x2.copy_from_slice(x0);
        }
        for a in 0..3 {
            let xte = &mut g.xte[a];
            for ii in 0..l {
                let mut s = xte[ii];
                for ((row, e), used) in self.x.chunks_exact(l).zip(&self.e).zip(&self.used) {
                    if used[a] {
                        s += row[ii] * e[a];
                    }
                }
                xte[ii] = s;
            }
            for (e, used) in self.e.iter().zip(&self.used) {
                if used[a] {
                    g.ete[a] += e[a] * e[a];
                    g.n[a] += 1;
                }
            }
        }
        self.x.clear();
        self.e.clear();
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
pub struct Reach(Vec<usize>);

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

    /// Whether the pair (i, j) is summed.
    #[inline(always)]
    fn pairs(&self, i: usize, j: usize) -> bool {
        i.max(j) < self.0[i.min(j)]
    }
}

/// The rows of a [`Gram`] a chunk of the sparse path has touched, so that only they are drained.
struct Touched {
    flags: Vec<bool>,
    rows: Vec<usize>,
}

impl Touched {
    fn new(l: usize) -> Self {
        Self { flags: vec![false; l], rows: Vec::with_capacity(l) }
    }

    #[inline]
    fn mark(&mut self, ii: usize) {
        if !self.flags[ii] {
            self.flags[ii] = true;
            self.rows.push(ii);
        }
    }

    fn clear(&mut self) {
        let Self { flags, rows } = self;
        rows.drain(..).for_each(|ii| flags[ii] = false);
    }
}

impl Gram {
    /// One sample of axis `a` with residual `e`: the sums of its non-zero knots `knots`
    /// (position, value) with themselves and with the other columns (values `row`, paired
    /// through `split`), for the pairs `reach` names; the other columns' own sums are
    /// [`KnotSplit`]'s.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn add_knots(
        &mut self,
        a: usize,
        knots: &[(usize, f64)],
        (split, row): (&KnotSplit, &[f64]),
        e: f64,
        reach: &Reach,
        touched: &mut Touched,
    ) {
        let l = self.l;
        let g = &mut self.xtx[a];
        for (k, &(jk, wk)) in knots.iter().enumerate() {
            touched.mark(jk);
            self.xte[a][jk] += wk * e;
            for &(p, at) in &split.pairs[jk] {
                g[at] += row[p] * wk;
            }
            for &(jj, wj) in &knots[k..] {
                if reach.pairs(jk, jj) {
                    g[jk.min(jj) * l + jk.max(jj)] += wk * wj;
                }
            }
        }
    }
}

/// The sums of a plan with free-drift knots. Its other columns ([`ColPlan::dense`]) are non-zero
/// at nearly every sample: they are summed a block of rows at a time, as the plan without knots
/// is ([`RowBlock`]), into a Gram of their own that a chunk's end adds to the pass's. The knots,
/// 2 of dozens per sample, are summed sample by sample against the rest. Every sum still takes
/// the samples in order. Summed together pair by pair through memory, sample by sample, the
/// two were half of `host calibrate`'s time once the drift had knots.
struct KnotSplit {
    /// Position of each of the plan's other columns in the pass's list (increasing).
    map: Vec<usize>,
    /// Per position in the pass's list (empty but for knots): the other columns the knot is
    /// summed with, as (index into `map`, index of the pair's sum in the upper triangle).
    pairs: Vec<Vec<(usize, usize)>>,
    blocks: [RowBlock; 3],
    /// Their sums since the chunk began.
    sums: Gram,
    knots: Vec<(usize, f64)>,
    any: bool,
}

impl KnotSplit {
    fn new(plan: &ColPlan, reach: &Reach) -> Self {
        let map: Vec<usize> = plan.dense.iter().map(|d| d.0).collect();
        let own = Reach(map.iter().map(|&c| map.partition_point(|&q| q < reach.0[c])).collect());
        let l = reach.0.len();
        let mut pairs = vec![Vec::new(); l];
        for &j in plan.knots.iter().flat_map(|g| g.at.iter().flatten()) {
            pairs[j] = map
                .iter()
                .enumerate()
                .filter(|&(_, &i)| reach.pairs(i, j))
                .map(|(p, &i)| (p, i.min(j) * l + i.max(j)))
                .collect();
        }
        Self {
            blocks: std::array::from_fn(|_| RowBlock::new(&own)),
            sums: Gram::new(map.len()),
            map,
            pairs,
            knots: Vec::new(),
            any: false,
        }
    }

    /// Sample `p` on axis `a` with residual `e` (`common` as for [`Evaluator::fill_dense`]).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn add(
        &mut self,
        ev: &Evaluator,
        (p, plan, common): (&Point, &ColPlan, &[f64]),
        a: usize,
        e: f64,
        local: &mut Gram,
        reach: &Reach,
        touched: &mut Touched,
    ) {
        let mut knots = std::mem::take(&mut self.knots);
        knots.clear();
        ev.for_each_knot(plan, p, |j, w| knots.push((j, w)));
        let row = self.blocks[a].push(e);
        ev.fill_dense(p, plan, a, common, row);
        let row = &self.blocks[a].x[self.blocks[a].x.len() - self.map.len()..];
        local.add_knots(a, &knots, (self, row), e, reach, touched);
        self.knots = knots;
        if self.blocks[a].is_full() {
            self.blocks[a].add_to(&mut self.sums, a);
        }
        self.any = true;
    }

    /// At a chunk's end: the other columns' sums into `local`, their rows marked `touched`.
    fn flush(&mut self, local: &mut Gram, touched: &mut Touched) {
        for (a, b) in self.blocks.iter_mut().enumerate() {
            b.add_to(&mut self.sums, a);
        }
        if !std::mem::take(&mut self.any) {
            return;
        }
        let (m, l) = (self.map.len(), local.l);
        for a in 0..3 {
            for (p, &i) in self.map.iter().enumerate() {
                local.xte[a][i] += std::mem::take(&mut self.sums.xte[a][p]);
                for (q, &j) in self.map.iter().enumerate().skip(p) {
                    local.xtx[a][i * l + j] += std::mem::take(&mut self.sums.xtx[a][p * m + q]);
                }
            }
            local.ete[a] += std::mem::take(&mut self.sums.ete[a]);
            local.n[a] += std::mem::take(&mut self.sums.n[a]);
        }
        for &i in &self.map {
            touched.mark(i);
        }
    }
}

/// One pass: per-run sums of `cols` against the residual of `model` (clipped samples left out of
/// their axis), every column pair.
pub fn accumulate(data: &LoopData, model: &Model, cols: &[Col]) -> Vec<Gram> {
    accumulate_pairs(data, model, cols, &Reach::all(cols.len()))
}

/// [`accumulate`] of the pairs `reach` names; every other entry of XᵀX is 0.
pub fn accumulate_pairs(data: &LoopData, model: &Model, cols: &[Col], reach: &Reach) -> Vec<Gram> {
    let ev = Evaluator::for_columns(data, model, cols);
    let l = cols.len();
    debug_assert_eq!(reach.0.len(), l);
    let plan = ColPlan::of(cols.iter().copied());
    let (mut common, mut model_common) = (Vec::with_capacity(l), Vec::new());
    // Without knots every column is in `plan.dense`, in column order.
    let dense = plan.knots.is_empty();
    debug_assert!(!dense || plan.dense.iter().enumerate().all(|(k, d)| d.0 == k));
    let mut block: [RowBlock; 3] = std::array::from_fn(|_| RowBlock::new(reach));
    let mut shared = SharedRows::new(reach);
    // A fit's pass and a step's lead with the model's own columns: their axis-independent values
    // are then the plan's first ones, computed once per sample rather than twice.
    let model_leads = ev.lin_plan.dense.len() <= plan.dense.len()
        && ev.lin_plan.dense.iter().zip(&plan.dense).all(|(m, c)| m.1 == c.1);
    // A model whose coefficients are all zero (the linear fit's one pass, from zero) predicts
    // an exact 0 at every sample: Σ 0·x over finite columns.
    let predicts_zero = model.beta.iter().flatten().all(|&b| b == 0.0);
    data.kin
        .runs
        .iter()
        .enumerate()
        .map(|(r, rk)| {
            let mut total = Gram::new(l);
            let mut local = Gram::new(l);
            let mut touched = Touched::new(l);
            let all_rows: Vec<usize> = (0..l).collect();
            let valid = &data.runs[r].valid;
            let mut cursor = Cursor::default();
            let mut split = (!dense).then(|| KnotSplit::new(&plan, reach));
            for start in (0..rk.samples.len()).step_by(CHUNK) {
                let end = (start + CHUNK).min(rk.samples.len());
                // `local` was drained: its three XᵀX are equal (zero).
                let mut same = true;
                for i in valid.indices_in(start, end) {
                    let (s, p) = ev.visit(r, i, &mut cursor);
                    ev.common_values(p, &plan, &mut common);
                    let pred = if predicts_zero {
                        [0.0; 3]
                    } else if model_leads {
                        ev.predict3_with(p, &common[..ev.lin_plan.dense.len()])
                    } else {
                        ev.common_values(p, &ev.lin_plan, &mut model_common);
                        ev.predict3_with(p, &model_common)
                    };
                    if plan.all_common {
                        let used = s.rate_counts.map(|c| !is_clipped(c));
                        let e: [f64; 3] = std::array::from_fn(|a| f64::from(s.rate_counts[a]) - pred[a]);
                        shared.push(&common, e, used);
                        if shared.is_full() {
                            shared.add_to(&mut local, &mut same);
                        }
                        continue;
                    }
                    for (a, &count) in s.rate_counts.iter().enumerate() {
                        if is_clipped(count) {
                            continue;
                        }
                        let e = f64::from(count) - pred[a];
                        // Each pair goes to the upper triangle (`symmetrise` fills the rest).
                        if dense {
                            // Every column at every sample, in column order, the rows summed a
                            // block at a time.
                            ev.fill_dense(p, &plan, a, &common, block[a].push(e));
                            if block[a].is_full() {
                                block[a].add_to(&mut local, a);
                            }
                            continue;
                        }
                        // With knots: the rest a block at a time, the knots sample by sample.
                        if let Some(split) = split.as_mut() {
                            split.add(&ev, (p, &plan, &common), a, e, &mut local, reach, &mut touched);
                        }
                    }
                }
                for (a, b) in block.iter_mut().enumerate() {
                    b.add_to(&mut local, a);
                }
                shared.add_to(&mut local, &mut same);
                if let Some(split) = split.as_mut() {
                    split.flush(&mut local, &mut touched);
                }
                total.drain_rows(&mut local, if dense { &all_rows } else { &touched.rows });
                touched.clear();
            }
            total.symmetrise();
            total
        })
        .collect()
}
