//! The trust matrix's arithmetic (`trust_matrix` bench): a calibration's z-values against the
//! simulated truth, and a cell's figures and bars over its seeds. Plain functions, unit-tested by
//! the `bench_measured` test target (`host/tests/bench_measured.rs`).

use super::replay::{max_abs, triple};
use serde_json::Value;
use std::ops::RangeInclusive;

pub use host::calib::result::truth_check::{Zs, Z_COUNT};

/// The z-values of a calibration against the simulator's truth file (`x.truth.json`, its
/// `m_counts_per_dps`): [`host::calib::result::truth_check::z_values`].
pub fn z_values(cal: &Value, truth: &Value) -> Result<Zs, String> {
    let m: [[f64; 3]; 3] = [0, 1, 2]
        .map(|i| triple(&truth["m_counts_per_dps"][i], "truth: m_counts_per_dps[i]"))
        .into_iter()
        .collect::<Result<Vec<_>, _>>()?
        .try_into()
        .expect("three rows");
    host::calib::result::truth_check::z_values(cal, &m)
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
