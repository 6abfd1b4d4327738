//! Rendering primitives for the calibration report: SVG figures ([`plots`]) and a
//! self-contained HTML page ([`html`]). Plain data in; nothing here knows calibration types, so
//! the report composer decides what to show and these modules decide only how.
//!
//! Composing a report:
//! ```no_run
//! use host::report::{Document, PlotSpec, Series, Verdict, line_plot, palette};
//! let mut doc = Document::new("Gyro calibration");
//! doc.verdict(Verdict::Ok, "Residuals at the noise floor on all axes.");
//! let spec = PlotSpec::new("Residual", "time [s]", "residual [°/s]");
//! let series = [Series::line("after", vec![(0.0, 0.1), (1.0, -0.1)], palette::AFTER)];
//! doc.figure_result(line_plot(&spec, &series), "Residual over time.");
//! doc.write_with_svgs("out", "calibration").unwrap();
//! ```

mod chart;
mod error;
pub mod html;
pub mod palette;
pub mod plots;
mod scale;

#[cfg(test)]
mod tests;

pub use html::{Document, Verdict, WrittenReport};
pub use plots::{
    bar_chart, line_plot, spectra_plot, spectrum_plot, theta2_panel, BarSeries, Marker, PlotError, PlotSpec, RefLine,
    Series, Spectrum, Style, Theta2Bins, Theta2Spec,
};
