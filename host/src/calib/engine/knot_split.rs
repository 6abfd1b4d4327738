//! The free drift's knots in a pass's sums ([`KnotSplit`]): 2-6 of dozens of columns are non-zero
//! at a sample, so they are summed apart from the dense columns, row by row against them.
//!
//! A cell whose knots are straight over its samples goes through its axis's [`KnotSegment`]. A
//! knot is a hat function of time, so between two of its grid's corners its value at a cell's
//! mean time t̄ is α + β·(t̄ − t₀). A cell of n samples enters the sums with its knots' values
//! √n·(α + β·τ) (τ = t̄ − t₀) beside its other columns' row x and its residual e, so over the
//! segment's cells c
//!
//! Σ v·x = α·Σ √n·x + β·Σ √n·τ·x,   Σ v·e likewise,   Σ vⱼ·vₖ = αⱼαₖ·Σn + (αⱼβₖ + βⱼαₖ)·Σn·τ + βⱼβₖ·Σn·τ²
//!
//! Two running sums of the row (contiguous, as the compiler vectorises them) replace a scattered
//! product with every other column for each of the cell's knots (2-6 of them): on
//! `realistic-2speed-s101` those products were 8 % of a calibration's instructions. The sums are
//! the same up to rounding (about 1e-16 of each, in another order).

use super::chain::{ColPlan, Evaluator};
use super::sums::{Gram, Reach, RowBlock, Touched};
use crate::calib::effects::terms::Point;

/// Per position in a pass's list (empty but for knots): the other columns a knot is summed with,
/// as (index into [`KnotSplit::map`], index of the pair's sum in the upper triangle).
type KnotPairs = [Vec<(usize, usize)>];

impl Gram {
    /// One row (a sample, or a cell) of axis `a` with residual `e`: the sums of its non-zero
    /// knots `knots` (position, value) with themselves and with the other columns (values
    /// `row`, paired through `pairs`, [`KnotSplit::pairs`]), for the pairs `reach` names; the
    /// other columns' own sums are [`KnotSplit`]'s.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn add_knots(
        &mut self,
        a: usize,
        knots: &[(usize, f64)],
        (pairs, row): (&KnotPairs, &[f64]),
        e: f64,
        reach: &Reach,
        touched: &mut Touched,
    ) {
        let l = self.l;
        let g = &mut self.xtx[a];
        for (k, &(jk, wk)) in knots.iter().enumerate() {
            touched.mark(jk);
            self.xte[a][jk] += wk * e;
            for &(p, at) in &pairs[jk] {
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
/// 2 of dozens per sample, are held beside the rows and summed against the rest, row by row,
/// when the block is drained. Every sum still takes the rows in order. Summed together pair by
/// pair through memory, sample by sample, the two were half of `host calibrate`'s time once the
/// drift had knots.
pub(super) struct KnotSplit {
    /// Position of each of the plan's other columns in the pass's list (increasing).
    map: Vec<usize>,
    /// Per position in the pass's list (empty but for knots): the other columns the knot is
    /// summed with, as (index into `map`, index of the pair's sum in the upper triangle).
    pairs: Vec<Vec<(usize, usize)>>,
    blocks: [RowBlock; 3],
    /// Per axis, the non-zero knots of the block's rows, by row: (position, value), and the
    /// row of each.
    knots: [Vec<(usize, f64)>; 3],
    knot_rows: [Vec<usize>; 3],
    /// Their sums since the chunk began.
    sums: Gram,
    any: bool,
    /// Per axis, the cells since its knots last changed whose knots are straight in time.
    segments: [KnotSegment; 3],
}

impl KnotSplit {
    pub(super) fn new(plan: &ColPlan, reach: &Reach) -> Self {
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
            knots: std::array::from_fn(|_| Vec::new()),
            knot_rows: std::array::from_fn(|_| Vec::new()),
            sums: Gram::new(map.len()),
            map,
            pairs,
            any: false,
            segments: Default::default(),
        }
    }

    /// Sample `p` on axis `a` with residual `e` (`common` as for [`Evaluator::fill_dense`]).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(super) fn add(
        &mut self,
        ev: &Evaluator,
        (p, plan, common): (&Point, &ColPlan, &[f64]),
        a: usize,
        e: f64,
        local: &mut Gram,
        reach: &Reach,
        touched: &mut Touched,
    ) {
        let knots = &mut self.knots[a];
        ev.for_each_knot(plan, p, |j, w| knots.push((j, w)));
        self.knot_rows[a].resize(knots.len(), self.blocks[a].e.len());
        ev.fill_dense(p, plan, a, common, self.blocks[a].push(e));
        if self.blocks[a].is_full() {
            self.drain(a, local, reach, touched);
        }
        self.any = true;
    }

    /// A row on axis `a` with residual `e`: its knots `knots` (position, value, each once), and
    /// its other columns `row`. A cell whose knots are straight lines in time over its samples
    /// (`straight`: the root of its samples' count and their mean time, s) adds its knots' sums
    /// through its axis's [`KnotSegment`].
    #[allow(clippy::too_many_arguments)]
    pub(super) fn add_row(
        &mut self,
        a: usize,
        (knots, row): (&[(usize, f64)], &[f64]),
        e: f64,
        straight: Option<(f64, f64)>,
        local: &mut Gram,
        reach: &Reach,
        touched: &mut Touched,
    ) {
        match straight {
            Some((root_n, t_mean_s)) => {
                let cell = StraightCell { knots, row, e, root_n, t_mean_s };
                self.segments[a].add(&cell, (local, a), &self.pairs, reach, touched);
            }
            None => {
                self.knots[a].extend_from_slice(knots);
                self.knot_rows[a].resize(self.knots[a].len(), self.blocks[a].e.len());
            }
        }
        self.blocks[a].push(e).copy_from_slice(row);
        if self.blocks[a].is_full() {
            self.drain(a, local, reach, touched);
        }
        self.any = true;
    }

    /// Axis `a`'s block into the sums: its other columns' into [`KnotSplit::sums`], its knots'
    /// into `local`, row by row.
    fn drain(&mut self, a: usize, local: &mut Gram, reach: &Reach, touched: &mut Touched) {
        let Self { map, pairs, blocks, knots, knot_rows, sums, .. } = self;
        let block = &mut blocks[a];
        if block.e.is_empty() {
            return;
        }
        let m = map.len();
        let (kn, kr) = (&knots[a], &knot_rows[a]);
        let mut lo = 0;
        for (c, &ec) in block.e.iter().enumerate() {
            let mut hi = lo;
            while hi < kr.len() && kr[hi] == c {
                hi += 1;
            }
            local.add_knots(a, &kn[lo..hi], (pairs, &block.x[c * m..(c + 1) * m]), ec, reach, touched);
            lo = hi;
        }
        block.add_to(sums, a);
        knots[a].clear();
        knot_rows[a].clear();
    }

    /// At a chunk's end: the other columns' sums into `local`, their rows marked `touched`.
    pub(super) fn flush(&mut self, local: &mut Gram, reach: &Reach, touched: &mut Touched) {
        for a in 0..3 {
            self.segments[a].close(local, a, &self.pairs, reach, touched);
            self.drain(a, local, reach, touched);
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
        }
        for &i in &self.map {
            touched.mark(i);
        }
    }
}

/// One axis's cells since its knots (their positions in the pass's list) last changed.
#[derive(Debug, Default)]
pub(super) struct KnotSegment {
    /// The knots' positions, and their values per √n at the first cell (τ = 0) and the last.
    knots: Vec<usize>,
    w_first: Vec<f64>,
    w_last: Vec<f64>,
    /// The first cell's mean time, s, and the last's τ.
    t0_s: f64,
    tau_last_s: f64,
    /// Σ √n·x and Σ √n·τ·x over the other columns.
    s0: Vec<f64>,
    s1: Vec<f64>,
    /// Σ √n·e, Σ √n·τ·e; Σ n, Σ n·τ, Σ n·τ².
    e0: f64,
    e1: f64,
    q: [f64; 3],
    cells: usize,
}

/// A cell's entry to a segment: its knots (position, value √n·w), its other columns' row and
/// residual, √n and its samples' mean time.
pub(super) struct StraightCell<'c> {
    pub knots: &'c [(usize, f64)],
    pub row: &'c [f64],
    pub e: f64,
    pub root_n: f64,
    pub t_mean_s: f64,
}

impl KnotSegment {
    /// Whether `knots` are this segment's, in order.
    fn same_knots(&self, knots: &[(usize, f64)]) -> bool {
        self.knots.len() == knots.len() && self.knots.iter().zip(knots).all(|(&j, &(k, _))| j == k)
    }

    /// Adds cell `c` of axis `a`; a cell with other knots first closes the segment into `g`.
    pub(super) fn add(
        &mut self,
        c: &StraightCell,
        (g, a): (&mut Gram, usize),
        pairs: &KnotPairs,
        reach: &Reach,
        touched: &mut Touched,
    ) {
        if self.cells > 0 && !self.same_knots(c.knots) {
            self.close(g, a, pairs, reach, touched);
        }
        let w = c.knots.iter().map(|&(_, v)| v / c.root_n);
        if self.cells == 0 {
            self.knots.clear();
            self.knots.extend(c.knots.iter().map(|&(j, _)| j));
            self.w_first.clear();
            self.w_first.extend(w);
            self.s0.clear();
            self.s0.resize(c.row.len(), 0.0);
            self.s1.clear();
            self.s1.resize(c.row.len(), 0.0);
            self.t0_s = c.t_mean_s;
        } else {
            self.w_last.clear();
            self.w_last.extend(w);
        }
        let tau = c.t_mean_s - self.t0_s;
        self.tau_last_s = tau;
        let (u, ut) = (c.root_n, c.root_n * tau);
        for ((s0, s1), &x) in self.s0.iter_mut().zip(&mut self.s1).zip(c.row) {
            *s0 += u * x;
            *s1 += ut * x;
        }
        self.e0 += u * c.e;
        self.e1 += ut * c.e;
        let n = u * u;
        self.q[0] += n;
        self.q[1] += n * tau;
        self.q[2] += n * tau * tau;
        self.cells += 1;
    }

    /// Each knot's (α, β) over the segment: its value at τ = 0 and its slope per s.
    fn lines(&self) -> Vec<(f64, f64)> {
        let span = self.tau_last_s;
        self.w_first
            .iter()
            .enumerate()
            .map(|(i, &w0)| if self.cells > 1 && span != 0.0 { (w0, (self.w_last[i] - w0) / span) } else { (w0, 0.0) })
            .collect()
    }

    /// Adds the segment's sums of its knots to axis `a` of `g` (the pairs `reach` names) and
    /// starts afresh.
    pub(super) fn close(&mut self, g: &mut Gram, a: usize, pairs: &KnotPairs, reach: &Reach, touched: &mut Touched) {
        if self.cells == 0 {
            return;
        }
        let lines = self.lines();
        let l = g.l;
        let (xtx, xte) = (&mut g.xtx[a], &mut g.xte[a]);
        for (i, (&jk, &(ak, bk))) in self.knots.iter().zip(&lines).enumerate() {
            touched.mark(jk);
            xte[jk] += ak * self.e0 + bk * self.e1;
            for &(p, at) in &pairs[jk] {
                xtx[at] += ak * self.s0[p] + bk * self.s1[p];
            }
            for (&jj, &(aj, bj)) in self.knots[i..].iter().zip(&lines[i..]) {
                if reach.pairs(jk, jj) {
                    xtx[jk.min(jj) * l + jk.max(jj)] +=
                        ak * aj * self.q[0] + (ak * bj + bk * aj) * self.q[1] + bk * bj * self.q[2];
                }
            }
        }
        (self.e0, self.e1, self.q, self.cells) = (0.0, 0.0, [0.0; 3], 0);
    }
}
