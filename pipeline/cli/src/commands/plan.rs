//! `plan` and `status`: what a build would run and why, and what is built.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use motionforge::build::{BuildOptions, ConfigRecord, Stage};
use motionforge::config::{Config, DEFAULT_CONFIG};

use super::{load_checked, parse_stage};
use crate::error::UsageError;
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
///
/// Given a dataset folder, reads the config its last build was given (recorded in the folder's
/// `.motionforge/config.json`); `--config` names another one.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge status out/demo
  motionforge status --config fixtures/demo.toml"
))]
pub(crate) struct StatusArgs {
    /// The dataset folder (`<output>/<name>`).
    dataset: Option<PathBuf>,
    /// Build configuration (TOML) [default: the one the dataset's last build was given, or
    /// motionforge.toml without a DATASET].
    #[arg(long, short)]
    config: Option<PathBuf>,
    /// The dataset folder's parent, instead of the config's `dataset.output`.
    #[arg(long, short, conflicts_with = "dataset")]
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
        crate::ui::print_json(&plan)?;
    } else {
        print_plan(&plan)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `motionforge status`.
pub(crate) fn status(args: StatusArgs, ui: &Ui) -> Result<ExitCode> {
    let config = match &args.dataset {
        Some(dataset) => dataset_config(dataset, args.config)?,
        None => load_checked(
            &args.config.unwrap_or_else(|| PathBuf::from(DEFAULT_CONFIG)),
            args.output,
        )?,
    };
    let status = motionforge::build::status(&config)?;
    if ui.json() {
        crate::ui::print_json(&status)?;
    } else {
        print_status(&status)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The config of the dataset in `dataset`: `config` when given, else the one its last build
/// recorded; its output is the folder's parent, and its dataset name must be the folder's.
fn dataset_config(dataset: &Path, config: Option<PathBuf>) -> Result<Config> {
    if !dataset.join(".motionforge").is_dir() {
        return Err(UsageError(format!(
            "{}: not a dataset folder (no .motionforge/ inside); give the folder a build wrote, or --config",
            dataset.display()
        ))
        .into());
    }
    let recorded = config.is_none();
    let Some(file) = config.or_else(|| ConfigRecord::load(dataset)) else {
        return Err(UsageError(format!(
            "{}: no build config recorded (the folder was built before builds recorded it); pass --config FILE",
            dataset.display()
        ))
        .into());
    };
    let dataset = motionforge::base::lexical_path(
        &std::path::absolute(dataset).unwrap_or_else(|_| dataset.to_path_buf()),
    );
    let parent = dataset.parent().map(Path::to_path_buf).unwrap_or_default();
    let loaded = load_checked(&file, Some(parent));
    let config = if recorded {
        loaded.with_context(|| {
            format!(
                "{}: the config its last build was given, {}, cannot be used; pass --config FILE",
                dataset.display(),
                file.display()
            )
        })?
    } else {
        loaded?
    };
    if config.dataset_dir() != dataset {
        return Err(UsageError(format!(
            "{} describes dataset `{}`, not the folder {}; pass that dataset's own --config",
            file.display(),
            config.dataset.name,
            dataset.display()
        ))
        .into());
    }
    Ok(config)
}
