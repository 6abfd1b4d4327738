//! Accumulation: one pass over the data sums, per run and axis, the Gram matrix of the columns
//! against the residual ([`Gram`]); [`accumulate_pairs`] sums only the pairs a solve reaches,
//! so a candidate's block against the model costs no more than it needs, sample by sample or in
//! cells ([`super::nodes`]).

use crate::calib::result::axes::is_clipped;

use super::cells::Cells;
use super::chain::Cursor;
use super::knot_split::KnotSplit;
use super::loop_data::LoopData;
use super::model::Model;
use super::pass::Pass;
use super::sums::{Gram, Reach, RowBlock, SharedRows, Touched, CHUNK};
use crate::calib::effects::terms::Col;

/// One pass: per-run sums of `cols` against the residual of `model` (clipped samples left out of
/// their axis), every column pair.
pub fn accumulate(data: &LoopData, model: &Model, cols: &[Col]) -> Vec<Gram> {
    accumulate_pairs(data, model, cols, &Reach::all(cols.len()), Cells::Exact)
}

/// [`accumulate`] of the pairs `reach` names (every other entry of XᵀX is 0), the samples
/// summed in `cells` ([`Cells`]). A run's sums leave out the columns that are zero in it (a
/// table harmonic's pair of another run: [`Col::in_run`]), whose entries stay 0: on six runs a
/// harmonic has twelve columns, of which a run sees two.
pub fn accumulate_pairs(data: &LoopData, model: &Model, cols: &[Col], reach: &Reach, cells: Cells) -> Vec<Gram> {
    let pass = Pass::new(data, model, cols, reach);
    (0..data.kin.runs.len())
        .map(|r| {
            let pose = data.kin.runs[r].pose;
            let keep: Vec<usize> = (0..cols.len()).filter(|&i| cols[i].in_run(r, pose)).collect();
            if keep.len() == cols.len() {
                return run_sums(&pass, r, cells);
            }
            let own: Vec<Col> = keep.iter().map(|&i| cols[i]).collect();
            let own_reach = reach.restricted(&keep);
            run_sums(&Pass::new(data, model, &own, &own_reach), r, cells).scattered(&keep, cols.len())
        })
        .collect()
}

/// The sums of run `r` of `pass`, sample by sample or in `cells`.
fn run_sums(pass: &Pass, r: usize, cells: Cells) -> Gram {
    match pass.cell_form(r, cells) {
        form if form.size == 1 => sample_sums(pass, r),
        form => super::nodes::cell_sums(pass, r, form),
    }
}

/// The sums of run `r`, sample by sample.
fn sample_sums(pass: &Pass, r: usize) -> Gram {
    let (ev, plan, reach) = (&pass.ev, &pass.plan, pass.reach);
    let rk = &pass.data.kin.runs[r];
    let l = reach.0.len();
    let (mut common, mut model_common) = (Vec::with_capacity(l), Vec::new());
    let mut total = Gram::new(l);
    let mut local = Gram::new(l);
    let mut touched = Touched::new(l);
    let all_rows: Vec<usize> = (0..l).collect();
    let valid = &pass.data.runs[r].valid;
    let mut cursor = Cursor::default();
    let mut block: [RowBlock; 3] = std::array::from_fn(|_| RowBlock::new(reach));
    let mut shared = SharedRows::new(reach);
    let mut split = (!pass.dense).then(|| KnotSplit::new(plan, reach));
    for start in (0..rk.samples.len()).step_by(CHUNK) {
        let end = (start + CHUNK).min(rk.samples.len());
        // `local` was drained: its three XᵀX are equal (zero).
        let mut same = true;
        for i in valid.indices_in(start, end) {
            let (s, p) = ev.visit(r, i, &mut cursor);
            ev.common_values(p, plan, &mut common);
            let pred = pass.predict(p, &common, &mut model_common);
            let used = s.rate_counts.map(|c| !is_clipped(c));
            let e: [f64; 3] = std::array::from_fn(|a| f64::from(s.rate_counts[a]) - pred[a]);
            for a in (0..3).filter(|&a| used[a]) {
                local.add_sample(a, e[a]);
            }
            if plan.all_common {
                shared.push(&common, e, used);
                if shared.is_full() {
                    shared.add_to(&mut local, &mut same);
                }
                continue;
            }
            for a in (0..3).filter(|&a| used[a]) {
                // Each pair goes to the upper triangle (`symmetrise` fills the rest).
                if let Some(split) = split.as_mut() {
                    // With knots: the rest a block at a time, the knots sample by sample.
                    split.add(ev, (p, plan, &common), a, e[a], &mut local, reach, &mut touched);
                } else {
                    // Every column at every sample, in column order, the rows summed a block
                    // at a time.
                    ev.fill_dense(p, plan, a, &common, block[a].push(e[a]));
                    if block[a].is_full() {
                        block[a].add_to(&mut local, a);
                    }
                }
            }
        }
        for (a, b) in block.iter_mut().enumerate() {
            b.add_to(&mut local, a);
        }
        shared.add_to(&mut local, &mut same);
        if let Some(split) = split.as_mut() {
            split.flush(&mut local, reach, &mut touched);
        }
        total.drain_rows(&mut local, if pass.dense { &all_rows } else { &touched.rows });
        touched.clear();
    }
    total.symmetrise();
    total
}
