//! A calibration report as plain text: the gyro's settings, each axis's sensitivity, direction
//! and offset with their σ, the angles between the axes, the residual against the noise floor,
//! the runs, the gear ratio and the paper's cross-check.

use super::{axis_table, PlusMinus};
use crate::calib::result::report::CalReport;
use std::fmt::Write as _;

impl CalReport {
    /// A readable multi-line summary, units everywhere, 1-σ beside each value.
    pub fn summary(&self) -> String {
        let mut o = String::new();
        let g = &self.gyro;
        let _ = writeln!(o, "Model: {}", self.model);
        let _ = writeln!(
            o,
            "Gyro: ±{} °/s, {} Hz; nominal sensitivity {:.4} counts/(°/s)",
            g.full_scale.range_dps(),
            g.odr.hz(),
            self.nominal_counts_per_dps
        );
        let _ = writeln!(
            o,
            "Samples: {} used, {} excluded (spin-up/stop, window edges, stale); clipped x/y/z: {}/{}/{}",
            self.samples_used, self.samples_excluded, self.clipped[0], self.clipped[1], self.clipped[2]
        );
        let _ = writeln!(o);
        axis_table::write(&mut o, self);
        let vs_nominal: Vec<String> =
            self.axes.iter().map(|a| format!("{} {:+.3} %", a.axis, a.k_vs_nominal_percent)).collect();
        let _ = writeln!(o, "  k against the datasheet's nominal sensitivity: {}", vs_nominal.join(", "));
        let _ = writeln!(o, "\nTilt components [°] (toward the other package axes):");
        for a in &self.axes {
            let c = &a.tilt_components_cov_deg2;
            let _ = writeln!(
                o,
                "  {} → {}: {:+.4} ± {:.4}   {} → {}: {:+.4} ± {:.4}",
                a.axis,
                a.tilt_component_axes[0],
                a.tilt_components_deg[0],
                c[0][0].sqrt(),
                a.axis,
                a.tilt_component_axes[1],
                a.tilt_components_deg[1],
                c[1][1].sqrt()
            );
        }
        let _ = writeln!(o, "\nAngles between axes [°]:");
        for p in &self.inter_axis {
            let _ = writeln!(
                o,
                "  {}–{}: {:.4}  (non-orthogonality {:+.4}°)",
                p.axes[0],
                p.axes[1],
                PlusMinus(p.angle_deg),
                p.non_orthogonality_deg
            );
        }
        let _ = writeln!(o, "\nResiduals (RMS vs noise floor measured from the data):");
        for r in &self.residuals {
            let _ = writeln!(
                o,
                "  {}: {:.2} counts = {:.4} °/s; floor {:.2} counts = {:.4} °/s; ratio {:.3}",
                r.axis, r.rms_counts, r.rms_dps, r.noise_floor_counts, r.noise_floor_dps, r.rms_over_floor
            );
        }
        for rr in &self.run_residuals {
            let ratios: Vec<String> = rr
                .axes
                .iter()
                .map(|a| format!("{} {:.2}/{:.2} counts", a.axis, a.rms_counts, a.noise_floor_counts))
                .collect();
            let _ =
                writeln!(o, "  run {} ({}, {:+.1} °/s): {}", rr.run, rr.pose, rr.commanded_rate_dps, ratios.join(", "));
        }
        let ac: Vec<String> = self
            .autocorrelation
            .iter()
            .map(|a| format!("{} ×{:.2} (blocks of {})", a.axis, a.inflation, a.block_samples))
            .collect();
        let _ = writeln!(o, "  covariance inflation for autocorrelation: {}", ac.join(", "));
        let gr = &self.gear;
        let _ = writeln!(
            o,
            "\nGear ratio θ2'/θ1': {:.8} (nominal {:.6}; {:+.3} ± {:.3} ppm from nominal)",
            gr.ratio.value,
            gr.nominal,
            gr.deviation_ppm,
            gr.ratio.sigma / gr.nominal * 1e6
        );
        for r in &self.runs {
            let i = &r.index;
            let _ = writeln!(
                o,
                "  run {} ({}, {:+.1} °/s → {:+.3} °/s measured, {:.1} Hz): {}/{} samples used ({} unsteady, {} edge, {} stale, {} near gaps); index {} pulses ({} rejected), θ2 ref ± {:.1e}°, centre rms {:.2} counts; θ1' window {} samples, quantisation {:.4} °/s",
                r.run,
                r.pose,
                r.commanded_rate_dps,
                r.steady_rate_dps,
                r.sample_rate_hz,
                r.samples_used,
                r.samples_total,
                r.excluded_unsteady,
                r.excluded_window_edge,
                r.excluded_stale,
                r.excluded_near_gaps,
                i.pulses,
                i.rejected,
                i.ref_sigma_deg,
                i.centre_rms_counts,
                r.rate_window_samples,
                r.rate_quantisation_dps
            );
        }
        match &self.paper {
            Some(p) => {
                let _ = writeln!(o, "\nPaper method (eq. 4-5) cross-check, z = (joint − paper)/σ_paper:");
                for a in &p.axes {
                    let _ = writeln!(
                        o,
                        "  {}: k {:.5} (z {:+.2}); offset {:+.3} counts (z {:+.2}); s [{:+.6}, {:+.6}, {:+.6}] (z {:+.2}, {:+.2}, {:+.2})",
                        a.axis,
                        PlusMinus(a.k_counts_per_dps),
                        a.z_k,
                        PlusMinus(a.offset_counts),
                        a.z_offset,
                        a.s[0].value,
                        a.s[1].value,
                        a.s[2].value,
                        a.z_s[0],
                        a.z_s[1],
                        a.z_s[2]
                    );
                }
                let _ = writeln!(o, "  agreement: max |z| {:.2}, rms z {:.2}", p.max_abs_z, p.rms_z);
            }
            None => {
                let _ = writeln!(o, "\nPaper method cross-check: not available (a per-pose sinusoid fit was singular)");
            }
        }
        o
    }
}
