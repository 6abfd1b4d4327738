//! DC motor, gearhead and tables as one rigid rotor, seen at the base-table axis.
//!
//! `J ω' = N·kt·i − τ_coulomb·sgn ω − b·ω − τ_cog·sin(12 θ2) − τ_unb·sin θ2 − τ_load`, with the
//! armature current at its steady state `i = (V − ke·N·ω) / R`: the RE 30's electrical time
//! constant L/R = 0.119 mH / 0.611 Ω = 0.19 ms is far below the 1 ms loop period.

use libm::sin;

/// Drive and load parameters, SI units at the table axis unless named otherwise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveParams {
    /// Bridge supply, V.
    pub vbus_v: f64,
    /// Terminal resistance, Ω (RE 30 #310007: 0.611 Ω).
    pub r_ohm: f64,
    /// Torque constant = back-EMF constant, N·m/A (RE 30 #310007: 25.9 mN·m/A).
    pub kt_nm_per_a: f64,
    /// Gearhead reduction (assumed GP 32 C 66:1).
    pub gear_ratio: f64,
    /// Total inertia at the table: tables + counterweight + gears, plus the rotor's 33.5 g·cm²
    /// times N², kg·m².
    pub j_kgm2: f64,
    /// Dry friction at the table, N·m: the RE 30's no-load current (73.9 mA · kt = 1.91 mN·m)
    /// through the gearhead (× 66) plus ≈ 20 mN·m of table bearings.
    pub coulomb_nm: f64,
    /// Viscous friction at the table, N·m·s/rad (assumed).
    pub viscous_nm_s: f64,
    /// Magnetic-gear cogging amplitude, N·m (assumed; 12-pole gears, EXCITER.md).
    pub cogging_nm: f64,
    /// Poles of the magnetic gears: cogging period is 1/12 turn of θ2.
    pub cogging_poles: f64,
    /// Residual unbalance of the sensor table about z2, passed through the 1:1 gear, N·m
    /// (assumed: 0.3 kg off-centre by 0.5 mm).
    pub unbalance_nm: f64,
}

impl DriveParams {
    /// The prototype as modelled.
    pub const PROTOTYPE: DriveParams = DriveParams {
        vbus_v: 24.0,
        r_ohm: 0.611,
        kt_nm_per_a: 25.9e-3,
        gear_ratio: 66.0,
        j_kgm2: 0.012 + 33.5e-7 * 66.0 * 66.0,
        coulomb_nm: 1.91e-3 * 66.0 + 0.020,
        viscous_nm_s: 5.0e-3,
        cogging_nm: 0.020,
        cogging_poles: 12.0,
        unbalance_nm: 0.3 * 9.81 * 0.5e-3,
    };
}

/// Motor state and the forces on it.
#[derive(Debug, Clone)]
pub struct Motor {
    /// Parameters.
    pub params: DriveParams,
    /// Base-table angle θ1, rad.
    pub theta_rad: f64,
    /// Base-table speed θ1', rad/s.
    pub omega_rad_s: f64,
    /// Extra load torque opposing positive rotation, N·m (test disturbance).
    pub load_nm: f64,
    /// The rotor is mechanically blocked.
    pub locked: bool,
}

impl Motor {
    /// At rest at angle 0.
    pub fn new(params: DriveParams) -> Self {
        Self { params, theta_rad: 0.0, omega_rad_s: 0.0, load_nm: 0.0, locked: false }
    }

    /// Armature current for terminal voltage `volts` (None: bridge off, motor coasting).
    pub fn current_a(&self, volts: Option<f64>) -> f64 {
        let p = &self.params;
        match volts {
            Some(v) => (v - p.kt_nm_per_a * p.gear_ratio * self.omega_rad_s) / p.r_ohm,
            None => 0.0,
        }
    }

    /// Advances by `dt_s` (semi-implicit Euler; `dt_s` ≪ the 5.6 ms mechanical time constant)
    /// with `volts` across the terminals. `theta2_rad` is the sensor-table angle for the
    /// position-dependent torques.
    pub fn step(&mut self, dt_s: f64, volts: Option<f64>, theta2_rad: f64) {
        if self.locked {
            self.omega_rad_s = 0.0;
            return;
        }
        let p = self.params;
        let drive = p.gear_ratio * p.kt_nm_per_a * self.current_a(volts)
            - p.viscous_nm_s * self.omega_rad_s
            - p.cogging_nm * sin(p.cogging_poles * theta2_rad)
            - p.unbalance_nm * sin(theta2_rad)
            - self.load_nm;
        let omega = self.omega_rad_s;
        if omega == 0.0 && drive.abs() <= p.coulomb_nm {
            return; // stiction holds
        }
        let friction = if omega != 0.0 { p.coulomb_nm * omega.signum() } else { p.coulomb_nm * drive.signum() };
        let next = omega + dt_s * (drive - friction) / p.j_kgm2;
        // Dry friction stops the rotor; it never reverses it.
        self.omega_rad_s = if omega != 0.0 && next.signum() != omega.signum() { 0.0 } else { next };
        self.theta_rad += dt_s * self.omega_rad_s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(m: &mut Motor, volts: Option<f64>, seconds: f64) {
        let dt = 20e-6;
        for _ in 0..(seconds / dt) as usize {
            let th = m.theta_rad;
            m.step(dt, volts, th);
        }
    }

    #[test]
    fn no_load_speed_matches_the_speed_constant() {
        // Without load torques the table runs at V / (ke · N): 24 V → 14.04 rad/s.
        let mut m = Motor::new(DriveParams {
            coulomb_nm: 0.0,
            viscous_nm_s: 0.0,
            cogging_nm: 0.0,
            unbalance_nm: 0.0,
            ..DriveParams::PROTOTYPE
        });
        run(&mut m, Some(24.0), 0.2);
        assert!((m.omega_rad_s - 24.0 / (25.9e-3 * 66.0)).abs() < 1e-3);
    }

    #[test]
    fn friction_holds_at_low_voltage_and_stops_a_coasting_rotor() {
        let mut m = Motor::new(DriveParams::PROTOTYPE);
        // Breakaway needs 0.146 N·m at the table: 85 mA, 52 mV.
        run(&mut m, Some(0.04), 0.1);
        assert_eq!(m.omega_rad_s, 0.0);
        run(&mut m, Some(6.0), 0.2);
        assert!(m.omega_rad_s > 3.0);
        run(&mut m, None, 5.0);
        assert_eq!(m.omega_rad_s, 0.0);
    }
}
