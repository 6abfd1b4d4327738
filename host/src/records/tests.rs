//! The records store against SQLite always and against PostgreSQL when `GYROCAL_TEST_PG` names
//! a server (`.ci/run` starts one). Without it the PostgreSQL tests are reported as ignored,
//! and under `CI=true` they fail: a store that was never exercised must not look like a pass.

use super::db::Conn;
use super::store::{self, NoiseRow, Param, Record, ThermalRecord, SCHEMA_VERSION};
use super::views;
use super::DbSpec;
use std::collections::HashSet;

/// A test database: an SQLite file in a temporary directory, or a fresh schema on the PostgreSQL
/// server. Dropping it removes the directory (the file and its -wal/-shm) or the schema, so runs
/// leave nothing behind, also when an assertion fails.
struct TestDb {
    spec: DbSpec,
    schema: Option<String>,
    _dir: Option<tempfile::TempDir>,
}

impl TestDb {
    fn sqlite(name: &str) -> Self {
        let dir = tempfile::Builder::new().prefix("gyrocal-records-").tempdir().expect("temporary directory");
        let p = dir.path().join(format!("{name}.sqlite"));
        Self { spec: DbSpec::Sqlite(p), schema: None, _dir: Some(dir) }
    }

    /// The configured server; without one these tests are ignored (build.rs), except under
    /// CI, where they run and fail here.
    fn postgres(name: &str) -> Self {
        match std::env::var("GYROCAL_TEST_PG") {
            Ok(url) => {
                let schema = format!("t_{}_{name}", std::process::id());
                let mut c =
                    ::postgres::Client::connect(&url, ::postgres::NoTls).expect("GYROCAL_TEST_PG server reachable");
                // Created here, before any writer: concurrent CREATE SCHEMA IF NOT EXISTS races in
                // PostgreSQL (both see it missing, one fails on the catalogue's unique index).
                c.batch_execute(&format!("DROP SCHEMA IF EXISTS {schema} CASCADE; CREATE SCHEMA {schema}")).unwrap();
                Self { spec: DbSpec::Postgres(url), schema: Some(schema), _dir: None }
            }
            Err(_) => panic!(
                "{name}: GYROCAL_TEST_PG is not set (CI={:?}): the PostgreSQL records tests must run in CI (.ci/run starts a server)",
                std::env::var("CI").unwrap_or_default()
            ),
        }
    }

    fn open(&self) -> Box<dyn Conn> {
        self.spec.open_in_schema(self.schema.as_deref()).expect("opens")
    }
}

impl Drop for TestDb {
    fn drop(&mut self) {
        if let (DbSpec::Postgres(url), Some(schema)) = (&self.spec, &self.schema) {
            // Best effort: a server gone away must not turn a passing test into a panic in drop.
            if let Ok(mut c) = ::postgres::Client::connect(url, ::postgres::NoTls) {
                let _ = c.batch_execute(&format!("DROP SCHEMA IF EXISTS {schema} CASCADE"));
            }
        }
    }
}

fn record(uid: &str, sensor: &str, params: &[(&str, f64, Option<f64>)]) -> Record {
    Record {
        id: None,
        uid: uid.into(),
        sensor_serial: Some(sensor.into()),
        operator: Some("ada".into()),
        rig: Some("rig-1".into()),
        calibrated_utc: "2026-11-23T05:00:00Z".into(),
        host_version: "0.1.0".into(),
        rig_firmware: Some("0.1.0".into()),
        full_scale_dps: 500,
        captures_sha256: "aa,bb".into(),
        verdict: "at noise floor".into(),
        result_json: "{}".into(),
        params: params
            .iter()
            .map(|&(n, v, s)| Param { name: n.into(), value: v, sigma: s, unit: "deg".into() })
            .collect(),
        noise: vec![NoiseRow {
            axis: 'x',
            arw_deg_per_sqrt_h: Some(1.8),
            bias_instability_deg_per_h: None,
            rrw_deg_per_h_per_sqrt_h: Some(0.5),
        }],
        thermal: None,
    }
}

/// A thermal record: `record` with a model over −20…70 °C whose x offset slope is `slope` ± 0.02
/// counts/°C (the other coefficients fixed), and, with `quadratic`, a curvature of the x offset.
fn thermal_record(uid: &str, slope: f64, quadratic: bool) -> Record {
    let mut r = record(uid, "G-7", &[("tilt_x", 1.0, Some(0.3))]);
    let c = |name: &str, value: f64, sigma: f64, unit: &str| Param {
        name: name.into(),
        value,
        sigma: Some(sigma),
        unit: unit.into(),
    };
    let mut coefficients = vec![
        c("thermal_k_x_c0", 57.3, 1e-3, "counts/(deg/s)"),
        c("thermal_offset_x_c0", 12.4, 0.05, "counts"),
        c("thermal_offset_x_c1", slope, 0.02, "counts/degC"),
    ];
    if quadratic {
        coefficients.push(c("thermal_offset_x_c2", 5.7e-3, 4e-4, "counts/degC^2"));
    }
    r.thermal = Some(ThermalRecord {
        reference_c: 25.0,
        range_c: [-20.5, 70.5],
        out_temp_at_0c: 12.3,
        setpoints_c: vec![-20.0, 0.0, 25.0, 50.0, 70.0],
        coefficients,
    });
    r
}

/// A thermal record stores and reads back its model; `show` prints it in every format and
/// `compare` puts each coefficient's change in combined σ.
fn thermal_models_are_stored_shown_and_compared(db: &TestDb) {
    let mut c = db.open();
    let (a, b) = (thermal_record("t1", 1.71, true), thermal_record("t2", 1.80, false));
    let (ida, _) = store::insert(c.as_mut(), &a).unwrap();
    let (idb, _) = store::insert(c.as_mut(), &b).unwrap();
    let got_a = store::get(c.as_mut(), ida).unwrap().unwrap();
    assert_eq!(got_a.thermal, a.thermal);
    let got_b = store::get(c.as_mut(), idb).unwrap().unwrap();
    let text = views::show(&got_a);
    assert!(text.contains("thermal model: setpoints -20, 0, 25, 50, 70 °C; holds for die -20.50…70.50 °C"), "{text}");
    assert!(text.contains("thermal_offset_x_c2            +5.700000e-3     4.000e-4  counts/degC^2"), "{text}");
    let json: serde_json::Value =
        serde_json::from_str(&views::show_as(&got_a, &views::History::Unread(String::new()), views::Format::Json))
            .unwrap();
    assert_eq!(json["thermal"]["coefficients"][3]["name"], "thermal_offset_x_c2");
    assert_eq!(json["thermal"]["range_c"][1], 70.5);
    let csv = views::show_as(&got_a, &views::History::Unread(String::new()), views::Format::Csv);
    assert!(csv.contains(&format!("{ida},thermal_offset_x_c1,1.71,0.02,counts/degC")), "{csv}");
    // (1.80 − 1.71) / √(0.02² + 0.02²) = 3.18 σ: changed; the curvature is in A only.
    let ch = views::changes(&got_a, &got_b);
    let slope = ch.iter().find(|c| c.name == "thermal_offset_x_c1").unwrap();
    assert!((slope.z.unwrap() - 0.09 / 0.02f64.hypot(0.02)).abs() < 1e-9, "{slope:?}");
    assert_eq!(ch.iter().find(|c| c.name == "thermal_k_x_c0").unwrap().z, Some(0.0));
    let cmp = views::compare(&got_a, &got_b);
    assert!(cmp.contains("1 of 4 parameters changed"), "{cmp}");
    assert!(cmp.contains("thermal coefficients in A only (orders differ): thermal_offset_x_c2"), "{cmp}");
    let cmp: serde_json::Value = serde_json::from_str(&views::compare_as(&got_a, &got_b, views::Format::Json)).unwrap();
    assert_eq!(cmp["thermal_coefficients_only_in"]["a"][0], "thermal_offset_x_c2");
    // A record without a model beside one with: said, not compared.
    let (idp, _) = store::insert(c.as_mut(), &record("p", "G-7", &[])).unwrap();
    let plain = store::get(c.as_mut(), idp).unwrap().unwrap();
    assert!(views::compare(&got_a, &plain).contains("only A holds a thermal model"));
}

/// A database at schema v2 (before thermal models) with a record opens at the latest version:
/// the old record reads back without a model, and a thermal record can be stored beside it.
fn migrates_from_v2(db: &TestDb) {
    let mut c: Box<dyn Conn> = match &db.spec {
        DbSpec::Sqlite(p) => Box::new(super::db::Sqlite::open(p).unwrap()),
        DbSpec::Postgres(u) => Box::new(super::db::Postgres::connect(u, db.schema.as_deref()).unwrap()),
    };
    assert_eq!(store::migrate_to(c.as_mut(), 2).unwrap(), 0);
    c.query(
        "INSERT INTO calibration (record_uid, calibrated_utc, host_version, full_scale_dps, captures_sha256, verdict, result_json) \
         VALUES ($1, $2, $3, $4, $5, $6, $7)",
        &[
            super::db::Val::Text(Some("v2".into())),
            super::db::Val::Text(Some("2026-01-01T00:00:00Z".into())),
            super::db::Val::Text(Some("0.1.0".into())),
            super::db::Val::Int(500),
            super::db::Val::Text(Some("dd".into())),
            super::db::Val::Text(Some("at noise floor".into())),
            super::db::Val::Text(Some("{}".into())),
        ],
    )
    .unwrap();
    drop(c);
    let mut c = db.open();
    assert_eq!(store::schema_version(c.as_mut()).unwrap(), 3);
    let old = store::list(c.as_mut(), None).unwrap()[0].id.unwrap();
    let old = store::get(c.as_mut(), old).unwrap().unwrap();
    assert_eq!((old.uid.as_str(), old.thermal.as_ref()), ("v2", None));
    let (id, _) = store::insert(c.as_mut(), &thermal_record("t", 1.7, false)).unwrap();
    assert_eq!(store::get(c.as_mut(), id).unwrap().unwrap().thermal.unwrap().coefficients.len(), 3);
}

fn round_trip_and_duplicates(db: &TestDb) {
    let mut c = db.open();
    assert_eq!(store::schema_version(c.as_mut()).unwrap(), SCHEMA_VERSION);
    let a = record("u1", "G-1", &[("tilt_x", 1.0, Some(0.3)), ("offset_x", -12.5, None)]);
    let (id1, new1) = store::insert(c.as_mut(), &a).unwrap();
    assert!(new1);
    let (again, new_again) = store::insert(c.as_mut(), &a).unwrap();
    assert_eq!((again, new_again), (id1, false), "a retried store keeps one record");
    let (id2, _) = store::insert(c.as_mut(), &record("u2", "G-2", &[("tilt_x", 1.5, Some(0.4))])).unwrap();
    let (id3, _) = store::insert(c.as_mut(), &record("u3", "G-1", &[("tilt_x", 2.5, Some(0.4))])).unwrap();
    assert_eq!(store::list(c.as_mut(), None).unwrap().len(), 3);
    let g1: Vec<i64> = store::list(c.as_mut(), Some("G-1")).unwrap().iter().map(|r| r.id.unwrap()).collect();
    assert_eq!(g1, vec![id1, id3]);
    let got = store::get(c.as_mut(), id1).unwrap().unwrap();
    let mut want = a.clone();
    want.id = Some(id1);
    want.params.sort_by(|x, y| x.name.cmp(&y.name));
    assert_eq!(got, want);
    assert_eq!(store::get(c.as_mut(), 9_999_999).unwrap(), None);
    // Latest per sensor: G-1's second record, then G-2.
    let latest: Vec<i64> = store::latest_per_sensor(c.as_mut()).unwrap().iter().map(|r| r.id.unwrap()).collect();
    assert_eq!(latest.iter().copied().collect::<HashSet<_>>(), HashSet::from([id2, id3]));
    // Compare: (1.5 − 1.0)/√(0.3² + 0.4²) = 0.5/0.5 = 1.
    let b = store::get(c.as_mut(), id2).unwrap().unwrap();
    let ch = views::changes(&got, &b);
    let tilt = ch.iter().find(|c| c.name == "tilt_x").unwrap();
    assert!((tilt.z.unwrap() - 1.0).abs() < 1e-12, "{tilt:?}");
    assert!(views::compare(&got, &b).contains("0 of 1 parameters changed"));
}

/// 8 rigs storing at once, each 10 records and each record twice (a retry): 80 records, every
/// uid once, no id twice.
fn eight_concurrent_writers(db: &TestDb) {
    // No connection before the writers: they also race to apply the migrations.
    let handles: Vec<_> = (0..8)
        .map(|w| {
            let spec = db.spec.clone();
            let schema = db.schema.clone();
            std::thread::spawn(move || {
                let mut c = spec.open_in_schema(schema.as_deref()).expect("writer connects");
                let mut ids = Vec::new();
                for i in 0..10 {
                    let r = record(&format!("w{w}-r{i}"), &format!("G-{w}"), &[("tilt_x", f64::from(i), Some(0.1))]);
                    let (id, new) = store::insert(c.as_mut(), &r).expect("stored");
                    assert!(new);
                    assert_eq!(store::insert(c.as_mut(), &r).expect("retry"), (id, false));
                    ids.push(id);
                }
                ids
            })
        })
        .collect();
    let ids: Vec<i64> = handles.into_iter().flat_map(|h| h.join().expect("writer")).collect();
    assert_eq!(ids.iter().collect::<HashSet<_>>().len(), 80);
    let mut c = db.open();
    let all = store::list(c.as_mut(), None).unwrap();
    assert_eq!(all.len(), 80);
    assert_eq!(all.iter().map(|r| r.uid.clone()).collect::<HashSet<_>>().len(), 80);
    for w in 0..8 {
        assert_eq!(store::list(c.as_mut(), Some(&format!("G-{w}"))).unwrap().len(), 10);
    }
}

/// A database at schema v1 with a record migrates to the latest version keeping the record.
fn migrates_from_v1(db: &TestDb) {
    let mut c: Box<dyn Conn> = match &db.spec {
        DbSpec::Sqlite(p) => Box::new(super::db::Sqlite::open(p).unwrap()),
        DbSpec::Postgres(u) => Box::new(super::db::Postgres::connect(u, db.schema.as_deref()).unwrap()),
    };
    assert_eq!(store::migrate_to(c.as_mut(), 1).unwrap(), 0);
    assert_eq!(store::schema_version(c.as_mut()).unwrap(), 1);
    c.query(
        "INSERT INTO calibration (record_uid, calibrated_utc, host_version, full_scale_dps, captures_sha256, verdict, result_json) \
         VALUES ($1, $2, $3, $4, $5, $6, $7)",
        &[
            super::db::Val::Text(Some("old".into())),
            super::db::Val::Text(Some("2025-01-01T00:00:00Z".into())),
            super::db::Val::Text(Some("0.0.9".into())),
            super::db::Val::Int(500),
            super::db::Val::Text(Some("cc".into())),
            super::db::Val::Text(Some("at noise floor".into())),
            super::db::Val::Text(Some("{}".into())),
        ],
    )
    .unwrap();
    drop(c);
    let mut c = db.open();
    assert_eq!(store::schema_version(c.as_mut()).unwrap(), SCHEMA_VERSION);
    let all = store::list(c.as_mut(), None).unwrap();
    assert_eq!(all.len(), 1);
    assert_eq!(all[0].uid, "old");
    let id = all[0].id.unwrap();
    let mut r = record("new", "G-9", &[]);
    r.params.clear();
    store::insert(c.as_mut(), &r).unwrap();
    assert!(store::get(c.as_mut(), id).unwrap().unwrap().noise.is_empty());
}

macro_rules! both_backends {
    ($($name:ident),*) => {
        mod sqlite { $( #[test] fn $name() { super::$name(&super::TestDb::sqlite(stringify!($name))); } )* }
        mod postgres { $(
            #[test]
            #[cfg_attr(not(gyrocal_test_pg), ignore = "no PostgreSQL: set GYROCAL_TEST_PG=postgres://… (.ci/run does)")]
            fn $name() { super::$name(&super::TestDb::postgres(stringify!($name))); }
        )* }
    };
}

both_backends!(
    round_trip_and_duplicates,
    eight_concurrent_writers,
    migrates_from_v1,
    migrates_from_v2,
    thermal_models_are_stored_shown_and_compared
);

#[test]
fn summary_names_the_outlier_among_twenty_sensors() {
    // 20 sensors with tilts 1.00, 1.01, …, 1.19° and one at 3°: median (11th of 21) 1.10, MAD
    // 0.05 (robust σ 0.0741), so 3° sits at z = 1.90/0.0741 = 25.6 and 1.19° at z = 1.2.
    let mut recs: Vec<Record> = (0..20)
        .map(|i| {
            let mut r =
                record(&format!("u{i}"), &format!("G-{i:02}"), &[("tilt_x", 1.0 + 0.01 * f64::from(i), Some(0.01))]);
            r.id = Some(i64::from(i));
            r
        })
        .collect();
    recs.push(record("bad", "G-BAD", &[("tilt_x", 3.0, Some(0.01))]));
    let d = views::distributions(&recs);
    // tilt_x, and from each record's noise row for x: ARW 1.8 and RRW 0.5 (no bias instability).
    let names: Vec<&str> = d.iter().map(|d| d.name.as_str()).collect();
    assert_eq!(names, ["tilt_x", "arw_x", "rrw_x"]);
    assert_eq!((d[1].n, d[1].median), (21, 1.8));
    assert!(d[1].sd < 1e-15, "{}", d[1].sd);
    assert!(d[1].outliers.is_empty(), "MAD 0: nobody is an outlier");
    let t = &d[0];
    assert_eq!(t.n, 21);
    assert!((t.median - 1.10).abs() < 1e-12);
    assert_eq!(t.outliers.len(), 1);
    assert_eq!(t.outliers[0].0, "G-BAD");
    assert!((t.outliers[0].2 - (3.0 - 1.10) / (1.4826 * 0.05)).abs() < 1e-6, "{:?}", t.outliers);
    let text = views::summary(&recs);
    assert!(text.contains("G-BAD: tilt_x = +3.0000 deg"), "{text}");
    // Histogram: 10 bins from 1.00 to 3.00 (0.2 wide): the 20 good sensors in the first, G-BAD in
    // the last.
    let h = views::histogram(&t.values);
    assert_eq!(h.iter().map(|b| b.1).collect::<Vec<_>>(), vec![20, 0, 0, 0, 0, 0, 0, 0, 0, 1]);
    assert!((h[0].0 - 1.1).abs() < 1e-12 && (h[9].0 - 2.9).abs() < 1e-12);
    let html = views::summary_html(&recs);
    assert!(html.contains("G-BAD: tilt_x = +3.0000 deg (z +25.6)") && html.contains("<svg"), "{html}");
}

/// A TLS session to the test server (`.ci/run` starts it with TLS on): `sslmode=require` (the
/// URL's own, or added to `GYROCAL_TEST_PG`) connects encrypted, stores and lists; the server
/// confirms the session is TLS (`pg_stat_ssl`).
#[test]
#[cfg_attr(not(gyrocal_test_pg), ignore = "no PostgreSQL: set GYROCAL_TEST_PG=postgres://… (.ci/run does)")]
fn postgres_over_tls_stores_and_lists() {
    let plain = TestDb::postgres("tls");
    let DbSpec::Postgres(url) = &plain.spec else { unreachable!() };
    let sep = if url.contains('?') { '&' } else { '?' };
    let tls = DbSpec::Postgres(format!("{url}{sep}sslmode=require"));
    let mut c = tls.open_in_schema(plain.schema.as_deref()).expect("a TLS session to the test server");
    let rows = c.query("SELECT ssl::text, version FROM pg_stat_ssl WHERE pid = pg_backend_pid()", &[]).unwrap();
    assert_eq!(rows[0][0].text().as_deref(), Some("true"), "the session is not encrypted");
    assert!(rows[0][1].text().is_some_and(|v| v.starts_with("TLSv1.")), "{:?}", rows[0][1].text());
    let (id, new) = store::insert(c.as_mut(), &record("tls-1", "G-TLS", &[("tilt_x", 1.0, Some(0.01))])).unwrap();
    assert!(new);
    let listed = store::list(c.as_mut(), Some("G-TLS")).unwrap();
    assert_eq!(listed.iter().map(|r| r.id.unwrap()).collect::<Vec<_>>(), vec![id]);
}

#[test]
fn db_specs_parse_and_passwords_are_hidden() {
    assert_eq!(DbSpec::parse("sqlite:/tmp/x.sqlite").unwrap(), DbSpec::Sqlite("/tmp/x.sqlite".into()));
    assert!(matches!(DbSpec::parse("postgres://u:p@h/db").unwrap(), DbSpec::Postgres(_)));
    assert!(DbSpec::parse("mysql://h").is_err());
    assert_eq!(super::redact("postgres://u:secret@h:5432/db"), "postgres://u:***@h:5432/db");
    assert_eq!(DbSpec::resolve(Some("sqlite:a.sqlite")).unwrap(), DbSpec::Sqlite("a.sqlite".into()));
}
