//! Noise figures of a gyro at rest: the overlapping Allan deviation per axis and, from it, angle
//! random walk, bias instability and rate random walk (IEEE Std 952-1997, Annex C).
//!
//! Crates considered: `allan`, `allan-tools` and `flickers` (crates.io) compute Allan
//! deviations, but none fits the gyro noise terms (N, B, K) that are the point here, and the
//! fit needs each point's cluster count, which their results do not carry. The deviation itself
//! is a dozen lines over a cumulative sum, so no dependency is taken for it.
//!
//! The figures come from a weighted least-squares fit of the three terms to the Allan variance,
//! `σ²(τ) = N²/τ + (2 ln 2/π) B² + K² τ/3` (IEEE 952 Table C.2: white rate noise N, flicker B,
//! rate random walk K), rather than from reading single points off the slopes: every τ then
//! contributes, each weighted by its number of independent clusters.

use crate::calib::Calibration;
use crate::capture::{Capture, Run};
use serde::{Deserialize, Serialize};

/// The flicker-noise (bias instability) floor of the Allan deviation: σ = √(2 ln 2 / π) B
/// ≈ 0.664 B (IEEE Std 952-1997, Table C.2).
pub const FLICKER_FACTOR: f64 = 0.664_282_5;

/// τ points per decade of the grid: 10 resolves the curve's bends without redundant work.
const POINTS_PER_DECADE: f64 = 10.0;

/// Largest cluster, as a fraction of the record: beyond N/3 fewer than about 2 independent
/// clusters remain and the estimate says nothing.
const MAX_CLUSTER_FRACTION: f64 = 1.0 / 3.0;

/// One point of an Allan deviation curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AllanPoint {
    /// Cluster time τ, s.
    pub tau_s: f64,
    /// Overlapping Allan deviation, °/s.
    pub adev_dps: f64,
    /// Samples per cluster.
    pub m: usize,
}

/// Noise figures of one axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisNoise {
    /// Axis name.
    pub axis: char,
    /// Angle random walk (white rate noise), °/√h.
    pub arw_deg_per_sqrt_h: f64,
    /// Bias instability from the fitted flicker term, °/h.
    pub bias_instability_deg_per_h: f64,
    /// Rate random walk, °/h/√h.
    pub rrw_deg_per_h_per_sqrt_h: f64,
    /// Minimum of the Allan deviation, °/s, and where it lies, s (the conventional reading of
    /// bias instability is this minimum / 0.664).
    pub adev_min_dps: f64,
    /// τ at the minimum, s.
    pub tau_at_min_s: f64,
    /// The curve.
    pub curve: Vec<AllanPoint>,
}

impl AxisNoise {
    /// The fitted terms as lines over the curve's τ range, each where its term is not zero:
    /// white rate noise N/√τ (slope −1/2 on log-log axes, ARW), the flicker floor 0.664 B
    /// (slope 0, bias instability) and the random walk K √(τ/3) (slope +1/2, RRW), IEEE Std
    /// 952-1997 Table C.2. N, B, K from the figures: N = ARW/60, B = BI/3600, K = RRW/(3600·60).
    pub fn fitted_lines(&self) -> Vec<(&'static str, Vec<(f64, f64)>)> {
        let (Some(first), Some(last)) = (self.curve.first(), self.curve.last()) else { return Vec::new() };
        let n = self.arw_deg_per_sqrt_h / S_PER_H.sqrt();
        let b = self.bias_instability_deg_per_h / S_PER_H;
        let k = self.rrw_deg_per_h_per_sqrt_h / (S_PER_H * S_PER_H.sqrt());
        let ends = [first.tau_s, last.tau_s];
        let line = |f: &dyn Fn(f64) -> f64| ends.iter().map(|&t| (t, f(t))).collect::<Vec<_>>();
        let mut out = Vec::new();
        if n > 0.0 {
            out.push(("ARW, N/√τ (slope −1/2)", line(&|t| n / t.sqrt())));
        }
        if b > 0.0 {
            out.push(("bias instability, 0.664 B (slope 0)", line(&|_| FLICKER_FACTOR * b)));
        }
        if k > 0.0 {
            out.push(("RRW, K √(τ/3) (slope +1/2)", line(&|t| k * (t / 3.0).sqrt())));
        }
        out
    }
}

/// Overlapping Allan deviation of a rate series sampled every `tau0_s`, at log-spaced cluster
/// sizes from 1 to a third of the record.
pub fn overlapping_adev(rate: &[f64], tau0_s: f64) -> Vec<AllanPoint> {
    let n = rate.len();
    // Angle θ_k = τ0 Σ_{j<k} ω_j, k = 0..=n. Kahan summation keeps the long sums exact enough.
    let mut theta = Vec::with_capacity(n + 1);
    let (mut sum, mut comp) = (0.0f64, 0.0f64);
    theta.push(0.0);
    for &w in rate {
        let y = w * tau0_s - comp;
        let t = sum + y;
        comp = (t - sum) - y;
        sum = t;
        theta.push(sum);
    }
    let max_m = ((n as f64) * MAX_CLUSTER_FRACTION) as usize;
    let mut ms: Vec<usize> = Vec::new();
    let mut x = 0.0f64;
    loop {
        let m = 10f64.powf(x / POINTS_PER_DECADE).round() as usize;
        if m > max_m {
            break;
        }
        if ms.last() != Some(&m) {
            ms.push(m);
        }
        x += 1.0;
    }
    ms.iter()
        .map(|&m| {
            let tau = m as f64 * tau0_s;
            let terms = n + 1 - 2 * m;
            let s: f64 = (0..terms).map(|k| (theta[k + 2 * m] - 2.0 * theta[k + m] + theta[k]).powi(2)).sum();
            AllanPoint { tau_s: tau, adev_dps: (s / (2.0 * tau * tau * terms as f64)).sqrt(), m }
        })
        .collect()
}

/// Fitted noise coefficients in base units: N (°/s/√Hz = °/√s), B (°/s), K (°/s/√s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseTerms {
    /// White rate noise density, °/√s.
    pub n: f64,
    /// Flicker (bias instability) coefficient, °/s.
    pub b: f64,
    /// Rate random walk, °/s/√s.
    pub k: f64,
}

/// Fits `σ² = a/τ + b' + c τ` with a, b', c ≥ 0 by weighted least squares. The variance of an
/// Allan-variance estimate is about σ⁴ m/N, so each point is weighted by (N/m)/σ⁴ with σ² from
/// the model of the previous pass (weighting by the observed σ⁴ instead would favour the points
/// that happen to come out low and bias every term down). Non-negativity by trying every subset
/// of terms and keeping the best feasible fit.
pub fn fit_terms(curve: &[AllanPoint], n_samples: usize) -> NoiseTerms {
    fit_terms_with(curve, n_samples, 0b111)
}

/// Passes of the reweighting: the weights settle within 3 (each pass changes them by the model's
/// change, which shrinks geometrically); 6 leaves margin.
const REWEIGHT_PASSES: usize = 6;

fn fit_terms_with(curve: &[AllanPoint], n_samples: usize, allowed: u8) -> NoiseTerms {
    let basis = |p: &AllanPoint| [1.0 / p.tau_s, 1.0, p.tau_s];
    let model_at = |c: &[f64; 3], p: &AllanPoint| {
        let f = basis(p);
        f[0] * c[0] + f[1] * c[1] + f[2] * c[2]
    };
    let mut var: Vec<f64> = curve.iter().map(|p| p.adev_dps.powi(2)).collect();
    let mut coef = [0.0; 3];
    for _ in 0..REWEIGHT_PASSES {
        let weight: Vec<f64> = curve
            .iter()
            .zip(&var)
            .map(|(p, v)| (n_samples as f64 / p.m as f64) / v.max(f64::MIN_POSITIVE).powi(2))
            .collect();
        let mut best: Option<([f64; 3], f64)> = None;
        for mask in (1u8..8).filter(|m| m & !allowed == 0) {
            let idx: Vec<usize> = (0..3).filter(|i| mask & (1 << i) != 0).collect();
            let k = idx.len();
            let mut ata = nalgebra::DMatrix::<f64>::zeros(k, k);
            let mut atb = nalgebra::DVector::<f64>::zeros(k);
            for (p, &w) in curve.iter().zip(&weight) {
                let (f, y) = (basis(p), p.adev_dps.powi(2));
                for (r, &i) in idx.iter().enumerate() {
                    atb[r] += w * f[i] * y;
                    for (c, &j) in idx.iter().enumerate() {
                        ata[(r, c)] += w * f[i] * f[j];
                    }
                }
            }
            let Some(sol) = ata.lu().solve(&atb) else { continue };
            if sol.iter().any(|&v| v < 0.0 || !v.is_finite()) {
                continue;
            }
            let mut c = [0.0; 3];
            for (r, &i) in idx.iter().enumerate() {
                c[i] = sol[r];
            }
            let cost: f64 =
                curve.iter().zip(&weight).map(|(p, &w)| w * (model_at(&c, p) - p.adev_dps.powi(2)).powi(2)).sum();
            if best.is_none_or(|(_, b)| cost < b) {
                best = Some((c, cost));
            }
        }
        coef = best.map_or([0.0; 3], |(c, _)| c);
        var = curve.iter().map(|p| model_at(&coef, p)).collect();
    }
    NoiseTerms { n: coef[0].sqrt(), b: coef[1].sqrt() / FLICKER_FACTOR, k: (3.0 * coef[2]).sqrt() }
}

/// Seconds per hour.
const S_PER_H: f64 = 3600.0;

/// A noise figure with three significant digits (fixed notation from 0.001 up to 10⁵, else
/// with an exponent), or `none seen` for a term the fit left out: the curve shows no such
/// slope within the stretch (printing 0.000 there read like a figure too small to show).
pub fn figure(v: f64) -> String {
    if v == 0.0 {
        return "none seen".into();
    }
    if !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor();
    if !(-3.0..5.0).contains(&mag) {
        return format!("{v:.2e}");
    }
    let decimals = (2.0 - mag).max(0.0) as usize;
    format!("{v:.decimals$}")
}

/// Noise figures of one axis from its rate series (°/s) at `tau0_s`.
pub fn axis_noise(axis: char, rate: &[f64], tau0_s: f64) -> AxisNoise {
    let curve = overlapping_adev(rate, tau0_s);
    let t = fit_terms(&curve, rate.len());
    let min = curve.iter().copied().min_by(|a, b| a.adev_dps.total_cmp(&b.adev_dps));
    AxisNoise {
        axis,
        // °/√s × √(3600 s/h) = °/√h.
        arw_deg_per_sqrt_h: t.n * S_PER_H.sqrt(),
        // °/s × 3600 s/h = °/h.
        bias_instability_deg_per_h: t.b * S_PER_H,
        // °/s/√s = (3600 °/h)/(√h/60) = 3600·60 °/h/√h.
        rrw_deg_per_h_per_sqrt_h: t.k * S_PER_H * S_PER_H.sqrt(),
        adev_min_dps: min.map_or(f64::NAN, |p| p.adev_dps),
        tau_at_min_s: min.map_or(f64::NAN, |p| p.tau_s),
        curve,
    }
}

/// The longest stretch of samples taken with the table at rest: the latest `MotorStatus`
/// before each sample reports zero speed and zero setpoint. A static run (a `Start` at 0 °/s:
/// `host calibrate --static-s`, `host simulate --rates-dps 0`) is one such stretch from end to
/// end.
pub fn static_stretch(cap: &Capture) -> Option<(&Run, std::ops::Range<usize>)> {
    let mut best: Option<(&Run, std::ops::Range<usize>)> = None;
    for run in &cap.runs {
        let mut stretches = Vec::new();
        let mut m = 0;
        let mut start: Option<usize> = None;
        for (i, s) in run.samples.iter().enumerate() {
            while m < run.motor.len() && run.motor[m].0 <= s.t_us {
                m += 1;
            }
            let at_rest = m > 0 && run.motor[m - 1].1.speed_cps == 0 && run.motor[m - 1].1.setpoint_cps == 0;
            match (at_rest, start) {
                (true, None) => start = Some(i),
                (false, Some(a)) => {
                    stretches.push(a..i);
                    start = None;
                }
                _ => {}
            }
        }
        stretches.extend(start.map(|a| a..run.samples.len()));
        for r in stretches {
            if best.as_ref().is_none_or(|(_, b)| r.len() > b.len()) {
                best = Some((run, r));
            }
        }
    }
    best.filter(|(_, r)| !r.is_empty())
}

/// Stretch below which bias instability and RRW are flagged as indicative, s: an hour gives
/// σ(τ) to τ = 20 min, past the tens to hundreds of seconds where a MEMS gyro's Allan minimum
/// typically lies (assumed, not from a datasheet: the L3G4200D's gives no Allan figures; the
/// part's own curve decides). Less one second: the stretch of an hour-long static run
/// (`--static-s 3600`) measures a few tenths of a second short (it starts at the first 10-Hz
/// motor report of zero speed, and spans first to last sample), and such a run is the hour
/// this threshold asks for (measured 3599.9 s).
pub const SHORT_STRETCH_S: f64 = 3600.0 - 1.0;

/// Fewest samples an analysis accepts: 1000 gives clusters up to ~330 samples, two decades.
pub const MIN_STATIC_SAMPLES: usize = 1000;

/// Noise figures of a capture's static stretch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseReport {
    /// Run the stretch lies in, from 1.
    pub run: usize,
    /// Samples analysed.
    pub samples: usize,
    /// Length, s.
    pub duration_s: f64,
    /// Sample period from the timestamps (median), s.
    pub tau0_s: f64,
    /// How counts became rates: the calibration's full correction, or each axis's count
    /// divided by the datasheet sensitivity.
    pub scaling: String,
    /// Per axis.
    pub axes: Vec<AxisNoise>,
}

/// Noise figures of a session: the longest static stretch among `caps`, through the calibration
/// (`host calibrate` gives it the captures' static runs; `None` without one long enough).
pub fn session_noise<'a>(caps: impl IntoIterator<Item = &'a Capture>, cal: &Calibration) -> Option<NoiseReport> {
    caps.into_iter()
        .filter_map(|c| static_stretch(c).map(|(_, r)| (r.len(), c)))
        .max_by_key(|(n, _)| *n)
        .and_then(|(_, c)| capture_noise(c, Some(cal)).ok())
}

/// Allan analysis of a capture's static stretch, in °/s through `cal` (package frame) or, without
/// it, through the datasheet sensitivity (sensor axes).
pub fn capture_noise(cap: &Capture, cal: Option<&Calibration>) -> Result<NoiseReport, String> {
    let (run, range) = static_stretch(cap).ok_or(
        "the capture holds no static stretch (no sample with the motor reporting zero speed and setpoint): \
         record one with `host calibrate --port … --static-s 600`, or simulate one with \
         `host simulate --poses 1 --rates-dps 0 --duration 600 --out static.cap`",
    )?;
    let samples = &run.samples[range.clone()];
    if samples.len() < MIN_STATIC_SAMPLES {
        return Err(format!("the static stretch holds {} samples, fewer than {MIN_STATIC_SAMPLES}", samples.len()));
    }
    let mut dt: Vec<i64> = samples.windows(2).map(|w| w[1].t_us - w[0].t_us).collect();
    dt.sort_unstable();
    let tau0_s = dt[dt.len() / 2] as f64 * 1e-6;
    let nominal = 1e6 / f64::from(run.gyro.full_scale.udps_per_lsb());
    let rates: Vec<[f64; 3]> = samples
        .iter()
        .map(|s| match cal {
            Some(c) => c.apply(s.rate_counts),
            None => s.rate_counts.map(|v| f64::from(v) / nominal),
        })
        .collect();
    let axes = ['x', 'y', 'z']
        .iter()
        .enumerate()
        .map(|(i, &a)| axis_noise(a, &rates.iter().map(|r| r[i]).collect::<Vec<_>>(), tau0_s))
        .collect();
    let run_no = cap.runs.iter().position(|r| std::ptr::eq(r, run)).map_or(0, |i| i + 1);
    Ok(NoiseReport {
        run: run_no,
        samples: samples.len(),
        duration_s: (samples[samples.len() - 1].t_us - samples[0].t_us) as f64 * 1e-6,
        tau0_s,
        scaling: match cal {
            Some(_) => "calibration (package frame)".into(),
            None => format!("datasheet sensitivity {nominal:.4} counts/(°/s) (sensor axes)"),
        },
        axes,
    })
}

impl NoiseReport {
    /// The Allan deviation of the three axes on log-log axes, as SVG, with each axis's fitted
    /// terms drawn dashed in its colour ([`AxisNoise::fitted_lines`]).
    pub fn adev_svg(&self) -> Result<String, crate::report::plots::PlotError> {
        use crate::report::plots::{line_plot, PlotSpec, Series};
        let mut series = Vec::new();
        for (i, a) in self.axes.iter().enumerate() {
            series.push(Series::line(
                format!("{} axis", a.axis),
                a.curve.iter().map(|p| (p.tau_s, p.adev_dps)).collect(),
                i,
            ));
            for (label, points) in a.fitted_lines() {
                series.push(Series::dashed(format!("{}: {label}", a.axis), points, i));
            }
        }
        let spec =
            PlotSpec::new("Overlapping Allan deviation (static stretch) and fitted terms", "τ [s]", "σ(τ) [°/s]")
                .with_log_x()
                .with_log_y();
        line_plot(&spec, &series)
    }

    /// An HTML block with the figures table and the plot, for the report.
    pub fn html_section(&self) -> String {
        let mut o = String::from("<section class=\"noise\">\n<h2>Noise figures</h2>\n<table>\n");
        o.push_str("<tr><th>axis</th><th class=\"num\">ARW [°/√h]</th><th class=\"num\">bias instability [°/h]</th><th class=\"num\">RRW [°/h/√h]</th><th class=\"num\">σ min [°/s]</th><th class=\"num\">at τ [s]</th></tr>\n");
        for a in &self.axes {
            o.push_str(&format!(
                "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{:.3e}</td><td class=\"num\">{:.2}</td></tr>\n",
                a.axis,
                figure(a.arw_deg_per_sqrt_h),
                figure(a.bias_instability_deg_per_h),
                figure(a.rrw_deg_per_h_per_sqrt_h),
                a.adev_min_dps,
                a.tau_at_min_s
            ));
        }
        o.push_str(&format!(
            "</table>\n<p>Run {}, {} samples over {:.1} s; rates through the {}.",
            self.run, self.samples, self.duration_s, self.scaling
        ));
        if self.duration_s < SHORT_STRETCH_S {
            o.push_str(&format!(
                " A {:.0} s stretch measures σ(τ) up to τ = {:.0} s only: ARW is firm, bias instability and RRW are \
                 indicative (\"none seen\" where the curve shows no such slope yet).",
                self.duration_s,
                self.duration_s * MAX_CLUSTER_FRACTION
            ));
        }
        o.push_str("</p>\n");
        if let Ok(svg) = self.adev_svg() {
            o.push_str(&svg);
        }
        o.push_str("\n</section>\n");
        o
    }
}

/// The figures' table of a [`NoiseReport`], without the Allan curve: [`NoiseReport::figures`].
pub struct Figures<'a>(&'a NoiseReport);

impl NoiseReport {
    /// The stretch and the figures per axis, without the curve's table (the calibration's
    /// summary prints these; `host noise` prints the whole report).
    pub fn figures(&self) -> Figures<'_> {
        Figures(self)
    }
}

impl std::fmt::Display for Figures<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = self.0;
        writeln!(
            f,
            "Static stretch: run {}, {} samples, {:.1} s at {:.2} Hz; rates through the {}",
            r.run,
            r.samples,
            r.duration_s,
            1.0 / r.tau0_s,
            r.scaling
        )?;
        writeln!(f, "axis  ARW [°/√h]  bias instability [°/h]  RRW [°/h/√h]  ADEV min [°/s] at τ [s]")?;
        let none_seen = r.axes.iter().any(|a| a.bias_instability_deg_per_h == 0.0 || a.rrw_deg_per_h_per_sqrt_h == 0.0);
        if r.duration_s < SHORT_STRETCH_S {
            writeln!(
                f,
                "(a {:.0} s stretch measures σ(τ) up to τ = {:.0} s only: ARW is firm, bias instability and RRW are indicative)",
                r.duration_s,
                r.duration_s * MAX_CLUSTER_FRACTION
            )?;
        }
        if none_seen {
            writeln!(f, "(none seen: the Allan curve shows no such slope within the stretch; a longer one may)")?;
        }
        for a in &r.axes {
            writeln!(
                f,
                "  {}   {:>10}  {:>22}  {:>12}  {:14.3e}  {:8.2}",
                a.axis,
                figure(a.arw_deg_per_sqrt_h),
                figure(a.bias_instability_deg_per_h),
                figure(a.rrw_deg_per_h_per_sqrt_h),
                a.adev_min_dps,
                a.tau_at_min_s
            )?;
        }
        Ok(())
    }
}

impl std::fmt::Display for NoiseReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.figures())?;
        writeln!(f, "\n τ [s]        ADEV x [°/s]   ADEV y [°/s]   ADEV z [°/s]")?;
        let n = self.axes.iter().map(|a| a.curve.len()).min().unwrap_or(0);
        for i in 0..n {
            write!(f, "{:10.4}", self.axes[0].curve[i].tau_s)?;
            for a in &self.axes {
                write!(f, "   {:12.4e}", a.curve[i].adev_dps)?;
            }
            writeln!(f)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// White rate noise of density `n` (°/√s) plus a rate random walk `k` (°/s/√s), sampled
    /// at 1/tau0: per-sample σ n/√τ0 and random-walk steps of σ k √τ0 (IEEE 952 Annex C).
    fn synthetic(seed: u64, len: usize, tau0: f64, n: f64, k: f64) -> Vec<f64> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut walk = 0.0;
        (0..len)
            .map(|_| {
                let w: f64 = StandardNormal.sample(&mut rng);
                let v: f64 = StandardNormal.sample(&mut rng);
                walk += k * tau0.sqrt() * v;
                n / tau0.sqrt() * w + walk
            })
            .collect()
    }

    /// Pure white noise: σ(τ) = N/√τ at every τ, so the deviation at τ0 is the sample σ.
    #[test]
    fn white_noise_follows_minus_one_half() {
        let n = 0.03; // °/√s, the L3G4200D datasheet's rate noise density (Table 4).
        let rate = synthetic(1, 200_000, 0.01, n, 0.0);
        let curve = overlapping_adev(&rate, 0.01);
        assert_eq!(curve[0].m, 1);
        for p in curve.iter().filter(|p| p.tau_s <= 20.0) {
            let want = n / p.tau_s.sqrt();
            assert!((p.adev_dps / want - 1.0).abs() < 0.1, "τ {} s: {} vs {want}", p.tau_s, p.adev_dps);
        }
    }

    /// White noise of the datasheet's density plus a rate random walk whose line crosses it at
    /// τ = 10 s, 8 h at 10 Hz, ten independent realisations: N and K come back within 10 % in
    /// every one (measured: N within 0.3 %, K from −9 % to +3.4 %; the fit's flicker term takes
    /// a little of the random walk's variance near the minimum), and the minimum of the deviation
    /// lies at the analytic τ* = √3 N/K with σ² = 2NK/√3.
    #[test]
    fn white_noise_and_random_walk_are_recovered_within_ten_percent() {
        let (tau0, n) = (0.1, 0.03);
        let k = 3f64.sqrt() * n / 10.0;
        for seed in 1..=10 {
            let rate = synthetic(seed, 288_000, tau0, n, k);
            let a = axis_noise('x', &rate, tau0);
            let arw = n * 60.0;
            let rrw = k * 216_000.0;
            eprintln!(
                "seed {seed}: ARW {:.4} °/√h (true {arw:.4}), RRW {:.2} °/h/√h (true {rrw:.2}), B {:.3} °/h, min {:.5} °/s at {} s",
                a.arw_deg_per_sqrt_h, a.rrw_deg_per_h_per_sqrt_h, a.bias_instability_deg_per_h, a.adev_min_dps, a.tau_at_min_s
            );
            assert!((a.arw_deg_per_sqrt_h / arw - 1.0).abs() < 0.1, "ARW {} vs {arw}", a.arw_deg_per_sqrt_h);
            assert!(
                (a.rrw_deg_per_h_per_sqrt_h / rrw - 1.0).abs() < 0.1,
                "RRW {} vs {rrw}",
                a.rrw_deg_per_h_per_sqrt_h
            );
            let min_want = (2.0 * n * k / 3f64.sqrt()).sqrt();
            assert!((a.adev_min_dps / min_want - 1.0).abs() < 0.1, "min {} vs {min_want}", a.adev_min_dps);
            assert!(a.tau_at_min_s > 5.0 && a.tau_at_min_s < 20.0, "τ* {}", a.tau_at_min_s);
        }
    }

    /// A simulated static run (0 °/s, 60 s at 800 Hz, datasheet noise ρ = 0.03 °/s/√Hz): the
    /// simulator draws white noise of σ = ρ √(f_s/2) per sample (ρ over the Nyquist band), so
    /// the Allan white-noise level is N = σ √τ0 = ρ/√2 and the ARW 60 ρ/√2 = 1.273 °/√h; the
    /// analysis finds it within 10 % on each axis and no rate random walk worth the name.
    #[test]
    fn simulated_static_run_gives_the_simulators_white_noise() {
        use crate::geometry::Pose;
        use crate::sim::{self, RunSpec, SimConfig};
        let cfg = SimConfig::with_runs(4, vec![RunSpec { pose: Pose::One, rate_dps: 0.0, duration_s: 60.0 }]);
        let mut bytes = Vec::new();
        sim::simulate_to(&cfg, &mut bytes).unwrap();
        let cap = crate::capture::decode(&bytes);
        let report = capture_noise(&cap, None).unwrap();
        assert!(report.samples > 40_000, "{}", report.samples);
        let want = 60.0 * cfg.noise_dps_per_sqrt_hz / 2f64.sqrt();
        for a in &report.axes {
            // Sensor axes through the datasheet sensitivity: the part's own k (±1.5 % σ) scales
            // the figure; 10 % covers it.
            assert!(
                (a.arw_deg_per_sqrt_h / want - 1.0).abs() < 0.1,
                "{}: ARW {} vs {want}",
                a.axis,
                a.arw_deg_per_sqrt_h
            );
        }
        eprintln!("{report}");
    }

    /// The simulator with white noise and a rate random walk (`bias_random_walk`, K at the top
    /// of the 0.001-0.005 °/s/√s range, so the two lines cross at τ* = √3·N/K ≈ 7 s), one
    /// 4-hour static run at 100 Hz per seed: the analysis recovers both the white-noise level
    /// (ARW = 60·ρ/√2) and K (RRW = K·3600·60) within 10 % on every axis.
    #[test]
    fn simulated_white_noise_and_random_walk_are_recovered_within_ten_percent() {
        use crate::geometry::Pose;
        use crate::sim::{self, RunSpec, SimConfig};
        let k = 0.005;
        for seed in 1..=3 {
            let mut cfg =
                SimConfig::with_runs(seed, vec![RunSpec { pose: Pose::One, rate_dps: 0.0, duration_s: 4.0 * 3600.0 }]);
            cfg.gyro.odr = protocol::Odr::Hz100;
            cfg.effects.enable(&format!("bias_random_walk={k}")).unwrap();
            let mut bytes = Vec::new();
            sim::simulate_to(&cfg, &mut bytes).unwrap();
            let cap = crate::capture::decode(&bytes);
            let report = capture_noise(&cap, None).unwrap();
            let arw = 60.0 * cfg.noise_dps_per_sqrt_hz / 2f64.sqrt();
            let rrw = k * S_PER_H * S_PER_H.sqrt();
            for a in &report.axes {
                eprintln!(
                    "seed {seed} {}: ARW {:.4} (true {arw:.4}) °/√h, RRW {:.2} (true {rrw:.2}) °/h/√h",
                    a.axis, a.arw_deg_per_sqrt_h, a.rrw_deg_per_h_per_sqrt_h
                );
                assert!((a.arw_deg_per_sqrt_h / arw - 1.0).abs() < 0.1, "seed {seed} {}: ARW", a.axis);
                assert!((a.rrw_deg_per_h_per_sqrt_h / rrw - 1.0).abs() < 0.1, "seed {seed} {}: RRW", a.axis);
            }
        }
    }

    /// Figures keep three significant digits at every size; a term the fit left out says so.
    #[test]
    fn figures_have_significant_digits_and_a_missing_term_says_so() {
        assert_eq!(figure(1.27832), "1.28");
        assert_eq!(figure(0.0123456), "0.0123");
        assert_eq!(figure(0.000123456), "1.23e-4");
        assert_eq!(figure(123.456), "123");
        assert_eq!(figure(0.0), "none seen");
        let axis = AxisNoise {
            axis: 'x',
            arw_deg_per_sqrt_h: 1.2783,
            bias_instability_deg_per_h: 0.0,
            rrw_deg_per_h_per_sqrt_h: 0.000_42,
            adev_min_dps: 7.22e-4,
            tau_at_min_s: 198.11,
            curve: Vec::new(),
        };
        let text = NoiseReport {
            run: 1,
            samples: 480_000,
            duration_s: 3600.0,
            tau0_s: 0.00125,
            scaling: "calibration (package frame)".into(),
            axes: vec![axis],
        }
        .to_string();
        assert!(
            text.contains("\n  x         1.28               none seen       4.20e-4        7.220e-4    198.11\n"),
            "{text}"
        );
        assert!(!text.contains("0.000 "), "{text}");
        assert!(text.contains("(none seen: the Allan curve shows no such slope within the stretch; a longer one may)"));
    }

    /// The plot has log-log axes and the fitted lines have the slopes of their terms.
    #[test]
    fn the_allan_plot_is_log_log_with_the_fitted_lines() {
        let (tau0, n) = (0.1, 0.03);
        let rate = synthetic(2, 100_000, tau0, n, 3f64.sqrt() * n / 10.0);
        let mut a = axis_noise('x', &rate, tau0);
        a.bias_instability_deg_per_h = 2.0;
        let lines = a.fitted_lines();
        let slope = |p: &[(f64, f64)]| (p[1].1 / p[0].1).log10() / (p[1].0 / p[0].0).log10();
        let slopes: Vec<(&str, f64)> = lines.iter().map(|(l, p)| (*l, slope(p))).collect();
        assert_eq!(slopes.len(), 3, "{slopes:?}");
        assert!(
            (slopes[0].1 + 0.5).abs() < 1e-12 && slopes[1].1 == 0.0 && (slopes[2].1 - 0.5).abs() < 1e-12,
            "{slopes:?}"
        );
        // At τ = 1 s the white-noise line is N itself, °/s (ARW / 60).
        let at_1s = a.arw_deg_per_sqrt_h / 60.0;
        let (t0, s0) = lines[0].1[0];
        assert!((s0 * t0.sqrt() - at_1s).abs() < 1e-12 * at_1s);
        let report = NoiseReport {
            run: 1,
            samples: rate.len(),
            duration_s: 10_000.0,
            tau0_s: tau0,
            scaling: "calibration (package frame)".into(),
            axes: vec![a],
        };
        let svg = report.adev_svg().unwrap();
        // Decade ticks on the τ axis (the curve spans 0.1 s to 3333 s), not log₁₀ τ.
        for tick in ["0.1", "1", "10", "100", "1000"] {
            assert!(svg.contains(&format!("\n{tick}\n</text>")), "no τ tick {tick}: {svg}");
        }
        assert!(!svg.contains("log₁₀"), "x is still log₁₀ τ");
        assert!(svg.contains("x: ARW, N/√τ (slope −1/2)") && svg.contains("x: RRW, K √(τ/3) (slope +1/2)"));
    }

    /// A constant offset has no Allan deviation: the figures see noise only.
    #[test]
    fn an_offset_does_not_count_as_noise() {
        let rate = synthetic(3, 50_000, 0.01, 0.03, 0.0);
        let shifted: Vec<f64> = rate.iter().map(|w| w + 12.5).collect();
        let a = overlapping_adev(&rate, 0.01);
        let b = overlapping_adev(&shifted, 0.01);
        for (p, q) in a.iter().zip(&b) {
            assert!((p.adev_dps / q.adev_dps - 1.0).abs() < 1e-6);
        }
    }

    /// The stretch of an hour's static run (`--static-s 3600`) measures 3599.9 s: an hour, so
    /// bias instability and RRW are not marked indicative; ten minutes are.
    #[test]
    fn an_hours_static_run_is_not_marked_indicative() {
        let report = |duration_s: f64| {
            NoiseReport {
                run: 1,
                samples: 2_880_000,
                duration_s,
                tau0_s: 0.00125,
                scaling: "calibration (package frame)".into(),
                axes: Vec::new(),
            }
            .to_string()
        };
        assert!(!report(3599.9).contains("indicative"), "{}", report(3599.9));
        assert!(!report(3600.0).contains("indicative"));
        assert!(report(600.0).contains(
            "(a 600 s stretch measures σ(τ) up to τ = 200 s only: ARW is firm, bias instability and RRW are indicative)"
        ));
    }
}
