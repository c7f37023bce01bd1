//! One module per command (or command group): its clap arguments and its `run`.

use std::path::Path;
use std::time::Duration;

use anyhow::Result;
use clap::Subcommand;
use motionforge::build::Stage;
use motionforge::config::Config;

pub(crate) mod bench;
mod bench_amass;
mod bench_build;
mod bench_clock;
mod bench_export;
mod bench_floor;
mod bench_machine;
pub(crate) mod build;
pub(crate) mod clean;
pub(crate) mod clips;
pub(crate) mod config;
pub(crate) mod export;
pub(crate) mod export_bvh;
pub(crate) mod labels;
pub(crate) mod mirror;
pub(crate) mod plan;
pub(crate) mod plan_session;
pub(crate) mod preview;
pub(crate) mod prompt;
pub(crate) mod report;
pub(crate) mod schema;
pub(crate) mod serve;

/// The commands, in the order `--help` lists them (each one's help is on its arguments).
#[derive(Subcommand)]
pub(crate) enum Command {
    Build(build::BuildCommand),
    Config(config::ConfigArgs),
    Clean(clean::CleanArgs),
    Run(build::RunArgs),
    Plan(plan::PlanArgs),
    Status(plan::StatusArgs),
    MirrorText(mirror::MirrorTextArgs),
    CalibrateMirror(mirror::CalibrateMirrorArgs),
    ExportBvh(export_bvh::ExportBvhArgs),
    Clips(clips::ClipsArgs),
    Preview(preview::PreviewArgs),
    Export(export::ExportArgs),
    Report(report::ReportArgs),
    PlanSession(plan_session::PlanSessionArgs),
    Schema(schema::SchemaArgs),
    Serve(serve::ServeArgs),
    /// Run one build for `motionforge serve`, in a process of its own (the service starts it;
    /// docs/service.md describes the protocol).
    #[command(name = "serve-build", hide = true)]
    ServeBuild(serve::ServeBuildArgs),
    Prompt(prompt::PromptArgs),
    Labels(labels::LabelsArgs),
    Bench(bench::BenchArgs),
}

/// `--wait` values: `30s`, `5m`, `1h 30m`, or bare seconds.
pub(crate) fn parse_wait(text: &str) -> Result<Duration, String> {
    if let Ok(seconds) = text.trim().parse::<u64>() {
        return Ok(Duration::from_secs(seconds));
    }
    humantime::parse_duration(text.trim())
        .map_err(|e| format!("{e}; expected a duration such as 30s, 5m or 1h"))
}

pub(crate) fn parse_stage(s: &str) -> std::result::Result<Stage, String> {
    s.parse()
}

/// Loads a config for a build: its values and every file it names, all problems at once.
pub(crate) fn load_checked(path: &Path, output: Option<std::path::PathBuf>) -> Result<Config> {
    let (config, summary) = Config::load_checked(path, output)?;
    for warning in &summary.warnings {
        tracing::warn!("{warning}");
    }
    Ok(config)
}

/// The value of an argument given in its new spelling or in its `old` one, which still works for
/// one release but warns on standard error, naming the new spelling.
pub(crate) fn deprecated<T>(
    new: Option<T>,
    old: Option<T>,
    old_name: &str,
    instead: &str,
) -> Option<T> {
    if old.is_some() {
        tracing::warn!("`{old_name}` is deprecated and goes in the next release; use {instead}");
    }
    new.or(old)
}
