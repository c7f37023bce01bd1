//! A failed command and its exit code (docs/reference.md, "Exit codes").

use std::error::Error;
use std::process::ExitCode;

use motionforge::build::BuildError;
use motionforge::build::clean::CleanError;
use motionforge::export::ExportError;
use motionforge::report::ReportError;

use crate::ui::Ui;

/// Exit code of a failure: a file that cannot be read or written, a held dataset folder...
pub(crate) const FAILURE: u8 = 1;
/// Exit code of a usage or config mistake, as clap's own.
pub(crate) const USAGE: u8 = 2;

/// A failed command: the error and the exit code it ends the program with (as cargo's
/// `CliError`).
pub(crate) struct CliError {
    error: anyhow::Error,
    code: u8,
}

/// A mistake in how a command was called that clap cannot see (a value valid only for the
/// dataset at hand, an option another one requires): exit code 2, as clap's own.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub(crate) struct UsageError(pub(crate) String);

/// The exit code an error stands for, by the kind of mistake it is.
trait ExitStatus: Error + 'static {
    fn exit_code(&self) -> u8 {
        USAGE
    }
}

// Mistakes in the config, in what it names, or in how the command was called.
impl ExitStatus for motionforge::config::ConfigError {}
impl ExitStatus for motionforge::source::SourceError {}
impl ExitStatus for motionforge::annotate::taxonomy::TaxonomyError {}
impl ExitStatus for motionforge::motion::profile::ProfileError {}
impl ExitStatus for motionforge::llm::prompt::PromptError {}
impl ExitStatus for motionforge::planner::SceneError {}
impl ExitStatus for motionforge::planner::PlanError {}
impl ExitStatus for UsageError {}
// An output that would replace or write into a folder the user keeps.
impl ExitStatus for motionforge::base::guard::Refused {}

impl ExitStatus for CleanError {
    fn exit_code(&self) -> u8 {
        match self {
            CleanError::NotADataset { .. } | CleanError::Refused(_) => USAGE,
            _ => FAILURE,
        }
    }
}

impl ExitStatus for ExportError {
    fn exit_code(&self) -> u8 {
        match self {
            ExportError::Refused(_) | ExportError::NotAnExport { .. } => USAGE,
            _ => FAILURE,
        }
    }
}

impl ExitStatus for ReportError {
    fn exit_code(&self) -> u8 {
        match self {
            ReportError::Refused(_) => USAGE,
            _ => FAILURE,
        }
    }
}

impl ExitStatus for BuildError {
    fn exit_code(&self) -> u8 {
        match self {
            BuildError::Source(_)
            | BuildError::Refused(_)
            | BuildError::Taxonomy(_)
            | BuildError::Prompt(_)
            | BuildError::Split(_) => USAGE,
            _ => FAILURE,
        }
    }
}

/// `error` as one of the types above, if it is one.
fn exit_status<'e>(error: &'e (dyn Error + 'static)) -> Option<&'e dyn ExitStatus> {
    fn of<'e, T: ExitStatus>(error: &'e (dyn Error + 'static)) -> Option<&'e dyn ExitStatus> {
        error.downcast_ref::<T>().map(|e| e as &dyn ExitStatus)
    }
    type Of = for<'e> fn(&'e (dyn Error + 'static)) -> Option<&'e dyn ExitStatus>;
    const TYPES: [Of; 13] = [
        of::<motionforge::config::ConfigError>,
        of::<motionforge::source::SourceError>,
        of::<motionforge::annotate::taxonomy::TaxonomyError>,
        of::<motionforge::motion::profile::ProfileError>,
        of::<motionforge::llm::prompt::PromptError>,
        of::<motionforge::planner::SceneError>,
        of::<motionforge::planner::PlanError>,
        of::<UsageError>,
        of::<motionforge::base::guard::Refused>,
        of::<CleanError>,
        of::<ExportError>,
        of::<ReportError>,
        of::<BuildError>,
    ];
    TYPES.iter().find_map(|of| of(error))
}

impl From<anyhow::Error> for CliError {
    /// A usage mistake anywhere in the error's causes (a config error inside a build error, say)
    /// makes the whole a usage mistake; anything else is a failure.
    fn from(error: anyhow::Error) -> Self {
        let usage = error
            .chain()
            .filter_map(exit_status)
            .any(|e| e.exit_code() == USAGE);
        let code = if usage { USAGE } else { FAILURE };
        CliError { error, code }
    }
}

impl CliError {
    /// Prints the error on standard error (a JSON line with `--json`) and gives its exit code.
    pub(crate) fn report(self, ui: &Ui) -> ExitCode {
        // A closed pipe (`motionforge mirror-text | head`) is not an error worth reporting.
        if self.error.chain().any(|e| {
            e.downcast_ref::<std::io::Error>()
                .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
        }) {
            return ExitCode::SUCCESS;
        }
        let message = self.message();
        if ui.json() {
            tracing::error!(exit_code = self.code, "{message}");
        } else {
            eprintln!("error: {message}");
        }
        ExitCode::from(self.code)
    }

    /// The error and its causes on one line, skipping causes the message already quotes.
    fn message(&self) -> String {
        let mut message = self.error.to_string();
        for cause in self.error.chain().skip(1) {
            let text = cause.to_string();
            if !message.contains(&text) {
                message = format!("{message}: {text}");
            }
        }
        message
    }
}
