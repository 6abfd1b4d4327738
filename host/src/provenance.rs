//! Which sensor, which run: the identity of a calibration session and the evidence it was
//! computed from. Captures stay the exact bytes of the wire; identity lives in a session
//! manifest (`session.json`) beside them, and every result carries a [`Provenance`].
//!
//! The provenance is an optional `provenance` member of `calibration.json`, added beside the
//! report's own fields, so files written before it existed still load (`CalReport` ignores
//! members it does not know).

use crate::capture::Capture;
use crate::report::html::escape;
use anyhow::{Context, Result};
use protocol::GyroConfig;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::fmt;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// Name of the session manifest written beside the captures of a live session.
pub const MANIFEST_FILE: &str = "session.json";

/// Who and what a session is about, as the operator states it.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Identity {
    /// Serial number of the gyro under calibration (as printed on its carrier board or label).
    pub sensor_serial: Option<String>,
    /// Who ran the session.
    pub operator: Option<String>,
    /// Which rig ran it.
    pub rig: Option<String>,
}

impl Identity {
    /// Fields of `self` where set, else those of `other`.
    pub fn or(self, other: Identity) -> Identity {
        Identity {
            sensor_serial: self.sensor_serial.or(other.sensor_serial),
            operator: self.operator.or(other.operator),
            rig: self.rig.or(other.rig),
        }
    }
}

/// One capture used, named and fingerprinted so a result can be traced to its exact bytes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CaptureDigest {
    /// File name as given (live: relative to the manifest).
    pub file: String,
    /// Size, bytes.
    pub bytes: u64,
    /// SHA-256 of the file's bytes, lower-case hex.
    pub sha256: String,
}

/// The session manifest: identity and captures, written beside the captures.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SessionManifest {
    /// Sensor, operator, rig.
    #[serde(flatten)]
    pub identity: Identity,
    /// When the session started, UTC, RFC 3339.
    pub started_utc: String,
    /// `host` version that recorded it.
    pub host_version: String,
    /// The captures, in recording order (empty until they are written).
    pub captures: Vec<CaptureDigest>,
}

impl SessionManifest {
    /// A manifest for a session starting now.
    pub fn start(identity: Identity) -> Self {
        Self { identity, started_utc: utc_now(), host_version: HOST_VERSION.to_string(), captures: Vec::new() }
    }

    /// Writes `dir/session.json`.
    pub fn write(&self, dir: &Path) -> Result<PathBuf> {
        let path = dir.join(MANIFEST_FILE);
        crate::files::write_atomic(&path, serde_json::to_string_pretty(self)?)?;
        Ok(path)
    }

    /// Compares `files` with the captures this manifest fingerprinted (matched by file name):
    /// one message per file whose bytes changed since it was recorded.
    pub fn verify(&self, files: &[PathBuf]) -> Result<Vec<String>> {
        let mut out = Vec::new();
        for f in files {
            let name = f.file_name().map(|n| n.to_string_lossy().into_owned());
            let recorded = self
                .captures
                .iter()
                .find(|c| Path::new(&c.file).file_name().map(|n| n.to_string_lossy().into_owned()) == name);
            if let Some(r) = recorded {
                let now = digest_file(f)?;
                if now.sha256 != r.sha256 {
                    out.push(format!(
                        "{} is not the capture recorded in {MANIFEST_FILE} (SHA-256 {} then, {} now)",
                        f.display(),
                        r.sha256,
                        now.sha256
                    ));
                }
            }
        }
        Ok(out)
    }

    /// Reads `dir/session.json` if there is one.
    pub fn read_beside(capture: &Path) -> Result<Option<Self>> {
        let path = capture.parent().unwrap_or(Path::new(".")).join(MANIFEST_FILE);
        if !path.exists() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
        let m = serde_json::from_str(&text).with_context(|| format!("{} is not a session manifest", path.display()))?;
        Ok(Some(m))
    }
}

/// Die-temperature range over the runs, from the gyro's OUT_TEMP register. The register reads
/// `c − T` with an offset `c` the datasheet leaves unspecified (L3G4200D Table 5: −1 LSB/°C), so
/// only the span is a temperature; the raw extremes are kept to compare sessions of one part.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DieTemperature {
    /// Lowest OUT_TEMP reading, LSB (the warmest moment: the register falls as T rises).
    pub out_temp_min_lsb: i8,
    /// Highest OUT_TEMP reading, LSB (the coolest moment).
    pub out_temp_max_lsb: i8,
    /// Span of die temperature during the runs, °C (1 LSB = 1 °C, datasheet Table 5).
    pub span_c: f64,
    /// Readings seen.
    pub readings: usize,
}

/// Everything a result needs to be traced: who, what, when, with what, from which bytes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// Sensor, operator, rig.
    #[serde(flatten)]
    pub identity: Identity,
    /// When the calibration was computed, UTC, RFC 3339.
    pub calibrated_utc: String,
    /// When the session was recorded (from its manifest), UTC, RFC 3339.
    pub session_started_utc: Option<String>,
    /// `host` version that computed it.
    pub host_version: String,
    /// Rig firmware version from the captures' `Hello`, e.g. `0.1.0`.
    pub rig_firmware: Option<String>,
    /// Gyro settings from the captures' `Hello`.
    pub gyro: Option<GyroConfig>,
    /// Every capture used.
    pub captures: Vec<CaptureDigest>,
    /// Die temperature during the runs.
    pub die_temperature: Option<DieTemperature>,
}

/// This program's version (Cargo package version).
pub const HOST_VERSION: &str = env!("CARGO_PKG_VERSION");

impl Provenance {
    /// Provenance of a result computed now from `files`: each capture as decoded, with the
    /// digest of the bytes it was decoded from.
    pub fn gather(identity: Identity, session_started_utc: Option<String>, files: &[(CaptureDigest, Capture)]) -> Self {
        let captures = files.iter().map(|(d, _)| d.clone()).collect();
        let hello = files.iter().find_map(|(_, c)| c.hello);
        let raw: Vec<i8> =
            files.iter().flat_map(|(_, c)| c.runs.iter().flat_map(|r| r.temperatures.iter().map(|t| t.raw))).collect();
        let die_temperature = match (raw.iter().min(), raw.iter().max()) {
            (Some(&lo), Some(&hi)) => Some(DieTemperature {
                out_temp_min_lsb: lo,
                out_temp_max_lsb: hi,
                span_c: f64::from(hi) - f64::from(lo),
                readings: raw.len(),
            }),
            _ => None,
        };
        Self {
            identity,
            calibrated_utc: utc_now(),
            session_started_utc,
            host_version: HOST_VERSION.to_string(),
            rig_firmware: hello.map(|h| format!("{}.{}.{}", h.firmware.major, h.firmware.minor, h.firmware.patch)),
            gyro: hello.map(|h| h.gyro),
            captures,
            die_temperature,
        }
    }

    /// Adds `"provenance": self` to a JSON object (the serialised report).
    pub fn attach(&self, mut report: serde_json::Value) -> serde_json::Value {
        if let Some(obj) = report.as_object_mut() {
            obj.insert("provenance".into(), serde_json::to_value(self).expect("plain data serialises"));
        }
        report
    }

    /// The `provenance` member of a calibration JSON, if present and well-formed; older files
    /// have none.
    pub fn from_calibration_json(text: &str) -> Option<Self> {
        let v: serde_json::Value = serde_json::from_str(text).ok()?;
        serde_json::from_value(v.get("provenance")?.clone()).ok()
    }
}

fn or_unknown(s: &Option<String>) -> &str {
    s.as_deref().unwrap_or("(not given)")
}

impl fmt::Display for Provenance {
    /// The lines the summary and the report print.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let id = &self.identity;
        writeln!(
            f,
            "Sensor: {}   operator: {}   rig: {}",
            or_unknown(&id.sensor_serial),
            or_unknown(&id.operator),
            or_unknown(&id.rig)
        )?;
        write!(f, "Calibrated: {} by host {}", self.calibrated_utc, self.host_version)?;
        if let Some(s) = &self.session_started_utc {
            write!(f, " (session recorded {s})")?;
        }
        writeln!(f)?;
        let g = self.gyro.map_or("(no Hello in the captures)".to_string(), |g| {
            format!("±{} °/s, {} Hz, bandwidth {:?}", g.full_scale.range_dps(), g.odr.hz(), g.bandwidth)
        });
        writeln!(f, "Rig firmware: {}   gyro: {g}", or_unknown(&self.rig_firmware))?;
        match &self.die_temperature {
            Some(t) => writeln!(
                f,
                "Die temperature: span {:.0} °C over {} readings (OUT_TEMP {}..{} LSB)",
                t.span_c, t.readings, t.out_temp_min_lsb, t.out_temp_max_lsb
            )?,
            None => writeln!(f, "Die temperature: no reading in the captures")?,
        }
        for c in &self.captures {
            writeln!(f, "Capture: {} ({} bytes) sha256 {}", c.file, c.bytes, c.sha256)?;
        }
        Ok(())
    }
}

impl Provenance {
    /// The certificate block of the HTML report: who, what, when, from which bytes.
    pub fn html_section(&self) -> String {
        let id = &self.identity;
        let mut rows = vec![
            ("Sensor serial", or_unknown(&id.sensor_serial).to_string()),
            ("Operator", or_unknown(&id.operator).to_string()),
            ("Rig", or_unknown(&id.rig).to_string()),
            ("Calibrated (UTC)", self.calibrated_utc.clone()),
            ("Session recorded (UTC)", self.session_started_utc.clone().unwrap_or_else(|| "(no manifest)".into())),
            ("Host version", self.host_version.clone()),
            ("Rig firmware", or_unknown(&self.rig_firmware).to_string()),
            (
                "Gyro",
                self.gyro.map_or("(no Hello)".into(), |g| {
                    format!("±{} °/s, {} Hz, bandwidth {:?}", g.full_scale.range_dps(), g.odr.hz(), g.bandwidth)
                }),
            ),
            (
                "Die temperature",
                self.die_temperature.map_or("(no reading)".into(), |t| {
                    format!(
                        "span {:.0} °C over {} readings (OUT_TEMP {}..{} LSB)",
                        t.span_c, t.readings, t.out_temp_min_lsb, t.out_temp_max_lsb
                    )
                }),
            ),
        ];
        for c in &self.captures {
            rows.push(("Capture", format!("{} ({} bytes), SHA-256 {}", c.file, c.bytes, c.sha256)));
        }
        let mut o = String::from("<section class=\"certificate\">\n<h2>Calibration certificate</h2>\n<table>\n");
        for (k, v) in rows {
            o.push_str(&format!(
                "<tr><th scope=\"row\">{}</th><td style=\"overflow-wrap:anywhere\">{}</td></tr>\n",
                escape(k),
                escape(&v)
            ));
        }
        o.push_str("</table>\n</section>\n");
        o
    }

    /// The report page `html` with [`Provenance::html_section`], then `extra` (e.g. the noise
    /// figures), right under its title: the page is assembled whole in memory and written once
    /// (never read back from its file, which a concurrent run could be writing).
    pub fn into_report(&self, html: &str, extra: &str) -> String {
        let at = html.find("</h1>").map_or(0, |i| i + "</h1>".len());
        format!("{}\n{}{extra}{}", &html[..at], self.html_section(), &html[at..])
    }
}

/// SHA-256 of a file, streamed in 1 MiB chunks (hour-long captures are 160 MB).
pub fn digest_file(path: &Path) -> Result<CaptureDigest> {
    let file = std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut reader = DigestReader::new(file);
    std::io::copy(&mut reader, &mut std::io::sink()).with_context(|| format!("cannot read {}", path.display()))?;
    Ok(reader.digest(path))
}

/// A reader that digests what passes through it, so a capture decoded as it is read is hashed
/// in the same pass rather than read a second time for its digest (the hashing itself stays).
pub struct DigestReader<R> {
    inner: R,
    hasher: Sha256,
    bytes: u64,
}

impl<R: Read> DigestReader<R> {
    pub fn new(inner: R) -> Self {
        Self { inner, hasher: Sha256::new(), bytes: 0 }
    }

    /// The digest of everything read so far, as the capture `path`.
    pub fn digest(self, path: &Path) -> CaptureDigest {
        let sha256 = self.hasher.finalize().iter().map(|b| format!("{b:02x}")).collect();
        CaptureDigest { file: path.display().to_string(), bytes: self.bytes, sha256 }
    }
}

impl<R: Read> Read for DigestReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.hasher.update(&buf[..n]);
        self.bytes += n as u64;
        Ok(n)
    }
}

/// Now, UTC, RFC 3339 to the second.
pub fn utc_now() -> String {
    humantime::format_rfc3339_seconds(SystemTime::now()).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// FIPS 180-2 test vector: SHA-256("abc").
    #[test]
    fn digest_of_abc_is_the_fips_vector() {
        let p = std::env::temp_dir().join(format!("prov-abc-{}", std::process::id()));
        std::fs::write(&p, b"abc").unwrap();
        let d = digest_file(&p).unwrap();
        std::fs::remove_file(&p).unwrap();
        assert_eq!(d.sha256, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
        assert_eq!(d.bytes, 3);
    }

    #[test]
    fn a_capture_changed_since_the_session_is_named() {
        let dir = std::env::temp_dir().join(format!("prov-verify-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (a, b) = (dir.join("a.cap"), dir.join("b.cap"));
        std::fs::write(&a, b"abc").unwrap();
        std::fs::write(&b, b"xyz").unwrap();
        let mut m = SessionManifest::start(Identity::default());
        m.captures = vec![digest_file(&a).unwrap(), digest_file(&b).unwrap()];
        assert!(m.verify(&[a.clone(), b.clone()]).unwrap().is_empty());
        std::fs::write(&b, b"xyZ").unwrap();
        let w = m.verify(&[a, b.clone()]).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(w.len(), 1);
        assert!(w[0].starts_with(&format!("{} is not the capture recorded in session.json", b.display())), "{w:?}");
    }

    #[test]
    fn provenance_round_trips_through_a_report_and_old_files_have_none() {
        let p = Provenance {
            identity: Identity { sensor_serial: Some("G-0042".into()), operator: Some("ada".into()), rig: None },
            calibrated_utc: "2026-11-23T05:00:00Z".into(),
            session_started_utc: None,
            host_version: HOST_VERSION.into(),
            rig_firmware: Some("0.1.0".into()),
            gyro: Some(GyroConfig::DEFAULT),
            captures: vec![CaptureDigest { file: "a.cap".into(), bytes: 3, sha256: "00".into() }],
            die_temperature: Some(DieTemperature {
                out_temp_min_lsb: 10,
                out_temp_max_lsb: 13,
                span_c: 3.0,
                readings: 9,
            }),
        };
        let with = p.attach(serde_json::json!({"model": "m"}));
        assert_eq!(Provenance::from_calibration_json(&with.to_string()), Some(p.clone()));
        assert_eq!(Provenance::from_calibration_json(r#"{"model":"m"}"#), None);
        let text = p.to_string();
        assert!(text.contains("Sensor: G-0042   operator: ada   rig: (not given)"), "{text}");
        assert!(text.contains("span 3 °C over 9 readings"), "{text}");
        let html = p.html_section();
        assert!(
            html.contains(
                "<tr><th scope=\"row\">Sensor serial</th><td style=\"overflow-wrap:anywhere\">G-0042</td></tr>"
            ),
            "{html}"
        );
    }
}
