//! `plan` and `status`: what a build would run and why, and what is built.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use motionforge::build::{BuildOptions, Stage};
use motionforge::config::DEFAULT_CONFIG;

use super::{load_checked, parse_stage};
use crate::summary::{print_plan, print_status};
use crate::ui::Ui;

/// Show what a build would run and why (which input, config key or stage version changed),
/// without running anything.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge plan --config fixtures/demo.toml
  motionforge plan --config fixtures/demo.toml --through label"
))]
pub(crate) struct PlanArgs {
    /// Build configuration (TOML).
    #[arg(long, short, default_value = DEFAULT_CONFIG)]
    config: PathBuf,
    /// The dataset folder's parent, instead of the config's `dataset.output`.
    #[arg(long, short)]
    output: Option<PathBuf>,
    /// Plan only up to this stage.
    #[arg(long, value_parser = parse_stage)]
    through: Option<Stage>,
}

/// Show each stage's state: fresh or stale, when it last ran and what it did, and the rows of
/// the written dataset.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge status --config fixtures/demo.toml"
))]
pub(crate) struct StatusArgs {
    /// Build configuration (TOML).
    #[arg(long, short, default_value = DEFAULT_CONFIG)]
    config: PathBuf,
    /// The dataset folder's parent, instead of the config's `dataset.output`.
    #[arg(long, short)]
    output: Option<PathBuf>,
}

/// `motionforge plan`.
pub(crate) fn plan(args: PlanArgs, ui: &Ui) -> Result<ExitCode> {
    let config = load_checked(&args.config, args.output)?;
    let plan = motionforge::build::plan(
        &config,
        &BuildOptions {
            through: args.through,
            ..BuildOptions::default()
        },
    )?;
    if ui.json() {
        writeln!(
            std::io::stdout(),
            "{}",
            serde_json::to_string_pretty(&plan)?
        )?;
    } else {
        print_plan(&plan)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `motionforge status`.
pub(crate) fn status(args: StatusArgs, ui: &Ui) -> Result<ExitCode> {
    let config = load_checked(&args.config, args.output)?;
    let status = motionforge::build::status(&config)?;
    if ui.json() {
        writeln!(
            std::io::stdout(),
            "{}",
            serde_json::to_string_pretty(&status)?
        )?;
    } else {
        print_status(&status)?;
    }
    Ok(ExitCode::SUCCESS)
}
