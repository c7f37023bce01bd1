//! `clips`: a built dataset's clips from its shards alone, with filters (shared with `preview`).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;
use motionforge::dataset::{self, ClipFilter, ClipInfo};

use crate::error::UsageError;

const CLIPS_EXAMPLES: &str = "\
Examples:
  motionforge clips out/demo --type wave
  motionforge clips out/demo --kind synthetic --split train --limit 5 --json";

/// List a built dataset's clips: id, split, kind, motion type, frames and caption, from its
/// shards alone, with filters.
///
/// Every filter given must match. `--kind` takes a source kind (real_single, real_pair,
/// synthetic) or `mirrored` / `original`; `--text` is a case-insensitive substring of the id,
/// motion type, action, caption, texts or paraphrases.
#[derive(clap::Args)]
#[command(after_help = CLIPS_EXAMPLES)]
pub(crate) struct ClipsArgs {
    /// The dataset folder (`<output>/<name>`, holding data/).
    dataset: PathBuf,
    #[command(flatten)]
    filter: FilterArgs,
    /// Print a JSON array of the clips' metadata instead of a table.
    #[arg(long)]
    json: bool,
}

/// `motionforge clips`.
pub(crate) fn run(args: ClipsArgs) -> Result<ExitCode> {
    clips(&args.dataset, &args.filter, args.json)?;
    Ok(ExitCode::SUCCESS)
}

/// The clip filters shared by `clips` and `preview`.
#[derive(clap::Args, Debug, Clone, Default)]
pub(crate) struct FilterArgs {
    /// Only clips of this motion type (e.g. `walk forward`, `wave`).
    #[arg(long = "type", value_name = "TYPE")]
    pub(crate) motion_type: Option<String>,
    /// Only clips of this split (train, validation, test, or the config's own names).
    #[arg(long)]
    pub(crate) split: Option<String>,
    /// Only clips of this kind: real_single, real_pair, synthetic, mirrored or original.
    #[arg(long, value_parser = ["real_single", "real_pair", "synthetic", "mirrored", "original"])]
    pub(crate) kind: Option<String>,
    /// Only clips whose id, motion type, action, caption, texts or paraphrases contain this (any case).
    #[arg(long, value_name = "SUBSTRING")]
    pub(crate) text: Option<String>,
    /// At most this many clips (the first in shard order).
    #[arg(long)]
    pub(crate) limit: Option<usize>,
}

impl FilterArgs {
    pub(crate) fn filter(&self) -> ClipFilter {
        ClipFilter {
            motion_type: self.motion_type.clone(),
            split: self.split.clone(),
            kind: self.kind.clone(),
            text: self.text.clone(),
        }
    }
}

/// Refuses a `--type` or `--split` the dataset has no clip of, listing the ones it has: an empty
/// answer would look like a filter that matched nothing.
pub(crate) fn check_filter_values(dir: &Path, all: &[ClipInfo], args: &FilterArgs) -> Result<()> {
    let check = |what: &str, given: &Option<String>, values: Vec<&str>| -> Result<()> {
        let Some(given) = given else { return Ok(()) };
        let mut values = values;
        values.sort_unstable();
        values.dedup();
        if values.contains(&given.as_str()) {
            return Ok(());
        }
        Err(UsageError(format!(
            "{}: no clip has {what} `{given}`; its values in {} are: {}",
            if what == "motion type" {
                "--type"
            } else {
                "--split"
            },
            dir.display(),
            values.join(", ")
        ))
        .into())
    };
    check(
        "motion type",
        &args.motion_type,
        all.iter()
            .filter_map(|c| c.motion_type.as_deref())
            .collect(),
    )?;
    check(
        "split",
        &args.split,
        all.iter().map(|c| c.split.as_str()).collect(),
    )
}

/// `motionforge clips`.
fn clips(dir: &Path, args: &FilterArgs, json: bool) -> Result<()> {
    // Read once: the whole list answers both what the filters may name and what they keep.
    let mut clips = dataset::list_clips(dir)?;
    check_filter_values(dir, &clips, args)?;
    let filter = args.filter();
    clips.retain(|c| filter.matches(c));
    if let Some(n) = args.limit {
        clips.truncate(n);
    }
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    if json {
        serde_json::to_writer_pretty(&mut out, &clips)?;
        writeln!(out)?;
        out.flush()?;
        return Ok(());
    }
    let kind = |c: &ClipInfo| {
        if c.mirrored {
            format!("{} mirrored", c.source_kind)
        } else {
            c.source_kind.clone()
        }
    };
    let width = |f: &dyn Fn(&ClipInfo) -> usize, header: &str| {
        clips.iter().map(f).max().unwrap_or(0).max(header.len())
    };
    let wi = width(&|c| c.clip_id.chars().count(), "clip_id");
    let ws = width(&|c| c.split.chars().count(), "split");
    let wk = width(&|c| kind(c).len(), "kind");
    let wt = width(
        &|c| c.motion_type.as_deref().unwrap_or("-").chars().count(),
        "type",
    );
    writeln!(
        out,
        "{:wi$}  {:ws$}  {:wk$}  {:wt$}  {:>6}  text",
        "clip_id", "split", "kind", "type", "frames"
    )?;
    for c in &clips {
        writeln!(
            out,
            "{:wi$}  {:ws$}  {:wk$}  {:wt$}  {:>6}  {}",
            c.clip_id,
            c.split,
            kind(c),
            c.motion_type.as_deref().unwrap_or("-"),
            c.frames,
            c.text
        )?;
    }
    out.flush()?;
    Ok(())
}
