//! How a run reports to whoever started it: log level and form, progress bars, status lines.

use std::io::IsTerminal;
use std::sync::Arc;

use motionforge::progress::ProgressSink;
use motionforge::terminal::{BarProgress, LogOptions, LogProgress};

/// Past a file size limit (`ulimit -f`), the kernel sends SIGXFSZ, whose default action kills
/// the process mid-write. Ignored, the write fails with EFBIG instead, which the build reports as
/// "File too large" (exit code 1) after removing its temporary file.
pub(crate) fn ignore_file_size_signal() {
    // SAFETY: setting a signal's disposition to SIG_IGN installs no handler code; it runs before
    // any other thread exists.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

/// How this run reports to whoever started it: log level and form, and progress bars.
pub(crate) struct Ui {
    pub(crate) log: LogOptions,
    bars: Option<Arc<BarProgress>>,
}

impl Ui {
    /// Sets up logging to standard error; bars only when it is a terminal and lines are not
    /// asked for.
    pub(crate) fn new(quiet: bool, verbose: u8, json: bool) -> Ui {
        let log = LogOptions {
            quiet,
            verbose,
            json,
        };
        // Commands that print a summary on standard output log finished stages at `debug` only.
        let summary_follows = !log.quiet && !log.json;
        let bars = log.bars(std::io::stderr().is_terminal()).then(|| {
            Arc::new(if summary_follows {
                BarProgress::before_summary()
            } else {
                BarProgress::new()
            })
        });
        let subscriber = match &bars {
            Some(b) => motionforge::terminal::subscriber(&log, b.log_writer()),
            None => motionforge::terminal::subscriber(&log, std::io::stderr),
        };
        // Only fails if a subscriber is already set, and none is: nothing to report.
        let _ = tracing::subscriber::set_global_default(subscriber);
        Ui { log, bars }
    }

    /// Where a build reports its stages.
    pub(crate) fn progress(&self) -> ProgressSink {
        match &self.bars {
            Some(bars) => ProgressSink::new(bars.clone()),
            None if self.status() && !self.log.json => {
                ProgressSink::new(Arc::new(LogProgress::before_summary()))
            }
            None => ProgressSink::new(Arc::new(LogProgress::new())),
        }
    }

    /// Whether status lines (the build summary, "wrote ..." lines) are printed.
    pub(crate) fn status(&self) -> bool {
        !self.log.quiet
    }

    /// Whether results are printed as JSON (`--json`): with [`print_json`].
    pub(crate) fn json(&self) -> bool {
        self.log.json
    }

    pub(crate) fn clear_bars(&self) {
        if let Some(bars) = &self.bars {
            bars.clear();
        }
    }
}

/// A command's result as JSON on standard output (`--json`): pretty-printed, one value, a newline.
pub(crate) fn print_json(value: &impl serde::Serialize) -> anyhow::Result<()> {
    use std::io::Write;
    writeln!(
        std::io::stdout(),
        "{}",
        serde_json::to_string_pretty(value)?
    )?;
    Ok(())
}
