//! One worker per dataset runs its builds one at a time, in the order they were queued: two
//! builds of one dataset would write the same folder.

use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::{mpsc, watch};

use super::child::{self, Ended};
use super::history::{BuildId, BuildState, Outcome};
use super::log::BuildLog;
use super::worker::Job;
use super::{Shared, say};
use motionforge_runner::BuildReport;

/// How long a build process killed by a stop signal waits for the service's own stop before it
/// is recorded as failed.
const STOP_GRACE: Duration = Duration::from_secs(2);

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
            // Dropping the build kills its process; `Service::stop` marks it interrupted.
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

    let job = Job {
        build: id,
        config: served.config.clone(),
        base_dir: served.config.base_dir.clone(),
        force: record.force,
        offline: record.offline,
        report: shared.jobs_dir.join(format!("{id}.report.json")),
    };
    let clock = Instant::now();
    // A process of its own: whatever ends the build (an abort, a signal) leaves the service up.
    let ended = child::run(&shared.builder, &shared.jobs_dir, job, &log).await;
    // However it ended, it may have replaced the dataset's shards.
    shared.readers.forget(dataset);
    let duration_ms = i64::try_from(clock.elapsed().as_millis()).unwrap_or(i64::MAX);
    let seconds = duration_ms as f64 / 1000.0;

    let outcome = match ended {
        Ended::Succeeded(report) => {
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
        Ended::Failed(why) => failed(&log, why.to_string(), duration_ms),
        Ended::Killed { signal, message } => {
            if child::is_stop_request(signal) {
                // Under systemd a stop signals every process of the unit at once: when the
                // service is stopping too, the build was interrupted, not failed. `work` drops
                // this future as soon as the stop is seen, and `Service::stop` records it.
                let _ = tokio::time::timeout(STOP_GRACE, stopping(shared.shutdown.clone())).await;
                if *shared.shutdown.borrow() {
                    return;
                }
            }
            failed(&log, message, duration_ms)
        }
    };
    match shared.history.finish(id, &outcome, shared.now_ms()) {
        Ok(true) => say(&format!(
            "build {id} of `{dataset}` {} in {seconds:.2} s{}",
            outcome.state.as_str(),
            outcome
                .error
                .as_deref()
                .and_then(|e| e.lines().next())
                .map(|e| format!(": {e}"))
                .unwrap_or_default()
        )),
        Ok(false) => say(&format!(
            "build {id} ended after it was marked interrupted; its result is not recorded"
        )),
        Err(e) => say(&format!("build {id}: cannot record its end: {e}")),
    }
    shared.set_live(id, None);
}

fn failed(log: &BuildLog, error: String, duration_ms: i64) -> Outcome {
    // The error may quote the process's last lines, which the log already has.
    log.line(&format!(
        "failed: {}",
        error.lines().next().unwrap_or_default()
    ));
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
