//! The photo-interrupter on the sensor table and the shield plate on the base (EXCITER.md): the
//! beam is blocked (level 1) while θ2, modulo a turn, is inside the plate's span.

use core::f64::consts::TAU;
use libm::floor;

/// Plate geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhotoInterrupter {
    /// θ2 where the plate begins, rad.
    pub plate_start_rad: f64,
    /// Angular width of the plate, rad (10 mm at 57 mm radius ≈ 10°, assumed).
    pub plate_width_rad: f64,
}

/// A change of level within a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossing {
    /// Fraction of the step, in [0, 1], at which the level changed.
    pub fraction: f64,
    /// Level after the change.
    pub level: bool,
}

impl PhotoInterrupter {
    /// Beam blocked at sensor-table angle `theta2_rad`.
    pub fn blocked(&self, theta2_rad: f64) -> bool {
        let phase = theta2_rad - self.plate_start_rad;
        phase - TAU * floor(phase / TAU) < self.plate_width_rad
    }

    /// The level change, if any, while θ2 moves linearly from `from_rad` to `to_rad`. Steps are
    /// far shorter than the plate, so there is at most one.
    pub fn crossing(&self, from_rad: f64, to_rad: f64) -> Option<Crossing> {
        let before = self.blocked(from_rad);
        let after = self.blocked(to_rad);
        if before == after {
            return None;
        }
        // The boundary crossed: the plate's leading or trailing edge nearest the path.
        let boundary = |offset: f64| {
            let b = self.plate_start_rad + offset;
            let lo = from_rad.min(to_rad);
            b + TAU * libm::ceil((lo - b) / TAU)
        };
        let edges = [boundary(0.0), boundary(self.plate_width_rad)];
        let span = to_rad - from_rad;
        let fraction =
            edges.iter().map(|&e| (e - from_rad) / span).filter(|f| (0.0..=1.0).contains(f)).fold(f64::NAN, f64::min);
        Some(Crossing { fraction: if fraction.is_nan() { 1.0 } else { fraction }, level: after })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PLATE: PhotoInterrupter = PhotoInterrupter { plate_start_rad: 1.0, plate_width_rad: 0.2 };

    #[test]
    fn level_follows_the_plate_every_turn() {
        assert!(!PLATE.blocked(0.99));
        assert!(PLATE.blocked(1.0));
        assert!(PLATE.blocked(1.0 + 5.0 * TAU + 0.1));
        assert!(!PLATE.blocked(1.21 - 3.0 * TAU));
    }

    #[test]
    fn crossings_are_located_inside_the_step_in_both_directions() {
        let c = PLATE.crossing(0.9 + TAU, 1.1 + TAU).unwrap();
        assert!((c.fraction - 0.5).abs() < 1e-9 && c.level);
        let c = PLATE.crossing(1.25, 1.15).unwrap();
        assert!((c.fraction - 0.5).abs() < 1e-9 && c.level);
        let c = PLATE.crossing(1.15, 1.25).unwrap();
        assert!((c.fraction - 0.5).abs() < 1e-9 && !c.level);
        assert_eq!(PLATE.crossing(0.5, 0.6), None);
    }
}
