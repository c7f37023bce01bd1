//! The `motionforge` command: argument parsing and human output over the library.

use std::io::{BufRead, IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};

use motionforge::build::{BuildOptions, BuildReport, Stage, build};
use motionforge::config::{Config, DEFAULT_CONFIG};
use motionforge::llm::cache::ResponseCache;
use motionforge::llm::prompt::{PartPromptVariant, Prompts};
use motionforge::motion::{MirrorPlan, OffsetPolicy, ProfileSpec, calibrate, read_bvh};
use motionforge::progress::ProgressSink;
use motionforge::terminal::{BarProgress, LogOptions, LogProgress};

/// Exit codes, shown after `--help` and documented in docs/user-guide.md.
const EXIT_CODES: &str = "\
Exit codes:
  0  success (including a build with rejected inputs, unless --strict)
  1  failure: a file that cannot be read or written (disk full, no permission), another
     build holding the dataset folder (see --wait), an LLM stage that cannot run
  2  usage or config error: bad arguments, a config that is missing, does not parse or
     fails its checks, or names files that do not exist (`motionforge config check`)
  3  build --strict finished, but some inputs were rejected (see rejects.jsonl)

Logging: progress and log lines go to standard error (bars on a terminal, plain lines
otherwise, JSON lines with --json); results go to standard output.";

/// Build text-to-motion training sets from mocap captures: segment, mirror, label, compose,
/// and write sharded Parquet with statistics for papers.
#[derive(Parser)]
#[command(
    name = "motionforge",
    version,
    about,
    long_about = None,
    propagate_version = true,
    after_help = EXIT_CODES
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Print only warnings and errors (no progress, no build summary).
    #[arg(long, short, global = true, conflicts_with = "verbose")]
    quiet: bool,
    /// Log more: -v adds debug lines (stage starts, timings, fields), -vv trace lines, -vvv
    /// dependencies' lines too.
    #[arg(long, short, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    /// Machine-readable output: log lines as JSON objects on standard error, and results (the
    /// build report, label scores, config check) as JSON on standard output.
    #[arg(long, global = true)]
    json: bool,
}

/// `--wait` values: `30s`, `5m`, `1h 30m`, or bare seconds.
fn parse_wait(text: &str) -> Result<Duration, String> {
    if let Ok(seconds) = text.trim().parse::<u64>() {
        return Ok(Duration::from_secs(seconds));
    }
    humantime::parse_duration(text.trim())
        .map_err(|e| format!("{e}; expected a duration such as 30s, 5m or 1h"))
}

/// What `build` and `run` share.
#[derive(clap::Args)]
struct BuildArgs {
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

#[derive(Subcommand)]
enum Command {
    /// Run every stage of a build: read captures, label, resample, mirror, write the clip table.
    ///
    /// Work whose inputs, config and stage version are unchanged is reused from the output
    /// folder's cache; bad inputs are listed in `rejects.jsonl` and the build goes on.
    #[command(after_help = EXIT_CODES)]
    Build {
        #[command(flatten)]
        args: BuildArgs,
    },
    /// Check a build configuration without building: every value, and every file it names.
    ///
    /// Prints every problem at once, as `file:line: key: value: expected ...` (exit code 2), or
    /// one line with what the build would read.
    Config {
        #[command(subcommand)]
        command: ConfigCommand,
    },
    /// Remove a built dataset's outputs (shards, card, manifest, report, stage cache), or with
    /// --cache-only only its stage cache.
    ///
    /// Only what a build writes is removed, and only inside `<output>/<name>`; the LLM response
    /// cache and files you put there are kept. Takes the dataset folder's lock, like a build.
    #[command(after_help = EXIT_CODES)]
    Clean {
        /// Build configuration naming the dataset folder.
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// The output folder the dataset was built into with `build --output`.
        #[arg(long, short)]
        output: Option<PathBuf>,
        /// Remove only the stage cache (`.motionforge/cache`); the next build recomputes every
        /// stage but rewrites no output that would be identical.
        #[arg(long)]
        cache_only: bool,
        /// When a build holds the dataset folder, wait this long for it (30s, 5m, 1h).
        #[arg(long, value_name = "DURATION", value_parser = parse_wait)]
        wait: Option<Duration>,
    },
    /// Run the named stages and every stage they depend on, nothing after them.
    ///
    /// Stages, in order: ingest, segment, label, paraphrase, plan, mirror, compose, write,
    /// report; each depends on all before it. `run segment` reads and cuts every capture and
    /// caches the result; a later `build` reuses it.
    Run {
        /// Stages to run (with their dependencies).
        #[arg(required = true, value_parser = parse_stage)]
        stages: Vec<Stage>,
        #[command(flatten)]
        args: BuildArgs,
    },
    /// Show what a build would run and why (which input, config key or stage version changed),
    /// without running anything.
    Plan {
        /// Build configuration (TOML).
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// The dataset folder's parent, instead of the config's `dataset.output`.
        #[arg(long, short)]
        output: Option<PathBuf>,
        /// Plan only up to this stage.
        #[arg(long, value_parser = parse_stage)]
        through: Option<Stage>,
    },
    /// Show each stage's state: fresh or stale, when it last ran and what it did, and the rows of
    /// the written dataset.
    Status {
        /// Build configuration (TOML).
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// The dataset folder's parent, instead of the config's `dataset.output`.
        #[arg(long, short)]
        output: Option<PathBuf>,
    },
    /// Mirror caption lines: swap left/right and clockwise/counterclockwise, whole words only.
    ///
    /// Reads FILE (or standard input) line by line and writes the mirrored lines to standard
    /// output, e.g. to mirror an existing HumanML3D-style caption set.
    MirrorText {
        /// Text file to mirror; standard input when absent.
        file: Option<PathBuf>,
    },
    /// Calibrate a skeleton profile's mirror reflections on captures and print them as TOML.
    ///
    /// Among the per-joint reflections that fit the skeleton's offsets, picks the one whose
    /// mirrored rotations best match the real ones (one roughly symmetric take, e.g. a walk,
    /// is enough). Paste the output into the profile's `[reflections]` table.
    CalibrateMirror {
        /// Bundled profile name (bandai-namco, cmu, smpl-22) or a profile TOML file.
        #[arg(long)]
        profile: String,
        /// BVH captures of that skeleton.
        #[arg(required = true)]
        captures: Vec<PathBuf>,
    },
    /// Write one clip (real, mirrored or synthetic) as a BVH file on its source skeleton, at full
    /// precision, for inspection in Blender.
    ExportBvh {
        /// Build configuration; stages reuse their cached outputs.
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// The clip id, as in the table's `clip_id` column.
        #[arg(long)]
        clip: String,
        /// Output file; default `<clip id with / and : replaced>.bvh` in the working folder.
        #[arg(long, short)]
        output: Option<PathBuf>,
        /// Send no LLM request while re-running stages.
        #[arg(long)]
        offline: bool,
        /// When a build holds the dataset folder (whose stage cache this reads and refreshes),
        /// wait this long for it (30s, 5m, 1h).
        #[arg(long, value_name = "DURATION", value_parser = parse_wait)]
        wait: Option<Duration>,
    },
    /// Write the statistics report of a built dataset: tables (LaTeX, Markdown), figures (SVG,
    /// PNG) and stats.json, from its shards and manifest alone.
    Report {
        /// The dataset folder (`<output>/<name>`, holding data/ and manifest.json).
        dataset: PathBuf,
        /// Where to write; default `<dataset>/report`.
        #[arg(long, short)]
        output: Option<PathBuf>,
    },
    /// Print the clip table schema (columns, types, version) as JSON.
    Schema,
    /// Serve an HTTP API that builds the datasets on request and on their `dataset.schedule`,
    /// one build at a time per dataset, with the run history kept across restarts
    /// (docs/service.md). Calls that change state need `Authorization: Bearer <token>`.
    Serve {
        /// A dataset's build configuration; repeat to serve several datasets.
        #[arg(long, short, default_value = "motionforge.toml")]
        config: Vec<PathBuf>,
        /// Address to listen on.
        #[arg(long, default_value = motionforge::serve::DEFAULT_BIND)]
        bind: String,
        /// Folder of the run history database.
        #[arg(long, default_value = motionforge::serve::DEFAULT_STATE_DIR)]
        state: PathBuf,
        /// Environment variable holding the bearer token (required: the service will not start
        /// without it).
        #[arg(long, default_value = motionforge::serve::DEFAULT_TOKEN_ENV)]
        token_env: String,
    },
    /// Work with prompt templates.
    Prompt {
        #[command(subcommand)]
        command: PromptCommand,
    },
    /// Body-part labels: import existing LLM answers, evaluate labellers.
    Labels {
        #[command(subcommand)]
        command: LabelsCommand,
    },
    /// Measure BVH read, forward kinematics and mirroring throughput on a folder of captures.
    Bench {
        /// Folder of BVH files (all must share one skeleton profile).
        #[arg(long, default_value = "../shared/data/bandai-namco-1/data")]
        data: PathBuf,
        /// Skeleton profile of the captures.
        #[arg(long, default_value = "bandai-namco")]
        profile: String,
        /// Repeat the whole folder this many times and keep the fastest pass.
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Instead, measure writing Parquet shards of at least this many frames (the folder's
        /// clips and mirrors, repeated), with the write's peak memory.
        #[arg(long)]
        write_frames: Option<usize>,
    },
}

#[derive(Subcommand)]
enum ConfigCommand {
    /// Check every value of the config and every file it names; print all problems at once.
    #[command(after_help = EXIT_CODES)]
    Check {
        /// Build configuration (TOML).
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// Check the dataset folder under this output folder, as `build --output` would.
        #[arg(long, short)]
        output: Option<PathBuf>,
    },
}

#[derive(Subcommand)]
enum PromptCommand {
    /// Print the exact prompt a stage sends for a text (for a paper's appendix, or debugging).
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

#[derive(Subcommand)]
enum LabelsCommand {
    /// Load existing answers into the build's LLM response cache, so labelling needs no request.
    ///
    /// Reads SINC's format, `{text: [answer_v1, answer_v2, answer_v3]}`, and stores the chosen
    /// answer under the key of the part_labels prompt for that text with the config's [llm]
    /// model and sampling parameters (for SINC's file: model text-davinci-003, kind completion,
    /// temperature 0, max_tokens 256).
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

fn main() -> ExitCode {
    let cli = Cli::parse();
    let ui = Ui::new(&cli);
    let result = run(cli, &ui);
    ui.clear_bars();
    match result {
        Ok(code) => code,
        Err(err) => {
            // A closed pipe (`motionforge mirror-text | head`) is not an error worth reporting.
            if err.chain().any(|e| {
                e.downcast_ref::<std::io::Error>()
                    .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
            }) {
                return ExitCode::SUCCESS;
            }
            let code = exit_code(&err);
            let message = error_message(&err);
            if ui.log.json {
                tracing::error!(exit_code = code, "{message}");
            } else {
                eprintln!("error: {message}");
            }
            ExitCode::from(code)
        }
    }
}

/// How this run reports to whoever started it: log level and form, and progress bars.
struct Ui {
    log: LogOptions,
    bars: Option<Arc<BarProgress>>,
}

impl Ui {
    /// Sets up logging to standard error; bars only when it is a terminal and lines are not
    /// asked for.
    fn new(cli: &Cli) -> Ui {
        let log = LogOptions {
            quiet: cli.quiet,
            verbose: cli.verbose,
            json: cli.json,
        };
        let bars = log
            .bars(std::io::stderr().is_terminal())
            .then(|| Arc::new(BarProgress::new()));
        let subscriber = match &bars {
            Some(b) => motionforge::terminal::subscriber(&log, b.log_writer()),
            None => motionforge::terminal::subscriber(&log, std::io::stderr),
        };
        // Only fails if a subscriber is already set, and none is: nothing to report.
        let _ = tracing::subscriber::set_global_default(subscriber);
        Ui { log, bars }
    }

    /// Where a build reports its stages.
    fn progress(&self) -> ProgressSink {
        match &self.bars {
            Some(bars) => ProgressSink::new(bars.clone()),
            None => ProgressSink::new(Arc::new(LogProgress::new())),
        }
    }

    /// Whether status lines (the build summary, "wrote ..." lines) are printed.
    fn status(&self) -> bool {
        !self.log.quiet
    }

    fn clear_bars(&self) {
        if let Some(bars) = &self.bars {
            bars.clear();
        }
    }
}

/// The error and its causes on one line, skipping causes the message already quotes.
fn error_message(err: &anyhow::Error) -> String {
    let mut message = err.to_string();
    for cause in err.chain().skip(1) {
        let text = cause.to_string();
        if !message.contains(&text) {
            message = format!("{message}: {text}");
        }
    }
    message
}

/// 2 for mistakes in the config or what it names (documented exit codes), 1 otherwise.
fn exit_code(err: &anyhow::Error) -> u8 {
    use motionforge::build::BuildError;
    let usage = err.chain().any(|e| {
        e.downcast_ref::<motionforge::config::ConfigError>()
            .is_some()
            || e.downcast_ref::<motionforge::source::SourceError>()
                .is_some()
            || e.downcast_ref::<motionforge::annotate::taxonomy::TaxonomyError>()
                .is_some()
            || e.downcast_ref::<motionforge::motion::profile::ProfileError>()
                .is_some()
            || e.downcast_ref::<motionforge::llm::prompt::PromptError>()
                .is_some()
            || matches!(
                e.downcast_ref::<motionforge::build::clean::CleanError>(),
                Some(motionforge::build::clean::CleanError::NotADataset { .. })
            )
            || matches!(
                e.downcast_ref::<BuildError>(),
                Some(
                    BuildError::Source(_)
                        | BuildError::Taxonomy(_)
                        | BuildError::Prompt(_)
                        | BuildError::Split(_)
                )
            )
    });
    if usage { 2 } else { 1 }
}

fn run(cli: Cli, ui: &Ui) -> Result<ExitCode> {
    match cli.command {
        Command::Build { args } => return build_command(args, None, ui),
        Command::Run { stages, args } => {
            return build_command(args, stages.iter().copied().max(), ui);
        }
        Command::Plan {
            config,
            output,
            through,
        } => {
            let config = load_checked(&config, output)?;
            let plan = motionforge::build::plan(
                &config,
                &BuildOptions {
                    through,
                    ..BuildOptions::default()
                },
            )?;
            if ui.log.json {
                writeln!(
                    std::io::stdout(),
                    "{}",
                    serde_json::to_string_pretty(&plan)?
                )?;
            } else {
                print_plan(&plan)?;
            }
        }
        Command::Status { config, output } => {
            let config = load_checked(&config, output)?;
            let status = motionforge::build::status(&config)?;
            if ui.log.json {
                writeln!(
                    std::io::stdout(),
                    "{}",
                    serde_json::to_string_pretty(&status)?
                )?;
            } else {
                print_status(&status)?;
            }
        }
        Command::Config {
            command: ConfigCommand::Check { config, output },
        } => config_check(&config, output, ui)?,
        Command::Clean {
            config,
            output,
            cache_only,
            wait,
        } => {
            let mut config = Config::load(&config)?;
            if let Some(output) = output {
                config.dataset.output = std::path::absolute(&output).unwrap_or(output);
            }
            let dir = config.dataset_dir();
            let report = motionforge::build::clean::clean(&dir, cache_only, wait)?;
            let mut out = std::io::stdout().lock();
            if ui.log.json {
                let value = serde_json::json!({
                    "dataset_dir": dir,
                    "removed": report.removed,
                    "bytes": report.bytes,
                    "kept": report.kept,
                });
                writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
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
        }
        Command::MirrorText { file } => mirror_text(file.as_deref())?,
        Command::CalibrateMirror { profile, captures } => calibrate_mirror(&profile, &captures)?,
        Command::ExportBvh {
            config,
            clip,
            output,
            offline,
            wait,
        } => export_bvh(&config, &clip, output, offline, wait, ui)?,
        Command::Report { dataset, output } => {
            let files = motionforge::report::report_dataset(&dataset, output.as_deref())?;
            if ui.status() {
                writeln!(
                    std::io::stdout(),
                    "wrote {} report files to {}",
                    files.len(),
                    output.unwrap_or_else(|| dataset.join("report")).display()
                )?;
            }
        }
        Command::Prompt { command } => prompt_command(command)?,
        Command::Serve {
            config,
            bind,
            state,
            token_env,
        } => motionforge::serve::run(&motionforge::serve::ServeCommand {
            configs: config,
            bind,
            state_dir: state,
            token_env,
        })?,
        Command::Labels { command } => labels_command(command, ui.log.json)?,
        Command::Schema => writeln!(
            std::io::stdout(),
            "{}",
            serde_json::to_string_pretty(&motionforge::io::schema::clip_schema_json())?
        )?,
        Command::Bench {
            data,
            profile,
            repeat,
            write_frames,
        } => match write_frames {
            Some(frames) => bench_write(&data, &profile, frames)?,
            None => bench(&data, &profile, repeat.max(1))?,
        },
    }
    Ok(ExitCode::SUCCESS)
}

/// Loads a config for a build: its values and every file it names, all problems at once.
/// `build`, or `run` up to `through`: the build with logs, progress and the summary.
fn build_command(args: BuildArgs, through: Option<Stage>, ui: &Ui) -> Result<ExitCode> {
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
    let report = build(
        &config,
        &BuildOptions {
            force: args.force,
            offline: args.offline,
            progress: ui.progress(),
            lock_wait: args.wait,
            through,
        },
    )?;
    ui.clear_bars();
    let seconds = started.elapsed().as_secs_f64();
    tracing::info!(
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
    if ui.log.json {
        writeln!(
            std::io::stdout(),
            "{}",
            serde_json::to_string_pretty(&report)?
        )?;
    } else if ui.status() {
        print_report(&report)?;
    }
    if args.strict && !report.rejects.is_empty() {
        return Ok(ExitCode::from(3));
    }
    Ok(ExitCode::SUCCESS)
}

fn load_checked(path: &Path, output: Option<PathBuf>) -> Result<Config> {
    let (config, summary) = Config::load_checked(path, output)?;
    for warning in &summary.warnings {
        tracing::warn!("{warning}");
    }
    Ok(config)
}

fn config_check(path: &Path, output: Option<PathBuf>, ui: &Ui) -> Result<()> {
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
                writeln!(
                    std::io::stdout(),
                    "{}",
                    serde_json::to_string_pretty(&value)?
                )?;
            }
            return Err(err.into());
        }
    };
    for warning in &summary.warnings {
        tracing::warn!("{warning}");
    }
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
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
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
    }
    Ok(())
}

fn counts(map: &std::collections::BTreeMap<String, usize>) -> String {
    if map.is_empty() {
        return "none".to_string();
    }
    map.iter()
        .map(|(k, n)| format!("{k} {n}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn parse_stage(s: &str) -> std::result::Result<Stage, String> {
    s.parse()
}

fn reasons(map: &std::collections::BTreeMap<String, usize>) -> String {
    map.iter()
        .map(|(why, n)| format!("{why} ({n})"))
        .collect::<Vec<_>>()
        .join("; ")
}

fn print_plan(plan: &motionforge::build::Plan) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "plan for {} ({}):",
        plan.dataset,
        plan.output.display()
    )?;
    for stage in &plan.stages {
        if stage.fresh() {
            writeln!(
                out,
                "{:>10}  up to date ({} items)",
                stage.stage.name(),
                stage.items
            )?;
        } else {
            writeln!(
                out,
                "{:>10}  {} of {} to run: {}",
                stage.stage.name(),
                stage.to_run,
                stage.items.max(stage.to_run),
                reasons(&stage.reasons)
            )?;
            for example in &stage.examples {
                writeln!(out, "{:>10}    {example}", "")?;
            }
        }
    }
    if plan.nothing_to_run() {
        writeln!(out, "nothing to run: a build would reuse everything")?;
    }
    Ok(())
}

/// `YYYY-MM-DD HH:MM UTC` of Unix seconds (days to civil date as in Howard Hinnant's algorithm).
fn utc(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1_460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02} UTC",
        rem / 3_600,
        (rem % 3_600) / 60
    )
}

fn print_status(status: &motionforge::build::Status) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    let rows = if status.splits.is_empty() {
        "not written yet".to_string()
    } else {
        status
            .splits
            .iter()
            .map(|(split, n)| format!("{split} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    writeln!(
        out,
        "{} ({}): {rows}",
        status.dataset,
        status.output.display()
    )?;
    writeln!(
        out,
        "{:>10}  {:<6} {:<21} {:>6} {:>6} {:>6}",
        "stage", "state", "last run", "items", "ran", "reused"
    )?;
    for s in &status.stages {
        let last = s.last_run.map_or_else(|| "never".to_string(), utc);
        writeln!(
            out,
            "{:>10}  {:<6} {:<21} {:>6} {:>6} {:>6}",
            s.stage.name(),
            if s.fresh { "fresh" } else { "stale" },
            last,
            s.items,
            s.ran,
            s.reused
        )?;
        if !s.fresh {
            writeln!(
                out,
                "{:>10}    {} to run: {}",
                "",
                s.to_run,
                reasons(&s.reasons)
            )?;
        }
    }
    Ok(())
}

fn print_report(report: &BuildReport) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    for stage in &report.stages {
        let what = if stage.ran == 0 {
            "up to date, nothing re-run".to_string()
        } else {
            format!(
                "ran {} of {} ({} reused)",
                stage.ran, stage.items, stage.reused
            )
        };
        writeln!(out, "{:>10}  {what}", stage.stage)?;
    }
    writeln!(
        out,
        "{} captures -> {} clips ({} mirrored) in {}/",
        report.captures,
        report.clips,
        report.mirrored,
        report.output.join(motionforge::build::DATA_DIR).display()
    )?;
    writeln!(out, "by kind: {}", counts(&report.kinds))?;
    writeln!(
        out,
        "motion types (originals): {}",
        counts(&report.motion_types)
    )?;
    if !report.unmapped_labels.is_empty() {
        writeln!(
            out,
            "labels with no motion type: {}",
            counts(&report.unmapped_labels)
        )?;
    }
    writeln!(out, "dropped segments: {}", counts(&report.drops_by_reason))?;
    if !report.notes_by_kind.is_empty() {
        writeln!(out, "annotation notes: {}", counts(&report.notes_by_kind))?;
    }
    let l = &report.labels;
    writeln!(
        out,
        "part labels: {} ({} texts, {} requests, {} cache hits, {} flagged)",
        counts(&l.sources),
        l.texts,
        l.requests,
        l.cache_hits,
        l.flagged.len()
    )?;
    if let Some((agreement, n)) = l.velocity_agreement {
        writeln!(
            out,
            "  motion velocity agrees with the lexicon on {:.0}% of parts ({n} clips)",
            agreement * 100.0
        )?;
    }
    for (name, r) in [
        ("paraphrases", &report.paraphrases),
        ("task plans", &report.plans),
    ] {
        let skipped = if r.skipped.is_empty() {
            String::new()
        } else {
            format!("; skipped: {}", counts(&r.skipped))
        };
        writeln!(
            out,
            "{name}: {} of {} texts answered, {} requests, {} rejected{skipped}",
            r.answered,
            r.texts,
            r.requests,
            r.rejected.len()
        )?;
    }
    let c = &report.synthetic;
    writeln!(
        out,
        "synthetic pairs: {} candidates, {} compatible pairs, {} sampled, {} composed, dropped: {}",
        c.candidates,
        c.compatible,
        c.sampled,
        c.composed,
        counts(&c.dropped)
    )?;
    let pc = &report.pair_check;
    if pc.texts > 0 {
        writeln!(
            out,
            "pair check (LLM): {} of {} pairs answered, {} requests{}",
            pc.answered,
            pc.texts,
            pc.requests,
            if pc.skipped.is_empty() {
                String::new()
            } else {
                format!("; skipped: {}", counts(&pc.skipped))
            }
        )?;
    }
    if report.rejects.is_empty() {
        writeln!(out, "rejects: none")?;
    } else {
        writeln!(
            out,
            "rejects: {} ({}), listed in {}:",
            report.rejects.len(),
            counts(&report.rejects_by_reason),
            report
                .output
                .join(motionforge::build::REJECTS_FILE)
                .display()
        )?;
        for r in report.rejects.iter().take(10) {
            writeln!(out, "  {r}")?;
        }
    }
    if report.nothing_ran() {
        writeln!(out, "nothing changed since the last build")?;
    }
    Ok(())
}

fn mirror_text(file: Option<&Path>) -> Result<()> {
    let stdin = std::io::stdin();
    let reader: Box<dyn BufRead> = match file {
        Some(p) => Box::new(std::io::BufReader::new(
            std::fs::File::open(p).with_context(|| format!("cannot open {}", p.display()))?,
        )),
        None => Box::new(stdin.lock()),
    };
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for line in reader.lines() {
        let line = line.context("reading text")?;
        writeln!(out, "{}", motionforge::text::mirror_text(&line))?;
    }
    out.flush()?;
    Ok(())
}

fn load_profile(name: &str) -> Result<ProfileSpec> {
    if name.ends_with(".toml") {
        let text =
            std::fs::read_to_string(name).with_context(|| format!("cannot read profile {name}"))?;
        Ok(ProfileSpec::from_toml(name, &text)?)
    } else {
        Ok(ProfileSpec::bundled(name)?)
    }
}

fn read_capture(path: &Path) -> Result<motionforge::motion::Bvh> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    read_bvh(&text).with_context(|| format!("{}", path.display()))
}

fn calibrate_mirror(profile: &str, captures: &[PathBuf]) -> Result<()> {
    let spec = load_profile(profile)?;
    let bvhs: Vec<_> = captures
        .iter()
        .map(|p| read_capture(p))
        .collect::<Result<_>>()?;
    let skeleton = &bvhs[0].skeleton;
    if let Some((p, _)) = captures
        .iter()
        .zip(&bvhs)
        .find(|(_, b)| b.skeleton.names().ne(skeleton.names()))
    {
        bail!(
            "{} has a different skeleton from {}",
            p.display(),
            captures[0].display()
        );
    }
    let bound = spec.bind(skeleton)?;
    let motions: Vec<_> = bvhs.iter().map(|b| &b.motion).collect();
    let reflections = calibrate(skeleton, &bound, &motions);
    let names: Vec<String> = captures
        .iter()
        .filter_map(|p| p.file_name())
        .map(|n| n.to_string_lossy().into_owned())
        .collect();
    writeln!(
        std::io::stdout(),
        "# Calibrated on {} with `motionforge calibrate-mirror`.\n[reflections]",
        names.join(", ")
    )?;
    for (joint, r) in skeleton.joints.iter().zip(&reflections) {
        writeln!(
            std::io::stdout(),
            "{} = \"{}\"",
            joint.name,
            serde_json::to_value(r)?.as_str().unwrap_or_default()
        )?;
    }
    Ok(())
}

fn bench(data: &Path, profile: &str, repeat: usize) -> Result<()> {
    let spec = load_profile(profile)?;
    let mut files: Vec<PathBuf> = std::fs::read_dir(data)
        .with_context(|| format!("cannot list {}", data.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "bvh"))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("no .bvh files in {}", data.display());
    }
    let texts: Vec<String> = files
        .iter()
        .map(std::fs::read_to_string)
        .collect::<std::io::Result<_>>()?;
    let bytes: usize = texts.iter().map(String::len).sum();
    let first = read_bvh(&texts[0]).with_context(|| files[0].display().to_string())?;
    let plan = MirrorPlan::from_profile(&first.skeleton, &spec.bind(&first.skeleton)?)?;
    let (mut parse_s, mut fk_s, mut mirror_s, mut total_s) =
        (f64::INFINITY, f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut frames = 0usize;
    for _ in 0..repeat {
        let (mut p, mut f, mut m) = (0.0, 0.0, 0.0);
        frames = 0;
        for text in &texts {
            let t0 = std::time::Instant::now();
            let bvh = read_bvh(text)?;
            let t1 = std::time::Instant::now();
            let pose = bvh.motion.forward_kinematics();
            let t2 = std::time::Instant::now();
            let mirrored = plan.mirror(&bvh.motion, OffsetPolicy::Keep);
            let t3 = std::time::Instant::now();
            std::hint::black_box((&pose, &mirrored));
            frames += bvh.motion.num_frames();
            p += (t1 - t0).as_secs_f64();
            f += (t2 - t1).as_secs_f64();
            m += (t3 - t2).as_secs_f64();
        }
        parse_s = parse_s.min(p);
        fk_s = fk_s.min(f);
        mirror_s = mirror_s.min(m);
        total_s = total_s.min(p + f + m);
    }
    let mb = bytes as f64 / 1e6;
    writeln!(
        std::io::stdout(),
        "{} files, {frames} frames, {mb:.1} MB, one thread, best of {repeat}",
        files.len()
    )?;
    writeln!(
        std::io::stdout(),
        "read      {:>10.0} frames/s  {:>7.1} MB/s",
        frames as f64 / parse_s,
        mb / parse_s
    )?;
    writeln!(
        std::io::stdout(),
        "fk        {:>10.0} frames/s",
        frames as f64 / fk_s
    )?;
    writeln!(
        std::io::stdout(),
        "mirror    {:>10.0} frames/s",
        frames as f64 / mirror_s
    )?;
    writeln!(
        std::io::stdout(),
        "read+fk+mirror {:>10.0} frames/s  {:>7.1} MB/s",
        frames as f64 / total_s,
        mb / total_s
    )?;
    Ok(())
}

fn part_variant(name: &str) -> Result<PartPromptVariant> {
    PartPromptVariant::ALL
        .into_iter()
        .find(|v| v.as_str() == name)
        .with_context(|| {
            format!(
                "unknown part_labels variant `{name}` (expected list_few_shot, list or free_form)"
            )
        })
}

fn prompt_command(command: PromptCommand) -> Result<()> {
    let PromptCommand::Render {
        template,
        text,
        second,
        variant,
        n,
        prompts_dir,
    } = command;
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
            &motionforge::stages::label::normalize_text(
                second.as_deref().context("pair_compat needs --second")?,
            ),
        )?,
        other => {
            return Err(motionforge::llm::prompt::PromptError::Unknown(other.to_string()).into());
        }
    };
    let mut out = std::io::stdout().lock();
    out.write_all(rendered.as_bytes())?;
    Ok(())
}

fn labels_command(command: LabelsCommand, json: bool) -> Result<()> {
    match command {
        LabelsCommand::Import {
            file,
            config,
            answer,
            variant,
        } => {
            let config = Config::load(&config)?;
            let llm = config.llm.as_ref().context(
                "labels import needs an [llm] section naming the model whose answers these are (SINC: model = \"text-davinci-003\", kind = \"completion\", temperature = 0, max_tokens = 256)",
            )?;
            let prompts = config.prompts()?;
            let json = std::fs::read_to_string(&file)
                .with_context(|| format!("cannot read {}", file.display()))?;
            let cache_path = config.llm_cache_path();
            let mut cache = ResponseCache::open(&cache_path)
                .with_context(|| format!("{}", cache_path.display()))?;
            let report = motionforge::stages::label::import_answers(
                &json,
                &file.display().to_string(),
                answer,
                part_variant(&variant)?,
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
        }
        LabelsCommand::Eval {
            gold,
            sources,
            config,
        } => {
            let gold_text = std::fs::read_to_string(&gold)
                .with_context(|| format!("cannot read {}", gold.display()))?;
            let gold_set = motionforge::parts::eval::read_gold(&gold_text)
                .with_context(|| format!("{}", gold.display()))?;
            let mut rows: Vec<(String, motionforge::parts::eval::Evaluation)> = Vec::new();
            for source in &sources {
                let evaluation = match source.as_str() {
                    // Gold files hold texts only: an unknown text gets the lexicon's default, as a
                    // clip would without motion to look at.
                    "embedded" => motionforge::parts::eval::evaluate(&gold_set, |t| {
                        Some(motionforge::parts::lexicon::label_text(t).parts)
                    }),
                    "cache" => {
                        let config = Config::load(&config)?;
                        let llm = config
                            .llm
                            .as_ref()
                            .context("--source cache needs an [llm] section in the config")?;
                        let prompts = config.prompts()?;
                        let cache = ResponseCache::open(&config.llm_cache_path())?;
                        let variant = config.part_labels.variant;
                        motionforge::parts::eval::evaluate(&gold_set, |t| {
                            let prompt = prompts
                                .part_labels(
                                    &motionforge::stages::label::normalize_text(t),
                                    variant,
                                )
                                .ok()?;
                            let answer = cache.get(&llm.cache_key(&prompt))?;
                            let parsed = motionforge::parts::answer::parse_part_answer(answer);
                            (!parsed.empty).then_some(parsed.parts)
                        })
                    }
                    file => {
                        let text = std::fs::read_to_string(file)
                            .with_context(|| format!("cannot read answers file {file}"))?;
                        let map: std::collections::BTreeMap<String, Vec<String>> =
                            serde_json::from_str(&text).with_context(|| {
                                format!("{file}: expected {{text: [answer, ...]}}")
                            })?;
                        motionforge::parts::eval::evaluate(&gold_set, |t| {
                            let parsed =
                                motionforge::parts::answer::parse_part_answer(map.get(t)?.last()?);
                            (!parsed.empty).then_some(parsed.parts)
                        })
                    }
                };
                rows.push((source.clone(), evaluation));
            }
            let mut out = std::io::stdout().lock();
            if json {
                let value: serde_json::Value = rows
                    .iter()
                    .map(|(s, e)| (s.clone(), serde_json::to_value(e).unwrap_or_default()))
                    .collect::<serde_json::Map<_, _>>()
                    .into();
                writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
            } else {
                let table: Vec<(&str, &motionforge::parts::eval::Evaluation)> =
                    rows.iter().map(|(s, e)| (s.as_str(), e)).collect();
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
        }
    }
    Ok(())
}

fn export_bvh(
    path: &Path,
    clip_id: &str,
    output: Option<PathBuf>,
    offline: bool,
    wait: Option<Duration>,
    ui: &Ui,
) -> Result<()> {
    let config = load_checked(path, None)?;
    // The stages read and refresh the dataset's stage cache, which a running build is writing.
    let _lock = motionforge::build::lock::WorkspaceLock::acquire(&config.dataset_dir(), wait)?;
    let (found, ids) = motionforge::build::find_clip(
        &config,
        &BuildOptions {
            offline,
            ..BuildOptions::default()
        },
        clip_id,
    )?;
    let Some(clip) = found else {
        let near: Vec<&str> = ids
            .iter()
            .map(String::as_str)
            .filter(|id| id.contains(clip_id) || clip_id.contains(*id))
            .take(5)
            .collect();
        let hint = if near.is_empty() {
            String::new()
        } else {
            format!("; did you mean {}", near.join(", "))
        };
        bail!(
            "no clip `{clip_id}` in this build ({} clips){hint}",
            ids.len()
        );
    };
    let text = motionforge::motion::write_bvh(&clip.motion)
        .with_context(|| format!("clip `{clip_id}`"))?;
    let path = output
        .unwrap_or_else(|| PathBuf::from(format!("{}.bvh", clip_id.replace(['/', ':', '+'], "_"))));
    motionforge::build::write_atomic(&path, text.as_bytes())?;
    if ui.status() {
        writeln!(
            std::io::stdout(),
            "wrote {} ({} frames at {} fps, skeleton {})",
            path.display(),
            clip.motion.num_frames(),
            clip.motion.fps,
            clip.profile
        )?;
    }
    Ok(())
}

/// Peak resident memory of this process in kB (Linux `VmHWM`), if readable.
fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

fn bench_write(data: &Path, profile: &str, target_frames: usize) -> Result<()> {
    let work = std::env::temp_dir().join(format!("motionforge-bench-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    let data = std::path::absolute(data)?;
    let config_text = format!(
        "[dataset]\nname = \"bench\"\noutput = \"out\"\n\n[synthetic]\nenabled = false\n\n[[sources]]\nname = \"bench\"\ncaptures = [\"{}/*.bvh\"]\nprofile = \"{profile}\"\n[sources.labels]\nkind = \"filename\"\npattern = \"^(?P<name>.+)$\"\naction = \"{{name}}\"\ntext = \"{{name}}\"\n[sources.segment]\nmax_seconds = 600\n",
        data.display()
    );
    let config_path = work.join("bench.toml");
    std::fs::write(&config_path, config_text)?;
    let config = Config::load(&config_path)?;
    let base = motionforge::build::collect_clips(&config, &BuildOptions::default())?;
    let base_frames: usize = base.iter().map(|c| c.motion.num_frames()).sum();
    if base_frames == 0 {
        bail!("no frames in {}", data.display());
    }
    let copies = target_frames.div_ceil(base_frames);
    let spec = load_profile(profile)?;
    let mut profiles = std::collections::BTreeMap::new();
    profiles.insert(spec.name.clone(), spec.bind(&base[0].motion.skeleton)?);
    let features = motionforge::features::FeatureConfig::default();
    // Shards of about 64 MB of rows each, as a build would cut them.
    let mut shards: Vec<Vec<motionforge::clip::Clip>> = vec![Vec::new()];
    let mut size = 0u64;
    for k in 0..copies {
        for c in &base {
            let bytes = (c.motion.num_frames() * c.motion.num_joints() * 7 * 4) as u64;
            if size + bytes > 64 << 20 && shards.last().is_some_and(|s| !s.is_empty()) {
                shards.push(Vec::new());
                size = 0;
            }
            size += bytes;
            let mut clip = c.clone();
            clip.clip_id = format!("{}#{k}", c.clip_id);
            if let Some(s) = shards.last_mut() {
                s.push(clip);
            }
        }
    }
    let frames = base_frames * copies;
    let before = peak_rss_kb();
    // Reset the peak so what follows measures the write alone (Linux: 5 > clear_refs).
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    let start = std::time::Instant::now();
    let mut bytes = 0u64;
    for (i, shard) in shards.iter().enumerate() {
        let path = work.join(format!("shard-{i:05}.parquet"));
        let file = std::fs::File::create(&path)?;
        motionforge::io::parquet::write_clips(file, shard, &profiles, "{}", &features)?;
        bytes += std::fs::metadata(&path)?.len();
    }
    let seconds = start.elapsed().as_secs_f64();
    let peak = peak_rss_kb();
    let _ = std::fs::remove_dir_all(&work);
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "{} clips, {frames} frames ({copies} copies of {} frames), {} shards, {:.1} MB written, one thread",
        shards.iter().map(Vec::len).sum::<usize>(),
        base_frames,
        shards.len(),
        bytes as f64 / 1e6
    )?;
    writeln!(
        out,
        "write     {:>10.0} frames/s  {:>7.1} MB/s  ({seconds:.2} s)",
        frames as f64 / seconds,
        bytes as f64 / 1e6 / seconds
    )?;
    if let (Some(b), Some(p)) = (before, peak) {
        writeln!(
            out,
            "peak RSS  {:.0} MB before writing (clips in memory), {:.0} MB peak while writing",
            b as f64 / 1024.0,
            p as f64 / 1024.0
        )?;
    }
    Ok(())
}
