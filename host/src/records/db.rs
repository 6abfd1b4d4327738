//! The two backends behind one small interface: run a script, run a statement with parameters,
//! read rows. Everything above ([`super::store`]) is written once against it, so SQLite and
//! PostgreSQL run the same queries, migrations and tests.

use anyhow::{Context, Result};

/// A value bound to or read from a statement. Nullable values carry their type, because
/// PostgreSQL types every parameter and refuses a NULL of the wrong one.
#[derive(Debug, Clone, PartialEq)]
pub enum Val {
    /// 64-bit integer (`BIGINT`).
    Int(i64),
    /// Double (`DOUBLE PRECISION`), possibly NULL.
    Real(Option<f64>),
    /// Text, possibly NULL.
    Text(Option<String>),
}

impl Val {
    /// The integer, if this is one.
    pub fn int(&self) -> Option<i64> {
        match self {
            Val::Int(v) => Some(*v),
            _ => None,
        }
    }
    /// The number, if this is a non-NULL real (or an integer).
    pub fn real(&self) -> Option<f64> {
        match self {
            Val::Real(v) => *v,
            Val::Int(v) => Some(*v as f64),
            Val::Text(_) => None,
        }
    }
    /// The text, if this is non-NULL text.
    pub fn text(&self) -> Option<String> {
        match self {
            Val::Text(v) => v.clone(),
            _ => None,
        }
    }
}

/// Which SQL the connection speaks, where the two differ (DDL only).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    /// SQLite 3 (bundled with rusqlite).
    Sqlite,
    /// PostgreSQL.
    Postgres,
}

/// One open connection.
pub trait Conn: Send {
    /// The dialect.
    fn dialect(&self) -> Dialect;
    /// Runs statements separated by `;`, without parameters.
    fn batch(&mut self, sql: &str) -> Result<()>;
    /// Runs one statement (placeholders `$1`, `$2`, …) and returns its rows.
    fn query(&mut self, sql: &str, params: &[Val]) -> Result<Vec<Vec<Val>>>;
    /// Starts a transaction that excludes every other writer until it ends: SQLite takes the
    /// write lock at once (`BEGIN IMMEDIATE`), PostgreSQL an advisory lock on `key`.
    fn begin_exclusive(&mut self, key: i64) -> Result<()>;
    /// Starts a transaction that will write: SQLite takes the write lock at once (a deferred
    /// transaction that must upgrade can fail with SQLITE_BUSY without waiting), PostgreSQL
    /// needs nothing more than `BEGIN`.
    fn begin_write(&mut self) -> Result<()>;
}

/// SQLite through rusqlite.
pub struct Sqlite(pub rusqlite::Connection);

/// How long a writer waits for another's lock before giving up, ms. 8 rigs storing at once each
/// hold the lock for a few ms; 30 s leaves room for a slow disk without hanging forever.
pub const SQLITE_BUSY_TIMEOUT_MS: u64 = 30_000;

impl Sqlite {
    /// Opens (creating) a database file; WAL so readers never block the writer.
    pub fn open(path: &std::path::Path) -> Result<Self> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        }
        let c = rusqlite::Connection::open(path)?;
        c.busy_timeout(std::time::Duration::from_millis(SQLITE_BUSY_TIMEOUT_MS))?;
        // Turning a new database to WAL needs its exclusive lock, and SQLite answers a writer
        // that races another doing the same with SQLITE_BUSY at once, without the busy handler
        // (it avoids a deadlock that way): retried here until the same timeout.
        let deadline = std::time::Instant::now() + std::time::Duration::from_millis(SQLITE_BUSY_TIMEOUT_MS);
        loop {
            match c.pragma_update(None, "journal_mode", "WAL") {
                Ok(()) => break,
                Err(rusqlite::Error::SqliteFailure(e, _))
                    if e.code == rusqlite::ErrorCode::DatabaseBusy && std::time::Instant::now() < deadline =>
                {
                    std::thread::sleep(std::time::Duration::from_millis(5));
                }
                Err(e) => return Err(e.into()),
            }
        }
        c.pragma_update(None, "foreign_keys", "ON")?;
        Ok(Self(c))
    }
}

impl rusqlite::ToSql for Val {
    fn to_sql(&self) -> rusqlite::Result<rusqlite::types::ToSqlOutput<'_>> {
        match self {
            Val::Int(v) => v.to_sql(),
            Val::Real(v) => v.to_sql(),
            Val::Text(v) => v.to_sql(),
        }
    }
}

impl Conn for Sqlite {
    fn dialect(&self) -> Dialect {
        Dialect::Sqlite
    }
    fn batch(&mut self, sql: &str) -> Result<()> {
        Ok(self.0.execute_batch(sql)?)
    }
    fn query(&mut self, sql: &str, params: &[Val]) -> Result<Vec<Vec<Val>>> {
        // SQLite reads `$1` as a parameter named "$1"; bound in order of first appearance, which
        // is numeric order in every query here. `?N` binds by number: convert to be exact.
        let sql = sql.replace('$', "?");
        let mut stmt = self.0.prepare_cached(&sql)?;
        let n = stmt.column_count();
        let mut rows = stmt.query(rusqlite::params_from_iter(params.iter()))?;
        let mut out = Vec::new();
        while let Some(row) = rows.next()? {
            let mut r = Vec::with_capacity(n);
            for i in 0..n {
                use rusqlite::types::ValueRef;
                r.push(match row.get_ref(i)? {
                    ValueRef::Null => Val::Text(None),
                    ValueRef::Integer(v) => Val::Int(v),
                    ValueRef::Real(v) => Val::Real(Some(v)),
                    ValueRef::Text(t) => Val::Text(Some(String::from_utf8_lossy(t).into_owned())),
                    ValueRef::Blob(_) => anyhow::bail!("unexpected blob in column {i}"),
                });
            }
            out.push(r);
        }
        Ok(out)
    }
    fn begin_exclusive(&mut self, _key: i64) -> Result<()> {
        self.begin_write()
    }
    fn begin_write(&mut self) -> Result<()> {
        Ok(self.0.execute_batch("BEGIN IMMEDIATE")?)
    }
}

/// PostgreSQL through the synchronous `postgres` client.
pub struct Postgres(pub postgres::Client);

impl Postgres {
    /// Connects to a `postgres://` URL; with `schema`, works inside that schema (created if
    /// missing), so tests can share one server without seeing each other's rows.
    pub fn connect(url: &str, schema: Option<&str>) -> Result<Self> {
        let mut c = super::pg::connect(url)?;
        if let Some(s) = schema {
            anyhow::ensure!(s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'), "bad schema name {s:?}");
            c.batch_execute(&format!("CREATE SCHEMA IF NOT EXISTS {s}; SET search_path TO {s}"))?;
        }
        Ok(Self(c))
    }
}

impl Conn for Postgres {
    fn dialect(&self) -> Dialect {
        Dialect::Postgres
    }
    fn batch(&mut self, sql: &str) -> Result<()> {
        Ok(self.0.batch_execute(sql)?)
    }
    fn query(&mut self, sql: &str, params: &[Val]) -> Result<Vec<Vec<Val>>> {
        use postgres::types::{ToSql, Type};
        let boxed: Vec<Box<dyn ToSql + Sync>> = params
            .iter()
            .map(|v| -> Box<dyn ToSql + Sync> {
                match v.clone() {
                    Val::Int(v) => Box::new(v),
                    Val::Real(v) => Box::new(v),
                    Val::Text(v) => Box::new(v),
                }
            })
            .collect();
        let refs: Vec<&(dyn ToSql + Sync)> = boxed.iter().map(|b| b.as_ref()).collect();
        let rows = self.0.query(sql, &refs)?;
        rows.iter()
            .map(|row| {
                (0..row.len())
                    .map(|i| {
                        let ty = row.columns()[i].type_();
                        Ok(if *ty == Type::INT8 {
                            row.get::<_, Option<i64>>(i).map_or(Val::Text(None), Val::Int)
                        } else if *ty == Type::INT4 {
                            row.get::<_, Option<i32>>(i).map_or(Val::Text(None), |v| Val::Int(v.into()))
                        } else if *ty == Type::FLOAT8 {
                            Val::Real(row.get(i))
                        } else if *ty == Type::TEXT || *ty == Type::VARCHAR {
                            Val::Text(row.get(i))
                        } else {
                            anyhow::bail!("unexpected column type {ty} in column {i}")
                        })
                    })
                    .collect()
            })
            .collect()
    }
    fn begin_exclusive(&mut self, key: i64) -> Result<()> {
        self.0.batch_execute("BEGIN")?;
        self.0.query("SELECT pg_advisory_xact_lock($1)", &[&key])?;
        Ok(())
    }
    fn begin_write(&mut self) -> Result<()> {
        Ok(self.0.batch_execute("BEGIN")?)
    }
}
