//! A figure's SVG made ready to print and converted: the bundled font registered with plotters
//! and given to usvg as the only font, the SVG's printed size, and its PDF (svg2pdf) and PNG
//! (resvg) from that one SVG.

use std::sync::{Arc, OnceLock};

use plotters::style::{FontStyle, register_font};
use svg2pdf::usvg;

use super::style::{FONT, FONT_BYTES, FONT_FAMILY};
use super::{DPI, FigureProblem, FigureSpec, ReportError};

/// Registers the bundled font once per process; every later call sees the first result.
pub(super) fn ensure_font() -> Result<(), ReportError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FONT, FontStyle::Normal, FONT_BYTES).is_ok());
    if ok { Ok(()) } else { Err(ReportError::Font) }
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
pub(super) fn with_printed_size(svg: &str, spec: &FigureSpec) -> Result<String, FigureProblem> {
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
pub(super) fn pdf_and_png(
    svg: &str,
    spec: &FigureSpec,
) -> Result<(Vec<u8>, Vec<u8>), FigureProblem> {
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
