//! `prompt render`: the exact prompt a stage sends for a text.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Subcommand;
use motionforge::llm::prompt::Prompts;

use super::labels::part_variant;
use crate::error::UsageError;

/// Work with prompt templates.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge prompt render part_labels --text 'a person kicks with the right leg'"
))]
pub(crate) struct PromptArgs {
    #[command(subcommand)]
    command: PromptCommand,
}

#[derive(Subcommand)]
enum PromptCommand {
    /// Print the exact prompt a stage sends for a text (for a paper's appendix, or debugging).
    #[command(after_help = "Examples:
  motionforge prompt render part_labels --text 'a person kicks with the right leg'
  motionforge prompt render pair_compat --text 'wave' --second 'walk forward'")]
    Render {
        /// Template: part_labels, task_plan, paraphrase or pair_compat.
        template: String,
        /// The action text (the first one, for pair_compat).
        #[arg(long)]
        text: String,
        /// The second action text (pair_compat).
        #[arg(long)]
        second: Option<String>,
        /// part_labels variant: list_few_shot (SINC's prompt), list, or free_form.
        #[arg(long, default_value = "list_few_shot")]
        variant: String,
        /// Alternatives asked for (paraphrase).
        #[arg(long, default_value_t = 3)]
        n: usize,
        /// A folder of edited templates to use instead of the bundled ones.
        #[arg(long)]
        prompts_dir: Option<PathBuf>,
    },
}

/// `motionforge prompt render`.
pub(crate) fn run(args: PromptArgs) -> Result<ExitCode> {
    let PromptCommand::Render {
        template,
        text,
        second,
        variant,
        n,
        prompts_dir,
    } = args.command;
    let prompts = match prompts_dir {
        Some(dir) => Prompts::with_overrides(&dir)?,
        None => Prompts::bundled()?,
    };
    // The build asks about normalised texts; show the prompt it would send.
    let text = motionforge::stages::label::normalize_text(&text);
    let rendered = match template.as_str() {
        "part_labels" => prompts.part_labels(&text, part_variant(&variant)?)?,
        "task_plan" => prompts.task_plan(&text)?,
        "paraphrase" => prompts.paraphrase(&text, n)?,
        "pair_compat" => prompts.pair_compat(
            &text,
            &motionforge::stages::label::normalize_text(second.as_deref().ok_or_else(|| {
                UsageError(
                    "pair_compat needs --second (the text of the other clip of the pair)".into(),
                )
            })?),
        )?,
        other => {
            return Err(motionforge::llm::prompt::PromptError::Unknown(other.to_string()).into());
        }
    };
    let mut out = std::io::stdout().lock();
    out.write_all(rendered.as_bytes())?;
    Ok(ExitCode::SUCCESS)
}
