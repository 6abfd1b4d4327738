//! The exports of a thermal calibration compiled and run (issue 27's bar): the C header with
//! `cc` and the Rust module with `rustc`, fed every int16 value on every axis at three OUT_TEMP
//! readings inside the calibrated range, against the host's double-precision path (the thermal
//! model's calibration at the reading's die temperature, what `host apply --temp-c` applies) to
//! the split's proven bound and so to 1e-5 °/s; at readings outside the range all three refuse.

use super::tests::{builds_without_std, cc, export_json, half_ulp, inputs_of, readings, scratch};
use super::*;
use crate::calib::Estimate;
use crate::thermal::{Quantity, SetpointCal, ThermalError, ThermalModel};
use protocol::FullScale;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The chamber setpoints of issue 27, °C.
const SETPOINTS_C: [f64; 5] = [-20.0, 0.0, 25.0, 50.0, 70.0];

/// OUT_TEMP at 0 °C of the fixture's die, LSB: the register's offset is unspecified (datasheet
/// Table 5); any value shows the mapping, a fractional one that the range's ends round.
const OUT_TEMP_AT_0C: f64 = 12.3;

/// A thermal model of datasheet size (L3G4200D Table 4 and the simulator's tempcos,
/// `host/src/sim/thermal.rs`): offsets moving ±0.03 °/s/°C with some curvature, sensitivities
/// 120, −90, 60 ppm/°C with 0.5 ppm/°C², directions turning 0.002 °/°C; values exactly on their
/// polynomials, with σ of a 20-s calibration. `k25` is the sensitivity at 25 °C, counts/(°/s).
fn thermal_model(k25: f64, offset25_counts: [f64; 3]) -> ThermalModel {
    let offset_per_c = [0.03, -0.02, 0.025].map(|dps| dps * k25);
    let k_ppm_per_c = [120.0, -90.0, 60.0];
    let turn_per_c = 0.002f64.to_radians();
    let setpoints: Vec<SetpointCal> = SETPOINTS_C
        .iter()
        .map(|&sp| {
            let dt = sp - 25.0;
            let values = std::array::from_fn(|a| {
                let offset = offset25_counts[a] + offset_per_c[a] * dt + 1e-4 * k25 * dt * dt;
                let k = k25 * (1.0 + (k_ppm_per_c[a] * dt + 0.5 * dt * dt) * 1e-6);
                let next = 0.012 - 0.004 * a as f64 + turn_per_c * dt;
                let other = -0.009 + 0.006 * a as f64 - 0.5 * turn_per_c * dt;
                Quantity::PER_AXIS.map(|q| match q {
                    Quantity::OffsetCounts => Estimate { value: offset, sigma: 0.02 },
                    Quantity::SensitivityCountsPerDps => Estimate { value: k, sigma: 2e-3 },
                    Quantity::DirectionNext => Estimate { value: next, sigma: 2e-5 },
                    Quantity::DirectionOther => Estimate { value: other, sigma: 2e-5 },
                })
            });
            SetpointCal {
                setpoint_c: sp,
                out_temp_mean_lsb: OUT_TEMP_AT_0C - sp,
                full_scale: if k25 > 30.0 { FullScale::Dps500 } else { FullScale::Dps2000 },
                values,
                common_sigma: [[0.0; 4]; 3],
                at_noise_floor: true,
            }
        })
        .collect();
    ThermalModel::fit(&setpoints).unwrap()
}

/// A thermal session's `calibration.json`: the model's calibration at 25 °C with provenance, the
/// model in its `thermal` section; a warm-up and a g-sensitivity (the sizes of
/// `tests::exports_with_terms`) for `apply_with`.
fn thermal_export(k25: f64, offset25_counts: [f64; 3]) -> Export {
    let model = thermal_model(k25, offset25_counts);
    let base = model.calibration_at(25.0).unwrap();
    let mut value: serde_json::Value =
        serde_json::from_str(&export_json(base.full_scale, base.m_counts_per_dps, base.offset_counts)).unwrap();
    value[crate::thermal::CALIBRATION_KEY] = serde_json::to_value(&model).unwrap();
    let mut e = Export::from_json(&value.to_string()).unwrap();
    assert!(e.thermal.is_some());
    e.drift = Some(DriftModel::WarmUp { amplitude_counts: [-16.5, 10.25, -21.75], tau_s: 88.25 });
    e.g_sensitivity_dps_per_g = Some([[0.02, 0.05, -0.01], [0.0, -0.03, 0.04], [0.06, 0.0, 0.015]]);
    e
}

/// ±500 °/s (57.14 counts/(°/s), datasheet) and ±2000 °/s (14.29) with offsets near the
/// datasheet's ±75 °/s zero-rate level.
fn thermal_exports() -> [Export; 2] {
    [thermal_export(57.3, [12.375, -30.5, 4.25]), thermal_export(14.33, [1040.375, -987.5, 12.25])]
}

/// One output line: the statuses of apply, apply_split and apply_with (0 ok, 1 out of range),
/// then the rates of apply, hi and lo of apply_split, and apply_with.
struct Line {
    status: [u8; 3],
    rate: [f32; 3],
    hi: [f32; 3],
    lo: [f32; 3],
    with: [f32; 3],
}

/// Runs `exe temp_raw` on the readings, each with the inputs of its index ([`inputs_of`]).
fn run(exe: &Path, temp_raw: i8, raw: &[[i16; 3]]) -> Vec<Line> {
    use std::io::Write;
    let mut child =
        Command::new(exe).arg(temp_raw.to_string()).stdin(Stdio::piped()).stdout(Stdio::piped()).spawn().expect("runs");
    let input: String = raw
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let x = inputs_of(i);
            let f = x.specific_force_g.unwrap_or([0.0; 3]);
            let has = u8::from(x.specific_force_g.is_some());
            format!("{} {} {} {} {has} {} {} {}\n", r[0], r[1], r[2], x.t_s, f[0], f[1], f[2])
        })
        .collect();
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()).unwrap());
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    assert!(out.status.success());
    let lines: Vec<Line> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let t: Vec<&str> = l.split_whitespace().collect();
            assert_eq!(t.len(), 15, "{l}");
            let s = |i: usize| t[i].parse::<u8>().unwrap();
            let f = |i: usize| f32::from_bits(u32::from_str_radix(t[i], 16).unwrap());
            let v = |i: usize| [f(i), f(i + 1), f(i + 2)];
            Line { status: [s(0), s(1), s(2)], rate: v(3), hi: v(6), lo: v(9), with: v(12) }
        })
        .collect();
    assert_eq!(lines.len(), raw.len());
    lines
}

/// Largest differences (°/s) of the split, the float and apply_with from the host.
#[derive(Debug, Default, Clone, Copy)]
struct Worst {
    split_dps: f64,
    float_dps: f64,
    with_dps: f64,
}

/// Checks one temperature inside the range: every status ok; `hi + lo` within its row's
/// proven bound of the host's rate (+1e-12 for the host's own rounding) and so within 1e-5 °/s;
/// the float equal to `hi`; apply_with (every 9th reading) within half an ulp, the bound and
/// 1e-6 of its terms of [`Export::apply_thermal_with`].
fn check_inside(e: &Export, table: &ThermalTable, temp_raw: i8, raw: &[[i16; 3]], got: &[Line]) -> Worst {
    let cal = table.calibration_at_reading(temp_raw).unwrap();
    let row = &table.rows[(i16::from(temp_raw) - i16::from(table.out_temp_range_lsb()[0])) as usize];
    assert_eq!(row.out_temp_lsb, temp_raw);
    let bounds = row.split.rows.map(|r| r.bound_dps());
    let mut w = Worst::default();
    for (n, (r, g)) in raw.iter().zip(got).enumerate() {
        assert_eq!(g.status, [0; 3], "raw {r:?} at OUT_TEMP {temp_raw}");
        let want = cal.apply(*r);
        for i in 0..3 {
            let d = (f64::from(g.hi[i]) + f64::from(g.lo[i]) - want[i]).abs();
            assert!(d <= bounds[i] + 1e-12 && d <= 1e-5, "raw {r:?} T {temp_raw} axis {i}: {d:e} °/s");
            assert!(f64::from(g.lo[i].abs()) <= half_ulp(g.hi[i]), "raw {r:?} axis {i}: lo {} hi {}", g.lo[i], g.hi[i]);
            assert_eq!(g.rate[i].to_bits(), g.hi[i].to_bits(), "raw {r:?} axis {i}");
            w.split_dps = w.split_dps.max(d);
            w.float_dps = w.float_dps.max((f64::from(g.rate[i]) - want[i]).abs());
        }
        if n % 9 == 0 {
            let want = e.apply_thermal_with(table, *r, temp_raw, &inputs_of(n)).unwrap();
            for i in 0..3 {
                let terms = (want[i] - cal.apply(*r)[i]).abs();
                let d = (f64::from(g.with[i]) - want[i]).abs();
                let tol = half_ulp(g.with[i]) + bounds[i] + 1e-6 * (terms + 1.0);
                assert!(d <= tol, "raw {r:?} T {temp_raw} axis {i}: with {} vs {} ({d:e} °/s)", g.with[i], want[i]);
                w.with_dps = w.with_dps.max(d);
            }
        }
    }
    w
}

/// Outside the range: every function refuses (status 1, NaN rates) and so does the host.
fn check_outside(table: &ThermalTable, temp_raw: i8, raw: &[[i16; 3]], got: &[Line]) {
    assert!(matches!(table.apply(raw[0], temp_raw), Err(ThermalError::OutOfRange { .. })), "OUT_TEMP {temp_raw}");
    for g in got {
        assert_eq!(g.status, [1; 3], "OUT_TEMP {temp_raw}");
        assert!(g.rate.iter().chain(&g.hi).chain(&g.with).all(|v| v.is_nan()), "OUT_TEMP {temp_raw}");
    }
}

/// The three readings inside the range (its ends and its middle) and two outside.
fn temperatures(table: &ThermalTable) -> ([i8; 3], [i8; 2]) {
    let [lo, hi] = table.out_temp_range_lsb();
    ([lo, ((i16::from(lo) + i16::from(hi)) / 2) as i8, hi], [lo - 1, hi + 1])
}

/// Runs a compiled export at the three readings inside and the two outside the range; returns
/// the worst differences.
fn run_and_check(e: &Export, table: &ThermalTable, exe: &Path) -> Worst {
    let raw = readings();
    let (inside, outside) = temperatures(table);
    let mut worst = Worst::default();
    for t in inside {
        let w = check_inside(e, table, t, &raw, &run(exe, t, &raw));
        worst.split_dps = worst.split_dps.max(w.split_dps);
        worst.float_dps = worst.float_dps.max(w.float_dps);
        worst.with_dps = worst.with_dps.max(w.with_dps);
    }
    for t in outside {
        check_outside(table, t, &raw[..64], &run(exe, t, &raw[..64]));
    }
    worst
}

const C_MAIN: &str = r#"#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "gyrocal.h"
static unsigned long bits(float f) { uint32_t u; memcpy(&u, &f, sizeof u); return (unsigned long)u; }
static void print3(const float v[3]) { printf(" %08lx %08lx %08lx", bits(v[0]), bits(v[1]), bits(v[2])); }
int main(int argc, char **argv) {
    const int8_t temp_raw = (int8_t)atoi(argc > 1 ? argv[1] : "0");
    int a, b, c, has, s1, s2, s3;
    float t, f[3], w[3], hi[3], lo[3], ww[3];
    while (scanf("%d %d %d %f %d %f %f %f", &a, &b, &c, &t, &has, &f[0], &f[1], &f[2]) == 8) {
        const int16_t raw[3] = {(int16_t)a, (int16_t)b, (int16_t)c};
        s1 = gyrocal_apply(raw, temp_raw, w);
        s2 = gyrocal_apply_split(raw, temp_raw, hi, lo);
        s3 = gyrocal_apply_with(raw, temp_raw, t, has ? f : NULL, ww);
        printf("%d %d %d", s1, s2, s3);
        print3(w); print3(hi); print3(lo); print3(ww);
        printf("\n");
    }
    return 0;
}
"#;

const RUST_MAIN: &str = r#"include!("gyrocal.rs");
fn main() {
    use std::io::{BufRead, Write};
    let temp_raw: i8 = std::env::args().nth(1).unwrap().parse().unwrap();
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    let nan = [f32::NAN; 3];
    for line in std::io::stdin().lock().lines() {
        let line = line.unwrap();
        let v: Vec<&str> = line.split_whitespace().collect();
        let raw = [v[0].parse().unwrap(), v[1].parse().unwrap(), v[2].parse().unwrap()];
        let f: [f32; 3] = [v[5].parse().unwrap(), v[6].parse().unwrap(), v[7].parse().unwrap()];
        let f = (v[4] == "1").then_some(f);
        let w = GYROCAL.apply(raw, temp_raw);
        let s = GYROCAL.apply_split(raw, temp_raw);
        let ww = GYROCAL.apply_with(raw, temp_raw, v[3].parse().unwrap(), f);
        write!(out, "{} {} {}", u8::from(w.is_err()), u8::from(s.is_err()), u8::from(ww.is_err())).unwrap();
        let (hi, lo) = s.unwrap_or((nan, nan));
        for x in w.unwrap_or(nan).iter().chain(&hi).chain(&lo).chain(&ww.unwrap_or(nan)) {
            write!(out, " {:08x}", x.to_bits()).unwrap();
        }
        writeln!(out).unwrap();
    }
}
"#;

/// Compiles the Rust module's test program (after checking the module builds without `std`).
fn rustc(dir: &Path) -> PathBuf {
    let rustc = builds_without_std(dir);
    std::fs::write(dir.join("main.rs"), RUST_MAIN).unwrap();
    let exe = dir.join("apply");
    let o = Command::new(&rustc).args(["--edition", "2021", "-O", "-o"]).arg(&exe).arg(dir.join("main.rs")).output();
    let o = o.unwrap();
    assert!(o.status.success(), "rustc failed:\n{}", String::from_utf8_lossy(&o.stderr));
    exe
}

#[test]
fn thermal_c_header_agrees_with_apply_temp_c_over_all_of_int16_at_three_temperatures() {
    for (n, e) in thermal_exports().iter().enumerate() {
        let table = e.thermal_table().unwrap().unwrap();
        let dir = scratch(&format!("cthermal{n}"));
        let header = e.render(Format::C).unwrap();
        std::fs::write(dir.path().join("gyrocal.h"), &header).unwrap();
        let w = run_and_check(e, &table, &cc(dir.path(), C_MAIN));
        let [lo, hi] = table.out_temp_range_lsb();
        eprintln!(
            "C thermal export {n}, OUT_TEMP {lo}..{hi} ({} rows, {} bytes), vs the model's calibration over {} \
             readings at 3 temperatures: split max {:.2e} °/s (bound {:.2e}), float max {:.2e}, with max {:.2e}",
            table.rows.len(),
            table.table_bytes(),
            readings().len(),
            w.split_dps,
            table.bound_dps(),
            w.float_dps,
            w.with_dps
        );
        assert!(header.contains(&format!("#define GYROCAL_OUT_TEMP_MIN_LSB ({lo})\n")), "{header}");
        assert!(header.contains(&format!("Valid for temp_raw {lo}..{hi} LSB only")), "{header}");
        assert!(header.contains("static inline int gyrocal_apply(const int16_t raw[3], int8_t temp_raw, float"));
    }
}

#[test]
fn thermal_rust_export_agrees_with_apply_temp_c_over_all_of_int16_at_three_temperatures() {
    for (n, e) in thermal_exports().iter().enumerate() {
        let table = e.thermal_table().unwrap().unwrap();
        let dir = scratch(&format!("rustthermal{n}"));
        let module = e.render(Format::Rust).unwrap();
        std::fs::write(dir.path().join("gyrocal.rs"), &module).unwrap();
        let w = run_and_check(e, &table, &rustc(dir.path()));
        eprintln!(
            "Rust thermal export {n} vs the model's calibration: split max {:.2e} °/s, float max {:.2e}, with max {:.2e}",
            w.split_dps, w.float_dps, w.with_dps
        );
        let [lo, hi] = table.out_temp_range_lsb();
        assert!(module.contains(&format!("out_temp_min_lsb: {lo},\n    out_temp_max_lsb: {hi},")), "{module}");
    }
}

/// The table: one row per OUT_TEMP reading whose die temperature is inside the model's range
/// (±2000 °/s fixture: 92 readings over −20.5…70.5 °C), each the model's own calibration there,
/// and the split rows summing back to its (K S)⁻¹ exactly.
#[test]
fn the_table_holds_the_models_calibration_at_every_reading_of_its_range() {
    let e = &thermal_exports()[1];
    let table = e.thermal_table().unwrap().unwrap();
    let m = e.thermal.as_ref().unwrap();
    assert_eq!(table.rows.len(), 91, "die −20.5…70.5 °C at OUT_TEMP 12.3 − T: readings −58…32");
    assert_eq!(table.out_temp_range_lsb(), [-58, 32]);
    let [cold, warm] = table.temp_range_c();
    assert!((cold - -19.7).abs() < 1e-9 && (warm - 70.3).abs() < 1e-9, "{cold} {warm}");
    assert!(m.check_range(cold - 1.0).is_err() && m.check_range(warm + 1.0).is_err());
    for r in &table.rows {
        let cal = m.calibration_at(m.temp_c_from_raw(r.out_temp_lsb)).unwrap();
        assert_eq!(r.calibration, cal);
        for (i, s) in r.split.rows.iter().enumerate() {
            for j in 0..3 {
                assert_eq!(s.m_hi[j] + s.m_mid[j] + s.m_lo[j], r.m_inv_dps_per_count[i][j]);
            }
        }
    }
    // The model moves the correction: the offsets alone by 0.03 °/s/°C over 90 °C.
    let raw = [7000, -3000, 5000];
    let (c, w) = (table.apply(raw, -58).unwrap(), table.apply(raw, 32).unwrap());
    assert!((c[0] - w[0]).abs() > 1.0, "{c:?} {w:?}");
}

/// A calibration without a thermal model exports as before: no table, the one-argument form.
#[test]
fn a_calibration_without_a_thermal_model_exports_as_before() {
    let base = thermal_exports()[0].thermal.as_ref().unwrap().calibration_at(25.0).unwrap();
    let e = Export::from_json(&export_json(base.full_scale, base.m_counts_per_dps, base.offset_counts)).unwrap();
    assert!(e.thermal.is_none() && e.thermal_table().unwrap().is_none());
    let header = e.render(Format::C).unwrap();
    assert!(header.contains("static inline void gyrocal_apply(const int16_t raw[3], float rate_dps[3])"));
    assert!(!header.contains("temp_raw"));
    assert!(!e.render(Format::Rust).unwrap().contains("temp_raw"));
}
