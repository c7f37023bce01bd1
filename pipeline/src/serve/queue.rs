//! One worker per dataset runs its builds one at a time, in the order they were queued: two
//! builds of one dataset would write the same folder.

use std::sync::Arc;
use std::time::Instant;

use tokio::sync::{mpsc, watch};

use super::history::{BuildId, BuildState, Outcome};
use super::log::BuildLog;
use super::{Shared, say};
use crate::build::{BuildOptions, BuildReport, build};
use crate::progress::ProgressSink;

/// Resolves once the service is stopping (or its stop sender is gone).
async fn stopping(mut shutdown: watch::Receiver<bool>) {
    let _ = shutdown.wait_for(|s| *s).await.map(|_| ());
}

/// Runs `dataset`'s queued builds until the service stops.
pub(crate) async fn work(
    shared: Arc<Shared>,
    dataset: String,
    mut queue: mpsc::UnboundedReceiver<BuildId>,
) {
    loop {
        let id = tokio::select! {
            biased;
            () = stopping(shared.shutdown.clone()) => return,
            id = queue.recv() => match id {
                Some(id) => id,
                None => return,
            },
        };
        tokio::select! {
            biased;
            // The build's thread runs on; `Service::stop` marks the build interrupted.
            () = stopping(shared.shutdown.clone()) => return,
            () = run_build(&shared, &dataset, id) => {}
        }
    }
}

async fn run_build(shared: &Arc<Shared>, dataset: &str, id: BuildId) {
    let Some(served) = shared.datasets.get(dataset) else {
        return;
    };
    let record = match shared.history.get(id) {
        Ok(Some(r)) => r,
        Ok(None) => return,
        Err(e) => {
            say(&format!("build {id}: {e}"));
            return;
        }
    };
    let log = Arc::new(BuildLog::new());
    log.line(&format!(
        "build {id} of `{dataset}` started ({} request{}{})",
        record.trigger.as_str(),
        if record.force { ", forced" } else { "" },
        match record.resumes {
            Some(r) => format!(", resumes build {r}"),
            None => String::new(),
        }
    ));
    // Live before it is `running`: a reader who sees it running finds its log.
    shared.set_live(id, Some(log.clone()));
    match shared.history.start(id, shared.now_ms()) {
        Ok(true) => {}
        // No longer queued (already run by an earlier service on this history).
        Ok(false) => {
            shared.set_live(id, None);
            return;
        }
        Err(e) => {
            shared.set_live(id, None);
            say(&format!("build {id}: cannot start: {e}"));
            return;
        }
    }
    say(&format!("build {id} of `{dataset}` started"));

    let config = served.config.clone();
    let options = BuildOptions {
        force: record.force,
        offline: record.offline,
        progress: ProgressSink::new(log.clone()),
        ..BuildOptions::default()
    };
    let clock = Instant::now();
    // The build is CPU-bound and uses rayon: keep it off the async workers.
    let result = tokio::task::spawn_blocking(move || build(&config, &options)).await;
    let duration_ms = i64::try_from(clock.elapsed().as_millis()).unwrap_or(i64::MAX);
    let seconds = duration_ms as f64 / 1000.0;

    let outcome = match result {
        Ok(Ok(report)) => {
            log.line(&summary(&report, seconds));
            Outcome {
                state: BuildState::Succeeded,
                report: serde_json::to_string(&report).ok(),
                error: None,
                stages: serde_json::to_string(&log.final_stages(Some(&report))).ok(),
                log: log.lines(),
                duration_ms,
            }
        }
        Ok(Err(err)) => failed(&log, error_chain(&err), duration_ms),
        Err(join) => {
            let why = if join.is_panic() {
                let payload = join.into_panic();
                let text = payload
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| payload.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "unknown panic".into());
                format!("the build panicked: {text}")
            } else {
                "the build was cancelled".to_string()
            };
            failed(&log, why, duration_ms)
        }
    };
    match shared.history.finish(id, &outcome, shared.now_ms()) {
        Ok(true) => say(&format!(
            "build {id} of `{dataset}` {} in {seconds:.2} s",
            outcome.state.as_str()
        )),
        Ok(false) => say(&format!(
            "build {id} ended after it was marked interrupted; its result is not recorded"
        )),
        Err(e) => say(&format!("build {id}: cannot record its end: {e}")),
    }
    shared.set_live(id, None);
}

fn failed(log: &BuildLog, error: String, duration_ms: i64) -> Outcome {
    log.line(&format!("failed: {error}"));
    Outcome {
        state: BuildState::Failed,
        report: None,
        stages: serde_json::to_string(&log.final_stages(None)).ok(),
        error: Some(error),
        log: log.lines(),
        duration_ms,
    }
}

/// One line on what a successful build did.
fn summary(report: &BuildReport, seconds: f64) -> String {
    let work = if report.nothing_ran() {
        "nothing changed, every stage reused".to_string()
    } else {
        let ran: Vec<String> = report
            .stages
            .iter()
            .filter(|s| s.ran > 0)
            .map(|s| format!("{} {}", s.stage, s.ran))
            .collect();
        format!("ran {}", ran.join(", "))
    };
    format!(
        "succeeded in {seconds:.2} s: {} captures, {} rows, {} rejects; {work}",
        report.captures,
        report.clips,
        report.rejects.len()
    )
}

/// The error and its causes on one line, skipping causes its message already quotes.
fn error_chain(err: &dyn std::error::Error) -> String {
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
