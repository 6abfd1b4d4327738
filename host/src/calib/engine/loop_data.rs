//! The data the loop fits, cached once: each run's kinematic samples, the stretches of them
//! clear of the run's ends and gaps, and its die temperature smoothed.

use crate::calib::data::kinematics::{temperature_at, Kinematics, RunKinematics};
use crate::calib::data::layout::Layout;
use crate::calib::effects::MAX_DELAY_S;
use crate::geometry::Pose;

/// Span of the moving average that smooths OUT_TEMP, s. The register counts whole °C; during
/// warm-up it steps every few seconds, so 20 s turns the steps into a ramp, and it is 10× the
/// table period at 0.5 Hz, so it cannot follow table-synchronous structure.
pub const TEMPERATURE_SMOOTHING_S: f64 = 20.0;

/// Which kinematic samples of a run the loop uses: those clear of the run's ends and gaps by
/// [`MAX_DELAY_S`], i.e. one index range per stretch between gaps (a handful per run), held as
/// ranges rather than a flag per sample (issue 7's memory bar: a 4-hour capture has 11.5 M).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ValidSamples {
    /// Ascending, disjoint, non-empty index ranges.
    ranges: Vec<std::ops::Range<usize>>,
}

impl ValidSamples {
    /// Whether sample `i` is used.
    pub fn contains(&self, i: usize) -> bool {
        let k = self.ranges.partition_point(|r| r.end <= i);
        self.ranges.get(k).is_some_and(|r| r.contains(&i))
    }

    /// The used samples' indices, ascending.
    pub fn indices(&self) -> impl Iterator<Item = usize> + '_ {
        self.ranges.iter().flat_map(|r| r.clone())
    }

    /// The used samples' indices in `lo..hi`, ascending.
    pub fn indices_in(&self, lo: usize, hi: usize) -> impl Iterator<Item = usize> + '_ {
        self.ranges_in(lo, hi).flatten()
    }

    /// The used samples in `lo..hi` as ranges of consecutive indices, ascending: each lies
    /// between two gaps.
    pub fn ranges_in(&self, lo: usize, hi: usize) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
        let k = self.ranges.partition_point(|r| r.end <= lo);
        self.ranges[k..].iter().take_while(move |r| r.start < hi).map(move |r| r.start.max(lo)..r.end.min(hi))
    }

    /// The first used sample.
    pub fn first(&self) -> Option<usize> {
        self.ranges.first().map(|r| r.start)
    }

    /// The last used sample.
    pub fn last(&self) -> Option<usize> {
        self.ranges.last().map(|r| r.end - 1)
    }

    /// Samples used.
    pub fn len(&self) -> usize {
        self.ranges.iter().map(|r| r.len()).sum()
    }

    /// Whether no sample is used.
    pub fn is_empty(&self) -> bool {
        self.ranges.is_empty()
    }

    /// Samples at times `t_s(0..n)` (s, ascending) whose spacing beyond `gap_s` is a gap, each
    /// used when at least `guard` samples lie between it and the run's ends or a gap: stretch
    /// [a, b] between gaps gives [a + guard, b − guard].
    pub(super) fn of(n: usize, t_s: impl Fn(usize) -> f64, gap_s: f64, guard: usize) -> Self {
        let mut ranges = Vec::new();
        let mut a = 0;
        for b in 0..n {
            if b + 1 == n || t_s(b + 1) - t_s(b) > gap_s {
                if b >= a + 2 * guard {
                    ranges.push(a + guard..b - guard + 1);
                }
                a = b + 1;
            }
        }
        Self { ranges }
    }
}

/// Per-run data the loop adds to the kinematics.
#[derive(Debug, Clone)]
pub struct RunData {
    /// Which kinematic samples are used (clear of the run's ends and gaps by [`MAX_DELAY_S`]).
    pub valid: ValidSamples,
    /// Samples used.
    pub n_valid: usize,
    /// Time of the first and last used sample, s.
    pub span_s: (f64, f64),
}

/// The cached kinematics and what the loop derives from them once.
#[derive(Debug, Clone)]
pub struct LoopData {
    /// Kinematics of every run.
    pub kin: Kinematics,
    /// Per run.
    pub runs: Vec<RunData>,
    /// Time of the first sample, s (origin of the warm-up exponential).
    pub t0_s: f64,
    /// Middle and half-span of the capture, s (for the polynomial drift).
    pub t_mid_s: f64,
    /// Half-span, s.
    pub t_half_s: f64,
    /// The poses the runs are in, in order of first appearance.
    pub poses: Vec<Pose>,
    /// What the effects' columns depend on.
    pub layout: Layout,
    /// Mean die temperature over every sample, OUT_TEMP counts: the smoothed temperature is
    /// reckoned from it ([`RunTemperatures`]).
    pub temp_mean_counts: f64,
    /// Whether the die's temperature readings (OUT_TEMP) changed at all over the capture: if
    /// not, the smoothed temperature is 0 at every sample, and so is every column made from it.
    pub temp_moved: bool,
    /// Spread of the smoothed die temperature over every sample, °C, once asked for
    /// ([`LoopData::temp_spread_c`]).
    temp_spread_c: std::sync::OnceLock<f64>,
    /// Each run's smoothed die temperature on its grid, once a pass asks for it
    /// ([`LoopData::temperature_grid`]).
    temperature_grids: std::sync::OnceLock<Vec<TemperatureGrid>>,
}

/// Spacing of the grid on which a run's smoothed die temperature is kept, s: 10 ms, a short
/// cell. The smoothed temperature is a moving average of OUT_TEMP's whole-°C steps over
/// [`TEMPERATURE_SMOOTHING_S`], so piecewise linear with kinks where a step enters or leaves the
/// window; linear interpolation between grid points is exact on its pieces and off by at most
/// (1 °C / 20 s)·(10 ms / 4) = 1.25e-4 °C next to a kink (for a temperature coefficient of
/// 100 ppm/°C, 0.0125 ppm for those few samples).
pub const TEMPERATURE_GRID_S: f64 = 0.01;

/// One run's smoothed die temperature ([`RunTemperatures`]) at every `step`-th sample and at its
/// last, and linearly between them. Every pass takes the temperature at its points; swept from
/// the readings each time, that was an interpolation and a running sum per sample and pass (5 %
/// of `host calibrate` on `realistic-2speed-s101`). Kept per sample it would cost 4 bytes each
/// (44 MiB at 4 hours: issue 7's memory bar); on the grid, half a byte at 800 Hz.
#[derive(Debug, Clone)]
pub struct TemperatureGrid {
    step: usize,
    /// Index of the run's last sample.
    last: usize,
    /// The smoothed temperature at samples 0, step, 2·step, … and at `last`, °C.
    values: Vec<f32>,
}

impl TemperatureGrid {
    /// The grid of `run`, from one sweep of its samples.
    fn of(run: &RunKinematics, temp_mean_counts: f64) -> Self {
        let step = ((TEMPERATURE_GRID_S * run.sample_rate_hz).round() as usize).max(1);
        let last = run.samples.len().saturating_sub(1);
        let mut temps = RunTemperatures::new(run, temp_mean_counts);
        let mut values: Vec<f32> = (0..=last).step_by(step).map(|i| temps.at(i)).collect();
        if !last.is_multiple_of(step) {
            values.push(temps.at(last));
        }
        Self { step, last, values }
    }

    /// The smoothed temperature at sample `i`, °C from the capture mean: the grid's value at its
    /// points, linear between them.
    #[inline]
    pub fn at(&self, i: usize) -> f32 {
        let k = i / self.step;
        let (a, b) = (k * self.step, ((k + 1) * self.step).min(self.last));
        match (self.values.get(k), self.values.get(k + 1)) {
            (Some(&va), Some(&vb)) if b > a => {
                let w = (i - a) as f64 / (b - a) as f64;
                (f64::from(va) + w * (f64::from(vb) - f64::from(va))) as f32
            }
            (Some(&va), _) => va,
            _ => f32::NAN,
        }
    }
}

/// The smoothed die temperature at one run's samples, °C from the capture mean: the moving
/// average over [`TEMPERATURE_SMOOTHING_S`] of OUT_TEMP interpolated at each sample (falling 1
/// count per °C, datasheet Table 5), rounded to f32. Computed as the samples are visited, from
/// running sums of which only the 2h + 2 a window spans are kept (a ring), rather than held per
/// sample (4 bytes each, 44 MiB at 4 hours: issue 7's memory bar). Visiting a run's samples
/// forward costs one interpolation per sample; going back restarts the run. The passes read it
/// from a grid made in one such sweep ([`TemperatureGrid`]).
#[derive(Debug, Clone)]
pub struct RunTemperatures<'a> {
    run: &'a RunKinematics,
    temp_mean_counts: f64,
    /// Half-width of the moving average, samples.
    h: usize,
    /// Running sums: the sum of the first k interpolated readings at `prefix[k % prefix.len()]`.
    prefix: Vec<f64>,
    /// Readings summed so far.
    filled: usize,
    /// `filled % prefix.len()`, stepped rather than divided (three divisions per sample
    /// otherwise).
    slot: usize,
    sum: f64,
    /// Where `temperature_at` stands in the run's readings.
    cursor: usize,
}

impl<'a> RunTemperatures<'a> {
    /// The temperatures of `run`, from the mean over the capture, `temp_mean_counts`.
    pub fn new(run: &'a RunKinematics, temp_mean_counts: f64) -> Self {
        let dt = 1.0 / run.sample_rate_hz;
        let h = ((TEMPERATURE_SMOOTHING_S / 2.0) / dt).round() as usize;
        Self { run, temp_mean_counts, h, prefix: vec![0.0; 2 * h + 2], filled: 0, slot: 0, sum: 0.0, cursor: 0 }
    }

    /// At kept sample `i`, °C from the capture mean.
    pub fn at(&mut self, i: usize) -> f32 {
        let ring_len = self.prefix.len();
        let (a, b) = (i.saturating_sub(self.h), (i + self.h + 1).min(self.run.samples.len()));
        if a + ring_len <= self.filled {
            *self = Self::new(self.run, self.temp_mean_counts);
        }
        let next = |slot: usize| if slot + 1 == ring_len { 0 } else { slot + 1 };
        while self.filled < b {
            let t_us = self.run.samples.get(self.filled).t_us();
            let t = temperature_at(&self.run.temperatures, t_us, &mut self.cursor);
            self.sum += if t.is_finite() { f64::from(t) } else { self.temp_mean_counts };
            self.filled += 1;
            self.slot = next(self.slot);
            self.prefix[self.slot] = self.sum;
        }
        // Visited forward, b is the last reading summed and, a whole window away, a is the slot
        // after it (b − a = 2h + 1 = ring_len − 1).
        let b_slot = if b == self.filled { self.slot } else { b % ring_len };
        let a_slot = if b - a + 1 == ring_len { next(b_slot) } else { a % ring_len };
        // OUT_TEMP falls 1 count per °C (datasheet Table 5).
        let mean = (self.prefix[b_slot] - self.prefix[a_slot]) / (b - a) as f64;
        (-(mean - self.temp_mean_counts)) as f32
    }
}

impl LoopData {
    /// Marks usable samples and smooths the temperature.
    pub fn new(kin: Kinematics) -> Self {
        let mut runs = Vec::with_capacity(kin.runs.len());
        let (mut t_lo, mut t_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut temp_sum, mut temp_n) = (0.0, 0usize);
        let (mut temp_lo, mut temp_hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for r in &kin.runs {
            if let (Some(a), Some(b)) = (r.samples.first(), r.samples.last()) {
                t_lo = t_lo.min(a.t_s());
                t_hi = t_hi.max(b.t_s());
            }
            for t in r.temperatures_counts() {
                if t.is_finite() {
                    temp_sum += f64::from(t);
                    temp_n += 1;
                    temp_lo = temp_lo.min(t);
                    temp_hi = temp_hi.max(t);
                }
            }
        }
        let temp_mean = if temp_n > 0 { temp_sum / temp_n as f64 } else { 0.0 };
        for r in &kin.runs {
            let s = &r.samples;
            let dt = 1.0 / r.sample_rate_hz;
            let guard = (MAX_DELAY_S / dt).ceil() as usize + 1;
            // A gap is any spacing beyond 1.5 nominal periods (a dropped or excluded sample).
            let gap = 1.5 * dt;
            let valid = ValidSamples::of(s.len(), |i| s.get(i).t_s(), gap, guard);
            let n_valid = valid.len();
            let first = valid.first().map_or(0.0, |i| s.get(i).t_s());
            let last = valid.last().map_or(first, |i| s.get(i).t_s());
            runs.push(RunData { valid, n_valid, span_s: (first, last) });
        }
        let mut poses: Vec<Pose> = Vec::new();
        for r in &kin.runs {
            if !poses.contains(&r.pose) {
                poses.push(r.pose);
            }
        }
        let run_poses: Vec<Pose> = kin.runs.iter().map(|r| r.pose).collect();
        let spans: Vec<(f64, f64)> = runs.iter().map(|r| r.span_s).collect();
        let layout = Layout::new(poses.clone(), &run_poses, &spans);
        Self {
            kin,
            runs,
            t0_s: t_lo,
            t_mid_s: 0.5 * (t_lo + t_hi),
            t_half_s: (0.5 * (t_hi - t_lo)).max(1e-9),
            poses,
            layout,
            temp_mean_counts: temp_mean,
            temp_moved: temp_hi > temp_lo,
            temp_spread_c: std::sync::OnceLock::new(),
            temperature_grids: std::sync::OnceLock::new(),
        }
    }

    /// Run `r`'s smoothed die temperature on its grid; every run's grid is made the first time
    /// a pass asks (only passes whose columns use the temperature do, and only where it moved).
    pub fn temperature_grid(&self, r: usize) -> &TemperatureGrid {
        let grids = self
            .temperature_grids
            .get_or_init(|| self.kin.runs.iter().map(|run| TemperatureGrid::of(run, self.temp_mean_counts)).collect());
        &grids[r]
    }

    /// Spread of the smoothed die temperature over every sample, °C: a sweep over every
    /// sample, made the first time a candidate rule asks (only the temperature drift's does,
    /// and only once the residual drifts), not for every calibration.
    pub fn temp_spread_c(&self) -> f64 {
        if !self.temp_moved {
            return 0.0;
        }
        *self.temp_spread_c.get_or_init(|| {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for r in &self.kin.runs {
                let mut temps = RunTemperatures::new(r, self.temp_mean_counts);
                for i in 0..r.samples.len() {
                    let t = f64::from(temps.at(i));
                    lo = lo.min(t);
                    hi = hi.max(t);
                }
            }
            hi - lo
        })
    }
}
