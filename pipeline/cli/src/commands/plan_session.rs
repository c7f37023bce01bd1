//! `plan-session`: the next capture session's instructions for a scene, steered by a built
//! dataset's gaps (motionforge::planner).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use motionforge::planner::{DatasetCounts, Scene, plan, write_session};

use crate::ui::Ui;

/// Examples and exit codes of `plan-session`.
const PLAN_SESSION_HELP: &str = "\
Examples:
  # a session for the living room, balanced only within itself
  motionforge plan-session --scene schemas/scenes/living-room.toml --seed 7 -o sessions
  # steered toward what the built dataset lacks, under a name of your choice
  motionforge plan-session out/demo --scene schemas/scenes/living-room.toml --seed 8 \\
      --capture living-room-0008 -o sessions

Exit codes:
  0  success
  1  a file that cannot be read or written (the dataset's shards, the output folder)
  2  a scene that does not parse, fails its checks, or has no valid session";

/// Plan the next capture session for a scene: the instructions an actor performs, as an
/// event log to time during the capture and a sheet for the operator.
///
/// A Markov chain over the scene's interactions (LINGO's Motion Planner) emits only
/// instructions whose requirements hold (posture, place, free or holding hands) and ends in
/// the scene's end state. Given a DATASET, it favours the motion types the built dataset has
/// fewest clips of, toward the scene's target (docs/planner.md). The same scene, dataset and
/// seed give the same session.
#[derive(clap::Args)]
#[command(after_help = PLAN_SESSION_HELP)]
pub(crate) struct PlanSessionArgs {
    /// A built dataset folder (`<output>/<name>`) whose clips per motion type to balance.
    dataset: Option<PathBuf>,
    /// The scene file (TOML; schemas/scene.md, schemas/scenes/living-room.toml).
    #[arg(long)]
    scene: PathBuf,
    /// Deprecated spelling of the DATASET argument.
    #[arg(long = "dataset", hide = true, conflicts_with = "dataset")]
    old_dataset: Option<PathBuf>,
    /// Seed of the chain.
    #[arg(long)]
    seed: u64,
    /// Folder to write `<capture>.csv` (the event log) and `<capture>.md` (the sheet) into.
    #[arg(long, short, default_value = ".")]
    output: PathBuf,
    /// The capture's name, and so the files' stem; default `<scene name>-<seed>`.
    #[arg(long, value_parser = parse_capture)]
    capture: Option<String>,
}

/// `--capture` values: letters, digits, `-`, `_` and `.` only (not first), so the name is a
/// file stem on any system and the event log's capture key.
fn parse_capture(name: &str) -> Result<String, String> {
    let ok = !name.is_empty()
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'));
    if ok {
        Ok(name.to_string())
    } else {
        Err(
            "expected letters, digits, `-`, `_` or `.` (it names the capture file and the log)"
                .into(),
        )
    }
}

/// `motionforge plan-session`.
pub(crate) fn run(args: PlanSessionArgs, ui: &Ui) -> Result<ExitCode> {
    let (json, status) = (ui.json(), ui.status());
    let dataset = super::deprecated(
        args.dataset,
        args.old_dataset,
        "--dataset",
        "motionforge plan-session <DATASET>",
    );
    let scene = Scene::load(&args.scene)?;
    let counts = match &dataset {
        Some(dir) => DatasetCounts::read(dir)
            .with_context(|| format!("reading the dataset {}", dir.display()))?,
        None => DatasetCounts::default(),
    };
    let session = plan(&scene, &counts, args.seed)
        .with_context(|| format!("scene {}", args.scene.display()))?;
    let capture = args
        .capture
        .unwrap_or_else(|| format!("{}-{}", slug(&scene.name), args.seed));
    let written = write_session(&session, &scene, &args.output, &capture)?;
    let (before, after) = session.kl();
    let mut out = std::io::stdout().lock();
    if json {
        let value = serde_json::json!({
            "scene": scene.name,
            "seed": args.seed,
            "capture": capture,
            "event_log": written.event_log,
            "sheet": written.sheet,
            "instructions": session.steps.len(),
            "seconds": (session.seconds() * 1000.0).round() / 1000.0,
            "session_counts": session.session_counts,
            "dataset_counts": session.dataset_counts,
            "kl_before": before,
            "kl_after": after,
            "never_possible": session.unreachable,
        });
        crate::ui::print_json(&value)?;
    } else if status {
        writeln!(
            out,
            "planned {} instructions (about {:.0} s) for scene `{}`, seed {}",
            session.steps.len(),
            session.seconds(),
            scene.name,
            args.seed
        )?;
        match (before, after) {
            (Some(b), Some(a)) => writeln!(
                out,
                "KL to the target: {b:.4} in {} -> {a:.4} with this session",
                show(dataset.as_deref())
            )?,
            (None, Some(a)) => writeln!(out, "KL of the session alone to the target: {a:.4}")?,
            _ => {}
        }
        for note in &session.unreachable {
            writeln!(out, "note: {note}")?;
        }
        writeln!(
            out,
            "wrote {} (fill in the times) and {}",
            written.event_log.display(),
            written.sheet.display()
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

fn show(dataset: Option<&Path>) -> String {
    dataset.map_or_else(String::new, |d| d.display().to_string())
}

/// A scene name as a file-name stem: lowercase, runs of other characters as one `-`.
fn slug(name: &str) -> String {
    let mut s = String::new();
    for c in name.chars() {
        if c.is_ascii_alphanumeric() {
            s.push(c.to_ascii_lowercase());
        } else if !s.ends_with('-') && !s.is_empty() {
            s.push('-');
        }
    }
    let s = s.trim_end_matches('-').to_string();
    if s.is_empty() { "session".into() } else { s }
}
