//! The trust matrix's arithmetic (`trust_matrix` bench): a calibration's z-values against the
//! simulated truth, and a cell's figures and bars over its seeds. Plain functions, unit-tested by
//! the `bench_measured` test target (`host/tests/bench_measured.rs`).

use super::replay::{max_abs, number, triple};
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use serde_json::Value;
use std::ops::RangeInclusive;

/// z-values judged per axis: the sensitivity, the three elements of the axis' row of M, and the
/// direction, in the order `validation/check.py` appends them.
pub const Z_PER_AXIS: usize = 5;

/// z-values judged per calibration. (check.py's docstring says 21; its code appends the
/// [`Z_PER_AXIS`] values above for each of the three axes, and these are those.)
pub const Z_COUNT: usize = 3 * Z_PER_AXIS;

/// One calibration's z-values, axis x first.
pub type Zs = [f64; Z_COUNT];

const AXES: [char; 3] = ['x', 'y', 'z'];

/// 2-dof Mahalanobis distance of s = m/|m| from `s_true` in the plane normal to s, with `cov3`
/// the covariance of the row m: check.py's `direction_z`, step for step. A covariance that is
/// not positive in that plane (check.py: infinite) or not a number (check.py: NaN) is infinite.
pub fn direction_z(m: [f64; 3], cov3: [[f64; 3]; 3], s_true: [f64; 3]) -> f64 {
    let m = Vector3::from(m);
    let cov = Matrix3::from_fn(|r, c| cov3[r][c]);
    let nm = m.norm();
    let s = m / nm;
    let a = if s.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let u = s.cross(&a).normalize();
    let v = s.cross(&u);
    // ds = (I − s sᵀ) dm / |m|: its components along u and v are u·dm/|m| and v·dm/|m|.
    let basis = [u / nm, v / nm];
    let c = Matrix2::from_fn(|r, q| basis[r].dot(&(cov * basis[q])));
    let d = s - Vector3::from(s_true);
    let e = Vector2::new(u.dot(&d), v.dot(&d));
    let det = c[(0, 0)] * c[(1, 1)] - c[(0, 1)] * c[(1, 0)];
    if det.is_nan() || det <= 0.0 {
        return f64::INFINITY;
    }
    let q = (c[(1, 1)] * e[0] * e[0] - 2.0 * c[(0, 1)] * e[0] * e[1] + c[(0, 0)] * e[1] * e[1]) / det;
    q.max(0.0).sqrt()
}

/// The z-values of a calibration (`calibration.json` of `host calibrate`) against the simulator's
/// truth (`x.truth.json`: `k_counts_per_dps`, rows `s`, `m_counts_per_dps`, check.py's `k`, `S`,
/// `M`), computed as `validation/check.py` does. Per axis i: |k − k_true| / `k_sigma`; each
/// element j of row i of M, |m_ij − M_ij| / √cov[p][p] with p the index of `m_<i><j>` in
/// `param_names` or else 4i + j; and [`direction_z`] of row i with the rows' 3×3 block of `cov`.
pub fn z_values(cal: &Value, truth: &Value) -> Result<Zs, String> {
    let names: Vec<&str> = cal["param_names"]
        .as_array()
        .ok_or("calibration: param_names is not a list")?
        .iter()
        .map(|n| n.as_str().ok_or("calibration: param_names holds a non-string"))
        .collect::<Result<_, _>>()?;
    let cov_rows = cal["cov"].as_array().ok_or("calibration: cov is not a matrix")?;
    let cov = |r: usize, q: usize| -> Result<f64, String> {
        cov_rows
            .get(r)
            .and_then(|row| row.get(q))
            .and_then(Value::as_f64)
            .ok_or(format!("calibration: no cov[{r}][{q}]"))
    };
    let axes = cal["axes"].as_array().filter(|a| a.len() == 3).ok_or("calibration: axes is not 3 axes")?;
    let mut z = [0.0; Z_COUNT];
    for (i, a) in axes.iter().enumerate() {
        let k = number(&a["k_counts_per_dps"], "calibration: axes[i].k_counts_per_dps")?;
        let k_sigma = number(&a["k_sigma"], "calibration: axes[i].k_sigma")?;
        let k_true = number(&truth["k_counts_per_dps"][i], "truth: k_counts_per_dps[i]")?;
        let m = triple(&cal["m_counts_per_dps"][i], "calibration: m_counts_per_dps[i]")?;
        let m_true = triple(&truth["m_counts_per_dps"][i], "truth: m_counts_per_dps[i]")?;
        let s_true = triple(&truth["s"][i], "truth: s[i]")?;
        let idx: [usize; 3] = std::array::from_fn(|j| {
            let name = format!("m_{}{}", AXES[i], AXES[j]);
            names.iter().position(|n| *n == name).unwrap_or(4 * i + j)
        });
        let zi = &mut z[Z_PER_AXIS * i..Z_PER_AXIS * (i + 1)];
        zi[0] = (k - k_true).abs() / k_sigma;
        for (j, &p) in idx.iter().enumerate() {
            zi[1 + j] = (m[j] - m_true[j]).abs() / cov(p, p)?.sqrt();
        }
        let mut cov3 = [[0.0; 3]; 3];
        for (r, &pr) in idx.iter().enumerate() {
            for (q, &pq) in idx.iter().enumerate() {
                cov3[r][q] = cov(pr, pq)?;
            }
        }
        zi[4] = direction_z(m, cov3, s_true);
    }
    Ok(z)
}

/// Above this |z| a result the tool vouches for (exit 0) is confidently wrong.
pub const BAR_Z: f64 = 4.0;

/// Where the RMS of an honest σ's z-values lies, over a cell's exit-0 seeds. (Of each axis' five
/// values the direction is a 2-dof distance, E z² = 2, so an honest σ gives an RMS near
/// √(6/5) ≈ 1.1.)
pub const BAR_RMS: RangeInclusive<f64> = 0.7..=1.3;

/// What became of one seed of a cell.
#[derive(Debug, Clone, Default)]
pub struct SeedOutcome {
    /// `host calibrate`'s exit status (None: it did not run, or did not exit normally).
    pub code: Option<i32>,
    /// Its z-values, if it wrote a readable calibration.
    pub z: Option<Zs>,
    /// Its CPU time (user + system), s.
    pub cpu_s: Option<f64>,
}

/// A cell's figures over its seeds.
#[derive(Debug, Clone, PartialEq)]
pub struct CellStats {
    pub seeds: usize,
    /// Seeds by exit status: 0 (at the noise floor), 3 (flagged), anything else or none.
    pub exit0: usize,
    pub exit3: usize,
    pub other: usize,
    /// Largest |z| over the exit-0 seeds (None: no seed exited 0). An exit-0 seed without a
    /// readable result counts as infinite.
    pub max_z_exit0: Option<f64>,
    /// Largest |z| over every seed with a result, flagged ones included (None: no result).
    pub max_z_all: Option<f64>,
    /// RMS of every z of the exit-0 seeds with a result (None: none).
    pub z_rms_exit0: Option<f64>,
    /// Exit-0 seeds with some |z| > [`BAR_Z`] (or no readable result).
    pub confidently_wrong: usize,
    /// CPU time of the calibrations that ran, s, and how many ran.
    pub cpu_s: f64,
    pub calibrations: usize,
}

/// RMS of every value of every set (a NaN counts as infinite; NaN of nothing).
pub fn z_rms(zs: &[Zs]) -> f64 {
    let n = zs.len() * Z_COUNT;
    let sum: f64 = zs.iter().flatten().map(|z| if z.is_nan() { f64::INFINITY } else { z * z }).sum();
    (sum / n as f64).sqrt()
}

/// A cell's figures from its seeds' outcomes.
pub fn cell_stats(seeds: &[SeedOutcome]) -> CellStats {
    let at_floor: Vec<&SeedOutcome> = seeds.iter().filter(|s| s.code == Some(0)).collect();
    let exit3 = seeds.iter().filter(|s| s.code == Some(3)).count();
    let worst = |s: &SeedOutcome| s.z.as_ref().map_or(f64::INFINITY, |z| max_abs(z));
    let max_of = |v: Vec<f64>| v.into_iter().reduce(f64::max);
    let zs: Vec<Zs> = at_floor.iter().filter_map(|s| s.z).collect();
    CellStats {
        seeds: seeds.len(),
        exit0: at_floor.len(),
        exit3,
        other: seeds.len() - at_floor.len() - exit3,
        max_z_exit0: max_of(at_floor.iter().map(|s| worst(s)).collect()),
        max_z_all: max_of(seeds.iter().filter(|s| s.z.is_some()).map(worst).collect()),
        z_rms_exit0: (!zs.is_empty()).then(|| z_rms(&zs)),
        confidently_wrong: at_floor.iter().filter(|s| worst(s) > BAR_Z).count(),
        cpu_s: seeds.iter().filter_map(|s| s.cpu_s).sum(),
        calibrations: seeds.iter().filter(|s| s.cpu_s.is_some()).count(),
    }
}

impl CellStats {
    /// No seed exited 0 with some |z| > [`BAR_Z`].
    pub fn never_confidently_wrong(&self) -> bool {
        self.confidently_wrong == 0
    }

    /// The exit-0 seeds' z RMS within [`BAR_RMS`] (None: no exit-0 seed, nothing to judge).
    pub fn rms_holds(&self) -> Option<bool> {
        self.z_rms_exit0.map(|r| BAR_RMS.contains(&r))
    }

    /// Every seed exited 0 (and there was one).
    pub fn all_exit0(&self) -> bool {
        self.seeds > 0 && self.exit0 == self.seeds
    }

    /// CPU s per calibration (NaN of none).
    pub fn cpu_per_calibration(&self) -> f64 {
        self.cpu_s / self.calibrations as f64
    }
}

/// The matrix's bars over its cells.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Bars {
    pub cells: usize,
    /// Cells with some exit-0 seed at |z| > [`BAR_Z`]. Bar: none.
    pub confidently_wrong_cells: usize,
    /// Cells with an exit-0 seed, and those of them whose z RMS is outside [`BAR_RMS`]. Bar: none.
    pub rms_cells: usize,
    pub rms_outside: usize,
    /// Cells of the live design with catalogued effects only, and those of them where some
    /// seed did not exit 0. Bar: none (and some such cell ran).
    pub live_cells: usize,
    pub live_not_all_exit0: usize,
}

/// The bars over `cells`, each with whether it is a cell of the live design with catalogued
/// effects only.
pub fn bars<'a>(cells: impl IntoIterator<Item = (&'a CellStats, bool)>) -> Bars {
    let mut b = Bars {
        cells: 0,
        confidently_wrong_cells: 0,
        rms_cells: 0,
        rms_outside: 0,
        live_cells: 0,
        live_not_all_exit0: 0,
    };
    for (c, live) in cells {
        b.cells += 1;
        b.confidently_wrong_cells += usize::from(!c.never_confidently_wrong());
        if let Some(holds) = c.rms_holds() {
            b.rms_cells += 1;
            b.rms_outside += usize::from(!holds);
        }
        if live {
            b.live_cells += 1;
            b.live_not_all_exit0 += usize::from(!c.all_exit0());
        }
    }
    b
}

impl Bars {
    pub fn never_confidently_wrong(&self) -> bool {
        self.confidently_wrong_cells == 0
    }
    pub fn rms_holds(&self) -> bool {
        self.rms_outside == 0
    }
    /// None when no cell of the live design with catalogued effects ran.
    pub fn live_holds(&self) -> Option<bool> {
        (self.live_cells > 0).then_some(self.live_not_all_exit0 == 0)
    }
    pub fn all_hold(&self) -> bool {
        self.never_confidently_wrong() && self.rms_holds() && self.live_holds() != Some(false)
    }
}
