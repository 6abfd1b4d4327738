//! A record of every calibration: an embedded SQLite file by default, PostgreSQL when a line of
//! rigs shares one store. One schema with versioned migrations ([`store`]), one code path for
//! both ([`db::Conn`]), and the production views: list, show, compare, summary ([`views`]).

pub mod db;
pub mod pg;
pub mod store;
pub mod views;

#[cfg(test)]
mod tests;

use crate::calib::{CalReport, Estimate};
use crate::provenance::Provenance;
use anyhow::{Context, Result};
use db::Conn;
use std::path::PathBuf;
pub use store::{NoiseRow, Param, Record, ThermalRecord};

/// Environment variable naming the database when `--db` is not given.
pub const DB_ENV: &str = "GYROCAL_DB";

/// Where the records live.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DbSpec {
    /// An SQLite file.
    Sqlite(PathBuf),
    /// A PostgreSQL URL, `postgres://user@host/db` or `postgresql://…`.
    Postgres(String),
}

impl DbSpec {
    /// Parses `sqlite:PATH` or `postgres://…` / `postgresql://…`.
    pub fn parse(s: &str) -> Result<Self> {
        if let Some(p) = s.strip_prefix("sqlite:") {
            anyhow::ensure!(!p.is_empty(), "--db sqlite: needs a path, e.g. sqlite:records.sqlite");
            return Ok(DbSpec::Sqlite(PathBuf::from(p)));
        }
        if s.starts_with("postgres://") || s.starts_with("postgresql://") {
            return Ok(DbSpec::Postgres(s.to_string()));
        }
        anyhow::bail!("database {s:?} is neither sqlite:PATH nor postgres://…")
    }

    /// `--db` if given, else `$GYROCAL_DB`, else the per-user default
    /// `sqlite:$XDG_DATA_HOME/gyrocal/records.sqlite` (XDG_DATA_HOME defaults to
    /// `~/.local/share`, per the XDG Base Directory specification).
    pub fn resolve(arg: Option<&str>) -> Result<Self> {
        if let Some(a) = arg {
            return Self::parse(a);
        }
        if let Ok(e) = std::env::var(DB_ENV) {
            return Self::parse(&e).with_context(|| format!("${DB_ENV}"));
        }
        let data = match std::env::var_os("XDG_DATA_HOME").filter(|v| !v.is_empty()) {
            Some(d) => PathBuf::from(d),
            None => PathBuf::from(std::env::var_os("HOME").context("neither --db, $GYROCAL_DB nor $HOME is set")?)
                .join(".local/share"),
        };
        Ok(DbSpec::Sqlite(data.join("gyrocal/records.sqlite")))
    }

    /// As [`DbSpec::open`], for reading: an SQLite file that does not exist is an error, never
    /// created (a mistyped path must not look like an empty database).
    pub fn open_existing(&self) -> Result<Box<dyn Conn>> {
        if let DbSpec::Sqlite(p) = self {
            if !p.exists() {
                anyhow::bail!("no records database at {} (check --db or ${DB_ENV})", p.display());
            }
        }
        self.open()
    }

    /// Opens a connection and brings the schema up to date.
    pub fn open(&self) -> Result<Box<dyn Conn>> {
        self.open_in_schema(None)
    }

    /// As [`DbSpec::open`], inside a PostgreSQL schema (ignored for SQLite); for tests.
    pub fn open_in_schema(&self, schema: Option<&str>) -> Result<Box<dyn Conn>> {
        let mut c: Box<dyn Conn> = match self {
            DbSpec::Sqlite(p) => Box::new(
                db::Sqlite::open(p).with_context(|| format!("cannot open the records database {}", p.display()))?,
            ),
            DbSpec::Postgres(url) => Box::new(
                db::Postgres::connect(url, schema).with_context(|| format!("cannot connect to {}", redact(url)))?,
            ),
        };
        store::migrate_to(c.as_mut(), store::SCHEMA_VERSION).context("cannot bring the records schema up to date")?;
        Ok(c)
    }
}

impl std::fmt::Display for DbSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DbSpec::Sqlite(p) => write!(f, "sqlite:{}", p.display()),
            DbSpec::Postgres(u) => write!(f, "{}", redact(u)),
        }
    }
}

/// A URL with its password replaced by `***`, for messages.
pub fn redact(url: &str) -> String {
    match (url.find("://"), url.find('@')) {
        (Some(s), Some(at)) if at > s => {
            let creds = &url[s + 3..at];
            match creds.find(':') {
                Some(c) => format!("{}{}:***{}", &url[..s + 3], &creds[..c], &url[at..]),
                None => url.to_string(),
            }
        }
        _ => url.to_string(),
    }
}

/// A fresh record uid: 128 random bits, hex.
pub fn new_uid() -> String {
    format!("{:032x}", rand::random::<u128>())
}

/// The parameters a production view compares, each with its 1-σ from the report.
pub fn params_from_report(r: &CalReport) -> Vec<Param> {
    let p = |name: String, value: f64, sigma: Option<f64>, unit: &str| Param { name, value, sigma, unit: unit.into() };
    let est = |name: String, e: Estimate, unit: &str| p(name, e.value, Some(e.sigma), unit);
    let mut out = Vec::new();
    let axes = ['x', 'y', 'z'];
    for (i, a) in r.axes.iter().enumerate() {
        let ax = axes[i];
        out.push(est(format!("k_{ax}"), a.k_counts_per_dps, "counts/(deg/s)"));
        out.push(p(
            format!("k_{ax}_vs_nominal"),
            a.k_vs_nominal_percent,
            Some(a.k_counts_per_dps.sigma / r.nominal_counts_per_dps * 100.0),
            "%",
        ));
        out.push(est(format!("offset_{ax}"), a.offset_counts, "counts"));
        out.push(est(format!("tilt_{ax}"), a.tilt_extrinsic_deg(), "deg"));
        for k in 0..2 {
            out.push(p(
                format!("tilt_{ax}_to_{}", a.tilt_component_axes[k]),
                a.tilt_components_deg[k],
                Some(a.tilt_components_cov_deg2[k][k].max(0.0).sqrt()),
                "deg",
            ));
        }
        for (j, col) in axes.iter().enumerate() {
            let s = r.cov.get(4 * i + j).and_then(|row| row.get(4 * i + j)).map(|v| v.max(0.0).sqrt());
            out.push(p(format!("m_{ax}{col}"), r.m_counts_per_dps[i][j], s, "counts/(deg/s)"));
        }
    }
    for ia in &r.inter_axis {
        out.push(p(
            format!("non_orthogonality_{}{}", ia.axes[0], ia.axes[1]),
            ia.non_orthogonality_deg,
            Some(ia.angle_deg.sigma),
            "deg",
        ));
    }
    for res in &r.residuals {
        out.push(p(format!("residual_over_floor_{}", res.axis), res.rms_over_floor, None, "1"));
    }
    out
}

/// The record of a calibration just written: report, provenance, verdict and the JSON file.
pub fn record_from(report: &CalReport, prov: &Provenance, verdict: &str, result_json: String) -> Record {
    Record {
        id: None,
        uid: new_uid(),
        sensor_serial: prov.identity.sensor_serial.clone(),
        operator: prov.identity.operator.clone(),
        rig: prov.identity.rig.clone(),
        calibrated_utc: prov.calibrated_utc.clone(),
        host_version: prov.host_version.clone(),
        rig_firmware: prov.rig_firmware.clone(),
        full_scale_dps: i64::from(report.gyro.full_scale.range_dps()),
        captures_sha256: prov.captures.iter().map(|c| c.sha256.as_str()).collect::<Vec<_>>().join(","),
        verdict: verdict.into(),
        params: params_from_report(report),
        noise: Vec::new(),
        thermal: crate::thermal::session::model_in(&result_json).ok().flatten().as_ref().map(ThermalRecord::of),
        result_json,
    }
}

impl ThermalRecord {
    /// What a record keeps of a thermal model: its range and every coefficient with its σ, named
    /// `thermal_{quantity}_{axis}_c{degree}` (quantity `offset`, `k`, or `s_` with the package
    /// axis of the direction component: `thermal_s_xy_c1` is x's direction toward y, per °C).
    pub fn of(m: &crate::thermal::ThermalModel) -> Self {
        use crate::thermal::Quantity;
        let axes = ['x', 'y', 'z'];
        let mut coefficients = Vec::new();
        for (c, (axis, q)) in m.curves.iter().zip(crate::thermal::Quantity::all()) {
            let (name, unit) = match q {
                Quantity::OffsetCounts => (format!("offset_{}", axes[axis]), "counts"),
                Quantity::SensitivityCountsPerDps => (format!("k_{}", axes[axis]), "counts/(deg/s)"),
                Quantity::DirectionNext => (format!("s_{}{}", axes[axis], axes[(axis + 1) % 3]), "1"),
                Quantity::DirectionOther => (format!("s_{}{}", axes[axis], axes[(axis + 2) % 3]), "1"),
            };
            for (d, e) in c.coef.iter().enumerate() {
                let unit = match d {
                    0 => unit.to_string(),
                    1 => format!("{unit}/degC"),
                    _ => format!("{unit}/degC^{d}"),
                };
                coefficients.push(Param {
                    name: format!("thermal_{name}_c{d}"),
                    value: e.value,
                    sigma: Some(e.sigma),
                    unit,
                });
            }
        }
        coefficients.sort_by(|a, b| a.name.cmp(&b.name));
        Self {
            reference_c: m.reference_c,
            range_c: m.range_c,
            out_temp_at_0c: m.out_temp_at_0c,
            setpoints_c: m.setpoints.iter().map(|s| s.setpoint_c).collect(),
            coefficients,
        }
    }
}

/// Opens the database and stores `rec`; returns its id.
pub fn store_record(spec: &DbSpec, rec: &Record) -> Result<i64> {
    let mut c = spec.open()?;
    Ok(store::insert(c.as_mut(), rec).with_context(|| format!("{spec} refused the record"))?.0)
}

/// The previous calibrations of `this` record's sensor in `c` (its records with an id below
/// `before`, every one when `None`), oldest first, each with its changes to `this` in σ.
pub fn history(c: &mut dyn Conn, this: &Record, before: Option<i64>) -> Result<views::History> {
    let Some(serial) = this.sensor_serial.as_deref() else {
        return Ok(views::History::Unread("no sensor serial: calibrate with --sensor".into()));
    };
    let mut earlier = Vec::new();
    for r in store::list(c, Some(serial))? {
        match r.id {
            Some(id) if before.is_none_or(|b| id < b) => earlier.extend(store::get(c, id)?),
            _ => {}
        }
    }
    Ok(views::History::of(serial, this, &earlier))
}

/// The history a calibration about to be recorded in `db` gets on its certificate: none with
/// `--no-db`, an empty one when the database does not exist yet; a database that cannot be read
/// is said, not an error (the record step reports it).
pub fn history_before_recording(db: Option<&DbSpec>, this: &Record) -> views::History {
    let Some(db) = db else { return views::History::Unread("--no-db: no records database read".into()) };
    if this.sensor_serial.is_none() {
        return views::History::Unread("no sensor serial: calibrate with --sensor".into());
    }
    if let DbSpec::Sqlite(p) = db {
        if !p.exists() {
            return views::History::of(this.sensor_serial.as_deref().unwrap_or_default(), this, &[]);
        }
    }
    match db.open().and_then(|mut c| history(c.as_mut(), this, None)) {
        Ok(h) => h,
        Err(e) => views::History::Unread(format!("{db} could not be read: {e:#}")),
    }
}
