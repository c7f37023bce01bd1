//! `labels import` and `labels eval`: existing LLM answers into the cache, and labellers scored.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::Subcommand;
use motionforge::config::{Config, DEFAULT_CONFIG};
use motionforge::llm::cache::ResponseCache;
use motionforge::llm::prompt::PartPromptVariant;
use motionforge::parts::eval::{Evaluation, Gold};

use crate::ui::Ui;

/// Body-part labels: import existing LLM answers, evaluate labellers.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge labels eval --gold ../shared/data/sinc/part-labels-gold-dev.json"
))]
pub(crate) struct LabelsArgs {
    #[command(subcommand)]
    command: LabelsCommand,
}

#[derive(Subcommand)]
enum LabelsCommand {
    /// Load existing answers into the build's LLM response cache, so labelling needs no request.
    ///
    /// Reads SINC's format, `{text: [answer_v1, answer_v2, answer_v3]}`, and stores the chosen
    /// answer under the key of the part_labels prompt for that text with the config's [llm]
    /// model and sampling parameters (for SINC's file: model text-davinci-003, kind completion,
    /// temperature 0, max_tokens 256).
    #[command(after_help = "Examples:
  motionforge labels import ../shared/data/sinc/gpt3-labels-list.json --config my-llm.toml")]
    Import {
        /// The answers file (e.g. ../shared/data/sinc/gpt3-labels-list.json).
        file: PathBuf,
        /// Build configuration with an [llm] section; its llm_cache is written.
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// Position of the answer to import in each list (SINC's Listing 1 prompt is the third).
        #[arg(long, default_value_t = 2)]
        answer: usize,
        /// The part_labels prompt variant the answers answer.
        #[arg(long, default_value = "list_few_shot")]
        variant: String,
    },
    /// Evaluate labellers on a gold file with SINC's Table 1 protocol (Yes/No as 1/0,
    /// Sometimes skipped): accuracy per part and their mean.
    #[command(after_help = "Examples:
  motionforge labels eval --gold ../shared/data/sinc/part-labels-gold-dev.json
  motionforge labels eval --gold ../shared/data/sinc/part-labels-gold-dev.json \\
      --source embedded --source ../shared/data/sinc/gpt3-labels-list.json")]
    Eval {
        /// Gold labels: {text: [global, torso, left arm, right arm, left leg, right leg]} with
        /// 1, 0 or 0.5 (sometimes).
        #[arg(long)]
        gold: PathBuf,
        /// Labeller to score: `embedded`, `cache` (the config's LLM cache), or a SINC-format
        /// answers file. Repeat to compare side by side.
        #[arg(long = "source", default_value = "embedded")]
        sources: Vec<String>,
        /// Build configuration, for `--source cache`.
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
    },
}

pub(crate) fn part_variant(name: &str) -> Result<PartPromptVariant> {
    PartPromptVariant::ALL
        .into_iter()
        .find(|v| v.as_str() == name)
        .with_context(|| {
            format!(
                "unknown part_labels variant `{name}` (expected list_few_shot, list or free_form)"
            )
        })
}

/// `motionforge labels import|eval`.
pub(crate) fn run(args: LabelsArgs, ui: &Ui) -> Result<ExitCode> {
    match args.command {
        LabelsCommand::Import {
            file,
            config,
            answer,
            variant,
        } => import(&file, &config, answer, &variant)?,
        LabelsCommand::Eval {
            gold,
            sources,
            config,
        } => eval(&gold, &sources, &config, ui.json())?,
    }
    Ok(ExitCode::SUCCESS)
}

/// `labels import`: the answers of a SINC-format file into the config's LLM response cache.
fn import(file: &Path, config: &Path, answer: usize, variant: &str) -> Result<()> {
    let config = Config::load(config)?;
    let llm = config.llm.as_ref().context(
        "labels import needs an [llm] section naming the model whose answers these are (SINC: model = \"text-davinci-003\", kind = \"completion\", temperature = 0, max_tokens = 256)",
    )?;
    let prompts = config.prompts()?;
    let json =
        std::fs::read_to_string(file).with_context(|| format!("cannot read {}", file.display()))?;
    let cache_path = config.llm_cache_path();
    let mut cache =
        ResponseCache::open(&cache_path).with_context(|| format!("{}", cache_path.display()))?;
    let report = motionforge::stages::label::import_answers(
        &json,
        &file.display().to_string(),
        answer,
        part_variant(variant)?,
        &prompts,
        llm,
        &mut cache,
    )?;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "imported {} answers into {} ({} already there)",
        report.imported,
        cache_path.display(),
        report.already
    )?;
    if !report.without_answer.is_empty() {
        writeln!(
            out,
            "{} texts had no answer at position {answer}",
            report.without_answer.len()
        )?;
    }
    writeln!(
        out,
        "{} answers use words outside the prompt's list:",
        report.outside_list.len()
    )?;
    for (text, words) in &report.outside_list {
        writeln!(out, "  {text}: {words}")?;
    }
    writeln!(
        out,
        "{} answers flagged (no synonym maps them, or no part):",
        report.flagged.len()
    )?;
    for (text, why) in &report.flagged {
        writeln!(out, "  {text}: {why}")?;
    }
    Ok(())
}

/// `labels eval`: each source's accuracy on the gold file, as a table or JSON.
fn eval(gold: &Path, sources: &[String], config: &Path, json: bool) -> Result<()> {
    let gold_text =
        std::fs::read_to_string(gold).with_context(|| format!("cannot read {}", gold.display()))?;
    let gold_set = motionforge::parts::eval::read_gold(&gold_text)
        .with_context(|| format!("{}", gold.display()))?;
    let mut rows: Vec<(String, Evaluation)> = Vec::new();
    for source in sources {
        rows.push((source.clone(), evaluate(&gold_set, source, config)?));
    }
    let mut out = std::io::stdout().lock();
    if json {
        let value: serde_json::Value = rows
            .iter()
            .map(|(s, e)| (s.clone(), serde_json::to_value(e).unwrap_or_default()))
            .collect::<serde_json::Map<_, _>>()
            .into();
        crate::ui::print_json(&value)?;
    } else {
        let table: Vec<(&str, &Evaluation)> = rows.iter().map(|(s, e)| (s.as_str(), e)).collect();
        write!(out, "{}", motionforge::parts::eval::format_table(&table))?;
        for (source, e) in &rows {
            if !e.missing.is_empty() {
                writeln!(
                    out,
                    "{source}: no label for {} texts: {}",
                    e.missing.len(),
                    e.missing.join("; ")
                )?;
            }
        }
    }
    Ok(())
}

/// One labeller (`embedded`, `cache` or an answers file) scored on the gold set.
fn evaluate(gold_set: &Gold, source: &str, config: &Path) -> Result<Evaluation> {
    Ok(match source {
        // Gold files hold texts only: an unknown text gets the lexicon's default, as a
        // clip would without motion to look at.
        "embedded" => motionforge::parts::eval::evaluate(gold_set, |t| {
            Some(motionforge::parts::lexicon::label_text(t).parts)
        }),
        "cache" => {
            let config = Config::load(config)?;
            let llm = config
                .llm
                .as_ref()
                .context("--source cache needs an [llm] section in the config")?;
            let prompts = config.prompts()?;
            let cache = ResponseCache::open(&config.llm_cache_path())?;
            let variant = config.part_labels.variant;
            motionforge::parts::eval::evaluate(gold_set, |t| {
                let prompt = prompts
                    .part_labels(&motionforge::stages::label::normalize_text(t), variant)
                    .ok()?;
                let answer = cache.get(&llm.cache_key(&prompt))?;
                let parsed = motionforge::parts::answer::parse_part_answer(answer);
                (!parsed.empty).then_some(parsed.parts)
            })
        }
        file => {
            let text = std::fs::read_to_string(file)
                .with_context(|| format!("cannot read answers file {file}"))?;
            let map: std::collections::BTreeMap<String, Vec<String>> = serde_json::from_str(&text)
                .with_context(|| format!("{file}: expected {{text: [answer, ...]}}"))?;
            motionforge::parts::eval::evaluate(gold_set, |t| {
                let parsed = motionforge::parts::answer::parse_part_answer(map.get(t)?.last()?);
                (!parsed.empty).then_some(parsed.parts)
            })
        }
    })
}
