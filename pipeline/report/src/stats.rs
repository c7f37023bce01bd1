//! The statistics: summaries per motion type, composition per split, label sources, goals and
//! plausibility, as one serialisable [`Stats`].

use std::cmp::Ordering;
use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;

use super::{ClipRow, ReportInput};
use motionforge_sources::clip::{SourceKind, Split};

/// Group name of clips whose label maps to no motion type (the build report's name too).
pub const UNMAPPED: &str = "(unmapped)";
/// Split name of rows from tables without a `split` column.
pub const NO_SPLIT: &str = "all";
/// Split name of rows whose `split` value is null.
pub const NULL_SPLIT: &str = "(none)";
/// Label-source name of rows whose `label_source` is null (unlabelled clips).
pub const NO_LABEL: &str = "(none)";
/// Source kinds always listed in the composition, in SINC's order, even when absent: a zero says
/// as much as a count.
pub const KNOWN_KINDS: [&str; 3] = [
    SourceKind::RealSingle.as_str(),
    SourceKind::RealPair.as_str(),
    SourceKind::Synthetic.as_str(),
];

/// A plausibility metric column and how to present it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MetricInfo {
    /// Column name in the clip table.
    pub column: &'static str,
    /// Readable name for tables and figures.
    pub name: &'static str,
    /// Unit for Markdown and figures.
    pub unit: &'static str,
    /// Unit for LaTeX.
    #[serde(skip)]
    pub unit_tex: &'static str,
    /// The default build threshold (`quality::Thresholds::default()`), as `<= x` or `>= x`.
    pub threshold: &'static str,
}

/// The four plausibility metrics, in the order of [`ClipRow::plausibility`].
pub const METRICS: [MetricInfo; 4] = [
    MetricInfo {
        column: "foot_skate",
        name: "foot skating",
        unit: "m/s",
        unit_tex: "m/s",
        threshold: "<= 0.4",
    },
    MetricInfo {
        column: "ground_penetration",
        name: "ground penetration",
        unit: "m",
        unit_tex: "m",
        threshold: "<= 0.03",
    },
    MetricInfo {
        column: "self_distance",
        name: "limb-to-spine distance",
        unit: "m",
        unit_tex: "m",
        threshold: ">= 0.03",
    },
    MetricInfo {
        column: "lean",
        name: "lean",
        unit: "°",
        unit_tex: "$^\\circ$",
        threshold: "<= 25",
    },
];

/// Order statistics of a sample. Quartiles interpolate linearly between order statistics
/// ([`quantile`]). Values are rounded to 6 decimals so `stats.json` stays readable and stable.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Summary {
    /// Sample size (finite values only).
    pub n: usize,
    /// Smallest value.
    pub min: f64,
    /// First quartile.
    pub q1: f64,
    /// Median.
    pub median: f64,
    /// Third quartile.
    pub q3: f64,
    /// Largest value.
    pub max: f64,
    /// Arithmetic mean.
    pub mean: f64,
}

impl Summary {
    /// The summary of the finite values of `values`; `None` when there are none.
    pub fn of(values: &[f64]) -> Option<Summary> {
        let sorted = sorted_finite(values);
        let (&min, &max) = (sorted.first()?, sorted.last()?);
        // Summing in sorted order makes the mean independent of the input order.
        let mean = sorted.iter().sum::<f64>() / sorted.len() as f64;
        Some(Summary {
            n: sorted.len(),
            min: round6(min),
            q1: round6(quantile(&sorted, 0.25)),
            median: round6(quantile(&sorted, 0.5)),
            q3: round6(quantile(&sorted, 0.75)),
            max: round6(max),
            mean: round6(mean),
        })
    }
}

/// The `q`-quantile (`0 <= q <= 1`) of ascending `sorted`, interpolating linearly between the two
/// nearest order statistics at position `q * (n - 1)` (R's type 7, NumPy's default). NaN for an
/// empty slice.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    let n = sorted.len();
    if n == 0 {
        return f64::NAN;
    }
    let pos = q.clamp(0.0, 1.0) * (n - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    let (a, b) = (sorted[lo.min(n - 1)], sorted[hi.min(n - 1)]);
    a + (b - a) * (pos - lo as f64)
}

/// Silverman's rule-of-thumb bandwidth for a Gaussian kernel:
/// `0.9 * min(sd, IQR / 1.34) * n^(-1/5)`, with the sample standard deviation alone when the IQR
/// is 0. `None` for fewer than two finite values or no spread, where no density can be drawn.
pub fn silverman_bandwidth(values: &[f64]) -> Option<f64> {
    let sorted = sorted_finite(values);
    let n = sorted.len();
    if n < 2 {
        return None;
    }
    let mean = sorted.iter().sum::<f64>() / n as f64;
    let var = sorted.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let sd = var.sqrt();
    let iqr = quantile(&sorted, 0.75) - quantile(&sorted, 0.25);
    let spread = if iqr > 0.0 { sd.min(iqr / 1.34) } else { sd };
    (spread > 0.0).then(|| 0.9 * spread * (n as f64).powf(-0.2))
}

/// Gaussian kernel density estimate of `values` with bandwidth `h` at each point of `grid`.
pub(crate) fn kde(values: &[f64], h: f64, grid: &[f64]) -> Vec<f64> {
    let norm = 1.0 / (values.len() as f64 * h * (2.0 * std::f64::consts::PI).sqrt());
    grid.iter()
        .map(|&x| {
            values
                .iter()
                .map(|&v| (-0.5 * ((x - v) / h).powi(2)).exp())
                .sum::<f64>()
                * norm
        })
        .collect()
}

/// Tukey's whisker ends: the most extreme values within 1.5 IQR of the quartiles.
pub(crate) fn whiskers(sorted: &[f64], q1: f64, q3: f64) -> (f64, f64) {
    let iqr = q3 - q1;
    let lo = sorted
        .iter()
        .copied()
        .find(|&v| v >= q1 - 1.5 * iqr)
        .unwrap_or(q1);
    let hi = sorted
        .iter()
        .rev()
        .copied()
        .find(|&v| v <= q3 + 1.5 * iqr)
        .unwrap_or(q3);
    (lo.min(q1), hi.max(q3))
}

pub(crate) fn sorted_finite(values: &[f64]) -> Vec<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v
}

/// Rounds to 6 decimals (and turns -0 into 0) for stable, readable JSON.
pub(crate) fn round6(x: f64) -> f64 {
    let r = (x * 1e6).round() / 1e6;
    if r == 0.0 { 0.0 } else { r }
}

/// Counts and lengths of one motion type (LAMA Table 3's columns, plus quartiles).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TypeStats {
    /// The motion type, or [`UNMAPPED`].
    pub motion_type: String,
    /// Number of clips.
    pub clips: usize,
    /// Sum of their frames.
    pub total_frames: u64,
    /// Sum of their lengths in seconds.
    pub total_seconds: f64,
    /// Their lengths in seconds.
    pub seconds: Option<Summary>,
}

/// How many rows of one source kind a split has.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct KindCount {
    /// `real_single`, `real_pair`, `synthetic`, or another value found in the table.
    pub source_kind: String,
    /// All rows of this kind.
    pub total: usize,
    /// Rows that are not mirrored copies.
    pub originals: usize,
    /// Mirrored copies.
    pub mirrored: usize,
    /// `total` over the split's rows (0 for an empty split).
    pub share: f64,
}

/// The training-set composition of one split (SINC figure A.4).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SplitComposition {
    /// Split name ([`NO_SPLIT`] without a split column).
    pub split: String,
    /// All rows of the split, mirrored copies included.
    pub total: usize,
    /// Counts per source kind, [`KNOWN_KINDS`] first.
    pub kinds: Vec<KindCount>,
}

/// Locomotion goals (`goal_pelvis`) of the original clips (LINGO figure A3).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GoalStats {
    /// Original clips with a goal.
    pub clips: usize,
    /// Those clips per motion type.
    pub per_type: BTreeMap<String, usize>,
    /// Lateral coordinate (m, + right).
    pub x: Option<Summary>,
    /// Forward coordinate (m).
    pub y: Option<Summary>,
    /// Distance from the start (m).
    pub distance: Option<Summary>,
}

/// One plausibility metric of real versus synthetic original clips.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MetricStats {
    /// The metric.
    #[serde(flatten)]
    pub info: MetricInfo,
    /// Real clips (`real_single` and `real_pair`).
    pub real: Option<Summary>,
    /// Synthetic clips.
    pub synthetic: Option<Summary>,
    /// Real clips without a finite value.
    pub real_missing: usize,
    /// Synthetic clips without a finite value.
    pub synthetic_missing: usize,
}

/// Dataset-wide counts.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Overview {
    /// All rows.
    pub rows: usize,
    /// Rows that are not mirrored copies.
    pub originals: usize,
    /// Mirrored copies.
    pub mirrored: usize,
    /// Splits present, in order (train, validation, test, then alphabetical).
    pub splits: Vec<String>,
    /// Hours of motion in all rows.
    pub hours: f64,
    /// Hours of motion in the original rows.
    pub hours_originals: f64,
    /// Real single clips (originals) that the motion-type statistics count.
    pub typed_clips: usize,
}

/// Every statistic of a report; written as `stats.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Stats {
    /// Report title.
    pub title: String,
    /// Caption statistics of the original real clips.
    pub text: TextStats,
    /// File names of the tables read, sorted.
    pub tables: Vec<String>,
    /// Dataset-wide counts.
    pub overview: Overview,
    /// Per motion type (original `real_single` clips), sorted by name with [`UNMAPPED`] last.
    pub motion_types: Vec<TypeStats>,
    /// All those clips together (the table's total row).
    pub motion_types_total: TypeStats,
    /// Rows per split and source kind, mirrored copies included.
    pub composition: Vec<SplitComposition>,
    /// Original real rows (not mirrored, not synthetic) per `label_source` ([`NO_LABEL`] for
    /// null).
    pub label_sources: BTreeMap<String, usize>,
    /// Locomotion goals.
    pub goals: GoalStats,
    /// Plausibility metrics, real versus synthetic originals, in the order of [`METRICS`].
    pub plausibility: Vec<MetricStats>,
    /// Dropped segments by reason.
    pub drops: BTreeMap<String, usize>,
    /// Rejected items by reason.
    pub rejects: BTreeMap<String, usize>,
    /// Clips whose text contradicts what their motion does, by clip id (absent when none).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub label_contradictions: Vec<motionforge_core::quality::Contradiction>,
}

/// Orders motion-type names alphabetically with [`UNMAPPED`] last.
pub(crate) fn type_order(a: &str, b: &str) -> Ordering {
    (a == UNMAPPED, a).cmp(&(b == UNMAPPED, b))
}

/// The motion types in the order of the report's type tables and both type figures: most clips
/// first, ties by name, [`UNMAPPED`] last.
pub(crate) fn types_in_report_order(stats: &Stats) -> Vec<&TypeStats> {
    let mut types: Vec<&TypeStats> = stats.motion_types.iter().collect();
    types.sort_by(|a, b| {
        (a.motion_type == UNMAPPED)
            .cmp(&(b.motion_type == UNMAPPED))
            .then(b.clips.cmp(&a.clips))
            .then(a.motion_type.cmp(&b.motion_type))
    });
    types
}

/// Orders split names as the build writes them ([`Split`]'s order: train, validation, test), with
/// [`NO_SPLIT`] after test and other names last, alphabetically.
pub(crate) fn split_order(a: &str, b: &str) -> Ordering {
    let rank = |s: &str| {
        if s == NO_SPLIT { 5 } else { 2 * Split::rank(s) }
    };
    (rank(a), a).cmp(&(rank(b), b))
}

/// The rows in a canonical order, so that nothing downstream depends on file or batch order.
pub(crate) fn sorted_rows(rows: &[ClipRow]) -> Vec<ClipRow> {
    let mut v = rows.to_vec();
    v.sort_by(|a, b| {
        (&a.clip_id, &a.split, &a.source_kind, a.mirrored, a.frames)
            .cmp(&(&b.clip_id, &b.split, &b.source_kind, b.mirrored, b.frames))
            .then(a.seconds.total_cmp(&b.seconds))
    });
    v
}

/// The rows the motion-type statistics count: original real single clips. Pairs and synthetic
/// compositions carry no motion type by design, so counting them would only swell
/// [`UNMAPPED`]; mirrored copies would double every count (the build report counts the same way).
pub(crate) fn typed_rows(rows: &[ClipRow]) -> impl Iterator<Item = &ClipRow> {
    rows.iter()
        .filter(|r| r.is_original() && r.source_kind == SourceKind::RealSingle.as_str())
}

/// What a text-to-motion paper reports of its captions, over the original real clips (mirrored
/// copies repeat their original's captions mirrored; synthetic pairs' are composed from their
/// sources').
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct TextStats {
    /// Clips counted.
    pub clips: usize,
    /// Their captions (`texts` entries).
    pub captions: usize,
    /// Distinct words over the captions: lowercase runs of ASCII letters, digits and `'`.
    pub vocabulary: usize,
    /// Words per caption.
    pub words_per_caption: Option<Summary>,
    /// Captions per clip.
    pub captions_per_clip: Option<Summary>,
    /// The most frequent verbs (lemmas, by HumanML3D's caption tagger), as (verb, captions
    /// holding it), most frequent first, ties by name; at most 10 (`TOP_VERBS`).
    pub top_verbs: Vec<(String, usize)>,
}

/// How many verbs [`TextStats::top_verbs`] lists.
pub(crate) const TOP_VERBS: usize = 10;

/// The words of a caption as the text statistics count them.
pub(crate) fn caption_words(caption: &str) -> Vec<String> {
    caption
        .to_lowercase()
        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '\''))
        .filter(|w| !w.is_empty())
        .map(str::to_string)
        .collect()
}

fn text_statistics(rows: &[ClipRow]) -> TextStats {
    let clips: Vec<&ClipRow> = rows
        .iter()
        .filter(|r| r.is_original() && !r.is_synthetic())
        .collect();
    let mut vocabulary = std::collections::BTreeSet::new();
    let mut words_per_caption = Vec::new();
    let mut verbs: BTreeMap<String, usize> = BTreeMap::new();
    let captions: Vec<&str> = clips
        .iter()
        .flat_map(|r| r.texts.iter().map(String::as_str))
        .collect();
    // Tagged together first, which is cheaper than one at a time; a caption that cannot be
    // tagged is left out of the verbs below as before.
    let _ = motionforge_language::caption::remember_all(&captions);
    for caption in clips.iter().flat_map(|r| &r.texts) {
        let words = caption_words(caption);
        words_per_caption.push(words.len() as f64);
        vocabulary.extend(words);
        if let Ok(tokens) = motionforge_language::caption::tokens(caption) {
            let in_caption: std::collections::BTreeSet<String> = tokens
                .into_iter()
                .filter(|t| t.tag == motionforge_language::caption::Upos::Verb)
                .map(|t| t.word.to_lowercase())
                .collect();
            for verb in in_caption {
                *verbs.entry(verb).or_insert(0) += 1;
            }
        }
    }
    let mut top_verbs: Vec<(String, usize)> = verbs.into_iter().collect();
    top_verbs.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    top_verbs.truncate(TOP_VERBS);
    let per_clip: Vec<f64> = clips.iter().map(|r| r.texts.len() as f64).collect();
    TextStats {
        clips: clips.len(),
        captions: words_per_caption.len(),
        vocabulary: vocabulary.len(),
        words_per_caption: Summary::of(&words_per_caption),
        captions_per_clip: Summary::of(&per_clip),
        top_verbs,
    }
}

/// Lengths in seconds per motion type of the original single clips (ascending), types in the
/// report's order: what the motion-length figure draws.
pub fn lengths_by_type(rows: &[ClipRow]) -> Vec<(String, Vec<f64>)> {
    let mut map: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for r in typed_rows(rows) {
        let t = r
            .motion_type
            .clone()
            .unwrap_or_else(|| UNMAPPED.to_string());
        map.entry(t).or_default().push(r.seconds);
    }
    let mut v: Vec<(String, Vec<f64>)> = map
        .into_iter()
        .map(|(k, mut s)| {
            s.sort_by(f64::total_cmp);
            (k, s)
        })
        .collect();
    v.sort_by(|a, b| type_order(&a.0, &b.0));
    v
}

/// Plausibility values of metric `k` for real (`false`) or synthetic (`true`) originals.
pub(crate) fn metric_values(rows: &[ClipRow], k: usize, synthetic: bool) -> (Vec<f64>, usize) {
    let mut values = Vec::new();
    let mut missing = 0;
    for r in rows
        .iter()
        .filter(|r| r.is_original() && r.is_synthetic() == synthetic)
    {
        match r.plausibility.map(|p| f64::from(p[k])) {
            Some(v) if v.is_finite() => values.push(v),
            _ => missing += 1,
        }
    }
    values.sort_by(f64::total_cmp);
    (values, missing)
}

/// Computes every statistic of `rows`; `input` gives the title, table names and drop/reject
/// counts. Independent of the order of `rows`.
pub fn statistics(rows: &[ClipRow], input: &ReportInput) -> Stats {
    let rows = sorted_rows(rows);
    let (motion_types, motion_types_total) = motion_type_stats(&rows);
    let overview = overview(&rows, motion_types_total.clips);
    let composition = composition_by_split(&rows, &overview.splits);
    Stats {
        title: input.title.clone(),
        text: text_statistics(&rows),
        tables: table_names(input),
        overview,
        motion_types,
        motion_types_total,
        composition,
        label_sources: label_sources(&rows),
        goals: goal_stats(&rows),
        plausibility: plausibility_stats(&rows),
        drops: input.drops.clone(),
        rejects: input.rejects.clone(),
        label_contradictions: {
            let mut listed = input.contradictions.clone();
            listed.sort_by(|a, b| (&a.clip_id, &a.claim).cmp(&(&b.clip_id, &b.claim)));
            listed
        },
    }
}

/// Rows, originals, splits and hours; `typed_clips` is the count of original single clips.
fn overview(rows: &[ClipRow], typed_clips: usize) -> Overview {
    let originals = rows.iter().filter(|r| r.is_original()).count();
    let seconds_all = sorted_finite(&rows.iter().map(|r| r.seconds).collect::<Vec<_>>());
    let seconds_orig = sorted_finite(
        &rows
            .iter()
            .filter(|r| r.is_original())
            .map(|r| r.seconds)
            .collect::<Vec<_>>(),
    );
    let mut splits: Vec<String> = rows
        .iter()
        .map(|r| r.split.clone())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    splits.sort_by(|a, b| split_order(a, b));
    Overview {
        rows: rows.len(),
        originals,
        mirrored: rows.len() - originals,
        splits,
        hours: round6(seconds_all.iter().sum::<f64>() / 3600.0),
        hours_originals: round6(seconds_orig.iter().sum::<f64>() / 3600.0),
        typed_clips,
    }
}

/// Clips, frames and lengths per motion type of the original single clips, and over all types.
fn motion_type_stats(rows: &[ClipRow]) -> (Vec<TypeStats>, TypeStats) {
    let mut frames: BTreeMap<String, u64> = BTreeMap::new();
    for r in typed_rows(rows) {
        let t = r
            .motion_type
            .clone()
            .unwrap_or_else(|| UNMAPPED.to_string());
        *frames.entry(t).or_default() += r.frames as u64;
    }
    let motion_types = lengths_by_type(rows)
        .into_iter()
        .map(|(t, secs)| TypeStats {
            clips: secs.len(),
            total_frames: frames.get(&t).copied().unwrap_or(0),
            total_seconds: round6(secs.iter().sum()),
            seconds: Summary::of(&secs),
            motion_type: t,
        })
        .collect();
    let typed: Vec<&ClipRow> = typed_rows(rows).collect();
    let typed_seconds: Vec<f64> =
        sorted_finite(&typed.iter().map(|r| r.seconds).collect::<Vec<_>>());
    let total = TypeStats {
        motion_type: "all types".to_string(),
        clips: typed.len(),
        total_frames: typed.iter().map(|r| r.frames as u64).sum(),
        total_seconds: round6(typed_seconds.iter().sum()),
        seconds: Summary::of(&typed_seconds),
    };
    (motion_types, total)
}

/// Rows per split and source kind (the known kinds first, then any other in name order).
fn composition_by_split(rows: &[ClipRow], splits: &[String]) -> Vec<SplitComposition> {
    let mut kinds: Vec<String> = KNOWN_KINDS.iter().map(|k| k.to_string()).collect();
    let extra: BTreeSet<&str> = rows
        .iter()
        .map(|r| r.source_kind.as_str())
        .filter(|k| !KNOWN_KINDS.contains(k))
        .collect();
    kinds.extend(extra.into_iter().map(str::to_string));
    splits
        .iter()
        .map(|split| {
            let in_split: Vec<&ClipRow> = rows.iter().filter(|r| &r.split == split).collect();
            SplitComposition {
                split: split.clone(),
                total: in_split.len(),
                kinds: kinds
                    .iter()
                    .map(|kind| kind_count(&in_split, kind))
                    .collect(),
            }
        })
        .collect()
}

/// The rows of one split of one source kind, originals and mirrored copies.
fn kind_count(in_split: &[&ClipRow], kind: &str) -> KindCount {
    let total = in_split.len();
    let of_kind = in_split.iter().filter(|r| r.source_kind == kind);
    let (mut originals, mut mirrored) = (0, 0);
    for r in of_kind {
        if r.mirrored {
            mirrored += 1;
        } else {
            originals += 1;
        }
    }
    let all = originals + mirrored;
    KindCount {
        source_kind: kind.to_string(),
        total: all,
        originals,
        mirrored,
        share: if total == 0 {
            0.0
        } else {
            round6(all as f64 / total as f64)
        },
    }
}

/// Original clips per label source. Real clips only: a synthetic pair's `composed` label is its
/// sources' labels again.
fn label_sources(rows: &[ClipRow]) -> BTreeMap<String, usize> {
    let mut label_sources = BTreeMap::new();
    for r in rows.iter().filter(|r| r.is_original() && !r.is_synthetic()) {
        let key = r
            .label_source
            .clone()
            .unwrap_or_else(|| NO_LABEL.to_string());
        *label_sources.entry(key).or_insert(0) += 1;
    }
    label_sources
}

/// Where the original clips with a finite `goal_pelvis` end, and how many per motion type.
fn goal_stats(rows: &[ClipRow]) -> GoalStats {
    let goal_rows: Vec<(&ClipRow, [f64; 2])> = rows
        .iter()
        .filter(|r| r.is_original())
        .filter_map(|r| {
            let g = r.goal_pelvis?;
            let g = [f64::from(g[0]), f64::from(g[1])];
            (g[0].is_finite() && g[1].is_finite()).then_some((r, g))
        })
        .collect();
    let mut per_type = BTreeMap::new();
    for (r, _) in &goal_rows {
        let t = r
            .motion_type
            .clone()
            .unwrap_or_else(|| UNMAPPED.to_string());
        *per_type.entry(t).or_insert(0) += 1;
    }
    GoalStats {
        clips: goal_rows.len(),
        per_type,
        x: Summary::of(&goal_rows.iter().map(|(_, g)| g[0]).collect::<Vec<_>>()),
        y: Summary::of(&goal_rows.iter().map(|(_, g)| g[1]).collect::<Vec<_>>()),
        distance: Summary::of(
            &goal_rows
                .iter()
                .map(|(_, g)| g[0].hypot(g[1]))
                .collect::<Vec<_>>(),
        ),
    }
}

/// Every plausibility metric's summary, real versus synthetic originals.
fn plausibility_stats(rows: &[ClipRow]) -> Vec<MetricStats> {
    METRICS
        .iter()
        .enumerate()
        .map(|(k, info)| {
            let (real, real_missing) = metric_values(rows, k, false);
            let (synthetic, synthetic_missing) = metric_values(rows, k, true);
            MetricStats {
                info: *info,
                real: Summary::of(&real),
                synthetic: Summary::of(&synthetic),
                real_missing,
                synthetic_missing,
            }
        })
        .collect()
}

/// The file names of the tables read, sorted.
fn table_names(input: &ReportInput) -> Vec<String> {
    let mut tables: Vec<String> = input
        .tables
        .iter()
        .map(|p| {
            p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| p.display().to_string())
        })
        .collect();
    tables.sort();
    tables
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quartiles_interpolate_like_numpy() {
        // numpy.percentile([1, 2, 3, 4], [25, 50, 75]) == [1.75, 2.5, 3.25]
        let s = Summary::of(&[4.0, 1.0, 3.0, 2.0]).unwrap();
        assert_eq!(
            (s.min, s.q1, s.median, s.q3, s.max),
            (1.0, 1.75, 2.5, 3.25, 4.0)
        );
        assert_eq!(s.mean, 2.5);
        // numpy.percentile([7, 15, 36, 39, 40, 41], [25, 50, 75]) == [20.25, 37.5, 39.75]
        let s = Summary::of(&[7.0, 15.0, 36.0, 39.0, 40.0, 41.0]).unwrap();
        assert_eq!((s.q1, s.median, s.q3), (20.25, 37.5, 39.75));
        let one = Summary::of(&[5.0]).unwrap();
        assert_eq!(
            (one.min, one.q1, one.median, one.q3, one.max),
            (5.0, 5.0, 5.0, 5.0, 5.0)
        );
        assert!(Summary::of(&[f64::NAN]).is_none());
        assert!(Summary::of(&[]).is_none());
    }

    #[test]
    fn silverman_matches_the_formula() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        // sd = 1.5811, IQR = 2 -> IQR/1.34 = 1.4925 is smaller.
        let h = silverman_bandwidth(&v).unwrap();
        let expected = 0.9 * (2.0 / 1.34) * 5f64.powf(-0.2);
        assert!((h - expected).abs() < 1e-12);
        assert!(silverman_bandwidth(&[3.0, 3.0]).is_none());
        assert!(silverman_bandwidth(&[3.0]).is_none());
        // The density integrates to about 1.
        let grid: Vec<f64> = (0..2000).map(|i| -5.0 + i as f64 * 0.01).collect();
        let area: f64 = kde(&v, h, &grid).iter().sum::<f64>() * 0.01;
        assert!((area - 1.0).abs() < 1e-3, "{area}");
    }

    #[test]
    fn whiskers_stop_at_the_last_point_within_the_fences() {
        let v = [1.0, 2.0, 3.0, 4.0, 100.0];
        let (q1, q3) = (quantile(&v, 0.25), quantile(&v, 0.75));
        assert_eq!(whiskers(&v, q1, q3), (1.0, 4.0));
    }

    #[test]
    fn splits_and_types_sort_conventionally() {
        let mut s = vec!["test", "zeta", "train", "val"];
        s.sort_by(|a, b| split_order(a, b));
        assert_eq!(s, ["train", "val", "test", "zeta"]);
        let mut t = vec![UNMAPPED, "wave", "kick"];
        t.sort_by(|a, b| type_order(a, b));
        assert_eq!(t, ["kick", "wave", UNMAPPED]);
    }
}
