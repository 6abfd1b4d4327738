//! What can be said of a set of runs before touching their samples: that there is something to
//! calibrate (runs of one gyro configuration, both poses), and the datasheet's sensitivity.

use crate::calib::result::error::CalError;
use crate::capture::Run;
use crate::geometry::Pose;

/// Datasheet sensitivity in counts per °/s.
pub fn nominal_counts_per_dps(fs: protocol::FullScale) -> f64 {
    1e6 / f64::from(fs.udps_per_lsb())
}

/// Checks what can be checked before touching the samples: runs present, one gyro config, both
/// poses.
pub fn check_runs(runs: &[Run]) -> Result<(), CalError> {
    let first = runs.first().ok_or(CalError::NoRuns)?;
    for (i, r) in runs.iter().enumerate().skip(1) {
        if r.gyro != first.gyro {
            return Err(CalError::InconsistentGyro {
                run: i + 1,
                label: r.label(),
                found: r.gyro,
                expected: first.gyro,
            });
        }
    }
    for (pose, other) in [(Pose::One, Pose::Two), (Pose::Two, Pose::One)] {
        if !runs.iter().any(|r| r.pose == pose) {
            return Err(CalError::MissingPose { present: other, missing: pose });
        }
    }
    Ok(())
}
