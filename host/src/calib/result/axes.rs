//! The gyro's three sensing axes as the calibration names them, and the one fact about a raw
//! count that every pass needs: whether it sits on a rail.

/// Axis names in report order.
pub const AXES: [char; 3] = ['x', 'y', 'z'];

/// A raw count at either rail: the true rate may lie beyond it (L3G4200D outputs saturate at
/// the i16 limits, datasheet §2.1 "measurement range"), so the sample says nothing about that
/// axis and is left out of it.
#[inline]
pub fn is_clipped(count: i16) -> bool {
    count == i16::MAX || count == i16::MIN
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_rails_are_clipped() {
        assert!(is_clipped(i16::MAX) && is_clipped(i16::MIN));
        assert!(!is_clipped(i16::MAX - 1) && !is_clipped(i16::MIN + 1) && !is_clipped(0));
    }
}
