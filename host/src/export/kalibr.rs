//! Kalibr IMU YAML, in the layout of Kalibr's `imu0` block for its `scale-misalignment` IMU model
//! (`kalibr_calibrate_imu_camera --imu-models scale-misalignment`), where the gyro measures
//! `ω_m = M C_gyro_i ω + A a + b` with `M` lower-triangular (scale and misalignment), `C_gyro_i`
//! a rotation, `A` the g-sensitivity and `b` a bias Kalibr estimates online as a random walk
//! (source: Kalibr's `IccSensors.py`, `IccScaledMisalignedImu`: `M_gyro_Dv` has the pattern
//! [[1,0,0],[1,1,0],[1,1,1]], and `addGyroscopeErrorTerms` predicts
//! `M (C_gyro_i C_i_b ω_b) + A (C_gyro_i C_i_b a_b)`; `setIntrisicsMatrices` writes the keys
//! `gyroscopes: {M, A, C_gyro_i}` used here).
//!
//! Mapping (Kalibr works in rad/s from a driver that divides counts by the datasheet
//! sensitivity, so our `K S` enters divided by that sensitivity):
//! - `gyroscopes.M`, `gyroscopes.C_gyro_i`: the factorisation `K S / k_nominal = M · C_gyro_i`
//!   (an RQ decomposition: lower-triangular with positive diagonal times a proper rotation);
//! - `update_rate`: the gyro's ODR, when the file records the gyro settings;
//! - `T_i_b`: identity (the package frame is taken as the IMU frame).
//!
//! - `gyroscopes.A`: the fitted g-sensitivity (°/s per g → rad/s per m/s²), zero when the
//!   calibration's model does not hold it;
//! - `gyroscope_noise_density`, `gyroscope_random_walk`: the Allan analysis of the static
//!   stretch (largest axis: Kalibr takes one value for all three), else stated defaults.
//!
//! The file is the `--imu` file Kalibr's camera-IMU calibration reads (`ImuParameters` in
//! `kalibr_common/ConfigReader.py`: top-level keys, every statistic positive) with the intrinsics
//! block beside them. What does not map: the offsets `v_off` (Kalibr has no fixed bias, it
//! estimates `b` online; given as a comment), the accelerometer fields (placeholders, said so),
//! `rostopic` (a placeholder to edit). Written by `yaml_serde`, its floats made YAML 1.1 (PyYAML).

use super::{sanitise, Export};
use nalgebra::Matrix3;
use std::fmt::Write as _;

/// `N = L C` with `L` lower-triangular (positive diagonal) and `C` a rotation, from the QR
/// decomposition of `Nᵀ = Q R`: `N = Rᵀ Qᵀ`.
pub fn lower_times_rotation(n: &Matrix3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
    let qr = n.transpose().qr();
    let (mut q, mut r) = (qr.q(), qr.r());
    for i in 0..3 {
        if r[(i, i)] < 0.0 {
            r.row_mut(i).neg_mut();
            q.column_mut(i).neg_mut();
        }
    }
    (r.transpose(), q.transpose())
}

/// g, m/s² (standard gravity, CGPM 1901; BIPM SI Brochure), to turn °/s per g into Kalibr's
/// rad/s per m/s².
const STANDARD_GRAVITY: f64 = 9.806_65;

/// Placeholders for the accelerometer, which this rig does not measure but Kalibr requires
/// (positive): the example IMU of Kalibr's wiki ("YAML formats": an ADIS16448), m/s²/√Hz and
/// m/s³/√Hz. The header says to replace them with the user's accelerometer's figures.
const ACCEL_NOISE_DENSITY_PLACEHOLDER: f64 = 1.86e-3;
const ACCEL_RANDOM_WALK_PLACEHOLDER: f64 = 4.33e-4;

/// Gyro rate random walk when the calibration measured none (no static stretch, or one too
/// short for the +½ slope, where the fit gives 0, which Kalibr refuses): 0.005 °/s/√s, the top of
/// the MEMS range the simulator's `bias_random_walk` effect cites, in rad/s²/√Hz (a pessimistic
/// figure is the safe side for Kalibr's bias model).
const GYRO_RANDOM_WALK_UNMEASURED_DPS_PER_SQRT_S: f64 = 0.005;

/// The update rate when the calibration file records no gyro settings: the rig's default ODR.
const DEFAULT_UPDATE_RATE_HZ: f64 = 800.0;

/// What Kalibr's `ImuParameters` (kalibr_common/ConfigReader.py) reads from the `--imu` file,
/// every field required, the four statistics positive: `rostopic` (a string), `update_rate`,
/// `accelerometer_noise_density`, `accelerometer_random_walk`, `gyroscope_noise_density`,
/// `gyroscope_random_walk`; then the intrinsics block of its `scale-misalignment` model, in the
/// keys Kalibr writes for it (`model`, `time_offset`, `T_i_b`, `gyroscopes: {M, A, C_gyro_i}`),
/// which its reader passes over. Field order is the file's order.
#[derive(serde::Serialize)]
#[allow(non_snake_case)] // Kalibr's key names.
struct ImuYaml {
    rostopic: &'static str,
    update_rate: f64,
    accelerometer_noise_density: f64,
    accelerometer_random_walk: f64,
    gyroscope_noise_density: f64,
    gyroscope_random_walk: f64,
    model: &'static str,
    time_offset: f64,
    T_i_b: [[f64; 4]; 4],
    gyroscopes: Gyroscopes,
}

#[derive(serde::Serialize)]
#[allow(non_snake_case)]
struct Gyroscopes {
    M: [[f64; 3]; 3],
    A: [[f64; 3]; 3],
    C_gyro_i: [[f64; 3]; 3],
}

#[cfg(test)]
#[test]
fn ryus_scientific_forms_become_yaml_1_1_floats() {
    let yaml = "a: 1e-7\nb: -1.5e-7\n- - 2e16\n  - -3.25e20\nc: 0.0005\nd: /imu0\ne: scale-misalignment\nf: 1e\n";
    assert_eq!(
        yaml_1_1_floats(yaml),
        "a: 1.0e-7\nb: -1.5e-7\n- - 2.0e+16\n  - -3.25e+20\nc: 0.0005\nd: /imu0\ne: scale-misalignment\nf: 1e\n"
    );
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

/// `yaml_serde` writes YAML 1.2 floats (Rust's shortest round trip, `ryu`): `1e-7`, `1.5e-7`,
/// `1e16`. Kalibr reads with PyYAML, whose YAML 1.1 float needs a decimal point and a signed
/// exponent, and takes those forms for strings. Every other form `ryu` writes (`0.0`, `1.25`,
/// `0.0005`) is a float to both. So the scientific plain scalars are rewritten `1.0e-7`,
/// `1.5e-7`, `1.0e+16`: the same number in either version of YAML. Hand-written because no
/// maintained serde YAML crate offers YAML 1.1 output.
fn yaml_1_1_floats(yaml: &str) -> String {
    let mut out = String::with_capacity(yaml.len() + 64);
    for line in yaml.lines() {
        // Block style, one scalar per line, last on it (`key: 1e-7`, `- 1e-7`, `- - 1e-7`).
        let (head, scalar) = line.rsplit_once(' ').map_or(("", line), |(h, s)| (h, s));
        let sep = if head.is_empty() && !line.contains(' ') { "" } else { " " };
        let (sign, body) = scalar.strip_prefix('-').map_or(("", scalar), |b| ("-", b));
        let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
        match body.split_once('e') {
            Some((mant, exp))
                if mant.split_once('.').map_or(digits(mant), |(i, f)| digits(i) && digits(f))
                    && digits(exp.strip_prefix('-').unwrap_or(exp)) =>
            {
                let point = if mant.contains('.') { "" } else { ".0" };
                let plus = if exp.starts_with('-') { "" } else { "+" };
                let _ = writeln!(out, "{head}{sep}{sign}{mant}{point}e{plus}{exp}");
            }
            _ => {
                let _ = writeln!(out, "{line}");
            }
        }
    }
    out
}

/// Renders the YAML: a header of comments (what is mapped, what is a placeholder), then the
/// document `yaml_serde` writes.
pub fn render(e: &Export) -> String {
    let nominal = 1e6 / f64::from(e.calibration.full_scale.udps_per_lsb());
    let n = Matrix3::from_fn(|i, j| e.calibration.m_counts_per_dps[i][j] / nominal);
    let (l, c) = lower_times_rotation(&n);
    let rad = std::f64::consts::PI / 180.0;
    // ARW °/√h → °/√s (÷ 60) = °/s/√Hz, then rad; RRW °/h/√h → °/s/√s (÷ 3600·60), then rad.
    // The largest axis: Kalibr takes one value for all three.
    let largest = |f: fn(&crate::allan::AxisNoise) -> f64| {
        e.noise.as_ref().map(|n| n.axes.iter().map(f).fold(0.0, f64::max)).filter(|v| *v > 0.0)
    };
    let noise_density = largest(|a| a.arw_deg_per_sqrt_h).map(|v| v / 60.0 * rad);
    let random_walk = largest(|a| a.rrw_deg_per_h_per_sqrt_h).map(|v| v / 216_000.0 * rad);
    // g-sensitivity: °/s per g of the rate in the package frame → Kalibr's A, rad/s per m/s²,
    // acting on the specific force in the IMU frame (the package frame here).
    let a = e.g_sensitivity_dps_per_g.map(|g| Matrix3::from_fn(|i, j| g[i][j] * rad / STANDARD_GRAVITY));
    let doc = ImuYaml {
        rostopic: "/imu0",
        update_rate: e.gyro.map_or(DEFAULT_UPDATE_RATE_HZ, |g| f64::from(g.odr.hz())),
        accelerometer_noise_density: ACCEL_NOISE_DENSITY_PLACEHOLDER,
        accelerometer_random_walk: ACCEL_RANDOM_WALK_PLACEHOLDER,
        gyroscope_noise_density: noise_density.unwrap_or(crate::sim::NOISE_DENSITY_DPS_PER_SQRT_HZ * rad),
        gyroscope_random_walk: random_walk.unwrap_or(GYRO_RANDOM_WALK_UNMEASURED_DPS_PER_SQRT_S * rad),
        model: "scale-misalignment",
        time_offset: 0.0,
        T_i_b: std::array::from_fn(|i| std::array::from_fn(|j| if i == j { 1.0 } else { 0.0 })),
        gyroscopes: Gyroscopes { M: rows(&l), A: rows(&a.unwrap_or_else(Matrix3::zeros)), C_gyro_i: rows(&c) },
    };
    let mut o = String::new();
    let mut line = |s: String| {
        o.push_str("# ");
        o.push_str(&s);
        o.push('\n');
    };
    line(format!(
        "Kalibr IMU configuration (scale-misalignment model) of gyro {}, calibrated {}.",
        sanitise(e.serial()),
        sanitise(e.date())
    ));
    line(format!("Generated by `host export --format kalibr` (host {}).", crate::provenance::HOST_VERSION));
    line("For kalibr_calibrate_imu_camera --imu THIS_FILE --imu-models scale-misalignment.".into());
    line(format!("Rates in rad/s after dividing counts by the datasheet sensitivity {nominal} counts/(deg/s)."));
    line(format!(
        "Not mapped: offsets (Kalibr estimates its bias online); here, counts: [{:.6}, {:.6}, {:.6}].",
        e.calibration.offset_counts[0], e.calibration.offset_counts[1], e.calibration.offset_counts[2]
    ));
    line("rostopic: edit to the topic your IMU driver publishes.".into());
    if e.gyro.is_none() {
        line(format!("update_rate: the file records no gyro settings; {DEFAULT_UPDATE_RATE_HZ} Hz assumed (the rig's default ODR)."));
    }
    line("accelerometer_*: NOT MEASURED by this rig; placeholders (Kalibr's example IMU): replace with your accelerometer's.".into());
    line(match noise_density {
        Some(_) => "gyroscope_noise_density: the static stretch's ARW, largest axis, rad/s/sqrt(Hz).".into(),
        None => {
            "gyroscope_noise_density: not measured (no static stretch): the L3G4200D datasheet's 0.03 deg/s/sqrt(Hz)."
                .into()
        }
    });
    line(match random_walk {
        Some(_) => "gyroscope_random_walk: the static stretch's RRW, largest axis, rad/s^2/sqrt(Hz).".into(),
        None => format!("gyroscope_random_walk: not measured: {GYRO_RANDOM_WALK_UNMEASURED_DPS_PER_SQRT_S} deg/s/sqrt(s), the top of the MEMS range (pessimistic)."),
    });
    line(match a {
        Some(_) => "gyroscopes.A: the fitted g-sensitivity, rad/s per m/s^2.".into(),
        None => "gyroscopes.A: zero: g-sensitivity not in this calibration's model.".into(),
    });
    let body = yaml_serde::to_string(&doc).expect("plain numbers and strings serialise");
    o.push_str(&yaml_1_1_floats(&body));
    o
}
