//! Flat JSON and CSV: every number of the correction, its 1-σ where known, and the identity,
//! for spreadsheets, databases and scripts that should not parse the full report.

use super::Export;
use serde_json::json;
use std::fmt::Write as _;

/// (name, value, 1-σ or NaN, unit), in a fixed order.
pub fn rows(e: &Export) -> Vec<(String, f64, f64, &'static str)> {
    let axes = ['x', 'y', 'z'];
    let mut out = Vec::new();
    let sig = e.sigma;
    for i in 0..3 {
        for j in 0..3 {
            let s = sig.map_or(f64::NAN, |s| s.m_counts_per_dps[i][j]);
            out.push((format!("m_{}{}", axes[i], axes[j]), e.calibration.m_counts_per_dps[i][j], s, "counts/(deg/s)"));
        }
    }
    for (i, ax) in axes.iter().enumerate() {
        let s = sig.map_or(f64::NAN, |s| s.offset_counts[i]);
        out.push((format!("offset_{ax}"), e.calibration.offset_counts[i], s, "counts"));
    }
    for i in 0..3 {
        for j in 0..3 {
            out.push((format!("m_inv_{}{}", axes[i], axes[j]), e.m_inv_dps_per_count[i][j], f64::NAN, "(deg/s)/count"));
        }
    }
    let b = e.offset_rate_dps();
    for (ax, bi) in axes.iter().zip(b) {
        out.push((format!("offset_rate_{ax}"), bi, f64::NAN, "deg/s"));
    }
    out
}

/// JSON: identity, settings and one member per parameter.
pub fn render_json(e: &Export) -> String {
    let params: serde_json::Map<String, serde_json::Value> = rows(e)
        .into_iter()
        .map(|(name, v, s, unit)| {
            (name, json!({"value": v, "sigma": if s.is_nan() { None } else { Some(s) }, "unit": unit}))
        })
        .collect();
    let doc = json!({
        "sensor_serial": e.serial(),
        "date_utc": e.date(),
        "model": e.calibration.model,
        "full_scale_dps": e.calibration.full_scale.range_dps(),
        "odr_hz": e.gyro.map(|g| g.odr.hz()),
        "bandwidth_bits": e.gyro.map(|g| g.bandwidth.bw_bits()),
        "formula": "rate_dps = m_inv * raw_counts - offset_rate = m_inv * (raw_counts - offset)",
        "parameters": params,
        "provenance": e.provenance,
    });
    serde_json::to_string_pretty(&doc).expect("plain data serialises") + "\n"
}

/// CSV: `name,value,sigma,unit`, identity first (sigma empty where unknown). Written without the
/// `csv` crate: four fixed columns whose only free text, serial and date, is always quoted here.
pub fn render_csv(e: &Export) -> String {
    let mut o = String::from("name,value,sigma,unit\n");
    let q = |s: &str| format!("\"{}\"", s.replace('"', "\"\""));
    let _ = writeln!(o, "sensor_serial,{},,", q(e.serial()));
    let _ = writeln!(o, "date_utc,{},,", q(e.date()));
    let _ = writeln!(o, "full_scale,{},,deg/s", e.calibration.full_scale.range_dps());
    if let Some(g) = e.gyro {
        let _ = writeln!(o, "odr,{},,Hz", g.odr.hz());
        let _ = writeln!(o, "bandwidth_bits,{},,", g.bandwidth.bw_bits());
    }
    for (name, v, s, unit) in rows(e) {
        let s = if s.is_nan() { String::new() } else { format!("{s:e}") };
        let _ = writeln!(o, "{name},{v:e},{s},{unit}");
    }
    o
}
