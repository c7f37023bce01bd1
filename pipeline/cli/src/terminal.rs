//! What a command-line run shows while it works: log lines (plain or JSON, through `tracing`) and
//! stage progress (bars on a terminal, log lines elsewhere).
//!
//! Everything here writes to standard error, so standard output stays free for results (the build
//! summary, `--json` reports, rendered prompts).

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Write;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::Layer;
use tracing_subscriber::filter::{LevelFilter, Targets};
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::{self, FmtContext, FormatEvent, FormatFields, MakeWriter};
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::registry::LookupSpan;

use crate::progress::Progress;

/// Log target of stage progress events.
pub const PROGRESS_TARGET: &str = "motionforge::progress";

/// How much to log, and in which form.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LogOptions {
    /// `-q`: warnings and errors only.
    pub quiet: bool,
    /// `-v` count: 1 debug, 2 trace, 3 trace from dependencies too.
    pub verbose: u8,
    /// `--json`: one JSON object per line instead of plain text.
    pub json: bool,
}

impl LogOptions {
    /// The level of motionforge's own events.
    pub fn level(&self) -> LevelFilter {
        match (self.quiet, self.verbose) {
            (true, _) => LevelFilter::WARN,
            (false, 0) => LevelFilter::INFO,
            (false, 1) => LevelFilter::DEBUG,
            _ => LevelFilter::TRACE,
        }
    }

    /// Whether stage progress should be drawn as bars, given whether standard error is a
    /// terminal: never in JSON or quiet mode, where lines (or nothing) are wanted.
    pub fn bars(&self, stderr_is_terminal: bool) -> bool {
        stderr_is_terminal && !self.json && !self.quiet
    }
}

/// A subscriber that writes motionforge's events at the chosen level (and dependencies' warnings
/// and errors, all of their events at `-vvv`) to `writer`.
pub fn subscriber<W>(options: &LogOptions, writer: W) -> Box<dyn Subscriber + Send + Sync>
where
    W: for<'a> MakeWriter<'a> + Send + Sync + 'static,
{
    let others = if options.verbose >= 3 {
        LevelFilter::TRACE
    } else {
        LevelFilter::WARN.min(options.level())
    };
    let filter = Targets::new()
        .with_default(others)
        .with_target("motionforge", options.level());
    let layer = if options.json {
        fmt::layer()
            .json()
            .flatten_event(true)
            .with_current_span(false)
            .with_span_list(false)
            .with_writer(writer)
            .boxed()
    } else {
        fmt::layer()
            .event_format(Plain {
                fields: options.verbose > 0,
            })
            .with_writer(writer)
            .boxed()
    };
    Box::new(tracing_subscriber::registry().with(layer.with_filter(filter)))
}

/// Plain lines: the message, prefixed by the level unless it is info, and with the event's
/// fields in parentheses when verbose.
struct Plain {
    fields: bool,
}

impl<S, N> FormatEvent<S, N> for Plain
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        _ctx: &FmtContext<'_, S, N>,
        mut writer: Writer<'_>,
        event: &Event<'_>,
    ) -> std::fmt::Result {
        let mut fields = Fields::default();
        event.record(&mut fields);
        let prefix = match *event.metadata().level() {
            Level::ERROR => "error: ",
            Level::WARN => "warning: ",
            Level::INFO => "",
            Level::DEBUG => "debug: ",
            Level::TRACE => "trace: ",
        };
        write!(writer, "{prefix}{}", fields.message)?;
        if self.fields && !fields.rest.is_empty() {
            write!(writer, " ({})", fields.rest.join(", "))?;
        }
        writeln!(writer)
    }
}

#[derive(Default)]
struct Fields {
    message: String,
    rest: Vec<String>,
}

impl Visit for Fields {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.message = value.to_string();
        } else {
            self.rest.push(format!("{}={value:?}", field.name()));
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.message, "{value:?}");
        } else {
            self.rest.push(format!("{}={value:?}", field.name()));
        }
    }
}

/// One stage's counts.
struct StageState {
    started: Instant,
    total: u64,
    done: u64,
    /// Last tenth of the total reported, so long stages log at most ten progress lines.
    tenth: u64,
    /// Items that failed.
    errors: u64,
    /// An LLM stage: its progress lines are info lines with the rate, errors and ETA, every tenth
    /// and at least every [`REQUEST_LOG_INTERVAL`], because requests can be slow.
    requests: bool,
    last_line: Instant,
}

/// Longest silence between two progress lines of an LLM stage.
const REQUEST_LOG_INTERVAL: Duration = Duration::from_secs(10);

impl StageState {
    fn new(total: u64, requests: bool) -> StageState {
        let now = Instant::now();
        StageState {
            started: now,
            total,
            done: 0,
            tenth: 0,
            errors: 0,
            requests,
            last_line: now,
        }
    }

    /// `3 of 9 requests, 0.4/s, 1 error, ETA 15 s`.
    fn request_line(&self) -> String {
        let seconds = self.started.elapsed().as_secs_f64();
        let rate = if seconds > 0.0 {
            self.done as f64 / seconds
        } else {
            0.0
        };
        let left = self.total.saturating_sub(self.done);
        let eta = if rate > 0.0 {
            format!("ETA {:.0} s", left as f64 / rate)
        } else {
            "ETA unknown".to_string()
        };
        format!(
            "{} of {} requests, {rate:.2}/s, {} error{}, {eta}",
            self.done,
            self.total,
            self.errors,
            if self.errors == 1 { "" } else { "s" }
        )
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic elsewhere must not silence progress: the counts are still usable.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Stage progress as log events: one `info` line when a stage finishes (with its counts and
/// time), `debug` lines when it starts and at every tenth of its items.
#[derive(Default)]
pub struct LogProgress {
    stages: Mutex<HashMap<String, StageState>>,
    /// Finished-stage lines at `debug` rather than `info`: a summary on standard output follows
    /// and says the same, so a plain run shows one summary, not two.
    summary_follows: bool,
}

impl LogProgress {
    /// A reporter with no stage started.
    pub fn new() -> LogProgress {
        LogProgress::default()
    }

    /// A reporter whose finished-stage lines are `debug` (shown with `-v`), for runs that print
    /// a summary of the stages afterwards.
    pub fn before_summary() -> LogProgress {
        LogProgress {
            summary_follows: true,
            ..LogProgress::default()
        }
    }
}

impl Progress for LogProgress {
    fn stage_started(&self, stage: &str, total: u64) {
        lock(&self.stages).insert(stage.to_string(), StageState::new(total, false));
        tracing::debug!(target: PROGRESS_TARGET, stage, total, "{stage}: started, {total} items");
    }

    fn requests_started(&self, stage: &str, total: u64) {
        lock(&self.stages).insert(stage.to_string(), StageState::new(total, true));
        tracing::info!(target: PROGRESS_TARGET, stage, total, "{stage}: sending {total} LLM requests");
    }

    fn failed(&self, stage: &str, n: u64) {
        if let Some(s) = lock(&self.stages).get_mut(stage) {
            s.errors += n;
        }
    }

    fn advanced(&self, stage: &str, n: u64) {
        let mut stages = lock(&self.stages);
        let Some(s) = stages.get_mut(stage) else {
            return;
        };
        s.done += n;
        if s.total == 0 {
            return;
        }
        if s.requests {
            let tenth = (s.done.min(s.total) * 10) / s.total;
            if (tenth > s.tenth || s.last_line.elapsed() >= REQUEST_LOG_INTERVAL)
                && s.done < s.total
            {
                s.tenth = tenth;
                s.last_line = Instant::now();
                let (done, total, errors, line) = (s.done, s.total, s.errors, s.request_line());
                drop(stages);
                tracing::info!(target: PROGRESS_TARGET, stage, done, total, errors, "{stage}: {line}");
            }
            return;
        }
        let tenth = (s.done.min(s.total) * 10) / s.total;
        if tenth > s.tenth && s.done < s.total {
            s.tenth = tenth;
            let (done, total) = (s.done, s.total);
            drop(stages);
            tracing::debug!(target: PROGRESS_TARGET, stage, done, total, "{stage}: {done} of {total}");
        }
    }

    fn stage_finished(&self, stage: &str, ran: u64, reused: u64) {
        let seconds = lock(&self.stages)
            .remove(stage)
            .map(|s| s.started.elapsed().as_secs_f64());
        let took = seconds.map(|s| format!(" in {s:.1} s")).unwrap_or_default();
        let what = if ran == 0 {
            format!("up to date, {reused} reused")
        } else {
            format!("ran {ran}, reused {reused}")
        };
        if self.summary_follows {
            tracing::debug!(target: PROGRESS_TARGET, stage, ran, reused, seconds, "{stage}: {what}{took}");
        } else {
            tracing::info!(target: PROGRESS_TARGET, stage, ran, reused, seconds, "{stage}: {what}{took}");
        }
    }

    fn note(&self, message: &str) {
        tracing::info!(target: PROGRESS_TARGET, "{message}");
    }
}

/// Stage progress as bars on a terminal (counts, elapsed time and ETA; a spinner when the total
/// is unknown), with the same log lines as [`LogProgress`] printed above them.
pub struct BarProgress {
    multi: MultiProgress,
    bars: Mutex<HashMap<String, ProgressBar>>,
    log: LogProgress,
}

impl BarProgress {
    /// Bars on standard error.
    pub fn new() -> BarProgress {
        BarProgress::with_draw_target(ProgressDrawTarget::stderr())
    }

    /// Bars drawn to `target` (tests draw to an in-memory terminal).
    pub fn with_draw_target(target: ProgressDrawTarget) -> BarProgress {
        BarProgress {
            multi: MultiProgress::with_draw_target(target),
            bars: Mutex::new(HashMap::new()),
            log: LogProgress::new(),
        }
    }

    /// Bars on standard error whose finished-stage lines are `debug`, as
    /// [`LogProgress::before_summary`].
    pub fn before_summary() -> BarProgress {
        BarProgress {
            log: LogProgress::before_summary(),
            ..BarProgress::new()
        }
    }

    /// A log writer for standard error that hides the bars while a line is printed, so log lines
    /// and bars do not overwrite each other.
    pub fn log_writer(&self) -> SuspendingStderr {
        SuspendingStderr(self.multi.clone())
    }

    /// Removes every bar from the terminal (before a summary or an error is printed).
    pub fn clear(&self) {
        for (_, bar) in lock(&self.bars).drain() {
            bar.finish_and_clear();
        }
        let _ = self.multi.clear();
    }

    /// Position and length of a running stage's bar.
    pub fn position(&self, stage: &str) -> Option<(u64, Option<u64>)> {
        lock(&self.bars)
            .get(stage)
            .map(|b| (b.position(), b.length()))
    }
}

impl Default for BarProgress {
    fn default() -> Self {
        BarProgress::new()
    }
}

/// The bar of an LLM stage: requests done, the rate, errors (in the message) and the ETA.
fn request_bar_style() -> ProgressStyle {
    ProgressStyle::with_template(
        "{prefix:>10} [{bar:30}] {pos}/{len} requests ({per_sec}, {msg}{elapsed}, ETA {eta})",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar())
    .progress_chars("=> ")
}

fn bar_style(total: u64) -> ProgressStyle {
    let template = if total == 0 {
        "{prefix:>10} {spinner} {pos} done, {elapsed}"
    } else {
        "{prefix:>10} [{bar:30}] {pos}/{len} ({elapsed}, ETA {eta})"
    };
    ProgressStyle::with_template(template)
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ")
}

impl Progress for BarProgress {
    fn stage_started(&self, stage: &str, total: u64) {
        self.log.stage_started(stage, total);
        let bar = self.multi.add(if total == 0 {
            ProgressBar::new_spinner()
        } else {
            ProgressBar::new(total)
        });
        bar.set_style(bar_style(total));
        bar.set_prefix(stage.to_string());
        // Redraws the elapsed time and ETA while items are slow (LLM requests).
        bar.enable_steady_tick(Duration::from_millis(250));
        if let Some(old) = lock(&self.bars).insert(stage.to_string(), bar) {
            old.finish_and_clear();
        }
    }

    fn requests_started(&self, stage: &str, total: u64) {
        self.log.requests_started(stage, total);
        let bar = self.multi.add(ProgressBar::new(total));
        bar.set_style(request_bar_style());
        bar.set_prefix(stage.to_string());
        bar.set_message("0 errors, ");
        bar.enable_steady_tick(Duration::from_millis(250));
        if let Some(old) = lock(&self.bars).insert(stage.to_string(), bar) {
            old.finish_and_clear();
        }
    }

    fn failed(&self, stage: &str, n: u64) {
        self.log.failed(stage, n);
        let errors = lock(&self.log.stages).get(stage).map(|s| s.errors);
        if let (Some(bar), Some(errors)) = (lock(&self.bars).get(stage), errors) {
            bar.set_message(format!(
                "{errors} error{}, ",
                if errors == 1 { "" } else { "s" }
            ));
        }
    }

    fn advanced(&self, stage: &str, n: u64) {
        self.log.advanced(stage, n);
        if let Some(bar) = lock(&self.bars).get(stage) {
            bar.inc(n);
        }
    }

    fn stage_finished(&self, stage: &str, ran: u64, reused: u64) {
        if let Some(bar) = lock(&self.bars).remove(stage) {
            bar.finish_and_clear();
            self.multi.remove(&bar);
        }
        self.log.stage_finished(stage, ran, reused);
    }

    fn note(&self, message: &str) {
        self.log.note(message);
    }
}

/// Makes writers to standard error that suspend the bars of a [`BarProgress`] while writing.
#[derive(Clone)]
pub struct SuspendingStderr(MultiProgress);

/// A writer made by [`SuspendingStderr`].
pub struct SuspendingWriter(MultiProgress);

impl Write for SuspendingWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.suspend(|| std::io::stderr().write(buf))
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        // One event is one write: the bars are hidden once per line, not once per chunk.
        self.0.suspend(|| std::io::stderr().write_all(buf))
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

impl<'a> MakeWriter<'a> for SuspendingStderr {
    type Writer = SuspendingWriter;

    fn make_writer(&'a self) -> Self::Writer {
        SuspendingWriter(self.0.clone())
    }
}

/// A writer into shared memory, for tests of what is logged.
#[derive(Clone, Default)]
pub struct MemoryWriter(Arc<Mutex<Vec<u8>>>);

impl MemoryWriter {
    /// Everything written so far, as text.
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&lock(&self.0)).into_owned()
    }
}

impl Write for MemoryWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        lock(&self.0).extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl<'a> MakeWriter<'a> for MemoryWriter {
    type Writer = MemoryWriter;

    fn make_writer(&'a self) -> Self::Writer {
        self.clone()
    }
}
