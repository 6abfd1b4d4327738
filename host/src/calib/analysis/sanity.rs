//! What must hold before a fit may be called a calibration (issue 24, item 3). A fit on too few
//! samples, or one whose numbers are not numbers, passes every test of the diagnostics (a test
//! on NaN is never significant) and would be certified at the noise floor, far off the truth.
//! So, around the loop:
//! - [`enough_samples`], before any fit: every run gives the fit at least one sensor-table
//!   revolution of samples once the gaps are cut out (what the fit really uses);
//! - [`sound`], on the answer: every parameter and σ finite, every σ positive, the covariance
//!   positive definite; otherwise there is no answer ([`CalError::Degenerate`], exit 1);
//! - [`vouch`], on the loop's report: [`sound`], then every noise floor and test statistic of
//!   the diagnostics a number; otherwise the answer stands but nothing vouches for it, and the
//!   verdict is [`crate::calib::analysis::closure::Verdict::UnexplainedStructure`] with the reason in [`crate::calib::analysis::closure::LoopReport::unvouched`]
//!   (exit 3).

use crate::calib::analysis::diagnostics::{AxisRunDiag, Diagnostics};
use crate::calib::engine::LoopData;
use crate::calib::result::axes::AXES;
use crate::calib::result::error::CalError;
use crate::calib::result::report::CalReport;

/// Fewest samples per run the fit must use once the gaps are cut out: one sensor-table
/// revolution at the run's commanded rate, the bar `kinematics` sets on the samples at steady
/// speed (the paper's per-pose sinusoid fit needs a whole period), now on the samples left clear
/// of every gap by `MAX_DELAY_S` (`ValidSamples`). It also covers what the diagnostics need of a
/// run: the noise floor's moving window (2·40 + 1 = 81 samples at 800 Hz,
/// `CalOptions::noise_window_s`; fewer give a NaN floor) and the whiteness test's 22 blocks of
/// 32 (704). 1600 at 180 °/s, 800 Hz, 1:1.
pub fn needed_samples(sample_rate_hz: f64, gear_ratio: f64, commanded_rate_dps: f64) -> usize {
    let table_dps = (gear_ratio * commanded_rate_dps).abs();
    if table_dps > 0.0 && sample_rate_hz.is_finite() {
        ((sample_rate_hz * 360.0 / table_dps).ceil() as usize).max(1)
    } else {
        usize::MAX
    }
}

/// Every run uses at least [`needed_samples`] once the gaps are cut out.
pub fn enough_samples(data: &LoopData) -> Result<(), CalError> {
    for (rk, rd) in data.kin.runs.iter().zip(&data.runs) {
        let needed = needed_samples(rk.sample_rate_hz, rk.gear_ratio, rk.commanded_rate_dps);
        if rd.n_valid < needed {
            return Err(CalError::TooFewBetweenGaps {
                run: rk.run,
                label: rk.label.clone(),
                usable: rd.n_valid,
                clear_ms: crate::calib::effects::MAX_DELAY_S * 1e3,
                kept: rk.samples.len(),
                needed,
            });
        }
    }
    Ok(())
}

/// Smallest pivot accepted in the Cholesky factorisation of the base parameters' correlation
/// matrix. Pivot j is 1 − R² of parameter j on those before it, and never below the matrix's
/// smallest eigenvalue; the fit accepts a normal matrix down to a reciprocal condition of 1e-13
/// (`engine::solve::MIN_RCOND`), so a covariance it produced honestly passes, and one whose pivot is
/// rounding (1e-16) is singular.
const MIN_PIVOT: f64 = 1e-13;

/// The first number of the answer that is not one: a parameter or σ not finite, a σ not
/// positive, a covariance not positive definite. `Ok` when the answer is sound.
pub fn sound(r: &CalReport) -> Result<(), CalError> {
    let degenerate = |what: String| CalError::Degenerate { model: r.model.clone(), what };
    for (p, name) in r.param_names.iter().enumerate() {
        let value = if p % 4 == 3 { r.offset_counts[p / 4] } else { r.m_counts_per_dps[p / 4][p % 4] };
        let var = r.cov.get(p).and_then(|row| row.get(p)).copied().unwrap_or(f64::NAN);
        if !value.is_finite() {
            return Err(degenerate(format!("{name} is {value}")));
        }
        if !(var.is_finite() && var > 0.0) {
            return Err(degenerate(format!("the variance of {name} is {var:e}")));
        }
    }
    for a in &r.axes {
        let k = a.k_counts_per_dps;
        if !(k.value.is_finite() && k.sigma.is_finite() && k.sigma > 0.0) {
            return Err(degenerate(format!(
                "the sensitivity of axis {} is {} ± {} counts/(°/s)",
                a.axis, k.value, k.sigma
            )));
        }
        // The direction's components and the tilt may have σ = 0 to rounding (a component of 1
        // moves only at second order), so only finite is asked of them.
        let derived = [("the tilt", a.tilt_deg), ("the offset", a.offset_counts)]
            .into_iter()
            .chain(["the direction's x", "the direction's y", "the direction's z"].into_iter().zip(a.s));
        for (what, e) in derived {
            if !(e.value.is_finite() && e.sigma.is_finite()) {
                return Err(degenerate(format!("{what} of axis {} is {} ± {}", a.axis, e.value, e.sigma)));
            }
        }
        let c = a.tilt_components_cov_deg2;
        if !(c[0][0] > 0.0 && c[0][0] * c[1][1] - c[0][1] * c[1][0] > 0.0) || c.iter().flatten().any(|v| !v.is_finite())
        {
            return Err(degenerate(format!(
                "the covariance of axis {}'s tilt components is not positive definite ({c:?} deg²)",
                a.axis
            )));
        }
    }
    // Cholesky of the correlation matrix (the covariance scaled to unit diagonal, so the check
    // does not depend on the parameters' units): its first pivot at or below MIN_PIVOT names the
    // parameter the ones before it already determine.
    let n = r.param_names.len();
    let sd: Vec<f64> = (0..n).map(|i| r.cov[i][i].sqrt()).collect();
    let mut l = vec![vec![0.0f64; n]; n];
    for j in 0..n {
        let pivot = r.cov[j][j] / (sd[j] * sd[j]) - (0..j).map(|k| l[j][k] * l[j][k]).sum::<f64>();
        if !(pivot.is_finite() && pivot > MIN_PIVOT) {
            return Err(degenerate(format!(
                "the covariance of the {n} base parameters is not positive definite (pivot {pivot:.1e} at {})",
                r.param_names[j]
            )));
        }
        l[j][j] = pivot.sqrt();
        for i in j + 1..n {
            let c = r.cov[i][j] / (sd[i] * sd[j]) - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            l[i][j] = c / l[j][j];
        }
    }
    Ok(())
}

/// The first noise floor or test statistic of `d` that is not a number, as "what, where".
pub fn first_not_a_number(d: &Diagnostics) -> Option<String> {
    for (a, axis) in AXES.into_iter().enumerate() {
        if !(d.noise_variance_counts2[a].is_finite() && d.noise_variance_counts2[a] > 0.0) {
            return Some(format!("axis {axis}: the noise variance is {:e} counts²", d.noise_variance_counts2[a]));
        }
        if !(d.floor_dps[a].is_finite() && d.floor_dps[a] > 0.0) {
            return Some(format!("axis {axis}: the noise floor is {} °/s", d.floor_dps[a]));
        }
        for (what, v) in [("RMS residual", d.rms_dps[a]), ("autocorrelation inflation", d.inflation[a])] {
            if !v.is_finite() {
                return Some(format!("axis {axis}: the {what} is {v}"));
            }
        }
    }
    for rd in &d.runs {
        for ad in &rd.axes {
            if let Some(what) = axis_run_not_a_number(ad) {
                return Some(format!(
                    "run {} ({}, {:+.1} °/s), axis {}: {what}",
                    rd.run, rd.pose, rd.commanded_rate_dps, ad.axis
                ));
            }
        }
    }
    None
}

fn axis_run_not_a_number(ad: &AxisRunDiag) -> Option<String> {
    for (what, v) in [("the noise floor", ad.floor_dps), ("the long-run noise", ad.noise_dps)] {
        if !(v.is_finite() && v > 0.0) {
            return Some(format!("{what} is {v} °/s"));
        }
    }
    let values = [
        ("the RMS residual", ad.rms_dps),
        ("RMS/floor", ad.rms_over_floor),
        ("the whiteness χ²", ad.whiteness.chi2),
        ("the time-drift χ²", ad.time_drift.chi2),
        ("the temperature χ²", ad.temperature.chi2),
        ("the rate-dependence χ²", ad.rate.chi2),
        ("the speed-ripple χ²", ad.ripple.chi2),
    ];
    for (what, v) in values {
        if !v.is_finite() {
            return Some(format!("{what} is {v}"));
        }
    }
    ad.orders
        .iter()
        .find(|o| !(o.chi2.is_finite() && o.amplitude_dps.is_finite() && o.sigma_dps.is_finite()))
        .map(|o| format!("the χ² of harmonic {} is {}", o.order, o.chi2))
}

#[cfg(test)]
mod tests {
    use crate::calib::testgen::{two_pose_runs, typical_sensor};
    use crate::calib::{calibrate, close_loop, CalOptions, LoopOptions, Verdict};
    use crate::capture::Run;

    /// A run as a lossy line leaves it: every 40th sample lost (a gap every 50 ms, so no
    /// sample lies 41 samples, `MAX_DELAY_S`, clear of one), but for two spots a quarter-turn
    /// apart where two losses in a row are spared, leaving a stretch of 119 samples with 37 clear
    /// of both its gaps: 74 per run, fewer than the noise floor's 81-sample window.
    fn lossy(mut run: Run) -> Run {
        let spared = [4000, 4040, 4400, 4440];
        let lost = |i: usize| i.is_multiple_of(40) && !spared.contains(&i);
        run.samples = run.samples.into_iter().enumerate().filter(|&(i, _)| !lost(i)).map(|(_, s)| s).collect();
        run
    }

    /// Issue 24, item 3: such runs used to be certified at the noise floor on a NaN floor (72
    /// samples per run, fewer than the floor's 81-sample window); now they are refused, with
    /// the run and the count the fit really had.
    #[test]
    fn few_samples_between_gaps_are_refused_not_certified() {
        let runs: Vec<Run> = two_pose_runs(3).into_iter().map(lossy).collect();
        let expected = "run 1 (pose 1, +180.0 °/s): too few usable samples once the gaps are cut out (74 of 14823 at steady speed lie 50 ms clear of every gap), need at least 1600 (one sensor-table revolution)";
        match close_loop(&runs, &LoopOptions::default(), None) {
            Ok(r) => {
                let m: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| typical_sensor().0[(i, j)]));
                let z = crate::calib::result::truth_check::max_z_against_m(r.final_report(), &m);
                panic!("not refused: {:?} at max |z| {z:.1}\n{}", r.verdict(), r.summary())
            }
            Err(e) => assert_eq!(e.to_string(), expected),
        }
        assert_eq!(calibrate(&runs, &CalOptions::default()).unwrap_err().to_string(), expected);
    }

    /// An answer whose σ or covariance is not one is no calibration; a NaN floor or statistic
    /// in the diagnostics leaves the answer but takes the verdict at the noise floor away.
    #[test]
    fn numbers_that_are_not_numbers_are_refused_or_flagged() {
        let good = close_loop(&two_pose_runs(4), &LoopOptions::default(), None).unwrap();
        assert_eq!(good.verdict(), Verdict::AtNoiseFloor, "{}", good.summary());
        let good = good.vouched().unwrap();
        assert_eq!((good.verdict(), &good.unvouched), (Verdict::AtNoiseFloor, &None));
        let model = good.final_report.model.clone();

        let mut r = good.clone();
        r.final_report.cov[5][5] = f64::NAN;
        assert_eq!(
            r.vouched().unwrap_err().to_string(),
            format!("degenerate fit ({model}): the variance of m_y.omega_y_dps is NaN; no calibration")
        );
        // m_z.omega_x_dps a copy of m_y.omega_x_dps: every variance positive, the whole singular.
        let mut r = good.clone();
        let cov = &mut r.final_report.cov;
        cov[8] = cov[4].clone();
        for row in cov.iter_mut() {
            row[8] = row[4];
        }
        let err = r.vouched().unwrap_err().to_string();
        let head = format!(
            "degenerate fit ({model}): the covariance of the 12 base parameters is not positive definite (pivot "
        );
        assert!(err.starts_with(&head) && err.ends_with(" at m_z.omega_x_dps); no calibration"), "{err}");

        let mut r = good.clone();
        r.initial.runs[1].axes[2].floor_dps = f64::NAN;
        let r = r.vouched().unwrap();
        let reason = "linear model, run 2 (pose 2, +180.0 °/s), axis z: the noise floor is NaN °/s";
        assert_eq!((r.verdict(), r.unvouched.as_deref()), (Verdict::UnexplainedStructure, Some(reason)));
        let summary = r.summary();
        assert!(summary.contains("VERDICT: NOT VOUCHED FOR") && summary.contains(reason), "{summary}");
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["unvouched"], reason);
        assert_eq!(json["verdict"], "UnexplainedStructure");
    }
}
