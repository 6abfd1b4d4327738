//! When the die has settled at a chamber setpoint: the slope of OUT_TEMP over a trailing window.
//!
//! Criterion: over the last [`SettleCriterion::window_s`], the least-squares slope of the die
//! temperature is at most [`SettleCriterion::max_slope_c_per_min`] in magnitude and the readings
//! span at most [`SettleCriterion::max_span_c`]. The slope default is MIL-STD-810H Part One's
//! definition of temperature stabilisation (the operating part's temperature changes by no more
//! than 2 °C per hour). OUT_TEMP reads whole °C (datasheet Table 5), so a slow drift shows as one
//! step now and then, and one step at the window's edge barely moves a fitted slope: the span
//! bound (one LSB) refuses any window with two steps in it, i.e. any drift above about one LSB
//! per window. The window, 20 min (engineering judgement), puts that resolution at 3 °C/h, next
//! to the standard's 2 °C/h; over its 1 200 readings the rounding alone scatters the fitted
//! slope by σ ≈ (1/√12)/(√1200 · 346 s) ≈ 0.0015 °C/min, twenty times below the threshold.
//! With the simulated die's 180-s lag, a settled die is within 0.1 °C of where it ends up,
//! ≤ 0.003 °/s of offset at the datasheet's 0.03 °/s/°C.

use std::collections::VecDeque;

/// MIL-STD-810H Part One, "temperature stabilization": 2 °C/h.
pub const DEFAULT_MAX_SLOPE_C_PER_MIN: f64 = 2.0 / 60.0;
/// Trailing window, s (see the module's note on OUT_TEMP's resolution).
pub const DEFAULT_WINDOW_S: f64 = 1200.0;
/// Largest span of the readings in the window, °C: one OUT_TEMP step.
pub const DEFAULT_MAX_SPAN_C: f64 = 1.0;

/// The settle criterion: slope at most `max_slope_c_per_min` over the trailing `window_s`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SettleCriterion {
    /// Largest |slope| accepted, °C/min.
    pub max_slope_c_per_min: f64,
    /// Trailing window the slope is fitted over, s.
    pub window_s: f64,
    /// Largest span (max − min) of the window's readings, °C.
    pub max_span_c: f64,
}

impl Default for SettleCriterion {
    fn default() -> Self {
        Self {
            max_slope_c_per_min: DEFAULT_MAX_SLOPE_C_PER_MIN,
            window_s: DEFAULT_WINDOW_S,
            max_span_c: DEFAULT_MAX_SPAN_C,
        }
    }
}

/// Watches die-temperature readings against a [`SettleCriterion`].
#[derive(Debug, Clone)]
pub struct SettleWatch {
    criterion: SettleCriterion,
    first_t_s: Option<f64>,
    readings: VecDeque<(f64, f64)>,
}

impl SettleWatch {
    /// A watch that has seen nothing yet.
    pub fn new(criterion: SettleCriterion) -> Self {
        Self { criterion, first_t_s: None, readings: VecDeque::new() }
    }

    /// Adds a reading (time in s, increasing; die temperature in °C) and says whether the die
    /// has now settled.
    pub fn push(&mut self, t_s: f64, temp_c: f64) -> bool {
        self.first_t_s.get_or_insert(t_s);
        self.readings.push_back((t_s, temp_c));
        while self.readings.front().is_some_and(|&(t, _)| t < t_s - self.criterion.window_s) {
            self.readings.pop_front();
        }
        self.settled()
    }

    /// The window's least-squares slope, °C/min (None with fewer than two readings).
    pub fn slope_c_per_min(&self) -> Option<f64> {
        let n = self.readings.len() as f64;
        if n < 2.0 {
            return None;
        }
        let mean_t = self.readings.iter().map(|r| r.0).sum::<f64>() / n;
        let mean_y = self.readings.iter().map(|r| r.1).sum::<f64>() / n;
        let (sxy, sxx) = self.readings.iter().fold((0.0, 0.0), |(sxy, sxx), &(t, y)| {
            (sxy + (t - mean_t) * (y - mean_y), sxx + (t - mean_t) * (t - mean_t))
        });
        (sxx > 0.0).then(|| 60.0 * sxy / sxx)
    }

    /// Whether a full window has been seen and its slope is within the criterion.
    pub fn settled(&self) -> bool {
        let (Some(first), Some(&(last, _))) = (self.first_t_s, self.readings.back()) else { return false };
        let (lo, hi) =
            self.readings.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| (lo.min(r.1), hi.max(r.1)));
        last - first >= self.criterion.window_s
            && hi - lo <= self.criterion.max_span_c
            && self.slope_c_per_min().is_some_and(|s| s.abs() <= self.criterion.max_slope_c_per_min)
    }

    /// Mean die temperature over the window, °C.
    pub fn mean_c(&self) -> Option<f64> {
        let n = self.readings.len();
        (n > 0).then(|| self.readings.iter().map(|r| r.1).sum::<f64>() / n as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_of_rounded_readings_settles_only_once_the_slope_is_below_the_criterion() {
        // A die approaching 40 °C with a 180-s lag from 10 °C below, read in whole degrees.
        let die = |t: f64| 40.0 - 10.0 * (-t / 180.0).exp();
        let mut w = SettleWatch::new(SettleCriterion::default());
        let settled_at = (0..20_000).map(f64::from).find(|&t| w.push(t, die(t).round())).unwrap();
        // The true slope 10/180·e^(−t/τ) °C/s falls to 2 °C/h at t = τ·ln(300) = 1027 s; the
        // 20-min window cannot say so before it is full.
        assert!((1200.0..2400.0).contains(&settled_at), "{settled_at}");
        assert!((die(settled_at) - 40.0).abs() < 0.1);
        // A constant reading settles after exactly one window, not before.
        let mut flat = SettleWatch::new(SettleCriterion::default());
        assert!(!(0..1200).any(|t| flat.push(f64::from(t), 25.0)));
        assert!(flat.push(1200.0, 25.0));
        assert_eq!(flat.mean_c(), Some(25.0));
        // A steady ramp at 0.05 °C/min never settles, nor one at 0.1 °C/min read in whole
        // degrees (one step per 10 min: a step at the window's edge hides from the slope, the
        // span sees the two).
        let mut ramp = SettleWatch::new(SettleCriterion::default());
        assert!(!(0..7200).any(|t| ramp.push(f64::from(t), 0.05 * f64::from(t) / 60.0)));
        let mut steps = SettleWatch::new(SettleCriterion::default());
        assert!(!(0..7200).any(|t| steps.push(f64::from(t), (0.1 * f64::from(t) / 60.0).round())));
    }
}
