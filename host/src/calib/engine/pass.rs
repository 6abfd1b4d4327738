//! What a pass fixes before it visits the samples ([`Pass`]): the evaluator of the chain at the
//! model, the columns' plan, and how the model's output is reckoned at a point.

use super::cells::{CellForm, Cells};
use super::chain::{ColPlan, Evaluator};
use super::loop_data::LoopData;
use super::model::Model;
use super::sums::Reach;
use crate::calib::effects::terms::{Col, Point};

/// What a pass fixes before it visits the samples: the columns' plan and how the model's output
/// is reckoned at a point.
pub(super) struct Pass<'a> {
    pub(super) data: &'a LoopData,
    pub(super) ev: Evaluator<'a>,
    pub(super) plan: ColPlan,
    pub(super) reach: &'a Reach,
    /// Whether the plan has no knots: every column is then in `plan.dense`, in column order.
    pub(super) dense: bool,
    /// Whether the pass's list leads with the model's own columns: their axis-independent
    /// values are then the plan's first ones, computed once per point rather than twice.
    model_leads: bool,
    /// Whether every coefficient of the model is zero (the linear fit's one pass, from zero):
    /// it predicts an exact 0 at every point, Σ 0·x over finite columns.
    predicts_zero: bool,
    /// The highest multiple of the turn rate at which a column of the pass or of the model
    /// varies ([`Col::turn_multiple`]).
    turn_multiple: u32,
}

impl<'a> Pass<'a> {
    pub(super) fn new(data: &'a LoopData, model: &'a Model, cols: &[Col], reach: &'a Reach) -> Self {
        let ev = Evaluator::for_columns(data, model, cols);
        debug_assert_eq!(reach.0.len(), cols.len());
        let plan = ColPlan::of(cols.iter().copied());
        let dense = plan.knots.is_empty();
        debug_assert!(!dense || plan.dense.iter().enumerate().all(|(k, d)| d.0 == k));
        let model_leads = ev.lin_plan.dense.len() <= plan.dense.len()
            && ev.lin_plan.dense.iter().zip(&plan.dense).all(|(m, c)| m.1 == c.1);
        let predicts_zero = model.beta.iter().flatten().all(|&b| b == 0.0);
        let turn_multiple = cols.iter().chain(&model.cols()).map(|c| c.turn_multiple()).max().unwrap_or(0);
        Self { data, ev, plan, reach, dense, model_leads, predicts_zero, turn_multiple }
    }

    /// The cells of run `r` (`cells`): long where every column varies slowly enough at its speed.
    pub(super) fn cell_form(&self, r: usize, cells: Cells) -> CellForm {
        let rk = &self.data.kin.runs[r];
        let turn_hz = rk.steady_rate_dps.abs() * rk.gear_ratio.abs().max(1.0) / 360.0;
        cells.form(rk.sample_rate_hz, f64::from(self.turn_multiple) * turn_hz)
    }

    /// The model's output on the three axes at `p`, whose values of the plan's
    /// axis-independent columns are `common` (`model_common`: scratch).
    #[inline]
    pub(super) fn predict(&self, p: &Point, common: &[f64], model_common: &mut Vec<f64>) -> [f64; 3] {
        if self.predicts_zero {
            [0.0; 3]
        } else if self.model_leads {
            self.ev.predict3_with(p, &common[..self.ev.lin_plan.dense.len()])
        } else {
            self.ev.common_values(p, &self.ev.lin_plan, model_common);
            self.ev.predict3_with(p, model_common)
        }
    }
}
