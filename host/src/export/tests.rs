//! The exports compiled and run: the C header with `cc`, the Rust module with `rustc`, each fed
//! every int16 value on every axis and compared with [`Calibration::apply`] (what `host apply`
//! prints), at ±500 and at ±2000 °/s.

use super::*;
use crate::provenance::{CaptureDigest, Identity, Provenance, HOST_VERSION};
use protocol::{FullScale, GyroConfig};
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// A tilted, scaled, offset sensor at ±500 °/s (tilts ≈ 1°, sensitivities within 2 % of the
/// datasheet's 57.14 counts/(°/s), fractional offsets), with provenance.
fn sample_export() -> Export {
    let m = [[57.3, 0.9, -0.4], [-0.6, 56.8, 1.1], [0.3, -0.7, 58.0]];
    export_of(FullScale::Dps500, m, [12.375, -30.5, 4.25])
}

/// The same kind of sensor at ±2000 °/s, the L3G4200D's widest range (70 m°/s per count, i.e.
/// 14.29 counts/(°/s): the int16 range spans ±2340 °/s), with offsets near the datasheet's
/// ±75 °/s zero-rate level.
fn wide_export() -> Export {
    let m = [[14.33, 0.22, -0.1], [-0.15, 14.2, 0.27], [0.08, -0.18, 14.5]];
    export_of(FullScale::Dps2000, m, [1040.375, -987.5, 12.25])
}

fn export_of(fs: FullScale, m: [[f64; 3]; 3], off: [f64; 3]) -> Export {
    Export::from_json(&export_json(fs, m, off)).unwrap()
}

/// `calibrate`'s JSON of a calibration with provenance (sensor G-0042, ±`fs`, ODR 800 Hz).
pub(super) fn export_json(fs: FullScale, m: [[f64; 3]; 3], off: [f64; 3]) -> String {
    let cal = Calibration::new("linear: v = K S ω + v_off".into(), fs, m, off).unwrap();
    let prov = Provenance {
        identity: Identity {
            sensor_serial: Some("G-0042".into()),
            operator: Some("ada".into()),
            rig: Some("rig-1".into()),
        },
        calibrated_utc: "2026-11-23T05:00:00Z".into(),
        session_started_utc: None,
        host_version: HOST_VERSION.into(),
        rig_firmware: Some("0.1.0".into()),
        gyro: Some(GyroConfig { full_scale: fs, ..GyroConfig::DEFAULT }),
        captures: vec![CaptureDigest { file: "a.cap".into(), bytes: 3, sha256: "ab".into() }],
        die_temperature: None,
    };
    prov.attach(serde_json::from_str(&cal.to_json()).unwrap()).to_string()
}

/// Raw readings over the whole int16 range: every value of each axis in turn (65 536 × 3), the
/// other two axes drawn uniformly from all of int16, and the eight corners. Fixed seed.
pub(super) fn readings() -> Vec<[i16; 3]> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let mut v: Vec<[i16; 3]> =
        (0..8).map(|c| std::array::from_fn(|i| if c >> i & 1 == 1 { i16::MAX } else { i16::MIN })).collect();
    for axis in 0..3 {
        for x in i16::MIN..=i16::MAX {
            let mut r: [i16; 3] = [rng.random(), rng.random(), rng.random()];
            r[axis] = x;
            v.push(r);
        }
    }
    v
}

/// A fresh directory for one test, removed when dropped (also when the test fails).
pub(super) fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new().prefix(&format!("host-export-{name}-")).tempdir().expect("temporary directory")
}

/// What an export program prints per reading: the float result, then hi and lo of the split.
struct Output {
    rate: [f32; 3],
    hi: [f32; 3],
    lo: [f32; 3],
}

/// Runs `exe`, feeding one `x y z` line per reading; each output line holds the nine floats'
/// bit patterns in hex (exact, and quick to read back).
fn run_on_readings(exe: &Path, raw: &[[i16; 3]]) -> Vec<Output> {
    use std::io::Write;
    let mut child = Command::new(exe).stdin(Stdio::piped()).stdout(Stdio::piped()).spawn().expect("runs");
    let input: String = raw.iter().map(|r| format!("{} {} {}\n", r[0], r[1], r[2])).collect();
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()).unwrap());
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    assert!(out.status.success());
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f32> =
                l.split_whitespace().map(|x| f32::from_bits(u32::from_str_radix(x, 16).unwrap())).collect();
            assert_eq!(v.len(), 9, "{l}");
            Output { rate: [v[0], v[1], v[2]], hi: [v[3], v[4], v[5]], lo: [v[6], v[7], v[8]] }
        })
        .collect()
}

/// Half an f32 ulp of `v`, °/s.
pub(super) fn half_ulp(v: f32) -> f64 {
    f64::from(f32::EPSILON) / 2.0 * 2f64.powf(f64::from(v.abs()).log2().floor())
}

/// Compares an export's output with `Calibration::apply` (what `host apply` prints) for every
/// reading and axis: the split `hi + lo` within the row's proven bound (the double-precision
/// reference adds ≤ 1e-12 °/s of its own) and so within the issue's 1e-5 °/s; `lo` normalised
/// (≤ half an ulp of `hi`); the float result equal to `hi`, so within half an ulp plus the
/// bound. Returns the largest differences of the split and of the float, °/s.
fn compare(e: &Export, raw: &[[i16; 3]], got: &[Output]) -> (f64, f64) {
    assert_eq!(got.len(), raw.len());
    let bounds = e.split().rows.map(|r| r.bound_dps());
    let (mut split, mut float) = (0.0f64, 0.0f64);
    for (r, g) in raw.iter().zip(got) {
        let want = e.calibration.apply(*r);
        for i in 0..3 {
            let d = (f64::from(g.hi[i]) + f64::from(g.lo[i]) - want[i]).abs();
            assert!(d <= bounds[i] + 1e-12, "raw {r:?} axis {i}: {}+{} vs {} ({d:e} °/s)", g.hi[i], g.lo[i], want[i]);
            assert!(d <= 1e-5);
            assert!(f64::from(g.lo[i].abs()) <= half_ulp(g.hi[i]), "raw {r:?} axis {i}: lo {} hi {}", g.lo[i], g.hi[i]);
            assert_eq!(g.rate[i].to_bits(), g.hi[i].to_bits(), "raw {r:?} axis {i}");
            let df = (f64::from(g.rate[i]) - want[i]).abs();
            assert!(df <= half_ulp(g.rate[i]) + bounds[i] + 1e-12, "raw {r:?} axis {i}: {df:e} °/s");
            split = split.max(d);
            float = float.max(df);
        }
    }
    (split, float)
}

fn compile_c(e: &Export, name: &str) -> (tempfile::TempDir, PathBuf, String) {
    let dir = scratch(name);
    let header = e.render(Format::C).unwrap();
    std::fs::write(dir.path().join("gyrocal.h"), &header).unwrap();
    let exe = cc(
        dir.path(),
        r#"#include <stdio.h>
#include <string.h>
#include "gyrocal.h"
static unsigned long bits(float f) { uint32_t u; memcpy(&u, &f, sizeof u); return (unsigned long)u; }
int main(void) {
    int a, b, c, i;
    while (scanf("%d %d %d", &a, &b, &c) == 3) {
        const int16_t raw[3] = {(int16_t)a, (int16_t)b, (int16_t)c};
        float w[3], hi[3], lo[3];
        gyrocal_apply(raw, w);
        gyrocal_apply_split(raw, hi, lo);
        for (i = 0; i < 3; i++) printf("%08lx ", bits(w[i]));
        for (i = 0; i < 3; i++) printf("%08lx ", bits(hi[i]));
        printf("%08lx %08lx %08lx\n", bits(lo[0]), bits(lo[1]), bits(lo[2]));
    }
    return 0;
}
"#,
    );
    (dir, exe, header)
}

/// Writes `main_c` into `dir` beside its `gyrocal.h`, compiles it strictly (C99, pedantic, every
/// warning an error) and returns the program.
pub(super) fn cc(dir: &Path, main_c: &str) -> PathBuf {
    std::fs::write(dir.join("main.c"), main_c).unwrap();
    let exe = dir.join("apply");
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    // -ffp-contract=fast lets the compiler fuse multiply-adds (as GCC does by default outside ISO
    // mode, and on a Cortex-M4F): the exact sums must not care.
    let o = Command::new(&cc)
        .args(["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2", "-ffp-contract=fast", "-o"])
        .arg(&exe)
        .arg(dir.join("main.c"))
        .arg("-lm")
        .output()
        .unwrap_or_else(|err| panic!("cannot run the C compiler {cc:?}: {err}"));
    assert!(o.status.success(), "cc failed:\n{}", String::from_utf8_lossy(&o.stderr));
    exe
}

#[test]
fn c_header_compiles_and_agrees_with_apply_over_all_of_int16() {
    let raw = readings();
    for (e, fs, bound) in
        [(sample_export(), 500, "5.960464477539063e-8"), (wide_export(), 2000, "2.384185791015625e-7")]
    {
        let (_dir, exe, header) = compile_c(&e, &format!("c{fs}"));
        let (split, float) = compare(&e, &raw, &run_on_readings(&exe, &raw));
        eprintln!(
            "C export at ±{fs} °/s vs apply over {} readings: split max {split:.2e} °/s (bound {bound}), float max {float:.2e} °/s",
            raw.len()
        );
        assert!(header.contains("#define GYROCAL_SENSOR_SERIAL \"G-0042\""), "{header}");
        assert!(header.contains(&format!("#define GYROCAL_FULL_SCALE_DPS {fs}\n")), "{header}");
        assert!(header.contains("#define GYROCAL_ODR_HZ 800"));
        assert!(header.contains(&format!("#define GYROCAL_SPLIT_BOUND_DPS {bound}\n")), "{header}");
        assert!(header.contains("static inline void gyrocal_apply(const int16_t raw[3], float rate_dps[3])"));
    }
}

/// Under -ffast-math, or with x87 excess precision (`-mfpmath=387`, FLT_EVAL_METHOD 2), the
/// header stops the build instead of silently losing its error-free sums. The x87 case is
/// checked where the compiler targets x86-64 (GCC; the host's `cc` here).
#[test]
fn c_header_refuses_fast_math_and_excess_precision() {
    let dir = scratch("flags");
    std::fs::write(dir.path().join("gyrocal.h"), sample_export().render(Format::C).unwrap()).unwrap();
    std::fs::write(dir.path().join("t.c"), "#include \"gyrocal.h\"\nint main(void) { return 0; }\n").unwrap();
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let compile = |flags: &[&str]| {
        let o = Command::new(&cc)
            .args(["-std=c99", "-fsyntax-only"])
            .args(flags)
            .arg(dir.path().join("t.c"))
            .output()
            .unwrap_or_else(|err| panic!("cannot run the C compiler {cc:?}: {err}"));
        (o.status.success(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    assert!(compile(&[]).0, "{}", compile(&[]).1);
    let (ok, err) = compile(&["-ffast-math"]);
    assert!(!ok && err.contains("-ffast-math reassociates the error-free sum"), "{err}");
    if cfg!(target_arch = "x86_64") {
        let (ok, err) = compile(&["-mfpmath=387"]);
        assert!(!ok && err.contains("gyrocal.h needs FLT_EVAL_METHOD == 0"), "{err}");
    }
}

#[test]
fn rust_export_compiles_no_std_and_agrees_with_apply_over_all_of_int16() {
    let raw = readings();
    for (e, fs) in [(sample_export(), 500), (wide_export(), 2000)] {
        let dir = scratch(&format!("rust{fs}"));
        let dir = dir.path();
        let module = e.render(Format::Rust).unwrap();
        std::fs::write(dir.join("gyrocal.rs"), &module).unwrap();
        let rustc = builds_without_std(dir);
        std::fs::write(
            dir.join("main.rs"),
            r#"include!("gyrocal.rs");
fn main() {
    use std::io::{BufRead, Write};
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for line in std::io::stdin().lock().lines() {
        let line = line.unwrap();
        let v: Vec<i16> = line.split_whitespace().map(|x| x.parse().unwrap()).collect();
        let raw = [v[0], v[1], v[2]];
        let w = GYROCAL.apply(raw);
        let (hi, lo) = GYROCAL.apply_split(raw);
        for f in w.iter().chain(&hi).chain(&lo) {
            write!(out, "{:08x} ", f.to_bits()).unwrap();
        }
        writeln!(out).unwrap();
    }
}
"#,
        )
        .unwrap();
        let exe = dir.join("apply");
        let o = Command::new(&rustc)
            .args(["--edition", "2021", "-O", "-o"])
            .arg(&exe)
            .arg(dir.join("main.rs"))
            .output()
            .unwrap();
        assert!(o.status.success(), "rustc failed:\n{}", String::from_utf8_lossy(&o.stderr));
        let (split, float) = compare(&e, &raw, &run_on_readings(&exe, &raw));
        eprintln!(
            "Rust export at ±{fs} °/s vs apply over {} readings: split max {split:.2e} °/s, float max {float:.2e} °/s",
            raw.len()
        );
        assert!(module.contains("sensor_serial: \"G-0042\""));
        assert!(module.contains("odr_hz: Some(800)"));
        assert!(module.contains(&format!("full_scale_dps: {fs},")));
    }
}

/// The split of every row: high parts on a grid of 2^(e−7) with at most 128 steps, middle parts
/// on 2^(e−14) with at most 64, both exact in f32, and the three summing back to the coefficient
/// exactly in f64 (the low part then loses only its f32 rounding).
#[test]
fn split_rows_are_exact_in_f32_and_sum_back() {
    for e in [sample_export(), wide_export()] {
        let sp = e.split();
        let b = e.offset_rate_dps();
        for (i, r) in sp.rows.iter().enumerate() {
            let largest = e.m_inv_dps_per_count[i].iter().fold(0.0f64, |a, v| a.max(v.abs()));
            assert_eq!(r.exponent, largest.log2().ceil() as i32);
            let (hi_step, mid_step) = (2f64.powi(r.exponent - 7), 2f64.powi(r.exponent - 14));
            let on = |v: f64, step: f64, most: f64| {
                let n = v / step;
                assert_eq!(n, n.round(), "{v} on a grid of {step}");
                assert!(n.abs() <= most, "{v}: {n} steps of {step}");
                assert_eq!(f64::from(v as f32), v);
            };
            for j in 0..3 {
                on(r.m_hi[j], hi_step, 128.0);
                on(r.m_mid[j], mid_step, 64.0);
                assert!(r.m_lo[j].abs() <= mid_step / 2.0);
                assert_eq!(r.m_hi[j] + r.m_mid[j] + r.m_lo[j], e.m_inv_dps_per_count[i][j]);
            }
            on(r.b_hi, hi_step, 2f64.powi(22));
            on(r.b_mid, mid_step, 64.0);
            assert!((r.b_hi + r.b_mid + r.b_lo - b[i]).abs() <= 1e-15 * b[i].abs());
        }
    }
}

#[test]
fn single_precision_exports_refuse_an_offset_they_cannot_carry_exactly() {
    let m = [[14.33, 0.22, -0.1], [-0.15, 14.2, 0.27], [0.08, -0.18, 14.5]];
    let e = export_of(FullScale::Dps2000, m, [12.0, -8192.0, 0.0]);
    for f in [Format::C, Format::Rust] {
        assert_eq!(
            e.render(f).unwrap_err().to_string(),
            "offset y is -8192 counts, beyond the ±8192 counts the single-precision exports carry exactly \
             (a zero-rate level that large is a broken sensor)"
        );
    }
    assert!(e.render(Format::Json).unwrap().contains("\"offset_y\""));
}

#[test]
fn kalibr_factors_reproduce_k_s_over_the_nominal_sensitivity() {
    let e = sample_export();
    let nominal = 1e6 / 17_500.0;
    let n = Matrix3::from_fn(|i, j| e.calibration.m_counts_per_dps[i][j] / nominal);
    let (l, c) = kalibr::lower_times_rotation(&n);
    assert!((l * c - n).abs().max() < 1e-14, "{}", l * c - n);
    assert!((c * c.transpose() - Matrix3::identity()).abs().max() < 1e-14);
    assert!((c.determinant() - 1.0).abs() < 1e-14);
    for i in 0..3 {
        assert!(l[(i, i)] > 0.0);
        for j in i + 1..3 {
            assert_eq!(l[(i, j)], 0.0);
        }
    }
    // M's diagonal is the sensitivity relative to nominal: 57.3/57.142857 = 1.00275, and the
    // YAML carries the factors as written.
    assert!((l[(0, 0)] - (57.3f64.powi(2) + 0.81 + 0.16).sqrt() / nominal).abs() < 1e-12);
    let yaml = e.render(Format::Kalibr).unwrap();
    assert!(yaml.contains("\nupdate_rate: 800.0\n"), "{yaml}");
    let m00: f64 = yaml_serde::from_str::<yaml_serde::Value>(&yaml).unwrap()["gyroscopes"]["M"][0][0].as_f64().unwrap();
    assert_eq!(m00, l[(0, 0)]);
}

/// The Kalibr file in Kalibr's own terms: without noise figures and g-sensitivity, the required
/// statistics are the stated placeholders (positive, as Kalibr's reader demands) and A is zero.
#[test]
fn kalibr_yaml_holds_every_field_kalibrs_reader_requires() {
    let yaml = sample_export().render(Format::Kalibr).unwrap();
    let body: Vec<&str> = yaml.lines().filter(|l| !l.starts_with('#')).take(8).collect();
    assert_eq!(
        body,
        [
            "rostopic: /imu0",
            "update_rate: 800.0",
            "accelerometer_noise_density: 0.00186",
            "accelerometer_random_walk: 0.000433",
            "gyroscope_noise_density: 0.0005235987755982988",
            "gyroscope_random_walk: 0.00008726646259971648",
            "model: scale-misalignment",
            "time_offset: 0.0",
        ]
    );
    assert!(yaml.contains("\n  A:\n  - - 0.0\n    - 0.0\n    - 0.0\n"), "{yaml}");
    assert!(yaml.contains("# gyroscopes.A: zero: g-sensitivity not in this calibration's model.\n"), "{yaml}");
}

/// A fitted g-sensitivity reaches Kalibr's A, in rad/s per m/s²: 0.05 °/s/g on x from gravity
/// along y is 0.05·π/180/9.80665.
#[test]
fn kalibr_a_carries_the_fitted_g_sensitivity() {
    let mut e = sample_export();
    e.g_sensitivity_dps_per_g = Some([[0.0, 0.05, 0.0], [0.0, 0.0, -0.02], [1e-9, 0.0, 0.0]]);
    let yaml = e.render(Format::Kalibr).unwrap();
    let v: yaml_serde::Value = yaml_serde::from_str(&yaml).unwrap();
    let a = |i: usize, j: usize| v["gyroscopes"]["A"][i][j].as_f64().unwrap();
    assert_eq!(a(0, 1), 0.05 * std::f64::consts::PI / 180.0 / 9.80665);
    assert_eq!(a(1, 2), -0.02 * std::f64::consts::PI / 180.0 / 9.80665);
    // 1e-9 °/s/g is 1.78e-12 in Kalibr's unit: written with a point and a signed exponent.
    assert!(yaml.contains("\n  - - 1.7797"), "{yaml}");
    assert!(yaml.contains("e-12\n"), "{yaml}");
    assert!(yaml.contains("# gyroscopes.A: the fitted g-sensitivity, rad/s per m/s^2.\n"), "{yaml}");
}

/// PyYAML, which Kalibr reads with (YAML 1.1), takes every number for a number: Kalibr's
/// `ImuParameters` checks run on the file as Python loads it.
#[test]
#[cfg_attr(not(has_pyyaml), ignore = "no PyYAML: apt-get install python3-yaml (.ci/run does)")]
fn kalibr_yaml_loads_in_pyyaml_with_every_number_a_number() {
    let mut e = sample_export();
    e.g_sensitivity_dps_per_g = Some([[0.0, 0.05, 0.0], [0.0, 0.0, -0.02], [1e-9, 0.0, 0.0]]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("imu.yaml");
    std::fs::write(&path, e.render(Format::Kalibr).unwrap()).unwrap();
    // Kalibr's ImuParameters (kalibr_common/ConfigReader.py): rostopic a string, update_rate and
    // the four statistics positive; here also every matrix entry a float.
    let script = r#"
import sys, yaml
d = yaml.safe_load(open(sys.argv[1]))
assert isinstance(d["rostopic"], str)
for k in ["update_rate", "accelerometer_noise_density", "accelerometer_random_walk",
          "gyroscope_noise_density", "gyroscope_random_walk"]:
    assert isinstance(d[k], float) and d[k] > 0.0, (k, d[k])
assert isinstance(d["time_offset"], float)
rows = [r for m in ("M", "A", "C_gyro_i") for r in d["gyroscopes"][m]] + d["T_i_b"]
assert all(isinstance(x, float) for r in rows for x in r), rows
print(d["gyroscopes"]["A"][2][0], d["gyroscope_random_walk"])
"#;
    let o = Command::new("python3").arg("-c").arg(script).arg(&path).output().expect("python3 runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(String::from_utf8_lossy(&o.stdout), "1.7797405352432584e-12 8.726646259971648e-05\n");
}

#[test]
fn json_and_csv_carry_every_parameter_exactly() {
    let e = sample_export();
    let j: serde_json::Value = serde_json::from_str(&e.render(Format::Json).unwrap()).unwrap();
    assert_eq!(j["sensor_serial"], "G-0042");
    assert_eq!(j["parameters"]["m_xy"]["value"], 0.9);
    assert_eq!(j["parameters"]["offset_x"]["value"], 12.375);
    assert_eq!(j["parameters"]["m_inv_zz"]["value"].as_f64().unwrap(), e.m_inv_dps_per_count[2][2]);
    let csv = e.render(Format::Csv).unwrap();
    let line = csv.lines().find(|l| l.starts_with("offset_y,")).unwrap();
    assert_eq!(line, "offset_y,-3.05e1,,counts");
    let v: f64 = csv.lines().find(|l| l.starts_with("m_inv_xy,")).unwrap().split(',').nth(1).unwrap().parse().unwrap();
    assert_eq!(v, e.m_inv_dps_per_count[0][1]);
    assert_eq!(csv.lines().count(), 1 + 5 + 24);
}

/// `sample_export` with a warm-up drift and a g-sensitivity; `wide_export` with a temperature
/// drift and none: sizes of a real part's (0.3 °/s warm-up, 0.05 °/s/°C, 0.05 °/s/g).
fn exports_with_terms() -> [Export; 2] {
    let mut a = sample_export();
    a.drift = Some(DriftModel::WarmUp { amplitude_counts: [-16.5, 10.25, -21.75], tau_s: 88.25 });
    a.g_sensitivity_dps_per_g = Some([[0.02, 0.05, -0.01], [0.0, -0.03, 0.04], [0.06, 0.0, 0.015]]);
    let mut b = wide_export();
    b.drift = Some(DriftModel::Temperature { counts_per_c: [0.7, -0.45, 0.2], reference_out_temp_lsb: 13.4 });
    [a, b]
}

/// The inputs of reading `i`: t over the first 10 min, OUT_TEMP over ±20 LSB round the
/// reference, the specific force turning on a cone (1 g) and absent every fifth reading.
pub(super) fn inputs_of(i: usize) -> Inputs {
    let a = i as f64 * 0.37;
    Inputs {
        t_s: (i % 600) as f64 + 0.25,
        out_temp_lsb: (i % 41) as f64 - 20.0 + 13.0,
        specific_force_g: (!i.is_multiple_of(5)).then(|| [0.6 * a.cos(), 0.6 * a.sin(), 0.8]),
    }
}

/// Every 9th reading of [`readings`] with its [`inputs_of`].
fn readings_with_inputs() -> Vec<([i16; 3], Inputs)> {
    readings().into_iter().step_by(9).enumerate().map(|(i, r)| (r, inputs_of(i))).collect()
}

/// One input line: `x y z t_s out_temp has_f fx fy fz`.
fn input_line(r: &[i16; 3], x: &Inputs) -> String {
    let f = x.specific_force_g.unwrap_or([0.0; 3]);
    let has = u8::from(x.specific_force_g.is_some());
    format!("{} {} {} {} {} {has} {} {} {}\n", r[0], r[1], r[2], x.t_s, x.out_temp_lsb, f[0], f[1], f[2])
}

/// Runs `exe` on the readings with inputs; each output line holds three floats' bit patterns.
fn run_with_inputs(exe: &Path, cases: &[([i16; 3], Inputs)]) -> Vec<[f32; 3]> {
    use std::io::Write;
    let mut child = Command::new(exe).stdin(Stdio::piped()).stdout(Stdio::piped()).spawn().expect("runs");
    let input: String = cases.iter().map(|(r, x)| input_line(r, x)).collect();
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()).unwrap());
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    assert!(out.status.success());
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f32> =
                l.split_whitespace().map(|x| f32::from_bits(u32::from_str_radix(x, 16).unwrap())).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// Compares `apply_with` of an export with [`Export::apply_with`]: within half an f32 ulp of the
/// result, the split's bound, and 1e-6 of the terms' size (their f32 rounding and the f32
/// exponential, each a few 1e-8 relative); returns the largest difference, °/s. Also checks
/// that the terms are not negligible, so that the comparison tests them.
fn compare_with(e: &Export, cases: &[([i16; 3], Inputs)], got: &[[f32; 3]]) -> f64 {
    assert_eq!(got.len(), cases.len());
    let bounds = e.split().rows.map(|r| r.bound_dps());
    let mut worst = 0.0f64;
    let mut largest_term = 0.0f64;
    for ((r, x), g) in cases.iter().zip(got) {
        let want = e.apply_with(*r, x);
        let plain = e.calibration.apply(*r);
        for i in 0..3 {
            let terms = (want[i] - plain[i]).abs();
            largest_term = largest_term.max(terms);
            let d = (f64::from(g[i]) - want[i]).abs();
            let tol = half_ulp(g[i]) + bounds[i] + 1e-6 * (terms + 1.0);
            assert!(d <= tol, "raw {r:?} {x:?} axis {i}: {} vs {} ({d:e} > {tol:e} °/s)", g[i], want[i]);
            worst = worst.max(d);
        }
    }
    assert!(largest_term > 0.1, "the drift and g-sensitivity terms reach {largest_term} °/s only");
    worst
}

#[test]
fn c_header_applies_the_drift_and_the_g_sensitivity_as_the_library_does() {
    let cases = readings_with_inputs();
    for (n, e) in exports_with_terms().iter().enumerate() {
        let dir = scratch(&format!("cwith{n}"));
        std::fs::write(dir.path().join("gyrocal.h"), e.render(Format::C).unwrap()).unwrap();
        std::fs::write(
            dir.path().join("main.c"),
            r#"#include <stdio.h>
#include <string.h>
#include "gyrocal.h"
static unsigned long bits(float f) { uint32_t u; memcpy(&u, &f, sizeof u); return (unsigned long)u; }
int main(void) {
    int a, b, c, has;
    float t, temp, f[3], w[3];
    while (scanf("%d %d %d %f %f %d %f %f %f", &a, &b, &c, &t, &temp, &has, &f[0], &f[1], &f[2]) == 9) {
        const int16_t raw[3] = {(int16_t)a, (int16_t)b, (int16_t)c};
        gyrocal_apply_with(raw, t, temp, has ? f : NULL, w);
        printf("%08lx %08lx %08lx\n", bits(w[0]), bits(w[1]), bits(w[2]));
    }
    return 0;
}
"#,
        )
        .unwrap();
        let exe = dir.path().join("apply");
        let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
        let o = Command::new(&cc)
            .args(["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2", "-ffp-contract=fast", "-o"])
            .arg(&exe)
            .arg(dir.path().join("main.c"))
            .arg("-lm")
            .output()
            .unwrap_or_else(|err| panic!("cannot run the C compiler {cc:?}: {err}"));
        assert!(o.status.success(), "cc failed:\n{}", String::from_utf8_lossy(&o.stderr));
        let worst = compare_with(e, &cases, &run_with_inputs(&exe, &cases));
        eprintln!("C apply_with, export {n}, vs Export::apply_with over {} readings: max {worst:.2e} °/s", cases.len());
    }
}

#[test]
fn rust_export_applies_the_drift_and_the_g_sensitivity_as_the_library_does() {
    let cases = readings_with_inputs();
    for (n, e) in exports_with_terms().iter().enumerate() {
        let dir = scratch(&format!("rustwith{n}"));
        let dir = dir.path();
        std::fs::write(dir.join("gyrocal.rs"), e.render(Format::Rust).unwrap()).unwrap();
        let rustc = builds_without_std(dir);
        std::fs::write(
            dir.join("main.rs"),
            r#"include!("gyrocal.rs");
fn main() {
    use std::io::{BufRead, Write};
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for line in std::io::stdin().lock().lines() {
        let line = line.unwrap();
        let v: Vec<&str> = line.split_whitespace().collect();
        let raw = [v[0].parse().unwrap(), v[1].parse().unwrap(), v[2].parse().unwrap()];
        let f: [f32; 3] = [v[6].parse().unwrap(), v[7].parse().unwrap(), v[8].parse().unwrap()];
        let f = (v[5] == "1").then_some(f);
        let w = GYROCAL.apply_with(raw, v[3].parse().unwrap(), v[4].parse().unwrap(), f);
        writeln!(out, "{:08x} {:08x} {:08x}", w[0].to_bits(), w[1].to_bits(), w[2].to_bits()).unwrap();
    }
}
"#,
        )
        .unwrap();
        let exe = dir.join("apply");
        let o = Command::new(&rustc)
            .args(["--edition", "2021", "-O", "-o"])
            .arg(&exe)
            .arg(dir.join("main.rs"))
            .output()
            .unwrap();
        assert!(o.status.success(), "rustc failed:\n{}", String::from_utf8_lossy(&o.stderr));
        let worst = compare_with(e, &cases, &run_with_inputs(&exe, &cases));
        eprintln!(
            "Rust apply_with, export {n}, vs Export::apply_with over {} readings: max {worst:.2e} °/s",
            cases.len()
        );
    }
}

/// The reference itself: a warm-up of c counts at t = 0 and a g-sensitivity G move the rate by
/// exactly (K S)⁻¹ c and (K S)⁻¹ diag(k) G f; the warm-up is gone after 40 T.
#[test]
fn apply_with_removes_the_modelled_offset_and_g_sensitivity() {
    let [e, _] = exports_with_terms();
    let raw = [1200, -800, 300];
    let none = Inputs { t_s: 40.0 * 88.25, out_temp_lsb: 0.0, specific_force_g: None };
    assert_eq!(e.apply_with(raw, &none), e.calibration.apply(raw));
    let inv = Matrix3::from_fn(|i, j| e.m_inv_dps_per_count[i][j]);
    let m = e.calibration.m_counts_per_dps;
    let k = Matrix3::from_diagonal(&Vector3::from_fn(|a, _| Vector3::from(m[a]).norm()));
    let g = Matrix3::from_fn(|i, j| e.g_sensitivity_dps_per_g.unwrap()[i][j]);
    let f = Vector3::new(0.0, 0.0, 1.0);
    let at_start = Inputs { t_s: 0.0, out_temp_lsb: 0.0, specific_force_g: Some(f.into()) };
    let want = Vector3::from(e.calibration.apply(raw)) - inv * Vector3::new(-16.5, 10.25, -21.75) - inv * k * g * f;
    let got = Vector3::from(e.apply_with(raw, &at_start));
    assert!((got - want).abs().max() < 1e-12, "{got} vs {want}");
}

/// The headers are ASCII with the symbols spelled out (no `?` for °, ± or ω), and say what they
/// leave out.
#[test]
fn headers_are_ascii_and_say_what_they_leave_out() {
    let [with, _] = exports_with_terms();
    let c = sample_export().render(Format::C).unwrap();
    assert!(c.is_ascii(), "{c}");
    assert!(!c.contains('?'), "{c}");
    assert!(c.contains(" * Model: linear: v = K S omega + v_off\n"), "{c}");
    assert!(
        c.contains(" * Left out:\n *   - offset drift: none in this calibration's model (the drift terms are zero)\n")
    );
    assert!(c.contains(" *   - g-sensitivity: not in this calibration's model (its terms are zero)\n"), "{c}");
    let rust = with.render(Format::Rust).unwrap();
    assert!(
        rust.contains(
            "// Left out:\n//   - offset drift with die temperature (this calibration's drift model is the warm-up)\n"
        ),
        "{rust}"
    );
    assert!(!rust.contains("g-sensitivity: not in"), "{rust}");
    let mut session = sample_export();
    session.drift = Some(DriftModel::SessionOnly {
        model: "offset drift: quadratic in time".into(),
        offsets_are: "the middle of the capture's time span, less half the quadratic term".into(),
    });
    assert!(session.render(Format::C).unwrap().contains(
        " *   - offset drift: 'offset drift: quadratic in time' describes the calibration session's own time span \
         only and is not exported (the drift terms are zero); the offsets are those at the middle of the \
         capture's time span, less half the quadratic term\n"
    ));
    assert_eq!(sanitise("±500 °/s, (K S)⁻¹, m²"), "+-500 deg/s, (K S)^-1, m^2");
}

/// `drift_model` in calibration.json reads back into the export.
#[test]
fn the_drift_model_reads_back_from_calibration_json() {
    let e = sample_export();
    let mut v: serde_json::Value = serde_json::from_str(&e.calibration.to_json()).unwrap();
    v[DRIFT_MODEL_KEY] = serde_json::json!({"kind": "warm_up", "amplitude_counts": [1.0, 2.0, 3.0], "tau_s": 60.0});
    let back = Export::from_json(&v.to_string()).unwrap();
    assert_eq!(back.drift, Some(DriftModel::WarmUp { amplitude_counts: [1.0, 2.0, 3.0], tau_s: 60.0 }));
}

/// Compiles `dir/gyrocal.rs` alone as a `no_std` library that denies warnings (metadata only),
/// and returns the `rustc` it used.
pub(super) fn builds_without_std(dir: &std::path::Path) -> String {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    std::fs::write(dir.join("lib.rs"), "#![no_std]\n#![deny(warnings)]\ninclude!(\"gyrocal.rs\");\n").unwrap();
    let o = Command::new(&rustc)
        .args(["--edition", "2021", "--crate-type", "rlib", "--emit", "metadata", "--out-dir"])
        .arg(dir)
        .arg(dir.join("lib.rs"))
        .output()
        .unwrap();
    assert!(o.status.success(), "no_std build failed:\n{}", String::from_utf8_lossy(&o.stderr));
    rustc
}
