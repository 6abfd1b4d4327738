//! Connecting to PostgreSQL as libpq users expect: `sslmode` as libpq spells it, TLS by rustls,
//! the password from the URL, else `PGPASSWORD`, else the password file (`PGPASSFILE`, default
//! `~/.pgpass`), per libpq's documentation ("Environment Variables", "The Password File",
//! "SSL Support", PostgreSQL 17 manual §32.14-32.19).

use anyhow::{bail, Context, Result};
use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::pki_types::{CertificateDer, ServerName, UnixTime};
use rustls::{DigitallySignedStruct, SignatureScheme};
use std::path::{Path, PathBuf};
use std::str::FromStr as _;
use std::sync::Arc;

/// libpq's `sslmode`, as parsed from the URL's query.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SslMode {
    /// No TLS.
    Disable,
    /// libpq's `allow` and `prefer` (its default): TLS if the server offers it, the certificate
    /// not checked (libpq checks none in these modes either). `allow` tries plain first in
    /// libpq; taken as `prefer` here (the same outcome against a server that accepts both).
    Prefer,
    /// TLS or no connection; the certificate not checked, as libpq without a root certificate.
    Require,
    /// TLS, the server's certificate chain checked against `sslrootcert` (else the system's
    /// roots) and its name against the host: libpq's `verify-full`; `verify-ca` is taken as
    /// this, stricter, one (rustls's verifier checks the name with the chain).
    VerifyFull,
}

/// A parsed `postgres://…` URL: the driver's configuration, the TLS mode and root certificate.
pub struct Target {
    /// What tokio-postgres connects with (password filled in).
    pub config: postgres::Config,
    /// The TLS mode.
    pub ssl_mode: SslMode,
    /// `sslrootcert=PATH`: PEM root certificates for `verify-full`.
    pub root_cert: Option<PathBuf>,
}

/// Parses `url`, taking out the query parameters libpq knows and tokio-postgres does not
/// (`sslmode`'s `allow`, `verify-ca`, `verify-full`; `sslrootcert`), and fills in the password.
pub fn target(url: &str, env: &dyn Fn(&str) -> Option<String>) -> Result<Target> {
    let (base, query) = url.split_once('?').unwrap_or((url, ""));
    let mut ssl_mode = SslMode::Prefer;
    let mut root_cert = None;
    let mut kept = Vec::new();
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        match pair.split_once('=') {
            Some(("sslmode", v)) => {
                ssl_mode = match v {
                    "disable" => SslMode::Disable,
                    "allow" | "prefer" => SslMode::Prefer,
                    "require" => SslMode::Require,
                    "verify-ca" | "verify-full" => SslMode::VerifyFull,
                    _ => bail!(
                        "sslmode={v} is not one of libpq's: disable, allow, prefer, require, verify-ca, verify-full"
                    ),
                }
            }
            Some(("sslrootcert", v)) => root_cert = Some(PathBuf::from(v)),
            _ => kept.push(pair),
        }
    }
    let url = if kept.is_empty() { base.to_string() } else { format!("{base}?{}", kept.join("&")) };
    let mut config = postgres::Config::from_str(&url).context("not a PostgreSQL URL")?;
    config.ssl_mode(match ssl_mode {
        SslMode::Disable => postgres::config::SslMode::Disable,
        SslMode::Prefer => postgres::config::SslMode::Prefer,
        SslMode::Require | SslMode::VerifyFull => postgres::config::SslMode::Require,
    });
    if config.get_password().is_none() {
        if let Some(p) = password_from_env(&config, env)? {
            config.password(p);
        }
    }
    Ok(Target { config, ssl_mode, root_cert })
}

/// `PGPASSWORD`, else the first matching line of the password file.
fn password_from_env(config: &postgres::Config, env: &dyn Fn(&str) -> Option<String>) -> Result<Option<String>> {
    if let Some(p) = env("PGPASSWORD").filter(|p| !p.is_empty()) {
        return Ok(Some(p));
    }
    let file = match env("PGPASSFILE") {
        Some(f) => PathBuf::from(f),
        None => match env("HOME") {
            Some(h) => Path::new(&h).join(".pgpass"),
            None => return Ok(None),
        },
    };
    let Ok(text) = std::fs::read_to_string(&file) else { return Ok(None) };
    // libpq ignores a password file readable by group or others, saying so.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        let mode = std::fs::metadata(&file)?.permissions().mode();
        if mode & 0o077 != 0 {
            bail!(
                "{} has group or world access (mode {:o}): libpq ignores such a file; chmod 0600 it",
                file.display(),
                mode & 0o777
            );
        }
    }
    let host = match config.get_hosts().first() {
        Some(postgres::config::Host::Tcp(h)) => h.clone(),
        // libpq matches a Unix-socket connection against `localhost`.
        _ => "localhost".into(),
    };
    let port = config.get_ports().first().copied().unwrap_or(5432).to_string();
    let user = config.get_user().unwrap_or_default().to_string();
    let db = config.get_dbname().map_or_else(|| user.clone(), str::to_string);
    Ok(pgpass_lookup(&text, [&host, &port, &db, &user]))
}

/// The password of the first line of a password file whose four fields (host, port, database,
/// user; `*` matches anything) match `want`. Fields are separated by `:`; `\` escapes `:` and
/// `\`; lines starting with `#` are comments.
pub fn pgpass_lookup(text: &str, want: [&str; 4]) -> Option<String> {
    for line in text.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty()) {
        let mut fields = vec![String::new()];
        let mut chars = line.chars();
        while let Some(c) = chars.next() {
            match c {
                '\\' => fields.last_mut()?.extend(chars.next()),
                ':' if fields.len() < 5 => fields.push(String::new()),
                c => fields.last_mut()?.push(c),
            }
        }
        if fields.len() == 5 && fields[..4].iter().zip(want).all(|(f, w)| f == "*" || f == w) {
            return fields.pop();
        }
    }
    None
}

/// Connects to `url`: TLS per its `sslmode`, the password per libpq's rules.
pub fn connect(url: &str) -> Result<postgres::Client> {
    let t = target(url, &|k| std::env::var(k).ok())?;
    Ok(match t.ssl_mode {
        SslMode::Disable => t.config.connect(postgres::NoTls)?,
        mode => t
            .config
            .connect(tokio_postgres_rustls::MakeRustlsConnect::new(tls_config(mode, t.root_cert.as_deref())?))?,
    })
}

/// rustls with the `ring` provider: certificate checks per `mode`.
fn tls_config(mode: SslMode, root_cert: Option<&Path>) -> Result<rustls::ClientConfig> {
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let builder = rustls::ClientConfig::builder_with_provider(provider.clone())
        .with_safe_default_protocol_versions()
        .context("TLS set-up")?;
    Ok(match mode {
        SslMode::VerifyFull => {
            let mut roots = rustls::RootCertStore::empty();
            match root_cert {
                Some(path) => {
                    use rustls::pki_types::pem::PemObject as _;
                    for cert in CertificateDer::pem_file_iter(path)
                        .with_context(|| format!("cannot read sslrootcert {}", path.display()))?
                    {
                        roots.add(cert.with_context(|| format!("sslrootcert {}", path.display()))?)?;
                    }
                }
                None => {
                    for cert in rustls_native_certs::load_native_certs().certs {
                        // A certificate of the system store rustls cannot parse is skipped, as
                        // libpq's OpenSSL would skip it.
                        let _ = roots.add(cert);
                    }
                }
            }
            builder.with_root_certificates(roots).with_no_client_auth()
        }
        _ => builder.dangerous().with_custom_certificate_verifier(Arc::new(Unchecked(provider))).with_no_client_auth(),
    })
}

/// libpq's `prefer` and `require`: the channel is encrypted and the handshake's signatures are
/// checked, but not who signed the server's certificate (use `verify-full` for that).
#[derive(Debug)]
struct Unchecked(Arc<rustls::crypto::CryptoProvider>);

impl ServerCertVerifier for Unchecked {
    fn verify_server_cert(
        &self,
        _: &CertificateDer<'_>,
        _: &[CertificateDer<'_>],
        _: &ServerName<'_>,
        _: &[u8],
        _: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        Ok(ServerCertVerified::assertion())
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls12_signature(message, cert, dss, &self.0.signature_verification_algorithms)
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls13_signature(message, cert, dss, &self.0.signature_verification_algorithms)
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.0.signature_verification_algorithms.supported_schemes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pgpass_lines_match_with_wildcards_and_escapes() {
        let file = "# comment\nother:5432:*:u:no\ndb.lab:*:records:gyro:p\\:w\\\\d\n*:*:*:*:fallback\n";
        assert_eq!(pgpass_lookup(file, ["db.lab", "5433", "records", "gyro"]).as_deref(), Some("p:w\\d"));
        assert_eq!(pgpass_lookup(file, ["db.lab", "5432", "other", "gyro"]).as_deref(), Some("fallback"));
        assert_eq!(pgpass_lookup("h:1:d:u:pw", ["h", "2", "d", "u"]), None);
    }

    fn env_of(vars: &'static [(&'static str, &'static str)]) -> impl Fn(&str) -> Option<String> {
        move |k| vars.iter().find(|(n, _)| *n == k).map(|(_, v)| v.to_string())
    }

    #[test]
    fn sslmode_as_libpq_spells_it_and_the_password_from_the_environment() {
        let t = target(
            "postgres://gyro@db.lab/records?sslmode=verify-full&sslrootcert=/etc/ca.pem",
            &env_of(&[("PGPASSWORD", "s3cret")]),
        )
        .unwrap();
        assert_eq!(t.ssl_mode, SslMode::VerifyFull);
        assert_eq!(t.root_cert.as_deref(), Some(Path::new("/etc/ca.pem")));
        assert_eq!(t.config.get_password(), Some(&b"s3cret"[..]));
        assert_eq!(t.config.get_dbname(), Some("records"));
        // The URL's own password wins over PGPASSWORD.
        let t =
            target("postgres://gyro:inurl@db.lab/records?sslmode=require", &env_of(&[("PGPASSWORD", "env")])).unwrap();
        assert_eq!((t.ssl_mode, t.config.get_password()), (SslMode::Require, Some(&b"inurl"[..])));
        assert_eq!(target("postgres://h/d", &env_of(&[])).unwrap().ssl_mode, SslMode::Prefer);
        let e = target("postgres://h/d?sslmode=always", &env_of(&[])).err().unwrap();
        assert_eq!(
            e.to_string(),
            "sslmode=always is not one of libpq's: disable, allow, prefer, require, verify-ca, verify-full"
        );
    }

    #[cfg(unix)]
    #[test]
    fn the_password_file_is_read_and_refused_when_others_can_read_it() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("pgpass");
        std::fs::write(&file, "db.lab:5432:records:gyro:fromfile\n").unwrap();
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o600)).unwrap();
        let path = file.to_str().unwrap().to_string();
        let env = move |k: &str| (k == "PGPASSFILE").then(|| path.clone());
        let t = target("postgres://gyro@db.lab/records", &env).unwrap();
        assert_eq!(t.config.get_password(), Some(&b"fromfile"[..]));
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = target("postgres://gyro@db.lab/records", &env).err().unwrap();
        assert_eq!(
            e.to_string(),
            format!(
                "{} has group or world access (mode 644): libpq ignores such a file; chmod 0600 it",
                file.display()
            )
        );
    }
}
