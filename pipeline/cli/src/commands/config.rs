//! `config check`: every value of a config and every file it names, without building.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;
use clap::Subcommand;
use motionforge::config::{Config, DEFAULT_CONFIG};

use crate::ui::Ui;

/// Check a build configuration without building: every value, and every file it names.
///
/// Prints every problem at once, as `file:line: key: value: expected ...` (exit code 2), or
/// one line with what the build would read.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge config check --config fixtures/demo.toml"
))]
pub(crate) struct ConfigArgs {
    #[command(subcommand)]
    command: ConfigCommand,
}

#[derive(Subcommand)]
enum ConfigCommand {
    /// Check every value of the config and every file it names; print all problems at once.
    ///
    /// With --probe, also ask the [llm] server for its model list (GET {base_url}/models, at most
    /// 5 s) and fail (exit code 1) when nothing answers.
    #[command(after_help = examples_then_exit_codes!(
        "  motionforge config check --config fixtures/demo.toml
  motionforge config check --config my.toml --probe --json"
    ))]
    Check {
        /// Build configuration (TOML).
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// Check the dataset folder under this output folder, as `build --output` would.
        #[arg(long, short)]
        output: Option<PathBuf>,
        /// Also try the [llm] endpoint: one GET of its model list.
        #[arg(long)]
        probe: bool,
    },
}

/// `motionforge config check`.
pub(crate) fn run(args: ConfigArgs, ui: &Ui) -> Result<ExitCode> {
    let ConfigCommand::Check {
        config,
        output,
        probe,
    } = args.command;
    config_check(&config, output, probe, ui)?;
    Ok(ExitCode::SUCCESS)
}

/// `config check --probe`: one GET of the endpoint's model list; `None` without an `[llm]` section.
fn probe_llm(config: &Config) -> Result<Option<(String, motionforge::llm::client::Probe)>> {
    let Some(llm) = &config.llm else {
        return Ok(None);
    };
    let client = motionforge::llm::client::LlmClient::new(llm.clone())?;
    let probe = client.probe()?;
    let served = if probe.models.is_empty() {
        String::new()
    } else {
        format!("; serves {}", probe.models.join(", "))
    };
    let line = format!(
        "LLM {} at {}: answered GET {} with HTTP {} in {} ms{served}",
        llm.model,
        llm.root(),
        probe.url,
        probe.status,
        probe.elapsed.as_millis()
    );
    Ok(Some((line, probe)))
}

fn config_check(path: &Path, output: Option<PathBuf>, probe: bool, ui: &Ui) -> Result<()> {
    let (config, summary) = match Config::load_checked(path, output) {
        Ok(ok) => ok,
        Err(err) => {
            if ui.log.json {
                let problems: Vec<serde_json::Value> = match &err {
                    motionforge::config::ConfigError::Invalid { problems, .. } => problems
                        .iter()
                        .map(|p| {
                            serde_json::json!({
                                "key": p.key, "value": p.value, "expected": p.expected, "line": p.line,
                            })
                        })
                        .collect(),
                    other => vec![serde_json::json!({ "message": other.to_string() })],
                };
                let value =
                    serde_json::json!({ "ok": false, "config": path, "problems": problems });
                crate::ui::print_json(&value)?;
            }
            return Err(err.into());
        }
    };
    for warning in &summary.warnings {
        tracing::warn!("{warning}");
    }
    let probed = if probe { probe_llm(&config)? } else { None };
    let captures: usize = summary.captures.iter().sum();
    let mut out = std::io::stdout().lock();
    if ui.log.json {
        let sources: Vec<serde_json::Value> = config
            .sources
            .iter()
            .zip(&summary.captures)
            .map(|(s, n)| serde_json::json!({ "name": s.name, "captures": n }))
            .collect();
        let value = serde_json::json!({
            "ok": true,
            "config": path,
            "dataset": config.dataset.name,
            "dataset_dir": config.dataset_dir(),
            "sources": sources,
            "warnings": summary.warnings,
            "probe": probed.as_ref().map(|(_, p)| serde_json::json!({
                "url": p.url,
                "status": p.status,
                "millis": p.elapsed.as_millis() as u64,
                "models": p.models,
            })),
        });
        crate::ui::print_json(&value)?;
    } else if ui.status() {
        let splits: Vec<String> = config
            .splits
            .ratios
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect();
        writeln!(
            out,
            "config {}: OK: dataset `{}` into {}, {} sources with {captures} captures, {} fps, seed {}, splits {}, LLM {}",
            path.display(),
            config.dataset.name,
            config.dataset_dir().display(),
            config.sources.len(),
            config.dataset.fps,
            config.dataset.seed,
            splits.join(" / "),
            config
                .llm
                .as_ref()
                .map(|l| format!("{} at {}", l.model, l.base_url))
                .unwrap_or_else(|| "none".into())
        )?;
        match (&probed, probe) {
            (Some((line, _)), _) => writeln!(out, "{line}")?,
            (None, true) => writeln!(out, "no [llm] section: nothing to probe")?,
            (None, false) => {}
        }
    }
    Ok(())
}
