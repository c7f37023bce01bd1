//! What a running build reports, kept in memory for `GET /builds/{id}` and stored when it ends.

use std::collections::VecDeque;
use std::sync::{Mutex, MutexGuard};

use serde::{Deserialize, Serialize};

use super::history::LOG_TAIL;
use motionforge_core::progress::Progress;
use motionforge_runner::BuildReport;

/// Longest log line kept; a longer note is cut.
const MAX_LINE: usize = 2000;

/// Progress of one stage of a build.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StageProgress {
    /// Stage name.
    pub stage: String,
    /// Items the stage covers (0 until it says).
    pub total: u64,
    /// Items done so far.
    pub done: u64,
    /// Items computed, once the stage finished.
    pub ran: Option<u64>,
    /// Items reused from the cache, once the stage finished.
    pub reused: Option<u64>,
    /// True once the stage finished.
    pub finished: bool,
}

#[derive(Debug, Default)]
struct Recorded {
    stages: Vec<StageProgress>,
    lines: VecDeque<String>,
}

/// Records a build's stage progress and the tail of its log.
#[derive(Debug, Default)]
pub struct BuildLog {
    inner: Mutex<Recorded>,
}

impl BuildLog {
    /// An empty log.
    pub fn new() -> BuildLog {
        BuildLog::default()
    }

    fn lock(&self) -> MutexGuard<'_, Recorded> {
        // Progress calls come from rayon workers; one that panicked must not silence the rest.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Adds a line, dropping the oldest beyond [`LOG_TAIL`].
    pub fn line(&self, text: &str) {
        let mut text = text.to_string();
        if text.len() > MAX_LINE {
            let mut cut = MAX_LINE;
            while !text.is_char_boundary(cut) {
                cut -= 1;
            }
            text.truncate(cut);
            text.push('…');
        }
        let mut r = self.lock();
        r.lines.push_back(text);
        while r.lines.len() > LOG_TAIL {
            r.lines.pop_front();
        }
    }

    /// The kept lines, oldest first.
    pub fn lines(&self) -> Vec<String> {
        self.lock().lines.iter().cloned().collect()
    }

    /// Stage progress so far, in the order stages started.
    pub fn stages(&self) -> Vec<StageProgress> {
        self.lock().stages.clone()
    }

    /// Stage progress at the end of a build: the report's per-stage counts, which are
    /// authoritative, after any stage that reported progress but is not in the report.
    pub fn final_stages(&self, report: Option<&BuildReport>) -> Vec<StageProgress> {
        let mut stages = self.stages();
        if let Some(report) = report {
            for run in &report.stages {
                let done = StageProgress {
                    stage: run.stage.clone(),
                    total: run.items as u64,
                    done: run.items as u64,
                    ran: Some(run.ran as u64),
                    reused: Some(run.reused as u64),
                    finished: true,
                };
                match stages.iter_mut().find(|s| s.stage == run.stage) {
                    Some(s) => *s = done,
                    None => stages.push(done),
                }
            }
        }
        stages
    }

    fn stage_mut<'a>(r: &'a mut Recorded, stage: &str) -> &'a mut StageProgress {
        let index = match r.stages.iter().position(|s| s.stage == stage) {
            Some(i) => i,
            None => {
                r.stages.push(StageProgress {
                    stage: stage.to_string(),
                    total: 0,
                    done: 0,
                    ran: None,
                    reused: None,
                    finished: false,
                });
                r.stages.len() - 1
            }
        };
        &mut r.stages[index]
    }
}

impl Progress for BuildLog {
    fn stage_started(&self, stage: &str, total: u64) {
        {
            let mut r = self.lock();
            let s = BuildLog::stage_mut(&mut r, stage);
            s.total = total;
            s.done = 0;
            s.finished = false;
        }
        self.line(&format!("{stage}: started, {total} items"));
    }

    fn advanced(&self, stage: &str, n: u64) {
        let mut r = self.lock();
        let s = BuildLog::stage_mut(&mut r, stage);
        s.done = s.done.saturating_add(n);
    }

    fn stage_finished(&self, stage: &str, ran: u64, reused: u64) {
        {
            let mut r = self.lock();
            let s = BuildLog::stage_mut(&mut r, stage);
            s.ran = Some(ran);
            s.reused = Some(reused);
            s.done = s.done.max(ran + reused);
            s.total = s.total.max(s.done);
            s.finished = true;
        }
        self.line(&format!("{stage}: finished, {ran} ran, {reused} reused"));
    }

    fn note(&self, message: &str) {
        self.line(message);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_calls_become_stage_counts_and_log_lines() {
        let log = BuildLog::new();
        log.stage_started("ingest", 9);
        log.advanced("ingest", 4);
        log.advanced("ingest", 2);
        log.note("rejected a.bvh: no frames");
        let s = &log.stages()[0];
        assert_eq!((s.total, s.done, s.finished), (9, 6, false));
        log.stage_finished("ingest", 3, 6);
        let s = &log.stages()[0];
        assert_eq!(
            (s.done, s.ran, s.reused, s.finished),
            (9, Some(3), Some(6), true)
        );
        assert_eq!(
            log.lines(),
            vec![
                "ingest: started, 9 items",
                "rejected a.bvh: no frames",
                "ingest: finished, 3 ran, 6 reused"
            ]
        );
    }

    #[test]
    fn the_log_keeps_its_tail() {
        let log = BuildLog::new();
        for i in 0..LOG_TAIL + 5 {
            log.note(&format!("line {i}"));
        }
        let lines = log.lines();
        assert_eq!(lines.len(), LOG_TAIL);
        assert_eq!(lines[0], "line 5");
        log.note(&"é".repeat(MAX_LINE));
        assert!(log.lines().last().unwrap().len() <= MAX_LINE + '…'.len_utf8());
    }
}
