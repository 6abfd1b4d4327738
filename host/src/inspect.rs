//! What a capture holds, for `host inspect` and for the header of every calibration.

use crate::capture::{Capture, Run, RunOrigin};
use protocol::{sample_status, Edge};
use serde::Serialize;
use std::fmt::{self, Write as _};

/// A hole in the sample timestamps: more than 1.5 nominal periods between two samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SampleGap {
    /// Time of the sample before the gap, s since the start of the capture.
    pub after_s: f64,
    /// Length of the gap, ms.
    pub gap_ms: f64,
    /// Samples missing, from the measured sample period.
    pub missing: u64,
}

/// Per-run facts.
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// e.g. "pose 1, +180.0 °/s".
    pub label: String,
    /// Pose number.
    pub pose: u8,
    /// Signed commanded base rate, °/s.
    pub rate_dps: f64,
    /// Whether the RunStarted frame was lost and the run recovered from motor status.
    pub recovered: bool,
    /// Whether the run ended with RunStopped.
    pub stopped: bool,
    /// Samples.
    pub samples: usize,
    /// Time covered by samples, s.
    pub duration_s: f64,
    /// Measured sample rate from the timestamps, Hz.
    pub sample_rate_hz: f64,
    /// Nominal ODR, Hz.
    pub odr_hz: u16,
    /// Index pulses (rising edges).
    pub index_pulses: usize,
    /// Index pulses per second.
    pub index_rate_hz: f64,
    /// Mean base speed from the encoder over the run, °/s.
    pub encoder_rate_dps: f64,
    /// Samples flagged overrun by the gyro.
    pub overrun_samples: usize,
    /// Samples at the i16 limits on any axis.
    pub clipped_samples: usize,
    /// Holes in the sample timestamps.
    pub gaps: Vec<SampleGap>,
    /// Faults reported during the run.
    pub faults: Vec<String>,
    /// Last counters report: queue drops, SPI errors.
    pub queue_drops: Option<u32>,
    /// SPI errors from the last counters report.
    pub spi_errors: Option<u32>,
}

/// A capture, summarised.
#[derive(Debug, Clone, Serialize)]
pub struct Inspection {
    /// Where it came from.
    pub source: String,
    /// Firmware version, if a Hello was seen.
    pub firmware: Option<String>,
    /// Protocol version, if a Hello was seen.
    pub protocol_version: Option<u16>,
    /// Gyro settings, as text.
    pub gyro: Option<String>,
    /// Encoder counts per revolution.
    pub encoder_counts_per_rev: Option<u32>,
    /// Gear ratio num/den.
    pub gear_ratio: Option<(u16, u16)>,
    /// Runs.
    pub runs: Vec<RunSummary>,
    /// Faults reported outside any run, e.g. `WatchdogReset at 0.000 s`.
    pub faults: Vec<String>,
    /// Loss accounting.
    pub loss: crate::capture::LossReport,
}

/// Summarises one run.
pub fn summarize_run(run: &Run) -> RunSummary {
    let odr_hz = run.gyro.odr.hz();
    let duration_s = run.duration_s();
    let n = run.samples.len();
    let sample_rate_hz = if duration_s > 0.0 { (n - 1) as f64 / duration_s } else { 0.0 };
    let period_us = if sample_rate_hz > 0.0 { 1e6 / sample_rate_hz } else { 1e6 / f64::from(odr_hz) };
    let gaps = run
        .samples
        .windows(2)
        .filter_map(|w| {
            let dt = (w[1].t_us - w[0].t_us) as f64;
            (dt > 1.5 * period_us).then(|| SampleGap {
                after_s: w[0].t_us as f64 * 1e-6,
                gap_ms: dt * 1e-3,
                missing: (dt / period_us).round() as u64 - 1,
            })
        })
        .collect();
    let index_pulses = run.index.iter().filter(|e| e.edge == Edge::Rising).count();
    let index_span_s = match (run.index.first(), run.index.last()) {
        (Some(a), Some(b)) if b.t_us > a.t_us => (b.t_us - a.t_us) as f64 * 1e-6,
        _ => 0.0,
    };
    let index_rate_hz = if index_span_s > 0.0 { (index_pulses.saturating_sub(1)) as f64 / index_span_s } else { 0.0 };
    let encoder_rate_dps = match (run.samples.first(), run.samples.last()) {
        (Some(a), Some(b)) if duration_s > 0.0 => {
            protocol::units::deg_from_counts((b.encoder - a.encoder) as f64, run.hello.encoder_counts_per_rev)
                / duration_s
        }
        _ => 0.0,
    };
    let last_counters = run.counters.last().map(|(_, c)| *c);
    RunSummary {
        label: run.label(),
        pose: run.pose.number(),
        rate_dps: run.commanded_rate_dps(),
        recovered: run.origin == RunOrigin::Recovered,
        stopped: run.stopped,
        samples: n,
        duration_s,
        sample_rate_hz,
        odr_hz,
        index_pulses,
        index_rate_hz,
        encoder_rate_dps,
        overrun_samples: run.samples.iter().filter(|s| s.status & sample_status::OVERRUN != 0).count(),
        clipped_samples: run
            .samples
            .iter()
            .filter(|s| s.rate_counts.iter().any(|&c| c == i16::MAX || c == i16::MIN))
            .count(),
        gaps,
        faults: run.faults.iter().map(|(t, f)| format!("{:?} at {:.3} s", f.fault, *t as f64 * 1e-6)).collect(),
        queue_drops: last_counters.map(|c| c.queue_drops),
        spi_errors: last_counters.map(|c| c.spi_errors),
    }
}

/// Summarises a decoded capture.
pub fn inspect(source: &str, capture: &Capture) -> Inspection {
    let h = capture.hello;
    Inspection {
        source: source.to_string(),
        firmware: h.map(|h| format!("{}.{}.{}", h.firmware.major, h.firmware.minor, h.firmware.patch)),
        protocol_version: h.map(|h| h.protocol_version),
        gyro: h.map(|h| {
            format!(
                "±{} °/s, ODR {} Hz, bandwidth {:?} ({:.1} Hz cut-off)",
                h.gyro.full_scale.range_dps(),
                h.gyro.odr.hz(),
                h.gyro.bandwidth,
                f64::from(h.gyro.bandwidth.cutoff_dhz(h.gyro.odr)) / 10.0
            )
        }),
        encoder_counts_per_rev: h.map(|h| h.encoder_counts_per_rev),
        gear_ratio: h.map(|h| (h.gear_ratio.num, h.gear_ratio.den)),
        runs: capture.runs.iter().map(summarize_run).collect(),
        faults: capture.faults.iter().map(|(t, f)| format!("{:?} at {:.3} s", f.fault, *t as f64 * 1e-6)).collect(),
        loss: capture.loss.clone(),
    }
}

impl fmt::Display for Inspection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "{}", self.source)?;
        match (&self.firmware, &self.gyro) {
            (Some(fw), Some(gyro)) => {
                writeln!(
                    f,
                    "  rig: firmware {fw}, protocol v{}, encoder {} counts/rev, gear ratio {}/{}",
                    self.protocol_version.unwrap_or_default(),
                    self.encoder_counts_per_rev.unwrap_or_default(),
                    self.gear_ratio.map_or(0, |g| g.0),
                    self.gear_ratio.map_or(0, |g| g.1),
                )?;
                writeln!(f, "  gyro: {gyro}")?;
            }
            _ => writeln!(f, "  rig: no Hello frame in this capture")?,
        }
        let l = &self.loss;
        if l.hello_assumed {
            writeln!(
                f,
                "  note: the Hello was lost; runs use the protocol's rig constants and their RunStarted gyro settings"
            )?;
        }
        for fault in &self.faults {
            writeln!(f, "  FAULT outside any run: {fault}")?;
        }
        writeln!(
            f,
            "  stream: {} bytes, {} frames valid, {} frames missing (sequence gaps), {} bytes in {} bad stretches, {} samples outside any run",
            l.bytes,
            l.frames_ok,
            l.frames_missing(),
            l.bytes_skipped(),
            l.error_count(),
            l.orphan_samples
        )?;
        for e in l.errors.iter().take(10) {
            writeln!(f, "    byte {}: {} ({} bytes skipped)", e.offset, e.error, e.len)?;
        }
        if l.error_count() > 10 {
            writeln!(f, "    … {} more", l.error_count() - 10)?;
        }
        for g in l.seq_gaps.iter().take(10) {
            writeln!(f, "    byte {}: {} frame(s) missing before this one", g.offset, g.missing)?;
        }
        if l.seq_gap_count() > 10 {
            writeln!(f, "    … {} more sequence gaps", l.seq_gap_count() - 10)?;
        }
        if self.runs.is_empty() {
            writeln!(f, "  runs: none")?;
        }
        for r in &self.runs {
            let mut notes = String::new();
            if r.recovered {
                notes.push_str(", start frame lost (pose from motor status)");
            }
            if !r.stopped {
                notes.push_str(", no stop frame (capture ended)");
            }
            writeln!(f, "  run {}{notes}", r.label)?;
            writeln!(
                f,
                "    {} samples over {:.2} s: {:.2} Hz measured (ODR {} Hz nominal), {} gaps",
                r.samples,
                r.duration_s,
                r.sample_rate_hz,
                r.odr_hz,
                r.gaps.len()
            )?;
            for g in r.gaps.iter().take(5) {
                writeln!(f, "      gap of {:.2} ms after {:.4} s (~{} samples)", g.gap_ms, g.after_s, g.missing)?;
            }
            writeln!(
                f,
                "    encoder: {:+.3} °/s mean; index: {} pulses, {:.4} Hz",
                r.encoder_rate_dps, r.index_pulses, r.index_rate_hz
            )?;
            let mut health = String::new();
            let _ = write!(health, "{} overrun, {} clipped samples", r.overrun_samples, r.clipped_samples);
            if let Some(q) = r.queue_drops {
                let _ = write!(health, "; rig counters: {q} queue drops, {} SPI errors", r.spi_errors.unwrap_or(0));
            }
            writeln!(f, "    {health}")?;
            for fault in &r.faults {
                writeln!(f, "    FAULT {fault}")?;
            }
        }
        Ok(())
    }
}
