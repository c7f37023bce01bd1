//! The figures, drawn with plotters at their printed size into SVG, then converted to PDF
//! (svg2pdf) and PNG (resvg) from that one SVG, so the three formats show the same drawing. Text
//! is set in the bundled DejaVu Sans: plotters lays it out with ab_glyph, and usvg, resvg and
//! svg2pdf load only that font (no system font), so output is the same on every machine.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use plotters::coord::Shift;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{FontStyle, FontTransform, register_font};
use rayon::prelude::*;
use svg2pdf::usvg;

use super::stats::{
    MetricInfo, SplitComposition, Stats, kde, lengths_by_type, metric_values, quantile,
    silverman_bandwidth, types_in_report_order, whiskers,
};
use super::{ClipRow, FigureProblem, ReportError};
use motionforge_core::base::write_atomic;
use motionforge_sources::clip::SourceKind;

/// Drawing units per inch. Figures are laid out in 1/300 in, so the PNG is the drawing at
/// 300 dpi and the SVG's user units are the PNG's pixels.
pub const DPI: u32 = 300;

/// How wide a figure is printed in a two-column paper.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Span {
    /// One column, 3.4 in: `figure` at `\columnwidth`.
    Column,
    /// Both columns, 7 in: `figure*` at `\textwidth`.
    Page,
}

impl Span {
    /// The printed width in inches.
    pub fn inches(self) -> f64 {
        match self {
            Span::Column => 3.4,
            Span::Page => 7.0,
        }
    }
}

/// A figure of the report: its file stem under `figures/`, caption, label and printed size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FigureSpec {
    /// File stem: the figure is written as `figures/<stem>.svg`, `.pdf` and `.png`.
    pub stem: &'static str,
    /// What the figure shows, for `report.md` and `figures.tex`.
    pub caption: &'static str,
    /// LaTeX label in `figures.tex`.
    pub label: &'static str,
    /// The width it is drawn for.
    pub span: Span,
    /// Width in drawing units ([`DPI`] per inch): the PNG's pixels.
    pub width: u32,
    /// Height in drawing units.
    pub height: u32,
}

impl FigureSpec {
    /// Printed width and height in inches.
    pub fn inches(&self) -> (f64, f64) {
        (
            f64::from(self.width) / f64::from(DPI),
            f64::from(self.height) / f64::from(DPI),
        )
    }
}

const COLUMN: u32 = 1020;
const PAGE: u32 = 2100;

/// Every figure, in the order of the report.
pub const FIGURES: [FigureSpec; 5] = [
    FigureSpec {
        stem: "motion_type_counts",
        caption: "Clips per motion type (original single clips; LINGO Fig. 6)",
        label: "fig:mf-motion-type-counts",
        span: Span::Page,
        width: PAGE,
        height: 780,
    },
    FigureSpec {
        stem: "motion_lengths",
        caption: "Motion length per motion type: Gaussian KDE violins over box plots (LINGO Fig. A2)",
        label: "fig:mf-motion-lengths",
        span: Span::Page,
        width: PAGE,
        height: 840,
    },
    FigureSpec {
        stem: "goal_locations",
        caption: "Locomotion goal locations in the first-frame canonical frame, over a 2D histogram (LINGO Fig. A3)",
        label: "fig:mf-goal-locations",
        span: Span::Column,
        width: COLUMN,
        height: 930,
    },
    FigureSpec {
        stem: "composition",
        caption: "Composition of each split by source kind, mirrored copies lighter (SINC Fig. A.4)",
        label: "fig:mf-composition",
        span: Span::Column,
        width: COLUMN,
        height: 780,
    },
    FigureSpec {
        stem: "plausibility",
        caption: "Plausibility metrics of real versus synthetic clips (originals), box plots",
        label: "fig:mf-plausibility",
        span: Span::Page,
        width: PAGE,
        height: 720,
    },
];

type DrawResult<T = ()> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

const FONT: &str = "sans-serif";
/// The family name usvg resolves `sans-serif` to: the bundled font's.
const FONT_FAMILY: &str = "DejaVu Sans";
const FONT_BYTES: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
/// Text sizes in points as printed: axis and panel titles, tick labels, notes and legends.
/// Papers set 8-9 pt in figures; `tests/report.rs` measures them on a compiled page.
const DESC: f64 = 9.0;
const TICK: f64 = 8.0;
const NOTE: f64 = 8.0;
/// At most this many goal points are drawn; the histogram below them counts every goal. Keeps
/// the SVG of a large dataset small.
const MAX_SCATTER: usize = 5000;
/// Individual values are drawn beside violins and box plots up to this many per category, and
/// only when there are at most [`MAX_STRIP_CATEGORIES`] categories: more would bury the shapes.
const MAX_STRIP: usize = 20;
/// See [`MAX_STRIP`].
const MAX_STRIP_CATEGORIES: usize = 12;

const BLUE: RGBColor = RGBColor(31, 119, 180);
const ORANGE: RGBColor = RGBColor(255, 127, 14);
const GREEN: RGBColor = RGBColor(44, 160, 44);
const RED: RGBColor = RGBColor(214, 39, 40);
const PURPLE: RGBColor = RGBColor(148, 103, 189);
const GREY: RGBColor = RGBColor(127, 127, 127);
const DARK: RGBColor = RGBColor(50, 50, 50);
const GRID: RGBColor = RGBColor(225, 225, 225);

/// A linear f64 axis with explicit tick positions: plotters' `with_key_points` disables label
/// formatters, and its own tick choice gives steps like 0.30000000000000004 or 2.5 clips.
#[derive(Debug, Clone)]
struct Axis {
    lo: f64,
    hi: f64,
    bold: Vec<f64>,
    light: Vec<f64>,
}

impl Axis {
    fn new(range: std::ops::Range<f64>, bold: Vec<f64>) -> Axis {
        Axis {
            lo: range.start,
            hi: range.end,
            bold,
            light: Vec::new(),
        }
    }

    fn with_light(mut self, light: Vec<f64>) -> Axis {
        self.light = light;
        self
    }

    /// A categorical axis: categories at 0, 1, ..., n - 1, half a slot of room at both ends.
    fn categories(n: usize) -> Axis {
        Axis::new(-0.5..n as f64 - 0.5, (0..n).map(|i| i as f64).collect())
    }
}

impl Ranged for Axis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let span = self.hi - self.lo;
        if span == 0.0 || !span.is_finite() {
            return (limit.0 + limit.1) / 2;
        }
        let t = (value - self.lo) / span;
        limit.0 + (f64::from(limit.1 - limit.0) * t).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

/// Registers the bundled font once per process; every later call sees the first result.
fn ensure_font() -> Result<(), ReportError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FONT, FontStyle::Normal, FONT_BYTES).is_ok());
    if ok { Ok(()) } else { Err(ReportError::Font) }
}

/// Drawing units for `points` (1/72 in) of print.
fn dots(points: f64) -> f64 {
    points * f64::from(DPI) / 72.0
}

/// [`dots`] rounded, for plotters' integer sizes.
fn udots(points: f64) -> u32 {
    dots(points).round() as u32
}

/// The figure font at `points` as printed. plotters writes an SVG `font-size` of its size / 1.24
/// (its ab_glyph layout takes the size as 1.24 em), so the size passed is scaled up by that.
fn font(points: f64) -> TextStyle<'static> {
    TextStyle::from((FONT, dots(points) * 1.24).into_font()).color(&BLACK)
}

/// A line `points` wide.
fn stroke(color: RGBColor, points: f64) -> ShapeStyle {
    color.stroke_width(udots(points).max(1))
}

/// The usvg options every conversion uses: only the bundled font, as `sans-serif`.
fn svg_options() -> &'static usvg::Options<'static> {
    static OPTIONS: OnceLock<usvg::Options<'static>> = OnceLock::new();
    OPTIONS.get_or_init(|| {
        let mut db = usvg::fontdb::Database::new();
        db.load_font_data(FONT_BYTES.to_vec());
        db.set_sans_serif_family(FONT_FAMILY);
        usvg::Options {
            font_family: FONT_FAMILY.to_string(),
            fontdb: Arc::new(db),
            ..usvg::Options::default()
        }
    })
}

/// The SVG plotters wrote, given its printed size: `width`/`height` in inches (the viewBox keeps
/// the drawing units), so an SVG viewer, usvg and a paper all see the figure at its size.
fn with_printed_size(svg: &str, spec: &FigureSpec) -> Result<String, FigureProblem> {
    let (w, h) = spec.inches();
    let drawn = format!("width=\"{}\" height=\"{}\"", spec.width, spec.height);
    if !svg.contains(&drawn) {
        return Err(FigureProblem::NoSize(drawn));
    }
    Ok(svg.replacen(&drawn, &format!("width=\"{w}in\" height=\"{h}in\""), 1))
}

/// PDF and PNG of one figure's SVG. The PDF embeds the subset of DejaVu Sans its text uses (text
/// stays text, searchable), written by svg2pdf with no date or random id, so the same SVG gives
/// the same bytes. The PNG is the SVG rasterised by resvg at [`DPI`] on white.
fn pdf_and_png(svg: &str, spec: &FigureSpec) -> Result<(Vec<u8>, Vec<u8>), FigureProblem> {
    let tree = usvg::Tree::from_str(svg, svg_options()).map_err(FigureProblem::Svg)?;
    // usvg measures in CSS pixels (96 per inch): a PDF point is 1/72 in.
    let pdf = svg2pdf::to_pdf(
        &tree,
        svg2pdf::ConversionOptions::default(),
        svg2pdf::PageOptions { dpi: 96.0 },
    )
    .map_err(FigureProblem::Pdf)?;
    let (w, h) = (spec.width, spec.height);
    let mut pixmap = resvg::tiny_skia::Pixmap::new(w, h).ok_or(FigureProblem::Canvas(w, h))?;
    pixmap.fill(resvg::tiny_skia::Color::WHITE);
    let scale = f64::from(DPI) / 96.0;
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::from_scale(scale as f32, scale as f32),
        &mut pixmap.as_mut(),
    );
    // Opaque (white below everything), so dropping alpha loses nothing.
    let rgb: Vec<u8> = pixmap
        .data()
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let png = motionforge_format::dataset::preview::png_bytes(&rgb, (w, h))
        .map_err(FigureProblem::Dataset)?;
    Ok((pdf, png))
}

/// Writes every figure of [`FIGURES`] as SVG, PDF and PNG into `dir`; returns the paths.
pub(crate) fn write_figures(
    rows: &[ClipRow],
    stats: &Stats,
    dir: &Path,
) -> Result<Vec<PathBuf>, ReportError> {
    ensure_font()?;
    fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    // The figures are drawn and encoded (SVG, then PDF and PNG from it) on all cores: together
    // they are most of the report's time on a small dataset.
    let written: Vec<Vec<PathBuf>> = FIGURES
        .par_iter()
        .map(|spec| write_figure(spec, rows, stats, dir))
        .collect::<Result<_, _>>()?;
    Ok(written.into_iter().flatten().collect())
}

/// Draws one figure and writes its SVG, PDF and PNG into `dir`.
fn write_figure(
    spec: &FigureSpec,
    rows: &[ClipRow],
    stats: &Stats,
    dir: &Path,
) -> Result<Vec<PathBuf>, ReportError> {
    let fail = |problem: FigureProblem| ReportError::Figure {
        figure: spec.stem.to_string(),
        problem: Box::new(problem),
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (spec.width, spec.height)).into_drawing_area();
        render(spec, &root, rows, stats)
            .and_then(|()| root.present().map_err(Into::into))
            .map_err(|e| fail(FigureProblem::Plot(e)))?;
    }
    let svg = with_printed_size(&svg, spec).map_err(fail)?;
    let (pdf, png) = pdf_and_png(&svg, spec).map_err(fail)?;
    // Each written like every other file (temporary file, then rename), so a full disk is
    // reported with the file's path and what to do.
    let mut written = Vec::new();
    for (ext, bytes) in [("svg", svg.as_bytes()), ("pdf", &pdf), ("png", &png)] {
        let path = dir.join(format!("{}.{ext}", spec.stem));
        write_atomic(&path, bytes)?;
        written.push(path);
    }
    Ok(written)
}

fn render<DB: DrawingBackend>(
    spec: &FigureSpec,
    root: &DrawingArea<DB, Shift>,
    rows: &[ClipRow],
    stats: &Stats,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    match spec.stem {
        "motion_type_counts" => motion_type_counts(root, stats),
        "motion_lengths" => motion_lengths(root, rows, stats),
        "goal_locations" => goal_locations(root, rows),
        "composition" => composition(root, stats),
        _ => plausibility(root, rows, stats),
    }
}

/// The figure's drawing area. Figures carry no title: a paper sets its own caption, and
/// `report.md` and `tables.tex` give each figure's ([`FIGURES`]). The top margin keeps the
/// highest tick label inside the image.
fn plot_area<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>) -> DrawingArea<DB, Shift> {
    root.margin(udots(3.0), 0, 0, 0)
}

pub(crate) fn kind_label(kind: &str) -> String {
    kind.replace('_', " ")
}

fn kind_color(kind: &str) -> RGBColor {
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
fn lighten(c: RGBColor, t: f64) -> RGBColor {
    let m = |v: u8| (f64::from(v) + (255.0 - f64::from(v)) * t).round() as u8;
    RGBColor(m(c.0), m(c.1), m(c.2))
}

/// Category labels under a categorical x axis: wrapped onto lines that fit the slot, or rotated
/// to read upwards when some word is wider than the slot.
struct Categories {
    lines: Vec<Vec<String>>,
    rotated: bool,
    /// Font size in points: [`TICK`], or [`NOTE`] when rotated (many categories, long names).
    size: f64,
    line_height: u32,
    /// Drawing units the labels need below the axis.
    height: u32,
}

fn layout_categories<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    labels: &[(String, Option<String>)],
    slot: f64,
) -> DrawResult<Categories>
where
    DB::ErrorType: 'static,
{
    let style = &font(TICK);
    let (_, line_height) = area.estimate_text_size("Ag", style)?;
    let line_height = line_height + udots(1.5);
    let fits = |s: &str| -> DrawResult<bool> {
        Ok(f64::from(area.estimate_text_size(s, style)?.0) <= slot * 0.92)
    };
    let mut all = Vec::new();
    let mut rotated = false;
    'labels: for (name, sub) in labels {
        let mut lines: Vec<String> = Vec::new();
        for word in name.split_whitespace() {
            if !fits(word)? {
                rotated = true;
                break 'labels;
            }
            match lines.last_mut() {
                Some(last) if fits(&format!("{last} {word}"))? => {
                    last.push(' ');
                    last.push_str(word);
                }
                _ => lines.push(word.to_string()),
            }
        }
        if let Some(sub) = sub {
            if !fits(sub)? {
                rotated = true;
                break;
            }
            lines.push(sub.clone());
        }
        if lines.len() > 4 {
            rotated = true;
            break;
        }
        all.push(lines);
    }
    if rotated {
        let style = &font(NOTE);
        let mut lines = Vec::new();
        let mut widest = 0;
        // Names alone: a rotated "(n = ...)" would make the labels as tall as the plot (the
        // tables give the counts).
        for (name, _) in labels {
            let text = name.clone();
            widest = widest.max(area.estimate_text_size(&text, style)?.0);
            lines.push(vec![text]);
        }
        return Ok(Categories {
            lines,
            rotated: true,
            size: NOTE,
            line_height,
            height: widest + udots(5.0),
        });
    }
    let most = all.iter().map(Vec::len).max().unwrap_or(1) as u32;
    Ok(Categories {
        lines: all,
        rotated: false,
        size: TICK,
        line_height,
        height: most * line_height + udots(5.0),
    })
}

/// Draws category labels on the whole figure, below `chart`'s category points at height `base`.
fn draw_categories<'a, DB: DrawingBackend + 'a>(
    root: &DrawingArea<DB, Shift>,
    chart: &AxisChart<'a, DB>,
    base: f64,
    cats: &Categories,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let style = &font(cats.size);
    let (x0, y0) = (
        root.get_pixel_range().0.start,
        root.get_pixel_range().1.start,
    );
    for (i, lines) in cats.lines.iter().enumerate() {
        let (x, y) = chart.backend_coord(&(i as f64, base));
        let (x, y) = (x - x0, y - y0);
        if cats.rotated {
            let s = style
                .transform(FontTransform::Rotate270)
                .pos(Pos::new(HPos::Right, VPos::Center));
            if let Some(text) = lines.first() {
                root.draw_text(text, &s, (x, y + udots(4.5) as i32))?;
            }
        } else {
            let s = style.pos(Pos::new(HPos::Center, VPos::Top));
            for (k, line) in lines.iter().enumerate() {
                // Clear of the tick marks below the axis.
                let dy = udots(4.5) + k as u32 * cats.line_height;
                root.draw_text(line, &s, (x, y + dy as i32))?;
            }
        }
    }
    Ok(())
}

/// A note in an empty plot, centred across and at `height` (0 top, 1 bottom) down.
fn draw_note<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    height: f64,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let (w, h) = area.dim_in_pixel();
    let s = font(DESC)
        .color(&GREY)
        .pos(Pos::new(HPos::Center, VPos::Center));
    area.draw_text(text, &s, (w as i32 / 2, (f64::from(h) * height) as i32))?;
    Ok(())
}

/// Count as a tick label: `1`, `10`, `100`, `1000`, `10k`, `100k`, `1M`.
fn count_label(v: f64) -> String {
    let v = v.round();
    if v >= 1e6 {
        format!("{}M", (v / 1e6).round())
    } else if v >= 1e4 {
        format!("{}k", (v / 1e3).round())
    } else {
        format!("{v}")
    }
}

/// Tick label of a linear axis with step `step`: as many decimals as the step has (0.025 needs
/// three), so ticks are written exactly.
fn tick_label(v: f64, step: f64) -> String {
    let decimals = if step > 0.0 && step.is_finite() {
        (0..=6usize)
            .find(|d| {
                let scaled = step * 10f64.powi(*d as i32);
                (scaled - scaled.round()).abs() < 1e-6 * scaled.max(1.0)
            })
            .unwrap_or(6)
    } else {
        2
    };
    let s = format!("{v:.decimals$}");
    // "-0.0" reads like a value below zero.
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// Evenly spaced "nice" ticks (1, 2, 2.5, 5 x 10^k) covering `[lo, hi]`, about `target` of them.
fn nice_ticks(lo: f64, hi: f64, target: usize) -> (Vec<f64>, f64) {
    let span = (hi - lo).max(1e-9);
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    let ticks = (first..=last).map(|k| k as f64 * step).collect();
    (ticks, step)
}

/// Integer ticks from 0 covering `top`: a count axis never shows 2.5 clips.
fn count_ticks(top: f64) -> (Vec<f64>, f64) {
    let (ticks, step) = nice_ticks(0.0, top, 6);
    if step >= 1.0 {
        let ticks = ticks.into_iter().filter(|t| t.fract() == 0.0).collect();
        return (ticks, step);
    }
    (
        (0..=top.floor().max(0.0) as u64)
            .map(|t| t as f64)
            .collect(),
        1.0,
    )
}

/// Tick marks, as printed.
const TICK_MARK: f64 = 3.0;

/// Width of a y label area holding `labels` as tick labels, and an axis title beside them when
/// `titled`.
fn y_label_area<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    labels: &[String],
    titled: bool,
) -> DrawResult<u32>
where
    DB::ErrorType: 'static,
{
    let mut widest = 0;
    for l in labels {
        widest = widest.max(area.estimate_text_size(l, &font(TICK))?.0);
    }
    let title = if titled { udots(DESC + 5.0) } else { 0 };
    Ok(widest + udots(TICK_MARK + 4.0) + title)
}

/// The y label area for `labels` (as [`y_label_area`]) and the width of each of `n` category
/// slots across what is left of `area` between its margins.
fn category_slots<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    labels: &[String],
    titled: bool,
    margin: u32,
    n: usize,
) -> DrawResult<(u32, f64)>
where
    DB::ErrorType: 'static,
{
    let y_area = y_label_area(area, labels, titled)?;
    let width = area
        .dim_in_pixel()
        .0
        .saturating_sub(2 * margin + y_area)
        .max(1);
    Ok((y_area, f64::from(width) / n as f64))
}

/// The printed labels of `ticks`, `step` apart.
fn tick_labels(ticks: &[f64], step: f64) -> Vec<String> {
    ticks.iter().map(|v| tick_label(*v, step)).collect()
}

/// Line widths, as printed: axes, grid lines, data outlines.
const AXIS_LINE: f64 = 0.6;
const GRID_LINE: f64 = 0.4;
const DATA_LINE: f64 = 0.7;
/// Radius of a clip's dot beside a box or violin.
const DOT: f64 = 1.3;

/// Horizontal offset of the `k`-th point of a strip, in category units: a fixed low-discrepancy
/// sequence instead of random jitter, so figures are reproducible.
fn jitter(k: usize, width: f64) -> f64 {
    ((k as f64 * 0.618_033_988_75).fract() - 0.5) * width
}

// ---------------------------------------------------------------------------------------------
// Figure 1: occurrences per motion type (LINGO Fig. 6).

fn motion_type_counts<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    stats: &Stats,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let types = types_in_report_order(stats);
    let area = plot_area(root);
    let n = types.len().max(1);
    let max = types.iter().map(|t| t.clips).max().unwrap_or(1).max(1) as f64;
    let min = types.iter().map(|t| t.clips).min().unwrap_or(1).max(1) as f64;
    // A log axis only for counts spanning more than two decades (LINGO's thousands against a
    // handful); a few clips per type read better as plain bars from zero.
    let log = max / min > 100.0;
    let (base, top, bold, light, step) = if log {
        // Bars rise from 0.5 so a type with one clip still shows a bar; the top leaves room for
        // the count above the tallest bar.
        let (lo, hi) = (0.5f64.log10(), (max * 2.5).log10());
        let bold: Vec<f64> = (lo.floor() as i32..=hi.ceil() as i32)
            .map(f64::from)
            // No tick below one clip: the axis only starts at 0.5 to give a count of 1 a bar.
            .filter(|v| *v >= -1e-9 && *v <= hi + 1e-9)
            .collect();
        let light: Vec<f64> = (lo.floor() as i32..=hi.ceil() as i32)
            .flat_map(|k| (2..10).map(move |m| (f64::from(m) * 10f64.powi(k)).log10()))
            .filter(|v| *v > lo && *v < hi)
            .collect();
        (lo, hi, bold, light, 1.0)
    } else {
        let top = max * 1.15;
        let (ticks, step) = count_ticks(top);
        (0.0, top, ticks, Vec::new(), step)
    };
    let height = |clips: usize| {
        if log {
            (clips as f64).log10()
        } else {
            clips as f64
        }
    };
    let tick_text = |v: f64| {
        if log {
            count_label(10f64.powf(v))
        } else {
            tick_label(v, step)
        }
    };
    let margin = udots(4.0);
    let tick_texts: Vec<String> = bold.iter().map(|v| tick_text(*v)).collect();
    let (y_area, slot) = category_slots(&area, &tick_texts, true, margin, n)?;
    let labels: Vec<(String, Option<String>)> = types
        .iter()
        .map(|t| (t.motion_type.clone(), None))
        .collect();
    let cats = layout_categories(&area, &labels, slot)?;
    let mut chart = category_chart(
        &area,
        (
            Axis::categories(n),
            Axis::new(base..top, bold).with_light(light),
        ),
        (margin, cats.height, y_area),
        &|v| tick_text(*v),
        (
            "motion type",
            if log { "clips (log scale)" } else { "clips" },
        ),
    )?;
    if types.is_empty() {
        draw_note(&area, "no original single clips", 0.45)?;
        return Ok(());
    }
    chart.draw_series(types.iter().enumerate().map(|(i, t)| {
        let x = i as f64;
        Rectangle::new(
            [(x - 0.36, base), (x + 0.36, height(t.clips))],
            BLUE.filled(),
        )
    }))?;
    // Counts above the bars when the widest fits its slot; with many types they would run
    // together, and the table has them.
    let style = font(NOTE);
    let mut widest = 0;
    for t in &types {
        widest = widest.max(area.estimate_text_size(&t.clips.to_string(), &style)?.0);
    }
    if f64::from(widest) <= slot * 0.9 {
        let style = style.pos(Pos::new(HPos::Center, VPos::Bottom));
        let lift = -(udots(1.5) as i32);
        chart.draw_series(types.iter().enumerate().map(|(i, t)| {
            EmptyElement::at((i as f64, height(t.clips)))
                + Text::new(t.clips.to_string(), (0, lift), style.clone())
        }))?;
    }
    draw_categories(root, &chart, base, &cats)?;
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Figure 2: motion length violins (LINGO Fig. A2).

fn motion_lengths<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    rows: &[ClipRow],
    stats: &Stats,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let order = types_in_report_order(stats);
    let lengths = lengths_by_type(rows);
    let data: Vec<(&str, &[f64])> = order
        .iter()
        .filter_map(|t| {
            lengths
                .iter()
                .find(|(name, _)| *name == t.motion_type)
                .map(|(name, v)| (name.as_str(), v.as_slice()))
        })
        .collect();
    let area = plot_area(root);
    let violins: Vec<Option<Vec<(f64, f64)>>> = data
        .iter()
        .enumerate()
        .map(|(i, (_, values))| violin_outline(values, i as f64))
        .collect();
    let top: f64 = data
        .iter()
        .filter_map(|(_, v)| v.last().copied())
        .fold(0.0, f64::max);
    let top = if top > 0.0 { top * 1.05 } else { 1.0 };
    let n = data.len().max(1);
    let (ticks, step) = nice_ticks(0.0, top, 6);
    let margin = udots(4.0);
    let (y_area, slot) = category_slots(&area, &tick_labels(&ticks, step), true, margin, n)?;
    let labels: Vec<(String, Option<String>)> = data
        .iter()
        .map(|(name, v)| (name.to_string(), Some(format!("(n = {})", v.len()))))
        .collect();
    let cats = layout_categories(&area, &labels, slot)?;
    let mut chart = category_chart(
        &area,
        (Axis::categories(n), Axis::new(0.0..top, ticks)),
        (margin, cats.height, y_area),
        &|v| tick_label(*v, step),
        ("motion type", "length (s)"),
    )?;
    if data.is_empty() {
        draw_note(&area, "no original single clips", 0.45)?;
        return Ok(());
    }
    for outline in violins.iter().flatten() {
        chart.draw_series(std::iter::once(Polygon::new(
            outline.clone(),
            lighten(BLUE, 0.7).filled(),
        )))?;
        chart.draw_series(std::iter::once(PathElement::new(
            outline
                .iter()
                .copied()
                .chain(outline.first().copied())
                .collect::<Vec<_>>(),
            stroke(BLUE, DATA_LINE),
        )))?;
    }
    // At least a few pixels wide, however many types share the axis.
    let half = 0.06f64.max(dots(1.0) / slot).min(0.25);
    for (i, (_, values)) in data.iter().enumerate() {
        // Without a violin the points are the distribution: always drawn.
        let no_violin = violins[i].is_none();
        let points = no_violin || (values.len() <= MAX_STRIP && data.len() <= MAX_STRIP_CATEGORIES);
        draw_box(&mut chart, values, i as f64, half, DARK, !points)?;
        if points {
            chart.draw_series(values.iter().enumerate().map(|(k, v)| {
                Circle::new(
                    (i as f64 + 0.18 + jitter(k, 0.1), *v),
                    udots(DOT),
                    lighten(BLACK, 0.45).filled(),
                )
            }))?;
        }
    }
    draw_categories(root, &chart, 0.0, &cats)?;
    Ok(())
}

/// Fewer values than this get their points and a box plot, not a violin: a density of three
/// clips is mostly the kernel's shape.
pub const MIN_VIOLIN: usize = 5;

/// The outline of a violin of ascending `values` at category `x`: a Gaussian KDE (Silverman's
/// bandwidth) on the values' own range, so no density is drawn beyond the shortest and longest
/// clip, scaled to a half-width of 0.4 at its peak so narrow and wide types stay comparable in
/// shape. `None` for fewer than [`MIN_VIOLIN`] values or no spread.
pub fn violin_outline(values: &[f64], x: f64) -> Option<Vec<(f64, f64)>> {
    if values.len() < MIN_VIOLIN {
        return None;
    }
    let h = silverman_bandwidth(values)?;
    let (a, b) = (*values.first()?, *values.last()?);
    let grid: Vec<f64> = (0..=160)
        .map(|k| a + (b - a) * f64::from(k) / 160.0)
        .collect();
    let density = kde(values, h, &grid);
    let peak = density.iter().copied().fold(0.0, f64::max);
    if peak <= 0.0 || !peak.is_finite() {
        return None;
    }
    let mut outline: Vec<(f64, f64)> = grid
        .iter()
        .zip(&density)
        .map(|(y, d)| (x + 0.4 * d / peak, *y))
        .collect();
    outline.extend(
        grid.iter()
            .zip(&density)
            .rev()
            .map(|(y, d)| (x - 0.4 * d / peak, *y)),
    );
    Some(outline)
}

/// Draws a box plot of ascending `sorted` at `x` with box half-width `half`: a filled quartile
/// box, a white median bar, Tukey whiskers and, when `outliers`, the values beyond them (left
/// out when every value is drawn as a point beside the box anyway, so none is drawn twice). One
/// value draws as a single bar.
fn draw_box<DB: DrawingBackend, X, Y>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<X, Y>>,
    sorted: &[f64],
    x: f64,
    half: f64,
    color: RGBColor,
    outliers: bool,
) -> DrawResult
where
    DB::ErrorType: 'static,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    if sorted.is_empty() {
        return Ok(());
    }
    let (q1, med, q3) = (
        quantile(sorted, 0.25),
        quantile(sorted, 0.5),
        quantile(sorted, 0.75),
    );
    let (lo, hi) = whiskers(sorted, q1, q3);
    chart.draw_series([
        PathElement::new(vec![(x, lo), (x, q1)], stroke(color, DATA_LINE)),
        PathElement::new(vec![(x, q3), (x, hi)], stroke(color, DATA_LINE)),
        PathElement::new(
            vec![(x - half * 0.6, lo), (x + half * 0.6, lo)],
            stroke(color, DATA_LINE),
        ),
        PathElement::new(
            vec![(x - half * 0.6, hi), (x + half * 0.6, hi)],
            stroke(color, DATA_LINE),
        ),
    ])?;
    chart.draw_series(std::iter::once(Rectangle::new(
        [(x - half, q1), (x + half, q3)],
        color.filled(),
    )))?;
    // A box of no height (one value, or identical quartiles) would hide a white median.
    let (median_color, reach) = if q3 > q1 {
        (WHITE, half)
    } else {
        (color, half * 1.4)
    };
    chart.draw_series(std::iter::once(PathElement::new(
        vec![(x - reach, med), (x + reach, med)],
        stroke(median_color, 1.0),
    )))?;
    if outliers {
        chart.draw_series(
            sorted
                .iter()
                .filter(|v| **v < lo || **v > hi)
                .map(|v| Circle::new((x, *v), udots(DOT), stroke(color, 0.4))),
        )?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Figure 3: locomotion goal locations (LINGO Fig. A3).

/// A "nice" step (1, 2, 2.5 or 5 x 10^k) at least `raw`.
fn nice_step(raw: f64) -> f64 {
    let raw = if raw > 0.0 && raw.is_finite() {
        raw
    } else {
        1.0
    };
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * mag)
}

/// ColorBrewer's YlGnBu, light to dark: low counts stay close to the white background.
fn heat_color(t: f64) -> RGBColor {
    const STOPS: [(u8, u8, u8); 9] = [
        (255, 255, 217),
        (237, 248, 177),
        (199, 233, 180),
        (127, 205, 187),
        (65, 182, 196),
        (29, 145, 192),
        (34, 94, 168),
        (37, 52, 148),
        (8, 29, 88),
    ];
    let t = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f64;
    let i = (t.floor() as usize).min(STOPS.len() - 2);
    let f = t - i as f64;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    let m = |x: u8, y: u8| (f64::from(x) + (f64::from(y) - f64::from(x)) * f).round() as u8;
    RGBColor(m(a.0, b.0), m(a.1, b.1), m(a.2, b.2))
}

/// A chart on two [`Axis`]: every figure's plot.
type AxisChart<'a, DB> = ChartContext<'a, DB, Cartesian2d<Axis, Axis>>;

/// The legend of the series drawn with labels, boxed at `position`, in the figures' note size.
fn draw_legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut AxisChart<'a, DB>,
    position: SeriesLabelPosition,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .position(position)
        .margin(udots(3.0))
        .legend_area_size(udots(NOTE + 2.0))
        .background_style(WHITE.filled())
        .border_style(stroke(GREY, GRID_LINE))
        .label_font(font(NOTE))
        .draw()?;
    Ok(())
}

/// The frame the category charts share (clips per motion type, lengths, composition): one slot
/// per category along x (`n` of them, labelled below by `draw_categories`, `label_height` tall),
/// the value axis `y` up the left, grid lines across at its ticks (light ones where it has
/// them). `sizes` is the margin, the category labels' height and the value labels' width.
fn category_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    (x, y): (Axis, Axis),
    (margin, label_height, y_area): (u32, u32, u32),
    y_label: &dyn Fn(&f64) -> String,
    (x_desc, y_desc): (&str, &str),
) -> DrawResult<AxisChart<'a, DB>>
where
    DB::ErrorType: 'static,
{
    let light_grid = !y.light.is_empty();
    let mut chart = ChartBuilder::on(area)
        .margin(margin)
        .x_label_area_size(label_height + udots(DESC + 6.0))
        .y_label_area_size(y_area)
        .build_cartesian_2d(x, y)?;
    let mut mesh = chart.configure_mesh();
    mesh.disable_x_mesh()
        .set_all_tick_mark_size(udots(TICK_MARK))
        .axis_style(stroke(BLACK, AXIS_LINE))
        .bold_line_style(stroke(GRID, GRID_LINE));
    if light_grid {
        mesh.light_line_style(stroke(RGBColor(242, 242, 242), GRID_LINE));
    }
    mesh.x_label_formatter(&|_| String::new())
        .y_label_formatter(y_label)
        .label_style(font(TICK))
        .axis_desc_style(font(DESC))
        .x_desc(x_desc)
        .y_desc(y_desc)
        .draw()?;
    Ok(chart)
}

fn goal_locations<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, rows: &[ClipRow]) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let goals: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.is_original())
        .filter_map(|r| r.goal_pelvis)
        .map(|g| (f64::from(g[0]), f64::from(g[1])))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let area = plot_area(root);
    let (aw, _) = area.dim_in_pixel();
    let bar_width = udots(50.0);
    let (main, bar) = area.split_horizontally(aw.saturating_sub(bar_width));
    let (margin, x_area, y_area) = (udots(4.0), udots(TICK + DESC + 12.0), udots(38.0));
    let (mw, mh) = main.dim_in_pixel();
    let pw = f64::from(mw.saturating_sub(2 * margin + y_area).max(1));
    let ph = f64::from(mh.saturating_sub(2 * margin + x_area).max(1));
    let view = GoalView::of(&goals, pw, ph);
    let (x0, x1, y0, y1) = (view.x.0, view.x.1, view.y.0, view.y.1);
    let step = nice_step((x1 - x0).max(y1 - y0) / (pw.max(ph) / dots(34.0)));
    let ticks = |lo: f64, hi: f64| -> Vec<f64> {
        ((lo / step).ceil() as i64..=(hi / step).floor() as i64)
            .map(|k| k as f64 * step)
            .collect()
    };
    let mut chart = ChartBuilder::on(&main)
        .margin(margin)
        .x_label_area_size(x_area)
        .y_label_area_size(y_area)
        .build_cartesian_2d(
            Axis::new(x0..x1, ticks(x0, x1)),
            Axis::new(y0..y1, ticks(y0, y1)),
        )?;

    // Histogram bins: square, about 30 across the larger data extent, aligned to the origin.
    let bin = nice_step(view.span / 30.0);
    let max_count = draw_goal_bins(&mut chart, &goals, bin)?;
    chart
        .configure_mesh()
        .set_all_tick_mark_size(udots(TICK_MARK))
        .axis_style(stroke(BLACK, AXIS_LINE))
        .bold_line_style(stroke(GRID, GRID_LINE))
        .x_label_formatter(&|v| tick_label(*v, step))
        .y_label_formatter(&|v| tick_label(*v, step))
        .label_style(font(TICK))
        .axis_desc_style(font(DESC))
        .x_desc("lateral (m, + right)")
        .y_desc("forward (m)")
        .draw()?;
    draw_goal_points(&mut chart, &goals, y1 - y0)?;
    if goals.is_empty() {
        draw_note(
            &chart.plotting_area().strip_coord_spec(),
            "no clips with a goal_pelvis",
            0.3,
        )?;
    }
    draw_heat_bar(&bar, margin, x_area, max_count, bin)
}

/// The goal plot's extent in metres: x and y ranges of equal scale that fit the plot's pixels.
struct GoalView {
    x: (f64, f64),
    y: (f64, f64),
    /// The larger side of the data's extent (with the start and the minimum), before padding.
    span: f64,
}

impl GoalView {
    /// The extent always holds the start (0, 0); equal axes: one metre is as long on x as on y,
    /// so the range of the shorter side grows to the plot's pixel aspect (`pw` by `ph`).
    fn of(goals: &[(f64, f64)], pw: f64, ph: f64) -> GoalView {
        let fold = |f: fn(f64, f64) -> f64, init: f64, pick: fn(&(f64, f64)) -> f64| {
            goals.iter().map(pick).fold(init, f)
        };
        let (mut x0, mut x1) = (fold(f64::min, 0.0, |g| g.0), fold(f64::max, 0.0, |g| g.0));
        let (mut y0, mut y1) = (fold(f64::min, 0.0, |g| g.1), fold(f64::max, 0.0, |g| g.1));
        // At least 2 m each way, so a few nearby goals (or none) do not zoom in to centimetres.
        for (lo, hi) in [(&mut x0, &mut x1), (&mut y0, &mut y1)] {
            let grow = (2.0 - (*hi - *lo)).max(0.0) / 2.0;
            *lo -= grow;
            *hi += grow;
        }
        let span = (x1 - x0).max(y1 - y0);
        let pad = 0.08 * span;
        x0 -= pad;
        x1 += pad;
        y0 -= pad;
        y1 += pad;
        let scale = ((x1 - x0) / pw).max((y1 - y0) / ph);
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        let (hx, hy) = (scale * pw / 2.0, scale * ph / 2.0);
        GoalView {
            x: (cx - hx, cx + hx),
            y: (cy - hy, cy + hy),
            span,
        }
    }
}

/// Draws the goals' 2D histogram in `bin`-metre squares; returns the largest count (at least 1).
fn draw_goal_bins<'a, DB: DrawingBackend + 'a>(
    chart: &mut AxisChart<'a, DB>,
    goals: &[(f64, f64)],
    bin: f64,
) -> DrawResult<usize>
where
    DB::ErrorType: 'static,
{
    let mut bins: std::collections::BTreeMap<(i64, i64), usize> = Default::default();
    for (x, y) in goals {
        *bins
            .entry(((x / bin).floor() as i64, (y / bin).floor() as i64))
            .or_insert(0) += 1;
    }
    let max_count = bins.values().copied().max().unwrap_or(1).max(1);
    chart.draw_series(bins.iter().map(|(&(i, j), &c)| {
        let (bx, by) = (i as f64 * bin, j as f64 * bin);
        Rectangle::new(
            [(bx, by), (bx + bin, by + bin)],
            heat_color(c as f64 / max_count as f64).filled(),
        )
    }))?;
    Ok(max_count)
}

/// Draws the goals as points over the bins, the start as a triangle (sized to the plot's
/// `height` in metres) and the legend.
fn draw_goal_points<'a, DB: DrawingBackend + 'a>(
    chart: &mut AxisChart<'a, DB>,
    goals: &[(f64, f64)],
    height: f64,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    // Points over the bins; a very large set is thinned by a fixed stride (the bins count all).
    let stride = goals.len().div_ceil(MAX_SCATTER).max(1);
    let shown: Vec<(f64, f64)> = goals.iter().copied().step_by(stride).collect();
    // Many points shrink and lose their outline so the histogram below stays visible.
    let radius = udots(match shown.len() {
        0..=100 => 1.6,
        101..=1000 => 1.0,
        _ => 0.6,
    });
    let label = if stride > 1 {
        format!("goal of a clip (every {stride}th of {})", goals.len())
    } else {
        format!("goal of a clip (n = {})", goals.len())
    };
    let swatch = udots(NOTE) as i32;
    let goals_drawn = chart.draw_series(
        shown
            .iter()
            .map(|p| Circle::new(*p, radius, lighten(RED, 0.15).filled())),
    )?;
    // No legend entry for goals that are not there.
    if !shown.is_empty() {
        goals_drawn
            .label(label)
            .legend(move |(x, y)| Circle::new((x + swatch / 2, y), udots(1.6), RED.filled()));
    }
    if shown.len() <= 100 {
        chart.draw_series(
            shown
                .iter()
                .map(|p| Circle::new(*p, radius, stroke(BLACK, 0.3))),
        )?;
    }
    let s = 0.02 * height;
    chart
        .draw_series(std::iter::once(Polygon::new(
            vec![(0.0, 2.0 * s), (-s, -s), (s, -s)],
            BLACK.filled(),
        )))?
        .label("start, facing +y")
        .legend(move |(x, y)| {
            let (h, w) = (swatch / 2, swatch / 3);
            Polygon::new(
                vec![(x + h, y - h), (x + h - w, y + w), (x + h + w, y + w)],
                BLACK.filled(),
            )
        });
    draw_legend(chart, SeriesLabelPosition::UpperLeft)?;
    Ok(())
}

/// The histogram's colour bar, aligned with the plot's vertical extent (the plot's `margin` and
/// x label area `x_area`).
fn draw_heat_bar<DB: DrawingBackend>(
    bar: &DrawingArea<DB, Shift>,
    margin: u32,
    x_area: u32,
    max_count: usize,
    bin: f64,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let mut cbar = ChartBuilder::on(bar)
        .margin_top(margin)
        .margin_bottom(margin + x_area)
        .margin_left(udots(3.0))
        .margin_right(udots(2.0))
        .set_label_area_size(LabelAreaPosition::Right, udots(34.0))
        .build_cartesian_2d(0.0..1.0, 0.0..max_count as f64)?;
    let cstep = nice_step(max_count as f64 / 6.0).max(1.0);
    cbar.draw_series((0..100).map(|k| {
        let (a, b) = (f64::from(k) / 100.0, f64::from(k + 1) / 100.0);
        Rectangle::new(
            [(0.0, a * max_count as f64), (1.0, b * max_count as f64)],
            heat_color((a + b) / 2.0).filled(),
        )
    }))?;
    cbar.configure_mesh()
        .disable_mesh()
        .set_all_tick_mark_size(udots(TICK_MARK))
        .axis_style(stroke(BLACK, AXIS_LINE))
        .y_labels((max_count as f64 / cstep) as usize + 1)
        .y_label_formatter(&|v| {
            if (v / cstep).fract().abs() < 1e-9 {
                format!("{v:.0}")
            } else {
                String::new()
            }
        })
        .label_style(font(TICK))
        .axis_desc_style(font(DESC))
        .y_desc(format!("clips per {} m bin", tick_label(bin, bin)))
        .draw()?;
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Figure 4: composition by source kind per split (SINC Fig. A.4).

fn composition<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, stats: &Stats) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let splits = &stats.composition;
    let area = plot_area(root);
    let n = splits.len().max(1);
    let kinds = kinds_with_rows(splits);
    let any_mirrored = splits
        .iter()
        .any(|s| s.kinds.iter().any(|k| k.mirrored > 0));
    let max = splits
        .iter()
        .flat_map(|s| s.kinds.iter().map(|c| c.total))
        .max()
        .unwrap_or(0)
        .max(1) as f64;
    let margin = udots(4.0);
    let labels: Vec<(String, Option<String>)> = splits
        .iter()
        .map(|s| (s.split.clone(), Some(format!("(n = {})", s.total))))
        .collect();
    // Room above the bars for the counts and the legend (upper right): the top grows so the
    // legend's rows fit above the tallest bar.
    let entries = kinds.len() + usize::from(any_mirrored);
    let legend = dots(NOTE + 3.5) * entries as f64 + dots(8.0);
    let plot_height = f64::from(area.dim_in_pixel().1) * 0.62;
    let headroom = ((legend + dots(NOTE + 3.0)) / plot_height).clamp(0.15, 0.7);
    let top = max / (1.0 - headroom);
    let (ticks, step) = count_ticks(top);
    let (y_area, slot) = category_slots(&area, &tick_labels(&ticks, step), true, margin, n)?;
    let cats = layout_categories(&area, &labels, slot)?;
    let mut chart = category_chart(
        &area,
        (Axis::categories(n), Axis::new(0.0..top, ticks)),
        (margin, cats.height, y_area),
        &|v| tick_label(*v, step),
        ("split", "clips"),
    )?;
    if kinds.is_empty() {
        draw_note(&area, "no clips", 0.45)?;
    } else {
        draw_kind_bars(&mut chart, &area, splits, &kinds, slot)?;
        draw_kind_legend(&mut chart, &kinds, any_mirrored)?;
    }
    draw_categories(root, &chart, 0.0, &cats)?;
    Ok(())
}

/// The kinds with rows in some split, in the table's order: a kind with no data gets neither
/// bars nor a legend entry (the table still lists it, with its zeros).
fn kinds_with_rows(splits: &[SplitComposition]) -> Vec<&str> {
    splits
        .first()
        .map(|s| {
            s.kinds
                .iter()
                .map(|k| k.source_kind.as_str())
                .filter(|kind| {
                    splits.iter().any(|s| {
                        s.kinds
                            .iter()
                            .any(|k| k.source_kind == *kind && k.total > 0)
                    })
                })
                .collect()
        })
        .unwrap_or_default()
}

/// One bar per split and shown kind, originals dark and mirrored copies lighter on top, with
/// its count above when the counts fit the bars (`slot`: a split's width in drawing units).
fn draw_kind_bars<'a, DB: DrawingBackend + 'a>(
    chart: &mut AxisChart<'a, DB>,
    area: &DrawingArea<DB, Shift>,
    splits: &[SplitComposition],
    kinds: &[&str],
    slot: f64,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let width = 0.8 / kinds.len().max(1) as f64;
    let bar_x = |s: usize, j: usize| s as f64 - 0.4 + (j as f64 + 0.5) * width;
    // Counts above the bars when the widest fits a bar's slot (the table has them all).
    let style = font(NOTE).pos(Pos::new(HPos::Center, VPos::Bottom));
    let mut widest = 0;
    for c in splits.iter().flat_map(|s| &s.kinds) {
        widest = widest.max(area.estimate_text_size(&c.total.to_string(), &style)?.0);
    }
    let counts_fit = f64::from(widest) <= slot * width * 1.05;
    let lift = -(udots(1.5) as i32);
    for (s, split) in splits.iter().enumerate() {
        let shown = split
            .kinds
            .iter()
            .filter(|c| kinds.contains(&c.source_kind.as_str()));
        for (j, c) in shown.enumerate() {
            let (x, half) = (bar_x(s, j), width * 0.42);
            let color = kind_color(&c.source_kind);
            chart.draw_series([
                Rectangle::new(
                    [(x - half, 0.0), (x + half, c.originals as f64)],
                    color.filled(),
                ),
                Rectangle::new(
                    [(x - half, c.originals as f64), (x + half, c.total as f64)],
                    lighten(color, 0.55).filled(),
                ),
            ])?;
            if counts_fit {
                chart.draw_series([EmptyElement::at((x, c.total as f64))
                    + Text::new(c.total.to_string(), (0, lift), style.clone())])?;
            }
        }
    }
    Ok(())
}

/// The legend: a swatch per shown kind, and one for the mirrored copies when there are some.
fn draw_kind_legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut AxisChart<'a, DB>,
    kinds: &[&str],
    any_mirrored: bool,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let swatch = udots(NOTE) as i32;
    for kind in kinds {
        let color = kind_color(kind);
        chart
            .draw_series(std::iter::empty::<Rectangle<(f64, f64)>>())?
            .label(kind_label(kind))
            .legend(move |(x, y)| {
                Rectangle::new(
                    [(x, y - swatch / 2), (x + swatch, y + swatch / 2)],
                    color.filled(),
                )
            });
    }
    if any_mirrored {
        chart
            .draw_series(std::iter::empty::<Rectangle<(f64, f64)>>())?
            .label("mirrored copies (lighter)")
            .legend(move |(x, y)| {
                Rectangle::new(
                    [(x, y - swatch / 2), (x + swatch, y + swatch / 2)],
                    lighten(GREY, 0.55).filled(),
                )
            });
    }
    draw_legend(chart, SeriesLabelPosition::UpperRight)?;
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Figure 5: plausibility, real versus synthetic.

fn plausibility<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    rows: &[ClipRow],
    stats: &Stats,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let area = plot_area(root);
    // One row of panels: a figure* across both columns, each panel a metric.
    let panels = area.split_evenly((1, 4));
    for (k, (panel, metric)) in panels.iter().zip(&stats.plausibility).enumerate() {
        plausibility_panel(root, panel, rows, k, &metric.info)?;
    }
    Ok(())
}

/// One metric's panel (metric `k` of the rows): real and synthetic box plots, with the values
/// as points when few, and the build's threshold.
fn plausibility_panel<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    panel: &DrawingArea<DB, Shift>,
    rows: &[ClipRow],
    k: usize,
    info: &MetricInfo,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let groups = [
        ("real", metric_values(rows, k, false).0, BLUE),
        ("synthetic", metric_values(rows, k, true).0, GREEN),
    ];
    let max = groups
        .iter()
        .flat_map(|g| g.1.last().copied())
        .fold(0.0, f64::max);
    // The build's default threshold, drawn so the distance to it shows; the axis reaches it.
    let threshold = info
        .threshold
        .split_whitespace()
        .last()
        .and_then(|t| t.parse::<f64>().ok())
        .filter(|t| t.is_finite());
    let reach = max.max(threshold.unwrap_or(0.0));
    // An all-zero metric (no penetration anywhere) still gets a readable axis.
    let top = if reach > 0.0 { reach * 1.15 } else { 0.01 };
    let (ticks, step) = nice_ticks(0.0, top, 5);
    let margin = udots(3.0);
    let (y_area, slot) = category_slots(panel, &tick_labels(&ticks, step), false, margin, 2)?;
    let labels: Vec<(String, Option<String>)> = groups
        .iter()
        .map(|(name, v, _)| (name.to_string(), Some(format!("(n = {})", v.len()))))
        .collect();
    let cats = layout_categories(panel, &labels, slot)?;
    // The panel's title says what and in which unit, in words (as the table's rows).
    let mut chart = ChartBuilder::on(panel)
        .caption(format!("{} ({})", info.name, info.unit), font(DESC))
        .margin(margin)
        .x_label_area_size(cats.height)
        .y_label_area_size(y_area)
        .build_cartesian_2d(Axis::categories(2), Axis::new(0.0..top, ticks))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .set_all_tick_mark_size(udots(TICK_MARK))
        .axis_style(stroke(BLACK, AXIS_LINE))
        .bold_line_style(stroke(GRID, GRID_LINE))
        .x_label_formatter(&|_| String::new())
        .y_label_formatter(&|v| tick_label(*v, step))
        .label_style(font(TICK))
        .draw()?;
    if let Some(t) = threshold {
        draw_threshold(&mut chart, info, t)?;
    }
    if max == 0.0 && groups.iter().any(|g| !g.1.is_empty()) {
        // A flat panel is a result, not a drawing error: say what it means.
        chart.draw_series(std::iter::once(Text::new(
            format!("every clip: 0 {}", info.unit),
            (0.5, top * 0.5),
            font(NOTE)
                .color(&GREY)
                .pos(Pos::new(HPos::Center, VPos::Center)),
        )))?;
    }
    for (g, (_, values, color)) in groups.iter().enumerate() {
        draw_metric_group(&mut chart, values, g as f64, *color, top)?;
    }
    draw_categories(root, &chart, 0.0, &cats)
}

/// The build's default threshold `t` of a metric, dashed across the panel and labelled.
fn draw_threshold<'a, DB: DrawingBackend + 'a>(
    chart: &mut AxisChart<'a, DB>,
    info: &MetricInfo,
    t: f64,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    chart.draw_series(DashedLineSeries::new(
        [(-0.5, t), (1.5, t)],
        udots(3.0),
        udots(2.0),
        stroke(RED, DATA_LINE),
    ))?;
    // `<=` set as in the tables: `≤`.
    let bound = info.threshold.replace("<=", "≤").replace(">=", "≥");
    chart.draw_series(std::iter::once(
        EmptyElement::at((1.45, t))
            + Text::new(
                format!("threshold {bound}"),
                (0, -(udots(1.0) as i32)),
                font(NOTE)
                    .color(&RED)
                    .pos(Pos::new(HPos::Right, VPos::Bottom)),
            ),
    ))?;
    Ok(())
}

/// One group's ascending `values` at `x`: a box plot, the values beside it when few, or a note
/// when there are none (halfway up to `top`).
fn draw_metric_group<'a, DB: DrawingBackend + 'a>(
    chart: &mut AxisChart<'a, DB>,
    values: &[f64],
    x: f64,
    color: RGBColor,
    top: f64,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    if values.is_empty() {
        chart.draw_series(std::iter::once(Text::new(
            "no values",
            (x, top / 2.0),
            font(NOTE)
                .color(&GREY)
                .pos(Pos::new(HPos::Center, VPos::Center)),
        )))?;
        return Ok(());
    }
    let points = values.len() <= MAX_STRIP;
    draw_box(chart, values, x, 0.12, color, !points)?;
    if points {
        chart.draw_series(values.iter().enumerate().map(|(i, v)| {
            Circle::new(
                (x + 0.3 + jitter(i, 0.16), *v),
                udots(DOT),
                lighten(color, 0.3).filled(),
            )
        }))?;
    }
    Ok(())
}
