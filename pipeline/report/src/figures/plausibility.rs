//! Figure 5: the plausibility metrics of real versus synthetic clips (originals), one panel of
//! box plots per metric with the build's threshold.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::axes::{
    Axis, AxisChart, TICK_MARK, category_slots, draw_categories, layout_categories, nice_ticks,
    plot_area, tick_label, tick_labels,
};
use super::lengths::draw_box;
use super::style::{
    AXIS_LINE, BLUE, DATA_LINE, DESC, DOT, GREEN, GREY, GRID, GRID_LINE, MAX_STRIP, NOTE, RED,
    TICK, font, jitter, lighten, stroke, udots,
};
use super::{DrawResult, Root};
use crate::ClipRow;
use crate::stats::{MetricInfo, Stats, metric_values};

pub(super) fn plausibility(root: &Root, rows: &[ClipRow], stats: &Stats) -> DrawResult {
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
