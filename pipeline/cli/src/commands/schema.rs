//! `schema`: the clip table's schema as JSON.

use std::process::ExitCode;

use anyhow::Result;

/// Print the clip table schema (columns, types, version) as JSON.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge schema > clips.schema.json"
))]
pub(crate) struct SchemaArgs {}

/// `motionforge schema`.
pub(crate) fn run(_: SchemaArgs) -> Result<ExitCode> {
    let schema = motionforge::io::schema::clip_schema_json();
    crate::ui::print_json(&schema)?;
    Ok(ExitCode::SUCCESS)
}
