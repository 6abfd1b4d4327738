//! What `host records` prints: a list, one record, two records compared in units of their
//! combined σ, and a production summary across sensors with outliers named.

use super::store::Record;
use statrs::statistics::{Data, OrderStatistics, Statistics};
use std::fmt::Write as _;

/// Output format of `host records list|show|compare`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Aligned columns for a terminal.
    Text,
    /// JSON, for scripts.
    Json,
    /// CSV with a header line, for spreadsheets.
    Csv,
}

/// A record's identity fields as JSON (what `list` gives per record).
fn record_json(r: &Record) -> serde_json::Value {
    serde_json::json!({
        "id": r.id,
        "uid": r.uid,
        "sensor_serial": r.sensor_serial,
        "operator": r.operator,
        "rig": r.rig,
        "calibrated_utc": r.calibrated_utc,
        "host_version": r.host_version,
        "rig_firmware": r.rig_firmware,
        "full_scale_dps": r.full_scale_dps,
        "captures_sha256": r.captures_sha256.split(',').filter(|s| !s.is_empty()).collect::<Vec<_>>(),
        "verdict": r.verdict,
    })
}

const LIST_CSV_HEADER: [&str; 10] = [
    "id",
    "sensor_serial",
    "calibrated_utc",
    "operator",
    "rig",
    "verdict",
    "full_scale_dps",
    "host_version",
    "rig_firmware",
    "captures_sha256",
];

fn csv_text(rows: impl IntoIterator<Item = Vec<String>>) -> String {
    let mut w = csv::Writer::from_writer(Vec::new());
    for row in rows {
        w.write_record(&row).expect("writing CSV to memory");
    }
    String::from_utf8(w.into_inner().expect("flushing CSV to memory")).expect("CSV of UTF-8 strings")
}

fn opt(v: &Option<String>) -> String {
    v.clone().unwrap_or_default()
}

fn num(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| v.to_string())
}

/// `list` in `format`.
pub fn list_as(records: &[Record], format: Format) -> String {
    match format {
        Format::Text => list(records),
        Format::Json => {
            let v: Vec<_> = records.iter().map(record_json).collect();
            serde_json::to_string_pretty(&v).expect("JSON of plain values") + "\n"
        }
        Format::Csv => {
            csv_text(std::iter::once(LIST_CSV_HEADER.map(String::from).to_vec()).chain(records.iter().map(|r| {
                vec![
                    r.id.unwrap_or(0).to_string(),
                    opt(&r.sensor_serial),
                    r.calibrated_utc.clone(),
                    opt(&r.operator),
                    opt(&r.rig),
                    r.verdict.clone(),
                    r.full_scale_dps.to_string(),
                    r.host_version.clone(),
                    opt(&r.rig_firmware),
                    r.captures_sha256.clone(),
                ]
            })))
        }
    }
}

/// `show` in `format`: the text and JSON hold the identity, every parameter, the noise figures
/// and the sensor's previous calibrations with each change in σ (`history`), JSON also the stored
/// calibration.json; CSV one line per parameter (the changes: `compare --format csv`).
pub fn show_as(r: &Record, history: &History, format: Format) -> String {
    match format {
        Format::Text => {
            show(r)
                + "
" + &history.text()
        }
        Format::Json => {
            let mut v = record_json(r);
            v["history"] = history.json();
            v["parameters"] = serde_json::to_value(&r.params).expect("JSON of plain values");
            v["noise"] = serde_json::to_value(&r.noise).expect("JSON of plain values");
            v["thermal"] = serde_json::to_value(&r.thermal).expect("JSON of plain values");
            v["calibration"] = serde_json::from_str(&r.result_json).unwrap_or(serde_json::Value::Null);
            serde_json::to_string_pretty(&v).expect("JSON of plain values") + "\n"
        }
        Format::Csv => csv_text(
            std::iter::once(vec!["id".into(), "name".into(), "value".into(), "sigma".into(), "unit".into()]).chain(
                r.params.iter().chain(r.thermal.iter().flat_map(|t| &t.coefficients)).map(|p| {
                    vec![
                        r.id.unwrap_or(0).to_string(),
                        p.name.clone(),
                        p.value.to_string(),
                        num(p.sigma),
                        p.unit.clone(),
                    ]
                }),
            ),
        ),
    }
}

/// `compare` in `format`: one entry per parameter with both values, the change and z.
pub fn compare_as(a: &Record, b: &Record, format: Format) -> String {
    let ch = changes(a, b);
    let changed = |c: &Change| c.z.is_some_and(|z| z.abs() > CHANGED_Z);
    match format {
        Format::Text => compare(a, b),
        Format::Json => {
            let params: Vec<_> = ch
                .iter()
                .map(|c| {
                    serde_json::json!({
                        "name": c.name, "unit": c.unit, "a": c.a, "b": c.b, "change": c.b - c.a,
                        "z": c.z, "changed": changed(c),
                    })
                })
                .collect();
            let v = serde_json::json!({
                "a": record_json(a),
                "b": record_json(b),
                "changed_beyond_sigma": CHANGED_Z,
                "parameters": params,
                "thermal_coefficients_only_in": {"a": only_in_one(a, b).0, "b": only_in_one(a, b).1},
            });
            serde_json::to_string_pretty(&v).expect("JSON of plain values") + "\n"
        }
        Format::Csv => csv_text(
            std::iter::once(["name", "unit", "a", "b", "change", "z", "changed"].map(String::from).to_vec()).chain(
                ch.iter().map(|c| {
                    vec![
                        c.name.clone(),
                        c.unit.clone(),
                        c.a.to_string(),
                        c.b.to_string(),
                        (c.b - c.a).to_string(),
                        num(c.z),
                        changed(c).to_string(),
                    ]
                }),
            ),
        ),
    }
}

/// One line per record.
pub fn list(records: &[Record]) -> String {
    let mut o = String::from("   id  sensor            calibrated (UTC)      operator      rig           verdict\n");
    for r in records {
        let _ = writeln!(
            o,
            "{:5}  {:16}  {:20}  {:12}  {:12}  {}",
            r.id.unwrap_or(0),
            r.sensor_serial.as_deref().unwrap_or("-"),
            r.calibrated_utc,
            r.operator.as_deref().unwrap_or("-"),
            r.rig.as_deref().unwrap_or("-"),
            r.verdict
        );
    }
    o
}

/// One record in full (without the stored JSON).
pub fn show(r: &Record) -> String {
    let mut o = String::new();
    let s = |v: &Option<String>| v.clone().unwrap_or_else(|| "-".into());
    let _ = writeln!(o, "record {}  ({})", r.id.unwrap_or(0), r.uid);
    let _ = writeln!(o, "sensor {}  operator {}  rig {}", s(&r.sensor_serial), s(&r.operator), s(&r.rig));
    let _ = writeln!(
        o,
        "calibrated {} by host {}; rig firmware {}; ±{} °/s",
        r.calibrated_utc,
        r.host_version,
        s(&r.rig_firmware),
        r.full_scale_dps
    );
    let _ = writeln!(o, "verdict: {}", r.verdict);
    for (i, h) in r.captures_sha256.split(',').filter(|h| !h.is_empty()).enumerate() {
        let _ = writeln!(o, "capture {} sha256 {h}", i + 1);
    }
    let _ = writeln!(o, "\nparameter                      value            1-σ  unit");
    for p in &r.params {
        let sigma = p.sigma.map_or("-".to_string(), |s| format!("{s:.3e}"));
        let _ = writeln!(o, "{:28} {:>+14.6}  {:>11}  {}", p.name, p.value, sigma, p.unit);
    }
    if !r.noise.is_empty() {
        let _ = writeln!(o, "\naxis  ARW [°/√h]  bias instability [°/h]  RRW [°/h/√h]");
        for n in &r.noise {
            let f = |v: Option<f64>| v.map_or("-".to_string(), crate::allan::figure);
            let _ = writeln!(
                o,
                "  {}   {:>9}  {:>22}  {:>12}",
                n.axis,
                f(n.arw_deg_per_sqrt_h),
                f(n.bias_instability_deg_per_h),
                f(n.rrw_deg_per_h_per_sqrt_h)
            );
        }
    }
    if let Some(t) = &r.thermal {
        o.push_str(&thermal_text(t));
    }
    o
}

/// A record's thermal model: where it holds, then every coefficient with its σ.
fn thermal_text(t: &super::ThermalRecord) -> String {
    let mut o = String::new();
    let setpoints: Vec<String> = t.setpoints_c.iter().map(|s| format!("{s}")).collect();
    let _ = writeln!(
        o,
        "\nthermal model: setpoints {} °C; holds for die {:.2}…{:.2} °C (die °C = {:.3} − OUT_TEMP); \
         polynomials in T − {} °C",
        setpoints.join(", "),
        t.range_c[0],
        t.range_c[1],
        t.out_temp_at_0c,
        t.reference_c
    );
    let _ = writeln!(o, "coefficient                    value            1-σ  unit");
    for p in &t.coefficients {
        let sigma = p.sigma.map_or("-".to_string(), |s| format!("{s:.3e}"));
        let _ = writeln!(o, "{:28} {:>+14.6e}  {:>11}  {}", p.name, p.value, sigma, p.unit);
    }
    o
}

/// One parameter of two records: the change and its size in combined σ.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    /// Parameter name.
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Value in the first record.
    pub a: f64,
    /// Value in the second.
    pub b: f64,
    /// (b − a) / √(σa² + σb²), when both σ are known and not both zero.
    pub z: Option<f64>,
}

/// Change beyond which a parameter is flagged as changed, in combined σ: 3σ, two-sided 0.27 %
/// false-alarm rate per parameter under Gaussian errors.
pub const CHANGED_Z: f64 = 3.0;

/// Every parameter present in both, in the first record's order, then every thermal
/// coefficient present in both (thermal records: a coefficient of an order one model did not
/// choose is in [`only_in_one`]).
pub fn changes(a: &Record, b: &Record) -> Vec<Change> {
    let coefficients = |r: &Record| r.thermal.as_ref().map(|t| t.coefficients.clone()).unwrap_or_default();
    let (ca, cb) = (coefficients(a), coefficients(b));
    a.params
        .iter()
        .chain(&ca)
        .filter_map(|pa| {
            let pb = b.params.iter().chain(&cb).find(|p| p.name == pa.name)?;
            let z = match (pa.sigma, pb.sigma) {
                (Some(sa), Some(sb)) if sa.hypot(sb) > 0.0 => Some((pb.value - pa.value) / sa.hypot(sb)),
                _ => None,
            };
            Some(Change { name: pa.name.clone(), unit: pa.unit.clone(), a: pa.value, b: pb.value, z })
        })
        .collect()
}

/// The thermal coefficients only one of two thermal records holds (their curves' orders
/// differ), as `(in A only, in B only)`; empty unless both are thermal.
pub fn only_in_one(a: &Record, b: &Record) -> (Vec<String>, Vec<String>) {
    let (Some(ta), Some(tb)) = (&a.thermal, &b.thermal) else { return (Vec::new(), Vec::new()) };
    let missing = |x: &super::ThermalRecord, y: &super::ThermalRecord| -> Vec<String> {
        x.coefficients
            .iter()
            .filter(|p| !y.coefficients.iter().any(|q| q.name == p.name))
            .map(|p| p.name.clone())
            .collect()
    };
    (missing(ta, tb), missing(tb, ta))
}

/// The comparison table.
pub fn compare(a: &Record, b: &Record) -> String {
    let mut o = String::new();
    let s = |v: &Option<String>| v.clone().unwrap_or_else(|| "-".into());
    let _ = writeln!(o, "A: record {} of {}, {}", a.id.unwrap_or(0), s(&a.sensor_serial), a.calibrated_utc);
    let _ = writeln!(o, "B: record {} of {}, {}", b.id.unwrap_or(0), s(&b.sensor_serial), b.calibrated_utc);
    if a.sensor_serial != b.sensor_serial {
        let _ = writeln!(o, "note: different sensors");
    }
    let _ =
        writeln!(o, "\nparameter                           A               B           B − A     z = (B−A)/σ  unit");
    let ch = changes(a, b);
    for c in &ch {
        let z = c.z.map_or("      -".to_string(), |z| format!("{z:+8.2}"));
        let flag = if c.z.is_some_and(|z| z.abs() > CHANGED_Z) { "  changed" } else { "" };
        let _ =
            writeln!(o, "{:28} {:>+14.6}  {:>+14.6}  {:>+12.3e}  {z}  {}{flag}", c.name, c.a, c.b, c.b - c.a, c.unit);
    }
    let n = ch.iter().filter(|c| c.z.is_some_and(|z| z.abs() > CHANGED_Z)).count();
    let _ = writeln!(o, "\n{n} of {} parameters changed by more than {CHANGED_Z} σ", ch.len());
    o.push_str(&thermal_notes(a, b));
    o
}

/// What a comparison of thermal models should say besides the coefficients: a record without
/// one, different ranges, coefficients of orders only one model chose.
fn thermal_notes(a: &Record, b: &Record) -> String {
    let mut o = String::new();
    match (&a.thermal, &b.thermal) {
        (None, None) => {}
        (Some(_), None) | (None, Some(_)) => {
            let which = if a.thermal.is_some() { "A" } else { "B" };
            let _ = writeln!(o, "note: only {which} holds a thermal model; its coefficients are not compared");
        }
        (Some(ta), Some(tb)) => {
            if ta.range_c != tb.range_c {
                let _ = writeln!(
                    o,
                    "note: the thermal models hold for die {:.2}…{:.2} °C (A) and {:.2}…{:.2} °C (B)",
                    ta.range_c[0], ta.range_c[1], tb.range_c[0], tb.range_c[1]
                );
            }
            let (only_a, only_b) = only_in_one(a, b);
            for (which, names) in [("A", only_a), ("B", only_b)] {
                if !names.is_empty() {
                    let _ = writeln!(o, "thermal coefficients in {which} only (orders differ): {}", names.join(", "));
                }
            }
        }
    }
    o
}

/// The parameters a calibration's history lists per axis: the sensitivity and the tilt of the
/// sensing axis from its package axis (its direction), `k_{axis}` and `tilt_{axis}`.
pub const HISTORY_QUANTITIES: [(&str, &str); 2] = [("k", "counts/(deg/s)"), ("tilt", "deg")];

/// One earlier calibration of a sensor against this one: [`changes`] from it to this.
#[derive(Debug, Clone, PartialEq)]
pub struct Earlier {
    /// The earlier record's id.
    pub id: i64,
    /// When it was calibrated, UTC.
    pub calibrated_utc: String,
    /// Every parameter in both, a = then, b = this, z = (this − then)/√(σ_this² + σ_then²).
    pub changes: Vec<Change>,
}

impl Earlier {
    /// The earlier record `then` against `this`.
    pub fn of(then: &Record, this: &Record) -> Self {
        Earlier { id: then.id.unwrap_or(0), calibrated_utc: then.calibrated_utc.clone(), changes: changes(then, this) }
    }

    /// The change of parameter `name`.
    pub fn change(&self, name: &str) -> Option<&Change> {
        self.changes.iter().find(|c| c.name == name)
    }

    /// The parameters that changed beyond [`CHANGED_Z`] combined σ.
    pub fn beyond(&self) -> Vec<&Change> {
        self.changes.iter().filter(|c| c.z.is_some_and(|z| z.abs() > CHANGED_Z)).collect()
    }
}

/// A calibration's history: the same sensor's earlier records, or why there is none to show.
#[derive(Debug, Clone, PartialEq)]
pub enum History {
    /// Not looked up, and why (no database, no serial, a database that cannot be read).
    Unread(String),
    /// The sensor and its earlier calibrations, oldest first (empty: the first one).
    Read {
        /// Sensor serial.
        serial: String,
        /// Earlier calibrations against this one.
        earlier: Vec<Earlier>,
    },
}

impl History {
    /// The history of `this` given the sensor's `earlier` records (with their parameters).
    pub fn of(serial: &str, this: &Record, earlier: &[Record]) -> Self {
        History::Read { serial: serial.to_string(), earlier: earlier.iter().map(|e| Earlier::of(e, this)).collect() }
    }

    /// One line saying what the history holds, or why it is not there.
    pub fn headline(&self) -> String {
        match self {
            History::Unread(why) => format!("Previous calibrations: not looked up ({why})."),
            History::Read { serial, earlier } if earlier.is_empty() => {
                format!("No previous calibration of {serial} in the records database.")
            }
            History::Read { serial, earlier } => format!(
                "{} previous calibration(s) of {serial}; Δ/σ = (this − then)/√(σ_this² + σ_then²), the change \
                 in units of the combined standard uncertainty; |Δ|/σ > {CHANGED_Z} is a change beyond the uncertainty.",
                earlier.len()
            ),
        }
    }

    /// As JSON: the state and, per earlier record, every parameter's change.
    pub fn json(&self) -> serde_json::Value {
        match self {
            History::Unread(why) => serde_json::json!({ "looked_up": false, "reason": why }),
            History::Read { serial, earlier } => serde_json::json!({
                "looked_up": true,
                "sensor_serial": serial,
                "changed_beyond_sigma": CHANGED_Z,
                "previous": earlier.iter().map(|e| serde_json::json!({
                    "id": e.id,
                    "calibrated_utc": e.calibrated_utc,
                    "parameters": e.changes.iter().map(|c| serde_json::json!({
                        "name": c.name, "unit": c.unit, "then": c.a, "this": c.b, "change": c.b - c.a,
                        "z": c.z, "changed": c.z.is_some_and(|z| z.abs() > CHANGED_Z),
                    })).collect::<Vec<_>>(),
                    "changed": e.beyond().iter().map(|c| c.name.as_str()).collect::<Vec<_>>(),
                })).collect::<Vec<_>>(),
            }),
        }
    }

    /// The rows of the history table, one per earlier record and axis: record, date, axis, then
    /// per [`HISTORY_QUANTITIES`] the earlier value and Δ/σ, and the quantities beyond 3σ.
    pub fn rows(&self) -> Vec<Vec<String>> {
        let History::Read { earlier, .. } = self else { return Vec::new() };
        let mut rows = Vec::new();
        for e in earlier {
            for ax in ['x', 'y', 'z'] {
                let mut row = vec![e.id.to_string(), e.calibrated_utc.clone(), ax.to_string()];
                let mut flagged = Vec::new();
                for (q, _) in HISTORY_QUANTITIES {
                    let c = e.change(&format!("{q}_{ax}"));
                    row.push(c.map_or("-".into(), |c| format!("{:.6}", c.a)));
                    row.push(c.and_then(|c| c.z).map_or("-".into(), |z| format!("{z:+.2}")));
                    if c.and_then(|c| c.z).is_some_and(|z| z.abs() > CHANGED_Z) {
                        flagged.push(q);
                    }
                }
                row.push(if flagged.is_empty() { "no".into() } else { flagged.join(", ") });
                rows.push(row);
            }
        }
        rows
    }

    /// The history table's header, matching [`History::rows`].
    pub fn header() -> Vec<String> {
        let mut h = vec!["record".to_string(), "calibrated (UTC)".into(), "axis".into()];
        for (q, unit) in HISTORY_QUANTITIES {
            h.push(format!("{q} then [{unit}]"));
            h.push(format!("Δ{q}/σ"));
        }
        h.push(format!("beyond {CHANGED_Z}σ"));
        h
    }

    /// Per earlier record, every parameter beyond 3σ (not only k and tilt), one line each.
    pub fn beyond_lines(&self) -> Vec<String> {
        let History::Read { earlier, .. } = self else { return Vec::new() };
        earlier
            .iter()
            .map(|e| {
                let b = e.beyond();
                let with_z = e.changes.iter().filter(|c| c.z.is_some()).count();
                if b.is_empty() {
                    format!("record {}: none of {with_z} parameters changed beyond {CHANGED_Z} σ", e.id)
                } else {
                    let names: Vec<String> =
                        b.iter().map(|c| format!("{} ({:+.1} σ)", c.name, c.z.unwrap_or(f64::NAN))).collect();
                    format!(
                        "record {}: {} of {with_z} parameters changed beyond {CHANGED_Z} σ: {}",
                        e.id,
                        b.len(),
                        names.join(", ")
                    )
                }
            })
            .collect()
    }

    /// As text, for `host records show`.
    pub fn text(&self) -> String {
        let mut o = self.headline() + "\n";
        let rows = self.rows();
        if rows.is_empty() {
            return o;
        }
        let mut table = vec![Self::header()];
        table.extend(rows);
        let widths: Vec<usize> =
            (0..table[0].len()).map(|j| table.iter().map(|r| r[j].chars().count()).max().unwrap_or(0)).collect();
        for r in &table {
            let cells: Vec<String> = r.iter().zip(&widths).map(|(c, w)| format!("{c:>w$}")).collect();
            let _ = writeln!(o, "{}", cells.join("  ").trim_end());
        }
        for l in self.beyond_lines() {
            let _ = writeln!(o, "{l}");
        }
        o
    }
}

/// Robust spread: median and MAD-based σ (1.4826 · MAD, the σ of a Gaussian with that MAD).
pub fn median_and_robust_sigma(values: &[f64]) -> (f64, f64) {
    let med = median(values);
    let dev: Vec<f64> = values.iter().map(|v| (v - med).abs()).collect();
    (med, 1.4826 * median(&dev))
}

/// The median (the mean of the two middle values for an even count; NaN of nothing): `statrs`'s
/// order statistics, selecting in place on a copy.
fn median(values: &[f64]) -> f64 {
    Data::new(values.to_vec()).median()
}

/// Robust z beyond which a sensor is named an outlier: 3.5, the modified z-score threshold of
/// Iglewicz and Hoaglin ("How to Detect and Handle Outliers", ASQC 1993).
pub const OUTLIER_Z: f64 = 3.5;

/// Distribution of one parameter across sensors.
#[derive(Debug, Clone, PartialEq)]
pub struct Distribution {
    /// Parameter.
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Sensors with a value.
    pub n: usize,
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation.
    pub sd: f64,
    /// Minimum, median, maximum.
    pub min: f64,
    /// Median.
    pub median: f64,
    /// Maximum.
    pub max: f64,
    /// Outliers: (sensor, value, robust z).
    pub outliers: Vec<(String, f64, f64)>,
    /// Values, for the histogram.
    pub values: Vec<f64>,
}

/// Parameters in the production summary: sensitivity departures, offsets, tilts,
/// non-orthogonality (then the noise figures where recorded).
const SUMMARY_PARAMS: &[&str] = &[
    "k_x_vs_nominal",
    "k_y_vs_nominal",
    "k_z_vs_nominal",
    "offset_x",
    "offset_y",
    "offset_z",
    "tilt_x",
    "tilt_y",
    "tilt_z",
    "non_orthogonality_xy",
    "non_orthogonality_xz",
    "non_orthogonality_yz",
];

/// Distributions over the latest record of each sensor.
pub fn distributions(latest: &[Record]) -> Vec<Distribution> {
    let mut out = Vec::new();
    for name in SUMMARY_PARAMS {
        let vals: Vec<(String, f64)> = latest
            .iter()
            .filter_map(|r| Some((r.sensor_serial.clone()?, r.params.iter().find(|p| p.name == *name)?.value)))
            .collect();
        let unit = latest.iter().flat_map(|r| &r.params).find(|p| p.name == *name).map(|p| p.unit.clone());
        out.extend(distribution(name, &unit.unwrap_or_default(), &vals));
    }
    // Noise figures, for the sensors whose latest session had a static stretch.
    type Figure = fn(&super::NoiseRow) -> Option<f64>;
    let figures: [(&str, &str, Figure); 3] = [
        ("arw", "deg/sqrt(h)", |n| n.arw_deg_per_sqrt_h),
        ("bias_instability", "deg/h", |n| n.bias_instability_deg_per_h),
        ("rrw", "deg/h/sqrt(h)", |n| n.rrw_deg_per_h_per_sqrt_h),
    ];
    for (name, unit, f) in figures {
        for axis in ['x', 'y', 'z'] {
            let vals: Vec<(String, f64)> = latest
                .iter()
                .filter_map(|r| Some((r.sensor_serial.clone()?, f(r.noise.iter().find(|n| n.axis == axis)?)?)))
                .collect();
            out.extend(distribution(&format!("{name}_{axis}"), unit, &vals));
        }
    }
    out
}

/// Statistics of (sensor, value) pairs; None without any.
fn distribution(name: &str, unit: &str, vals: &[(String, f64)]) -> Option<Distribution> {
    if vals.is_empty() {
        return None;
    }
    let v: Vec<f64> = vals.iter().map(|(_, x)| *x).collect();
    let n = v.len();
    let mean = v.iter().mean();
    // The sample standard deviation (n − 1); one sensor has no spread rather than NaN.
    let sd = if n > 1 { v.iter().std_dev() } else { 0.0 };
    let (med, rs) = median_and_robust_sigma(&v);
    let outliers = vals
        .iter()
        .filter(|_| rs > 0.0)
        .map(|(s, x)| (s.clone(), *x, (x - med) / rs))
        .filter(|(_, _, z)| z.abs() > OUTLIER_Z)
        .collect();
    Some(Distribution {
        name: name.to_string(),
        unit: unit.to_string(),
        n,
        mean,
        sd,
        min: v.iter().copied().fold(f64::INFINITY, f64::min),
        median: med,
        max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        outliers,
        values: v,
    })
}

/// A one-line histogram, `width` bins from min to max, heights as ` ▁▂▃▄▅▆▇█`.
pub fn sparkline(values: &[f64], width: usize) -> String {
    const BARS: [char; 9] = [' ', '▁', '▂', '▃', '▄', '▅', '▆', '▇', '█'];
    let (lo, hi) = values.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
    let mut bins = vec![0usize; width];
    for &v in values {
        let i = if hi > lo { (((v - lo) / (hi - lo)) * width as f64) as usize } else { width / 2 };
        bins[i.min(width - 1)] += 1;
    }
    let top = *bins.iter().max().unwrap_or(&1);
    bins.iter().map(|&b| BARS[(b * 8).div_ceil(top).min(8)]).collect()
}

/// The production summary.
pub fn summary(latest: &[Record]) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "{} sensors (latest calibration of each; calibrations stored without --sensor are not counted)\n",
        latest.len()
    );
    let _ = writeln!(
        o,
        "parameter              unit                 mean        sd         min      median         max  histogram (min..max)"
    );
    let dists = distributions(latest);
    for d in &dists {
        let _ = writeln!(
            o,
            "{:22} {:13} {:>+11.4} {:>9.4} {:>+11.4} {:>+11.4} {:>+11.4}  |{}|",
            d.name,
            d.unit,
            d.mean,
            d.sd,
            d.min,
            d.median,
            d.max,
            sparkline(&d.values, 24)
        );
    }
    let _ = writeln!(o, "\nOutliers (robust z = (x − median)/(1.4826·MAD) beyond ±{OUTLIER_Z}):");
    let mut any = false;
    for d in &dists {
        for (s, v, z) in &d.outliers {
            any = true;
            let _ = writeln!(o, "  {s}: {} = {v:+.4} {} (z {z:+.1})", d.name, d.unit);
        }
    }
    if !any {
        let _ = writeln!(o, "  none");
    }
    o
}

/// Bins of each summary histogram: √n rounded for the 20-100 sensors of a production batch
/// gives 4-10; 10 keeps the figures comparable across batches.
const HISTOGRAM_BINS: usize = 10;

/// Counts in `HISTOGRAM_BINS` equal bins from min to max, with each bin's centre.
pub fn histogram(values: &[f64]) -> Vec<(f64, usize)> {
    let (lo, hi) = values.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
    let width = if hi > lo { (hi - lo) / HISTOGRAM_BINS as f64 } else { 1.0 };
    let mut counts = vec![0usize; HISTOGRAM_BINS];
    for &v in values {
        counts[(((v - lo) / width) as usize).min(HISTOGRAM_BINS - 1)] += 1;
    }
    counts.into_iter().enumerate().map(|(i, c)| (lo + (i as f64 + 0.5) * width, c)).collect()
}

/// The production summary as an HTML page: the table, one histogram per parameter, outliers.
pub fn summary_html(latest: &[Record]) -> String {
    use crate::report::plots::{bar_chart, BarSeries, PlotSpec};
    let mut doc = crate::report::Document::new(format!("Calibration records: {} sensors", latest.len()));
    let dists = distributions(latest);
    doc.paragraph(
        "Latest calibration of each sensor (calibrations stored without --sensor are not counted). Outliers: \
         robust z = (x − median)/(1.4826·MAD) beyond ±3.5.",
    );
    doc.table(
        "Distributions across sensors",
        &["parameter", "unit", "n", "mean", "sd", "min", "median", "max"],
        dists
            .iter()
            .map(|d| {
                vec![
                    d.name.clone(),
                    d.unit.clone(),
                    d.n.to_string(),
                    format!("{:+.4}", d.mean),
                    format!("{:.4}", d.sd),
                    format!("{:+.4}", d.min),
                    format!("{:+.4}", d.median),
                    format!("{:+.4}", d.max),
                ]
            })
            .collect(),
    );
    let outliers: Vec<String> = dists
        .iter()
        .flat_map(|d| {
            d.outliers.iter().map(move |(s, v, z)| format!("{s}: {} = {v:+.4} {} (z {z:+.1})", d.name, d.unit))
        })
        .collect();
    if outliers.is_empty() {
        doc.findings(["No outlier."]);
    } else {
        doc.findings(outliers);
    }
    for d in &dists {
        let h = histogram(&d.values);
        let spec = PlotSpec::new(format!("{} across sensors", d.name), format!("{} [{}]", d.name, d.unit), "sensors")
            .with_size(800, 300);
        let cats: Vec<String> = h.iter().map(|(c, _)| format!("{c:+.3}")).collect();
        let series = [BarSeries {
            label: "sensors per bin".into(),
            values: h.iter().map(|(_, n)| *n as f64).collect(),
            colour: 0,
        }];
        doc.figure_result(bar_chart(&spec, &cats, &series, None), format!("{}: histogram, bin centres", d.name));
    }
    doc.render()
}
