//! `clips`: a built dataset's clips from its shards alone, with filters (shared with `preview`).

use std::io::{IsTerminal, Write};
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
    /// Print whole ids and captions however wide the table gets. Without it, on a terminal, long
    /// ids are cut in the middle (`…`) and captions at the end so each line fits the terminal's
    /// width (COLUMNS, else the terminal's own, else 100); piped output is never cut.
    #[arg(long)]
    wide: bool,
}

/// `motionforge clips`.
pub(crate) fn run(args: ClipsArgs) -> Result<ExitCode> {
    let width = (!args.wide && !args.json && std::io::stdout().is_terminal()).then(terminal_width);
    clips(&args.dataset, &args.filter, args.json, width)?;
    Ok(ExitCode::SUCCESS)
}

/// Columns of the terminal on standard output: `COLUMNS` when set to a number, else the
/// terminal's own width, else 100.
fn terminal_width() -> usize {
    if let Some(columns) = std::env::var("COLUMNS")
        .ok()
        .and_then(|c| c.trim().parse::<usize>().ok())
        .filter(|c| *c > 0)
    {
        return columns;
    }
    // SAFETY: TIOCGWINSZ fills the `winsize` it is given and reads nothing else; a failure leaves
    // it zeroed.
    let mut size: libc::winsize = unsafe { std::mem::zeroed() };
    let ok = unsafe { libc::ioctl(libc::STDOUT_FILENO, libc::TIOCGWINSZ, &mut size) } == 0;
    if ok && size.ws_col > 0 {
        usize::from(size.ws_col)
    } else {
        100
    }
}

/// `text` in at most `width` characters: cut in the middle with `…`, keeping its start and end
/// (where clip ids differ: the capture, the frames, a mirror's `:m`).
fn cut_middle(text: &str, width: usize) -> String {
    let n = text.chars().count();
    if n <= width {
        return text.to_string();
    }
    let keep = width.saturating_sub(1);
    let head = keep.div_ceil(2);
    let tail = keep - head;
    let start: String = text.chars().take(head).collect();
    let end: String = text.chars().skip(n - tail).collect();
    format!("{start}…{end}")
}

/// `text` in at most `width` characters: cut at the end with `…`.
fn cut_end(text: &str, width: usize) -> String {
    if text.chars().count() <= width {
        return text.to_string();
    }
    let start: String = text.chars().take(width.saturating_sub(1)).collect();
    format!("{start}…")
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

/// `motionforge clips`: the table cut to `width` columns when given.
fn clips(dir: &Path, args: &FilterArgs, json: bool, width: Option<usize>) -> Result<()> {
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
    let widest = |f: &dyn Fn(&ClipInfo) -> usize, header: &str| {
        clips.iter().map(f).max().unwrap_or(0).max(header.len())
    };
    let mut wi = widest(&|c| c.clip_id.chars().count(), "clip_id");
    let ws = widest(&|c| c.split.chars().count(), "split");
    let wk = widest(&|c| kind(c).len(), "kind");
    let wt = widest(
        &|c| c.motion_type.as_deref().unwrap_or("-").chars().count(),
        "type",
    );
    // Split, kind, type and frames with their separators, and the separator before the text.
    let fixed = 2 + ws + 2 + wk + 2 + wt + 2 + 6 + 2;
    let text_width = width.map(|columns| {
        // The id gives way first, down to a readable start and end; the caption takes the rest.
        wi = wi.min(columns.saturating_sub(fixed + MIN_TEXT).max(MIN_ID));
        columns.saturating_sub(wi + fixed).max(1)
    });
    writeln!(
        out,
        "{:wi$}  {:ws$}  {:wk$}  {:wt$}  {:>6}  text",
        "clip_id", "split", "kind", "type", "frames"
    )?;
    for c in &clips {
        let (id, text) = match text_width {
            Some(tw) => (cut_middle(&c.clip_id, wi), cut_end(&c.text, tw)),
            None => (c.clip_id.clone(), c.text.clone()),
        };
        writeln!(
            out,
            "{id:wi$}  {:ws$}  {:wk$}  {:wt$}  {:>6}  {text}",
            c.split,
            kind(c),
            c.motion_type.as_deref().unwrap_or("-"),
            c.frames,
        )?;
    }
    out.flush()?;
    Ok(())
}

/// Columns a cut id keeps at least (its start and end), however narrow the terminal.
const MIN_ID: usize = 24;
/// Columns the caption keeps before ids are cut further.
const MIN_TEXT: usize = 24;
