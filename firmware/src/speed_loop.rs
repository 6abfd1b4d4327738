//! Base-table speed loop: a setpoint ramp, feed-forward, and a PI with anti-windup, run at a
//! fixed rate from the encoder count.
//!
//! The integral is kept as a *position* error in counts — the counts the table should have
//! travelled at the ramped setpoint minus the counts it did travel — so encoder quantisation
//! never accumulates: 1 count per period is 1000 cps (0.6 % of 0.5 Hz) in a single-period
//! speed, but the integral stays exact, and the mean speed converges to the setpoint.
//!
//! Gains are designed on a first-order model of the drive (maxon RE 30 through a gearhead, 66:1
//! on the prototype, see [`design`] and [`Drive`]): feed-forward `1/K`, PI zero on the
//! mechanical pole, crossover 15 Hz. The host sets the gearhead, load inertia and supply of its
//! rig with `ConfigureDrive` ([`Gains::for_drive`]).

/// Loop rate, Hz: one update per TIM3 period. 15 Hz crossover × ~65 leaves the sampling delay
/// and the 1-count measurement noise (filtered by the mechanics) harmless.
pub const LOOP_HZ: u32 = 1_000;

/// The drive model behind the gains. Values from maxon's RE 30 Ø30 mm 60 W 24 V data
/// (order no. 310007) and the rig geometry in EXCITER.md; the gearhead ratio and table inertia
/// are design assumptions (the paper does not give them).
pub mod design {
    /// Bridge supply, V: the motor's nominal voltage.
    pub const VBUS_V: f32 = 24.0;
    /// Back-EMF constant, V·s/rad (= torque constant 25.9 mNm/A).
    pub const KE_VS_PER_RAD: f32 = 25.9e-3;
    /// Terminal resistance, Ω.
    pub const R_OHM: f32 = 0.611;
    /// Gearhead reduction (maxon GP 32 C, 66:1): 0.5 Hz needs ≈ 23 % duty at 24 V.
    pub const GEAR_RATIO: f32 = 66.0;
    /// Rotor inertia (33.5 g·cm²) reflected to the table plus ≈ 0.012 kg·m² of tables, gears
    /// and counterweight, kg·m².
    pub const J_TABLE_KGM2: f32 = 0.012 + 33.5e-7 * GEAR_RATIO * GEAR_RATIO;
    /// Encoder counts per radian of the base table.
    pub const COUNTS_PER_RAD: f32 = protocol::ENCODER_COUNTS_PER_REV as f32 / (2.0 * core::f32::consts::PI);
    /// Steady-state speed per unit duty, counts/s: `VBUS / (KE · N)` rad/s at the table.
    pub const K_CPS_PER_DUTY: f32 = VBUS_V / (KE_VS_PER_RAD * GEAR_RATIO) * COUNTS_PER_RAD;
    /// Mechanical time constant with the table load, s: `R · J / (KE · N)²` ≈ 5.6 ms.
    pub const TAU_S: f32 = R_OHM * J_TABLE_KGM2 / (KE_VS_PER_RAD * GEAR_RATIO * KE_VS_PER_RAD * GEAR_RATIO);
    /// Loop crossover, rad/s: 15 Hz. In the simulated plant 25 and 35 Hz gave more ripple (the
    /// 1-count encoder flicker amplified) and no better rejection of the 6 Hz gear cogging.
    pub const CROSSOVER_RAD_S: f32 = 2.0 * core::f32::consts::PI * 15.0;
}

/// A drive train, in the design's units ([`protocol::DriveConfig`] on the wire).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drive {
    /// Gearhead reduction, motor turns per table turn.
    pub gear_ratio: f32,
    /// Inertia the gearhead turns, at the table, kg·m² (without the rotor).
    pub load_inertia_kgm2: f32,
    /// Bridge supply, V.
    pub supply_v: f32,
}

/// The RE 30's rotor inertia, kg·m² (maxon #310007: 33.5 g·cm²).
pub const ROTOR_INERTIA_KGM2: f32 = 33.5e-7;

impl Drive {
    /// The prototype ([`design`]).
    pub const PROTOTYPE: Drive =
        Drive { gear_ratio: design::GEAR_RATIO, load_inertia_kgm2: 0.012, supply_v: design::VBUS_V };

    /// From the wire's integers.
    pub fn from_config(c: &protocol::DriveConfig) -> Self {
        Drive {
            // Divisions, correctly rounded: 24 000 mV is exactly 24 V.
            gear_ratio: c.gear_ratio_milli as f32 / 1e3,
            load_inertia_kgm2: c.load_inertia_gcm2 as f32 / 1e7,
            supply_v: c.supply_mv as f32 / 1e3,
        }
    }

    /// Total inertia at the table: the load plus the rotor reflected through the gearhead.
    pub const fn inertia_kgm2(&self) -> f32 {
        self.load_inertia_kgm2 + ROTOR_INERTIA_KGM2 * self.gear_ratio * self.gear_ratio
    }

    /// Steady-state table speed per unit duty, counts/s: `V / (KE · N)` rad/s.
    pub const fn k_cps_per_duty(&self) -> f32 {
        self.supply_v / (design::KE_VS_PER_RAD * self.gear_ratio) * design::COUNTS_PER_RAD
    }

    /// Mechanical time constant, s: `R · J / (KE · N)²`.
    pub const fn tau_s(&self) -> f32 {
        let ke_n = design::KE_VS_PER_RAD * self.gear_ratio;
        design::R_OHM * self.inertia_kgm2() / (ke_n * ke_n)
    }
}

/// Controller gains. Duty is a signed fraction of the bridge supply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// Feed-forward, duty per count/s of setpoint.
    pub kff: f32,
    /// Proportional, duty per count/s of speed error.
    pub kp: f32,
    /// Integral, duty per count of accumulated position error.
    pub ki: f32,
    /// Output limit, |duty|: the bridge needs some off-time to refresh its bootstrap supply.
    pub duty_limit: f32,
    /// Setpoint ramp, counts/s per second.
    pub ramp_cps_per_s: f32,
}

impl Gains {
    /// Gains from [`design`]: crossover `ωc` with the PI zero cancelling the mechanical pole.
    /// The ramp, 90 °/s² (81 000 cps/s), reaches 0.5 Hz in 2 s with ≈ 19 mN·m of accelerating
    /// torque on the table, gentle on the contactless magnetic gears.
    pub const RE30_GP32: Gains = Gains::for_drive(&Drive::PROTOTYPE);

    /// Gains for `drive`: the same design (crossover [`design::CROSSOVER_RAD_S`], PI zero on the
    /// mechanical pole, feed-forward `1/K`), the same ramp and duty limit.
    pub const fn for_drive(drive: &Drive) -> Gains {
        let k = drive.k_cps_per_duty();
        let tau = drive.tau_s();
        let kp = design::CROSSOVER_RAD_S * tau / k;
        Gains { kff: 1.0 / k, kp, ki: kp / tau, duty_limit: 0.95, ramp_cps_per_s: 81_000.0 }
    }
}

/// Ramp + PI state. Call [`SpeedLoop::update_over`] once per period with the period measured
/// (nominally [`LOOP_HZ`] times a second).
#[derive(Debug, Clone)]
pub struct SpeedLoop {
    gains: Gains,
    target_cps: f32,
    setpoint_cps: f32,
    integral_counts: f32,
    duty: f32,
}

impl SpeedLoop {
    /// A loop at rest.
    pub const fn new(gains: Gains) -> Self {
        Self { gains, target_cps: 0.0, setpoint_cps: 0.0, integral_counts: 0.0, duty: 0.0 }
    }

    /// Where the ramp is heading, counts/s (signed).
    pub fn set_target(&mut self, target_cps: i32) {
        self.target_cps = target_cps as f32;
    }

    /// Motor off: forget the ramp and the integral, so a restart begins from rest.
    pub fn reset(&mut self) {
        *self = Self::new(self.gains);
    }

    /// New gains, from rest (the rig changes them only between runs).
    pub fn set_gains(&mut self, gains: Gains) {
        *self = Self::new(gains);
    }

    /// Gains in force.
    pub fn gains(&self) -> Gains {
        self.gains
    }

    /// One nominal period (1 / [`LOOP_HZ`]): [`Self::update_over`].
    pub fn update(&mut self, delta_counts: i32) -> f32 {
        self.update_over(delta_counts, 1.0 / LOOP_HZ as f32)
    }

    /// One period of `period_s` seconds, as measured: `delta_counts` is how far the encoder
    /// moved in it. A late or early tick changes the expected travel, not the speed error.
    /// Returns the duty to apply, signed, within `±duty_limit`.
    pub fn update_over(&mut self, delta_counts: i32, period_s: f32) -> f32 {
        let g = &self.gains;
        // The measured period ran at the previous setpoint: compare against that one.
        let travel_error = self.setpoint_cps * period_s - delta_counts as f32;
        let error_cps = travel_error / period_s;

        let step = g.ramp_cps_per_s * period_s;
        self.setpoint_cps += crate::limit(self.target_cps - self.setpoint_cps, step);
        let output = |integral: f32| g.kff * self.setpoint_cps + g.kp * error_cps + g.ki * integral;

        let integral = self.integral_counts + travel_error;
        let unclamped = output(integral);
        // Conditional integration: while saturated, do not integrate further into saturation.
        if unclamped.abs() <= g.duty_limit || unclamped.signum() != travel_error.signum() {
            self.integral_counts = integral;
        }
        self.duty = crate::limit(output(self.integral_counts), g.duty_limit);
        self.duty
    }

    /// Where the ramp is heading, counts/s (signed): 0 at rest, after a Stop or a trip.
    pub fn target_cps(&self) -> i32 {
        self.target_cps as i32
    }

    /// Ramped setpoint, counts/s (signed).
    pub fn setpoint_cps(&self) -> i32 {
        self.setpoint_cps as i32
    }

    /// The ramp has reached the target.
    pub fn at_target(&self) -> bool {
        self.setpoint_cps == self.target_cps
    }

    /// Last duty returned.
    pub fn duty(&self) -> f32 {
        self.duty
    }

    /// Accumulated position error, counts.
    pub fn integral_counts(&self) -> f32 {
        self.integral_counts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn design_numbers_match_the_datasheet_arithmetic() {
        // 24 V / (25.9 mV·s/rad · 66) = 14.04 rad/s at the table, × 51 566 counts/rad.
        assert!((design::K_CPS_PER_DUTY - 724_000.0).abs() < 1_000.0);
        assert!((design::TAU_S - 5.6e-3).abs() < 0.1e-3);
    }

    #[test]
    fn the_prototype_drive_gives_the_design_gains() {
        let d = Drive::PROTOTYPE;
        assert_eq!(d.k_cps_per_duty(), design::K_CPS_PER_DUTY);
        assert!((d.tau_s() / design::TAU_S - 1.0).abs() < 1e-6);
        assert_eq!(Drive::from_config(&protocol::DriveConfig::PROTOTYPE), d);
        // Half the ratio: twice the speed per duty; the rotor's share of J drops four-fold.
        let half = Drive { gear_ratio: 33.0, ..d };
        assert!((half.k_cps_per_duty() / d.k_cps_per_duty() - 2.0).abs() < 1e-6);
        let j = 0.012 + 33.5e-7 * 33.0 * 33.0;
        assert!((half.inertia_kgm2() - j).abs() < 1e-9);
        let g = Gains::for_drive(&half);
        assert!((g.kff * half.k_cps_per_duty() - 1.0).abs() < 1e-6);
        assert!((g.kp / g.ki - half.tau_s()).abs() < 1e-9, "PI zero on the mechanical pole");
    }

    #[test]
    fn ramp_is_rate_limited_in_both_directions() {
        let mut l = SpeedLoop::new(Gains::RE30_GP32);
        l.set_target(162_000);
        l.update(0);
        assert_eq!(l.setpoint_cps(), 81);
        for _ in 0..1999 {
            l.update(0);
        }
        // 2000 periods × 81 cps = 162 000: exactly at the target, not beyond.
        assert_eq!(l.setpoint_cps(), 162_000);
        assert!(l.at_target());
        l.set_target(-162_000);
        l.update(0);
        assert_eq!(l.setpoint_cps(), 162_000 - 81);
    }

    /// A tick 30 % late (interrupt latency, a long higher-priority task) finds 30 % more counts:
    /// with Δcount/Δt that is no speed error, where dividing by the nominal 1 ms made it one.
    #[test]
    fn a_late_tick_is_not_a_speed_error() {
        let run_at_speed = || {
            let mut l = SpeedLoop::new(Gains::RE30_GP32);
            l.set_target(162_000);
            for _ in 0..2_000 {
                l.update(162);
            }
            assert!(l.at_target());
            l
        };
        let mut nominal = run_at_speed();
        let mut late = run_at_speed();
        let on_time = nominal.update_over(162, 1e-3);
        let after_late = late.update_over(211, 1.3e-3); // 162 000 cps × 1.3 ms = 210.6 counts
        assert!((after_late - on_time).abs() < 1e-3, "duty {after_late} after a late tick vs {on_time}");
        assert!((late.integral_counts() - nominal.integral_counts()).abs() < 1.0);
    }

    #[test]
    fn saturated_output_does_not_wind_up() {
        let limit = Gains::RE30_GP32.duty_limit;
        let mut l = SpeedLoop::new(Gains::RE30_GP32);
        l.set_target(162_000);
        // Stalled encoder: the output climbs into saturation.
        let mut periods = 0;
        while l.update(0) < limit {
            periods += 1;
            assert!(periods < 5_000, "never saturated");
        }
        let at_saturation = l.integral_counts();
        for _ in 0..5_000 {
            assert_eq!(l.update(0), limit);
        }
        // Conditional integration froze the integral where saturation began; a naive one
        // would hold the whole 5 s ramp-and-hold backlog, ≈ 710 000 counts.
        assert_eq!(l.integral_counts(), at_saturation);
        // The encoder now runs 8 counts per period faster than the setpoint: the integral
        // unwinds at once and the output leaves saturation within (backlog above the
        // saturation point) / 8 periods — a naive integrator would need ≈ 88 000.
        l.update(170);
        assert!(l.integral_counts() < at_saturation);
        let mut periods = 1;
        while l.update(170) >= limit {
            periods += 1;
            assert!(periods < 1_000, "still saturated");
        }
    }

    #[test]
    fn steady_state_at_setpoint_holds_feed_forward_duty() {
        let mut l = SpeedLoop::new(Gains::RE30_GP32);
        l.set_target(-162_000);
        // A table that follows the ramp exactly, read through a 1-count encoder.
        let mut position = 0.0f64;
        let mut count = 0i64;
        let mut delta = 0;
        for _ in 0..3_000 {
            l.update(delta);
            position += f64::from(l.setpoint_cps()) / f64::from(LOOP_HZ);
            delta = (position.floor() as i64 - count) as i32;
            count += i64::from(delta);
        }
        let ff = -162_000.0 / design::K_CPS_PER_DUTY;
        // Residue: one count of quantisation through kp (1000 cps) and ki (1 count).
        let tolerance = Gains::RE30_GP32.kp * 1_000.0 + Gains::RE30_GP32.ki * 2.0;
        assert!((l.duty() - ff).abs() < tolerance, "duty {} vs {ff}", l.duty());
    }
}
