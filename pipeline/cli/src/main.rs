//! The `motionforge` command: parses the command line and runs one command (`commands/`).

use std::process::ExitCode;

use clap::Parser;

#[macro_use]
mod help;
mod commands;
mod error;
mod summary;
mod ui;

use commands::Command;
use error::CliError;
use ui::Ui;

// A build makes and frees many small values on every core (clip texts, decoded cache entries,
// Parquet pages); with mimalloc's per-thread heaps a full build of Bandai Namco 2 took about 5%
// less time and CPU than with glibc's allocator, for about 40 MB more peak memory
// (docs/performance.md).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Build text-to-motion training sets from mocap captures: segment, mirror, label, compose,
/// and write sharded Parquet with statistics for papers.
#[derive(Parser)]
#[command(
    name = "motionforge",
    version,
    about,
    long_about = None,
    propagate_version = true,
    after_help = examples_then_exit_codes!(
        "  motionforge build --config fixtures/demo.toml     # the demo dataset into out/demo/
  motionforge status --config fixtures/demo.toml    # what is built, rows per split"
    )
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Print only warnings and errors (no progress, no build summary).
    #[arg(long, short, global = true, conflicts_with = "verbose")]
    quiet: bool,
    /// Log more: -v adds debug lines (each stage's start, a line per item done, or per tenth of
    /// the items past ten, its time, and each line's fields), -vv trace lines, -vvv dependencies'
    /// lines too.
    #[arg(long, short, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    /// Machine-readable output: log lines as JSON objects on standard error, and results (the
    /// build report, label scores, config check) as JSON on standard output.
    #[arg(long, global = true)]
    json: bool,
}

fn main() -> ExitCode {
    ui::ignore_file_size_signal();
    let cli = Cli::parse();
    let ui = Ui::new(cli.quiet, cli.verbose, cli.json);
    let result = run(cli.command, &ui);
    ui.clear_bars();
    result.unwrap_or_else(|err| err.report(&ui))
}

/// Runs one command; a failure carries its exit code.
fn run(command: Command, ui: &Ui) -> Result<ExitCode, CliError> {
    use commands::*;
    Ok(match command {
        Command::Build(args) => build::build(args, ui)?,
        Command::Run(args) => build::run(args, ui)?,
        Command::Config(args) => config::run(args, ui)?,
        Command::Clean(args) => clean::run(args, ui)?,
        Command::Plan(args) => plan::plan(args, ui)?,
        Command::Status(args) => plan::status(args, ui)?,
        Command::MirrorText(args) => mirror::mirror_text(args)?,
        Command::CalibrateMirror(args) => mirror::calibrate_mirror(args)?,
        Command::ExportBvh(args) => export_bvh::run(args, ui)?,
        Command::Clips(args) => clips::run(args)?,
        Command::Preview(args) => preview::run(args, ui)?,
        Command::Export(args) => export::run(args, ui)?,
        Command::Report(args) => report::run(args, ui)?,
        Command::PlanSession(args) => plan_session::run(args, ui)?,
        Command::Schema(args) => schema::run(args)?,
        Command::Serve(args) => serve::serve(args)?,
        Command::ServeBuild(args) => serve::serve_build(args),
        Command::Prompt(args) => prompt::run(args)?,
        Command::Labels(args) => labels::run(args, ui)?,
        Command::Bench(args) => bench::run(args, ui)?,
    })
}
