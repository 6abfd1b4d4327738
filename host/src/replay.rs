//! The captures `host calibrate` is given, made ready for the calibration: each file decoded
//! once, run by run, its digest taken from the same bytes; its losses, faults and a lost `Hello`
//! said; every run checked against all the others for the same data given twice; the moving
//! runs' kinematics reconstructed as they are decoded, and the static runs (0 °/s, whose samples
//! give the noise figures) kept in their captures.

use crate::calib::data::kinematics::{KinOptions, Reconstruction};
use crate::capture::{self, Capture, PackedSamples, Run, Samples as _};
use crate::provenance::{CaptureDigest, DigestReader};
use anyhow::{bail, Context, Result};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The captures, decoded.
pub struct Loaded {
    /// Each file's digest and capture; the moving runs carry no samples (their kinematics are in
    /// `kinematics`), the static runs carry theirs.
    pub captures: Vec<(CaptureDigest, Capture)>,
    /// The moving runs' kinematics, reconstructed run by run.
    pub kinematics: Reconstruction,
}

impl Loaded {
    /// Takes the moving runs out of the captures (the calibration's data); the static runs stay
    /// there for the noise figures.
    pub fn take_moving_runs(&mut self) -> Vec<Run> {
        let mut moving_runs = Vec::new();
        for (_, cap) in &mut self.captures {
            let (still, moving): (Vec<_>, Vec<_>) =
                std::mem::take(&mut cap.runs).into_iter().partition(|r| r.rate_mdps == 0);
            cap.runs = still;
            moving_runs.extend(moving);
        }
        moving_runs
    }
}

/// Decodes `files` in order; `note` receives one informational line per file (its losses) and
/// per thing worth saying (a lost `Hello`, a fault outside any run). An error names the file:
/// unreadable, another protocol version, no run at all, or a run that is the same data as an
/// earlier one (it would count twice and shrink every σ by √2).
pub fn load(files: &[PathBuf], kinematics: KinOptions, note: &mut dyn FnMut(&str)) -> Result<Loaded> {
    let mut loaded = Loaded { captures: Vec::new(), kinematics: Reconstruction::new(kinematics) };
    let mut seen: HashMap<u64, (PathBuf, usize)> = HashMap::new();
    for f in files {
        let mut fingerprints = Vec::new();
        let (cap, digest) = read_capture_by_run(f, |mut run, samples| {
            fingerprints.push((!samples.is_empty()).then(|| run.fingerprint_with(&samples)));
            if run.rate_mdps == 0 {
                run.samples = samples.to_vec();
            } else {
                loaded.kinematics.add(&run, &samples);
            }
            run
        })?;
        let runs_with_samples =
            cap.runs.iter().zip(fingerprints).enumerate().filter_map(|(i, (r, p))| Some((i, r, p?)));
        for (i, run, fingerprint) in runs_with_samples {
            if let Some((first, j)) = seen.insert(fingerprint, (f.clone(), i + 1)) {
                bail!(
                    "run {} of {} ({}) is the same data as run {j} of {}: give each capture once",
                    i + 1,
                    f.display(),
                    run.label(),
                    first.display()
                );
            }
        }
        check(f, &cap, note)?;
        loaded.captures.push((digest, cap));
    }
    Ok(loaded)
}

/// Says what one decoded capture lost, and refuses one this host cannot calibrate from.
fn check(f: &Path, cap: &Capture, note: &mut dyn FnMut(&str)) -> Result<()> {
    let l = &cap.loss;
    note(&format!(
        "{}: {} run(s), {} bytes, {} frames lost, {} bytes corrupt",
        f.display(),
        cap.runs.len(),
        l.bytes,
        l.frames_missing(),
        l.bytes_skipped()
    ));
    if let Some(h) = cap.hello.filter(|h| h.protocol_version != protocol::PROTOCOL_VERSION) {
        bail!(
            "{} was recorded with protocol v{}, this host reads v{}",
            f.display(),
            h.protocol_version,
            protocol::PROTOCOL_VERSION
        );
    }
    if cap.runs.is_empty() {
        bail!(
            "{} holds no run: no RunStarted frame and no motor status naming a pose ({} valid frames)",
            f.display(),
            l.frames_ok
        );
    }
    if cap.loss.hello_assumed {
        note(&format!("{}: the Hello was lost; the protocol's rig constants are assumed", f.display()));
    }
    for (t, fault) in &cap.faults {
        note(&format!(
            "{}: the rig reported {:?} outside any run at {:.3} s",
            f.display(),
            fault.fault,
            *t as f64 * 1e-6
        ));
    }
    Ok(())
}

/// Reads and decodes a capture file run by run: `on_run` gets each run with its samples (packed)
/// as soon as it is decoded, and returns the run the capture keeps. The file's digest is taken
/// from the same bytes, as they are read.
pub fn read_capture_by_run(
    path: &Path,
    on_run: impl FnMut(Run, PackedSamples) -> Run,
) -> Result<(Capture, CaptureDigest)> {
    let file = std::fs::File::open(path).with_context(|| format!("cannot read capture {}", path.display()))?;
    let mut reader = DigestReader::new(file);
    let cap = capture::decode_reader_by_run(&mut reader, on_run)
        .with_context(|| format!("cannot read capture {}", path.display()))?;
    Ok((cap, reader.digest(path)))
}
