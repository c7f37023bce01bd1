//! `serve` (the HTTP service) and `serve-build` (one of its builds, in a process of its own).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;

/// Serve an HTTP API that builds the datasets on request and on their `dataset.schedule`,
/// one build at a time per dataset, with the run history kept across restarts
/// (docs/service.md). Calls that change state need `Authorization: Bearer <token>`.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  MOTIONFORGE_TOKEN=$(openssl rand -hex 16) motionforge serve --config fixtures/demo.toml"
))]
pub(crate) struct ServeArgs {
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
}

#[derive(clap::Args)]
pub(crate) struct ServeBuildArgs {
    /// The job file the service wrote.
    #[arg(long)]
    job: PathBuf,
}

/// `motionforge serve`.
pub(crate) fn serve(args: ServeArgs) -> Result<ExitCode> {
    motionforge::serve::run(&motionforge::serve::ServeCommand {
        configs: args.config,
        bind: args.bind,
        state_dir: args.state,
        token_env: args.token_env,
        // Builds run in processes of this very binary, so service and builds agree.
        builder: std::env::current_exe()
            .map_err(|e| anyhow::anyhow!("cannot find this program's own path: {e}"))?,
    })?;
    Ok(ExitCode::SUCCESS)
}

/// `motionforge serve-build`: the worker's own exit code.
pub(crate) fn serve_build(args: ServeBuildArgs) -> ExitCode {
    motionforge::serve::worker::main(&args.job)
}
