//! The exports compiled and run: the C header with `cc`, the Rust module with `rustc`, each fed
//! raw readings and compared with [`Calibration::apply`] (what `host apply` prints).

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
    let off = [12.375, -30.5, 4.25];
    let cal = Calibration::new("linear: v = K S ω + v_off".into(), FullScale::Dps500, m, off).unwrap();
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
        gyro: Some(GyroConfig::DEFAULT),
        captures: vec![CaptureDigest { file: "a.cap".into(), bytes: 3, sha256: "ab".into() }],
        die_temperature: None,
    };
    let text = prov.attach(serde_json::from_str(&cal.to_json()).unwrap()).to_string();
    Export::from_json(&text).unwrap()
}

/// Raw readings: the extremes, 1000 across the whole range (up to ±570 °/s here) and 1000 within
/// ±2800 counts (≈ ±50 °/s, where a bench or a vehicle spends its time). Fixed seed.
fn readings() -> Vec<[i16; 3]> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let mut v = vec![[0, 0, 0], [i16::MAX; 3], [i16::MIN; 3], [i16::MAX, i16::MIN, 0], [1, -1, 2]];
    v.extend((0..1000).map(|_| [rng.random(), rng.random(), rng.random()]));
    v.extend((0..1000).map(|_| std::array::from_fn(|_| rng.random_range(-2800..=2800))));
    v
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("host-export-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs `exe`, feeding one `x y z` line per reading, and parses three floats per output line.
fn run_on_readings(exe: &Path, raw: &[[i16; 3]]) -> Vec<[f64; 3]> {
    use std::io::Write;
    let mut child = Command::new(exe).stdin(Stdio::piped()).stdout(Stdio::piped()).spawn().expect("runs");
    let input: String = raw.iter().map(|r| format!("{} {} {}\n", r[0], r[1], r[2])).collect();
    child.stdin.take().unwrap().write_all(input.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// Compares an export's output with `Calibration::apply`. The split coefficients leave only the
/// result's own rounding, half an f32 ulp: agreement to 1e-5 °/s is required below 256 °/s
/// (half-ulp ≤ 7.6e-6 °/s there), and to half an ulp plus 1e-6 °/s everywhere (above 256 °/s
/// an f32 cannot hold a rate closer than 1.5e-5 °/s). Returns the largest differences (below
/// 256 °/s, anywhere), °/s.
fn compare(e: &Export, raw: &[[i16; 3]], got: &[[f64; 3]]) -> (f64, f64) {
    assert_eq!(got.len(), raw.len());
    let (mut below, mut all) = (0.0f64, 0.0f64);
    for (r, g) in raw.iter().zip(got) {
        let want = e.calibration.apply(*r);
        for i in 0..3 {
            let d = (g[i] - want[i]).abs();
            let half_ulp = f64::from(f32::EPSILON) / 2.0 * 2f64.powf(want[i].abs().log2().floor());
            assert!(d <= half_ulp + 1e-6, "raw {r:?} axis {i}: {} vs {} ({d:e} °/s apart)", g[i], want[i]);
            if want[i].abs() < 256.0 {
                assert!(d <= 1e-5, "raw {r:?} axis {i}: {} vs {}, {d:e} °/s apart", g[i], want[i]);
                below = below.max(d);
            }
            all = all.max(d);
        }
    }
    (below, all)
}

#[test]
fn c_header_compiles_and_agrees_with_apply() {
    let e = sample_export();
    let dir = scratch("c");
    std::fs::write(dir.join("gyrocal.h"), e.render(Format::C)).unwrap();
    std::fs::write(
        dir.join("main.c"),
        r#"#include <stdio.h>
#include "gyrocal.h"
int main(void) {
    int a, b, c;
    while (scanf("%d %d %d", &a, &b, &c) == 3) {
        const int16_t raw[3] = {(int16_t)a, (int16_t)b, (int16_t)c};
        float w[3];
        gyrocal_apply(raw, w);
        /* %.17g of the float widened to double: its exact value, so the comparison sees the export alone. */
        printf("%.17g %.17g %.17g\n", (double)w[0], (double)w[1], (double)w[2]);
    }
    return 0;
}
"#,
    )
    .unwrap();
    let exe = dir.join("apply");
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let o = Command::new(&cc)
        .args(["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2", "-o"])
        .arg(&exe)
        .arg(dir.join("main.c"))
        .output()
        .unwrap_or_else(|err| panic!("cannot run the C compiler {cc:?}: {err}"));
    assert!(o.status.success(), "cc failed:\n{}", String::from_utf8_lossy(&o.stderr));
    let raw = readings();
    let (small, all) = compare(&e, &raw, &run_on_readings(&exe, &raw));
    eprintln!("C export vs apply: max {small:.2e} °/s below 256 °/s, {all:.2e} °/s over the full scale");
    let header = std::fs::read_to_string(dir.join("gyrocal.h")).unwrap();
    assert!(header.contains("#define GYROCAL_SENSOR_SERIAL \"G-0042\""), "{header}");
    assert!(header.contains("#define GYROCAL_FULL_SCALE_DPS 500"));
    assert!(header.contains("#define GYROCAL_ODR_HZ 800"));
}

#[test]
fn rust_export_compiles_no_std_and_agrees_with_apply() {
    let e = sample_export();
    let dir = scratch("rust");
    let module = e.render(Format::Rust);
    std::fs::write(dir.join("gyrocal.rs"), &module).unwrap();
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    // no_std: the module alone as a library that links no std.
    std::fs::write(dir.join("lib.rs"), "#![no_std]\n#![deny(warnings)]\ninclude!(\"gyrocal.rs\");\n").unwrap();
    let o = Command::new(&rustc)
        .args(["--edition", "2021", "--crate-type", "rlib", "--emit", "metadata", "--out-dir"])
        .arg(&dir)
        .arg(dir.join("lib.rs"))
        .output()
        .unwrap();
    assert!(o.status.success(), "no_std build failed:\n{}", String::from_utf8_lossy(&o.stderr));
    std::fs::write(
        dir.join("main.rs"),
        r#"include!("gyrocal.rs");
fn main() {
    use std::io::BufRead;
    for line in std::io::stdin().lock().lines() {
        let line = line.unwrap();
        let v: Vec<i16> = line.split_whitespace().map(|x| x.parse().unwrap()).collect();
        let w = GYROCAL.apply([v[0], v[1], v[2]]);
        // Widened to f64: its exact value (an f32's shortest form would read back as another f64).
        println!("{:e} {:e} {:e}", f64::from(w[0]), f64::from(w[1]), f64::from(w[2]));
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
    let raw = readings();
    let (small, all) = compare(&e, &raw, &run_on_readings(&exe, &raw));
    eprintln!("Rust export vs apply: max {small:.2e} °/s below 256 °/s, {all:.2e} °/s over the full scale");
    assert!(module.contains("sensor_serial: \"G-0042\""));
    assert!(module.contains("odr_hz: Some(800)"));
}

/// The split of every row: high parts on a grid of 2^q with at most 7 significant bits, exact in
/// f32, and high + low equal to the coefficient to f32 precision of the low part.
#[test]
fn split_rows_are_exact_in_f32_and_sum_back() {
    let e = sample_export();
    let sp = e.split();
    let b = e.offset_rate_dps();
    for (i, r) in sp.rows.iter().enumerate() {
        let largest = e.m_inv_dps_per_count[i].iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let quantum = 2f64.powi(largest.log2().ceil() as i32 - 7);
        for j in 0..3 {
            let n = r.m_hi[j] / quantum;
            assert_eq!(n, n.round());
            assert!(n.abs() <= 128.0);
            assert_eq!(f64::from(r.m_hi[j] as f32), r.m_hi[j]);
            let back = r.m_hi[j] + f64::from(r.m_lo[j] as f32);
            assert!((back - e.m_inv_dps_per_count[i][j]).abs() <= quantum * 2f64.powi(-24));
        }
        assert_eq!(f64::from(r.b_hi as f32), r.b_hi);
        assert!((r.b_hi + r.b_lo - b[i]).abs() < 1e-15);
    }
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
    let yaml = e.render(Format::Kalibr);
    assert!(yaml.contains("  update_rate: 800.0\n"), "{yaml}");
    assert!(yaml.contains(&format!("      - [{:.12e}, {:.12e}, {:.12e}]", l[(0, 0)], 0.0, 0.0)), "{yaml}");
}

#[test]
fn json_and_csv_carry_every_parameter_exactly() {
    let e = sample_export();
    let j: serde_json::Value = serde_json::from_str(&e.render(Format::Json)).unwrap();
    assert_eq!(j["sensor_serial"], "G-0042");
    assert_eq!(j["parameters"]["m_xy"]["value"], 0.9);
    assert_eq!(j["parameters"]["offset_x"]["value"], 12.375);
    assert_eq!(j["parameters"]["m_inv_zz"]["value"].as_f64().unwrap(), e.m_inv_dps_per_count[2][2]);
    let csv = e.render(Format::Csv);
    let line = csv.lines().find(|l| l.starts_with("offset_y,")).unwrap();
    assert_eq!(line, "offset_y,-3.05e1,,counts");
    let v: f64 = csv.lines().find(|l| l.starts_with("m_inv_xy,")).unwrap().split(',').nth(1).unwrap().parse().unwrap();
    assert_eq!(v, e.m_inv_dps_per_count[0][1]);
    assert_eq!(csv.lines().count(), 1 + 5 + 24);
}
