//! The service's side of a build process ([`super::worker`] describes the protocol): start it,
//! turn its output into the build's log and progress, and tell how it ended.

use std::collections::VecDeque;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{ExitStatus, Stdio};
use std::sync::Mutex;
use std::time::Duration;

use tokio::io::{AsyncBufReadExt, AsyncRead, BufReader};
use tokio::process::Command;

use super::log::BuildLog;
use super::worker::{Event, Job, SUBCOMMAND, write_atomic};
use motionforge_core::progress::Progress;
use motionforge_runner::BuildReport;

/// Lines of the process's own output quoted in the error when it dies.
pub(crate) const LAST_LINES: usize = 20;
/// Longest line read from the process; the rest of a longer one is dropped.
const MAX_LINE_BYTES: usize = 64 * 1024;
/// How long to wait for the output pipes to close after the process ended (a process it started
/// may still hold them).
const DRAIN: Duration = Duration::from_secs(2);

/// How a build process ended.
#[derive(Debug)]
pub(crate) enum Ended {
    /// It wrote its report.
    Succeeded(Box<BuildReport>),
    /// It exited with an error, or could not be started, or gave no report.
    Failed(BuildFailure),
    /// A signal ended it.
    Killed {
        /// The signal number.
        signal: i32,
        /// What to record: the signal and the process's last lines.
        message: String,
    },
}

/// Why a build process failed (recorded in the build's history as these words).
#[derive(Debug, thiserror::Error)]
pub(crate) enum BuildFailure {
    /// The job file could not be written.
    #[error("cannot write the build job {}: {source}", job.display())]
    WriteJob {
        /// The job file.
        job: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The builder could not be started.
    #[error("cannot start the build process {}: {source}", builder.display())]
    Start {
        /// The builder executable.
        builder: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The process was started without its output pipes.
    #[error("the build process has no output pipes")]
    NoPipes,
    /// Waiting for the process failed.
    #[error("cannot wait for the build process: {0}")]
    Wait(#[source] std::io::Error),
    /// The process exited 0 without a readable report.
    #[error("the build process exited 0 but {problem}{last_lines}")]
    NoReport {
        /// What is wrong with the report.
        problem: ReportProblem,
        /// Its last output lines (see [`last_lines`]).
        last_lines: String,
    },
    /// The process said why it failed (its `failed` event).
    // The message of another process, which sends it as text.
    #[error("{0}")]
    Reported(String),
    /// The process exited non-zero without saying why.
    #[error("the build process exited with code {}{last_lines}", code.map_or_else(|| "an unknown status".to_string(), |c| c.to_string()))]
    Exited {
        /// Its exit code, `None` when it has none.
        code: Option<i32>,
        /// Its last output lines (see [`last_lines`]).
        last_lines: String,
    },
}

/// Why the report of a process that exited 0 cannot be used.
#[derive(Debug, thiserror::Error)]
pub(crate) enum ReportProblem {
    /// The report file cannot be read.
    #[error("its report {} is missing: {source}", path.display())]
    Missing {
        /// The report file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The report is not a build report.
    #[error("its report {} does not parse: {source}", path.display())]
    Parse {
        /// The report file.
        path: PathBuf,
        /// The error.
        source: serde_json::Error,
    },
}

/// The files of one build's job, removed when the build ends however it ends (a build cancelled
/// by the service's stop included).
struct JobFiles {
    job: PathBuf,
    report: PathBuf,
}

impl Drop for JobFiles {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.job);
        let _ = std::fs::remove_file(&self.report);
    }
}

/// What the output readers gathered.
#[derive(Debug, Default)]
struct Seen {
    /// The last lines of output (progress events as the log shows them).
    tail: VecDeque<String>,
    /// The message of a `failed` event.
    failure: Option<String>,
}

impl Seen {
    fn push(&mut self, line: String) {
        self.tail.push_back(line);
        while self.tail.len() > LAST_LINES {
            self.tail.pop_front();
        }
    }
}

/// Runs `job` in a process of `builder` and waits for it, feeding `log` as it reports. Dropping
/// the future kills the process.
pub(crate) async fn run(builder: &Path, jobs_dir: &Path, job: Job, log: &BuildLog) -> Ended {
    let files = JobFiles {
        job: jobs_dir.join(format!("{}.json", job.build)),
        report: job.report.clone(),
    };
    let _ = std::fs::remove_file(&files.report);
    let written = serde_json::to_vec(&job)
        .map_err(std::io::Error::other)
        .and_then(|json| write_atomic(&files.job, &json));
    if let Err(source) = written {
        return Ended::Failed(BuildFailure::WriteJob {
            job: files.job.clone(),
            source,
        });
    }

    let mut command = Command::new(builder);
    command
        .arg(SUBCOMMAND)
        .arg("--job")
        .arg(&files.job)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        // The service stops it (or it stops itself when its standard input closes); its own
        // process group keeps a Ctrl-C at the service's terminal from reaching it first.
        .process_group(0)
        .kill_on_drop(true);
    let mut child = match command.spawn() {
        Ok(child) => child,
        Err(source) => {
            return Ended::Failed(BuildFailure::Start {
                builder: builder.to_path_buf(),
                source,
            });
        }
    };
    // Held open until the process has ended: its end of file tells the process the service is
    // gone. (`Child::wait` would close it if it were left in `child`.)
    let stdin = child.stdin.take();
    let (Some(stdout), Some(stderr)) = (child.stdout.take(), child.stderr.take()) else {
        return Ended::Failed(BuildFailure::NoPipes);
    };

    let seen = Mutex::new(Seen::default());
    let reading = async {
        tokio::join!(
            read_lines(stdout, |line| on_stdout(line, log, &seen)),
            read_lines(stderr, |line| on_text(line, log, &seen)),
        );
    };
    tokio::pin!(reading);
    let mut read_all = false;
    let status = tokio::select! {
        status = child.wait() => status,
        () = &mut reading => {
            read_all = true;
            child.wait().await
        }
    };
    if !read_all {
        let _ = tokio::time::timeout(DRAIN, &mut reading).await;
    }
    drop(stdin);
    let seen = std::mem::take(&mut *seen.lock().unwrap_or_else(|e| e.into_inner()));

    match status {
        Err(e) => Ended::Failed(BuildFailure::Wait(e)),
        Ok(status) if status.success() => match read_report(&files.report) {
            Ok(report) => Ended::Succeeded(Box::new(report)),
            Err(problem) => Ended::Failed(BuildFailure::NoReport {
                problem,
                last_lines: last_lines(&seen),
            }),
        },
        Ok(status) => ended_badly(status, seen),
    }
}

fn read_report(path: &Path) -> Result<BuildReport, ReportProblem> {
    let bytes = std::fs::read(path).map_err(|source| ReportProblem::Missing {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_slice(&bytes).map_err(|source| ReportProblem::Parse {
        path: path.to_path_buf(),
        source,
    })
}

/// The record of a process that exited non-zero or was killed.
fn ended_badly(status: ExitStatus, seen: Seen) -> Ended {
    if let Some(signal) = status.signal() {
        let core = if status.core_dumped() {
            ", core dumped"
        } else {
            ""
        };
        return Ended::Killed {
            signal,
            message: format!(
                "the build process was killed by signal {signal} ({}{core}){}",
                signal_name(signal),
                last_lines(&seen)
            ),
        };
    }
    match seen.failure {
        Some(message) => Ended::Failed(BuildFailure::Reported(message)),
        None => Ended::Failed(BuildFailure::Exited {
            code: status.code(),
            last_lines: last_lines(&seen),
        }),
    }
}

/// `; its last output lines:` and the lines, one per line, or a note that there were none.
fn last_lines(seen: &Seen) -> String {
    if seen.tail.is_empty() {
        return "; it printed nothing".to_string();
    }
    let mut text = format!("; its last {} output lines:", seen.tail.len());
    for line in &seen.tail {
        text.push('\n');
        text.push_str(line);
    }
    text
}

/// The usual name of a Unix signal.
pub(crate) fn signal_name(signal: i32) -> String {
    let name = match signal {
        1 => "SIGHUP",
        2 => "SIGINT",
        3 => "SIGQUIT",
        4 => "SIGILL",
        5 => "SIGTRAP",
        6 => "SIGABRT",
        7 => "SIGBUS",
        8 => "SIGFPE",
        9 => "SIGKILL",
        10 => "SIGUSR1",
        11 => "SIGSEGV",
        12 => "SIGUSR2",
        13 => "SIGPIPE",
        14 => "SIGALRM",
        15 => "SIGTERM",
        24 => "SIGXCPU",
        25 => "SIGXFSZ",
        31 => "SIGSYS",
        _ => return format!("signal {signal}"),
    };
    name.to_string()
}

/// True for the signals that ask a process to stop (rather than report a fault).
pub(crate) fn is_stop_request(signal: i32) -> bool {
    matches!(signal, 1 | 2 | 15)
}

fn on_stdout(line: &str, log: &BuildLog, seen: &Mutex<Seen>) {
    let event = line
        .starts_with("{")
        .then(|| serde_json::from_str::<Event>(line).ok())
        .flatten();
    let Some(event) = event else {
        on_text(line, log, seen);
        return;
    };
    let shown = match event {
        Event::StageStarted { stage, total } => {
            log.stage_started(&stage, total);
            format!("{stage}: started, {total} items")
        }
        Event::Advanced { stage, n } => {
            log.advanced(&stage, n);
            return;
        }
        Event::StageFinished { stage, ran, reused } => {
            log.stage_finished(&stage, ran, reused);
            format!("{stage}: finished, {ran} ran, {reused} reused")
        }
        Event::Note { message } => {
            log.note(&message);
            message
        }
        Event::Failed { message } => {
            seen.lock().unwrap_or_else(|e| e.into_inner()).failure = Some(message);
            return;
        }
        Event::Succeeded => return,
    };
    seen.lock().unwrap_or_else(|e| e.into_inner()).push(shown);
}

fn on_text(line: &str, log: &BuildLog, seen: &Mutex<Seen>) {
    if line.trim().is_empty() {
        return;
    }
    log.line(line);
    seen.lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(line.to_string());
}

/// Calls `each` with every line of `reader` (without its line end, invalid UTF-8 replaced, cut
/// at [`MAX_LINE_BYTES`]) until end of file or a read error.
async fn read_lines(reader: impl AsyncRead + Unpin, mut each: impl FnMut(&str)) {
    let mut reader = BufReader::new(reader);
    let mut line: Vec<u8> = Vec::new();
    loop {
        let (used, complete) = match reader.fill_buf().await {
            Ok([]) | Err(_) => break,
            Ok(buf) => {
                let (chunk, used, complete) = match buf.iter().position(|&b| b == b'\n') {
                    Some(i) => (&buf[..i], i + 1, true),
                    None => (buf, buf.len(), false),
                };
                let room = MAX_LINE_BYTES.saturating_sub(line.len());
                line.extend_from_slice(&chunk[..chunk.len().min(room)]);
                (used, complete)
            }
        };
        reader.consume(used);
        if complete {
            each(String::from_utf8_lossy(&line).trim_end_matches('\r'));
            line.clear();
        }
    }
    if !line.is_empty() {
        each(String::from_utf8_lossy(&line).trim_end_matches('\r'));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn lines_are_split_cut_and_the_last_one_kept_without_its_end() {
        let mut input = b"one\r\ntwo\n".to_vec();
        input.extend(std::iter::repeat_n(b'x', MAX_LINE_BYTES + 10));
        input.extend(b"\n\xffbad\nlast");
        let mut lines = Vec::new();
        read_lines(&input[..], |l| lines.push(l.to_string())).await;
        assert_eq!(lines.len(), 5, "{:?}", &lines[..2]);
        assert_eq!((lines[0].as_str(), lines[1].as_str()), ("one", "two"));
        assert_eq!(lines[2].len(), MAX_LINE_BYTES);
        assert_eq!(lines[3], "\u{fffd}bad");
        assert_eq!(lines[4], "last");
    }

    #[test]
    fn output_becomes_progress_log_lines_and_the_tail() {
        let log = BuildLog::new();
        let seen = Mutex::new(Seen::default());
        on_stdout(
            r#"{"event":"stage_started","stage":"ingest","total":9}"#,
            &log,
            &seen,
        );
        on_stdout(
            r#"{"event":"advanced","stage":"ingest","n":4}"#,
            &log,
            &seen,
        );
        on_stdout("plain words", &log, &seen);
        on_stdout(
            r#"{"event":"failed","message":"no such skeleton"}"#,
            &log,
            &seen,
        );
        on_text("thread 'main' panicked", &log, &seen);
        assert_eq!(log.stages()[0].done, 4);
        assert_eq!(
            log.lines(),
            vec![
                "ingest: started, 9 items",
                "plain words",
                "thread 'main' panicked"
            ]
        );
        let seen = seen.into_inner().unwrap();
        assert_eq!(seen.failure.as_deref(), Some("no such skeleton"));
        assert_eq!(seen.tail.len(), 3);
    }

    #[test]
    fn a_killed_process_is_named_by_its_signal_with_its_last_lines() {
        let mut seen = Seen::default();
        for i in 0..LAST_LINES + 3 {
            seen.push(format!("line {i}"));
        }
        let Ended::Killed { signal, message } = ended_badly(ExitStatus::from_raw(6), seen) else {
            panic!("not killed");
        };
        assert_eq!(signal, 6);
        assert!(
            message.starts_with("the build process was killed by signal 6 (SIGABRT)"),
            "{message}"
        );
        assert!(message.ends_with("\nline 22"), "{message}");
        assert!(
            !message.contains("line 2\n"),
            "only the last lines: {message}"
        );
        // Exit code 3 (a wait status holds it shifted by 8), no failed event: the code and tail.
        let Ended::Failed(failure) = ended_badly(ExitStatus::from_raw(3 << 8), Seen::default())
        else {
            panic!("not failed");
        };
        assert_eq!(
            failure.to_string(),
            "the build process exited with code 3; it printed nothing"
        );
    }
}
