//! `clean`: remove what a build wrote, or only its stage cache.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Result;
use motionforge::config::{Config, DEFAULT_CONFIG};

use super::parse_wait;
use crate::ui::Ui;

/// Remove a built dataset's outputs (shards, card, manifest, report, stage cache), or with
/// --cache-only only its stage cache.
///
/// Only what a build writes is removed, and only inside `<output>/<name>`; the LLM response
/// cache and files you put there are kept. Takes the dataset folder's lock, like a build.
#[derive(clap::Args)]
#[command(after_help = examples_then_exit_codes!(
    "  motionforge clean out/demo
  motionforge clean out/demo --cache-only
  motionforge clean --config fixtures/demo.toml"
))]
pub(crate) struct CleanArgs {
    /// The dataset folder (`<output>/<name>`), instead of the one a config names.
    dataset: Option<PathBuf>,
    /// Build configuration naming the dataset folder.
    #[arg(long, short, default_value = DEFAULT_CONFIG, conflicts_with = "dataset")]
    config: PathBuf,
    /// The output folder the dataset was built into with `build --output`.
    #[arg(long, short, conflicts_with = "dataset")]
    output: Option<PathBuf>,
    /// Remove only the stage cache (`.motionforge/cache`); the next build recomputes every
    /// stage but rewrites no output that would be identical.
    #[arg(long)]
    cache_only: bool,
    /// When a build holds the dataset folder, wait this long for it (30s, 5m, 1h).
    #[arg(long, value_name = "DURATION", value_parser = parse_wait)]
    wait: Option<Duration>,
}

/// `motionforge clean`.
pub(crate) fn run(args: CleanArgs, ui: &Ui) -> Result<ExitCode> {
    let dir = match args.dataset {
        Some(dataset) => dataset,
        None => {
            let mut config = Config::load(&args.config)?;
            if let Some(output) = args.output {
                config.dataset.output = std::path::absolute(&output).unwrap_or(output);
            }
            config.dataset_dir()
        }
    };
    let report = motionforge::build::clean::clean(&dir, args.cache_only, args.wait)?;
    let mut out = std::io::stdout().lock();
    if ui.json() {
        let value = serde_json::json!({
            "dataset_dir": dir,
            "removed": report.removed,
            "bytes": report.bytes,
            "kept": report.kept,
        });
        crate::ui::print_json(&value)?;
    } else if ui.status() {
        if report.removed.is_empty() {
            writeln!(out, "nothing to clean in {}", dir.display())?;
        } else {
            writeln!(
                out,
                "removed {} ({:.1} MB) from {}",
                report.removed.join(", "),
                report.bytes as f64 / 1e6,
                dir.display()
            )?;
        }
        if !report.kept.is_empty() {
            writeln!(out, "kept: {}", report.kept.join(", "))?;
        }
    }
    Ok(ExitCode::SUCCESS)
}
