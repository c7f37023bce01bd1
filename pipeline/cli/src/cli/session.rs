//! `plan-session`: the next capture session's instructions for a scene, steered by a built
//! dataset's gaps (motionforge::planner).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use motionforge::planner::{DatasetCounts, Scene, plan, write_session};

/// What `plan-session` was asked for.
pub(crate) struct PlanSessionArgs {
    pub scene: PathBuf,
    pub dataset: Option<PathBuf>,
    pub seed: u64,
    pub output: PathBuf,
    pub capture: Option<String>,
}

/// `--capture` values: letters, digits, `-`, `_` and `.` only (not first), so the name is a
/// file stem on any system and the event log's capture key.
pub(crate) fn parse_capture(name: &str) -> Result<String, String> {
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

pub(crate) fn plan_session(args: PlanSessionArgs, json: bool, status: bool) -> Result<()> {
    let scene = Scene::load(&args.scene)?;
    let counts = match &args.dataset {
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
        writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
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
                show(args.dataset.as_deref())
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
    Ok(())
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
