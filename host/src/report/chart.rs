//! The drawing layer under the plot functions: a plotters frame (axes, grid, tick labels) plus
//! our own clipping, dashing, legend and text in pixel space. Plotters neither clips series to
//! the plotting area nor dashes lines in SVG, and its built-in legend sits on top of the data;
//! doing those here keeps every figure inside its frame and its legend off the curves.

use super::error::PlotError;
use super::palette::{self, GRID, GRID_MINOR, INK};
use super::scale::Axis;
use plotters::coord::ranged1d::{KeyPointHint, NoDefaultFormatting, Ranged, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

pub(crate) type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

/// Font family: left to the browser, which renders SVG text (no font files on CI).
pub(crate) const FONT: &str = "sans-serif";
/// Text sizes, CSS px.
pub(crate) const TITLE_PX: f64 = 16.0;
pub(crate) const DESC_PX: f64 = 14.0;
pub(crate) const TICK_PX: f64 = 12.5;
pub(crate) const LEGEND_PX: f64 = 13.0;
/// Space between the right edge of the plotting area and the figure edge: room for the last
/// x tick label, which is centred on the edge.
pub(crate) const MARGIN_RIGHT: i32 = 28;
/// Left margin of the figure, before the y label area.
pub(crate) const MARGIN_LEFT: i32 = 6;
/// Height of the x tick label plus axis description area.
pub(crate) const X_LABEL_AREA: i32 = 48;

/// Allowed figure sizes, px: below this nothing legible fits, above it is a mistake.
const MIN_SIZE: (u32, u32) = (240, 160);
const MAX_SIDE: u32 = 8000;

fn backend_err<E: std::error::Error>(e: E) -> PlotError {
    PlotError::Backend(e.to_string())
}

/// Size to give plotters so that the SVG says `size_px`: its SVG backend divides by 1.24.
fn font_size(size_px: f64) -> f64 {
    size_px * 1.24
}

/// Estimated rendered width of `s`: the mean advance of sans-serif glyphs is about 0.56 em,
/// enough to keep labels apart without font metrics.
pub(crate) fn text_width(s: &str, size_px: f64) -> f64 {
    s.chars().count() as f64 * 0.56 * size_px
}

/// Draws into a fresh white SVG of `width`×`height` px and returns its text.
pub(crate) fn render(
    width: u32,
    height: u32,
    draw: impl FnOnce(&Area<'_>) -> Result<(), PlotError>,
) -> Result<String, PlotError> {
    if width < MIN_SIZE.0 || height < MIN_SIZE.1 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(PlotError::InvalidSize { width, height });
    }
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(backend_err)?;
        draw(&root)?;
        root.present().map_err(backend_err)?;
    }
    Ok(buf)
}

/// Text at a pixel position.
pub(crate) fn text(
    area: &Area<'_>,
    s: &str,
    at: (i32, i32),
    size_px: f64,
    anchor: (HPos, VPos),
    colour: RGBColor,
    bold: bool,
) -> Result<(), PlotError> {
    let font =
        if bold { (FONT, font_size(size_px), FontStyle::Bold) } else { (FONT, font_size(size_px), FontStyle::Normal) };
    let style = TextStyle::from(font.into_font()).color(&colour).pos(Pos::new(anchor.0, anchor.1));
    area.draw(&Text::new(s.to_string(), at, style)).map_err(backend_err)
}

/// The figure title, centred at the top; returns the height it took.
pub(crate) fn title(area: &Area<'_>, s: &str) -> Result<i32, PlotError> {
    if s.is_empty() {
        return Ok(8);
    }
    let (w, _) = area.dim_in_pixel();
    text(area, s, (w as i32 / 2, 8), TITLE_PX, (HPos::Center, VPos::Top), INK, true)?;
    Ok(32)
}

/// How a legend entry shows its series.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Swatch {
    Line,
    Dashed,
    Point,
    /// A line inside a shaded band.
    LineBand,
    Bar,
    /// No swatch: a bold group name.
    Heading,
}

#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LegendItem {
    pub label: String,
    pub colour: RGBColor,
    pub swatch: Swatch,
    /// Starts a new legend row: one row per group (e.g. before, after) reads as a key.
    pub new_row: bool,
}

impl LegendItem {
    pub fn new(label: impl Into<String>, colour: RGBColor, swatch: Swatch) -> Self {
        Self { label: label.into(), colour, swatch, new_row: false }
    }

    /// A bold group name opening a new row.
    pub fn group(label: impl Into<String>) -> Self {
        Self { label: label.into(), colour: INK, swatch: Swatch::Heading, new_row: true }
    }

    fn width(&self) -> i32 {
        let text = text_width(&self.label, LEGEND_PX).ceil() as i32;
        match self.swatch {
            Swatch::Heading => text + 14,
            _ => SWATCH_W + 6 + text + 18,
        }
    }
}

const LEGEND_ROW: i32 = 20;
const SWATCH_W: i32 = 26;

/// Legend entries flowed left to right in rows; positions relative to (left, top). Rows that
/// wrap inside a group are indented past its name, so they still read as part of it.
fn legend_layout(items: &[LegendItem], width: i32) -> Vec<(i32, i32)> {
    let (mut x, mut row, mut indent) = (0, 0, 0);
    items
        .iter()
        .map(|it| {
            let w = it.width();
            if it.new_row {
                indent = 0;
            }
            if x > indent && (it.new_row || x + w > width) {
                x = indent;
                row += 1;
            }
            let at = (x, row * LEGEND_ROW);
            if it.swatch == Swatch::Heading {
                indent = w;
            }
            x += w;
            at
        })
        .collect()
}

/// Height a legend of these items takes in `width` px (0 for none).
pub(crate) fn legend_height(items: &[LegendItem], width: i32) -> i32 {
    legend_layout(items, width).last().map_or(0, |(_, y)| y + LEGEND_ROW + 6)
}

/// Draws the legend in a strip of its own between title and plot, so it never hides data.
pub(crate) fn legend(area: &Area<'_>, items: &[LegendItem], left: i32, top: i32, width: i32) -> Result<(), PlotError> {
    for (it, (dx, dy)) in items.iter().zip(legend_layout(items, width)) {
        let (x, y) = (left + dx, top + dy + LEGEND_ROW / 2);
        let c = it.colour;
        match it.swatch {
            Swatch::Line => path(area, &[(x, y), (x + SWATCH_W, y)], c, 2)?,
            Swatch::Dashed => {
                for d in dashes(&[(x as f64, y as f64), ((x + SWATCH_W) as f64, y as f64)], 6.0, 4.0) {
                    path(area, &round(&d), c, 1)?;
                }
            }
            Swatch::Point => circle(area, (x + SWATCH_W / 2, y), 4, c)?,
            Swatch::LineBand => {
                area.draw(&Rectangle::new([(x, y - 6), (x + SWATCH_W, y + 6)], c.mix(0.2).filled()))
                    .map_err(backend_err)?;
                path(area, &[(x, y), (x + SWATCH_W, y)], c, 2)?;
            }
            Swatch::Heading => {}
            Swatch::Bar => {
                area.draw(&Rectangle::new([(x + 4, y - 7), (x + SWATCH_W - 4, y + 7)], c.filled()))
                    .map_err(backend_err)?;
            }
        }
        let (tx, bold) = if it.swatch == Swatch::Heading { (x, true) } else { (x + SWATCH_W + 6, false) };
        text(area, &it.label, (tx, y), LEGEND_PX, (HPos::Left, VPos::Center), INK, bold)?;
    }
    Ok(())
}

/// Width of the y tick label plus axis description area for this axis.
pub(crate) fn y_label_area(y: &Axis) -> i32 {
    (y.widest_label() as f64 * 0.6 * TICK_PX).ceil() as i32 + 14 + DESC_PX as i32 + 10
}

/// What a frame shows besides the two axes.
pub(crate) struct FrameText<'a> {
    pub x_desc: &'a str,
    pub y_desc: &'a str,
    /// Width of the y label area, px: equal across stacked panels so their x axes line up.
    pub y_label_area: i32,
    /// False for the upper of two stacked panels sharing the x axis.
    pub x_labels: bool,
    /// Vertical grid lines (off for categorical axes).
    pub x_grid: bool,
}

/// Draws axes, grid and tick labels in `area` and returns the data-to-pixel map of the
/// plotting area.
pub(crate) fn frame(area: &Area<'_>, x: &Axis, y: &Axis, t: &FrameText<'_>) -> Result<Mapper, PlotError> {
    let (xk, yk) = (Ticked::from(x), Ticked::from(y));
    let mut chart = ChartBuilder::on(area)
        .margin_left(MARGIN_LEFT)
        .margin_right(MARGIN_RIGHT)
        .margin_top(8)
        .margin_bottom(4)
        .x_label_area_size(if t.x_labels { X_LABEL_AREA } else { 6 })
        .y_label_area_size(t.y_label_area)
        .build_cartesian_2d(xk, yk)
        .map_err(backend_err)?;
    let x_fmt = |v: &f64| if t.x_labels { label_at(&x.major, *v) } else { String::new() };
    let y_fmt = |v: &f64| label_at(&y.major, *v);
    let tick_font = (FONT, font_size(TICK_PX)).into_font().color(&INK);
    let desc_font = (FONT, font_size(DESC_PX)).into_font().color(&INK);
    let mut mesh = chart.configure_mesh();
    mesh.x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt)
        .label_style(tick_font)
        .axis_desc_style(desc_font)
        .bold_line_style(GRID)
        .light_line_style(GRID_MINOR)
        .axis_style(INK);
    if t.x_labels {
        mesh.x_desc(t.x_desc);
    }
    if !t.x_grid {
        mesh.disable_x_mesh();
    }
    mesh.y_desc(t.y_desc).draw().map_err(backend_err)?;
    let (left, bottom) = chart.backend_coord(&(x.lo, y.lo));
    let (right, top) = chart.backend_coord(&(x.hi, y.hi));
    // Plotters draws only the left and bottom axes; close the box so clipped data reads as
    // clipped rather than as running off the page.
    let (bx, by) = area.get_base_pixel();
    area.draw(&Rectangle::new([(left - bx, top - by), (right - bx, bottom - by)], INK.mix(0.5).stroke_width(1)))
        .map_err(backend_err)?;
    Ok(Mapper {
        x: (x.lo, x.hi),
        y: (y.lo, y.hi),
        px_x: (left as f64, right as f64),
        px_y: (bottom as f64, top as f64),
        x_log: x.log,
        y_log: y.log,
    })
}

/// A plotters coordinate with our ticks: plotters' own `WithKeyPoints` wrapper cannot be
/// formatted, and owning the map keeps mesh and data on the same pixel rounding.
struct Ticked {
    lo: f64,
    hi: f64,
    major: Vec<f64>,
    minor: Vec<f64>,
}

impl From<&Axis> for Ticked {
    fn from(a: &Axis) -> Self {
        Self { lo: a.lo, hi: a.hi, major: a.major.iter().map(|m| m.0).collect(), minor: a.minor.clone() }
    }
}

impl Ranged for Ticked {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, v: &f64, limit: (i32, i32)) -> i32 {
        let t = (v - self.lo) / (self.hi - self.lo);
        limit.0 + (t * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<H: KeyPointHint>(&self, hint: H) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.minor.clone()
        } else {
            self.major.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

impl ValueFormatter<f64> for Ticked {
    fn format(v: &f64) -> String {
        v.to_string()
    }
}

fn label_at(major: &[(f64, String)], v: f64) -> String {
    major.iter().min_by(|a, b| (a.0 - v).abs().total_cmp(&(b.0 - v).abs())).map(|m| m.1.clone()).unwrap_or_default()
}

/// Maps plotted units (log10 on log axes) of one plotting area to absolute pixels: draw the
/// data on the root area, not on the sub-area the frame was drawn in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Mapper {
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub px_x: (f64, f64),
    pub px_y: (f64, f64),
    pub x_log: bool,
    pub y_log: bool,
}

impl Mapper {
    /// Data to plotted units; `None` for what cannot be drawn.
    pub fn plotted(&self, (x, y): (f64, f64)) -> Option<(f64, f64)> {
        let f = |v: f64, log: bool| match (v.is_finite(), log) {
            (false, _) => None,
            (true, true) => (v > 0.0).then(|| v.log10()),
            (true, false) => Some(v),
        };
        Some((f(x, self.x_log)?, f(y, self.y_log)?))
    }

    pub fn px(&self, (x, y): (f64, f64)) -> (f64, f64) {
        let lerp = |v: f64, (a, b): (f64, f64), (pa, pb): (f64, f64)| pa + (v - a) / (b - a) * (pb - pa);
        (lerp(x, self.x, self.px_x), lerp(y, self.y, self.px_y))
    }

    fn clip_box(&self) -> ClipBox {
        ClipBox { x0: self.x.0, x1: self.x.1, y0: self.y.0, y1: self.y.1 }
    }

    /// Pixel x of a data x, if inside the plotting area.
    pub fn px_x_of(&self, x: f64) -> Option<f64> {
        let (p, _) = self.plotted((x, if self.y_log { 1.0 } else { 0.0 }))?;
        (p >= self.x.0 && p <= self.x.1).then(|| self.px((p, self.y.0)).0)
    }
}

#[derive(Debug, Clone, Copy)]
struct ClipBox {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

/// Liang–Barsky: the part of segment a→b inside the box.
fn clip_segment(a: (f64, f64), b: (f64, f64), c: ClipBox) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, a.0 - c.x0), (dx, c.x1 - a.0), (-dy, a.1 - c.y0), (dy, c.y1 - a.1)] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    // Unclipped ends are returned exactly, so that consecutive segments still join.
    let at = |t: f64| {
        if t <= 0.0 {
            a
        } else if t >= 1.0 {
            b
        } else {
            (a.0 + t * dx, a.1 + t * dy)
        }
    };
    (t0 <= t1).then(|| (at(t0), at(t1)))
}

/// Splits a polyline at undrawable points and clips it to the box: the visible runs.
fn clip_polyline(pts: &[Option<(f64, f64)>], c: ClipBox) -> Vec<Vec<(f64, f64)>> {
    let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut open = false;
    for w in pts.windows(2) {
        let (Some(a), Some(b)) = (w[0], w[1]) else {
            open = false;
            continue;
        };
        match clip_segment(a, b, c) {
            Some((p, q)) => {
                if !(open && p == a) {
                    runs.push(vec![p]);
                }
                runs.last_mut().expect("a run was just pushed or is open").push(q);
                open = q == b;
            }
            None => open = false,
        }
    }
    runs
}

/// Sutherland–Hodgman: the polygon clipped to the box.
fn clip_polygon(poly: &[(f64, f64)], c: ClipBox) -> Vec<(f64, f64)> {
    type Edge = (fn(&(f64, f64), &ClipBox) -> bool, fn((f64, f64), (f64, f64), &ClipBox) -> (f64, f64));
    let edges: [Edge; 4] = [
        (|p, c| p.0 >= c.x0, |a, b, c| (c.x0, a.1 + (b.1 - a.1) * (c.x0 - a.0) / (b.0 - a.0))),
        (|p, c| p.0 <= c.x1, |a, b, c| (c.x1, a.1 + (b.1 - a.1) * (c.x1 - a.0) / (b.0 - a.0))),
        (|p, c| p.1 >= c.y0, |a, b, c| (a.0 + (b.0 - a.0) * (c.y0 - a.1) / (b.1 - a.1), c.y0)),
        (|p, c| p.1 <= c.y1, |a, b, c| (a.0 + (b.0 - a.0) * (c.y1 - a.1) / (b.1 - a.1), c.y1)),
    ];
    let mut out = poly.to_vec();
    for (inside, cut) in edges {
        let input = std::mem::take(&mut out);
        for (i, &cur) in input.iter().enumerate() {
            let prev = input[(i + input.len() - 1) % input.len()];
            match (inside(&prev, &c), inside(&cur, &c)) {
                (true, true) => out.push(cur),
                (true, false) => out.push(cut(prev, cur, &c)),
                (false, true) => {
                    out.push(cut(prev, cur, &c));
                    out.push(cur);
                }
                (false, false) => {}
            }
        }
    }
    out
}

/// Cuts a pixel path into dashes of `on` px separated by `off` px.
fn dashes(path: &[(f64, f64)], on: f64, off: f64) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let (mut drawing, mut left) = (true, on);
    if let Some(&p) = path.first() {
        out.push(vec![p]);
    }
    for w in path.windows(2) {
        let (mut a, b) = (w[0], w[1]);
        let mut len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        while len > 0.0 {
            let step = left.min(len);
            let t = step / len;
            let p = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
            if drawing {
                out.last_mut().expect("a dash is open while drawing").push(p);
            }
            left -= step;
            len -= step;
            a = p;
            if left <= 1e-9 {
                drawing = !drawing;
                left = if drawing { on } else { off };
                if drawing {
                    out.push(vec![p]);
                }
            }
        }
    }
    out.retain(|d| d.len() >= 2);
    out
}

fn round(path: &[(f64, f64)]) -> Vec<(i32, i32)> {
    path.iter().map(|p| (p.0.round() as i32, p.1.round() as i32)).collect()
}

fn path(area: &Area<'_>, pts: &[(i32, i32)], c: RGBColor, width: u32) -> Result<(), PlotError> {
    area.draw(&PathElement::new(pts.to_vec(), c.stroke_width(width))).map_err(backend_err)
}

fn circle(area: &Area<'_>, at: (i32, i32), r: i32, c: RGBColor) -> Result<(), PlotError> {
    area.draw(&Circle::new(at, r, c.filled())).map_err(backend_err)
}

/// How a line is stroked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Stroke {
    pub colour: RGBColor,
    pub width: u32,
    pub dashed: bool,
}

impl Stroke {
    pub fn solid(colour: RGBColor) -> Self {
        Self { colour, width: 2, dashed: false }
    }
    pub fn reference() -> Self {
        Self { colour: palette::REFERENCE, width: 1, dashed: true }
    }
}

/// A data polyline, broken at NaN and clipped to the plotting area.
pub(crate) fn line(area: &Area<'_>, m: &Mapper, pts: &[(f64, f64)], s: Stroke) -> Result<(), PlotError> {
    let plotted: Vec<_> = pts.iter().map(|&p| m.plotted(p)).collect();
    line_plotted(area, m, &plotted, s)
}

fn line_plotted(area: &Area<'_>, m: &Mapper, plotted: &[Option<(f64, f64)>], s: Stroke) -> Result<(), PlotError> {
    for run in clip_polyline(plotted, m.clip_box()) {
        let px: Vec<_> = run.iter().map(|&p| m.px(p)).collect();
        if s.dashed {
            for d in dashes(&px, 6.0, 4.0) {
                path(area, &round(&d), s.colour, s.width)?;
            }
        } else {
            path(area, &round(&px), s.colour, s.width)?;
        }
    }
    Ok(())
}

/// A horizontal line across the plotting area at data y (skipped if outside).
pub(crate) fn hline(area: &Area<'_>, m: &Mapper, y: f64, s: Stroke) -> Result<(), PlotError> {
    let Some((_, py)) = m.plotted((if m.x_log { 1.0 } else { 0.0 }, y)) else { return Ok(()) };
    line_plotted(area, m, &[Some((m.x.0, py)), Some((m.x.1, py))], s)
}

/// A vertical line across the plotting area at data x (skipped if outside).
pub(crate) fn vline(area: &Area<'_>, m: &Mapper, x: f64, s: Stroke) -> Result<(), PlotError> {
    let Some((px, _)) = m.plotted((x, if m.y_log { 1.0 } else { 0.0 })) else { return Ok(()) };
    line_plotted(area, m, &[Some((px, m.y.0)), Some((px, m.y.1))], s)
}

/// Filled markers at the points inside the plotting area.
pub(crate) fn points(area: &Area<'_>, m: &Mapper, pts: &[(f64, f64)], colour: RGBColor) -> Result<(), PlotError> {
    let c = m.clip_box();
    for p in pts.iter().filter_map(|&p| m.plotted(p)) {
        if p.0 >= c.x0 && p.0 <= c.x1 && p.1 >= c.y0 && p.1 <= c.y1 {
            let (x, y) = m.px(p);
            circle(area, (x.round() as i32, y.round() as i32), 3, colour)?;
        }
    }
    Ok(())
}

/// A shaded band between lower and upper at each x, broken where any of the three is
/// undrawable, clipped to the plotting area.
pub(crate) fn band(area: &Area<'_>, m: &Mapper, xlu: &[(f64, f64, f64)], colour: RGBColor) -> Result<(), PlotError> {
    // (lower, upper) edge points of the band piece being collected.
    type Run = Vec<((f64, f64), (f64, f64))>;
    let mut run: Run = Vec::new();
    let flush = |run: &mut Run| -> Result<(), PlotError> {
        if run.len() >= 2 {
            let poly: Vec<_> = run.iter().map(|r| r.0).chain(run.iter().rev().map(|r| r.1)).collect();
            let clipped = clip_polygon(&poly, m.clip_box());
            if clipped.len() >= 3 {
                let px = round(&clipped.iter().map(|&p| m.px(p)).collect::<Vec<_>>());
                area.draw(&Polygon::new(px, colour.mix(0.2).filled())).map_err(backend_err)?;
            }
        }
        run.clear();
        Ok(())
    };
    for &(x, lo, hi) in xlu {
        match (m.plotted((x, lo)), m.plotted((x, hi))) {
            (Some(l), Some(h)) => run.push((l, h)),
            _ => flush(&mut run)?,
        }
    }
    flush(&mut run)
}

/// A filled bar over plotted x0..x1 from the baseline (0, or the bottom of a log axis) to
/// data `value`, clipped; returns the pixel top of the bar for its value label.
pub(crate) fn bar(
    area: &Area<'_>,
    m: &Mapper,
    x0: f64,
    x1: f64,
    value: f64,
    colour: RGBColor,
) -> Result<Option<(f64, f64)>, PlotError> {
    let Some((_, v)) = m.plotted((if m.x_log { 1.0 } else { x0 }, value)) else { return Ok(None) };
    let base = if m.y_log { m.y.0 } else { 0.0f64.clamp(m.y.0, m.y.1) };
    let top = v.clamp(m.y.0, m.y.1);
    let (a, b) = (m.px((x0, base)), m.px((x1, top)));
    area.draw(&Rectangle::new(
        [(a.0.round() as i32, a.1.round() as i32), (b.0.round() as i32, b.1.round() as i32)],
        colour.filled(),
    ))
    .map_err(backend_err)?;
    Ok(Some(((a.0 + b.0) / 2.0, b.1)))
}

#[cfg(test)]
mod tests {
    use super::*;

    const UNIT: ClipBox = ClipBox { x0: 0.0, x1: 1.0, y0: 0.0, y1: 1.0 };

    #[test]
    fn segments_clip_to_the_box() {
        assert_eq!(clip_segment((-1.0, 0.5), (2.0, 0.5), UNIT), Some(((0.0, 0.5), (1.0, 0.5))));
        assert_eq!(clip_segment((-1.0, 2.0), (-0.5, 3.0), UNIT), None);
        assert_eq!(clip_segment((0.2, 0.2), (0.4, 0.4), UNIT), Some(((0.2, 0.2), (0.4, 0.4))));
    }

    #[test]
    fn polylines_break_at_gaps_and_at_excursions() {
        let p = |x, y| Some((x, y));
        // Inside, out through the top, back in, a NaN gap, then a last segment.
        let runs =
            clip_polyline(&[p(0.1, 0.5), p(0.3, 1.5), p(0.5, 0.5), None, p(0.7, 0.5), p(0.8, 0.5), p(0.9, 0.5)], UNIT);
        assert_eq!(runs.len(), 3, "{runs:?}");
        assert_eq!(runs[0], vec![(0.1, 0.5), (0.2, 1.0)]);
        assert_eq!(runs[1], vec![(0.4, 1.0), (0.5, 0.5)]);
        assert_eq!(runs[2], vec![(0.7, 0.5), (0.8, 0.5), (0.9, 0.5)], "joined segments stay one run");
        assert!(clip_polyline(&[p(0.5, 0.5)], UNIT).is_empty());
    }

    #[test]
    fn polygons_clip_to_the_box() {
        let sq = [(-1.0, -1.0), (2.0, -1.0), (2.0, 2.0), (-1.0, 2.0)];
        let c = clip_polygon(&sq, UNIT);
        assert_eq!(c.len(), 4);
        assert!(c.iter().all(|p| (0.0..=1.0).contains(&p.0) && (0.0..=1.0).contains(&p.1)));
        assert!(clip_polygon(&[(2.0, 2.0), (3.0, 2.0), (3.0, 3.0)], UNIT).is_empty());
    }

    #[test]
    fn legend_rows_wrap_and_indent_within_a_group() {
        let item = |l: &str| LegendItem::new(l, INK, Swatch::Line);
        let items = [
            LegendItem::group("before:"),
            item("aaaaaaaaaa"),
            item("bbbbbbbbbb"),
            LegendItem::group("after:"),
            item("c"),
        ];
        let at = legend_layout(&items, 260);
        let indent = items[0].width();
        assert_eq!(at[0], (0, 0));
        assert_eq!(at[1], (indent, 0));
        assert_eq!(at[2], (indent, LEGEND_ROW), "wrapped under the first entry, not under the group name");
        assert_eq!(at[3], (0, 2 * LEGEND_ROW), "a group starts its own row");
        assert_eq!(at[4].1, 2 * LEGEND_ROW);
        assert_eq!(legend_height(&items, 260), 3 * LEGEND_ROW + 6);
        assert_eq!(legend_height(&[], 260), 0);
    }

    #[test]
    fn dashes_alternate_on_and_off() {
        let d = dashes(&[(0.0, 0.0), (25.0, 0.0)], 6.0, 4.0);
        let spans: Vec<_> = d.iter().map(|s| (s[0].0, s.last().unwrap().0)).collect();
        assert_eq!(spans, [(0.0, 6.0), (10.0, 16.0), (20.0, 25.0)]);
    }
}
