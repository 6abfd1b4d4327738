//! Host commands: validation, execution, acknowledgement. Every command frame gets exactly one
//! [`Ack`], sent after whatever the command itself emits (Hello, RunStarted), so a host that has
//! the ack has everything it caused.

use crate::link::Received;
use crate::rig::{GyroControl, Rig, Run};
use crate::speed_loop::{Drive, Gains};
use crate::supervisor::{MAX_RATE_MDPS, OVER_SPEED_CPS};
use protocol::{
    Ack, CmdResult, Command, DriveConfig, RigMsg, RunStarted, RunStopped, StartRun, ENCODER_COUNTS_PER_REV,
};

/// Milli-degrees per second to base-table encoder counts per second, rounded to nearest
/// ([`protocol::units::cps_from_mdps`]): 180 000 m°/s (0.5 Hz) is exactly 162 000 cps.
pub const fn rate_cps(rate_mdps: u32) -> u32 {
    protocol::units::cps_from_mdps(rate_mdps, ENCODER_COUNTS_PER_REV)
}

/// The drive a `ConfigureDrive` describes, or why it is refused: outside
/// [`protocol::drive_limits`], or unable to exceed the over-speed limit at full duty (a runaway
/// would then go undetected, [`crate::supervisor::OVER_SPEED_CPS`]).
pub fn drive_for(config: &DriveConfig) -> Result<Drive, CmdResult> {
    let drive = Drive::from_config(config);
    if !config.in_limits() || drive.k_cps_per_duty() <= OVER_SPEED_CPS as f32 {
        return Err(CmdResult::InvalidArgument);
    }
    Ok(drive)
}

/// Signed setpoint for a start request (0 for a static run), or why it is refused.
pub fn setpoint_cps(start: &StartRun) -> Result<i32, CmdResult> {
    if start.rate_mdps > MAX_RATE_MDPS {
        return Err(CmdResult::InvalidArgument);
    }
    Ok(start.direction.sign() * rate_cps(start.rate_mdps) as i32)
}

impl Rig {
    /// Executes one command and acknowledges it.
    pub(crate) fn execute(&mut self, t_us: u32, rx: Received, gyro: &mut impl GyroControl) {
        let result = match rx.command {
            Command::Identify => {
                self.send_hello();
                // Faults in force, again: the host may have connected after they were reported.
                for fault in [self.reset_fault, self.gyro_fault].into_iter().flatten() {
                    self.report(t_us, fault);
                }
                CmdResult::Ok
            }
            Command::Start(start) => self.start(t_us, &start),
            Command::Stop => {
                match self.run {
                    Run::Running { tag } => {
                        self.speed_loop.set_target(0);
                        self.run = Run::Stopping { tag };
                    }
                    // Nothing turns: the run ends now.
                    Run::Static { tag } => {
                        self.run = Run::Idle;
                        self.link.send(&RigMsg::RunStopped(RunStopped { t_us, run_tag: tag }));
                    }
                    Run::Idle | Run::Stopping { .. } => {}
                }
                CmdResult::Ok
            }
            Command::ConfigureGyro(config) => {
                if self.run != Run::Idle {
                    CmdResult::Busy
                } else {
                    match gyro.apply(config) {
                        Ok(()) => {
                            self.gyro_config = config;
                            self.gyro_fault = None;
                            // Restart the silence watch: the new ODR begins now.
                            self.last_sample_us = t_us;
                            self.send_hello();
                            CmdResult::Ok
                        }
                        Err(fault) => {
                            self.gyro_fault = Some(fault);
                            self.report(t_us, fault);
                            CmdResult::Faulted
                        }
                    }
                }
            }
            Command::Heartbeat => CmdResult::Ok,
            Command::ConfigureDrive(config) => match (self.run, drive_for(&config)) {
                (Run::Idle, Ok(drive)) => {
                    self.speed_loop.set_gains(Gains::for_drive(&drive));
                    CmdResult::Ok
                }
                (Run::Idle, Err(refusal)) => refusal,
                _ => CmdResult::Busy,
            },
        };
        self.link.send(&RigMsg::Ack(Ack { cmd_seq: rx.seq, result }));
    }

    fn start(&mut self, t_us: u32, start: &StartRun) -> CmdResult {
        if self.gyro_fault.is_some() {
            return CmdResult::Faulted;
        }
        if self.run != Run::Idle {
            return CmdResult::Busy;
        }
        let target_cps = match setpoint_cps(start) {
            Ok(cps) => cps,
            Err(refusal) => return refusal,
        };
        self.motor_off();
        self.motor_faults = 0;
        self.speed_loop.set_target(target_cps);
        self.run =
            if start.is_static() { Run::Static { tag: start.run_tag } } else { Run::Running { tag: start.run_tag } };
        self.link.send(&RigMsg::RunStarted(RunStarted {
            t_us,
            run_tag: start.run_tag,
            rate_mdps: start.rate_mdps,
            direction: start.direction,
            gyro: self.gyro_config,
        }));
        CmdResult::Ok
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::Direction;

    #[test]
    fn drive_validation() {
        let ok = |c: DriveConfig| drive_for(&c).map(|d| (d.gear_ratio, d.load_inertia_kgm2, d.supply_v));
        assert_eq!(ok(DriveConfig::PROTOTYPE), Ok((66.0, 0.012, 24.0)));
        let p = DriveConfig::PROTOTYPE;
        assert_eq!(ok(DriveConfig { gear_ratio_milli: 999, ..p }), Err(CmdResult::InvalidArgument));
        assert_eq!(ok(DriveConfig { load_inertia_gcm2: 10_000_001, ..p }), Err(CmdResult::InvalidArgument));
        assert_eq!(ok(DriveConfig { supply_mv: 5_999, ..p }), Err(CmdResult::InvalidArgument));
        // 24 V through 117:1 still exceeds 450 °/s at full duty (405 000 cps: 724 000 × 66/117 =
        // 408 000); 118:1 does not (404 900).
        assert!(ok(DriveConfig { gear_ratio_milli: 117_000, ..p }).is_ok());
        assert_eq!(ok(DriveConfig { gear_ratio_milli: 118_000, ..p }), Err(CmdResult::InvalidArgument));
        // At 48 V, twice the ratio.
        assert!(ok(DriveConfig { gear_ratio_milli: 235_000, supply_mv: 48_000, ..p }).is_ok());
        assert_eq!(
            ok(DriveConfig { gear_ratio_milli: 236_000, supply_mv: 48_000, ..p }),
            Err(CmdResult::InvalidArgument)
        );
    }

    #[test]
    fn start_validation() {
        let run = |rate_mdps, direction| StartRun { rate_mdps, direction, run_tag: 1 };
        assert_eq!(setpoint_cps(&run(180_000, Direction::Cw)), Ok(-162_000));
        assert_eq!(setpoint_cps(&run(MAX_RATE_MDPS, Direction::Ccw)), Ok(324_000));
        assert_eq!(setpoint_cps(&run(0, Direction::Cw)), Ok(0), "a static run");
        assert_eq!(setpoint_cps(&run(MAX_RATE_MDPS + 1, Direction::Ccw)), Err(CmdResult::InvalidArgument));
    }
}
