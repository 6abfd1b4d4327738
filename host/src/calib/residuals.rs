//! Second pass over the residuals of a fit: their size per run and axis, the white-noise floor
//! measured from their high-frequency part, their cross-axis correlation, and how much their
//! autocorrelation inflates the variance of the estimates.

use super::blocking::{Blocking, LongRun};
use super::error::CalError;
use super::kinematics::Kinematics;
use super::lsq::{run_residuals, Fit, AXES};
use super::model::Columns;

/// Residual statistics of one run, per axis, counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunResidual {
    /// Unclipped samples.
    pub n: [u64; 3],
    /// RMS residual.
    pub rms_counts: [f64; 3],
    /// Noise floor: RMS of the residual's high-frequency part, corrected to white-noise RMS.
    pub noise_floor_counts: [f64; 3],
}

/// Residual statistics of all runs.
#[derive(Debug, Clone)]
pub struct ResidualPass {
    /// Per run, in run order.
    pub per_run: Vec<RunResidual>,
    /// Per axis over all runs.
    pub pooled: RunResidual,
    /// Blocking estimate per axis.
    pub long_run: [LongRun; 3],
    /// Contemporaneous correlation of the residuals between axes.
    pub correlation: [[f64; 3]; 3],
}

/// Centred moving-average high-pass of each axis: Σ(e − mean of the 2w+1 around it)² and
/// the number of samples it stands for, Σ(1 − 1/(2w+1)), so that their ratio is the white-noise
/// variance. Samples without a full window (run ends) are skipped, and so are windows holding a
/// clipped (NaN) value, which a NaN sum marks by itself.
fn high_pass_power(e: &[[f64; 3]], w: usize) -> ([f64; 3], f64) {
    let n = e.len();
    let width = 2 * w + 1;
    if n < width {
        return ([0.0; 3], 0.0);
    }
    let mut sum = [0.0; 3];
    for v in &e[..width] {
        for a in 0..3 {
            sum[a] += v[a];
        }
    }
    let mut power = [0.0; 3];
    let mut used = 0usize;
    let inv = 1.0 / width as f64;
    for i in w..n - w {
        if i > w {
            let (out, inn) = (&e[i - w - 1], &e[i + w]);
            if out.iter().chain(inn).any(|v| v.is_nan()) {
                // Restart the window sums: NaN would poison them for good.
                sum = [0.0; 3];
                for v in &e[i - w..=i + w] {
                    for a in 0..3 {
                        sum[a] += v[a];
                    }
                }
            } else {
                for a in 0..3 {
                    sum[a] += inn[a] - out[a];
                }
            }
        }
        if sum.iter().all(|s| !s.is_nan()) {
            for a in 0..3 {
                power[a] += (e[i][a] - sum[a] * inv).powi(2);
            }
            used += 1;
        }
    }
    (power, used as f64 * (1.0 - inv))
}

/// Computes the residual statistics. `noise_window_s` is the span of the high-pass's moving
/// average: short against the table's period so that model misfit stays out of the floor, long
/// against the noise's correlation time so that the floor is not biased low. Samples with any
/// axis clipped are left out of the blocking and the floor (they are rare, and the lanes run in
/// lockstep), but not out of each other axis's RMS.
pub fn residual_pass<const P: usize, M: Columns<P>>(
    model: &M,
    fit: &Fit<P>,
    kin: &Kinematics,
    noise_window_s: f64,
) -> Result<ResidualPass, CalError> {
    let mut blocking = Blocking::<3>::default();
    let mut cross = [[0.0f64; 3]; 3];
    let mut buf = Vec::new();
    let mut per_run = Vec::with_capacity(kin.runs.len());
    let (mut pooled_n, mut pooled_ss, mut pooled_hp, mut pooled_hw) = ([0u64; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
    for run in &kin.runs {
        run_residuals(model, fit, run, &mut buf);
        let mut n = [0u64; 3];
        let mut ss = [0.0; 3];
        for e in &buf {
            if e.iter().all(|v| !v.is_nan()) {
                blocking.push(*e);
                for i in 0..3 {
                    ss[i] += e[i] * e[i];
                    n[i] += 1;
                    for j in i + 1..3 {
                        cross[i][j] += e[i] * e[j];
                    }
                }
            } else {
                for (i, &v) in e.iter().enumerate() {
                    if !v.is_nan() {
                        ss[i] += v * v;
                        n[i] += 1;
                    }
                }
            }
        }
        blocking.end_segment();
        let w = ((noise_window_s * run.sample_rate_hz / 2.0).round() as usize).max(1);
        let (hp, hw) = high_pass_power(&buf, w);
        let rr = RunResidual {
            n,
            rms_counts: std::array::from_fn(|a| (ss[a] / n[a].max(1) as f64).sqrt()),
            noise_floor_counts: std::array::from_fn(|a| if hw > 0.0 { (hp[a] / hw).sqrt() } else { f64::NAN }),
        };
        for a in 0..3 {
            pooled_n[a] += n[a];
            pooled_ss[a] += ss[a];
            pooled_hp[a] += hp[a];
            pooled_hw[a] += hw;
        }
        per_run.push(rr);
    }
    let pooled = RunResidual {
        n: pooled_n,
        rms_counts: std::array::from_fn(|a| (pooled_ss[a] / pooled_n[a].max(1) as f64).sqrt()),
        noise_floor_counts: std::array::from_fn(|a| (pooled_hp[a] / pooled_hw[a]).sqrt()),
    };
    // Fewer than two unclipped residuals leave an axis as undetermined as a singular system.
    let estimate = |a: usize| blocking.estimate(a).ok_or(CalError::Singular { axis: AXES[a], rcond: 0.0 });
    let long_run = [estimate(0)?, estimate(1)?, estimate(2)?];
    let correlation = std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let (a, b) = (i.min(j), i.max(j));
            let diag = |k: usize| pooled_ss[k];
            if a == b {
                1.0
            } else {
                // Cross sums cover the all-unclipped samples; the diagonal the per-axis ones: the
                // handful of clipped samples barely matter to a correlation.
                cross[a][b] / (diag(a) * diag(b)).sqrt()
            }
        })
    });
    Ok(ResidualPass { per_run, pooled, long_run, correlation })
}
