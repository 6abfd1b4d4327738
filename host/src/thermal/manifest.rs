//! A thermal session's folder: one subfolder per setpoint with its captures, and `thermal.json`
//! naming each setpoint with its folder and captures (so every capture carries its setpoint).

use super::settle::SettleCriterion;
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The manifest's file name in the session folder.
pub const MANIFEST_FILE: &str = "thermal.json";

/// One setpoint of the session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetpointEntry {
    /// Chamber setpoint, °C.
    pub setpoint_c: f64,
    /// Subfolder of the session folder holding this setpoint's captures.
    pub dir: String,
    /// Capture file names in `dir`, in recording order.
    pub captures: Vec<String>,
    /// From the chamber's step to the settled verdict, s (rig time spent waiting).
    #[serde(default)]
    pub settle_s: Option<f64>,
}

/// The thermal session's manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalManifest {
    /// The settle criterion the session waited on.
    pub criterion: SettleCriterion,
    /// The setpoints in the order they were run.
    pub setpoints: Vec<SetpointEntry>,
}

impl ThermalManifest {
    /// The folder name of setpoint number `index` (from 1) at `setpoint_c`: `sp1_m20c`, `sp3_25c`.
    pub fn folder_name(index: usize, setpoint_c: f64) -> String {
        let t = format!("{setpoint_c}").replace('-', "m").replace('.', "p");
        format!("sp{index}_{t}c")
    }

    /// Writes `dir/thermal.json` whole.
    pub fn write(&self, dir: &Path) -> Result<PathBuf> {
        let path = dir.join(MANIFEST_FILE);
        crate::files::write_atomic(&path, serde_json::to_string_pretty(self)?)?;
        Ok(path)
    }

    /// Reads `dir/thermal.json` if `dir` is a folder holding one.
    pub fn read_in(dir: &Path) -> Result<Option<Self>> {
        let path = dir.join(MANIFEST_FILE);
        if !dir.is_dir() || !path.is_file() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
        let m: Self =
            serde_json::from_str(&text).with_context(|| format!("{} is not a thermal manifest", path.display()))?;
        if m.setpoints.is_empty() {
            bail!("{} names no setpoint", path.display());
        }
        for s in &m.setpoints {
            if !s.setpoint_c.is_finite() || s.captures.is_empty() || s.dir.contains("..") {
                bail!(
                    "{}: setpoint {:?} needs a finite temperature, a folder inside the session and a capture",
                    path.display(),
                    s.setpoint_c
                );
            }
        }
        Ok(Some(m))
    }

    /// Each setpoint's folder and capture paths under the session folder `dir`.
    pub fn paths(&self, dir: &Path) -> Vec<(f64, PathBuf, Vec<PathBuf>)> {
        self.setpoints
            .iter()
            .map(|s| {
                let d = dir.join(&s.dir);
                let caps = s.captures.iter().map(|c| d.join(c)).collect();
                (s.setpoint_c, d, caps)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folder_names_and_the_manifest_round_trip() {
        assert_eq!(ThermalManifest::folder_name(1, -20.0), "sp1_m20c");
        assert_eq!(ThermalManifest::folder_name(3, 25.0), "sp3_25c");
        assert_eq!(ThermalManifest::folder_name(4, 37.5), "sp4_37p5c");
        let dir = std::env::temp_dir().join(format!("thermal-manifest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        assert_eq!(ThermalManifest::read_in(&dir).unwrap(), None);
        let m = ThermalManifest {
            criterion: SettleCriterion::default(),
            setpoints: vec![SetpointEntry {
                setpoint_c: -20.0,
                dir: "sp1_m20c".into(),
                captures: vec!["session.cap".into()],
                settle_s: Some(2100.0),
            }],
        };
        m.write(&dir).unwrap();
        let back = ThermalManifest::read_in(&dir).unwrap().unwrap();
        assert_eq!(back, m);
        assert_eq!(back.paths(&dir)[0].2, vec![dir.join("sp1_m20c").join("session.cap")]);
        std::fs::write(
            dir.join(MANIFEST_FILE),
            r#"{"criterion":{"max_slope_c_per_min":0.03,"window_s":600,"max_span_c":1},"setpoints":[]}"#,
        )
        .unwrap();
        assert!(ThermalManifest::read_in(&dir).unwrap_err().to_string().contains("names no setpoint"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
