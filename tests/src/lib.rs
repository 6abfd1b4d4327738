//! Shared helpers for the end-to-end tests: the committed captures, frame boundaries of a clean
//! stream, and the comparison of a calibration with the truth it was simulated from.

use host::calib::CalReport;
use host::sim::Truth;
use std::path::PathBuf;

/// 3σ for one parameter.
pub const Z_1D: f64 = 3.0;
/// The 2-D equivalent of 3σ (99.73 % of a 2-D normal lies within this Mahalanobis distance):
/// a direction has two tilt components.
pub const Z_2D: f64 = 3.44;

/// The virtual rig's device under test and offsets (`host::virtual_rig`, one place).
pub use host::virtual_rig::{VIRTUAL_GYRO_KS, VIRTUAL_GYRO_OFFSET_DPS};

/// Simulated time per lockstep step (`host::virtual_rig::LOCKSTEP_STEP_NS`).
pub use host::virtual_rig::LOCKSTEP_STEP_NS;

/// The simulated clock of a [`LockstepRig`], for `host::link::Link::with_clock`.
pub use host::virtual_rig::SimClock;

/// The firmware's virtual rig on a pty in lockstep (`virtual_rig --lockstep`): simulated time
/// advances only when this end reads, so a loaded machine slows the test down but never changes
/// what happens in it. Reading and writing it is reading and writing the pty
/// (`host::virtual_rig::LockstepPort`, the rig's standard input and output as its control
/// lines); [`Self::clock`] is the rig's simulated time. Killed when dropped.
pub struct LockstepRig {
    child: std::process::Child,
    port: host::virtual_rig::LockstepPort,
    /// The pty device, e.g. `/dev/pts/3`.
    pub path: String,
}

impl LockstepRig {
    /// Starts `exe` (pass `env!("CARGO_BIN_EXE_virtual_rig")`) with `--lockstep` and `args`,
    /// and opens its pty.
    pub fn spawn(exe: &str, args: &[&str]) -> Self {
        use std::io::BufRead;
        let mut child = std::process::Command::new(exe)
            .arg("--lockstep")
            .args(args)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::inherit())
            .spawn()
            .expect("spawn virtual_rig");
        let stdin = child.stdin.take().expect("stdin");
        let mut stdout = std::io::BufReader::new(child.stdout.take().expect("stdout"));
        let mut line = String::new();
        stdout.read_line(&mut line).expect("pty path");
        let path = line.trim().to_string();
        assert!(path.starts_with("/dev/"), "unexpected first line {path:?}");
        let port = host::virtual_rig::LockstepPort::open(&path, Box::new(stdout), Box::new(stdin))
            .expect("open the virtual rig's pty");
        Self { child, port, path }
    }

    /// The rig's simulated time.
    pub fn clock(&self) -> SimClock {
        self.port.clock()
    }

    /// Simulated time now, ns.
    pub fn now_ns(&self) -> u64 {
        self.port.now_ns()
    }

    /// Advances the rig by `ns` after it has received everything written so far, and reads all
    /// it sent meanwhile.
    pub fn step(&mut self, ns: u64) {
        self.port.step(ns).expect("the virtual rig steps");
    }
}

impl std::io::Read for LockstepRig {
    /// Returns what the rig has sent; when nothing is waiting, first runs one step of simulated
    /// time, and times out (`ErrorKind::TimedOut`) if the rig said nothing in it.
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.port.read(buf)
    }
}

impl std::io::Write for LockstepRig {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.port.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.port.flush()
    }
}

impl Drop for LockstepRig {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Path of a file under `tests/data/`.
pub fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data").join(name)
}

/// Reads a committed capture and its truth.
pub fn committed(stem: &str) -> (Vec<u8>, Truth) {
    let bytes = std::fs::read(data(&format!("{stem}.cap"))).expect("committed capture");
    let truth = serde_json::from_str(&std::fs::read_to_string(data(&format!("{stem}.truth.json"))).expect("truth"))
        .expect("truth parses");
    (bytes, truth)
}

/// `(start, len)` of every frame of a clean stream, delimiter excluded.
pub fn frames(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, &b) in bytes.iter().enumerate() {
        if b == 0 {
            out.push((start, i - start));
            start = i + 1;
        }
    }
    out
}

/// How far a calibration is from the truth, per axis, in units of its own uncertainty.
#[derive(Debug, Clone, Copy)]
pub struct AxisError {
    /// (k − k_true)/σ_k.
    pub k_z: f64,
    /// Mahalanobis distance of the direction error over its two tilt components.
    pub direction_md: f64,
    /// k error, ppm.
    pub k_ppm: f64,
    /// Angle between estimated and true direction, degrees.
    pub direction_deg: f64,
}

/// Compares every axis with the truth.
pub fn errors(report: &CalReport, truth: &Truth) -> [AxisError; 3] {
    std::array::from_fn(|i| {
        let a = &report.axes[i];
        let s = truth.s[i];
        let (j, l) = ((i + 1) % 3, (i + 2) % 3);
        let truth_tilt = [s[j].atan2(s[i]).to_degrees(), s[l].atan2(s[i]).to_degrees()];
        let d = [a.tilt_components_deg[0] - truth_tilt[0], a.tilt_components_deg[1] - truth_tilt[1]];
        let cos = (0..3).map(|c| a.s[c].value * s[c]).sum::<f64>().clamp(-1.0, 1.0);
        AxisError {
            k_z: a.k_counts_per_dps.z(truth.k_counts_per_dps[i]),
            direction_md: host::calib::result::derived::mahalanobis2(d, a.tilt_components_cov_deg2),
            k_ppm: (a.k_counts_per_dps.value / truth.k_counts_per_dps[i] - 1.0) * 1e6,
            direction_deg: cos.acos().to_degrees(),
        }
    })
}

/// Panics with the report if any axis is outside 3σ of the truth.
pub fn assert_within_3_sigma(report: &CalReport, truth: &Truth, context: &str) {
    for (i, e) in errors(report, truth).iter().enumerate() {
        assert!(
            e.k_z.abs() <= Z_1D && e.direction_md <= Z_2D,
            "{context}: axis {i} off the truth: k {:.2} σ, direction {:.2} σ\n{}",
            e.k_z,
            e.direction_md,
            report.summary()
        );
    }
}

/// ±500 °/s full scale (the virtual rig's default): 17.5 m°/s per count (L3G4200D datasheet
/// Table 4).
const VIRTUAL_DPS_PER_COUNT: f64 = 17.5e-3;

/// Panics with the report unless every axis matches the virtual rig's gyro
/// ([`VIRTUAL_GYRO_KS`], [`VIRTUAL_GYRO_OFFSET_DPS`]) within 3σ of the calibration's own
/// uncertainty: sensitivity, direction (both tilt components) and offset. In σ, not in fixed
/// tolerances, since the virtual gyro has the datasheet's noise and nothing the model lacks
/// stands above it (firmware/README.md, "Measured").
pub fn assert_matches_virtual_gyro(report: &CalReport) {
    let summary = report.summary();
    for (i, a) in report.axes.iter().enumerate() {
        let m: [f64; 3] = VIRTUAL_GYRO_KS[i].map(|v| v / VIRTUAL_DPS_PER_COUNT);
        let k = m.iter().map(|v| v * v).sum::<f64>().sqrt();
        let s = m.map(|v| v / k);
        let offset = VIRTUAL_GYRO_OFFSET_DPS[i] / VIRTUAL_DPS_PER_COUNT;
        let (j, l) = ((i + 1) % 3, (i + 2) % 3);
        let tilt = [s[j].atan2(s[i]).to_degrees(), s[l].atan2(s[i]).to_degrees()];
        let d = [a.tilt_components_deg[0] - tilt[0], a.tilt_components_deg[1] - tilt[1]];
        let k_z = a.k_counts_per_dps.z(k);
        let offset_z = a.offset_counts.z(offset);
        let direction_md = host::calib::result::derived::mahalanobis2(d, a.tilt_components_cov_deg2);
        eprintln!(
            "axis {i}: k {:.3} vs {k:.3} ({k_z:+.2} σ), direction {direction_md:.2} σ, \
             offset {:.2} vs {offset:.2} counts ({offset_z:+.2} σ)",
            a.k_counts_per_dps.value, a.offset_counts.value
        );
        assert!(
            k_z.abs() <= Z_1D && direction_md <= Z_2D && offset_z.abs() <= Z_1D,
            "axis {i} off the virtual gyro: k {k_z:.2} σ, direction {direction_md:.2} σ, \
             offset {offset_z:.2} σ\n{summary}"
        );
    }
}
