//! A thermal session's files: simulating one (`host simulate --chamber-c`) and recomputing one
//! from its folder (`host calibrate --replay <folder>`).

use super::manifest::{SetpointEntry, ThermalManifest, MANIFEST_FILE};
use super::settle::SettleCriterion;
use super::warm_up::BesideModel;
use super::{SetpointCal, ThermalModel, CALIBRATION_KEY};
use crate::calib::CalReport;
use crate::sim::{self, SimConfig};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// The thermal report's file name in the output folder.
pub const THERMAL_REPORT: &str = "thermal.html";

/// Capture file name in each setpoint folder of a simulated programme (its truth beside it).
pub const SIM_CAPTURE: &str = "session.cap";

/// Simulates `base`'s runs at each setpoint into `out_dir/spN_Tc/session.cap` (truth beside
/// each) and writes `out_dir/thermal.json`; an existing manifest there is refused.
pub fn simulate_programme(base: &SimConfig, setpoints_c: &[f64], out_dir: &Path) -> Result<ThermalManifest> {
    if out_dir.join(MANIFEST_FILE).exists() {
        bail!("{} already holds a thermal session ({MANIFEST_FILE}): choose another --out", out_dir.display());
    }
    let criterion = SettleCriterion::default();
    let steps = super::programme::programme(base, setpoints_c, criterion).context("invalid simulation")?;
    let mut entries = Vec::with_capacity(steps.len());
    for (i, (step, &setpoint_c)) in steps.iter().zip(setpoints_c).enumerate() {
        let dir_name = ThermalManifest::folder_name(i + 1, setpoint_c);
        let dir = out_dir.join(&dir_name);
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let out = sim::simulate(&step.config).context("invalid simulation")?;
        let cap = dir.join(SIM_CAPTURE);
        crate::files::write_atomic(&cap, &out.bytes)?;
        crate::files::write_atomic(&cap.with_extension("truth.json"), out.truth.to_json_pretty())?;
        entries.push(SetpointEntry {
            setpoint_c,
            dir: dir_name,
            captures: vec![SIM_CAPTURE.to_string()],
            settle_s: Some(step.settle_s),
        });
    }
    let manifest = ThermalManifest { criterion, setpoints: entries };
    manifest.write(out_dir)?;
    Ok(manifest)
}

/// The OUT_TEMP readings of the runs in `files`.
pub fn out_temp_readings(files: &[PathBuf]) -> Result<Vec<i8>> {
    let mut raw = Vec::new();
    for f in files {
        let file = std::fs::File::open(f).with_context(|| format!("cannot read capture {}", f.display()))?;
        let cap = crate::capture::decode_reader_by_run(file, |run, _| run)
            .with_context(|| format!("cannot read capture {}", f.display()))?;
        raw.extend(cap.runs.iter().flat_map(|r| r.temperatures.iter().map(|t| t.raw)));
    }
    Ok(raw)
}

/// One setpoint's calibration as `calibrate` wrote it (`dir/calibration.json`) with its
/// captures' OUT_TEMP readings.
pub fn setpoint_from_files(
    setpoint_c: f64,
    cal_dir: &Path,
    captures: &[PathBuf],
) -> Result<(SetpointCal, serde_json::Value)> {
    let path = cal_dir.join("calibration.json");
    let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{} is not JSON", path.display()))?;
    let report: CalReport = serde_json::from_value(value.clone())
        .with_context(|| format!("{} is not a calibration report", path.display()))?;
    let raw = out_temp_readings(captures)?;
    let sp = SetpointCal::from_report(setpoint_c, &report, &raw)
        .with_context(|| format!("the captures of setpoint {setpoint_c} °C hold no OUT_TEMP reading"))?;
    Ok((sp, value))
}

/// Fits the model over the setpoints and writes `out_dir/thermal.html` (each quantity against
/// temperature) and `out_dir/calibration.json`: the calibration of
/// the setpoint nearest the model's reference temperature (what `host apply` uses without
/// `--temp-c`, and the exports), with the model in its `thermal` section and any setpoint's own
/// warm-up coefficients beside the model's slopes. Returns the model and that comparison.
pub fn write_model(
    out_dir: &Path,
    setpoints: Vec<(SetpointCal, serde_json::Value)>,
) -> Result<(ThermalModel, Vec<BesideModel>)> {
    let cals: Vec<SetpointCal> = setpoints.iter().map(|(s, _)| s.clone()).collect();
    let model = ThermalModel::fit(&cals).context("thermal model")?;
    let own: Vec<(f64, serde_json::Value)> = setpoints.iter().map(|(s, v)| (s.setpoint_c, v.clone())).collect();
    let beside = super::warm_up::beside_model(&model, &own);
    let nearest = setpoints
        .into_iter()
        .min_by(|a, b| {
            (a.0.setpoint_c - model.reference_c).abs().total_cmp(&(b.0.setpoint_c - model.reference_c).abs())
        })
        .expect("the model has setpoints");
    let mut value = nearest.1;
    let obj = value.as_object_mut().context("a calibration report is a JSON object")?;
    obj.insert(CALIBRATION_KEY.into(), serde_json::to_value(&model)?);
    obj.insert("thermal_base_setpoint_c".into(), nearest.0.setpoint_c.into());
    if !beside.is_empty() {
        obj.insert(super::warm_up::BESIDE_MODEL_KEY.into(), serde_json::to_value(&beside)?);
    }
    crate::files::write_atomic(&out_dir.join("calibration.json"), serde_json::to_string_pretty(&value)?)?;
    crate::files::write_atomic(&out_dir.join(THERMAL_REPORT), super::plots::html(&model, &beside))?;
    Ok((model, beside))
}

/// The thermal model in a `calibration.json`, if it holds one.
pub fn model_in(calibration_json: &str) -> Result<Option<ThermalModel>> {
    let value: serde_json::Value = serde_json::from_str(calibration_json).context("not JSON")?;
    value
        .get(CALIBRATION_KEY)
        .map(|m| serde_json::from_value(m.clone()).context("its thermal section is not a thermal model"))
        .transpose()
}
