//! Axis ranges and tick positions, computed here rather than by plotters so that degenerate data
//! (a single point, constant values, NaN) and log axes get sensible, predictable ranges, and so
//! that the layout code knows every tick label before drawing. No other crate is taken for it:
//! the 1-2-5 steps are a dozen lines, and the charting crate already used is the one whose ticks
//! this replaces.

use super::error::PlotError;

/// One axis, ready to draw. Log axes are drawn as a linear axis over log10 of the data, so
/// `lo`, `hi` and the ticks are in plotted units (log10 for a log axis).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Axis {
    /// Visible interval, plotted units.
    pub lo: f64,
    pub hi: f64,
    /// Labelled ticks with their labels, plotted units.
    pub major: Vec<(f64, String)>,
    /// Unlabelled grid lines (the 2…9 multiples on a log axis).
    pub minor: Vec<f64>,
    pub log: bool,
}

impl Axis {
    /// Data value to plotted units; `None` where it cannot be drawn (NaN, ≤ 0 on a log axis).
    pub fn plotted(&self, v: f64) -> Option<f64> {
        if !v.is_finite() {
            None
        } else if self.log {
            (v > 0.0).then(|| v.log10())
        } else {
            Some(v)
        }
    }

    /// Widest tick label, characters: sizes the label area.
    pub fn widest_label(&self) -> usize {
        self.major.iter().map(|(_, l)| l.chars().count()).max().unwrap_or(1)
    }

    /// Categorical axis: one unit per category, labelled at the centres.
    pub fn categories(names: &[String]) -> Self {
        Self {
            lo: 0.0,
            hi: names.len().max(1) as f64,
            major: names.iter().enumerate().map(|(i, n)| (i as f64 + 0.5, n.clone())).collect(),
            minor: Vec::new(),
            log: false,
        }
    }
}

/// How to choose an axis.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AxisRequest<'a> {
    /// Explicit range, data units; overrides the data extent.
    pub fixed: Option<(f64, f64)>,
    /// Explicit ticks, data units; those inside the range are used as given.
    pub ticks: Option<&'a [f64]>,
    pub log: bool,
    /// Fraction of the span added on each side of a data-derived range.
    pub pad: f64,
    /// Wanted number of labelled ticks.
    pub target_ticks: usize,
    /// Which axis, for error messages.
    pub name: &'static str,
}

/// Smallest and largest drawable value (finite; positive on a log axis), plotted units.
pub(crate) fn extent(values: impl IntoIterator<Item = f64>, log: bool) -> Option<(f64, f64)> {
    let probe = Axis { lo: 0.0, hi: 1.0, major: Vec::new(), minor: Vec::new(), log };
    values.into_iter().filter_map(|v| probe.plotted(v)).fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// Builds the axis from the data extent (plotted units, from [`extent`]) or the fixed range.
pub(crate) fn axis(data: Option<(f64, f64)>, req: AxisRequest<'_>) -> Result<Axis, PlotError> {
    let (lo, hi) = match req.fixed {
        Some((a, b)) => {
            let valid = a.is_finite() && b.is_finite() && a < b && (!req.log || a > 0.0);
            if !valid {
                return Err(PlotError::InvalidRange { axis: req.name, lo: a, hi: b, log: req.log });
            }
            if req.log {
                (a.log10(), b.log10())
            } else {
                (a, b)
            }
        }
        None => {
            let (a, b) = data.ok_or(PlotError::NoFiniteData)?;
            padded(a, b, req.pad, req.log)
        }
    };
    let mut axis = Axis { lo, hi, major: Vec::new(), minor: Vec::new(), log: req.log };
    match req.ticks {
        Some(ticks) => {
            let step = ticks.windows(2).map(|w| (w[1] - w[0]).abs()).filter(|s| *s > 0.0).fold(f64::INFINITY, f64::min);
            let step = if step.is_finite() { step } else { (hi - lo).abs().max(1.0) };
            axis.major = ticks
                .iter()
                .filter_map(|&t| axis.plotted(t).map(|p| (p, t)))
                .filter(|(p, _)| within(*p, lo, hi))
                .map(|(p, t)| (p, format_linear(t, step)))
                .collect();
        }
        None if req.log => log_ticks(&mut axis, req.target_ticks),
        None => {
            let step = best_step(lo, hi, req.target_ticks);
            axis.major = multiples(lo, hi, step).into_iter().map(|t| (t, format_linear(t, step))).collect();
        }
    }
    Ok(axis)
}

/// Pads a data extent; widens a zero-width one so a single point or a constant sits mid-axis.
fn padded(a: f64, b: f64, pad: f64, log: bool) -> (f64, f64) {
    if b > a {
        // A span beyond f64 (±1e308 data) is drawn unpadded rather than as ±∞.
        let p = if (b - a).is_finite() { (b - a) * pad } else { 0.0 };
        (a - p, b + p)
    } else if log {
        (a - 0.5, a + 0.5)
    } else if a == 0.0 {
        (-1.0, 1.0)
    } else {
        (a - 0.1 * a.abs(), a + 0.1 * a.abs())
    }
}

fn within(v: f64, lo: f64, hi: f64) -> bool {
    let eps = (hi - lo).abs() * 1e-9;
    v >= lo - eps && v <= hi + eps
}

/// 1, 2 or 5 × 10ⁿ, the smallest not below `raw`: steps people can add up in their heads.
pub(crate) fn nice_step(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let mag = 10f64.powf(raw.log10().floor());
    let norm = raw / mag;
    let m = [1.0, 2.0, 5.0, 10.0].into_iter().find(|m| *m >= norm * (1.0 - 1e-9)).unwrap_or(10.0);
    m * mag
}

/// The 1-2-5 step whose tick count is nearest `target`, the coarser on a tie: rounding the
/// raw step up alone can leave a tall axis with three ticks.
fn best_step(lo: f64, hi: f64, target: usize) -> f64 {
    let target = target.max(1);
    let up = nice_step((hi - lo) / target as f64);
    let mantissa = (up / 10f64.powf(up.log10().floor())).round();
    let down = if mantissa == 5.0 { up * 0.4 } else { up * 0.5 };
    let miss = |step: f64| multiples(lo, hi, step).len().abs_diff(target);
    if miss(down) < miss(up) {
        down
    } else {
        up
    }
}

/// Multiples of `step` inside [lo, hi], snapped so that 0.30000000000000004 prints as 0.3.
fn multiples(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let first = (lo / step - 1e-9).ceil();
    let last = (hi / step + 1e-9).floor();
    // Count in f64: a span of 1e308 would overflow an integer count.
    if !(first.is_finite() && last.is_finite()) || last < first || last - first > 1000.0 {
        return Vec::new();
    }
    (first as i64..=last as i64).map(|i| i as f64 * step).collect()
}

/// Decades as labelled ticks; within a narrow range also 2× and 5×, and the other multiples as
/// minor grid lines so that a log axis still reads as one.
fn log_ticks(axis: &mut Axis, target: usize) {
    let (lo, hi) = (axis.lo, axis.hi);
    let d0 = (lo - 1e-9).ceil() as i32;
    let d1 = (hi + 1e-9).floor() as i32;
    let decades = (d1 - d0 + 1).max(0) as usize;
    let mut major: Vec<f64> = Vec::new();
    let mut minor: Vec<f64> = Vec::new();
    let every = decades.div_ceil(target.max(1)).max(1);
    if decades >= 3 {
        major.extend((d0..=d1).filter(|d| ((d - d0) as usize).is_multiple_of(every)).map(f64::from));
    }
    for d in (lo.floor() as i32)..=(hi.ceil() as i32) {
        for k in 1..10 {
            let v = f64::from(d) + f64::from(k).log10();
            if !within(v, lo, hi) {
                continue;
            }
            let labelled = if decades >= 3 { k == 1 && major.contains(&f64::from(d)) } else { matches!(k, 1 | 2 | 5) };
            if labelled && decades < 3 {
                major.push(v);
            } else if !labelled && (every == 1 || k == 1) {
                // Skipped decades keep a grid line; the 2…9 lines would be clutter there.
                minor.push(v);
            }
        }
    }
    if major.len() < 2 {
        // Less than a factor of ~2 in range: linear ticks read better than none.
        let (a, b) = (10f64.powf(lo), 10f64.powf(hi));
        let step = nice_step((b - a) / target.max(1) as f64);
        major = multiples(a, b, step).into_iter().filter(|v| *v > 0.0).map(f64::log10).collect();
        minor.clear();
    }
    major.sort_by(f64::total_cmp);
    axis.major = major.into_iter().map(|p| (p, format_value(10f64.powf(p)))).collect();
    axis.minor = minor;
}

/// A tick on a linear axis, with as many decimals as the step needs.
pub(crate) fn format_linear(v: f64, step: f64) -> String {
    if v.abs() < step * 1e-9 {
        return "0".into();
    }
    let big = v.abs().max(step);
    let s = if big >= 1e6 || step < 1e-4 {
        let digits = ((v.abs().log10().floor() - step.log10().floor()).max(0.0) as usize).min(6);
        format!("{v:.digits$e}")
    } else {
        let decimals = (-(step.log10() + 1e-9).floor()).clamp(0.0, 10.0) as usize;
        format!("{v:.decimals$}")
    };
    minus(s)
}

/// A value in three significant figures, for log-axis ticks and bar labels.
pub(crate) fn format_value(v: f64) -> String {
    if !v.is_finite() {
        return "n/a".into();
    }
    if v == 0.0 {
        return "0".into();
    }
    let mag = v.abs().log10().floor();
    let s = if !(-4.0..6.0).contains(&mag) {
        let e = format!("{v:.2e}");
        let (m, x) = e.split_once('e').unwrap_or((&e, "0"));
        format!("{}e{x}", trim_zeros(m))
    } else {
        let decimals = (2.0 - mag).max(0.0) as usize;
        trim_zeros(&format!("{v:.decimals$}")).to_string()
    };
    minus(s)
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// A real minus sign: a hyphen is too short to read as one next to digits.
fn minus(s: String) -> String {
    s.replace('-', "\u{2212}")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(log: bool) -> AxisRequest<'static> {
        AxisRequest { fixed: None, ticks: None, log, pad: 0.05, target_ticks: 6, name: "y" }
    }

    fn labels(a: &Axis) -> Vec<&str> {
        a.major.iter().map(|(_, l)| l.as_str()).collect()
    }

    #[test]
    fn nice_steps_are_1_2_5() {
        assert_eq!(nice_step(0.13), 0.2);
        assert_eq!(nice_step(3.0), 5.0);
        assert_eq!(nice_step(7.0), 10.0);
        assert_eq!(nice_step(1.0), 1.0);
        assert_eq!(nice_step(f64::NAN), 1.0);
    }

    #[test]
    fn linear_ticks_cover_the_data_and_print_cleanly() {
        let a = axis(extent([0.1, 0.2, 0.7], false), req(false)).unwrap();
        assert!(a.lo < 0.1 && a.hi > 0.7);
        assert_eq!(labels(&a), ["0.1", "0.2", "0.3", "0.4", "0.5", "0.6", "0.7"]);
        let b = axis(extent([-3.0, 3.0], false), req(false)).unwrap();
        assert_eq!(labels(&b), ["\u{2212}3", "\u{2212}2", "\u{2212}1", "0", "1", "2", "3"]);
    }

    #[test]
    fn degenerate_extents_get_a_usable_range() {
        let single = axis(extent([5.0], false), req(false)).unwrap();
        assert!(single.lo < 5.0 && single.hi > 5.0 && single.major.len() >= 2);
        let zero = axis(extent([0.0, 0.0], false), req(false)).unwrap();
        assert_eq!((zero.lo, zero.hi), (-1.0, 1.0));
        let log_single = axis(extent([0.02], true), req(true)).unwrap();
        assert!(log_single.lo < 0.02f64.log10() && log_single.hi > 0.02f64.log10());
        assert!(log_single.major.len() >= 2);
        assert_eq!(extent([f64::NAN, f64::INFINITY], false), None);
        assert!(matches!(axis(None, req(false)), Err(PlotError::NoFiniteData)));
        assert_eq!(extent([-1.0, 0.0, 2.0], true), Some((2f64.log10(), 2f64.log10())));
    }

    #[test]
    fn fixed_ranges_are_checked() {
        let bad = AxisRequest { fixed: Some((1.0, 1.0)), ..req(false) };
        assert!(matches!(axis(None, bad), Err(PlotError::InvalidRange { .. })));
        let nonpositive_log = AxisRequest { fixed: Some((0.0, 10.0)), ..req(true) };
        assert!(matches!(axis(None, nonpositive_log), Err(PlotError::InvalidRange { .. })));
        let ok = AxisRequest { fixed: Some((0.0, 360.0)), ticks: Some(&[0.0, 45.0, 90.0, 400.0]), ..req(false) };
        let a = axis(None, ok).unwrap();
        assert_eq!(labels(&a), ["0", "45", "90"]);
    }

    #[test]
    fn log_axes_label_decades_or_1_2_5() {
        let wide = axis(extent([1e-4, 10.0], true), req(true)).unwrap();
        assert_eq!(labels(&wide), ["0.0001", "0.001", "0.01", "0.1", "1", "10"]);
        assert!(!wide.minor.is_empty());
        let narrow = axis(extent([0.3, 4.0], true), req(true)).unwrap();
        assert_eq!(labels(&narrow), ["0.5", "1", "2"]);
        let very_wide = axis(extent([1e-9, 1e3], true), req(true)).unwrap();
        assert!(very_wide.major.len() <= 7, "{:?}", labels(&very_wide));
        assert_eq!(labels(&very_wide)[0], "1e\u{2212}9");
    }

    #[test]
    fn values_print_in_three_figures() {
        assert_eq!(format_value(1.0), "1");
        assert_eq!(format_value(0.012345), "0.0123");
        assert_eq!(format_value(123.456), "123");
        assert_eq!(format_value(2.5e7), "2.5e7");
        assert_eq!(format_value(-0.5), "\u{2212}0.5");
        assert_eq!(format_value(f64::NAN), "n/a");
    }
}
