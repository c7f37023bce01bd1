//! The process that runs one build for the service (`motionforge serve-build --job <file>`), and
//! the protocol between the two.
//!
//! The service runs every build in a child process of its own binary, so a build that aborts
//! (an allocation failure, a stack overflow, a bug in a dependency) ends that process, not the
//! service. The protocol:
//!
//! - the service writes a [`Job`] as JSON into its state folder and starts the child with
//!   `serve-build --job <file>`, its standard input a pipe it keeps open;
//! - the child reports on standard output, one JSON [`Event`] per line; anything else it prints
//!   (on either stream) is a log line;
//! - on success it writes the build report as JSON to `Job::report`, prints
//!   [`Event::Succeeded`] and exits 0; on failure it prints [`Event::Failed`] and exits 1;
//! - when its standard input reaches end of file the service is gone, and the child exits
//!   rather than build on for no one.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};

use super::history::BuildId;
use motionforge_core::progress::{Progress, ProgressSink};
use motionforge_runner::config::Config;
use motionforge_runner::{BuildError, BuildOptions, build};

/// The hidden subcommand of the binary that runs a [`Job`].
pub const SUBCOMMAND: &str = "serve-build";

/// How long a build process waits for the dataset folder's lock. The service runs one build of
/// a dataset at a time, so a holder is a build process of a service that was killed (it exits
/// once it sees its standard input close, a fraction of a second later, but a service restarted
/// at once starts its resume build before that) or a build started by hand.
pub const LOCK_WAIT: std::time::Duration = std::time::Duration::from_secs(60);

/// What the child needs to run one build.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Job {
    /// The build's id in the service's history (for messages).
    pub build: BuildId,
    /// The dataset's config.
    pub config: Config,
    /// The config's folder, which relative paths resolve against (not part of the config's
    /// serialised form).
    pub base_dir: PathBuf,
    /// Recompute everything.
    pub force: bool,
    /// Send no LLM request.
    pub offline: bool,
    /// Where to write the build report on success.
    pub report: PathBuf,
}

impl Job {
    /// The config as the service loaded it.
    pub fn config(&self) -> Config {
        let mut config = self.config.clone();
        config.base_dir = self.base_dir.clone();
        config
    }
}

/// One line of the child's standard output.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    /// See [`Progress::stage_started`].
    StageStarted {
        /// Stage name.
        stage: String,
        /// Items it covers.
        total: u64,
    },
    /// See [`Progress::advanced`].
    Advanced {
        /// Stage name.
        stage: String,
        /// Items done since the last event.
        n: u64,
    },
    /// See [`Progress::stage_finished`].
    StageFinished {
        /// Stage name.
        stage: String,
        /// Items computed.
        ran: u64,
        /// Items reused from the cache.
        reused: u64,
    },
    /// See [`Progress::note`].
    Note {
        /// The line.
        message: String,
    },
    /// The build failed; the child exits 1 after this line.
    Failed {
        /// The error and its causes, on one line.
        message: String,
    },
    /// The report is written; the child exits 0 after this line.
    Succeeded,
}

/// Why the child could not run its build.
#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    /// The job file cannot be read.
    #[error("cannot read build job {path}: {source}")]
    ReadJob {
        /// The job file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The job file is not a job (written by another version of motionforge?).
    #[error("build job {path} is not valid: {source}")]
    ParseJob {
        /// The job file.
        path: PathBuf,
        /// The JSON error.
        source: serde_json::Error,
    },
    /// The build failed.
    #[error(transparent)]
    Build(#[from] BuildError),
    /// The report cannot be written.
    #[error("cannot write the build report {path}: {source}")]
    WriteReport {
        /// The report file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// Writes events to standard output, one whole line at a time (progress comes from several
/// threads). A closed pipe is ignored here: the standard input watch ends the process.
#[derive(Debug, Default)]
struct EventWriter {
    out: Mutex<()>,
}

impl EventWriter {
    fn send(&self, event: &Event) {
        let Ok(mut line) = serde_json::to_vec(event) else {
            return;
        };
        line.push(b'\n');
        let _guard = self.out.lock().unwrap_or_else(|e| e.into_inner());
        let mut out = std::io::stdout().lock();
        let _ = out.write_all(&line).and_then(|()| out.flush());
    }
}

impl Progress for EventWriter {
    fn stage_started(&self, stage: &str, total: u64) {
        self.send(&Event::StageStarted {
            stage: stage.to_string(),
            total,
        });
    }

    fn advanced(&self, stage: &str, n: u64) {
        self.send(&Event::Advanced {
            stage: stage.to_string(),
            n,
        });
    }

    fn stage_finished(&self, stage: &str, ran: u64, reused: u64) {
        self.send(&Event::StageFinished {
            stage: stage.to_string(),
            ran,
            reused,
        });
    }

    fn note(&self, message: &str) {
        self.send(&Event::Note {
            message: message.to_string(),
        });
    }
}

/// Reads a job file.
pub fn read_job(path: &Path) -> Result<Job, WorkerError> {
    let text = std::fs::read(path).map_err(|source| WorkerError::ReadJob {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_slice(&text).map_err(|source| WorkerError::ParseJob {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes `bytes` to `path` through a temporary file beside it, so the service never reads half
/// a file.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut temp = path.as_os_str().to_owned();
    temp.push(".tmp");
    let temp = PathBuf::from(temp);
    std::fs::write(&temp, bytes)?;
    std::fs::rename(&temp, path)
}

fn run_job(job_file: &Path, events: &Arc<EventWriter>) -> Result<(), WorkerError> {
    let job = read_job(job_file)?;
    let options = BuildOptions {
        force: job.force,
        offline: job.offline,
        progress: ProgressSink::new(events.clone()),
        lock_wait: Some(LOCK_WAIT),
        ..BuildOptions::default()
    };
    let report = build(&job.config(), &options)?;
    let json = serde_json::to_vec(&report).map_err(|e| WorkerError::WriteReport {
        path: job.report.clone(),
        source: std::io::Error::other(e),
    })?;
    write_atomic(&job.report, &json).map_err(|source| WorkerError::WriteReport {
        path: job.report.clone(),
        source,
    })
}

/// Ends the process once standard input reaches end of file: the service holds the other end,
/// so that means it is gone (even killed with SIGKILL, which no handler sees).
fn exit_when_orphaned() {
    let spawned = std::thread::Builder::new()
        .name("serve-build-stdin".into())
        .spawn(|| {
            let mut stdin = std::io::stdin().lock();
            let mut buf = [0u8; 256];
            loop {
                match stdin.read(&mut buf) {
                    Ok(0) => break,
                    Ok(_) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(_) => break,
                }
            }
            // Not `eprintln!`: standard error is a pipe to the service too, closed now, and
            // its panic would end this thread instead of the process, leaving the build to run
            // on, holding the dataset's lock, for no one.
            let _ = writeln!(
                std::io::stderr(),
                "motionforge serve-build: the service is gone; stopping the build"
            );
            std::process::exit(1);
        });
    if let Err(e) = spawned {
        // Not fatal: the service still kills the build when it stops cleanly.
        let _ = writeln!(
            std::io::stderr(),
            "motionforge serve-build: cannot watch standard input: {e}"
        );
    }
}

/// The `serve-build` subcommand: runs the job in `job_file`, reporting as the module describes.
/// Exits 0 when the report is written, 1 otherwise.
pub fn main(job_file: &Path) -> ExitCode {
    exit_when_orphaned();
    let events = Arc::new(EventWriter::default());
    match run_job(job_file, &events) {
        Ok(()) => {
            events.send(&Event::Succeeded);
            ExitCode::SUCCESS
        }
        Err(err) => {
            events.send(&Event::Failed {
                message: error_chain(&err),
            });
            ExitCode::from(1)
        }
    }
}

/// The error and its causes on one line, skipping causes its message already quotes.
pub(crate) fn error_chain(err: &dyn std::error::Error) -> String {
    let mut message = err.to_string();
    let mut cause = err.source();
    while let Some(c) = cause {
        let text = c.to_string();
        if !message.contains(&text) {
            message = format!("{message}: {text}");
        }
        cause = c.source();
    }
    message
}

#[cfg(test)]
mod tests {
    use super::*;

    fn repo() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
    }

    #[test]
    fn a_job_carries_the_config_exactly() {
        // The child must build what the service loaded: same values, same fingerprints.
        for file in ["fixtures/demo.toml", "docs/examples/sinc-labels.toml"] {
            let config = Config::load(&repo().join(file)).unwrap();
            let job = Job {
                build: 7,
                config: config.clone(),
                base_dir: config.base_dir.clone(),
                force: true,
                offline: false,
                report: "r.json".into(),
            };
            let back: Job = serde_json::from_str(&serde_json::to_string(&job).unwrap()).unwrap();
            let mut expected = config;
            // When to build is not part of what to build, and the child has no use for it.
            expected.dataset.schedule = None;
            assert_eq!(back.config(), expected, "{file}");
        }
    }

    #[test]
    fn events_are_tagged_json_lines() {
        let line = serde_json::to_string(&Event::StageFinished {
            stage: "ingest".into(),
            ran: 3,
            reused: 6,
        })
        .unwrap();
        assert_eq!(
            line,
            r#"{"event":"stage_finished","stage":"ingest","ran":3,"reused":6}"#
        );
        assert_eq!(
            serde_json::from_str::<Event>(r#"{"event":"succeeded"}"#).unwrap(),
            Event::Succeeded
        );
        assert!(serde_json::from_str::<Event>("ingest: started").is_err());
    }
}
