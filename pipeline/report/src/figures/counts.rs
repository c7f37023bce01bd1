//! Figure 1: occurrences per motion type (LINGO Fig. 6), bars on a linear or, for counts spanning
//! more than two decades, a log axis.

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::axes::{
    Axis, category_chart, count_label, count_ticks, draw_categories, draw_note, plot_area,
    tick_label,
};
use super::style::{BLUE, NOTE, font, udots};
use super::{DrawResult, Root};
use crate::stats::{Stats, types_in_report_order};

pub(super) fn motion_type_counts(root: &Root, stats: &Stats) -> DrawResult {
    let types = types_in_report_order(stats);
    let area = plot_area(root);
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
    let labels: Vec<(String, Option<String>)> = types
        .iter()
        .map(|t| (t.motion_type.clone(), None))
        .collect();
    let (mut chart, cats, slot) = category_chart(
        &area,
        &labels,
        Axis::new(base..top, bold).with_light(light),
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
