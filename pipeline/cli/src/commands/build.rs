//! `build` and `run`: the build with logs, progress and the summary.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Result;
use motionforge::build::{BuildOptions, Stage};
use motionforge::config::DEFAULT_CONFIG;

use super::{load_checked, parse_stage, parse_wait};
use crate::summary::{counts, print_report};
use crate::ui::Ui;

/// What `build` and `run` share.
#[derive(clap::Args)]
pub(crate) struct BuildArgs {
    /// Build configuration (TOML); relative paths inside resolve against its folder.
    #[arg(long, short, default_value = DEFAULT_CONFIG)]
    config: PathBuf,
    /// Write the dataset here instead of the config's `dataset.output`.
    #[arg(long, short)]
    output: Option<PathBuf>,
    /// Recompute, ignoring cached stage outputs.
    #[arg(long)]
    force: bool,
    /// Exit with code 3 when any input was rejected.
    #[arg(long)]
    strict: bool,
    /// Send no LLM request: LLM stages use cached answers only.
    #[arg(long)]
    offline: bool,
    /// When another build holds the dataset folder, wait this long for it (30s, 5m, 1h)
    /// instead of failing at once.
    #[arg(long, value_name = "DURATION", value_parser = parse_wait)]
    wait: Option<Duration>,
}

/// Run every stage of a build: read captures, label, resample, mirror, write the clip table.
///
/// Work whose inputs, config and stage version are unchanged is reused from the output
/// folder's cache; bad inputs are listed in `rejects.jsonl` and the build goes on.
#[derive(clap::Args)]
#[command(after_help = examples_then_exit_codes!(
    "  motionforge build --config fixtures/demo.toml
  motionforge build --config my.toml --output /data/sets --offline --wait 5m"
))]
pub(crate) struct BuildCommand {
    #[command(flatten)]
    args: BuildArgs,
}

/// Run the named stages and every stage they depend on, nothing after them.
///
/// Stages, in order: ingest, segment, label, paraphrase, plan, mirror, pair_check, compose,
/// label_check, write, report; each depends on all before it. `run segment` reads and cuts every capture and
/// caches the result; a later `build` reuses it.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge run segment --config fixtures/demo.toml      # read and cut every capture
  motionforge run label mirror --config fixtures/demo.toml"
))]
pub(crate) struct RunArgs {
    /// Stages to run (with their dependencies).
    #[arg(required = true, value_parser = parse_stage)]
    stages: Vec<Stage>,
    #[command(flatten)]
    args: BuildArgs,
}

/// Exit code of a build that finished but wrote no row (every capture rejected or dropped).
const EXIT_EMPTY: u8 = 4;
/// Exit code of `build --strict` when some input was rejected.
const EXIT_STRICT: u8 = 3;

/// `motionforge build`.
pub(crate) fn build(command: BuildCommand, ui: &Ui) -> Result<ExitCode> {
    build_through(command.args, None, ui)
}

/// `motionforge run <stage>...`: the build up to the last stage named.
pub(crate) fn run(command: RunArgs, ui: &Ui) -> Result<ExitCode> {
    build_through(command.args, command.stages.iter().copied().max(), ui)
}

/// `build`, or `run` up to `through`: the build with logs, progress and the summary.
fn build_through(args: BuildArgs, through: Option<Stage>, ui: &Ui) -> Result<ExitCode> {
    let config = load_checked(&args.config, args.output)?;
    let dataset_dir = config.dataset_dir();
    tracing::info!(
        dataset = %config.dataset.name,
        folder = %dataset_dir.display(),
        "building {} into {}",
        config.dataset.name,
        dataset_dir.display()
    );
    let started = std::time::Instant::now();
    let report = motionforge::build::build(
        &config,
        &BuildOptions {
            force: args.force,
            offline: args.offline,
            progress: ui.progress(),
            lock_wait: args.wait,
            through,
            config_file: Some(args.config.clone()),
        },
    )?;
    ui.clear_bars();
    let seconds = started.elapsed().as_secs_f64();
    // The summary on standard output (or the JSON report) says this too; `-v` shows the line.
    tracing::debug!(
        clips = report.clips,
        captures = report.captures,
        rejects = report.rejects.len(),
        seconds,
        "built {} clips from {} captures in {seconds:.1} s",
        report.clips,
        report.captures
    );
    if !report.rejects.is_empty() {
        tracing::warn!(
            rejects = report.rejects.len(),
            "{} inputs rejected ({}), listed in {}",
            report.rejects.len(),
            counts(&report.rejects_by_reason),
            dataset_dir.join(motionforge::build::REJECTS_FILE).display()
        );
    }
    if ui.json() {
        crate::ui::print_json(&report)?;
    } else if ui.status() {
        print_report(&report, seconds)?;
    }
    if report.clips == 0 && through.is_none_or(|t| t >= Stage::Write) {
        let dropped: usize = report.drops_by_reason.values().sum();
        tracing::error!(
            captures = report.captures,
            rejects = report.rejects.len(),
            dropped,
            "0 clips: {}; see {} and {}",
            empty_reason(report.captures, report.rejects.len(), dropped),
            dataset_dir.join(motionforge::build::REJECTS_FILE).display(),
            dataset_dir.join(motionforge::build::REPORT_FILE).display()
        );
        return Ok(ExitCode::from(EXIT_EMPTY));
    }
    if args.strict && !report.rejects.is_empty() {
        return Ok(ExitCode::from(EXIT_STRICT));
    }
    Ok(ExitCode::SUCCESS)
}

/// Why a build has no rows, in words.
fn empty_reason(captures: usize, rejects: usize, dropped: usize) -> String {
    let captures_word = if captures == 1 { "capture" } else { "captures" };
    match (captures, rejects, dropped) {
        (0, _, _) => "no capture was found".to_string(),
        (c, r, 0) if r >= c => format!("every capture was rejected ({r} of {c} {captures_word})"),
        (c, r, d) => format!(
            "{r} of {c} {captures_word} rejected and every segment of the others dropped ({d} segments)"
        ),
    }
}
