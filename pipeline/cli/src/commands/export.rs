//! `export humanml3d`: a built dataset in HumanML3D's layout, from its shards alone.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Subcommand;
use motionforge::motion::ProfileSpec;

use crate::ui::Ui;

/// Export a built dataset in another layout, from its shards alone (no rebuild).
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge export humanml3d out/demo"
))]
pub(crate) struct ExportArgs {
    #[command(subcommand)]
    command: ExportCommand,
}

#[derive(Subcommand)]
enum ExportCommand {
    /// A HumanML3D folder (new_joint_vecs, new_joints, joints, texts, Mean/Std, split lists)
    /// that text-to-motion, T2M-GPT, MoMask and their evaluators load as they load HumanML3D.
    ///
    /// Every row becomes SMPL's 22 body joints (by its skeleton profile's [smpl22] table), y up,
    /// 20 fps, and HumanML3D's 263 numbers per frame computed as HumanML3D computes them
    /// (docs/humanml3d.md). Mirrored rows are named M<name>, in their original's split.
    #[command(after_help = examples_then_exit_codes!(
        "  motionforge export humanml3d out/demo
  motionforge export humanml3d out/demo -o /data/HumanML3D-demo --force"
    ))]
    Humanml3d(Humanml3dArgs),
}

#[derive(clap::Args)]
struct Humanml3dArgs {
    /// The dataset folder (`<output>/<name>`, holding data/ and skeletons.json).
    #[arg(required_unless_present = "old_dataset")]
    dataset: Option<PathBuf>,
    /// The folder to write; default `<dataset>/humanml3d`.
    #[arg(long, short)]
    output: Option<PathBuf>,
    /// Deprecated spelling of the DATASET argument.
    #[arg(long = "dataset", short = 'd', hide = true, conflicts_with = "dataset")]
    old_dataset: Option<PathBuf>,
    /// Deprecated spelling of `--output`.
    #[arg(long = "out", hide = true, conflicts_with = "output")]
    old_out: Option<PathBuf>,
    /// Replace the output folder if it exists.
    #[arg(long)]
    force: bool,
    /// A skeleton profile TOML for a skeleton that is not bundled; repeatable.
    #[arg(long, value_name = "TOML")]
    profile: Vec<PathBuf>,
}

/// `motionforge export humanml3d`.
pub(crate) fn run(args: ExportArgs, ui: &Ui) -> Result<ExitCode> {
    let ExportCommand::Humanml3d(args) = args.command;
    let mut profiles = Vec::new();
    for path in args.profile {
        let text = std::fs::read_to_string(&path)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        profiles.push(ProfileSpec::from_toml(&path.display().to_string(), &text)?);
    }
    let dataset = super::deprecated(
        args.dataset,
        args.old_dataset,
        "--dataset",
        "motionforge export humanml3d <DATASET>",
    )
    .unwrap_or_default();
    let out = super::deprecated(args.output, args.old_out, "--out", "--output (-o)")
        .unwrap_or_else(|| dataset.join(motionforge::export::humanml3d::DEFAULT_DIR));
    let options = motionforge::export::ExportOptions {
        force: args.force,
        profiles,
    };
    let summary = motionforge::export::export_humanml3d(&dataset, &out, &options)?;
    if ui.json() {
        // The summary export.json records, with where it went.
        let mut value = serde_json::to_value(&summary)?;
        if let Some(object) = value.as_object_mut() {
            object.insert("output".into(), serde_json::json!(out));
        }
        crate::ui::print_json(&value)?;
    } else if ui.status() {
        let mut stdout = std::io::stdout();
        writeln!(
            stdout,
            "exported {} of {} clips ({} rows of 263) to {}",
            summary.exported,
            summary.clips,
            summary.rows,
            out.display()
        )?;
        for s in &summary.skipped {
            writeln!(stdout, "  skipped {}: {}", s.clip_id, s.reason)?;
        }
        if !summary.filtered_by_loaders.is_empty() {
            writeln!(
                stdout,
                "  {} clips are outside 40 to 199 rows: HumanML3D's loaders drop them (listed in export.json)",
                summary.filtered_by_loaders.len()
            )?;
        }
    }
    Ok(ExitCode::SUCCESS)
}
