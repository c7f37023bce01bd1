//! The figures, drawn with plotters at their printed size into SVG, then converted to PDF
//! (svg2pdf) and PNG (resvg) from that one SVG, so the three formats show the same drawing. Text
//! is set in the bundled DejaVu Sans: plotters lays it out with ab_glyph, and usvg, resvg and
//! svg2pdf load only that font (no system font), so output is the same on every machine.
//!
//! This file holds what the report has figures of ([`FIGURES`], their printed sizes) and writes
//! them; each figure is drawn in its own file (`counts.rs`, `lengths.rs`, `goals.rs`,
//! `composition.rs`, `plausibility.rs`) from the frame and axes every figure shares (`axes.rs`)
//! and the sizes, colours and lines they are set in (`style.rs`); `encode.rs` turns the SVG
//! into PDF and PNG.

mod axes;
mod composition;
mod counts;
mod encode;
mod goals;
mod lengths;
mod plausibility;
mod style;

use std::fs;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;
use rayon::prelude::*;

use self::encode::{ensure_font, pdf_and_png, with_printed_size};
pub use self::lengths::{MIN_VIOLIN, violin_outline};
pub(crate) use self::style::kind_label;
use super::stats::Stats;
use super::{ClipRow, FigureProblem, ReportError};
use motionforge_core::base::write_atomic;

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

/// A whole figure's drawing area: each is drawn once, as SVG, and PDF and PNG are encoded from it.
type Root<'a> = DrawingArea<SVGBackend<'a>, Shift>;

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

fn render(spec: &FigureSpec, root: &Root, rows: &[ClipRow], stats: &Stats) -> DrawResult {
    root.fill(&WHITE)?;
    match spec.stem {
        "motion_type_counts" => counts::motion_type_counts(root, stats),
        "motion_lengths" => lengths::motion_lengths(root, rows, stats),
        "goal_locations" => goals::goal_locations(root, rows),
        "composition" => composition::composition(root, stats),
        _ => plausibility::plausibility(root, rows, stats),
    }
}
