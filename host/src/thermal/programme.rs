//! A simulated chamber programme: the simulator's sessions at each setpoint, each starting when
//! the live session's own settle watch finds the simulated OUT_TEMP settled. (Here rather than
//! in `sim`, so that `sim` imports nothing of `thermal`.)

use super::settle::{SettleCriterion, SettleWatch};
use crate::sim::thermal::{ChamberStep, TemperatureDependence};
use crate::sim::{self, ConfigError, SimConfig};

/// Longest simulated wait for a settled die at one setpoint, s: 24 h (judgement: a chamber that
/// has not settled the die in a day is broken, not slow).
pub const MAX_SETTLE_S: f64 = 86_400.0;

/// One setpoint of a simulated chamber programme: its session and the wait before it.
#[derive(Debug, Clone)]
pub struct ProgrammeStep {
    /// The session at this setpoint (its `chamber` set).
    pub config: SimConfig,
    /// From the chamber's step to the settled verdict, s.
    pub settle_s: f64,
}

/// The sessions of a chamber programme: `base`'s runs at each setpoint in turn, each starting
/// when `criterion` finds the simulated OUT_TEMP settled. The die starts at the lab's ambient
/// (the simulator's power-up temperature); each step starts from the previous setpoint (its
/// small remaining lag ignored). Temperature dependence is switched on at its defaults unless
/// `base` sets it.
pub fn programme(
    base: &SimConfig,
    setpoints_c: &[f64],
    criterion: SettleCriterion,
) -> Result<Vec<ProgrammeStep>, ConfigError> {
    // The rig's OUT_TEMP offset and the lab's temperature, as the simulator draws them.
    let at_power_up = sim::simulate(&SimConfig { runs: Vec::new(), chamber: None, ..base.clone() })?.truth;
    let out_temp_at_0c = at_power_up.out_temp_at_0c;
    let rise_c = base.effects.offset_drift.map_or(0.0, |d| d.rise_c);
    let mut from_c = at_power_up.ambient_c;
    let mut steps = Vec::with_capacity(setpoints_c.len());
    for (j, &setpoint_c) in setpoints_c.iter().enumerate() {
        let mut step = ChamberStep::new(j as u32 + 1, from_c, setpoint_c);
        let refuse = |requirement: String| ConfigError { field: "chamber".into(), requirement };
        if !step.is_valid() {
            return Err(refuse(format!("setpoint {setpoint_c} must be finite")));
        }
        let mut watch = SettleWatch::new(criterion);
        let reading = |t: f64| -(out_temp_at_0c - (step.die_c(t) + rise_c)).round();
        let settle_s = (0..=MAX_SETTLE_S as u32)
            .map(f64::from)
            .find(|&t| watch.push(t, reading(t)))
            .ok_or_else(|| refuse(format!("setpoint {setpoint_c} °C does not settle within 24 h")))?;
        step.capture_after_s = settle_s;
        let mut config = base.clone();
        config.chamber = Some(step);
        config.effects.temperature_dependence.get_or_insert_with(TemperatureDependence::default);
        config.validate()?;
        steps.push(ProgrammeStep { config, settle_s });
        from_c = setpoint_c;
    }
    Ok(steps)
}
