//! `tables.tex` (booktabs tables ready to `\input`), `figures.tex` (the figures' floats) and
//! `report.md` (the same tables in Markdown, with every figure embedded).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::figures::{FIGURES, Span, kind_label};
use super::stats::{MetricInfo, MetricStats, Stats, Summary, TypeStats, types_in_report_order};

/// Escapes LaTeX's special characters (`\ & % $ # _ { } ~ ^`) so any name typesets as written.
pub fn latex_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\textbackslash{}"),
            '&' | '%' | '$' | '#' | '_' | '{' | '}' => {
                out.push('\\');
                out.push(c);
            }
            '~' => out.push_str("\\textasciitilde{}"),
            '^' => out.push_str("\\textasciicircum{}"),
            _ => out.push(c),
        }
    }
    out
}

/// Escapes characters that would break a Markdown table cell or start emphasis or code.
pub fn markdown_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '\\' | '|' | '*' | '_' | '`' | '<' | '>' | '[' | ']' => {
                out.push('\\');
                out.push(c);
            }
            '\n' | '\r' => out.push(' '),
            _ => out.push(c),
        }
    }
    out
}

/// Seconds with two decimals.
fn secs(v: f64) -> String {
    format!("{v:.2}")
}

/// A metric value with the decimals its unit needs (millimetres for metres, tenths of degrees).
fn metric(info: &MetricInfo, v: f64) -> String {
    if info.column == "lean" {
        format!("{v:.1}")
    } else {
        format!("{v:.3}")
    }
}

fn pct(share: f64) -> String {
    format!("{:.1}", share * 100.0)
}

/// The five length columns of a type row; dashes without clips.
fn length_cells(s: &Option<Summary>) -> [String; 5] {
    match s {
        Some(s) => [
            secs(s.min),
            secs(s.q1),
            secs(s.median),
            secs(s.q3),
            secs(s.max),
        ],
        None => std::array::from_fn(|_| "--".to_string()),
    }
}

fn summary_cells(info: &MetricInfo, s: &Option<Summary>) -> [String; 6] {
    match s {
        Some(s) => [
            s.n.to_string(),
            metric(info, s.min),
            metric(info, s.q1),
            metric(info, s.median),
            metric(info, s.q3),
            metric(info, s.max),
        ],
        None => [
            "0".to_string(),
            "--".into(),
            "--".into(),
            "--".into(),
            "--".into(),
            "--".into(),
        ],
    }
}

fn title_or(stats: &Stats, fallback: &str) -> String {
    if stats.title.is_empty() {
        fallback.to_string()
    } else {
        stats.title.clone()
    }
}

// ---------------------------------------------------------------------------------------------
// LaTeX.

/// The text-statistics rows: (statistic, value) in the order both tables print them.
fn text_rows(t: &super::stats::TextStats) -> Vec<(String, String)> {
    // Short cells, so the table fits one column of a two-column paper.
    let mean =
        |s: &Option<super::Summary>| s.map_or("none".to_string(), |s| format!("{:.1}", s.mean));
    let range = |s: &Option<super::Summary>| {
        s.map_or("none".to_string(), |s| format!("{} to {}", s.min, s.max))
    };
    vec![
        ("Clips".into(), t.clips.to_string()),
        ("Captions".into(), t.captions.to_string()),
        ("Vocabulary".into(), t.vocabulary.to_string()),
        ("Words per caption, mean".into(), mean(&t.words_per_caption)),
        (
            "Words per caption, range".into(),
            range(&t.words_per_caption),
        ),
        ("Captions per clip, mean".into(), mean(&t.captions_per_clip)),
        (
            "Captions per clip, range".into(),
            range(&t.captions_per_clip),
        ),
    ]
}

/// Tables that cannot fit one column of a two-column paper (eight or more columns, or columns
/// per source kind) are set as `table*`, across both columns; the rest fit a column.
/// `tests/report.rs` compiles `tables.tex` in a two-column document and checks for overfull boxes.
const WIDE_TABLES: [&str; 3] = [
    "tab:mf-motion-types",
    "tab:mf-composition",
    "tab:mf-plausibility",
];

fn tex_table(out: &mut String, caption: &str, label: &str, spec: &str, body: &str) {
    let float = if WIDE_TABLES.contains(&label) {
        "table*"
    } else {
        "table"
    };
    let _ = writeln!(out, "\\begin{{{float}}}[tbp]");
    let _ = writeln!(out, "\\centering");
    let _ = writeln!(out, "\\caption{{{caption}}}");
    let _ = writeln!(out, "\\label{{{label}}}");
    let _ = writeln!(out, "\\begin{{tabular}}{{{spec}}}");
    let _ = writeln!(out, "\\toprule");
    out.push_str(body);
    let _ = writeln!(out, "\\bottomrule");
    let _ = writeln!(out, "\\end{{tabular}}");
    let _ = writeln!(out, "\\end{{{float}}}");
    out.push('\n');
}

fn tex_type_row(t: &TypeStats, name: &str) -> String {
    let l = length_cells(&t.seconds);
    format!(
        "{name} & {} & {} & {} & {} & {} & {} & {} \\\\\n",
        t.clips, l[0], l[1], l[2], l[3], l[4], t.total_frames
    )
}

fn tex_counts(out: &mut String, heading: &str, counts: &BTreeMap<String, usize>) {
    let _ = writeln!(out, "\\multicolumn{{2}}{{l}}{{\\emph{{{heading}}}}} \\\\");
    if counts.is_empty() {
        let _ = writeln!(out, "none & 0 \\\\");
    }
    for (reason, n) in counts {
        let _ = writeln!(out, "{} & {n} \\\\", latex_escape(reason));
    }
}

/// `tables.tex`: every table as a `table` float with caption and `tab:mf-*` label.
pub(crate) fn latex(stats: &Stats) -> String {
    let title = latex_escape(&title_or(stats, "the dataset"));
    let mut out = String::new();
    out.push_str("% Dataset statistics written by motionforge's report module.\n");
    out.push_str("% Needs \\usepackage{booktabs}; place the tables with \\input{tables.tex}.\n\n");
    tex_motion_types(&mut out, stats, &title);
    tex_composition(&mut out, stats, &title);
    tex_label_sources(&mut out, stats, &title);
    tex_text(&mut out, stats, &title);
    tex_plausibility(&mut out, stats, &title);
    tex_drops(&mut out, stats, &title);
    out
}

/// Motion types: clips, length quartiles and total frames.
fn tex_motion_types(out: &mut String, stats: &Stats, title: &str) {
    // LAMA Table 3's columns (segment length range, count, total frames) with the quartiles in
    // between.
    let mut body = String::new();
    body.push_str(" & & \\multicolumn{5}{c}{Length (s)} & \\\\\n\\cmidrule(lr){3-7}\n");
    body.push_str("Motion type & Clips & Min & $Q_1$ & Median & $Q_3$ & Max & Total frames \\\\\n");
    body.push_str("\\midrule\n");
    for t in types_in_report_order(stats) {
        body.push_str(&tex_type_row(t, &latex_escape(&t.motion_type)));
    }
    body.push_str("\\midrule\n");
    body.push_str(&tex_type_row(&stats.motion_types_total, "All types"));
    tex_table(
        out,
        &format!(
            "Motion types of {title}: clip count, motion length and total frames (original single clips; mirrored copies not counted)."
        ),
        "tab:mf-motion-types",
        "lrrrrrrr",
        &body,
    );
}

/// Composition: clips per split and source kind.
fn tex_composition(out: &mut String, stats: &Stats, title: &str) {
    // One row per split, one column per source kind.
    let kinds: Vec<String> = stats
        .composition
        .first()
        .map(|s| s.kinds.iter().map(|k| k.source_kind.clone()).collect())
        .unwrap_or_default();
    let mut body = String::new();
    body.push_str("Split");
    for k in &kinds {
        let _ = write!(body, " & {}", latex_escape(&kind_label(k)));
    }
    body.push_str(" & Total \\\\\n\\midrule\n");
    for s in &stats.composition {
        body.push_str(&latex_escape(&s.split));
        for k in &s.kinds {
            let _ = write!(body, " & {} ({}\\%)", k.total, pct(k.share));
        }
        let _ = writeln!(body, " & {} \\\\", s.total);
    }
    tex_table(
        out,
        &format!(
            "Composition of {title} by source kind: clips per split, mirrored copies included (share of the split in parentheses)."
        ),
        "tab:mf-composition",
        &format!("l{}r", "r".repeat(kinds.len())),
        &body,
    );
}

/// Clips per label source.
fn tex_label_sources(out: &mut String, stats: &Stats, title: &str) {
    let mut body = String::from("Label source & Clips \\\\\n\\midrule\n");
    for (source, n) in &stats.label_sources {
        let _ = writeln!(body, "{} & {n} \\\\", latex_escape(source));
    }
    tex_table(
        out,
        &format!(
            "Sources of the body-part labels of {title} (original real clips; synthetic pairs take their sources' labels)."
        ),
        "tab:mf-label-sources",
        "lr",
        &body,
    );
}

/// Caption statistics and the most frequent verbs.
fn tex_text(out: &mut String, stats: &Stats, title: &str) {
    let mut body = String::from("Statistic & Value \\\\\n\\midrule\n");
    for (name, value) in text_rows(&stats.text) {
        let _ = writeln!(body, "{name} & {value} \\\\");
    }
    let _ = writeln!(
        body,
        "\\midrule\nMost frequent verbs & Captions \\\\\n\\midrule"
    );
    for (verb, n) in &stats.text.top_verbs {
        let _ = writeln!(body, "{} & {n} \\\\", latex_escape(verb));
    }
    tex_table(
        out,
        &format!("Captions of {title} (original real clips)."),
        "tab:mf-text",
        "lr",
        &body,
    );
}

/// Plausibility metrics, real versus synthetic.
fn tex_plausibility(out: &mut String, stats: &Stats, title: &str) {
    let mut body = String::new();
    body.push_str(
        "Metric & Clips & $n$ & Min & $Q_1$ & Median & $Q_3$ & Max & Threshold \\\\\n\\midrule\n",
    );
    for (i, m) in stats.plausibility.iter().enumerate() {
        if i > 0 {
            body.push_str("\\addlinespace\n");
        }
        body.push_str(&tex_metric_rows(m));
    }
    tex_table(
        out,
        &format!(
            "Plausibility of real and synthetic clips of {title} (originals). Thresholds are the build's defaults."
        ),
        "tab:mf-plausibility",
        "llrrrrrrl",
        &body,
    );
}

/// Drops and rejects by reason.
fn tex_drops(out: &mut String, stats: &Stats, title: &str) {
    let mut body = String::from("Reason & Count \\\\\n\\midrule\n");
    tex_counts(&mut body, "Dropped segments", &stats.drops);
    body.push_str("\\midrule\n");
    tex_counts(&mut body, "Rejected items", &stats.rejects);
    tex_table(
        out,
        &format!("Segments dropped and items rejected while building {title}, by reason."),
        "tab:mf-drops",
        "lr",
        &body,
    );
}

/// `figures.tex`: every figure of [`FIGURES`] as a float with its caption and `fig:mf-*` label,
/// the PDF included at the width it was drawn for (`\columnwidth`, or `\textwidth` in a
/// `figure*`), so its text prints at the size it was set in. `tests/report.rs` compiles it in a
/// two-column page and measures that text.
pub(crate) fn latex_figures(stats: &Stats) -> String {
    let title = latex_escape(&title_or(stats, "the dataset"));
    let mut out = String::new();
    out.push_str("% Dataset figures written by motionforge's report module.\n");
    out.push_str(
        "% Needs \\usepackage{graphicx}; place the figures with \\input{figures.tex}. The paths are\n\
         % relative to the main document: with the report in report/, add \\graphicspath{{report/}}.\n\n",
    );
    for f in &FIGURES {
        let (float, width) = match f.span {
            Span::Column => ("figure", "\\columnwidth"),
            Span::Page => ("figure*", "\\textwidth"),
        };
        let _ = writeln!(out, "\\begin{{{float}}}[tbp]");
        let _ = writeln!(out, "\\centering");
        let _ = writeln!(
            out,
            "\\includegraphics[width={width}]{{figures/{}.pdf}}",
            f.stem
        );
        let _ = writeln!(out, "\\caption{{{title}: {}.}}", latex_escape(f.caption));
        let _ = writeln!(out, "\\label{{{}}}", f.label);
        let _ = writeln!(out, "\\end{{{float}}}");
        out.push('\n');
    }
    out
}

fn tex_metric_rows(m: &MetricStats) -> String {
    let info = &m.info;
    let threshold = latex_escape(info.threshold)
        .replace("<=", "$\\le$")
        .replace(">=", "$\\ge$");
    let mut out = String::new();
    for (g, s) in [("real", &m.real), ("synthetic", &m.synthetic)] {
        let c = summary_cells(info, s);
        let (name, thr) = if g == "real" {
            (
                format!("{} ({})", latex_escape(info.name), info.unit_tex),
                threshold.clone(),
            )
        } else {
            (String::new(), String::new())
        };
        let _ = writeln!(
            out,
            "{name} & {g} & {} & {} & {} & {} & {} & {} & {thr} \\\\",
            c[0], c[1], c[2], c[3], c[4], c[5]
        );
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Markdown.

fn md_row(out: &mut String, cells: &[String]) {
    out.push('|');
    for c in cells {
        let _ = write!(out, " {c} |");
    }
    out.push('\n');
}

fn md_header(out: &mut String, cells: &[&str], numeric_from: usize) {
    md_row(
        out,
        &cells.iter().map(|c| c.to_string()).collect::<Vec<_>>(),
    );
    out.push('|');
    for i in 0..cells.len() {
        out.push_str(if i >= numeric_from { "---:|" } else { "---|" });
    }
    out.push('\n');
}

fn md_figure(out: &mut String, stem: &str) {
    if let Some(f) = FIGURES.iter().find(|f| f.stem == stem) {
        let _ = writeln!(
            out,
            "\n![{}](figures/{stem}.png)\n\n*{}.* Vector versions: [figures/{stem}.pdf](figures/{stem}.pdf) (for LaTeX: `figures.tex`), [figures/{stem}.svg](figures/{stem}.svg).\n",
            f.caption, f.caption
        );
    }
}

fn md_counts(out: &mut String, heading: &str, counts: &BTreeMap<String, usize>) {
    let _ = writeln!(out, "{heading}:\n");
    if counts.is_empty() {
        out.push_str("none.\n\n");
        return;
    }
    md_header(out, &["reason", "count"], 1);
    for (reason, n) in counts {
        md_row(out, &[markdown_escape(reason), n.to_string()]);
    }
    out.push('\n');
}

/// `report.md`: overview, the tables, and every figure of [`FIGURES`] embedded as PNG with a link
/// to its SVG.
pub(crate) fn markdown(stats: &Stats) -> String {
    let mut out = String::new();
    md_title(&mut out, stats);
    md_overview(&mut out, stats);
    md_motion_types(&mut out, stats);
    md_goals(&mut out, stats);
    md_composition(&mut out, stats);
    md_label_sources(&mut out, stats);
    md_captions(&mut out, stats);
    md_plausibility(&mut out, stats);
    md_drops(&mut out, stats);
    out
}

/// Title and where the numbers come from.
fn md_title(out: &mut String, stats: &Stats) {
    let _ = writeln!(
        out,
        "# {}: dataset statistics\n",
        markdown_escape(&title_or(stats, "Dataset"))
    );
    let tables: Vec<String> = stats.tables.iter().map(|t| format!("`{t}`")).collect();
    let _ = writeln!(
        out,
        "Written by motionforge's report module from {} table{} ({}). The numbers are in \
         `stats.json`, the LaTeX tables in `tables.tex` (booktabs).\n",
        stats.tables.len(),
        if stats.tables.len() == 1 { "" } else { "s" },
        if tables.is_empty() {
            "none named".to_string()
        } else {
            tables.join(", ")
        }
    );
}

/// The overview table: rows, originals, splits, hours.
fn md_overview(out: &mut String, stats: &Stats) {
    let o = &stats.overview;
    out.push_str("## Overview\n\n");
    md_header(out, &["", "value"], 1);
    let splits: Vec<String> = o.splits.iter().map(|s| markdown_escape(s)).collect();
    for (k, v) in [
        ("rows (clips)", o.rows.to_string()),
        ("originals", o.originals.to_string()),
        ("mirrored copies", o.mirrored.to_string()),
        ("splits", splits.join(", ")),
        ("hours of motion (all rows)", format!("{:.3}", o.hours)),
        (
            "hours of motion (originals)",
            format!("{:.3}", o.hours_originals),
        ),
        (
            "original single clips (motion-type statistics)",
            o.typed_clips.to_string(),
        ),
    ] {
        md_row(out, &[k.to_string(), v]);
    }
}

/// Clips and lengths per motion type, with their figures.
fn md_motion_types(out: &mut String, stats: &Stats) {
    out.push_str(
        "\n## Motion types\n\nOriginal `real_single` clips per motion type (pairs and synthetic \
         compositions carry no type; mirrored copies would double every count). Lengths in \
         seconds; quartiles interpolate linearly. LAMA Table 3's columns with the quartiles \
         added.\n\n",
    );
    md_header(
        out,
        &[
            "motion type",
            "clips",
            "min (s)",
            "Q1 (s)",
            "median (s)",
            "Q3 (s)",
            "max (s)",
            "total frames",
        ],
        1,
    );
    let type_row = |out: &mut String, t: &TypeStats, name: String| {
        let l = length_cells(&t.seconds);
        let mut cells = vec![name, t.clips.to_string()];
        cells.extend(l);
        cells.push(t.total_frames.to_string());
        md_row(out, &cells);
    };
    for t in types_in_report_order(stats) {
        type_row(out, t, markdown_escape(&t.motion_type));
    }
    type_row(out, &stats.motion_types_total, "**all types**".to_string());
    md_figure(out, "motion_type_counts");
    md_figure(out, "motion_lengths");
}

/// Where locomotion clips end (`goal_pelvis`), with its figure.
fn md_goals(out: &mut String, stats: &Stats) {
    let g = &stats.goals;
    let _ = writeln!(
        out,
        "## Locomotion goals\n\n{} original clips have a `goal_pelvis` (where the pelvis ends, in \
         the first-frame canonical frame: x right, y forward, metres).\n",
        g.clips
    );
    if let (Some(x), Some(y), Some(d)) = (&g.x, &g.y, &g.distance) {
        md_header(out, &["", "min", "median", "max"], 1);
        for (name, s) in [
            ("lateral x (m)", x),
            ("forward y (m)", y),
            ("distance (m)", d),
        ] {
            md_row(
                out,
                &[
                    name.to_string(),
                    format!("{:.2}", s.min),
                    format!("{:.2}", s.median),
                    format!("{:.2}", s.max),
                ],
            );
        }
        out.push('\n');
        let per: Vec<String> = g
            .per_type
            .iter()
            .map(|(t, n)| format!("{} {n}", markdown_escape(t)))
            .collect();
        let _ = writeln!(out, "Per motion type: {}.", per.join(", "));
    }
    md_figure(out, "goal_locations");
}

/// Rows per split and source kind, with its figure.
fn md_composition(out: &mut String, stats: &Stats) {
    out.push_str(
        "## Composition\n\nRows per split and source kind, mirrored copies included (their \
         share of the split in parentheses).\n\n",
    );
    let kinds: Vec<String> = stats
        .composition
        .first()
        .map(|s| s.kinds.iter().map(|k| kind_label(&k.source_kind)).collect())
        .unwrap_or_default();
    let mut header: Vec<&str> = vec!["split"];
    header.extend(kinds.iter().map(String::as_str));
    header.push("total");
    md_header(out, &header, 1);
    for s in &stats.composition {
        let mut cells = vec![markdown_escape(&s.split)];
        cells.extend(
            s.kinds
                .iter()
                .map(|k| format!("{} ({}%; {} mirrored)", k.total, pct(k.share), k.mirrored)),
        );
        cells.push(s.total.to_string());
        md_row(out, &cells);
    }
    md_figure(out, "composition");
}

/// Original real clips per label source.
fn md_label_sources(out: &mut String, stats: &Stats) {
    out.push_str(
        "## Label sources\n\nOriginal real clips per `label_source` (`(none)`: unlabelled); synthetic pairs are left out: their `composed` labels are their sources' labels.\n\n",
    );
    md_header(out, &["label source", "clips"], 1);
    for (source, n) in &stats.label_sources {
        md_row(out, &[markdown_escape(source), n.to_string()]);
    }
}

/// Caption statistics and the most frequent verbs.
fn md_captions(out: &mut String, stats: &Stats) {
    out.push_str(
        "\n## Captions\n\nThe captions (`texts`) of the original real clips: words are lowercase runs of letters, digits and `'`; verbs are lemmas tagged by the HumanML3D caption tagger, counted once per caption.\n\n",
    );
    md_header(out, &["statistic", "value"], 1);
    for (name, value) in text_rows(&stats.text) {
        md_row(out, &[name, value]);
    }
    out.push('\n');
    md_header(out, &["most frequent verb", "captions"], 1);
    for (verb, n) in &stats.text.top_verbs {
        md_row(out, &[markdown_escape(verb), n.to_string()]);
    }
}

/// Plausibility metrics, real versus synthetic, with its figure.
fn md_plausibility(out: &mut String, stats: &Stats) {
    out.push_str(
        "\n## Plausibility\n\nReal (`real_single`, `real_pair`) versus synthetic original clips. \
         The threshold is the build's default (`quality::Thresholds`).\n\n",
    );
    md_header(
        out,
        &[
            "metric",
            "clips",
            "n",
            "min",
            "Q1",
            "median",
            "Q3",
            "max",
            "threshold",
        ],
        2,
    );
    for m in &stats.plausibility {
        for (g, s, missing) in [
            ("real", &m.real, m.real_missing),
            ("synthetic", &m.synthetic, m.synthetic_missing),
        ] {
            let c = summary_cells(&m.info, s);
            let name = if g == "real" {
                format!("{} ({})", m.info.name, m.info.unit)
            } else {
                String::new()
            };
            let n = if missing > 0 {
                format!("{} (+{missing} without a value)", c[0])
            } else {
                c[0].clone()
            };
            md_row(
                out,
                &[
                    name,
                    g.to_string(),
                    n,
                    c[1].clone(),
                    c[2].clone(),
                    c[3].clone(),
                    c[4].clone(),
                    c[5].clone(),
                    if g == "real" {
                        m.info.threshold.replace("<=", "≤").replace(">=", "≥")
                    } else {
                        String::new()
                    },
                ],
            );
        }
    }
    md_figure(out, "plausibility");
}

/// Drops and rejects by reason, and labels that contradict the motion.
fn md_drops(out: &mut String, stats: &Stats) {
    out.push_str("## Drops and rejects\n\n");
    md_counts(out, "Dropped segments", &stats.drops);
    md_counts(out, "Rejected items", &stats.rejects);
    if !stats.label_contradictions.is_empty() {
        // Listed for the reader to judge, never fixed: a label may be wrong, or the take.
        out.push_str(
            "## Labels that contradict the motion

",
        );
        out.push_str("| clip | the text says | the motion | measured |\n|---|---|---|---:|\n");
        for c in &stats.label_contradictions {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {:.2} |",
                markdown_escape(&c.clip_id),
                markdown_escape(&c.claim),
                markdown_escape(&c.motion),
                c.measured
            );
        }
        out.push('\n');
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latex_specials_are_escaped() {
        assert_eq!(
            latex_escape(r"a_b & 50% $x$ #1 {y} ~^\"),
            r"a\_b \& 50\% \$x\$ \#1 \{y\} \textasciitilde{}\textasciicircum{}\textbackslash{}"
        );
    }

    #[test]
    fn markdown_cells_cannot_break_tables() {
        assert_eq!(markdown_escape("a|b_c"), r"a\|b\_c");
    }
}
