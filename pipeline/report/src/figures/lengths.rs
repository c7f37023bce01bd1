//! Figure 2: motion length per motion type (LINGO Fig. A2), Gaussian KDE violins over box plots,
//! with the clips as points when few; the box plot is shared with the plausibility figure.

use plotters::prelude::*;

use super::axes::{
    Axis, category_chart, draw_categories, draw_note, nice_ticks, plot_area, tick_label,
};
use super::style::{
    BLUE, DARK, DATA_LINE, DOT, MAX_STRIP, MAX_STRIP_CATEGORIES, dots, jitter, lighten, stroke,
    udots,
};
use super::{DrawResult, Root};
use crate::ClipRow;
use crate::stats::{
    Stats, kde, lengths_by_type, quantile, silverman_bandwidth, types_in_report_order, whiskers,
};

pub(super) fn motion_lengths(root: &Root, rows: &[ClipRow], stats: &Stats) -> DrawResult {
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
    let (ticks, step) = nice_ticks(0.0, top, 6);
    let labels: Vec<(String, Option<String>)> = data
        .iter()
        .map(|(name, v)| (name.to_string(), Some(format!("(n = {})", v.len()))))
        .collect();
    let (mut chart, cats, slot) = category_chart(
        &area,
        &labels,
        Axis::new(0.0..top, ticks),
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
pub(super) fn draw_box<DB: DrawingBackend, X, Y>(
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
