//! Figure 4: the composition of each split by source kind (SINC Fig. A.4), a bar per kind with
//! mirrored copies lighter on top, and its legend.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::axes::{
    Axis, AxisChart, category_chart, count_ticks, draw_categories, draw_legend, draw_note,
    plot_area, tick_label,
};
use super::style::{GREY, NOTE, dots, font, kind_color, kind_label, lighten, udots};
use super::{DrawResult, Root};
use crate::stats::{SplitComposition, Stats};

pub(super) fn composition(root: &Root, stats: &Stats) -> DrawResult {
    let splits = &stats.composition;
    let area = plot_area(root);
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
    let (mut chart, cats, slot) = category_chart(
        &area,
        &labels,
        Axis::new(0.0..top, ticks),
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
