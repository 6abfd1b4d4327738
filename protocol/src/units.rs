//! The wire's units and the one place they are converted: rates travel as m°/s (`Start`,
//! `RunStarted`) and as encoder counts per second (`Motor`), people and the host's maths use °/s.
//! Every conversion between them, on either end, is one of these functions.

use crate::msg::Direction;

/// Milli-degrees per degree.
pub const MDEG_PER_DEG: u32 = 1_000;

/// Degrees per revolution.
pub const DEG_PER_REV: f64 = 360.0;

/// A wire rate magnitude (m°/s) → °/s.
pub fn dps_from_mdps(rate_mdps: u32) -> f64 {
    f64::from(rate_mdps) / f64::from(MDEG_PER_DEG)
}

/// A wire rate and direction → signed °/s (positive counter-clockwise).
pub fn signed_dps(rate_mdps: u32, direction: Direction) -> f64 {
    dps_from_mdps(rate_mdps) * f64::from(direction.sign())
}

/// The magnitude of a rate in °/s → m°/s on the wire, rounded to nearest (NaN → 0, beyond
/// `u32` saturates: a caller checks limits, e.g. [`crate::MAX_RATE_MDPS`], before sending).
pub fn mdps_from_dps(rate_dps: f64) -> u32 {
    // `as` saturates and maps NaN to 0; adding ½ rounds a non-negative value (no libm in no_std).
    (rate_dps.abs() * f64::from(MDEG_PER_DEG) + 0.5) as u32
}

/// The direction of a signed rate in °/s (0 counts as counter-clockwise).
pub fn direction_of(rate_dps: f64) -> Direction {
    if rate_dps < 0.0 {
        Direction::Cw
    } else {
        Direction::Ccw
    }
}

/// m°/s → encoder counts per second of a rig with `counts_per_rev`, rounded to nearest, in
/// integers (the firmware's setpoint): 180 000 m°/s is exactly 162 000 cps at 324 000 counts/rev.
pub const fn cps_from_mdps(rate_mdps: u32, counts_per_rev: u32) -> u32 {
    let mdeg_per_rev = 360 * MDEG_PER_DEG as u64;
    ((rate_mdps as u64 * counts_per_rev as u64 + mdeg_per_rev / 2) / mdeg_per_rev) as u32
}

/// Encoder counts (or counts per second) → degrees (per second), for `counts_per_rev`.
pub fn deg_from_counts(counts: f64, counts_per_rev: u32) -> f64 {
    counts * DEG_PER_REV / f64::from(counts_per_rev)
}

/// Degrees (per second) → encoder counts (per second), for `counts_per_rev`.
pub fn counts_from_deg(deg: f64, counts_per_rev: u32) -> f64 {
    deg / DEG_PER_REV * f64::from(counts_per_rev)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ENCODER_COUNTS_PER_REV as CPR;

    #[test]
    fn conversions_are_exact_at_the_paper_speed_and_round_trip() {
        assert_eq!(cps_from_mdps(180_000, CPR), 162_000);
        assert_eq!(cps_from_mdps(360_000, CPR), CPR);
        assert_eq!(cps_from_mdps(1, CPR), 1); // 0.9 rounds up
        assert_eq!(cps_from_mdps(u32::MAX, CPR), 3_865_470_566); // 3 865 470 565.5, no overflow
        assert_eq!(deg_from_counts(162_000.0, CPR), 180.0);
        assert_eq!(counts_from_deg(180.0, CPR), 162_000.0);
        assert_eq!(mdps_from_dps(-180.0), 180_000);
        assert_eq!(mdps_from_dps(0.0004), 0);
        assert_eq!(mdps_from_dps(0.0005), 1);
        assert_eq!(mdps_from_dps(f64::NAN), 0);
        assert_eq!(signed_dps(90_000, Direction::Cw), -90.0);
        assert_eq!(direction_of(-1.0), Direction::Cw);
        assert_eq!(direction_of(0.0), Direction::Ccw);
        for mdps in [1, 999, 180_000, 359_999, 360_000] {
            assert_eq!(mdps_from_dps(dps_from_mdps(mdps)), mdps);
        }
    }
}
