//! Commands that read a built dataset folder alone: clips, export-bvh from the shards, preview.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use motionforge::base::guard::{Kept, check_replaceable};
use motionforge::dataset::preview::{self, Panel, PreviewOptions};
use motionforge::dataset::{self, ClipFilter, ClipInfo, Companions};

use crate::Ui;

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
fn check_filter_values(dir: &Path, all: &[ClipInfo], args: &FilterArgs) -> Result<()> {
    let check = |what: &str, given: &Option<String>, values: Vec<&str>| -> Result<()> {
        let Some(given) = given else { return Ok(()) };
        let mut values = values;
        values.sort_unstable();
        values.dedup();
        if values.contains(&given.as_str()) {
            return Ok(());
        }
        Err(crate::cli::UsageError(format!(
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
pub(crate) fn clips(dir: &Path, args: &FilterArgs, json: bool) -> Result<()> {
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

/// `motionforge export-bvh <dataset> --clip <id>`.
pub(crate) fn export_bvh_from_shards(
    dir: &Path,
    clip_id: &str,
    output: Option<PathBuf>,
    ui: &Ui,
) -> Result<()> {
    let frames = dataset::read_clip(dir, clip_id)?;
    let skeletons = dataset::read_skeletons(dir)?;
    let entry = skeletons.get(&frames.info.skeleton).with_context(|| {
        format!(
            "clip `{clip_id}`: skeleton `{}` is not in {}",
            frames.info.skeleton,
            dir.join(motionforge::base::layout::SKELETONS_FILE)
                .display()
        )
    })?;
    let motion = dataset::skeletons::clip_motion(&frames, entry)
        .map_err(|e| anyhow::anyhow!("clip `{clip_id}`: {e}"))?;
    let text =
        motionforge::motion::write_bvh(&motion).with_context(|| format!("clip `{clip_id}`"))?;
    let path = output.unwrap_or_else(|| default_bvh_path(clip_id));
    motionforge::base::write_atomic(&path, text.as_bytes())?;
    say_bvh_written(&path, &motion, &frames.info.skeleton, ui)
}

/// Where `export-bvh` writes without `-o`: the clip id as a plain file name, in the working folder.
pub(crate) fn default_bvh_path(clip_id: &str) -> PathBuf {
    PathBuf::from(format!("{}.bvh", preview::file_stem(clip_id)))
}

/// What `export-bvh` wrote: a line, or with `--json` an object on standard output.
pub(crate) fn say_bvh_written(
    path: &Path,
    motion: &motionforge::motion::Motion,
    skeleton: &str,
    ui: &Ui,
) -> Result<()> {
    let mut out = std::io::stdout();
    if ui.log.json {
        let value = serde_json::json!({
            "path": path,
            "frames": motion.num_frames(),
            "fps": motion.fps,
            "skeleton": skeleton,
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
    } else if ui.status() {
        writeln!(
            out,
            "wrote {} ({} frames at {} fps, skeleton {skeleton})",
            path.display(),
            motion.num_frames(),
            motion.fps,
        )?;
    }
    Ok(())
}

/// `preview --with`.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum WithArg {
    /// The clip alone.
    None,
    /// The clip and its mirror (or a mirror and its original).
    Mirror,
    /// A synthetic pair and its two sources.
    Sources,
}

/// `motionforge preview`.
pub(crate) fn preview(
    dir: &Path,
    ids: &[String],
    args: &FilterArgs,
    with: WithArg,
    output: &Path,
    options: &PreviewOptions,
    ui: &Ui,
) -> Result<()> {
    let clips = dataset::list_clips(dir)?;
    check_filter_values(dir, &clips, args)?;
    let filter = args.filter();
    let mut chosen: Vec<&ClipInfo> = if ids.is_empty() {
        clips.iter().filter(|c| filter.matches(c)).collect()
    } else {
        let mut v = Vec::new();
        for id in ids {
            match clips.iter().find(|c| &c.clip_id == id) {
                Some(c) => v.push(c),
                None => {
                    let all: Vec<String> = clips.iter().map(|c| c.clip_id.clone()).collect();
                    return Err(dataset::DatasetError::NoClip {
                        path: dir.to_path_buf(),
                        clip_id: id.clone(),
                        count: all.len(),
                        hint: dataset::near_clip_ids(id, &all),
                    }
                    .into());
                }
            }
        }
        v
    };
    if let Some(n) = args.limit {
        chosen.truncate(n);
    }
    let with = match with {
        WithArg::None => Companions::None,
        WithArg::Mirror => Companions::Mirror,
        WithArg::Sources => Companions::Sources,
    };
    let kept = Kept::working_folder().and(dir, "the dataset folder it previews", &[]);
    check_replaceable(output, &kept, "pass another --output")?;
    let skeletons = dataset::read_skeletons(dir)?;
    let mut out = std::io::stdout().lock();
    for clip in chosen {
        let mut rows = vec![dataset::read_clip_in(dir, &clips, &clip.clip_id)?];
        for id in dataset::companion_ids(clip, with, &clips) {
            rows.push(dataset::read_clip_in(dir, &clips, &id)?);
        }
        let panels = rows
            .iter()
            .map(|r| {
                skeletons
                    .get(&r.info.skeleton)
                    .map(|skeleton| Panel {
                        frames: r,
                        skeleton,
                    })
                    .with_context(|| {
                        format!(
                            "clip `{}`: skeleton `{}` is not in skeletons.json",
                            r.info.clip_id, r.info.skeleton
                        )
                    })
            })
            .collect::<Result<Vec<_>>>()?;
        // A pair's sources may walk far while the pair stays put: each fits its own panel.
        let scaling = match with {
            Companions::Sources => preview::PanelScale::Own,
            _ => preview::PanelScale::Shared,
        };
        let rendered = preview::render_scaled(&panels, options, scaling)?;
        let [gif, png] =
            preview::write_preview(&rendered, output, &preview::file_stem(&clip.clip_id))?;
        if ui.status() {
            writeln!(
                out,
                "wrote {} ({} frames at {} fps) and {}",
                gif.display(),
                rendered.frames.len(),
                rendered.fps,
                png.display()
            )?;
        }
    }
    Ok(())
}

/// `bench --previews <dataset>`: GIF and filmstrip of the first 100 original clips, one thread.
pub(crate) fn bench_previews(dir: &Path) -> Result<()> {
    let clips = dataset::list_clips(dir)?;
    let skeletons = dataset::read_skeletons(dir)?;
    let chosen: Vec<&ClipInfo> = clips.iter().filter(|c| !c.mirrored).take(100).collect();
    let work = tempfile_dir()?;
    let options = PreviewOptions::default();
    let start = std::time::Instant::now();
    let (mut frames, mut bytes) = (0usize, 0u64);
    for clip in &chosen {
        let row = dataset::read_clip_in(dir, &clips, &clip.clip_id)?;
        let skeleton = skeletons
            .get(&row.info.skeleton)
            .with_context(|| format!("skeleton `{}` not in skeletons.json", row.info.skeleton))?;
        let drawn = preview::render(
            &[Panel {
                frames: &row,
                skeleton,
            }],
            &options,
        )?;
        frames += drawn.frames.len();
        let [gif, png] = preview::write_preview(&drawn, &work, &preview::file_stem(&clip.clip_id))?;
        bytes += std::fs::metadata(gif)?.len() + std::fs::metadata(png)?.len();
    }
    let seconds = start.elapsed().as_secs_f64();
    let _ = std::fs::remove_dir_all(&work);
    writeln!(
        std::io::stdout(),
        "{} previews ({} GIF frames at {} fps, {} px, filmstrips of {}), {:.1} MB, one thread: {:.2} s, {:.1} previews/s",
        chosen.len(),
        frames,
        options.fps,
        options.size,
        options.strip_frames,
        bytes as f64 / 1e6,
        seconds,
        chosen.len() as f64 / seconds
    )?;
    Ok(())
}

fn tempfile_dir() -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("motionforge-previews-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    Ok(dir)
}
