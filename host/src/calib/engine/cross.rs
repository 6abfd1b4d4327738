//! One pass of a model's columns against groups of other columns (the loop's candidates, the
//! effects the consider covariance weighs): the model's columns with every column, each group's
//! with its own. A candidate's score and an effect's consider covariance are both read from these
//! cross-products (issue 25's "one primitive"), so when the model they are wanted for is the one
//! the sums were taken of, and they were summed as it needs ([`Cells`]), the second reads them
//! rather than making its own pass.

use super::{accumulate_pairs, Cells, Col, Gram, LinCol, LoopData, Model, Reach, SharedPar};
use nalgebra::Vector3;
use std::ops::Range;

/// The summed cross-products of one model (at its parameters) with groups of columns.
#[derive(Debug, Clone)]
pub struct CrossSums {
    /// The model they were taken of: its columns and parameter values.
    lin: Vec<LinCol>,
    shared: Vec<SharedPar>,
    beta: [Vec<f64>; 3],
    theta: Vec<f64>,
    s_hat: [Vector3<f64>; 3],
    /// The model's columns, then every group's.
    cols: Vec<Col>,
    /// Each group's place in `cols`.
    blocks: Vec<Range<usize>>,
    /// How the samples were summed.
    cells: Cells,
    /// The sums over every run.
    total: Gram,
}

impl CrossSums {
    /// One pass over `data`: `model`'s columns against its residual and every column of
    /// `groups`, each group against itself, the samples summed in `cells`. `None` without runs.
    pub fn gather(data: &LoopData, model: &Model, groups: &[&[Col]], cells: Cells) -> Option<Self> {
        let mut cols = model.cols();
        let lead = cols.len();
        let mut blocks = Vec::with_capacity(groups.len());
        for g in groups {
            let start = cols.len();
            cols.extend_from_slice(g);
            blocks.push(start..cols.len());
        }
        let reach = Reach::blocks(lead, groups.iter().map(|g| g.len()));
        let total = Gram::sum(&accumulate_pairs(data, model, &cols, &reach, cells))?;
        Some(Self {
            lin: model.lin.clone(),
            shared: model.shared.clone(),
            beta: model.beta.clone(),
            theta: model.theta.clone(),
            s_hat: model.s_hat,
            cols,
            blocks,
            cells,
            total,
        })
    }

    /// The sums over every run, the model's columns first, then the groups' in order.
    pub fn total(&self) -> &Gram {
        &self.total
    }

    /// Where group `g`'s columns sit in [`CrossSums::total`].
    pub fn block(&self, g: usize) -> Range<usize> {
        self.blocks[g].clone()
    }

    /// Whether these are the sums of `model` as it is now: the same columns at the same values.
    fn of(&self, model: &Model) -> bool {
        self.lin == model.lin
            && self.shared == model.shared
            && self.beta == model.beta
            && self.theta == model.theta
            && self.s_hat == model.s_hat
    }

    /// The sums [`CrossSums::gather`] would take of `model` and `groups` in `cells`, read from
    /// these without a pass: when they are of the same model at the same values, summed the same
    /// way, and every group's columns lie within one gathered group (so every pair a group needs
    /// was summed). `None` otherwise.
    pub fn read(&self, model: &Model, groups: &[&[Col]], cells: Cells) -> Option<Gram> {
        if !self.of(model) || self.cells != cells {
            return None;
        }
        let lead = self.lin.len() + self.shared.len();
        let mut idx: Vec<usize> = (0..lead).collect();
        for g in groups {
            let block = self.blocks.iter().find(|b| g.iter().all(|c| self.cols[(*b).clone()].contains(c)))?;
            let within = &self.cols[block.clone()];
            for c in g.iter() {
                idx.push(block.start + within.iter().position(|d| d == c)?);
            }
        }
        Some(self.total.restricted(&idx))
    }
}
