//! A pass in cells ([`super::cells`]) with the chain evaluated at a few nodes per cell, not at
//! every sample: the first sample, the next cell's first (the last of a stretch's last cell) and
//! one (a short cell) or three (a long one) equally spaced between. Every column but the free
//! drift's knots, and the model's output, is taken at a sample from the polynomial through the
//! nodes' values (Lagrange's form, in the samples' own times), so a cell's sums are the
//! polynomial's sums over its samples. The knots, straight lines in time between their corners,
//! sum over a cell to its count times their values at its samples' mean time, taken once per
//! cell and axis (sample by sample in the few cells a corner crosses). The residual's eᵀe and
//! the counts are the samples' own (a clipped sample leaves its axis's cell, as it leaves the
//! samples' sums).
//!
//! The quadratic's error at a sample is about 0.06·(ω·h)³ of a column varying at ω rad/s over
//! a node spacing of h s (half a short cell, 5 ms): 2.5e-7 of the signal at the tables' 0.5 Hz
//! and 3e-3 of a harmonic at 12 Hz (a 12-pole gear's 24× mesh at 180 °/s), well inside the
//! information a cell loses anyway; the quartic's through a long cell's five nodes 10 ms apart
//! about 0.03·(ω·h)⁵, 1e-9 at 0.5 Hz and 1e-5 at 2 Hz. Consecutive cells share their bounding
//! node, so a short cell costs two evaluations of the chain where its samples would cost eight,
//! a long one four where they would cost 32.

use std::ops::Range;

use super::cells::CellForm;
use super::chain::Evaluator;
use super::knot_split::KnotSplit;
use super::loop_data::LoopData;
use super::pass::Pass;
use super::sums::{Gram, RowBlock, SharedRows, Touched, CHUNK};
use crate::calib::data::kinematics::KinSample;
use crate::calib::effects::terms::Point;
use crate::calib::result::axes::is_clipped;

/// The most nodes a cell has: a long cell's five.
const MAX_NODES: usize = 5;

/// The polynomial through one to [`MAX_NODES`] nodes, as weights on the nodes' values at any
/// time.
#[derive(Debug, Clone, Copy)]
struct Lagrange {
    k: usize,
    t_s: [f64; MAX_NODES],
    /// 1 / Π (t_j − t_q) over the other nodes q.
    inv: [f64; MAX_NODES],
}

impl Lagrange {
    /// Through nodes at distinct times `t_s` (s, from an origin near them).
    fn new(t_s: &[f64]) -> Self {
        let k = t_s.len();
        debug_assert!((1..=MAX_NODES).contains(&k));
        let mut at = [0.0; MAX_NODES];
        at[..k].copy_from_slice(t_s);
        let inv = std::array::from_fn(|j| {
            let d: f64 = (0..k).filter(|&q| q != j).map(|q| at[j] - at[q]).product();
            if j < k {
                d.recip()
            } else {
                0.0
            }
        });
        Self { k, t_s: at, inv }
    }

    /// The weight of each node's value in the polynomial's value at `t_s` (0 past the k-th).
    #[inline]
    fn weights(&self, t_s: f64) -> [f64; MAX_NODES] {
        let d = self.t_s.map(|t| t_s - t);
        let mut w = [0.0; MAX_NODES];
        match self.k {
            3 => w[..3].copy_from_slice(&[
                d[1] * d[2] * self.inv[0],
                d[0] * d[2] * self.inv[1],
                d[0] * d[1] * self.inv[2],
            ]),
            2 => w[..2].copy_from_slice(&[d[1] * self.inv[0], d[0] * self.inv[1]]),
            1 => w[0] = 1.0,
            k => {
                // Π over the other nodes as the product of those before and those after.
                let mut before = 1.0;
                for j in 0..k {
                    w[j] = before * self.inv[j];
                    before *= d[j];
                }
                let mut after = 1.0;
                for j in (0..k).rev() {
                    w[j] *= after;
                    after *= d[j];
                }
            }
        }
        w
    }
}

/// The chain at one node.
#[derive(Debug, Clone, Default)]
struct Node {
    /// Its sample.
    i: usize,
    t_s: f64,
    /// The model's output, counts.
    pred: [f64; 3],
    /// The plan's axis-independent column values (every column's, for an all-common plan).
    common: Vec<f64>,
    /// Per axis, the plan's dense columns (none for an all-common plan).
    rows: [Vec<f64>; 3],
}

impl Node {
    fn new() -> Self {
        Self { i: usize::MAX, ..Self::default() }
    }

    /// The node at sample `s`, sample `i` of run `r` (`scratch`: scratch).
    fn set(&mut self, pass: &Pass, r: usize, (i, s): (usize, KinSample), scratch: &mut Vec<f64>) {
        let p = pass.ev.point_with(r, i, s);
        pass.ev.common_values(&p, &pass.plan, &mut self.common);
        self.pred = pass.predict(&p, &self.common, scratch);
        if !pass.plan.all_common {
            for (a, row) in self.rows.iter_mut().enumerate() {
                row.resize(pass.plan.dense.len(), 0.0);
                pass.ev.fill_dense(&p, &pass.plan, a, &self.common, row);
            }
        }
        (self.i, self.t_s) = (i, s.t_s());
    }
}

/// What one axis of a cell has summed: its samples' node weights and residuals, and how many.
#[derive(Debug, Clone, Copy, Default)]
struct AxisCell {
    w: [f64; MAX_NODES],
    e: f64,
    n: u32,
}

/// Adds `w` at knot `j` to `list` (each knot once).
#[inline]
fn merge(list: &mut Vec<(usize, f64)>, (j, w): (usize, f64)) {
    match list.iter_mut().find(|k| k.0 == j) {
        Some(k) => k.1 += w,
        None => list.push((j, w)),
    }
}

/// One run's pass in cells.
struct CellPass<'p, 'a> {
    pass: &'p Pass<'a>,
    r: usize,
    /// Intervals between a cell's nodes ([`CellForm::intervals`]).
    intervals: usize,
    nodes: [Node; MAX_NODES],
    /// Nodes of the last cell.
    k: usize,
    total: Gram,
    local: Gram,
    touched: Touched,
    same: bool,
    blocks: [RowBlock; 3],
    shared: SharedRows,
    split: Option<KnotSplit>,
    /// Knots of the cell's samples used on every axis, and of those used on some only, per axis.
    knots_all: Vec<(usize, f64)>,
    knots_axis: [Vec<(usize, f64)>; 3],
    row: Vec<f64>,
    scratch: Vec<f64>,
    /// Every row of the sums, which a chunk of a plan without knots touches.
    all_rows: Vec<usize>,
}

impl<'p, 'a> CellPass<'p, 'a> {
    fn new(pass: &'p Pass<'a>, r: usize, intervals: usize) -> Self {
        let l = pass.reach.0.len();
        Self {
            pass,
            r,
            intervals,
            nodes: std::array::from_fn(|_| Node::new()),
            k: 0,
            total: Gram::new(l),
            local: Gram::new(l),
            touched: Touched::new(l),
            same: true,
            blocks: std::array::from_fn(|_| RowBlock::new(pass.reach)),
            shared: SharedRows::new(pass.reach),
            split: (!pass.dense).then(|| KnotSplit::new(&pass.plan, pass.reach)),
            knots_all: Vec::new(),
            knots_axis: std::array::from_fn(|_| Vec::new()),
            row: Vec::new(),
            scratch: Vec::new(),
            all_rows: (0..l).collect(),
        }
    }

    /// The nodes of the cell of samples `cell` in a stretch of consecutive samples ending at
    /// `stretch_end` ([`node_samples`]); the first is the last cell's last when they meet.
    fn place_nodes(&mut self, cell: &Range<usize>, stretch_end: usize) {
        let (idx, k) = node_samples(cell, stretch_end, self.intervals);
        let (first, at) = (idx[0], &idx[..k]);
        let samples = &self.pass.data.kin.runs[self.r].samples;
        if self.k > 0 && self.nodes[self.k - 1].i == first {
            self.nodes.swap(0, self.k - 1);
        } else {
            self.nodes[0].set(self.pass, self.r, (first, samples.get(first)), &mut self.scratch);
        }
        for (node, &i) in self.nodes.iter_mut().zip(at).skip(1) {
            node.set(self.pass, self.r, (i, samples.get(i)), &mut self.scratch);
        }
        self.k = at.len();
    }

    /// The cell of samples `cell`, in a stretch of consecutive samples ending at `stretch_end`.
    fn add_cell(&mut self, cell: Range<usize>, stretch_end: usize) {
        self.place_nodes(&cell, stretch_end);
        let (nodes, k) = (&self.nodes, self.k);
        let t0 = nodes[0].t_s;
        let times: [f64; MAX_NODES] = std::array::from_fn(|j| nodes[j].t_s - t0);
        let lagrange = Lagrange::new(&times[..k]);
        let samples = &self.pass.data.kin.runs[self.r].samples;
        let stretch = self.pass.data.layout.run_stretch[self.r];
        let mut axes = [AxisCell::default(); 3];
        let mut all_used = true;
        self.knots_all.clear();
        self.knots_axis.iter_mut().for_each(Vec::clear);
        // Knots are straight lines in time between their corners: where none falls inside the
        // cell, its samples' knot values sum to their count times the values at their mean
        // time (per axis, over the samples it uses), so only a cell across a corner takes them
        // sample by sample.
        let (ev, plan) = (&self.pass.ev, &self.pass.plan);
        let knots_per_sample = self.split.is_some()
            && !ev.knots_straight(plan, stretch, samples.get(cell.start).t_s(), samples.get(cell.end - 1).t_s());
        let mut t_sum_s = [0.0; 3];
        for i in cell {
            let s = samples.get(i);
            let dt_s = s.t_s() - t0;
            let w = lagrange.weights(dt_s);
            let used = s.rate_counts.map(|c| !is_clipped(c));
            all_used &= used == [true; 3];
            for (a, ax) in axes.iter_mut().enumerate().filter(|(a, _)| used[*a]) {
                let pred = (0..k).map(|j| w[j] * nodes[j].pred[a]).sum::<f64>();
                let e = f64::from(s.rate_counts[a]) - pred;
                self.local.add_sample(a, e);
                ax.w[..k].iter_mut().zip(&w[..k]).for_each(|(s, w)| *s += w);
                (ax.e, ax.n) = (ax.e + e, ax.n + 1);
                t_sum_s[a] += dt_s;
            }
            if knots_per_sample {
                let (all, each) = (&mut self.knots_all, &mut self.knots_axis);
                ev.knots_at(plan, stretch, s.t_s(), None, |j, w| {
                    if used == [true; 3] {
                        merge(all, (j, w));
                    } else {
                        for a in (0..3).filter(|&a| used[a]) {
                            merge(&mut each[a], (j, w));
                        }
                    }
                });
            }
        }
        let mut straight = [None; 3];
        if self.split.is_some() && !knots_per_sample {
            for (a, ax) in axes.iter().enumerate().filter(|(_, ax)| ax.n > 0) {
                let (n, each) = (f64::from(ax.n), &mut self.knots_axis[a]);
                let t_mean_s = t0 + t_sum_s[a] / n;
                ev.knots_at(plan, stretch, t_mean_s, None, |j, w| each.push((j, n * w)));
                straight[a] = Some((n.sqrt(), t_mean_s));
            }
        }
        self.emit(&axes, all_used, straight);
    }

    /// The cell's rows: per axis its samples' sums over the root of their count. `straight`, per
    /// axis, where its knots are straight lines over the cell: the root of its count and its
    /// samples' mean time, s.
    fn emit(&mut self, axes: &[AxisCell; 3], all_used: bool, straight: [Option<(f64, f64)>; 3]) {
        let pass = self.pass;
        let scale = axes.map(|ax| if ax.n > 0 { f64::from(ax.n).sqrt().recip() } else { 0.0 });
        let e = std::array::from_fn(|a| axes[a].e * scale[a]);
        if pass.plan.all_common {
            if all_used {
                self.combine(axes[0].w.map(|w| w * scale[0]), |n| &n.common);
                self.shared.push(&self.row, e, [true; 3]);
                self.after_shared();
                return;
            }
            for a in (0..3).filter(|&a| axes[a].n > 0) {
                self.combine(axes[a].w.map(|w| w * scale[a]), |n| &n.common);
                self.shared.push(&self.row, e, std::array::from_fn(|b| b == a));
                self.after_shared();
            }
            return;
        }
        for a in (0..3).filter(|&a| axes[a].n > 0) {
            self.combine(axes[a].w.map(|w| w * scale[a]), |n| &n.rows[a]);
            match self.split.as_mut() {
                Some(split) => {
                    let knots = &mut self.knots_axis[a];
                    self.knots_all.iter().for_each(|&kw| merge(knots, kw));
                    knots.iter_mut().for_each(|kw| kw.1 *= scale[a]);
                    let rows = (knots.as_slice(), self.row.as_slice());
                    split.add_row(a, rows, e[a], straight[a], &mut self.local, pass.reach, &mut self.touched);
                }
                None => {
                    self.blocks[a].push(e[a]).copy_from_slice(&self.row);
                    if self.blocks[a].is_full() {
                        self.blocks[a].add_to(&mut self.local, a);
                    }
                }
            }
        }
    }

    /// Σ_j w_j·(the values `of` node j) into `row`.
    fn combine(&mut self, w: [f64; MAX_NODES], of: impl Fn(&Node) -> &Vec<f64>) {
        let k = self.k;
        self.row.clear();
        self.row.extend_from_slice(of(&self.nodes[0]));
        self.row.iter_mut().for_each(|v| *v *= w[0]);
        for (node, &wj) in self.nodes[1..k].iter().zip(&w[1..k]) {
            self.row.iter_mut().zip(of(node)).for_each(|(v, x)| *v += wj * x);
        }
    }

    fn after_shared(&mut self) {
        if self.shared.is_full() {
            self.shared.add_to(&mut self.local, &mut self.same);
        }
    }

    /// At a chunk's end: the blocks into the chunk's sums, and those into the run's.
    fn end_chunk(&mut self) {
        for (a, b) in self.blocks.iter_mut().enumerate() {
            b.add_to(&mut self.local, a);
        }
        self.shared.add_to(&mut self.local, &mut self.same);
        match self.split.as_mut() {
            Some(split) => {
                split.flush(&mut self.local, self.pass.reach, &mut self.touched);
                self.total.drain_rows(&mut self.local, &self.touched.rows);
                self.touched.clear();
            }
            None => self.total.drain_rows(&mut self.local, &self.all_rows),
        }
        // `local` was drained: its three XᵀX are equal (zero).
        self.same = true;
    }
}

/// The sums of run `r` in cells of `form`: within each chunk of [`CHUNK`] samples, each
/// stretch of consecutive valid samples cut into cells from its start (the last shorter).
pub(super) fn cell_sums(pass: &Pass, r: usize, form: CellForm) -> Gram {
    let (n, size) = (pass.data.kin.runs[r].samples.len(), form.size);
    let mut cp = CellPass::new(pass, r, form.intervals);
    for start in (0..n).step_by(CHUNK) {
        for stretch in pass.data.runs[r].valid.ranges_in(start, (start + CHUNK).min(n)) {
            for cell in cells_of(&stretch, size) {
                cp.add_cell(cell, stretch.end);
            }
        }
        cp.end_chunk();
    }
    cp.total.symmetrise();
    cp.total
}

/// A stretch of consecutive samples cut into cells of `size` from its start (the last shorter).
fn cells_of(stretch: &Range<usize>, size: usize) -> impl Iterator<Item = Range<usize>> {
    let end = stretch.end;
    stretch.clone().step_by(size).map(move |c0| c0..(c0 + size).min(end))
}

/// Where a cell of samples `cell`, in a stretch of consecutive samples ending at `stretch_end`,
/// takes its nodes: its first sample, the next cell's first (or its own last), and between them
/// the samples that cut the span into `intervals` equal parts (rounded down); fewer when it has
/// fewer samples.
fn node_samples(cell: &Range<usize>, stretch_end: usize, intervals: usize) -> ([usize; MAX_NODES], usize) {
    let (first, last) = (cell.start, if cell.end < stretch_end { cell.end } else { cell.end - 1 });
    // q = 0 only where the cell is one sample (last = first).
    let q = intervals.min(last - first).min(MAX_NODES - 1);
    let mut idx = [last; MAX_NODES];
    for (j, i) in idx.iter_mut().enumerate().take(q) {
        *i = first + j * (last - first) / q;
    }
    (idx, q + 1)
}

/// Visits the valid samples of run `r` in order, each with `values` (a few numbers of the chain
/// at a point) taken at the nodes of its cell ([`super::cells::CELL_S`]) and at the sample from
/// the quadratic through them: what a walk of the residual needs, for two evaluations of the
/// chain per cell where each sample would cost one.
pub fn for_each_interpolated<const K: usize>(
    ev: &Evaluator,
    data: &LoopData,
    r: usize,
    mut values: impl FnMut(&Point) -> [f64; K],
    mut visit: impl FnMut(usize, KinSample, [f64; K]),
) {
    let samples = &data.kin.runs[r].samples;
    let CellForm { size, intervals } = CellForm::short(data.kin.runs[r].sample_rate_hz);
    let mut at = |i: usize| -> (usize, f64, [f64; K]) {
        let s = samples.get(i);
        (i, s.t_s(), values(&ev.point_with(r, i, s)))
    };
    let mut nodes: [(usize, f64, [f64; K]); MAX_NODES] = [(usize::MAX, 0.0, [0.0; K]); MAX_NODES];
    let mut k = 0;
    for stretch in data.runs[r].valid.ranges_in(0, samples.len()) {
        for cell in cells_of(&stretch, size) {
            let (idx, kn) = node_samples(&cell, stretch.end, intervals);
            nodes[0] = if k > 0 && nodes[k - 1].0 == idx[0] { nodes[k - 1] } else { at(idx[0]) };
            for j in 1..kn {
                nodes[j] = at(idx[j]);
            }
            k = kn;
            let t0 = nodes[0].1;
            let times: [f64; MAX_NODES] = std::array::from_fn(|j| nodes[j].1 - t0);
            let lagrange = Lagrange::new(&times[..k]);
            // A short cell's three nodes (all but a stretch's last cells) spelled out: the sum
            // over a run-time count of nodes kept the compiler from unrolling it.
            let three = (k == 3).then(|| (nodes[0].2, nodes[1].2, nodes[2].2));
            for i in cell.clone() {
                let s = samples.get(i);
                let w = lagrange.weights(s.t_s() - t0);
                let v = match three {
                    Some((a, b, c)) => std::array::from_fn(|q| w[0] * a[q] + w[1] * b[q] + w[2] * c[q]),
                    None => std::array::from_fn(|q| (0..k).map(|j| w[j] * nodes[j].2[q]).sum()),
                };
                visit(i, s, v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{node_samples, Lagrange};

    /// The weights reproduce any quadratic through three nodes, a line through two, a constant
    /// through one.
    #[test]
    fn the_weights_give_the_polynomial_through_the_nodes() {
        let f = |t: f64| 3.0 - 2.0 * t + 0.5 * t * t;
        let nodes = [0.0, 0.004, 0.01];
        let lagrange = Lagrange::new(&nodes);
        for t in [0.0, 0.001, 0.00725, 0.01, 0.02] {
            let w = lagrange.weights(t);
            let got: f64 = (0..3).map(|j| w[j] * f(nodes[j])).sum();
            assert!((got - f(t)).abs() < 1e-12, "at {t}: {got} against {}", f(t));
        }
        let line = Lagrange::new(&[0.0, 0.00125]);
        let w = line.weights(0.0005);
        assert!((w[0] - 0.6).abs() < 1e-12 && (w[1] - 0.4).abs() < 1e-12 && w[2] == 0.0, "{w:?}");
        assert_eq!(Lagrange::new(&[0.0]).weights(0.3), [1.0, 0.0, 0.0, 0.0, 0.0]);
    }

    /// Four and five nodes reproduce a cubic and a quartic, the weights summing to one.
    #[test]
    fn more_nodes_give_the_polynomial_of_higher_degree() {
        let quartic = |t: f64| 1.0 - 40.0 * t + 900.0 * t * t - 2e4 * t.powi(3) + 3e5 * t.powi(4);
        for nodes in [&[0.0, 0.01, 0.02, 0.03][..], &[0.0, 0.01, 0.02, 0.03, 0.04]] {
            let lagrange = Lagrange::new(nodes);
            let f = |t: f64| if nodes.len() == 5 { quartic(t) } else { quartic(t) - 3e5 * t.powi(4) };
            for t in [0.0, 0.0037, 0.015, 0.029, 0.04] {
                let w = lagrange.weights(t);
                let got: f64 = nodes.iter().zip(w).map(|(&tn, wj)| wj * f(tn)).sum();
                assert!((got - f(t)).abs() < 1e-10, "{} nodes at {t}: {got} against {}", nodes.len(), f(t));
                assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                assert!(w[nodes.len()..].iter().all(|&x| x == 0.0));
            }
        }
    }

    /// A cell's nodes: its first sample, equal parts to the next cell's first (its own last at a
    /// stretch's end), fewer where it has fewer samples.
    #[test]
    fn a_cells_nodes_cut_it_into_equal_parts() {
        assert_eq!(node_samples(&(0..32), 100, 4), ([0, 8, 16, 24, 32], 5));
        assert_eq!(node_samples(&(0..8), 100, 2), ([0, 4, 8, 8, 8], 3));
        assert_eq!(node_samples(&(96..100), 100, 4), ([96, 97, 98, 99, 99], 4));
        assert_eq!(node_samples(&(10..12), 12, 4), ([10, 11, 11, 11, 11], 2));
        assert_eq!(node_samples(&(10..11), 11, 2), ([10, 10, 10, 10, 10], 1));
    }
}
