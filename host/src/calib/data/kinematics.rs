//! Table angles and rates at every gyro sample, from the encoder and the index, computed once per
//! calibration and shared by every model fitted to them.
//!
//! θ2 comes from the unwrapped encoder count referenced to the index: each index pulse (the
//! shield plate blocking the photo-interrupter) is centred on θ2 = 0, so its centre is the
//! midpoint of its rising and falling edge, whichever way the table turns. The pulse centres of a
//! run lie on a line `centre_k = ref + k·period`; fitting it gives the reference and, pooled over
//! runs, the period, i.e. the actual gear ratio. θ1' is the slope of local straight-line fits of
//! encoder count against sample time, corrected to be exact for cubics ([`super::encoder_rate`]),
//! θ2' = ratio·θ1'.

use super::encoder_rate::{for_each_rate_cps, noise_gain_per_s, slope_at_cps};
use crate::calib::result::error::CalError;
use crate::calib::result::estimate::Estimate;
use crate::calib::result::gear::{GearEstimate, IndexStats};
use crate::capture::{Run, RunTemperature, Samples};
use crate::geometry::{omega2, Pose};
use nalgebra::Matrix3;
use protocol::{sample_status, Edge};
use serde::{Deserialize, Serialize};

/// Standard deviation of uniform quantisation, in quanta: 1/√12.
const UNIFORM_QUANTISATION_SIGMA: f64 = 0.288_675_134_594_812_9;

/// MAD to σ for a normal distribution: 1/Φ⁻¹(3/4).
const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// Index pulse centres further than this many robust σ from the line are rejected (a missed or
/// spurious edge shifts a centre by half a plate width, far more).
const INDEX_OUTLIER_SIGMAS: f64 = 5.0;

/// Floor of the outlier threshold, encoder counts: with exact data the MAD is 0, and a centre is
/// only known to the quantum of its two edge counts.
const INDEX_OUTLIER_FLOOR_COUNTS: f64 = 2.0;

/// Values a median of sample spacings or speeds looks at: its standard error is then ~1 % of the
/// spread, far inside the 2 % steady-speed tolerance.
const MEDIAN_SUBSAMPLE: usize = 8192;

/// A sample off the run's speed by more than [`KinOptions::steady_tolerance`], but by no more
/// than this many times it, is kept when the mean speed over the base revolution centred on it
/// is within the tolerance: that is the motor's speed ripple, which the encoder tracks, not a
/// ramp. Cutting ripple peaks instead kept only the samples near the ripple's mean, a few
/// phases of θ1 (and of θ2, geared to it): with a 5 % ripple at 1× (ten times the simulator's
/// default) 17 % of the samples were left, the answer moved from 8 to 41 ppm off the truth, and
/// the phase-selected residual was flagged by a 9σ line at 1× (trust bench, `speed_ripple` at
/// 10×). Five times the 2 % tolerance, 10 %, is beyond what a speed loop lets through
/// (engineering judgement): a stall or a glitch, which stays out.
const RIPPLE_TOLERANCE_FACTOR: f64 = 5.0;

/// Settings of the kinematics reconstruction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct KinOptions {
    /// Span of the local straight-line fits that give θ1', s (corrected for their third moment,
    /// [`super::encoder_rate`]). 20 ms is 17 samples at 800 Hz: the encoder's quantisation then
    /// puts 0.016 °/s rms on θ1' (324 000 counts/rev), 25× below the L3G4200D's ≈0.4 °/s rms
    /// noise (0.03 °/s/√Hz, datasheet Table 4, over its 110 Hz bandwidth), while a speed ripple
    /// loses 1.1e-3 of itself at 8 Hz and 1.6e-2 at 16 Hz.
    pub rate_window_s: f64,
    /// Samples whose θ1' is further than this fraction from the run's median speed are spin-up,
    /// stop or a stall, and excluded, unless the motor's own ripple is all that moves them
    /// ([`RIPPLE_TOLERANCE_FACTOR`]). The linear model holds at any speed; the cut removes the
    /// ramps, where angular acceleration magnifies unmodelled timing errors.
    pub steady_tolerance: f64,
}

impl Default for KinOptions {
    fn default() -> Self {
        Self { rate_window_s: 0.020, steady_tolerance: 0.02 }
    }
}

/// Kinematics at one gyro sample (24 bytes: millions of them are held, so neither θ2' =
/// ratio·θ1', ω_s nor the temperature is stored; see [`RunKinematics::theta2_rate_dps`],
/// [`RunKinematics::omega_package_dps`] and [`RunKinematics::temperatures_counts`]). The time is
/// the capture's integer µs in 48 bits (8.9 years), exact; θ1' is kept in f32, whose rounding
/// (4e-8 of the rate) is 3000× below the encoder quantisation already on it
/// (`RunKinematics::rate_quantisation_dps`), so 8 of the 32 bytes it took in f64 with padding go.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KinSample {
    /// Sensor-table angle θ2, rad (0 at the centre of the index plate).
    theta2: f64,
    /// Low 32 bits of the sample time, µs since the start of the capture.
    t_us_lo: u32,
    /// Base-table rate θ1', °/s.
    theta1_rate: f32,
    /// Raw gyro output, counts.
    pub rate_counts: [i16; 3],
    /// Bits 32-47 of the sample time.
    t_us_hi: u16,
}

impl KinSample {
    /// A sample at `t_us` µs since the start of the capture (0 ≤ t_us < 2^48).
    pub fn new(t_us: i64, theta2_rad: f64, theta1_rate_dps: f64, rate_counts: [i16; 3]) -> Self {
        debug_assert!((0..1 << 48).contains(&t_us), "sample time {t_us} µs outside 48 bits");
        let t = t_us.clamp(0, (1 << 48) - 1) as u64;
        Self {
            theta2: theta2_rad,
            t_us_lo: t as u32,
            theta1_rate: theta1_rate_dps as f32,
            rate_counts,
            t_us_hi: (t >> 32) as u16,
        }
    }

    /// Sample time, µs since the start of the capture.
    #[inline]
    pub fn t_us(&self) -> i64 {
        (i64::from(self.t_us_hi) << 32) | i64::from(self.t_us_lo)
    }

    /// Sample time, s since the start of the capture.
    #[inline]
    pub fn t_s(&self) -> f64 {
        self.t_us() as f64 * 1e-6
    }

    /// Sensor-table angle θ2, rad (0 at the centre of the index plate).
    #[inline]
    pub fn theta2_rad(&self) -> f64 {
        self.theta2
    }

    /// Base-table rate θ1', °/s.
    #[inline]
    pub fn theta1_rate_dps(&self) -> f64 {
        f64::from(self.theta1_rate)
    }
}

/// Longest time span of one block of [`KinSamples`], µs: the 16-bit time offset within a block
/// reaches 65.5 ms, so 40 ms leaves room for a dropped or excluded sample or two (a spacing
/// beyond that is stored whole, see `KinSamples::escapes`).
const BLOCK_SPAN_US: f64 = 40_000.0;

/// Most samples a [`KinSamples`] block holds: 32 at 800 Hz (38.75 ms); a base of 16 bytes per
/// block is then half a byte per sample.
const MAX_BLOCK_SAMPLES: usize = 32;

/// Offset marking a sample stored whole in `KinSamples::escapes`.
const ESCAPED: u16 = u16::MAX;

/// One sample as [`KinSamples`] holds it, 14 bytes (align 2): time and encoder count as offsets
/// from its block's first sample, θ1' as f32 bits, the raw gyro output.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PackedSample {
    /// Time since the block's first sample, µs, or [`ESCAPED`].
    dt_us: u16,
    /// Encoder count since the block's first sample.
    de_counts: i16,
    /// θ1', °/s, as `f32::to_bits` split in two halves (so that the record keeps align 2).
    theta1_rate_bits: [u16; 2],
    /// Raw gyro output, counts.
    rate_counts: [i16; 3],
}

/// A run's kept samples, packed: 14.5 bytes a sample instead of [`KinSample`]'s 24 (issue 7's
/// memory bar: the loop holds every sample of the capture, 11.5 M at 4 hours). Time and encoder
/// count are the capture's exact integers, as offsets from the first sample of each block of
/// `block` samples; θ2 is made from the count on demand with the same expression, so every
/// value read back is bit for bit what was stored before (no rounding is added anywhere).
#[derive(Debug, Clone, PartialEq)]
pub struct KinSamples {
    packed: Vec<PackedSample>,
    /// (t_us, encoder count) of each block's first sample.
    bases: Vec<(i64, i64)>,
    /// (index, t_us, encoder count) of the samples whose offsets do not fit (gaps, or a rate
    /// beyond 32767 counts a block), by index.
    escapes: Vec<(usize, i64, i64)>,
    /// log2 of the samples per block.
    block_shift: u32,
    /// Encoder count of θ2 = 0.
    ref_counts: f64,
    /// θ2 per encoder count, rad (2π over the index period).
    rad_per_count: f64,
}

impl KinSamples {
    /// An empty set with θ2 = (count − `ref_counts`)·`rad_per_count`, for samples `dt_s` apart.
    pub fn new(ref_counts: f64, rad_per_count: f64, dt_s: f64) -> Self {
        let fit = (BLOCK_SPAN_US / (dt_s * 1e6)).floor() as usize + 1;
        let block = fit.clamp(1, MAX_BLOCK_SAMPLES);
        // The largest power of two not above `block`.
        let block_shift = usize::BITS - 1 - block.leading_zeros();
        Self { packed: Vec::new(), bases: Vec::new(), escapes: Vec::new(), block_shift, ref_counts, rad_per_count }
    }

    /// Sets θ2 = (count − `ref_counts`)·`rad_per_count` for every sample held and to come (the
    /// reference is known only once every run's index is pooled, after the samples are packed).
    pub fn set_theta2_reference(&mut self, ref_counts: f64, rad_per_count: f64) {
        self.ref_counts = ref_counts;
        self.rad_per_count = rad_per_count;
    }

    /// Room for `n` more samples.
    pub fn reserve(&mut self, n: usize) {
        self.packed.reserve(n);
        self.bases.reserve(n >> self.block_shift);
    }

    /// Appends a sample at `t_us` µs with encoder count `encoder`.
    pub fn push(&mut self, t_us: i64, encoder: i64, theta1_rate_dps: f64, rate_counts: [i16; 3]) {
        let i = self.packed.len();
        if i & ((1 << self.block_shift) - 1) == 0 {
            self.bases.push((t_us, encoder));
        }
        let (bt, be) = self.bases[i >> self.block_shift];
        let bits = (theta1_rate_dps as f32).to_bits();
        let theta1_rate_bits = [bits as u16, (bits >> 16) as u16];
        let (dt, de) = (t_us - bt, encoder - be);
        let fits = (0..i64::from(ESCAPED)).contains(&dt) && i16::try_from(de).is_ok();
        let (dt_us, de_counts) = if fits {
            (dt as u16, de as i16)
        } else {
            self.escapes.push((i, t_us, encoder));
            (ESCAPED, 0)
        };
        self.packed.push(PackedSample { dt_us, de_counts, theta1_rate_bits, rate_counts });
    }

    /// Frees the room reserved beyond the samples.
    pub fn shrink_to_fit(&mut self) {
        self.packed.shrink_to_fit();
        self.bases.shrink_to_fit();
        self.escapes.shrink_to_fit();
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.packed.len()
    }

    /// Whether none is held.
    pub fn is_empty(&self) -> bool {
        self.packed.is_empty()
    }

    /// Sample `i` (panics beyond the end, as a slice does).
    // Always inlined: every pass reads each sample through it, and the batch that reads ahead
    // (`engine::chain::Cursor`) called it out of line (2 % of a 1-h replay).
    #[inline(always)]
    pub fn get(&self, i: usize) -> KinSample {
        let p = &self.packed[i];
        let (t_us, encoder) = if p.dt_us == ESCAPED {
            let k = self.escapes.partition_point(|e| e.0 < i);
            (self.escapes[k].1, self.escapes[k].2)
        } else {
            let (bt, be) = self.bases[i >> self.block_shift];
            (bt + i64::from(p.dt_us), be + i64::from(p.de_counts))
        };
        let bits = u32::from(p.theta1_rate_bits[0]) | (u32::from(p.theta1_rate_bits[1]) << 16);
        KinSample {
            theta2: (encoder as f64 - self.ref_counts) * self.rad_per_count,
            t_us_lo: t_us as u32,
            theta1_rate: f32::from_bits(bits),
            rate_counts: p.rate_counts,
            t_us_hi: (t_us >> 32) as u16,
        }
    }

    /// The first sample.
    pub fn first(&self) -> Option<KinSample> {
        (!self.is_empty()).then(|| self.get(0))
    }

    /// The last sample.
    pub fn last(&self) -> Option<KinSample> {
        self.len().checked_sub(1).map(|i| self.get(i))
    }

    /// Every sample, in order.
    pub fn iter(&self) -> KinIter<'_> {
        KinIter { samples: self, next: 0..self.len() }
    }

    /// The samples in consecutive runs of `n` (the last one shorter), as a slice's `chunks`.
    pub fn chunks(&self, n: usize) -> impl Iterator<Item = KinIter<'_>> + '_ {
        (0..self.len()).step_by(n.max(1)).map(move |a| KinIter { samples: self, next: a..(a + n).min(self.len()) })
    }
}

/// The samples of a [`KinSamples`] in order, decoded one by one.
#[derive(Debug, Clone)]
pub struct KinIter<'a> {
    samples: &'a KinSamples,
    next: std::ops::Range<usize>,
}

impl Iterator for KinIter<'_> {
    type Item = KinSample;
    #[inline]
    fn next(&mut self) -> Option<KinSample> {
        self.next.next().map(|i| self.samples.get(i))
    }
    fn size_hint(&self) -> (usize, Option<usize>) {
        self.next.size_hint()
    }
}

impl ExactSizeIterator for KinIter<'_> {}

impl<'a> IntoIterator for &'a KinSamples {
    type Item = KinSample;
    type IntoIter = KinIter<'a>;
    fn into_iter(self) -> KinIter<'a> {
        self.iter()
    }
}

/// One run's kinematics and bookkeeping.
#[derive(Debug, Clone)]
pub struct RunKinematics {
    /// Run number, from 1, in the order given.
    pub run: usize,
    /// Pose.
    pub pose: Pose,
    /// `Run::label()`.
    pub label: String,
    /// Commanded base-table rate, °/s (signed).
    pub commanded_rate_dps: f64,
    /// R_qᵀ, package ← table (geometry, eq. 2).
    pub rot_t: Matrix3<f64>,
    /// Gear ratio θ2'/θ1' used (the pooled estimate).
    pub gear_ratio: f64,
    /// Samples kept (steady speed, full rate window, not stale), in time order.
    pub samples: KinSamples,
    /// Samples in the run.
    pub total: usize,
    /// Dropped as spin-up, stop or off-speed.
    pub excluded_unsteady: usize,
    /// Dropped because the rate window did not fit inside the run.
    pub excluded_window_edge: usize,
    /// Dropped because the rig flagged them stale.
    pub excluded_stale: usize,
    /// Median base-table rate θ1', °/s.
    pub steady_rate_dps: f64,
    /// Samples per second, from the median sample spacing.
    pub sample_rate_hz: f64,
    /// Samples in the θ1' window.
    pub rate_window_samples: usize,
    /// RMS of the encoder quantisation on θ1', °/s.
    pub rate_quantisation_dps: f64,
    /// θ2 reference.
    pub index: IndexStats,
    /// The run's die-temperature readings (a few per second at most; the per-sample values are
    /// interpolated from them on demand).
    pub temperatures: Vec<RunTemperature>,
    /// Base-table angle θ1 on the encoder's own scale (2π·count/counts-per-rev, modulo a turn)
    /// where θ2 = 0: the magnetic gears' pole-pass error follows the base's rotation against the
    /// ground, which only the encoder sees; θ1 = this + θ2/ratio.
    pub theta1_at_index_rad: f64,
    /// Half the index plate's width as a θ2 angle, rad: the pulse edges, whose midpoint is
    /// θ2 = 0, lie at ±this.
    pub plate_half_width_rad: f64,
}

impl RunKinematics {
    /// Sensor-table rate θ2' at a sample, °/s.
    pub fn theta2_rate_dps(&self, s: &KinSample) -> f64 {
        self.gear_ratio * s.theta1_rate_dps()
    }

    /// Rate the package feels at a sample, ω_s = R_qᵀ ω2 (geometry, eq. 1-2), °/s in package axes.
    #[inline]
    pub fn omega_package_dps(&self, s: &KinSample) -> [f64; 3] {
        (self.rot_t * omega2(s.theta1_rate_dps(), s.theta2_rad(), self.theta2_rate_dps(s))).into()
    }

    /// Gyro die temperature at every kept sample, OUT_TEMP counts (−1 count/°C, offset unknown),
    /// interpolated in time (NaN without readings).
    pub fn temperatures_counts(&self) -> impl Iterator<Item = f32> + '_ {
        let mut cursor = 0;
        self.samples.iter().map(move |s| temperature_at(&self.temperatures, s.t_us(), &mut cursor))
    }
}

/// Kinematics of all runs.
#[derive(Debug, Clone)]
pub struct Kinematics {
    /// Per run, in the order given.
    pub runs: Vec<RunKinematics>,
    /// Gear ratio estimate.
    pub gear: GearEstimate,
}

/// One index pulse: its centre and width in encoder counts.
#[derive(Debug, Clone, Copy)]
struct Pulse {
    centre_counts: f64,
    width_counts: f64,
}

/// Rising edge followed by the next falling edge, in arrival order. Both directions work: the
/// plate always starts to block first, only the encoder runs the other way.
fn pulses(run: &Run) -> Vec<Pulse> {
    let mut out = Vec::new();
    let mut rising: Option<i64> = None;
    for e in &run.index {
        match e.edge {
            Edge::Rising => rising = Some(e.encoder),
            Edge::Falling => {
                if let Some(r) = rising.take() {
                    out.push(Pulse {
                        centre_counts: 0.5 * (r + e.encoder) as f64,
                        width_counts: (e.encoder - r).unsigned_abs() as f64,
                    });
                }
            }
        }
    }
    out
}

/// The upper middle value, selected in place by std's `select_nth_unstable_by` (no sort, no
/// copy): statrs's `OrderStatistics::median` would average the two middle values of an even
/// count, a different estimator from the one every committed figure was made with.
fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mid = values.len() / 2;
    let (_, m, _) = values.select_nth_unstable_by(mid, f64::total_cmp);
    *m
}

/// Pulse centres of one run against their revolution number.
struct IndexLine {
    /// (revolution number, centre counts) of the inliers.
    points: Vec<(f64, f64)>,
    pulses: usize,
    rejected: usize,
    width_counts: f64,
}

impl IndexLine {
    /// Numbers the pulses with the nominal period, fits a line, drops outliers, refits.
    fn new(pulses: &[Pulse], nominal_period_counts: f64) -> Self {
        let first = pulses[0].centre_counts;
        let all: Vec<(f64, f64)> = pulses
            .iter()
            .map(|p| (((p.centre_counts - first) / nominal_period_counts).round(), p.centre_counts))
            .collect();
        let mut widths: Vec<f64> = pulses.iter().map(|p| p.width_counts).collect();
        let width_counts = median(&mut widths);
        let (a, p) = line_fit(&all, nominal_period_counts);
        let mut dev: Vec<f64> = all.iter().map(|&(k, c)| (c - a - p * k).abs()).collect();
        let threshold =
            (INDEX_OUTLIER_SIGMAS * MAD_TO_SIGMA * median(&mut dev.clone())).max(INDEX_OUTLIER_FLOOR_COUNTS);
        let mut points = Vec::with_capacity(all.len());
        for (pt, d) in all.iter().zip(dev.iter_mut()) {
            if *d <= threshold {
                points.push(*pt);
            }
        }
        Self { rejected: all.len() - points.len(), pulses: all.len(), points, width_counts }
    }

    /// Least-squares (intercept, slope, σ of centres, σ intercept, σ slope); σ floored at the
    /// quantisation of a midpoint of two counts.
    fn fit(&self, nominal_period_counts: f64) -> (f64, f64, f64, f64, f64) {
        let (a, p) = line_fit(&self.points, nominal_period_counts);
        let n = self.points.len() as f64;
        let rss: f64 = self.points.iter().map(|&(k, c)| (c - a - p * k).powi(2)).sum();
        let quant = UNIFORM_QUANTISATION_SIGMA / 2f64.sqrt();
        let sigma = if n > 2.0 { (rss / (n - 2.0)).sqrt().max(quant) } else { quant };
        let kbar = self.points.iter().map(|pt| pt.0).sum::<f64>() / n;
        let skk: f64 = self.points.iter().map(|pt| (pt.0 - kbar).powi(2)).sum();
        let sp = if skk > 0.0 { sigma / skk.sqrt() } else { f64::INFINITY };
        let sa = sigma * (1.0 / n + kbar * kbar / skk.max(f64::MIN_POSITIVE)).sqrt();
        (a, p, (rss / n).sqrt(), sa, sp)
    }

    /// Intercept with the slope held at `period`, and its σ.
    fn intercept(&self, period_counts: f64, sigma_centre: f64) -> (f64, f64) {
        let n = self.points.len() as f64;
        let a = self.points.iter().map(|&(k, c)| c - period_counts * k).sum::<f64>() / n;
        (a, sigma_centre / n.sqrt())
    }
}

/// Straight line c = a + p·k; with one point the slope is `fallback_slope`.
fn line_fit(points: &[(f64, f64)], fallback_slope: f64) -> (f64, f64) {
    let n = points.len() as f64;
    let kbar = points.iter().map(|p| p.0).sum::<f64>() / n;
    let cbar = points.iter().map(|p| p.1).sum::<f64>() / n;
    let skk: f64 = points.iter().map(|p| (p.0 - kbar).powi(2)).sum();
    let skc: f64 = points.iter().map(|p| (p.0 - kbar) * (p.1 - cbar)).sum();
    let p = if skk > 0.0 { skc / skk } else { fallback_slope };
    (cbar - p * kbar, p)
}

/// Median of at most ~`MEDIAN_SUBSAMPLE` evenly strided values of `f(0..len)`: a robust level
/// needs no more.
fn strided_median(len: usize, f: impl Fn(usize) -> f64) -> f64 {
    let stride = len.div_ceil(MEDIAN_SUBSAMPLE).max(1);
    let mut sub: Vec<f64> = (0..len).step_by(stride).map(f).collect();
    median(&mut sub)
}

/// Temperature at `t_us` by linear interpolation, held at the ends; `cursor` walks forward.
pub fn temperature_at(temps: &[RunTemperature], t_us: i64, cursor: &mut usize) -> f32 {
    match temps.len() {
        0 => return f32::NAN,
        1 => return f32::from(temps[0].raw),
        _ => {}
    }
    while *cursor + 2 < temps.len() && temps[*cursor + 1].t_us <= t_us {
        *cursor += 1;
    }
    let (a, b) = (&temps[*cursor], &temps[*cursor + 1]);
    let span = (b.t_us - a.t_us) as f64;
    let w = if span > 0.0 { ((t_us - a.t_us) as f64 / span).clamp(0.0, 1.0) } else { 0.0 };
    (f64::from(a.raw) + w * f64::from(b.raw - a.raw)) as f32
}

/// The index line of a run (everything about its index that does not depend on the pooled
/// gear ratio).
struct RunPrep {
    number: usize,
    line: IndexLine,
    fit: (f64, f64, f64, f64, f64),
}

/// What a run's samples give before the pooled gear ratio and the index are known: its kept
/// samples (θ2's reference still to set), the counts of the others, its rates. Made as each run
/// is decoded in a long replay ([`Reconstruction`]), so only its kinematics outlive its samples.
struct SampledRun {
    samples: KinSamples,
    total: usize,
    windows: usize,
    unsteady: usize,
    stale: usize,
    steady_rate_dps: f64,
    sample_rate_hz: f64,
    rate_window_samples: usize,
    rate_quantisation_dps: f64,
}

/// Reconstructs θ2, θ1', θ2' and temperature at every usable sample of every run.
pub fn reconstruct(runs: &[Run], opts: &KinOptions) -> Result<Kinematics, CalError> {
    let mut rec = Reconstruction::new(*opts);
    for run in runs {
        rec.add(run, &run.samples[..]);
    }
    rec.finish(runs)
}

/// A reconstruction fed run by run: each run's samples are turned into its kept kinematics as it
/// comes ([`Reconstruction::add`], while a replay decodes the next), and the runs' index lines,
/// the pooled gear ratio and θ2's references follow once all are in
/// ([`Reconstruction::finish`]), so a long capture's raw samples and kinematics are held together
/// for one run at most (issue 7's memory bar). The result is [`reconstruct`]'s, bit for bit: it
/// is the same code.
pub struct Reconstruction {
    opts: KinOptions,
    /// Encoder counts per revolution, from the first run's `Hello`.
    cpr: Option<f64>,
    sampled: Vec<SampledRun>,
}

impl Reconstruction {
    /// A reconstruction of no run yet.
    pub fn new(opts: KinOptions) -> Self {
        Self { opts, cpr: None, sampled: Vec::new() }
    }

    /// Turns the next run's samples into its kinematics; the run itself (index, temperatures,
    /// settings) is given again to [`Reconstruction::finish`], its samples are no longer needed.
    pub fn add(&mut self, run: &Run, samples: &(impl Samples + ?Sized)) {
        let cpr = *self.cpr.get_or_insert(f64::from(run.hello.encoder_counts_per_rev));
        self.sampled.push(sampled_run(run, samples, cpr, &self.opts));
    }

    /// The kinematics of `runs`, the runs given to [`Reconstruction::add`] in the same order.
    pub fn finish(self, runs: &[Run]) -> Result<Kinematics, CalError> {
        assert_eq!(runs.len(), self.sampled.len(), "every run's samples were added, in order");
        let (preps, cpr, period, gear) = prepare(runs)?;
        debug_assert_eq!(self.cpr.unwrap_or(cpr), cpr, "the first run's Hello gives the encoder resolution");
        let out = preps
            .into_iter()
            .zip(self.sampled)
            .zip(runs)
            .map(|((p, sampled), run)| run_kinematics(p, sampled, run, cpr, period, gear.ratio.value))
            .collect::<Result<_, _>>()?;
        Ok(Kinematics { runs: out, gear })
    }
}

/// The index lines of every run and the pooled gear ratio: (per-run preparations, encoder
/// counts per revolution, pooled index period in counts, gear estimate).
fn prepare(runs: &[Run]) -> Result<(Vec<RunPrep>, f64, f64, GearEstimate), CalError> {
    let first = runs.first().ok_or(CalError::NoRuns)?;
    let cpr = f64::from(first.hello.encoder_counts_per_rev);
    let nominal = f64::from(first.hello.gear_ratio.num) / f64::from(first.hello.gear_ratio.den);
    let nominal_period = cpr / nominal;

    let mut preps = Vec::with_capacity(runs.len());
    for (i, run) in runs.iter().enumerate() {
        let p = pulses(run);
        if p.is_empty() {
            return Err(CalError::NoIndex { run: i + 1, label: run.label(), edges: run.index.len() });
        }
        let line = IndexLine::new(&p, nominal_period);
        let fit = line.fit(nominal_period);
        preps.push(RunPrep { number: i + 1, line, fit });
    }

    // Pool the per-run periods, weighted by 1/σ²; runs with a single pulse carry no period.
    let (mut wsum, mut psum) = (0.0, 0.0);
    for p in &preps {
        let sp = p.fit.4;
        if sp.is_finite() && sp > 0.0 {
            wsum += 1.0 / (sp * sp);
            psum += p.fit.1 / (sp * sp);
        }
    }
    let (period, period_sigma) =
        if wsum > 0.0 { (psum / wsum, (1.0 / wsum).sqrt()) } else { (nominal_period, f64::NAN) };
    let ratio = cpr / period;
    let gear = GearEstimate {
        nominal,
        ratio: Estimate::new(ratio, ratio * period_sigma / period),
        deviation_ppm: (ratio - nominal) / nominal * 1e6,
    };
    Ok((preps, cpr, period, gear))
}

/// A run's kept samples and rates from its samples alone (`cpr`: encoder counts per revolution).
fn sampled_run(run: &Run, s: &(impl Samples + ?Sized), cpr: f64, opts: &KinOptions) -> SampledRun {
    let total = s.len();
    let spacing_us = |i: usize| {
        let mut pair = s.iter_from(i);
        let (a, b) = (pair.next().expect("a sample"), pair.next().expect("its successor"));
        (b.t_us - a.t_us) as f64
    };
    let dt_s = strided_median(total.saturating_sub(1), spacing_us) * 1e-6;
    let sample_rate_hz = 1.0 / dt_s;
    let h = ((opts.rate_window_s * sample_rate_hz / 2.0).round() as usize).max(1);
    let deg_per_count = 360.0 / cpr;
    let rate_quantisation_dps = UNIFORM_QUANTISATION_SIGMA * deg_per_count * noise_gain_per_s(h, dt_s);
    // A rate needs the straight lines centred on it and h samples either side.
    let windows = total.saturating_sub(4 * h);

    // The steady speed is the median of the rates near the commanded one, so that a short run
    // dominated by its ramps still finds its plateau; with none near, the median of all.
    let commanded = run.commanded_rate_dps();
    let near_band = opts.steady_tolerance * commanded.abs();
    let rate_at = |j: usize| slope_at_cps(s, j + h, h) * deg_per_count;
    let lines = total.saturating_sub(2 * h);
    let mut near: Vec<f64> = (0..lines)
        .step_by(lines.div_ceil(MEDIAN_SUBSAMPLE).max(1))
        .map(rate_at)
        .filter(|r| (r - commanded).abs() <= near_band)
        .collect();
    let steady_rate_dps = if near.is_empty() { strided_median(lines, rate_at) } else { median(&mut near) };
    let tol = opts.steady_tolerance * steady_rate_dps.abs();

    // θ2's reference comes with the index, once every run is in (`run_kinematics`).
    let mut samples = KinSamples::new(0.0, 0.0, dt_s);
    samples.reserve(windows);
    let (mut unsteady, mut stale) = (0, 0);
    let revolution = RevolutionMean::new(steady_rate_dps, sample_rate_hz, deg_per_count);
    for_each_rate_cps(s, h, dt_s, |i, smp, slope_cps| {
        let rate = slope_cps * deg_per_count;
        if smp.status & sample_status::STALE != 0 {
            stale += 1;
            return;
        }
        let off = (rate - steady_rate_dps).abs();
        let steady = off <= tol
            || (off <= RIPPLE_TOLERANCE_FACTOR * tol
                && revolution.at(s, i).is_some_and(|mean| (mean - steady_rate_dps).abs() <= tol));
        if !steady {
            unsteady += 1;
            return;
        }
        samples.push(smp.t_us, smp.encoder, rate, smp.rate_counts);
    });
    samples.shrink_to_fit();
    SampledRun {
        samples,
        total,
        windows,
        unsteady,
        stale,
        steady_rate_dps,
        sample_rate_hz,
        rate_window_samples: 2 * h + 1,
        rate_quantisation_dps,
    }
}

/// The mean speed over one base revolution centred on a sample: the encoder's count across it
/// over its time, °/s. Every harmonic of the base's rotation averages out of it.
struct RevolutionMean {
    /// Samples either side of the centre: half a revolution at the steady speed.
    half: usize,
    deg_per_count: f64,
}

impl RevolutionMean {
    fn new(steady_rate_dps: f64, sample_rate_hz: f64, deg_per_count: f64) -> Self {
        let half_s = if steady_rate_dps != 0.0 { 180.0 / steady_rate_dps.abs() } else { f64::INFINITY };
        let half = (half_s * sample_rate_hz).round();
        Self { half: if half.is_finite() { half as usize } else { usize::MAX }, deg_per_count }
    }

    /// At sample `i`; None when the revolution reaches past either end of the run.
    fn at(&self, s: &(impl Samples + ?Sized), i: usize) -> Option<f64> {
        let (lo, hi) = (i.checked_sub(self.half)?, i.checked_add(self.half)?);
        if hi >= s.len() {
            return None;
        }
        let a = s.iter_from(lo).next()?;
        let b = s.iter_from(hi).next()?;
        let dt_us = b.t_us - a.t_us;
        (dt_us > 0).then(|| (b.encoder - a.encoder) as f64 * self.deg_per_count / (dt_us as f64 * 1e-6))
    }
}

fn run_kinematics(
    p: RunPrep,
    sampled: SampledRun,
    run: &Run,
    cpr: f64,
    period: f64,
    ratio: f64,
) -> Result<RunKinematics, CalError> {
    let centre_sigma = if p.line.points.len() > 2 {
        p.fit.2 * (p.line.points.len() as f64 / (p.line.points.len() as f64 - 2.0)).sqrt()
    } else {
        UNIFORM_QUANTISATION_SIGMA / 2f64.sqrt()
    };
    let (ref_counts, ref_sigma) = p.line.intercept(period, centre_sigma.max(UNIFORM_QUANTISATION_SIGMA / 2f64.sqrt()));
    let index = IndexStats {
        pulses: p.line.pulses,
        rejected: p.line.rejected,
        ref_counts: Estimate::new(ref_counts, ref_sigma),
        ref_sigma_deg: ref_sigma / period * 360.0,
        centre_rms_counts: p.fit.2,
        plate_width_counts: p.line.width_counts,
        period_counts: Estimate::new(if p.fit.4.is_finite() { p.fit.1 } else { f64::NAN }, p.fit.4),
    };
    let SampledRun { mut samples, total, windows, unsteady, stale, sample_rate_hz, .. } = sampled;
    samples.set_theta2_reference(ref_counts, std::f64::consts::TAU / period);
    let label = run.label();
    let commanded = run.commanded_rate_dps();

    // One sensor-table revolution at the commanded speed: the paper's per-pose sinusoid fit needs
    // a whole period.
    let commanded_dps = commanded.abs();
    let needed = if commanded_dps > 0.0 {
        (sample_rate_hz * 360.0 / (ratio * commanded_dps)).ceil() as usize
    } else {
        total + 1
    };
    if samples.len() < needed.max(1) {
        return Err(CalError::TooFewSamples {
            run: p.number,
            label,
            usable: samples.len(),
            total,
            needed: needed.max(1),
        });
    }

    let theta1_at_index_rad = ref_counts.rem_euclid(cpr) / cpr * std::f64::consts::TAU;
    Ok(RunKinematics {
        theta1_at_index_rad,
        plate_half_width_rad: std::f64::consts::PI * p.line.width_counts / period,
        run: p.number,
        pose: run.pose,
        label,
        commanded_rate_dps: run.commanded_rate_dps(),
        rot_t: run.pose.rotation().transpose(),
        gear_ratio: ratio,
        samples,
        total,
        excluded_unsteady: unsteady,
        excluded_window_edge: total - windows,
        excluded_stale: stale,
        steady_rate_dps: sampled.steady_rate_dps,
        sample_rate_hz,
        rate_window_samples: sampled.rate_window_samples,
        rate_quantisation_dps: sampled.rate_quantisation_dps,
        index,
        temperatures: run.temperatures.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs whose samples were packed and added one by one, then dropped, reconstruct exactly as
    /// the runs with their samples do.
    #[test]
    fn run_by_run_reconstruction_is_the_whole_one() {
        let bytes = crate::sim::simulate(&crate::sim::SimConfig::standard(5, 6.0)).expect("simulates").bytes;
        let runs = crate::capture::decode(&bytes).runs;
        let opts = KinOptions::default();
        let whole = reconstruct(&runs, &opts).expect("reconstructs");
        let mut rec = Reconstruction::new(opts);
        let mut bare = runs.clone();
        for run in &mut bare {
            let mut packed = crate::capture::PackedSamples::default();
            run.samples.drain(..).for_each(|s| packed.push(s));
            rec.add(run, &packed);
        }
        let by_run = rec.finish(&bare).expect("reconstructs");
        assert_eq!(format!("{by_run:?}"), format!("{whole:?}"));
        assert!(whole.runs.iter().all(|r| r.samples.len() > 1000));
    }

    /// The decoded sample stays 24 bytes and the held one 14: every pass streams millions of
    /// them, and the loop holds them all (issue 7's memory bar).
    #[test]
    fn sample_records_are_24_and_14_bytes() {
        assert_eq!(std::mem::size_of::<KinSample>(), 24);
        assert_eq!(std::mem::size_of::<PackedSample>(), 14);
    }

    /// Packing is exact: every time, count, θ1' (as f32) and output read back is the one pushed,
    /// θ2 is the expression the reconstruction used, bit for bit, whether the sample fits its
    /// block or is stored whole (a gap, a jump of the count, time running back, past 2^32 µs).
    #[test]
    fn packed_samples_read_back_exactly() {
        let (ref_counts, rad_per_count) = (1234.5, std::f64::consts::TAU / 27_000.123);
        for dt_s in [1.0 / 800.0, 1.0 / 100.0, 0.5] {
            let mut packed = KinSamples::new(ref_counts, rad_per_count, dt_s);
            let dt_us = (dt_s * 1e6) as i64;
            let mut expected = Vec::new();
            let (mut t_us, mut encoder) = ((1i64 << 32) - 40 * dt_us, -5_000_000i64);
            for i in 0..1000i64 {
                t_us += match i {
                    100 => 70_000,
                    200 => -3,
                    300 => 10_000_000,
                    _ => dt_us,
                };
                encoder += match i {
                    400 => 40_000,
                    401 => -40_000,
                    _ => 202 - i % 5,
                };
                let rate = 180.0 + (i as f64 * 0.37).sin() * 1e-3;
                let counts = [i as i16, -(i as i16), i16::MAX - i as i16];
                packed.push(t_us, encoder, rate, counts);
                let theta2 = (encoder as f64 - ref_counts) * rad_per_count;
                expected.push(KinSample::new(t_us, theta2, rate, counts));
            }
            packed.shrink_to_fit();
            assert_eq!(packed.len(), expected.len());
            // Only the samples after a jump in the same block are stored whole.
            let escaped = packed.escapes.len();
            assert!((packed.block_shift == 0 || escaped > 0) && escaped <= 4 << packed.block_shift, "{escaped}");
            for (i, (got, want)) in packed.iter().zip(&expected).enumerate() {
                assert_eq!(got, *want, "dt {dt_s} s, sample {i}");
                assert_eq!(got.theta2_rad().to_bits(), want.theta2_rad().to_bits());
            }
            assert_eq!((packed.first(), packed.last()), (expected.first().copied(), expected.last().copied()));
        }
        // 32 samples a block at 800 Hz (38.75 ms), 4 at 100 Hz (30 ms), 1 at 2 Hz.
        assert_eq!(KinSamples::new(0.0, 1.0, 1.0 / 800.0).block_shift, 5);
        assert_eq!(KinSamples::new(0.0, 1.0, 1.0 / 100.0).block_shift, 2);
        assert_eq!(KinSamples::new(0.0, 1.0, 0.5).block_shift, 0);
    }
}
