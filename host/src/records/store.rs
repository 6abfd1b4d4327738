//! The records schema, its migrations and every query, written once for both backends.

use super::db::{Conn, Dialect, Val};
use anyhow::{bail, Context, Result};

/// Advisory-lock key under which PostgreSQL migrations run, so concurrent first connections
/// (8 rigs starting at once) apply each migration exactly once. Any fixed i64 does; this one is
/// "gyrocal" in ASCII.
const MIGRATION_LOCK_KEY: i64 = 0x67_79_72_6f_63_61_6c;

/// One schema change. `{id}` in the SQL stands for the auto-numbered key, the only DDL the two
/// dialects spell differently.
struct Migration {
    version: i64,
    what: &'static str,
    sql: &'static str,
}

/// The schema, in order. Never edit a released migration: add one.
const MIGRATIONS: &[Migration] = &[
    Migration {
        version: 1,
        what: "calibrations and their parameters",
        sql: "
CREATE TABLE calibration (
    id {id},
    record_uid TEXT NOT NULL UNIQUE,
    sensor_serial TEXT,
    operator TEXT,
    rig TEXT,
    calibrated_utc TEXT NOT NULL,
    host_version TEXT NOT NULL,
    rig_firmware TEXT,
    full_scale_dps BIGINT NOT NULL,
    captures_sha256 TEXT NOT NULL,
    verdict TEXT NOT NULL,
    result_json TEXT NOT NULL
);
CREATE INDEX calibration_by_sensor ON calibration (sensor_serial, id);
CREATE TABLE parameter (
    calibration_id BIGINT NOT NULL REFERENCES calibration (id),
    name TEXT NOT NULL,
    value DOUBLE PRECISION NOT NULL,
    sigma DOUBLE PRECISION,
    unit TEXT NOT NULL,
    PRIMARY KEY (calibration_id, name)
);",
    },
    Migration {
        version: 2,
        what: "noise figures from an Allan analysis, per axis",
        sql: "
CREATE TABLE noise (
    calibration_id BIGINT NOT NULL REFERENCES calibration (id),
    axis TEXT NOT NULL,
    arw_deg_per_sqrt_h DOUBLE PRECISION,
    bias_instability_deg_per_h DOUBLE PRECISION,
    rrw_deg_per_h_per_sqrt_h DOUBLE PRECISION,
    PRIMARY KEY (calibration_id, axis)
);",
    },
    Migration {
        version: 3,
        what: "thermal models: range and polynomial coefficients with their sigma",
        sql: "
CREATE TABLE thermal_model (
    calibration_id BIGINT NOT NULL PRIMARY KEY REFERENCES calibration (id),
    reference_c DOUBLE PRECISION NOT NULL,
    range_min_c DOUBLE PRECISION NOT NULL,
    range_max_c DOUBLE PRECISION NOT NULL,
    out_temp_at_0c DOUBLE PRECISION NOT NULL,
    setpoints_c TEXT NOT NULL
);
CREATE TABLE thermal_coefficient (
    calibration_id BIGINT NOT NULL REFERENCES thermal_model (calibration_id),
    name TEXT NOT NULL,
    value DOUBLE PRECISION NOT NULL,
    sigma DOUBLE PRECISION,
    unit TEXT NOT NULL,
    PRIMARY KEY (calibration_id, name)
);",
    },
];

/// Latest schema version this program writes.
pub const SCHEMA_VERSION: i64 = 3;

fn ddl(dialect: Dialect, sql: &str) -> String {
    let id = match dialect {
        Dialect::Sqlite => "INTEGER PRIMARY KEY AUTOINCREMENT",
        Dialect::Postgres => "BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY",
    };
    sql.replace("{id}", id)
}

/// Brings the schema to `target` (normally [`SCHEMA_VERSION`]); returns the version found.
pub fn migrate_to(c: &mut dyn Conn, target: i64) -> Result<i64> {
    c.begin_exclusive(MIGRATION_LOCK_KEY)?;
    let r = (|| {
        c.batch("CREATE TABLE IF NOT EXISTS schema_migration (version BIGINT PRIMARY KEY, what TEXT NOT NULL, applied_utc TEXT NOT NULL)")?;
        let found = c.query("SELECT COALESCE(MAX(version), 0) FROM schema_migration", &[])?[0][0].int().unwrap_or(0);
        if found > SCHEMA_VERSION {
            bail!("the records database has schema v{found}, newer than this host's v{SCHEMA_VERSION}: update host");
        }
        for m in MIGRATIONS.iter().filter(|m| m.version > found && m.version <= target) {
            c.batch(&ddl(c.dialect(), m.sql)).with_context(|| format!("migration {} ({})", m.version, m.what))?;
            c.query(
                "INSERT INTO schema_migration (version, what, applied_utc) VALUES ($1, $2, $3)",
                &[Val::Int(m.version), Val::Text(Some(m.what.into())), Val::Text(Some(crate::provenance::utc_now()))],
            )?;
        }
        Ok(found)
    })();
    c.batch(if r.is_ok() { "COMMIT" } else { "ROLLBACK" })?;
    r
}

/// The schema version in the database.
pub fn schema_version(c: &mut dyn Conn) -> Result<i64> {
    Ok(c.query("SELECT COALESCE(MAX(version), 0) FROM schema_migration", &[])?[0][0].int().unwrap_or(0))
}

/// One parameter of a calibration.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Param {
    /// Name, e.g. `tilt_x_deg`.
    pub name: String,
    /// Value.
    pub value: f64,
    /// 1-σ, where the calibration gives one.
    pub sigma: Option<f64>,
    /// Unit.
    pub unit: String,
}

/// Noise figures of one axis.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct NoiseRow {
    /// Axis name.
    pub axis: char,
    /// Angle random walk, °/√h.
    pub arw_deg_per_sqrt_h: Option<f64>,
    /// Bias instability, °/h.
    pub bias_instability_deg_per_h: Option<f64>,
    /// Rate random walk, °/h/√h.
    pub rrw_deg_per_h_per_sqrt_h: Option<f64>,
}

impl From<&crate::allan::AxisNoise> for NoiseRow {
    fn from(a: &crate::allan::AxisNoise) -> Self {
        let f = |v: f64| v.is_finite().then_some(v);
        NoiseRow {
            axis: a.axis,
            arw_deg_per_sqrt_h: f(a.arw_deg_per_sqrt_h),
            bias_instability_deg_per_h: f(a.bias_instability_deg_per_h),
            rrw_deg_per_h_per_sqrt_h: f(a.rrw_deg_per_h_per_sqrt_h),
        }
    }
}

/// A thermal calibration's model as its record holds it: where it holds and each polynomial
/// coefficient with its σ (`thermal_{axis}_{quantity}_c{degree}`, the coefficient of
/// `(T − reference_c)^degree`; [`ThermalRecord::of`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ThermalRecord {
    /// Temperature the polynomials are expanded about, °C.
    pub reference_c: f64,
    /// Die temperatures the model holds for, °C.
    pub range_c: [f64; 2],
    /// Die °C = `out_temp_at_0c − OUT_TEMP`.
    pub out_temp_at_0c: f64,
    /// The chamber setpoints, °C, coldest first.
    pub setpoints_c: Vec<f64>,
    /// Every coefficient of every curve, in curve order (as stored: by name).
    pub coefficients: Vec<Param>,
}

/// A stored calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Database key (None before it is stored).
    pub id: Option<i64>,
    /// Unique per calibration, made by the writer: storing the same record twice (a retry after
    /// a lost reply) keeps one.
    pub uid: String,
    /// Sensor serial.
    pub sensor_serial: Option<String>,
    /// Operator.
    pub operator: Option<String>,
    /// Rig.
    pub rig: Option<String>,
    /// When calibrated, UTC, RFC 3339.
    pub calibrated_utc: String,
    /// Host version.
    pub host_version: String,
    /// Rig firmware version.
    pub rig_firmware: Option<String>,
    /// Full scale, °/s.
    pub full_scale_dps: i64,
    /// SHA-256 of every capture, comma-separated.
    pub captures_sha256: String,
    /// Verdict of the closed loop.
    pub verdict: String,
    /// The whole calibration.json.
    pub result_json: String,
    /// Parameters.
    pub params: Vec<Param>,
    /// Noise figures (empty without an Allan analysis).
    pub noise: Vec<NoiseRow>,
    /// The thermal model, for a thermal calibration.
    pub thermal: Option<ThermalRecord>,
}

const COLUMNS: &str = "id, record_uid, sensor_serial, operator, rig, calibrated_utc, host_version, rig_firmware, \
                       full_scale_dps, captures_sha256, verdict, result_json";

fn record_from_row(r: &[Val]) -> Result<Record> {
    let text = |i: usize| r[i].text().with_context(|| format!("column {i} is NULL"));
    Ok(Record {
        id: r[0].int(),
        uid: text(1)?,
        sensor_serial: r[2].text(),
        operator: r[3].text(),
        rig: r[4].text(),
        calibrated_utc: text(5)?,
        host_version: text(6)?,
        rig_firmware: r[7].text(),
        full_scale_dps: r[8].int().context("full_scale_dps")?,
        captures_sha256: text(9)?,
        verdict: text(10)?,
        result_json: text(11)?,
        params: Vec::new(),
        noise: Vec::new(),
        thermal: None,
    })
}

/// Stores a record in one transaction; returns its id and whether it was new (false: a record
/// with this uid was already there, and is left as it was).
pub fn insert(c: &mut dyn Conn, rec: &Record) -> Result<(i64, bool)> {
    c.begin_write()?;
    let r = (|| {
        let rows = c.query(
            "INSERT INTO calibration (record_uid, sensor_serial, operator, rig, calibrated_utc, host_version, \
             rig_firmware, full_scale_dps, captures_sha256, verdict, result_json) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11) ON CONFLICT (record_uid) DO NOTHING RETURNING id",
            &[
                Val::Text(Some(rec.uid.clone())),
                Val::Text(rec.sensor_serial.clone()),
                Val::Text(rec.operator.clone()),
                Val::Text(rec.rig.clone()),
                Val::Text(Some(rec.calibrated_utc.clone())),
                Val::Text(Some(rec.host_version.clone())),
                Val::Text(rec.rig_firmware.clone()),
                Val::Int(rec.full_scale_dps),
                Val::Text(Some(rec.captures_sha256.clone())),
                Val::Text(Some(rec.verdict.clone())),
                Val::Text(Some(rec.result_json.clone())),
            ],
        )?;
        let Some(id) = rows.first().and_then(|r| r[0].int()) else {
            let rows =
                c.query("SELECT id FROM calibration WHERE record_uid = $1", &[Val::Text(Some(rec.uid.clone()))])?;
            return Ok((rows[0][0].int().context("id")?, false));
        };
        insert_params(c, "parameter", id, &rec.params)?;
        for n in &rec.noise {
            c.query(
                "INSERT INTO noise (calibration_id, axis, arw_deg_per_sqrt_h, bias_instability_deg_per_h, \
                 rrw_deg_per_h_per_sqrt_h) VALUES ($1, $2, $3, $4, $5)",
                &[
                    Val::Int(id),
                    Val::Text(Some(n.axis.to_string())),
                    Val::Real(n.arw_deg_per_sqrt_h),
                    Val::Real(n.bias_instability_deg_per_h),
                    Val::Real(n.rrw_deg_per_h_per_sqrt_h),
                ],
            )?;
        }
        if let Some(t) = &rec.thermal {
            insert_thermal(c, id, t)?;
        }
        Ok((id, true))
    })();
    match &r {
        Ok(_) => c.batch("COMMIT")?,
        Err(_) => {
            let _ = c.batch("ROLLBACK");
        }
    }
    r
}

/// A record's thermal model, inside [`insert`]'s transaction.
fn insert_thermal(c: &mut dyn Conn, id: i64, t: &ThermalRecord) -> Result<()> {
    let setpoints: Vec<String> = t.setpoints_c.iter().map(f64::to_string).collect();
    c.query(
        "INSERT INTO thermal_model (calibration_id, reference_c, range_min_c, range_max_c, out_temp_at_0c, \
         setpoints_c) VALUES ($1, $2, $3, $4, $5, $6)",
        &[
            Val::Int(id),
            Val::Real(Some(t.reference_c)),
            Val::Real(Some(t.range_c[0])),
            Val::Real(Some(t.range_c[1])),
            Val::Real(Some(t.out_temp_at_0c)),
            Val::Text(Some(setpoints.join(","))),
        ],
    )?;
    insert_params(c, "thermal_coefficient", id, &t.coefficients)
}

/// Rows of `table` (`parameter` or `thermal_coefficient`, which share their columns) for
/// calibration `id`, inside [`insert`]'s transaction.
fn insert_params(c: &mut dyn Conn, table: &str, id: i64, params: &[Param]) -> Result<()> {
    let sql = format!("INSERT INTO {table} (calibration_id, name, value, sigma, unit) VALUES ($1, $2, $3, $4, $5)");
    for p in params {
        c.query(
            &sql,
            &[
                Val::Int(id),
                Val::Text(Some(p.name.clone())),
                Val::Real(Some(p.value)),
                Val::Real(p.sigma),
                Val::Text(Some(p.unit.clone())),
            ],
        )?;
    }
    Ok(())
}

/// A record's thermal model (`None` for a calibration at one temperature, and for every record
/// of a database before schema v3).
fn get_thermal(c: &mut dyn Conn, id: i64) -> Result<Option<ThermalRecord>> {
    let rows = c.query(
        "SELECT reference_c, range_min_c, range_max_c, out_temp_at_0c, setpoints_c FROM thermal_model \
         WHERE calibration_id = $1",
        &[Val::Int(id)],
    )?;
    let Some(r) = rows.first() else { return Ok(None) };
    let real = |i: usize| r[i].real().with_context(|| format!("thermal_model column {i} is NULL"));
    let setpoints_c = r[4]
        .text()
        .unwrap_or_default()
        .split(',')
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<f64>().with_context(|| format!("thermal_model setpoint {s:?}")))
        .collect::<Result<_>>()?;
    let coefficients = params_of(c, "thermal_coefficient", id)?;
    Ok(Some(ThermalRecord {
        reference_c: real(0)?,
        range_c: [real(1)?, real(2)?],
        out_temp_at_0c: real(3)?,
        setpoints_c,
        coefficients,
    }))
}

/// The name, value, σ and unit rows of `table` (`parameter` or `thermal_coefficient`) of a
/// record, by name.
fn params_of(c: &mut dyn Conn, table: &str, id: i64) -> Result<Vec<Param>> {
    Ok(c.query(
        &format!("SELECT name, value, sigma, unit FROM {table} WHERE calibration_id = $1 ORDER BY name"),
        &[Val::Int(id)],
    )?
    .iter()
    .map(|r| Param {
        name: r[0].text().unwrap_or_default(),
        value: r[1].real().unwrap_or(f64::NAN),
        sigma: r[2].real(),
        unit: r[3].text().unwrap_or_default(),
    })
    .collect())
}

/// Records, oldest first, optionally of one sensor (without parameters).
pub fn list(c: &mut dyn Conn, sensor: Option<&str>) -> Result<Vec<Record>> {
    let rows = match sensor {
        Some(s) => c.query(
            &format!("SELECT {COLUMNS} FROM calibration WHERE sensor_serial = $1 ORDER BY id"),
            &[Val::Text(Some(s.into()))],
        )?,
        None => c.query(&format!("SELECT {COLUMNS} FROM calibration ORDER BY id"), &[])?,
    };
    rows.iter().map(|r| record_from_row(r)).collect()
}

/// Ids of the records one of whose captures has this SHA-256, oldest first.
pub fn records_with_capture(c: &mut dyn Conn, sha256: &str) -> Result<Vec<i64>> {
    // captures_sha256 is a comma-separated list of 64-hex digests: a digest has no LIKE
    // wildcard, and no digest is a substring of another of the same length.
    let rows = c.query(
        "SELECT id FROM calibration WHERE captures_sha256 LIKE $1 ORDER BY id",
        &[Val::Text(Some(format!("%{sha256}%")))],
    )?;
    rows.iter().map(|r| r[0].int().context("id")).collect()
}

/// One record with its parameters and noise figures.
pub fn get(c: &mut dyn Conn, id: i64) -> Result<Option<Record>> {
    let rows = c.query(&format!("SELECT {COLUMNS} FROM calibration WHERE id = $1"), &[Val::Int(id)])?;
    let Some(row) = rows.first() else { return Ok(None) };
    let mut rec = record_from_row(row)?;
    rec.params = params_of(c, "parameter", id)?;
    rec.noise = c
        .query(
            "SELECT axis, arw_deg_per_sqrt_h, bias_instability_deg_per_h, rrw_deg_per_h_per_sqrt_h FROM noise \
             WHERE calibration_id = $1 ORDER BY axis",
            &[Val::Int(id)],
        )?
        .iter()
        .map(|r| NoiseRow {
            axis: r[0].text().and_then(|s| s.chars().next()).unwrap_or('?'),
            arw_deg_per_sqrt_h: r[1].real(),
            bias_instability_deg_per_h: r[2].real(),
            rrw_deg_per_h_per_sqrt_h: r[3].real(),
        })
        .collect();
    rec.thermal = get_thermal(c, id)?;
    Ok(Some(rec))
}

/// The latest record of every sensor that has a serial, with parameters.
pub fn latest_per_sensor(c: &mut dyn Conn) -> Result<Vec<Record>> {
    let ids = c.query(
        "SELECT MAX(id) FROM calibration WHERE sensor_serial IS NOT NULL GROUP BY sensor_serial ORDER BY MAX(id)",
        &[],
    )?;
    let mut out = Vec::new();
    for r in ids {
        let id = r[0].int().context("id")?;
        out.extend(get(c, id)?);
    }
    Ok(out)
}
