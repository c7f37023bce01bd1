//! Progress of a running build, reported to whoever watches it (a terminal bar, log lines, the
//! service's build record). The build calls these; they must be cheap and never fail.

use std::fmt;
use std::sync::Arc;

/// Receives a build's progress. Every method has a no-op default.
pub trait Progress: Send + Sync {
    /// A stage starts over `total` items (captures, texts, pairs, shards).
    fn stage_started(&self, _stage: &str, _total: u64) {}
    /// `n` more items of the stage are done.
    fn advanced(&self, _stage: &str, _n: u64) {}
    /// The stage is finished: `ran` items computed, `reused` taken from the cache.
    fn stage_finished(&self, _stage: &str, _ran: u64, _reused: u64) {}
    /// A line worth showing (a rejected input, a skipped request).
    fn note(&self, _message: &str) {}
    /// An LLM stage starts sending `total` requests: shown like [`Progress::stage_started`], with
    /// the request rate and errors.
    fn requests_started(&self, stage: &str, total: u64) {
        self.stage_started(stage, total);
    }
    /// `n` items of the stage failed (counted in [`Progress::advanced`] too).
    fn failed(&self, _stage: &str, _n: u64) {}
}

/// A shared progress receiver; the default reports nowhere.
#[derive(Clone, Default)]
pub struct ProgressSink(Option<Arc<dyn Progress>>);

impl ProgressSink {
    /// Reports to `progress`.
    pub fn new(progress: Arc<dyn Progress>) -> Self {
        ProgressSink(Some(progress))
    }

    /// See [`Progress::stage_started`].
    pub fn stage_started(&self, stage: &str, total: u64) {
        if let Some(p) = &self.0 {
            p.stage_started(stage, total);
        }
    }

    /// See [`Progress::advanced`].
    pub fn advanced(&self, stage: &str, n: u64) {
        if let Some(p) = &self.0 {
            p.advanced(stage, n);
        }
    }

    /// See [`Progress::stage_finished`].
    pub fn stage_finished(&self, stage: &str, ran: u64, reused: u64) {
        if let Some(p) = &self.0 {
            p.stage_finished(stage, ran, reused);
        }
    }

    /// See [`Progress::requests_started`].
    pub fn requests_started(&self, stage: &str, total: u64) {
        if let Some(p) = &self.0 {
            p.requests_started(stage, total);
        }
    }

    /// See [`Progress::failed`].
    pub fn failed(&self, stage: &str, n: u64) {
        if let Some(p) = &self.0 {
            p.failed(stage, n);
        }
    }

    /// See [`Progress::note`].
    pub fn note(&self, message: &str) {
        if let Some(p) = &self.0 {
            p.note(message);
        }
    }
}

impl fmt::Debug for ProgressSink {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(if self.0.is_some() {
            "ProgressSink(..)"
        } else {
            "ProgressSink(none)"
        })
    }
}
