//! `report`: the statistics report of a built dataset, from its shards and manifest alone.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;

use crate::ui::Ui;

/// Write the statistics report of a built dataset: tables (LaTeX, Markdown), figures (SVG,
/// PNG) and stats.json, from its shards and manifest alone.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge report out/demo
  motionforge report out/demo --output paper/figures"
))]
pub(crate) struct ReportArgs {
    /// The dataset folder (`<output>/<name>`, holding data/ and manifest.json).
    dataset: PathBuf,
    /// Where to write; default `<dataset>/report`.
    #[arg(long, short)]
    output: Option<PathBuf>,
}

/// `motionforge report`.
pub(crate) fn run(args: ReportArgs, ui: &Ui) -> Result<ExitCode> {
    let dataset = args.dataset;
    let files = motionforge::report::report_dataset(&dataset, args.output.as_deref())?;
    let output = args.output.unwrap_or_else(|| dataset.join("report"));
    if ui.json() {
        let value = serde_json::json!({
            "output": output,
            "files": files,
        });
        crate::ui::print_json(&value)?;
    } else if ui.status() {
        writeln!(
            std::io::stdout(),
            "wrote {} report files to {}",
            files.len(),
            output.display()
        )?;
    }
    Ok(ExitCode::SUCCESS)
}
