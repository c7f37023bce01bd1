//! The frame every figure shares: the [`Axis`] with explicit ticks, "nice" tick positions and
//! their labels, category labels under a categorical axis (wrapped or rotated to fit), the
//! category chart of the bar, violin and composition figures, the legend and a note in an empty
//! plot.

use plotters::coord::Shift;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::prelude::*;
use plotters::style::FontTransform;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::DrawResult;
use super::style::{AXIS_LINE, DESC, GREY, GRID, GRID_LINE, NOTE, TICK, font, stroke, udots};

/// A linear f64 axis with explicit tick positions: plotters' `with_key_points` disables label
/// formatters, and its own tick choice gives steps like 0.30000000000000004 or 2.5 clips.
#[derive(Debug, Clone)]
pub(super) struct Axis {
    lo: f64,
    hi: f64,
    bold: Vec<f64>,
    light: Vec<f64>,
}

impl Axis {
    pub(super) fn new(range: std::ops::Range<f64>, bold: Vec<f64>) -> Axis {
        Axis {
            lo: range.start,
            hi: range.end,
            bold,
            light: Vec::new(),
        }
    }

    pub(super) fn with_light(mut self, light: Vec<f64>) -> Axis {
        self.light = light;
        self
    }

    /// A categorical axis: categories at 0, 1, ..., n - 1, half a slot of room at both ends.
    pub(super) fn categories(n: usize) -> Axis {
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

/// The figure's drawing area. Figures carry no title: a paper sets its own caption, and
/// `report.md` and `tables.tex` give each figure's ([`FIGURES`](super::FIGURES)). The top margin
/// keeps the highest tick label inside the image.
pub(super) fn plot_area<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
) -> DrawingArea<DB, Shift> {
    root.margin(udots(3.0), 0, 0, 0)
}

/// Category labels under a categorical x axis: wrapped onto lines that fit the slot, or rotated
/// to read upwards when some word is wider than the slot.
pub(super) struct Categories {
    pub(super) lines: Vec<Vec<String>>,
    pub(super) rotated: bool,
    /// Font size in points: [`TICK`], or [`NOTE`] when rotated (many categories, long names).
    pub(super) size: f64,
    pub(super) line_height: u32,
    /// Drawing units the labels need below the axis.
    pub(super) height: u32,
}

pub(super) fn layout_categories<DB: DrawingBackend>(
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
pub(super) fn draw_categories<'a, DB: DrawingBackend + 'a>(
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
pub(super) fn draw_note<DB: DrawingBackend>(
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
pub(super) fn count_label(v: f64) -> String {
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
pub(super) fn tick_label(v: f64, step: f64) -> String {
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
pub(super) fn nice_ticks(lo: f64, hi: f64, target: usize) -> (Vec<f64>, f64) {
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
pub(super) fn count_ticks(top: f64) -> (Vec<f64>, f64) {
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
pub(super) const TICK_MARK: f64 = 3.0;

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
pub(super) fn category_slots<DB: DrawingBackend>(
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
pub(super) fn tick_labels(ticks: &[f64], step: f64) -> Vec<String> {
    ticks.iter().map(|v| tick_label(*v, step)).collect()
}

/// A chart on two [`Axis`]: every figure's plot.
pub(super) type AxisChart<'a, DB> = ChartContext<'a, DB, Cartesian2d<Axis, Axis>>;

/// The legend of the series drawn with labels, boxed at `position`, in the figures' note size.
pub(super) fn draw_legend<'a, DB: DrawingBackend + 'a>(
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
/// per category along x, their `labels` laid out to fit it (drawn below by `draw_categories`),
/// the value axis `y` up the left labelled by `y_label`, grid lines across at its ticks (light
/// ones where it has them). Returns the chart, the laid-out labels and the slot width.
pub(super) fn category_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    labels: &[(String, Option<String>)],
    y: Axis,
    y_label: &dyn Fn(&f64) -> String,
    (x_desc, y_desc): (&str, &str),
) -> DrawResult<(AxisChart<'a, DB>, Categories, f64)>
where
    DB::ErrorType: 'static,
{
    let n = labels.len().max(1);
    let margin = udots(4.0);
    let tick_texts: Vec<String> = y.bold.iter().map(y_label).collect();
    let (y_area, slot) = category_slots(area, &tick_texts, true, margin, n)?;
    let cats = layout_categories(area, labels, slot)?;
    let light_grid = !y.light.is_empty();
    let mut chart = ChartBuilder::on(area)
        .margin(margin)
        .x_label_area_size(cats.height + udots(DESC + 6.0))
        .y_label_area_size(y_area)
        .build_cartesian_2d(Axis::categories(n), y)?;
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
    Ok((chart, cats, slot))
}
