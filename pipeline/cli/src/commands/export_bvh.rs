//! `export-bvh`: one clip as a BVH file on its source skeleton, from a dataset folder's shards or
//! by re-running a build's stages.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use motionforge::build::BuildOptions;
use motionforge::config::DEFAULT_CONFIG;
use motionforge::dataset::{self, preview};

use super::{load_checked, parse_wait};
use crate::ui::Ui;

const EXPORT_BVH_EXAMPLES: &str = "\
Examples:
  motionforge export-bvh out/demo --clip 'cmu/01_01:1207-2407:m' -o jump-mirrored.bvh
  motionforge export-bvh --config fixtures/demo.toml --clip 'cmu/01_01:1207-2407'";

/// Write one clip (real, mirrored or synthetic) as a BVH file on its source skeleton, for
/// inspection in Blender: from a built dataset folder alone (shards and skeletons.json), or
/// with --config by re-running the build's stages from the captures.
///
/// Both routes write the clip as the dataset stores it (its f32 rotations), so they give the
/// same file (docs/decisions.md).
#[derive(clap::Args)]
#[command(after_help = EXPORT_BVH_EXAMPLES)]
pub(crate) struct ExportBvhArgs {
    /// The dataset folder (`<output>/<name>`, holding data/ and skeletons.json).
    #[arg(conflicts_with = "config")]
    dataset: Option<PathBuf>,
    /// Instead of a dataset folder: the build configuration; stages reuse their cached
    /// outputs (default motionforge.toml when no dataset folder is given).
    #[arg(long, short)]
    config: Option<PathBuf>,
    /// The clip id, as in the table's `clip_id` column.
    #[arg(long)]
    clip: String,
    /// Output file; default `<clip id with / and : replaced>.bvh` in the working folder.
    #[arg(long, short)]
    output: Option<PathBuf>,
    /// Send no LLM request while re-running stages.
    #[arg(long)]
    offline: bool,
    /// When a build holds the dataset folder (whose stage cache this reads and refreshes),
    /// wait this long for it (30s, 5m, 1h).
    #[arg(long, value_name = "DURATION", value_parser = parse_wait)]
    wait: Option<Duration>,
}

/// `motionforge export-bvh`.
pub(crate) fn run(args: ExportBvhArgs, ui: &Ui) -> Result<ExitCode> {
    match args.dataset {
        Some(dataset) => from_shards(&dataset, &args.clip, args.output, ui)?,
        None => {
            let config = args.config.unwrap_or_else(|| PathBuf::from(DEFAULT_CONFIG));
            from_config(
                &config,
                &args.clip,
                args.output,
                args.offline,
                args.wait,
                ui,
            )?
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `motionforge export-bvh <dataset> --clip <id>`.
fn from_shards(dir: &Path, clip_id: &str, output: Option<PathBuf>, ui: &Ui) -> Result<()> {
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
        crate::ui::print_json(&value)?;
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

/// `motionforge export-bvh --config <config> --clip <id>`: the clip from the build's stages.
fn from_config(
    path: &Path,
    clip_id: &str,
    output: Option<PathBuf>,
    offline: bool,
    wait: Option<Duration>,
    ui: &Ui,
) -> Result<()> {
    let config = load_checked(path, None)?;
    // The stages read and refresh the dataset's stage cache, which a running build is writing.
    let _lock = motionforge::build::lock::WorkspaceLock::acquire(&config.dataset_dir(), wait)?;
    let (found, ids) = motionforge::build::find_clip(
        &config,
        &BuildOptions {
            offline,
            ..BuildOptions::default()
        },
        clip_id,
    )?;
    let Some((clip, profile)) = found else {
        let hint = motionforge::dataset::near_clip_ids(clip_id, &ids);
        bail!(
            "no clip `{clip_id}` in this build ({} clips){hint}",
            ids.len()
        );
    };
    // The clip as the dataset stores it, so this route and `export-bvh <dataset>` write the same
    // file.
    let motion = motionforge::build::stored_motion(&clip, &profile);
    let text =
        motionforge::motion::write_bvh(&motion).with_context(|| format!("clip `{clip_id}`"))?;
    let path = output.unwrap_or_else(|| default_bvh_path(clip_id));
    motionforge::build::write_atomic(&path, text.as_bytes())?;
    say_bvh_written(&path, &clip.motion, &clip.clip.profile, ui)
}
