//! Plot functions for the calibration report: plain data in, a self-contained SVG string out.
//!
//! Text is left to the viewer's sans-serif font (the SVG backend needs no font files). NaN
//! points are drawn as gaps, data outside an explicit range is clipped at the frame, and
//! undrawable input (nothing finite, bad ranges, mismatched lengths) is a [`PlotError`] rather
//! than a blank or misleading figure.
//!
//! Drawn with plotters through [`super::chart`], whose doc says what plotters lacks and why that
//! layer is ours; moving it onto another charting crate is left for a later round (issue 7).

use super::chart::{self, Area, FrameText, LegendItem, Mapper, Stroke, Swatch, MARGIN_LEFT, MARGIN_RIGHT, TICK_PX};
pub use super::error::PlotError;
use super::palette::{self, INK};
use super::scale::{self, Axis, AxisRequest};
use plotters::style::text_anchor::{HPos, VPos};

/// Title, axis labels (with units), ranges and size of one figure.
#[derive(Debug, Clone, PartialEq)]
pub struct PlotSpec {
    /// Figure title, drawn above the plot.
    pub title: String,
    /// x axis label, with unit, e.g. "θ2 [°]".
    pub x_label: String,
    /// y axis label, with unit, e.g. "residual [°/s]".
    pub y_label: String,
    /// Explicit x range; `None` fits the data.
    pub x_range: Option<(f64, f64)>,
    /// Explicit y range; `None` fits the data.
    pub y_range: Option<(f64, f64)>,
    /// Width, px.
    pub width_px: u32,
    /// Height, px.
    pub height_px: u32,
    /// Explicit x ticks; `None` chooses 1-2-5 steps.
    pub x_ticks: Option<Vec<f64>>,
    /// Logarithmic y axis (values ≤ 0 are not drawn).
    pub log_y: bool,
    /// Logarithmic x axis (values ≤ 0 are not drawn).
    pub log_x: bool,
}

impl PlotSpec {
    /// 800×420 px (fits a 60 rem column), ranges from the data, linear axes.
    pub fn new(title: impl Into<String>, x_label: impl Into<String>, y_label: impl Into<String>) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            x_range: None,
            y_range: None,
            width_px: 800,
            height_px: 420,
            x_ticks: None,
            log_y: false,
            log_x: false,
        }
    }
    /// Sets the x range.
    pub fn with_x_range(mut self, lo: f64, hi: f64) -> Self {
        self.x_range = Some((lo, hi));
        self
    }
    /// Sets the y range.
    pub fn with_y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y_range = Some((lo, hi));
        self
    }
    /// Sets the size, px.
    pub fn with_size(mut self, width_px: u32, height_px: u32) -> Self {
        self.width_px = width_px;
        self.height_px = height_px;
        self
    }
    /// Sets the x ticks.
    pub fn with_x_ticks(mut self, ticks: Vec<f64>) -> Self {
        self.x_ticks = Some(ticks);
        self
    }
    /// Makes the y axis logarithmic.
    pub fn with_log_y(mut self) -> Self {
        self.log_y = true;
        self
    }
    /// Makes the x axis logarithmic.
    pub fn with_log_x(mut self) -> Self {
        self.log_x = true;
        self
    }
}

/// How a series is drawn.
#[derive(Debug, Clone, PartialEq)]
pub enum Style {
    /// Solid 2 px line.
    Line,
    /// Dashed 1 px line, for references and bounds drawn as data.
    Dashed,
    /// Filled dots, for measurements (bin means).
    Points,
    /// Solid line inside a shaded band, e.g. a mean ±1 SE; `lower`/`upper` pair with `points`.
    LineWithBand {
        /// Lower edge of the band at each point's x.
        lower: Vec<f64>,
        /// Upper edge of the band at each point's x.
        upper: Vec<f64>,
    },
}

/// One labelled data series; an empty label keeps it out of the legend.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// (x, y) in data units; NaN breaks the line.
    pub points: Vec<(f64, f64)>,
    /// How to draw it.
    pub style: Style,
    /// Index into the colour-blind-safe palette ([`palette::SERIES`]).
    pub colour: usize,
}

impl Series {
    /// A solid line.
    pub fn line(label: impl Into<String>, points: Vec<(f64, f64)>, colour: usize) -> Self {
        Self { label: label.into(), points, style: Style::Line, colour }
    }
    /// A dashed line.
    pub fn dashed(label: impl Into<String>, points: Vec<(f64, f64)>, colour: usize) -> Self {
        Self { label: label.into(), points, style: Style::Dashed, colour }
    }
    /// Dots.
    pub fn points(label: impl Into<String>, points: Vec<(f64, f64)>, colour: usize) -> Self {
        Self { label: label.into(), points, style: Style::Points, colour }
    }
    /// A line in a band from `lower` to `upper`.
    pub fn with_band(
        label: impl Into<String>,
        points: Vec<(f64, f64)>,
        lower: Vec<f64>,
        upper: Vec<f64>,
        colour: usize,
    ) -> Self {
        Self { label: label.into(), points, style: Style::LineWithBand { lower, upper }, colour }
    }

    fn check(&self) -> Result<(), PlotError> {
        if let Style::LineWithBand { lower, upper } = &self.style {
            for (what, v) in [("band lower", lower), ("band upper", upper)] {
                if v.len() != self.points.len() {
                    return Err(PlotError::LengthMismatch {
                        series: self.label.clone(),
                        what,
                        expected: self.points.len(),
                        got: v.len(),
                    });
                }
            }
        }
        Ok(())
    }

    fn ys(&self) -> Vec<f64> {
        let mut ys: Vec<f64> = self.points.iter().map(|p| p.1).collect();
        if let Style::LineWithBand { lower, upper } = &self.style {
            ys.extend(lower.iter().chain(upper));
        }
        ys
    }

    fn legend_item(&self) -> Option<LegendItem> {
        let swatch = match self.style {
            Style::Line => Swatch::Line,
            Style::Dashed => Swatch::Dashed,
            Style::Points => Swatch::Point,
            Style::LineWithBand { .. } => Swatch::LineBand,
        };
        (!self.label.is_empty()).then(|| LegendItem::new(&self.label, palette::series(self.colour), swatch))
    }
}

/// Draws series bands first, then lines, then points, so that measurements stay on top.
fn draw_series(root: &Area<'_>, m: &Mapper, series: &[Series]) -> Result<(), PlotError> {
    for s in series {
        if let Style::LineWithBand { lower, upper } = &s.style {
            let xlu: Vec<_> = s.points.iter().zip(lower.iter().zip(upper)).map(|(p, (l, u))| (p.0, *l, *u)).collect();
            chart::band(root, m, &xlu, palette::series(s.colour))?;
        }
    }
    for s in series {
        let c = palette::series(s.colour);
        match s.style {
            Style::Line | Style::LineWithBand { .. } => chart::line(root, m, &s.points, Stroke::solid(c))?,
            Style::Dashed => chart::line(root, m, &s.points, Stroke { colour: c, width: 1, dashed: true })?,
            Style::Points => {}
        }
    }
    for s in series.iter().filter(|s| s.style == Style::Points) {
        chart::points(root, m, &s.points, palette::series(s.colour))?;
    }
    Ok(())
}

/// Labelled ticks for an axis of this many px: about one per 100 px across, so labels never
/// touch, and one per 50 px up.
fn x_tick_target(width: u32) -> usize {
    (width as usize / 100).clamp(3, 12)
}
fn y_tick_target(height: u32) -> usize {
    (height as usize / 50).clamp(3, 10)
}

fn x_axis(spec: &PlotSpec, data: Option<(f64, f64)>, pad: f64) -> Result<Axis, PlotError> {
    scale::axis(
        data,
        AxisRequest {
            fixed: spec.x_range,
            ticks: spec.x_ticks.as_deref(),
            log: spec.log_x,
            pad,
            target_ticks: x_tick_target(spec.width_px),
            name: "x",
        },
    )
}

fn y_axis(fixed: Option<(f64, f64)>, data: Option<(f64, f64)>, log: bool, height: u32) -> Result<Axis, PlotError> {
    scale::axis(
        data,
        AxisRequest { fixed, ticks: None, log, pad: 0.06, target_ticks: y_tick_target(height), name: "y" },
    )
}

/// Width available to a legend: the plotting area's.
fn legend_width(width: u32, y_area: i32) -> i32 {
    width as i32 - MARGIN_LEFT - y_area - MARGIN_RIGHT
}

/// Draws the title and, under it, the legend strip aligned with the plot frame; returns the pixel
/// row where the plot body may begin. Every chart starts this way.
fn heading(
    root: &chart::Area<'_>,
    title: &str,
    items: &[LegendItem],
    width_px: u32,
    y_label_area: i32,
) -> Result<i32, PlotError> {
    let top = chart::title(root, title)?;
    let lw = legend_width(width_px, y_label_area);
    chart::legend(root, items, MARGIN_LEFT + y_label_area, top, lw)?;
    Ok(top + chart::legend_height(items, lw))
}

/// Line, dot and band series on shared axes, with a legend strip above the plot.
pub fn line_plot(spec: &PlotSpec, series: &[Series]) -> Result<String, PlotError> {
    series.iter().try_for_each(Series::check)?;
    if !series.iter().any(|s| s.points.iter().any(|p| p.0.is_finite() && p.1.is_finite())) {
        return Err(PlotError::NoFiniteData);
    }
    let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
    let x = x_axis(spec, scale::extent(xs, spec.log_x), 0.02)?;
    let ydata = scale::extent(series.iter().flat_map(Series::ys), spec.log_y);
    let y = y_axis(spec.y_range, ydata, spec.log_y, spec.height_px)?;
    let items: Vec<_> = series.iter().filter_map(Series::legend_item).collect();
    chart::render(spec.width_px, spec.height_px, |root| {
        let ya = chart::y_label_area(&y);
        let below_legend = heading(root, &spec.title, &items, spec.width_px, ya)?;
        let (_, body) = root.split_vertically(below_legend);
        let text =
            FrameText { x_desc: &spec.x_label, y_desc: &spec.y_label, y_label_area: ya, x_labels: true, x_grid: true };
        let m = chart::frame(&body, &x, &y, &text)?;
        draw_series(root, &m, series)
    })
}

/// θ2 bin statistics of one axis and run, for one calibration state ("before", "after").
#[derive(Debug, Clone, PartialEq)]
pub struct Theta2Bins {
    /// Legend prefix, e.g. "before" or "after".
    pub label: String,
    /// Palette index, e.g. [`palette::BEFORE`].
    pub colour: usize,
    /// Bin centres, degrees in 0…360.
    pub theta2_deg: Vec<f64>,
    /// Mean measured output in each bin (NaN for an empty bin).
    pub measured: Vec<f64>,
    /// Model prediction at each bin centre.
    pub model: Vec<f64>,
    /// Mean residual (measured − model) in each bin.
    pub residual: Vec<f64>,
    /// Standard error of each residual mean.
    pub residual_se: Vec<f64>,
    /// Samples in each bin.
    pub counts: Vec<u64>,
    /// White-noise floor of one sample, same unit; draws ±floor/√n, the spread bin means would
    /// have if the model left nothing but noise.
    pub noise_floor: Option<f64>,
}

impl Theta2Bins {
    fn check(&self) -> Result<(), PlotError> {
        let n = self.theta2_deg.len();
        let lens = [
            ("measured", self.measured.len()),
            ("model", self.model.len()),
            ("residual", self.residual.len()),
            ("residual_se", self.residual_se.len()),
            ("counts", self.counts.len()),
        ];
        match lens.into_iter().find(|(_, l)| *l != n) {
            Some((what, got)) => Err(PlotError::LengthMismatch { series: self.label.clone(), what, expected: n, got }),
            None => Ok(()),
        }
    }

    fn floor_over_root_n(&self) -> Option<Vec<f64>> {
        let f = self.noise_floor?;
        Some(self.counts.iter().map(|&n| if n > 0 { f / (n as f64).sqrt() } else { f64::NAN }).collect())
    }

    fn pts(&self, ys: &[f64]) -> Vec<(f64, f64)> {
        self.theta2_deg.iter().copied().zip(ys.iter().copied()).collect()
    }
}

/// Title, unit and size of a θ2 figure.
#[derive(Debug, Clone, PartialEq)]
pub struct Theta2Spec {
    /// Figure title, e.g. "Axis x, run 3 (pose 1, +180 °/s)".
    pub title: String,
    /// Unit of output and residual, e.g. "°/s".
    pub unit: String,
    /// Width, px.
    pub width_px: u32,
    /// Height, px (both panels).
    pub height_px: u32,
}

impl Theta2Spec {
    /// 800×600 px.
    pub fn new(title: impl Into<String>, unit: impl Into<String>) -> Self {
        Self { title: title.into(), unit: unit.into(), width_px: 800, height_px: 600 }
    }
}

/// Fit and residual against θ2 for one axis and run: the upper panel shows measured bin
/// means (dots) and the model (line); the lower one the residual bin means with a ±1 SE band,
/// the zero line and ±floor/√n (dashed). Each entry of `curves` (before, after) is overlaid in
/// its own colour; the panels share the 0…360° axis so features line up by eye. When the
/// "before" residual dwarfs the "after" one, draw "after" alone too: its scale is the story.
pub fn theta2_panel(spec: &Theta2Spec, curves: &[Theta2Bins]) -> Result<String, PlotError> {
    curves.iter().try_for_each(Theta2Bins::check)?;
    let top_vals = || curves.iter().flat_map(|c| c.measured.iter().chain(&c.model).copied());
    let floors: Vec<Vec<f64>> = curves.iter().map(|c| c.floor_over_root_n().unwrap_or_default()).collect();
    let bottom_vals: Vec<f64> = curves
        .iter()
        .zip(&floors)
        .flat_map(|(c, f)| {
            let band = c.residual.iter().zip(&c.residual_se).flat_map(|(r, s)| [r - s, r + s]);
            c.residual.iter().copied().chain(band).chain(f.iter().flat_map(|v| [*v, -v]))
        })
        .collect();
    if scale::extent(top_vals(), false).is_none() && scale::extent(bottom_vals.iter().copied(), false).is_none() {
        return Err(PlotError::NoFiniteData);
    }
    let ticks: Vec<f64> = (0..=8).map(|i| f64::from(i) * 45.0).collect();
    let x = scale::axis(
        None,
        AxisRequest {
            fixed: Some((0.0, 360.0)),
            ticks: Some(&ticks),
            log: false,
            pad: 0.0,
            target_ticks: 8,
            name: "x",
        },
    )?;
    let top_h = spec.height_px * 11 / 20;
    // An all-NaN panel still gets axes (around zero), so the figure keeps its shape.
    let y_top = y_axis(None, scale::extent(top_vals(), false).or(Some((0.0, 0.0))), false, top_h)?;
    let y_bot =
        y_axis(None, scale::extent(bottom_vals.iter().copied().chain([0.0]), false), false, spec.height_px - top_h)?;

    let mut items = Vec::new();
    for c in curves {
        let col = palette::series(c.colour);
        items.push(LegendItem::group(format!("{}:", c.label)));
        items.push(LegendItem::new("measured (bin mean)", col, Swatch::Point));
        items.push(LegendItem::new("model", col, Swatch::Line));
        items.push(LegendItem::new("residual ±1 SE", col, Swatch::LineBand));
        if c.noise_floor.is_some() {
            items.push(LegendItem::new("±floor/√n", col, Swatch::Dashed));
        }
    }
    let unit = &spec.unit;
    chart::render(spec.width_px, spec.height_px, |root| {
        let ya = chart::y_label_area(&y_top).max(chart::y_label_area(&y_bot));
        let below_legend = heading(root, &spec.title, &items, spec.width_px, ya)?;
        let (_, body) = root.split_vertically(below_legend);
        let (_, body_h) = body.dim_in_pixel();
        let (upper, lower) = body.split_vertically(body_h * 11 / 20);
        let up_desc = format!("output [{unit}]");
        let up_text = FrameText { x_desc: "", y_desc: &up_desc, y_label_area: ya, x_labels: false, x_grid: true };
        let mu = chart::frame(&upper, &x, &y_top, &up_text)?;
        let low_desc = format!("residual [{unit}]");
        let low_text =
            FrameText { x_desc: "θ2 [°]", y_desc: &low_desc, y_label_area: ya, x_labels: true, x_grid: true };
        let ml = chart::frame(&lower, &x, &y_bot, &low_text)?;
        chart::hline(root, &ml, 0.0, Stroke { colour: INK, width: 1, dashed: false })?;
        for c in curves {
            let col = palette::series(c.colour);
            let xlu: Vec<_> = c
                .theta2_deg
                .iter()
                .zip(c.residual.iter().zip(&c.residual_se))
                .map(|(t, (r, s))| (*t, r - s, r + s))
                .collect();
            chart::band(root, &ml, &xlu, col)?;
        }
        for (c, floor) in curves.iter().zip(&floors) {
            let col = palette::series(c.colour);
            chart::line(root, &mu, &c.pts(&c.model), Stroke::solid(col))?;
            chart::line(root, &ml, &c.pts(&c.residual), Stroke::solid(col))?;
            if !floor.is_empty() {
                let dashed = Stroke { colour: col, width: 1, dashed: true };
                chart::line(root, &ml, &c.pts(floor), dashed)?;
                chart::line(root, &ml, &c.pts(&floor.iter().map(|v| -v).collect::<Vec<_>>()), dashed)?;
            }
        }
        for c in curves {
            chart::points(root, &mu, &c.pts(&c.measured), palette::series(c.colour))?;
        }
        Ok(())
    })
}

/// A labelled frequency, e.g. "1×" at the table rate.
#[derive(Debug, Clone, PartialEq)]
pub struct Marker {
    /// Frequency, Hz.
    pub freq_hz: f64,
    /// Label drawn above the plot, e.g. "1×".
    pub label: String,
}

/// One amplitude spectrum.
#[derive(Debug, Clone, PartialEq)]
pub struct Spectrum {
    /// Legend text, e.g. "before" (empty: no legend entry).
    pub label: String,
    /// Bin frequencies, Hz.
    pub freqs_hz: Vec<f64>,
    /// Amplitude of each bin, °/s.
    pub amp_dps: Vec<f64>,
    /// Palette index.
    pub colour: usize,
}

/// Amplitude spectrum on a log amplitude axis, with dashed vertical lines at `markers` and the
/// noise floor as a dashed horizontal line.
pub fn spectrum_plot(
    spec: &PlotSpec,
    freqs_hz: &[f64],
    amp_dps: &[f64],
    markers: &[Marker],
    floor_dps: Option<f64>,
) -> Result<String, PlotError> {
    let one = Spectrum {
        label: String::new(),
        freqs_hz: freqs_hz.to_vec(),
        amp_dps: amp_dps.to_vec(),
        colour: palette::AFTER,
    };
    spectra_plot(spec, std::slice::from_ref(&one), markers, floor_dps)
}

const MARKER_LANE: i32 = 17;

/// Marker label lanes: labels that would overlap go one lane higher, so close harmonics stay
/// readable. Returns (marker index, pixel x, lane) for markers inside the x range.
fn marker_lanes(markers: &[Marker], px_x: impl Fn(f64) -> Option<f64>) -> Vec<(usize, f64, i32)> {
    let mut placed: Vec<(usize, f64, i32)> =
        markers.iter().enumerate().filter_map(|(i, mk)| px_x(mk.freq_hz).map(|x| (i, x, 0))).collect();
    placed.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut lane_end: Vec<f64> = Vec::new();
    for p in &mut placed {
        let half = chart::text_width(&markers[p.0].label, TICK_PX) / 2.0;
        let lane = lane_end.iter().position(|end| p.1 - half > end + 6.0).unwrap_or(lane_end.len());
        if lane == lane_end.len() {
            lane_end.push(0.0);
        }
        lane_end[lane] = p.1 + half;
        p.2 = lane as i32;
    }
    placed
}

/// Several spectra (e.g. before and after) overlaid; see [`spectrum_plot`]. The y axis is
/// always logarithmic (`spec.log_y` is ignored); bins with amplitude ≤ 0 are not drawn.
pub fn spectra_plot(
    spec: &PlotSpec,
    spectra: &[Spectrum],
    markers: &[Marker],
    floor_dps: Option<f64>,
) -> Result<String, PlotError> {
    for s in spectra {
        if s.amp_dps.len() != s.freqs_hz.len() {
            return Err(PlotError::LengthMismatch {
                series: s.label.clone(),
                what: "amp_dps",
                expected: s.freqs_hz.len(),
                got: s.amp_dps.len(),
            });
        }
    }
    let drawable = |f: f64, a: f64| f.is_finite() && a.is_finite() && a > 0.0;
    let xs = spectra
        .iter()
        .flat_map(|s| s.freqs_hz.iter().zip(&s.amp_dps).filter(|(f, a)| drawable(**f, **a)).map(|p| *p.0));
    let x = x_axis(spec, scale::extent(xs, false), 0.0)?;
    let ys = spectra.iter().flat_map(|s| s.amp_dps.iter().copied()).collect::<Vec<_>>();
    if scale::extent(ys.iter().copied(), true).is_none() {
        return Err(PlotError::NoFiniteData);
    }
    let y = y_axis(spec.y_range, scale::extent(ys.into_iter().chain(floor_dps), true), true, spec.height_px)?;
    let mut items: Vec<_> = spectra
        .iter()
        .filter(|s| !s.label.is_empty())
        .map(|s| LegendItem::new(&s.label, palette::series(s.colour), Swatch::Line))
        .collect();
    if floor_dps.is_some() {
        items.push(LegendItem::new("noise floor", palette::REFERENCE, Swatch::Dashed));
    }
    chart::render(spec.width_px, spec.height_px, |root| {
        let ya = chart::y_label_area(&y);
        let below_legend = heading(root, &spec.title, &items, spec.width_px, ya)?;
        // Lay the labels out on the x mapping the frame will have: its pixel span is fixed by
        // the margins and the label area.
        let (left, right) = ((MARGIN_LEFT + ya) as f64, (spec.width_px as i32 - MARGIN_RIGHT) as f64);
        let predicted = |f: f64| {
            (f.is_finite() && f >= x.lo && f <= x.hi).then(|| left + (f - x.lo) / (x.hi - x.lo) * (right - left))
        };
        let lanes = marker_lanes(markers, predicted);
        let strip = lanes.iter().map(|l| (l.2 + 1) * MARKER_LANE).max().unwrap_or(0);
        let (_, body) = root.split_vertically(below_legend + strip);
        let text =
            FrameText { x_desc: &spec.x_label, y_desc: &spec.y_label, y_label_area: ya, x_labels: true, x_grid: true };
        let m = chart::frame(&body, &x, &y, &text)?;
        for &(i, _, lane) in &lanes {
            chart::vline(root, &m, markers[i].freq_hz, Stroke::reference())?;
            if let Some(px) = m.px_x_of(markers[i].freq_hz) {
                let at = (px.round() as i32, m.px_y.1 as i32 - 3 - lane * MARKER_LANE);
                chart::text(root, &markers[i].label, at, TICK_PX, (HPos::Center, VPos::Bottom), INK, false)?;
            }
        }
        if let Some(f) = floor_dps {
            chart::hline(root, &m, f, Stroke::reference())?;
        }
        for s in spectra {
            let pts: Vec<_> = s.freqs_hz.iter().copied().zip(s.amp_dps.iter().copied()).collect();
            chart::line(root, &m, &pts, Stroke { colour: palette::series(s.colour), width: 1, dashed: false })?;
        }
        Ok(())
    })
}

/// One group member of a bar chart, e.g. "before" with one value per axis.
#[derive(Debug, Clone, PartialEq)]
pub struct BarSeries {
    /// Legend text.
    pub label: String,
    /// One value per category; NaN shows as "n/a".
    pub values: Vec<f64>,
    /// Palette index.
    pub colour: usize,
}

/// A labelled horizontal reference, e.g. "noise floor" at 1.
#[derive(Debug, Clone, PartialEq)]
pub struct RefLine {
    /// Value, y units.
    pub value: f64,
    /// Legend text.
    pub label: String,
}

/// Grouped bars, one group per category (e.g. axis x, y, z), one bar per series (e.g. before,
/// after), each labelled with its value so the figure also serves as the table. Honours
/// `spec.log_y` and `spec.y_range`; x range and ticks are the categories.
pub fn bar_chart(
    spec: &PlotSpec,
    categories: &[String],
    series: &[BarSeries],
    reference: Option<&RefLine>,
) -> Result<String, PlotError> {
    for s in series {
        if s.values.len() != categories.len() {
            return Err(PlotError::LengthMismatch {
                series: s.label.clone(),
                what: "values",
                expected: categories.len(),
                got: s.values.len(),
            });
        }
    }
    let vals = || series.iter().flat_map(|s| s.values.iter().copied());
    if categories.is_empty() || scale::extent(vals(), spec.log_y).is_none() {
        return Err(PlotError::NoFiniteData);
    }
    let x = Axis::categories(categories);
    let baseline = (!spec.log_y).then_some(0.0);
    let ydata = scale::extent(vals().chain(reference.map(|r| r.value)).chain(baseline), spec.log_y);
    // Headroom above the tallest bar for its value label.
    let ydata = ydata.map(|(lo, hi)| (lo, hi + (hi - lo) * 0.08));
    let y = y_axis(spec.y_range, ydata, spec.log_y, spec.height_px)?;
    let mut items: Vec<_> =
        series.iter().map(|s| LegendItem::new(&s.label, palette::series(s.colour), Swatch::Bar)).collect();
    if let Some(r) = reference {
        items.push(LegendItem::new(&r.label, palette::REFERENCE, Swatch::Dashed));
    }
    chart::render(spec.width_px, spec.height_px, |root| {
        let ya = chart::y_label_area(&y);
        let below_legend = heading(root, &spec.title, &items, spec.width_px, ya)?;
        let (_, body) = root.split_vertically(below_legend);
        let text =
            FrameText { x_desc: &spec.x_label, y_desc: &spec.y_label, y_label_area: ya, x_labels: true, x_grid: false };
        let m = chart::frame(&body, &x, &y, &text)?;
        let group = 0.7;
        let w = group / series.len().max(1) as f64;
        let bottom_px = m.px_y.0 as i32;
        for (j, s) in series.iter().enumerate() {
            for (i, &v) in s.values.iter().enumerate() {
                let x0 = i as f64 + (1.0 - group) / 2.0 + j as f64 * w;
                // A hair of white between neighbours keeps adjacent bars distinct in grey print.
                let drawn = chart::bar(root, &m, x0 + 0.01, x0 + w - 0.01, v, palette::series(s.colour))?;
                let centre = m.px((x0 + w / 2.0, m.y.0)).0.round() as i32;
                let (at, vpos) = match drawn {
                    Some((_, top_px)) if v >= 0.0 || spec.log_y => ((centre, top_px as i32 - 3), VPos::Bottom),
                    Some((_, top_px)) => ((centre, top_px as i32 + 3), VPos::Top),
                    None => ((centre, bottom_px - 3), VPos::Bottom),
                };
                chart::text(root, &scale::format_value(v), at, TICK_PX, (HPos::Center, vpos), INK, false)?;
            }
        }
        if let Some(r) = reference {
            chart::hline(root, &m, r.value, Stroke { colour: palette::REFERENCE, width: 2, dashed: true })?;
        }
        Ok(())
    })
}
