//! Okabe–Ito colours: distinguishable with the common colour-vision deficiencies and in grey
//! print. Yellow is left out: it vanishes on white paper.

use plotters::style::RGBColor;

/// Series colours, indexed by `Series::colour` (modulo the length).
pub const SERIES: [RGBColor; 7] = [
    RGBColor(0x00, 0x72, 0xB2), // blue
    RGBColor(0xD5, 0x5E, 0x00), // vermillion
    RGBColor(0x00, 0x9E, 0x73), // bluish green
    RGBColor(0xE6, 0x9F, 0x00), // orange
    RGBColor(0xCC, 0x79, 0xA7), // reddish purple
    RGBColor(0x56, 0xB4, 0xE9), // sky blue
    RGBColor(0x00, 0x00, 0x00), // black
];

/// Colour index for "before calibration" data throughout the report.
pub const BEFORE: usize = 1;
/// Colour index for "after calibration" data throughout the report.
pub const AFTER: usize = 0;

/// Reference lines (zero, noise floor, markers): present but quieter than data.
pub const REFERENCE: RGBColor = RGBColor(0x55, 0x55, 0x55);
/// Grid lines.
pub const GRID: RGBColor = RGBColor(0xDD, 0xDD, 0xDD);
/// Minor grid lines (log axes).
pub const GRID_MINOR: RGBColor = RGBColor(0xEE, 0xEE, 0xEE);
/// Axis lines, tick labels, titles.
pub const INK: RGBColor = RGBColor(0x22, 0x22, 0x22);

/// The colour for a series index.
pub fn series(index: usize) -> RGBColor {
    SERIES[index % SERIES.len()]
}

/// `#RRGGBB`, as the SVG backend writes it: lets tests find a series' elements.
pub fn hex(c: RGBColor) -> String {
    format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2)
}
