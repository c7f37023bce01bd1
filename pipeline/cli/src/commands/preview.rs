//! `preview`: clips drawn as animated stick figures from a built dataset's shards alone.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use motionforge::base::guard::{Kept, check_replaceable};
use motionforge::dataset::preview::{self, Panel, PreviewOptions};
use motionforge::dataset::{self, ClipInfo, Companions};

use super::clips::{FilterArgs, check_filter_values};
use crate::ui::Ui;

const PREVIEW_EXAMPLES: &str = "\
Examples:
  motionforge preview out/demo --clip 'cmu/01_01:1207-2407' --with mirror
  motionforge preview out/demo --kind synthetic --limit 3 --with sources -o /tmp/pairs";

/// Render clips as animated stick figures from a built dataset's shards alone: an animated
/// GIF and a PNG filmstrip per clip, optionally beside its mirror or a synthetic pair's sources.
///
/// Each clip is drawn in its canonical frame (first frame's pelvis at the origin, facing +y)
/// by a fixed camera in front of the character, 20 degrees above, over a half-metre ground
/// grid; bones are coloured by body part (left arm blue, left leg teal, right arm red, right
/// leg orange, torso dark grey), the pelvis goal is a purple cross, and the caption and clip id
/// are the title. Files: `<output>/<clip id with / : + as _>.gif` and `.png`.
#[derive(clap::Args)]
#[command(after_help = PREVIEW_EXAMPLES)]
pub(crate) struct PreviewArgs {
    /// The dataset folder (`<output>/<name>`, holding data/ and skeletons.json).
    dataset: PathBuf,
    /// A clip id (repeat for several); without it, every clip the filters keep.
    #[arg(long)]
    clip: Vec<String>,
    #[command(flatten)]
    filter: FilterArgs,
    /// Draw beside each clip: its mirror (`mirror`) or a synthetic pair's two sources
    /// (`sources`).
    #[arg(long, value_enum, default_value = "none")]
    with: WithArg,
    /// Folder to write the previews into.
    #[arg(long, short, default_value = "previews")]
    output: PathBuf,
    /// Frames per second of the GIF (the clip is resampled to it).
    #[arg(long, default_value_t = 20.0)]
    fps: f64,
    /// Size in pixels of one clip's square drawing.
    #[arg(long, default_value_t = 280)]
    size: u32,
    /// Poses in the filmstrip.
    #[arg(long, default_value_t = 8)]
    strip: usize,
}

/// `motionforge preview`.
pub(crate) fn run(args: PreviewArgs, ui: &Ui) -> Result<ExitCode> {
    let options = PreviewOptions {
        fps: args.fps,
        size: args.size,
        strip_frames: args.strip,
        animate: true,
    };
    preview(
        &args.dataset,
        &args.clip,
        &args.filter,
        args.with,
        &args.output,
        &options,
        ui,
    )?;
    Ok(ExitCode::SUCCESS)
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

/// The previews of the clips chosen by id or by the filters.
fn preview(
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
    let mut written = Vec::new();
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
        if ui.json() {
            written.push(serde_json::json!({
                "clip_id": clip.clip_id,
                "panels": rows.iter().map(|r| &r.info.clip_id).collect::<Vec<_>>(),
                "gif": gif,
                "png": png,
                "frames": rendered.frames.len(),
                "fps": rendered.fps,
            }));
        } else if ui.status() {
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
    if ui.json() {
        let value = serde_json::json!({ "output": output, "previews": written });
        crate::ui::print_json(&value)?;
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
