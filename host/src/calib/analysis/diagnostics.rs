//! Residual diagnostics after a fit, per run and axis: size against the noise floor measured from
//! the data, whiteness, harmonics of the table rate, drift in time, dependence on temperature,
//! on the rate along the axis and on the motor's speed ripple, clipped samples; every test at a
//! Bonferroni-corrected level, every significant one turned into a sentence that says what, where,
//! how strong and what it suggests. Also the binned residual and spectrum the report plots.

use crate::calib::analysis::angle_sums::{
    angle_bin_centres, harmonic_coefficients, AngleFits, AngleSums, OrderSums, SlopeSums, ANGLE_BINS,
};
use crate::calib::analysis::binning::Binning;
use crate::calib::analysis::blocking::Blocking;
use crate::calib::analysis::spectrum::{AmplitudeSpectrum, Periodogram};
use crate::calib::analysis::stats::{chi2_to_sigma, chi2_upper_quantile};
use crate::calib::engine::{for_each_interpolated, Evaluator, LoopData, Model};
use crate::calib::result::axes::{is_clipped, AXES};
use crate::geometry::Pose;
use serde::{Deserialize, Serialize};

/// Highest harmonic of the table rate examined sample by sample (the catalogue's).
pub const MAX_ORDER: usize = crate::calib::effects::MAX_HARMONIC_ORDER;

/// θ2 bins of the plotted residual: 1° each.
pub const THETA2_BINS: usize = 360;

/// Block length of the whiteness test, s: 40 ms is 3× the correlation time of the noise behind
/// the slowest L3G4200D low-pass (12.5 Hz at 100 Hz ODR: 1/(2π·12.5 Hz) = 13 ms), so white sensor
/// noise gives white block means, and 1/6 of the period of the 8th harmonic at 0.5 Hz, so
/// structure survives the averaging.
const WHITENESS_BLOCK_S: f64 = 0.04;

/// Lags of the Ljung–Box statistic: 20 blocks = 0.8 s, one table period at 1.25 Hz or more.
const LJUNG_BOX_LAGS: usize = 20;

/// Width of the time bins of the drift test, s: 10 s, 5 table periods at 0.5 Hz, so that
/// table-synchronous structure averages out, and ≥ 10 bins in a 2-minute run.
const TIME_BIN_S: f64 = 10.0;

/// Bins of the rate-magnitude test.
const RATE_BINS: usize = 8;

/// RMS/floor above which the residual is called in excess of the floor. The floor's estimate is
/// biased low by < 3 % by noise correlated within its window (`CalOptions::noise_window_s`);
/// 5 % leaves that margin. The harmonic and drift tests are far more sensitive; this one catches
/// broadband structure.
const RMS_EXCESS_RATIO: f64 = 1.05;

/// Noise band for the long-run noise level: from this many table harmonics up (above the
/// catalogue's 8th), to half the gyro's low-pass cut-off (where the filter still passes > 94 %
/// of the power, Butterworth 2nd order), and at least this low limit, Hz.
const NOISE_BAND_FIRST_HARMONIC: f64 = 9.5;
const NOISE_BAND_MIN_HZ: f64 = 1.0;

/// Highest frequency in the plotted spectrum, in table harmonics.
const SPECTRUM_PLOT_HARMONICS: f64 = 10.5;
/// Points in a plotted spectrum.
const SPECTRUM_PLOT_POINTS: usize = 1500;

/// Tests per run and axis (9 orders, whiteness, time, temperature, rate, speed ripple, RMS).
const TESTS_PER_RUN_AXIS: usize = MAX_ORDER + 1 + 6;

/// One harmonic of the residual against θ2 in one run and axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OrderTerm {
    /// Harmonic number n (0 = the run's mean).
    pub order: u32,
    /// Amplitude, °/s.
    pub amplitude_dps: f64,
    /// Phase of a·sin + b·cos as atan2(b, a), degrees.
    pub phase_deg: f64,
    /// 1-σ of each coefficient, °/s.
    pub sigma_dps: f64,
    /// χ² of the coefficients against 0 (1 dof for n = 0, else 2).
    pub chi2: f64,
    /// Above the Bonferroni-corrected threshold.
    pub significant: bool,
}

/// A scalar test statistic.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Test {
    /// χ² (or z² for a slope).
    pub chi2: f64,
    /// Degrees of freedom.
    pub dof: usize,
    /// Equivalent normal deviate.
    pub sigma: f64,
    /// Above the Bonferroni-corrected threshold.
    pub significant: bool,
}

/// Diagnostics of one axis in one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisRunDiag {
    /// Axis name.
    pub axis: char,
    /// Unclipped samples.
    pub n: usize,
    /// RMS residual, °/s.
    pub rms_dps: f64,
    /// White-noise floor from the residual's high-frequency part, °/s.
    pub floor_dps: f64,
    /// Long-run noise level from the spectrum between the table harmonics, °/s.
    pub noise_dps: f64,
    /// rms / floor.
    pub rms_over_floor: f64,
    /// Harmonics 0..=8 of the residual against θ2.
    pub orders: Vec<OrderTerm>,
    /// Ljung–Box on block means.
    pub whiteness: Test,
    /// Spread of the 10-s bin means about the run mean.
    pub time_drift: Test,
    /// Range of the 10-s bin means, °/s.
    pub time_drift_range_dps: f64,
    /// Slope against the smoothed temperature, °/s per °C.
    pub temperature_slope_dps_per_c: f64,
    /// Its test.
    pub temperature: Test,
    /// Spread of the bin means against |rate along the axis|.
    pub rate: Test,
    /// Largest rate-bin mean, °/s.
    pub rate_max_dps: f64,
    /// Slope against the fractional speed deviation θ1'/steady − 1, °/s per %.
    pub ripple_slope_dps_per_percent: f64,
    /// Its test.
    pub ripple: Test,
    /// RMS of the speed deviation, %.
    pub speed_deviation_rms_percent: f64,
    /// Samples clipped at the rails (left out).
    pub clipped: u64,
}

/// Residual and fit against θ2 for a plot, per 1° bin.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Theta2Curve {
    /// Bin centres, degrees.
    pub theta2_deg: Vec<f64>,
    /// Mean residual, °/s (NaN for an empty bin).
    pub residual_dps: Vec<f64>,
    /// Standard error of the mean residual, °/s.
    pub residual_se_dps: Vec<f64>,
    /// Mean fitted output (offset included), °/s.
    pub fit_dps: Vec<f64>,
    /// Samples per bin.
    pub counts: Vec<u64>,
}

/// Plot data of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunPlots {
    /// Per axis, against θ2.
    pub theta2: Vec<Theta2Curve>,
    /// Per axis, residual amplitude spectrum.
    pub spectrum: Vec<AmplitudeSpectrum>,
    /// Sensor-table rate, Hz (markers at its multiples).
    pub table_hz: f64,
    /// Base-table rate, Hz.
    pub base_hz: f64,
}

/// Diagnostics of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunDiag {
    /// Run number, from 1.
    pub run: usize,
    /// Pose.
    pub pose: Pose,
    /// Commanded base-table rate, °/s.
    pub commanded_rate_dps: f64,
    /// Per axis.
    pub axes: Vec<AxisRunDiag>,
    /// Plot data.
    pub plots: RunPlots,
}

/// What a finding is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum FindingKind {
    /// Run mean (order 0) differs between runs.
    RunOffset,
    /// A harmonic of the table rate (order ≥ 1).
    Harmonic(u32),
    /// Failed whiteness.
    NotWhite,
    /// Drift within runs.
    TimeDrift,
    /// Follows the temperature.
    Temperature,
    /// Depends on the rate magnitude.
    RateDependence,
    /// Follows the speed ripple.
    SpeedRipple,
    /// RMS above the floor.
    RmsExcess,
}

/// One significant structure, in numbers ([`crate::present::findings`] says it in words).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Finding {
    /// What.
    pub kind: FindingKind,
    /// (run, axis index) where it is significant.
    pub places: Vec<(usize, usize)>,
    /// Largest size, in [`FindingKind::unit`].
    pub max_dps: f64,
    /// Largest significance, σ.
    pub max_sigma: f64,
    /// Where it is largest.
    pub worst: Worst,
}

/// The largest instance of a finding.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Worst {
    /// Run number, from 1.
    pub run: usize,
    /// The run's pose.
    pub pose: Pose,
    /// The run's commanded base-table rate, °/s.
    pub commanded_rate_dps: f64,
    /// Axis index.
    pub axis: usize,
    /// Size, in [`FindingKind::unit`].
    pub size: f64,
    /// Significance, σ (None for the RMS excess, which is a ratio, not a test).
    pub sigma: Option<f64>,
    /// The axis's RMS residual in that run, °/s.
    pub rms_dps: f64,
    /// Its noise floor there, °/s.
    pub floor_dps: f64,
}

impl FindingKind {
    /// The unit its sizes are in.
    pub fn unit(self) -> &'static str {
        match self {
            FindingKind::Temperature => "°/s per °C",
            FindingKind::SpeedRipple => "°/s per % of speed",
            FindingKind::RunOffset
            | FindingKind::Harmonic(_)
            | FindingKind::NotWhite
            | FindingKind::TimeDrift
            | FindingKind::RateDependence
            | FindingKind::RmsExcess => "°/s",
        }
    }
}

/// Diagnostics of a fit over all runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Diagnostics {
    /// Per run.
    pub runs: Vec<RunDiag>,
    /// Long-run noise variance per axis, counts² (the χ² weights are its inverse).
    pub noise_variance_counts2: [f64; 3],
    /// RMS residual per axis over all runs, °/s.
    pub rms_dps: [f64; 3],
    /// Noise floor per axis over all runs, °/s.
    pub floor_dps: [f64; 3],
    /// Blocking inflation of the residual per axis (1 for white).
    pub inflation: [f64; 3],
    /// Block length blocking settled on, samples.
    pub block_samples: [u64; 3],
    /// Contemporaneous correlation of the residuals between axes.
    pub correlation: [[f64; 3]; 3],
    /// Significant structures.
    pub findings: Vec<Finding>,
    /// Tests made (the Bonferroni divisor).
    pub tests: usize,
    /// Per-test significance level.
    pub alpha_per_test: f64,
}

impl Diagnostics {
    /// χ² weights: inverse long-run noise variance per axis.
    pub fn weights(&self) -> [f64; 3] {
        self.noise_variance_counts2.map(|v| 1.0 / v)
    }

    /// Whether any structure was found.
    pub fn has_structure(&self) -> bool {
        !self.findings.is_empty()
    }
}

/// One bin's sums: Σe, Σe², the count, and Σ of an extra value (the model's output).
#[derive(Debug, Clone, Copy, Default)]
struct Bin {
    sum: f64,
    sumsq: f64,
    count: f64,
    extra: f64,
}

/// Binned means, a bin's sums side by side (one bounds check a sample, where four vectors took
/// four).
#[derive(Debug, Clone)]
struct Bins(Vec<Bin>);

impl Bins {
    fn new(n: usize) -> Self {
        Self(vec![Bin::default(); n])
    }

    #[inline]
    fn add(&mut self, k: usize, e: f64, extra: f64) {
        let b = &mut self.0[k];
        b.sum += e;
        b.sumsq += e * e;
        b.count += 1.0;
        b.extra += extra;
    }

    /// Only Σe and the count, where nothing reads the others ([`Bins::spread`]).
    #[inline]
    fn add_to_mean(&mut self, k: usize, e: f64) {
        let b = &mut self.0[k];
        b.sum += e;
        b.count += 1.0;
    }

    /// χ² of the bin means about their weighted mean for variance `var`, dof, and the largest
    /// |bin mean − mean|, and the range of the means.
    fn spread(&self, var: f64) -> (f64, usize, f64, f64) {
        let total: f64 = self.0.iter().map(|b| b.count).sum();
        let mean = self.0.iter().map(|b| b.sum).sum::<f64>() / total.max(1.0);
        let (mut chi2, mut used, mut max_dev) = (0.0, 0usize, 0.0f64);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &Bin { sum: s, count: c, .. } in &self.0 {
            if c < 2.0 {
                continue;
            }
            let m = s / c;
            chi2 += c * (m - mean).powi(2) / var;
            max_dev = max_dev.max((m - mean).abs());
            lo = lo.min(m);
            hi = hi.max(m);
            used += 1;
        }
        (chi2, used.saturating_sub(1), max_dev, if used > 0 { hi - lo } else { 0.0 })
    }
}

/// Sums of the residual per bin of |rate along the axis|, for the rate-magnitude test of the
/// residual without its 0× and 1× parts (offset and phase misfits, reported as such). Those parts
/// are b₀ + a₁ sin θ + b₁ cos θ, so the bin sums of the residual, of sin θ and of cos θ, taken in
/// the first pass, give the bin means without them once the first pass has fitted a₁, b₁, b₀:
/// no per-sample bin number is kept for a second pass.
#[derive(Debug, Clone, Default)]
struct RateBinSums {
    e: [f64; RATE_BINS],
    sin: [f64; RATE_BINS],
    cos: [f64; RATE_BINS],
    count: [f64; RATE_BINS],
}

impl RateBinSums {
    #[inline]
    fn add(&mut self, k: usize, e: f64, (sin, cos): (f64, f64)) {
        self.e[k] += e;
        self.sin[k] += sin;
        self.cos[k] += cos;
        self.count[k] += 1.0;
    }

    /// The bins of the residual less its orders 0 and 1 (`coefs` of the first pass).
    fn without_orders_0_and_1(&self, coefs: &[(f64, f64); MAX_ORDER + 1]) -> Bins {
        let mut b = Bins::new(RATE_BINS);
        for (k, bin) in b.0.iter_mut().enumerate() {
            bin.sum = self.e[k] - (coefs[0].1 * self.count[k] + coefs[1].0 * self.sin[k] + coefs[1].1 * self.cos[k]);
            bin.count = self.count[k];
        }
        b
    }
}

/// How far the residual's slope against the speed deviation, `slope` (counts per %), lies beyond
/// what θ1''s own noise puts there, `full_echo`. The model reads ω_s through the encoder's θ1',
/// so the part n of a deviation that is the estimate's noise (the encoder's quantisation, the
/// timestamps' jitter) moves the prediction and not the gyro: the residual takes
/// −∂v/∂θ1'·n = −k·ω_a·(deviation in %)/100, whose mean over a run is `full_echo` =
/// −k·⟨ω_a⟩/100 (the sinusoid in θ2 averages out; ⟨ω_a⟩ is the constant θ2' term along the
/// axis). Of a real ripple the model takes the encoder's measure and leaves nothing, so the slope
/// lies between 0 (all ripple) and `full_echo` (all noise); a slope outside that, toward more than
/// the echo or the other way, is the table not doing what the encoder says. On a clean hour the
/// slope was 14.9σ from 0 and within the echo.
pub(crate) fn ripple_beyond_echo(slope: f64, full_echo: f64) -> f64 {
    let (lo, hi) = if full_echo < 0.0 { (full_echo, 0.0) } else { (0.0, full_echo) };
    if slope < lo {
        slope - lo
    } else if slope > hi {
        slope - hi
    } else {
        0.0
    }
}

/// The speed deviation θ1'/steady − 1, a fraction (× 100 where reported in %).
#[inline]
fn speed_deviation(theta1_rate_dps: f64, steady_rate_dps: f64) -> f64 {
    theta1_rate_dps / steady_rate_dps - 1.0
}

/// White-noise variance from the remainder of a centred moving average of half-width `w`;
/// windows holding a clipped (NaN) value are skipped. The running sums are those of a prefix-sum
/// array, in the same order, but only the 2w + 2 a window spans are kept (a ring): a whole run's
/// prefix array would be 12 bytes per sample beside the residual itself (issue 7's memory bar).
// Out of line: inlined into `diagnose`, its running sums lived on the stack (a store and a
// reload per element; ~1 % of a 1-h replay with the periodogram's loops).
#[inline(never)]
fn high_pass_variance(e: &[f32], w: usize) -> f64 {
    let n = e.len();
    let width = 2 * w + 1;
    if n < width {
        return f64::NAN;
    }
    // prefix[k] (sum of the first k values, NaN as 0) and nan_prefix[k] at ring[k % ring_len].
    let ring_len = width + 1;
    let mut prefix = vec![0.0f64; ring_len];
    let mut nan_prefix = vec![0u32; ring_len];
    let (mut sum, mut nans) = (0.0f64, 0u32);
    let inv = 1.0 / width as f64;
    let (mut power, mut used) = (0.0, 0usize);
    // k % ring_len, stepped rather than divided (two divisions per sample and axis otherwise);
    // k − width ≡ k + 1 (mod ring_len), the slot after it.
    let mut slot = 0;
    for (k, &v) in (1..=n).zip(e) {
        slot = if slot + 1 == ring_len { 0 } else { slot + 1 };
        let v = f64::from(v);
        sum += if v.is_nan() { 0.0 } else { v };
        nans += u32::from(v.is_nan());
        prefix[slot] = sum;
        nan_prefix[slot] = nans;
        // The window centred on i = k − w − 1 spans prefix[i − w .. i + w + 1] = [k − width, k].
        if k >= width {
            let lo = if slot + 1 == ring_len { 0 } else { slot + 1 };
            if nan_prefix[lo] != nans {
                continue;
            }
            let i = k - w - 1;
            let mean = (sum - prefix[lo]) * inv;
            power += (f64::from(e[i]) - mean).powi(2);
            used += 1;
        }
    }
    power / (used as f64 * (1.0 - inv))
}

/// Ljung–Box statistic of the block means of `e` (blocks with a NaN dropped). Written here: statrs
/// has the χ² it is compared with (`stats`) but no Ljung–Box, and no kept crate takes block means
/// of an f32 residual with NaN gaps; the statistic is one sum.
// Out of line: inlined into `diagnose`, its running sums lived on the stack (a store and a
// reload per element; ~1 % of a 1-h replay with the periodogram's loops).
#[inline(never)]
fn ljung_box(e: &[f32], block: usize, lags: usize) -> (f64, usize) {
    let means: Vec<f64> = e
        .chunks_exact(block.max(1))
        .filter(|c| c.iter().all(|v| !v.is_nan()))
        .map(|c| c.iter().map(|&v| f64::from(v)).sum::<f64>() / c.len() as f64)
        .collect();
    let n = means.len();
    if n <= lags + 2 {
        return (0.0, lags);
    }
    let mean = means.iter().sum::<f64>() / n as f64;
    let c0: f64 = means.iter().map(|m| (m - mean).powi(2)).sum();
    let q: f64 = (1..=lags)
        .map(|k| {
            let ck: f64 = (k..n).map(|i| (means[i] - mean) * (means[i - k] - mean)).sum();
            (ck / c0).powi(2) / (n - k) as f64
        })
        .sum::<f64>()
        * (n * (n + 2)) as f64;
    (q, lags)
}

/// Runs the diagnostics of `model` on all runs. `cutoff_hz` is the gyro's low-pass cut-off,
/// `alpha` the family-wise false-alarm probability, `noise_window_s` the floor's window.
pub fn diagnose(data: &LoopData, model: &Model, cutoff_hz: f64, alpha: f64, noise_window_s: f64) -> Diagnostics {
    let ev = Evaluator::new(data, model);
    let m = model.m();
    let k: [f64; 3] = std::array::from_fn(|a| (m[(a, 0)].powi(2) + m[(a, 1)].powi(2) + m[(a, 2)].powi(2)).sqrt());
    let n_runs = data.kin.runs.len();
    let tests = TESTS_PER_RUN_AXIS * 3 * n_runs;
    let cx = DiagCtx { k, level: Level { alpha_per_test: alpha / tests as f64 }, cutoff_hz, noise_window_s };
    let mut pooled = Pooled::default();
    let mut walker = Walker::new(&ev);
    let mut fft_planner = realfft::RealFftPlanner::new();
    let runs = (0..n_runs)
        .map(|r| {
            let sums = walker.walk(data, r, &mut pooled);
            run_diag(data, r, sums, &cx, &mut pooled, &mut fft_planner)
        })
        .collect();
    pooled.into_diagnostics(runs, &k, tests, cx.level.alpha_per_test)
}

/// What every run's diagnostics share.
struct DiagCtx {
    /// Each axis's sensitivity, counts per °/s: residuals in counts are reported in °/s.
    k: [f64; 3],
    level: Level,
    /// The gyro's low-pass cut-off, Hz.
    cutoff_hz: f64,
    /// The noise floor's window, s.
    noise_window_s: f64,
}

/// The per-test level of the Bonferroni-corrected family.
struct Level {
    alpha_per_test: f64,
}

impl Level {
    /// χ² threshold for `dof` degrees of freedom.
    fn threshold(&self, dof: usize) -> f64 {
        chi2_upper_quantile(dof, self.alpha_per_test)
    }

    fn test(&self, chi2: f64, dof: usize) -> Test {
        Test { chi2, dof, sigma: chi2_to_sigma(dof, chi2), significant: dof > 0 && chi2 > self.threshold(dof) }
    }
}

/// What the whole data set pools across runs, per axis.
#[derive(Default)]
struct Pooled {
    /// The residuals of samples whose three axes are all unclipped, for the block inflation.
    blocking: Blocking<3>,
    /// Σ eᵢ·eⱼ (i < j) over those samples.
    cross: [[f64; 3]; 3],
    /// Σe², floor variance·n, noise variance·n, n.
    sums: [(f64, f64, f64, usize); 3],
}

impl Pooled {
    fn into_diagnostics(self, runs: Vec<RunDiag>, k: &[f64; 3], tests: usize, alpha_per_test: f64) -> Diagnostics {
        let pooled = &self.sums;
        let per_sample = |a: usize, v: f64| v / pooled[a].3.max(1) as f64;
        let noise_variance_counts2 = std::array::from_fn(|a| per_sample(a, pooled[a].2));
        let rms_dps = std::array::from_fn(|a| per_sample(a, pooled[a].0).sqrt() / k[a]);
        let floor_dps = std::array::from_fn(|a| per_sample(a, pooled[a].1).sqrt() / k[a]);
        let est: [Option<_>; 3] = std::array::from_fn(|a| self.blocking.estimate(a));
        let inflation = std::array::from_fn(|a| est[a].map_or(1.0, |l| l.inflation()));
        let block_samples = std::array::from_fn(|a| est[a].map_or(1, |l| 1u64 << l.level));
        let correlation = std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let (a, b) = (i.min(j), i.max(j));
                if a == b {
                    1.0
                } else {
                    self.cross[a][b] / (pooled[a].0 * pooled[b].0).sqrt()
                }
            })
        });
        let mut d = Diagnostics {
            runs,
            noise_variance_counts2,
            rms_dps,
            floor_dps,
            inflation,
            block_samples,
            correlation,
            findings: Vec::new(),
            tests,
            alpha_per_test,
        };
        d.findings = findings(&d);
        d
    }
}

/// What one walk over a run's residual gathers, per axis.
struct RunSums {
    /// The residual per used sample, f32 (its rounding, 6e-8 of a residual, is far below the
    /// noise it measures): the floor, spectrum and whiteness need the series, and it is the
    /// largest thing the diagnostics hold (issue 7's memory bar). NaN where clipped.
    e: [Vec<f32>; 3],
    angle: AngleSums,
    theta_bins: [Bins; 3],
    time_bins: [Bins; 3],
    temp: [SlopeSums; 3],
    rate_sums: [RateBinSums; 3],
    clipped: [u64; 3],
    /// Σ (θ1'/θ1'_steady − 1)² over the used samples.
    dev_sq: f64,
    /// Unclipped samples and Σe² per axis.
    n_axis: [usize; 3],
    ss_axis: [f64; 3],
    /// Σ of the rate along each axis (ŝ·ω_s, °/s) over its unclipped samples: its mean gives the
    /// echo of θ1''s own noise in the residual ([`ripple_beyond_echo`]).
    axis_rate_sum_dps: [f64; 3],
}

/// Walks runs' residuals sample by sample into [`RunSums`].
struct Walker<'a> {
    ev: &'a Evaluator<'a>,
    centres: Vec<(f64, f64)>,
    theta2_binning: Binning,
    angle_binning: Binning,
    scratch: Vec<f64>,
}

impl<'a> Walker<'a> {
    fn new(ev: &'a Evaluator<'a>) -> Self {
        Self {
            ev,
            centres: angle_bin_centres(),
            theta2_binning: Binning::new(std::f64::consts::TAU, THETA2_BINS),
            angle_binning: Binning::new(std::f64::consts::TAU, ANGLE_BINS),
            scratch: Vec::new(),
        }
    }

    /// Run `r`'s sums; its fully unclipped residual rows go into `pooled`.
    fn walk(&mut self, data: &LoopData, r: usize, pooled: &mut Pooled) -> RunSums {
        let (rk, rd) = (&data.kin.runs[r], &data.runs[r]);
        let t_first = rk.samples.first().map_or(0.0, |s| s.t_s());
        let n_time = ((rk.samples.last().map_or(0.0, |s| s.t_s()) - t_first) / TIME_BIN_S).ceil().max(1.0) as usize;
        let mut sums = RunSums {
            e: std::array::from_fn(|_| Vec::with_capacity(rd.n_valid)),
            angle: AngleSums::new(),
            theta_bins: std::array::from_fn(|_| Bins::new(THETA2_BINS)),
            time_bins: std::array::from_fn(|_| Bins::new(n_time)),
            temp: [SlopeSums::default(); 3],
            rate_sums: Default::default(),
            clipped: [0; 3],
            dev_sq: 0.0,
            n_axis: [0; 3],
            ss_axis: [0.0; 3],
            axis_rate_sum_dps: [0.0; 3],
        };
        // Rate bins span 0 to the largest possible axis rate, |θ1'|·√2 + |θ2'| bounds |ω_s|.
        let rate_max = rk.steady_rate_dps.abs() * (2f64.sqrt() + rk.gear_ratio.abs()) * 1.05;
        let rate_binning = Binning::new(rate_max, RATE_BINS);
        let time_binning = Binning::of_width(TIME_BIN_S, n_time);
        // The chain at the nodes of each cell, the sample's values from the quadratic through
        // them (`engine::for_each_interpolated`): the model's output, θ2, each axis's rate and
        // the die temperature.
        let (ev, scratch) = (self.ev, &mut self.scratch);
        let values = |p: &crate::calib::engine::Point| -> [f64; 8] {
            let pred = ev.predict3(p, scratch);
            let rate: [f64; 3] = std::array::from_fn(|a| ev.axis_rate(p, a));
            [pred[0], pred[1], pred[2], p.theta2_rad, rate[0], rate[1], rate[2], p.temp_c]
        };
        let (theta2_binning, angle_binning, centres) = (&self.theta2_binning, &self.angle_binning, &self.centres);
        for_each_interpolated(ev, data, r, values, |_, s, v| {
            let (preds, theta2_rad, temp_c) = (&v[..3], v[3], v[7]);
            let (bin, hb) = theta2_binning.angle_indices(angle_binning, theta2_rad);
            let tb = time_binning.index(s.t_s() - t_first);
            let dev = speed_deviation(s.theta1_rate_dps(), rk.steady_rate_dps);
            sums.dev_sq += dev * dev;
            let dev_pct = dev * 100.0;
            let mut row = [f64::NAN; 3];
            sums.angle.add_sample(hb, dev_pct);
            for a in 0..3 {
                let rbin = rate_binning.index(v[4 + a].abs());
                if is_clipped(s.rate_counts[a]) {
                    sums.clipped[a] += 1;
                    sums.e[a].push(f32::NAN);
                    sums.angle.add_clipped(a, hb, dev_pct);
                    continue;
                }
                let pred = preds[a];
                let ea = f64::from(s.rate_counts[a]) - pred;
                row[a] = ea;
                sums.n_axis[a] += 1;
                sums.ss_axis[a] += ea * ea;
                sums.axis_rate_sum_dps[a] += v[4 + a];
                sums.e[a].push(ea as f32);
                sums.angle.add_residual(a, hb, dev_pct, ea);
                sums.theta_bins[a].add(bin, ea, pred);
                sums.time_bins[a].add_to_mean(tb, ea);
                sums.temp[a].add(temp_c, ea);
                sums.rate_sums[a].add(rbin, ea, centres[hb]);
            }
            if row.iter().all(|v| !v.is_nan()) {
                pooled.blocking.push(row);
                for i in 0..3 {
                    for j in i + 1..3 {
                        pooled.cross[i][j] += row[i] * row[j];
                    }
                }
            }
        });
        pooled.blocking.end_segment();
        sums
    }
}

/// Run `r`'s diagnostics from its sums; its noise figures go into `pooled`.
fn run_diag(
    data: &LoopData,
    r: usize,
    sums: RunSums,
    cx: &DiagCtx,
    pooled: &mut Pooled,
    fft_planner: &mut realfft::RealFftPlanner<f64>,
) -> RunDiag {
    let (k, level) = (&cx.k, &cx.level);
    let rk = &data.kin.runs[r];
    let fs = rk.sample_rate_hz;
    let table_hz = (rk.gear_ratio * rk.steady_rate_dps).abs() / 360.0;
    let base_hz = rk.steady_rate_dps.abs() / 360.0;
    let AngleFits { orders, ripple: mut ripples } = sums.angle.fits(fft_planner);
    let n_used = sums.e[0].len().max(1);
    let speed_deviation_rms_percent = (sums.dev_sq / n_used as f64).sqrt() * 100.0;
    let band_lo = (NOISE_BAND_FIRST_HARMONIC * table_hz).max(NOISE_BAND_MIN_HZ);
    let band = NoiseBand {
        floor_window: ((cx.noise_window_s * fs / 2.0).round() as usize).max(1),
        lo_hz: band_lo,
        hi_hz: (0.5 * cx.cutoff_hz).min(fs / 8.0).max(band_lo * 2.0).min(0.45 * fs),
    };
    let mut axes = Vec::with_capacity(3);
    let mut theta2 = Vec::with_capacity(3);
    let mut spectrum = Vec::with_capacity(3);
    for a in 0..3 {
        let ka = k[a];
        let ea = &sums.e[a];
        let (n, ss) = (sums.n_axis[a], sums.ss_axis[a]);
        let floor_var = high_pass_variance(ea, band.floor_window);
        let pg = Periodogram::with_planner(ea, fs, fft_planner);
        let noise_var = pg
            .noise_variance(band.lo_hz, band.hi_hz, table_hz)
            .filter(|v| v.is_finite() && *v > 0.0)
            .unwrap_or(floor_var);
        let p = &mut pooled.sums[a];
        *p = (p.0 + ss, p.1 + floor_var * n as f64, p.2 + noise_var * n as f64, p.3 + n);
        let nf = n.max(1) as f64;
        let rate_bins = sums.rate_sums[a].without_orders_0_and_1(&harmonic_coefficients(&orders[a]));
        let ripple = std::mem::take(&mut ripples[a]);
        let block = ((WHITENESS_BLOCK_S * fs).round() as usize).max(1);
        let (q, lags) = ljung_box(ea, block, LJUNG_BOX_LAGS);
        let (tchi, tdof, _, trange) = sums.time_bins[a].spread(noise_var);
        let (rchi, rdof, rmax, _) = rate_bins.spread(noise_var);
        let (ts, tsd) = sums.temp[a].slope(noise_var);
        let (rs, rsd) = ripple.slope(noise_var);
        let echo = -ka * sums.axis_rate_sum_dps[a] / n.max(1) as f64 / 100.0;
        let z2 = |s: f64, sd: f64| if sd.is_finite() && sd > 0.0 { (s / sd).powi(2) } else { 0.0 };
        let rms = (ss / nf).sqrt();
        let floor = floor_var.sqrt();
        axes.push(AxisRunDiag {
            axis: AXES[a],
            n,
            rms_dps: rms / ka,
            floor_dps: floor / ka,
            noise_dps: noise_var.sqrt() / ka,
            rms_over_floor: rms / floor,
            orders: order_terms(&orders[a], noise_var, nf, ka, level),
            whiteness: level.test(q, lags),
            time_drift: level.test(tchi, tdof),
            time_drift_range_dps: trange / ka,
            temperature_slope_dps_per_c: ts / ka,
            temperature: level.test(z2(ts, tsd), 1),
            rate: level.test(rchi, rdof),
            rate_max_dps: rmax / ka,
            ripple_slope_dps_per_percent: rs / ka,
            ripple: level.test(z2(ripple_beyond_echo(rs, echo), rsd), 1),
            speed_deviation_rms_percent,
            clipped: sums.clipped[a],
        });
        theta2.push(theta2_curve(&sums.theta_bins[a], ka));
        spectrum.push(AmplitudeSpectrum::from_periodogram(
            &pg,
            ka,
            (SPECTRUM_PLOT_HARMONICS * table_hz).min(0.5 * fs),
            SPECTRUM_PLOT_POINTS,
        ));
    }
    RunDiag {
        run: rk.run,
        pose: rk.pose,
        commanded_rate_dps: rk.commanded_rate_dps,
        axes,
        plots: RunPlots { theta2, spectrum, table_hz, base_hz },
    }
}

/// Where a run's noise is measured: the floor's high-pass window (samples) and the band of the
/// long-run noise level.
struct NoiseBand {
    floor_window: usize,
    lo_hz: f64,
    hi_hz: f64,
}

/// The harmonic tests of one run and axis: order 0 (the mean, 1 dof), then each order's
/// amplitude and phase (2 dof), in counts scaled to °/s by `ka`.
fn order_terms(orders: &[OrderSums; MAX_ORDER + 1], noise_var: f64, nf: f64, ka: f64, level: &Level) -> Vec<OrderTerm> {
    orders
        .iter()
        .enumerate()
        .map(|(nn, o)| {
            if nn == 0 {
                let mean = o.ec / nf;
                let sd = (noise_var / nf).sqrt();
                let chi2 = (mean / sd).powi(2);
                OrderTerm {
                    order: 0,
                    amplitude_dps: mean / ka,
                    phase_deg: 0.0,
                    sigma_dps: sd / ka,
                    chi2,
                    significant: chi2 > level.threshold(1),
                }
            } else {
                let (sa, cb) = o.solve();
                let sd = (2.0 * noise_var / nf).sqrt();
                let chi2 = (sa * sa + cb * cb) / (sd * sd);
                OrderTerm {
                    order: nn as u32,
                    amplitude_dps: (sa * sa + cb * cb).sqrt() / ka,
                    phase_deg: cb.atan2(sa).to_degrees(),
                    sigma_dps: sd / ka,
                    chi2,
                    significant: chi2 > level.threshold(2),
                }
            }
        })
        .collect()
}

/// The plotted residual against θ2 of one run and axis, °/s.
fn theta2_curve(tb: &Bins, ka: f64) -> Theta2Curve {
    let per_bin = |f: &dyn Fn(&Bin) -> f64| tb.0.iter().map(f).collect::<Vec<f64>>();
    Theta2Curve {
        theta2_deg: (0..THETA2_BINS).map(|b| (b as f64 + 0.5) * 360.0 / THETA2_BINS as f64).collect(),
        residual_dps: per_bin(&|b| if b.count > 0.0 { b.sum / b.count / ka } else { f64::NAN }),
        residual_se_dps: per_bin(&|b| {
            let c = b.count;
            if c > 1.0 {
                let mean = b.sum / c;
                ((b.sumsq / c - mean * mean).max(0.0) / (c - 1.0)).sqrt() / ka
            } else {
                f64::NAN
            }
        }),
        fit_dps: per_bin(&|b| if b.count > 0.0 { b.extra / b.count / ka } else { f64::NAN }),
        counts: tb.0.iter().map(|b| b.count as u64).collect(),
    }
}

/// Groups the significant tests by kind.
fn findings(d: &Diagnostics) -> Vec<Finding> {
    let mut kinds: Vec<FindingKind> = vec![FindingKind::RunOffset];
    kinds.extend((1..=MAX_ORDER as u32).map(FindingKind::Harmonic));
    kinds.extend([
        FindingKind::TimeDrift,
        FindingKind::Temperature,
        FindingKind::RateDependence,
        FindingKind::NotWhite,
        FindingKind::RmsExcess,
    ]);
    let mut out = Vec::new();
    for kind in kinds {
        // (run index, axis, size °/s, σ)
        let mut hits: Vec<(usize, usize, f64, f64)> = Vec::new();
        for (ri, rd) in d.runs.iter().enumerate() {
            for (a, ad) in rd.axes.iter().enumerate() {
                let hit = match kind {
                    FindingKind::RunOffset => {
                        let o = &ad.orders[0];
                        o.significant.then(|| (o.amplitude_dps.abs(), o.chi2.sqrt()))
                    }
                    FindingKind::Harmonic(n) => {
                        let o = &ad.orders[n as usize];
                        o.significant.then(|| (o.amplitude_dps, o.amplitude_dps / o.sigma_dps))
                    }
                    FindingKind::NotWhite => ad.whiteness.significant.then_some((ad.rms_dps, ad.whiteness.sigma)),
                    FindingKind::TimeDrift => {
                        ad.time_drift.significant.then_some((ad.time_drift_range_dps, ad.time_drift.sigma))
                    }
                    FindingKind::Temperature => ad
                        .temperature
                        .significant
                        .then_some((ad.temperature_slope_dps_per_c.abs(), ad.temperature.sigma)),
                    FindingKind::RateDependence => ad.rate.significant.then_some((ad.rate_max_dps, ad.rate.sigma)),
                    FindingKind::SpeedRipple => {
                        ad.ripple.significant.then_some((ad.ripple_slope_dps_per_percent.abs(), ad.ripple.sigma))
                    }
                    FindingKind::RmsExcess => (ad.rms_over_floor > RMS_EXCESS_RATIO).then(|| {
                        let excess = (ad.rms_dps.powi(2) - ad.floor_dps.powi(2)).max(0.0).sqrt();
                        (excess, f64::NAN)
                    }),
                };
                if let Some((size, sigma)) = hit {
                    hits.push((ri, a, size, sigma));
                }
            }
        }
        if hits.is_empty() {
            continue;
        }
        let worst = hits.iter().copied().max_by(|x, y| x.2.total_cmp(&y.2)).expect("non-empty");
        let max_sigma = hits.iter().map(|h| h.3).filter(|s| s.is_finite()).fold(0.0f64, f64::max);
        let (rd, ad) = (&d.runs[worst.0], &d.runs[worst.0].axes[worst.1]);
        out.push(Finding {
            kind,
            places: hits.iter().map(|h| (d.runs[h.0].run, h.1)).collect(),
            max_dps: worst.2,
            max_sigma,
            worst: Worst {
                run: rd.run,
                pose: rd.pose,
                commanded_rate_dps: rd.commanded_rate_dps,
                axis: worst.1,
                size: worst.2,
                sigma: worst.3.is_finite().then_some(worst.3),
                rms_dps: ad.rms_dps,
                floor_dps: ad.floor_dps,
            },
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ring of running sums gives the floor bit for bit as the whole prefix array it
    /// replaced (kept here as the reference), NaN windows skipped alike.
    #[test]
    fn high_pass_ring_matches_the_prefix_array() {
        fn reference(e: &[f32], w: usize) -> f64 {
            let n = e.len();
            let width = 2 * w + 1;
            if n < width {
                return f64::NAN;
            }
            let mut prefix = vec![0.0f64];
            let mut nan_prefix = vec![0u32];
            for &v in e {
                let v = f64::from(v);
                prefix.push(prefix[prefix.len() - 1] + if v.is_nan() { 0.0 } else { v });
                nan_prefix.push(nan_prefix[nan_prefix.len() - 1] + u32::from(v.is_nan()));
            }
            let inv = 1.0 / width as f64;
            let (mut power, mut used) = (0.0, 0usize);
            for i in w..n - w {
                if nan_prefix[i + w + 1] != nan_prefix[i - w] {
                    continue;
                }
                let mean = (prefix[i + w + 1] - prefix[i - w]) * inv;
                power += (f64::from(e[i]) - mean).powi(2);
                used += 1;
            }
            power / (used as f64 * (1.0 - inv))
        }
        let mut e: Vec<f32> =
            (0..5000).map(|i| ((i * 7919) % 613) as f32 * 0.37 - 100.0 + (i as f32 * 0.01).sin()).collect();
        for i in [0, 17, 18, 2500, 4999] {
            e[i] = f32::NAN;
        }
        for w in [1, 3, 40] {
            let (a, b) = (high_pass_variance(&e, w), reference(&e, w));
            assert_eq!(a.to_bits(), b.to_bits(), "w {w}: {a} vs {b}");
            assert!(a.is_finite() && a > 0.0);
        }
        assert!(high_pass_variance(&e[..5], 3).is_nan());
    }
}
