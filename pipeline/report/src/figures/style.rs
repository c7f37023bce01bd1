//! What the figures are set in, as printed: the font and its sizes, colours, line widths and the
//! size of a clip's dot, converted to drawing units; a source kind's colour and label.

use plotters::prelude::*;

use super::DPI;
use motionforge_sources::clip::SourceKind;

pub(super) const FONT: &str = "sans-serif";
/// The family name usvg resolves `sans-serif` to: the bundled font's.
pub(super) const FONT_FAMILY: &str = "DejaVu Sans";
pub(super) const FONT_BYTES: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");
/// Text sizes in points as printed: axis and panel titles, tick labels, notes and legends.
/// Papers set 8-9 pt in figures; `tests/report.rs` measures them on a compiled page.
pub(super) const DESC: f64 = 9.0;
pub(super) const TICK: f64 = 8.0;
pub(super) const NOTE: f64 = 8.0;
/// At most this many goal points are drawn; the histogram below them counts every goal. Keeps
/// the SVG of a large dataset small.
pub(super) const MAX_SCATTER: usize = 5000;
/// Individual values are drawn beside violins and box plots up to this many per category, and
/// only when there are at most [`MAX_STRIP_CATEGORIES`] categories: more would bury the shapes.
pub(super) const MAX_STRIP: usize = 20;
/// See [`MAX_STRIP`].
pub(super) const MAX_STRIP_CATEGORIES: usize = 12;

pub(super) const BLUE: RGBColor = RGBColor(31, 119, 180);
const ORANGE: RGBColor = RGBColor(255, 127, 14);
pub(super) const GREEN: RGBColor = RGBColor(44, 160, 44);
pub(super) const RED: RGBColor = RGBColor(214, 39, 40);
const PURPLE: RGBColor = RGBColor(148, 103, 189);
pub(super) const GREY: RGBColor = RGBColor(127, 127, 127);
pub(super) const DARK: RGBColor = RGBColor(50, 50, 50);
pub(super) const GRID: RGBColor = RGBColor(225, 225, 225);

/// Drawing units for `points` (1/72 in) of print.
pub(super) fn dots(points: f64) -> f64 {
    points * f64::from(DPI) / 72.0
}

/// [`dots`] rounded, for plotters' integer sizes.
pub(super) fn udots(points: f64) -> u32 {
    dots(points).round() as u32
}

/// The figure font at `points` as printed. plotters writes an SVG `font-size` of its size / 1.24
/// (its ab_glyph layout takes the size as 1.24 em), so the size passed is scaled up by that.
pub(super) fn font(points: f64) -> TextStyle<'static> {
    TextStyle::from((FONT, dots(points) * 1.24).into_font()).color(&BLACK)
}

/// A line `points` wide.
pub(super) fn stroke(color: RGBColor, points: f64) -> ShapeStyle {
    color.stroke_width(udots(points).max(1))
}

pub(crate) fn kind_label(kind: &str) -> String {
    kind.replace('_', " ")
}

pub(super) fn kind_color(kind: &str) -> RGBColor {
    match SourceKind::parse(kind) {
        Some(SourceKind::RealSingle) => BLUE,
        Some(SourceKind::RealPair) => ORANGE,
        Some(SourceKind::Synthetic) => GREEN,
        None => PURPLE,
    }
}

/// `c` mixed with white: `t = 0` is `c`, `t = 1` white. Figures use opaque colours only: svg2pdf
/// writes a PDF's graphics states (one per opacity) in hash-map order, so two translucent colours
/// would make two builds' PDFs differ.
pub(super) fn lighten(c: RGBColor, t: f64) -> RGBColor {
    let m = |v: u8| (f64::from(v) + (255.0 - f64::from(v)) * t).round() as u8;
    RGBColor(m(c.0), m(c.1), m(c.2))
}

/// Line widths, as printed: axes, grid lines, data outlines.
pub(super) const AXIS_LINE: f64 = 0.6;
pub(super) const GRID_LINE: f64 = 0.4;
pub(super) const DATA_LINE: f64 = 0.7;
/// Radius of a clip's dot beside a box or violin.
pub(super) const DOT: f64 = 1.3;

/// Horizontal offset of the `k`-th point of a strip, in category units: a fixed low-discrepancy
/// sequence instead of random jitter, so figures are reproducible.
pub(super) fn jitter(k: usize, width: f64) -> f64 {
    ((k as f64 * 0.618_033_988_75).fract() - 0.5) * width
}
