//! Dataset statistics for papers: the numbers and figures of LINGO's appendix B.2 (occurrences per
//! motion type, motion-length violins, locomotion goal locations), LAMA's Table 3 (per-category
//! length range, count and total frames) and SINC's figure A.4 (training-set composition), plus
//! label sources, plausibility of real versus synthetic clips, and drop/reject counts.
//!
//! [`read_rows`] reads the few columns needed from clip tables, [`statistics`] reduces them to a
//! serialisable [`Stats`], and [`write_report`] writes `stats.json`, `tables.tex` (booktabs),
//! `figures.tex`, `report.md` and `figures/*.svg`, `*.pdf` and `*.png` into a folder. The same
//! rows always give the same bytes: categories are sorted, floats have fixed formatting, nothing
//! records the time.
//!
//! # A clip's way through this crate
//!
//! Step 6: the clip's row, read back from the shards, is counted in its motion type, length,
//! goals, label source and plausibility. Principal types: [`Stats`], [`ReportInput`].

mod figures;
mod gallery;
mod read;
mod stats;
mod tables;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use figures::{DPI, FIGURES, FigureSpec, MIN_VIOLIN, Span, violin_outline};
pub use read::{find_clip_tables, read_build_counts, read_rows};
pub use stats::{
    GoalStats, KNOWN_KINDS, KindCount, METRICS, MetricInfo, MetricStats, NO_LABEL, NO_SPLIT,
    NULL_SPLIT, Overview, SplitComposition, Stats, Summary, TextStats, TypeStats, UNMAPPED,
    lengths_by_type, quantile, silverman_bandwidth, statistics,
};
pub use tables::{latex_escape, markdown_escape};

use motionforge_core::base::WorkspaceError;
use motionforge_core::base::guard::{Kept, check_replaceable};

/// What a report is made from besides the clip rows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReportInput {
    /// Parquet clip tables the rows were read from (only their file names reach the report, so
    /// the output does not depend on where the dataset lies).
    pub tables: Vec<PathBuf>,
    /// Segments dropped by the build, by reason (`drops_by_reason` of `build-report.json`).
    pub drops: BTreeMap<String, usize>,
    /// Items rejected by the build, by reason (`rejects_by_reason` of `build-report.json`).
    pub rejects: BTreeMap<String, usize>,
    /// Title of the report and of its figures, usually the dataset name.
    pub title: String,
    /// Clips whose text contradicts their motion (the manifest's `label_contradictions`).
    pub contradictions: Vec<motionforge_core::quality::Contradiction>,
}

/// One clip, reduced to what the statistics need.
#[derive(Debug, Clone, PartialEq)]
pub struct ClipRow {
    /// `clip_id` column.
    pub clip_id: String,
    /// `split` column; [`NO_SPLIT`] (`"all"`) when the table has no such column, `"(none)"` for a
    /// null value.
    pub split: String,
    /// `source_kind` column: `real_single`, `real_pair` or `synthetic`.
    pub source_kind: String,
    /// `mirrored` column.
    pub mirrored: bool,
    /// `motion_type` column (null for pairs, synthetic clips and unmapped labels).
    pub motion_type: Option<String>,
    /// Length in seconds: `num_frames / fps`.
    pub seconds: f64,
    /// `num_frames` column.
    pub frames: usize,
    /// `goal_pelvis` column: `[x, y]` metres in the first-frame canonical frame.
    pub goal_pelvis: Option<[f32; 2]>,
    /// `label_source` column.
    pub label_source: Option<String>,
    /// `texts` column: every caption of the clip (empty when the table has no such column).
    pub texts: Vec<String>,
    /// `[foot_skate, ground_penetration, self_distance, lean]` (m/s, m, m, degrees); `None` when
    /// all four are null or the table has none of these columns. A single null metric is NaN.
    pub plausibility: Option<[f32; 4]>,
}

impl ClipRow {
    /// True for rows counted as originals: everything but mirrored copies.
    pub fn is_original(&self) -> bool {
        !self.mirrored
    }

    /// True for synthetic compositions (`source_kind == "synthetic"`).
    pub fn is_synthetic(&self) -> bool {
        self.source_kind == motionforge_sources::clip::SourceKind::Synthetic.as_str()
    }
}

/// Why a row's value cannot be used by the statistics.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValueProblem {
    /// A required column is null.
    #[error("`{0}` is null")]
    Null(&'static str),
    /// The frame rate is not a positive number.
    #[error("`fps` is {0}, not a positive rate")]
    Fps(f64),
    /// The frame count is negative (or beyond what the platform counts).
    #[error("`num_frames` is {0}")]
    Frames(i64),
    /// The goal is not two numbers.
    #[error("`goal_pelvis` has {0} values, expected [x, y]")]
    Goal(usize),
}

/// Why a figure (or the gallery) could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum FigureProblem {
    /// The plotting library failed.
    #[error("{0}")]
    Plot(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// The drawn SVG lacks the size attributes its printed size replaces.
    #[error("the SVG has no `{0}` to give its printed size")]
    NoSize(String),
    /// The SVG does not read back.
    #[error("{0}")]
    Svg(#[source] svg2pdf::usvg::Error),
    /// The PDF could not be made (svg2pdf's error is `Display` but not `std::error::Error`).
    #[error("{0}")]
    Pdf(svg2pdf::ConversionError),
    /// The raster image could not be allocated.
    #[error("cannot make a {0} x {1} image")]
    Canvas(u32, u32),
    /// Reading the dataset, drawing a preview or encoding a PNG failed.
    #[error("{0}")]
    Dataset(#[from] motionforge_format::dataset::DatasetError),
    /// The dataset's `skeletons.json` cannot be read.
    #[error("{0}")]
    Skeletons(#[from] motionforge_format::io::skeletons::SkeletonsError),
    /// A clip's skeleton is not in `skeletons.json`.
    #[error("skeleton `{skeleton}` of `{clip_id}` is not in skeletons.json")]
    NoSkeleton {
        /// The skeleton's id.
        skeleton: String,
        /// The clip.
        clip_id: String,
    },
}

/// Errors of reading tables and writing a report; each names the file involved.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The dataset's `manifest.json` cannot be read.
    #[error(transparent)]
    Manifest(#[from] motionforge_format::io::manifest::ManifestError),
    /// A file or folder could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A clip table cannot be found, opened or decoded, or lacks a column the report needs.
    #[error(transparent)]
    Dataset(#[from] motionforge_format::dataset::DatasetError),
    /// A value that the statistics cannot use.
    #[error("{path}: row {row} ({clip_id}): {problem}")]
    InvalidValue {
        /// The table.
        path: PathBuf,
        /// Row index in the table, from 0.
        row: usize,
        /// The row's clip id, when it could be read.
        clip_id: String,
        /// What is wrong.
        problem: ValueProblem,
    },
    /// A JSON file (the build report) could not be parsed.
    #[error("{path}: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: serde_json::Error,
    },
    /// A count of the build report (`drops_by_reason`...) is not a map from name to count.
    #[error("{path}: `{key}`: {source}")]
    Counts {
        /// The build report.
        path: PathBuf,
        /// The key of the counts.
        key: &'static str,
        /// The reader's error.
        source: serde_json::Error,
    },
    /// `stats.json` could not be encoded.
    #[error("{path}: {source}")]
    Encode {
        /// The file.
        path: PathBuf,
        /// The encoder's error.
        source: serde_json::Error,
    },
    /// A figure could not be drawn.
    #[error("figure {figure}: {problem}")]
    Figure {
        /// The figure's file stem (`gallery` for the gallery).
        figure: String,
        /// What failed (boxed: a dataset error is large, and this is the rare case).
        problem: Box<FigureProblem>,
    },
    /// The bundled font could not be registered with the plotting library.
    #[error("the bundled font could not be loaded")]
    Font,
    /// An output file could not be written.
    #[error(transparent)]
    Write(#[from] WorkspaceError),
    /// The output folder is, holds or lies inside a folder the report must keep.
    #[error(transparent)]
    Refused(#[from] motionforge_core::base::guard::Refused),
}

/// Writes the report of `rows` and `stats` into `out_dir` (created if needed): `stats.json`,
/// `tables.tex`, `figures.tex`, `report.md` and, under `figures/`, an SVG, a PDF and a PNG of
/// every figure in [`FIGURES`]. Every file is written atomically (temporary file in the same folder, then rename).
/// Returns the written paths in a fixed order.
pub fn write_report(
    rows: &[ClipRow],
    stats: &Stats,
    out_dir: &Path,
) -> Result<Vec<PathBuf>, ReportError> {
    write_report_with(rows, stats, out_dir, None)
}

/// [`write_report`], with the gallery of the dataset folder `gallery_of` when given.
fn write_report_with(
    rows: &[ClipRow],
    stats: &Stats,
    out_dir: &Path,
    gallery_of: Option<&Path>,
) -> Result<Vec<PathBuf>, ReportError> {
    let mut written = Vec::new();
    let rows = stats::sorted_rows(rows);

    let tex_path = out_dir.join("tables.tex");
    motionforge_core::base::write_atomic(&tex_path, tables::latex(stats).as_bytes())?;
    written.push(tex_path);

    let figures_tex = out_dir.join("figures.tex");
    motionforge_core::base::write_atomic(&figures_tex, tables::latex_figures(stats).as_bytes())?;
    written.push(figures_tex);

    let figure_dir = out_dir.join("figures");
    written.extend(figures::write_figures(&rows, stats, &figure_dir)?);

    let mut markdown = tables::markdown(stats);
    if let Some(dataset) = gallery_of {
        let (files, section) = gallery::write_gallery(dataset, &rows, out_dir)?;
        written.extend(files);
        markdown.push_str(&section);
    }
    let md_path = out_dir.join("report.md");
    motionforge_core::base::write_atomic(&md_path, markdown.as_bytes())?;
    written.push(md_path);

    // Last, so a report cut short by a crash has no `stats.json` and does not look finished.
    let json_path = out_dir.join("stats.json");
    let mut json = serde_json::to_string_pretty(stats).map_err(|source| ReportError::Encode {
        path: json_path.clone(),
        source,
    })?;
    json.push('\n');
    motionforge_core::base::write_atomic(&json_path, json.as_bytes())?;
    written.insert(0, json_path);
    Ok(written)
}

/// The report of a built dataset folder, from its shards (`data/`) and `manifest.json` alone,
/// written to `out_dir` (default `<dataset>/report`). Returns the files written.
pub fn report_dataset(dataset: &Path, out_dir: Option<&Path>) -> Result<Vec<PathBuf>, ReportError> {
    if let Some(out) = out_dir {
        let kept =
            Kept::working_folder().and(dataset, "the dataset folder it reports on", &["report"]);
        check_replaceable(out, &kept, "pass another --output")?;
    }
    // Without a manifest (a folder of shards from elsewhere) the counts are empty.
    let manifest = motionforge_format::io::manifest::Manifest::read(dataset)?;
    let counts = manifest
        .as_ref()
        .map(|m| m.counts.clone())
        .unwrap_or_default();
    let contradictions = manifest
        .as_ref()
        .map(|m| m.label_contradictions.clone())
        .unwrap_or_default();
    let tables = find_clip_tables(&dataset.join(motionforge_core::base::layout::DATA_DIR))?;
    let title = manifest.map(|m| m.dataset).unwrap_or_else(|| {
        dataset
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    });
    let input = ReportInput {
        tables,
        drops: counts.drop_reason.to_names(),
        rejects: counts.reject_reason.to_names(),
        title,
        contradictions,
    };
    let rows = read_rows(&input.tables)?;
    let stats = statistics(&rows, &input);
    let out = out_dir
        .map(Path::to_path_buf)
        .unwrap_or_else(|| dataset.join("report"));
    write_report_with(&rows, &stats, &out, Some(dataset))
}
