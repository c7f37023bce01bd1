//! Figure 3: locomotion goal locations (LINGO Fig. A3) in the first-frame canonical frame, points
//! over a 2D histogram on equal axes, with the histogram's colour bar.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::axes::{Axis, AxisChart, TICK_MARK, draw_legend, draw_note, plot_area, tick_label};
use super::style::{
    AXIS_LINE, DESC, GRID, GRID_LINE, MAX_SCATTER, NOTE, RED, TICK, dots, font, lighten, stroke,
    udots,
};
use super::{DrawResult, Root};
use crate::ClipRow;

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

pub(super) fn goal_locations(root: &Root, rows: &[ClipRow]) -> DrawResult {
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
