//! A model: the effects it holds, the linear columns and shared parameters they bring, the
//! shared parameters' values, and the inputs of the kinematic chain those set.

use crate::calib::data::layout::Layout;
use crate::calib::effects::terms::Shifts;
use crate::calib::effects::Effect;
use crate::geometry::Pose;
use nalgebra::{Matrix3, Vector3};

use super::loop_data::LoopData;
use crate::calib::effects::terms::{Col, LinCol, SharedPar};

/// A zero-mean Gaussian prior on a shared parameter ([`Model::priors`]): its column in the
/// sums, its precision 1/σ², and its value where the sums were taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    /// Its column in the sums ([`Model::cols`]' order).
    pub col: usize,
    /// 1/σ², in the parameter's fitted unit.
    pub precision: f64,
    /// Its value where the sums were taken (the prior pulls the step towards −value).
    pub value: f64,
}

/// A model: its effects, columns and current parameter values.
#[derive(Debug, Clone)]
pub struct Model {
    /// Effects added, in order.
    pub effects: Vec<Effect>,
    /// Per-axis linear columns.
    pub lin: Vec<LinCol>,
    /// Shared parameters.
    pub shared: Vec<SharedPar>,
    /// Coefficients of `lin`, per axis.
    pub beta: [Vec<f64>; 3],
    /// Values of `shared`.
    pub theta: Vec<f64>,
    /// Unit axis directions (rows of M normalised) that define the rate along each axis for the
    /// rate-dependent scale, updated every iteration.
    pub s_hat: [Vector3<f64>; 3],
    /// Earth's vertical rate when it is known (from a latitude) rather than fitted, °/s.
    pub earth_vertical_known_dps: f64,
    /// Shared parameters a fit found the runs could not bound within their physical size: held
    /// by their prior ([`SharedPar::prior`]) in every solve of this model.
    pub prior_held: Vec<SharedPar>,
    /// What of the data the effects' columns depend on.
    pub layout: Layout,
}

impl Model {
    /// The linear model of EXCITER.md eq. 6 with all coefficients 0, for data in both poses.
    pub fn base() -> Self {
        Self::base_for(&Pose::ALL)
    }

    /// The linear model for `data`.
    pub fn for_data(data: &LoopData) -> Self {
        Self { layout: data.layout.clone(), ..Self::base_for(&data.poses) }
    }

    /// The linear model for data holding `poses` (and no free drift).
    pub fn base_for(poses: &[Pose]) -> Self {
        Self {
            effects: Vec::new(),
            lin: vec![LinCol::Omega(0), LinCol::Omega(1), LinCol::Omega(2), LinCol::One],
            shared: Vec::new(),
            beta: std::array::from_fn(|_| vec![0.0; 4]),
            theta: Vec::new(),
            s_hat: std::array::from_fn(|a| Vector3::ith(a, 1.0)),
            earth_vertical_known_dps: 0.0,
            prior_held: Vec::new(),
            layout: Layout { poses: poses.to_vec(), ..Layout::default() },
        }
    }

    /// Columns of the model: linear then shared.
    pub fn cols(&self) -> Vec<Col> {
        self.lin.iter().map(|&c| Col::Lin(c)).chain(self.shared.iter().map(|&p| Col::Shared(p))).collect()
    }

    /// The priors of the shared parameters it holds by them ([`Model::prior_held`]) at their
    /// values, each at its column of the sums of [`Model::cols`].
    pub fn priors(&self) -> Vec<Prior> {
        let nl = self.lin.len();
        self.shared
            .iter()
            .zip(&self.theta)
            .enumerate()
            .filter(|(_, (p, _))| self.prior_held.contains(p))
            .filter_map(|(k, (p, &value))| Some(Prior { col: nl + k, precision: p.prior()?.sigma.powi(-2), value }))
            .collect()
    }

    /// Value of a shared parameter, if in the model.
    pub fn theta_of(&self, p: SharedPar) -> Option<f64> {
        self.shared.iter().position(|&q| q == p).map(|i| self.theta[i])
    }

    /// Coefficient of a linear column on an axis, if in the model.
    pub fn beta_of(&self, axis: usize, c: LinCol) -> Option<f64> {
        self.lin.iter().position(|&q| q == c).map(|i| self.beta[axis][i])
    }

    /// M, counts per °/s.
    pub fn m(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|a, k| self.beta_of(a, LinCol::Omega(k)).unwrap_or(0.0))
    }

    /// The model with `effect` added, its linear coefficients and shared parameters set from
    /// `init_lin` (per axis, one per new linear column) and `init_shared`.
    pub fn with(&self, effect: Effect, init_lin: [Vec<f64>; 3], init_shared: Vec<f64>) -> Self {
        let (lin, shared) = effect.params(&self.layout);
        debug_assert_eq!(shared.len(), init_shared.len(), "{effect:?}: a value for each shared parameter");
        let mut m = self.clone();
        m.effects.push(effect);
        m.lin.extend(lin);
        for (b, init) in m.beta.iter_mut().zip(init_lin) {
            b.extend(init);
        }
        m.shared.extend(shared);
        m.theta.extend(init_shared);
        m
    }

    /// The model with `effect` taken out (its columns and parameters), the rest as fitted.
    pub fn without(&self, effect: Effect) -> Self {
        let (lin, shared) = effect.params(&self.layout);
        let mut m = self.clone();
        m.effects.retain(|&e| e != effect);
        let keep_lin: Vec<bool> = self.lin.iter().map(|c| !lin.contains(c)).collect();
        let keep =
            |v: &Vec<f64>, k: &[bool]| v.iter().zip(k).filter(|(_, &k)| k).map(|(&x, _)| x).collect::<Vec<f64>>();
        for b in &mut m.beta {
            *b = keep(b, &keep_lin);
        }
        m.lin.retain(|c| !lin.contains(c));
        let keep_shared: Vec<bool> = self.shared.iter().map(|p| !shared.contains(p)).collect();
        m.theta = keep(&self.theta, &keep_shared);
        m.shared.retain(|p| !shared.contains(p));
        m.prior_held.retain(|p| !shared.contains(p));
        m
    }

    /// Whether shared parameter `p` only shapes its effect's linear columns and these are all 0
    /// (a warm-up's time constant while its amplitude is 0): its Jacobian is then 0, and the
    /// effect is absent whatever its value.
    pub fn shapes_only_zero_columns(&self, p: SharedPar) -> bool {
        let mut own = self.lin.iter().enumerate().filter(|(_, c)| matches!(c, LinCol::Of(e, _) if *e == p.effect));
        let mut any = false;
        let all_zero = own.all(|(i, _)| {
            any = true;
            (0..3).all(|a| self.beta[a][i] == 0.0)
        });
        any && all_zero
    }

    pub(super) fn update_directions(&mut self) {
        let m = self.m();
        for a in 0..3 {
            let row = Vector3::new(m[(a, 0)], m[(a, 1)], m[(a, 2)]);
            if row.norm() > 0.0 {
                self.s_hat[a] = row.normalize();
            }
        }
    }
}

/// The kinematic chain's inputs at a model's values: each shared parameter's effect sets its own.
pub(super) fn shifts_of(m: &Model) -> Shifts {
    let mut s = Shifts::nominal(m.earth_vertical_known_dps);
    for (&p, &v) in m.shared.iter().zip(&m.theta) {
        p.effect.behaviour(|b| b.shift(p.k, v, &mut s));
    }
    s
}
