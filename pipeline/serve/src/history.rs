//! The service's run history: one SQLite row per build, kept across restarts.
//!
//! Times are unix milliseconds (UTC). The connection holds SQLite's lock for its whole life
//! (`locking_mode = EXCLUSIVE`), so a second service on the same state folder fails to start
//! instead of running builds of the same datasets at the same time. Every call is one short
//! statement or transaction on a small table, so async handlers make them directly rather than
//! through a blocking pool.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use rusqlite::{Connection, OptionalExtension, Row, params};
use serde::{Deserialize, Serialize};

/// A build's id: increasing integers, never reused.
pub type BuildId = i64;

/// File name of the history database inside the state folder.
pub const HISTORY_FILE: &str = "history.sqlite3";

/// Lines of a build's log kept in its row.
pub const LOG_TAIL: usize = 200;

/// Where a build is in its life.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BuildState {
    /// Waiting for the dataset's earlier builds.
    Queued,
    /// Building now.
    Running,
    /// Finished with a build report.
    Succeeded,
    /// Stopped by an error.
    Failed,
    /// The service stopped while it ran; a `resume` build follows it (see
    /// [`History::interrupt_running`]).
    Interrupted,
}

impl BuildState {
    /// The name stored and served.
    pub fn as_str(self) -> &'static str {
        match self {
            BuildState::Queued => "queued",
            BuildState::Running => "running",
            BuildState::Succeeded => "succeeded",
            BuildState::Failed => "failed",
            BuildState::Interrupted => "interrupted",
        }
    }

    /// Parses a stored or requested name.
    pub fn parse(text: &str) -> Option<BuildState> {
        [
            BuildState::Queued,
            BuildState::Running,
            BuildState::Succeeded,
            BuildState::Failed,
            BuildState::Interrupted,
        ]
        .into_iter()
        .find(|s| s.as_str() == text)
    }

    /// True once the build will not change any more.
    pub fn is_final(self) -> bool {
        matches!(
            self,
            BuildState::Succeeded | BuildState::Failed | BuildState::Interrupted
        )
    }
}

/// Why a build was requested.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Trigger {
    /// `POST /builds`.
    Api,
    /// The dataset's cron schedule.
    Schedule,
    /// Resumes a build the service was stopped in.
    Resume,
}

impl Trigger {
    /// The name stored and served.
    pub fn as_str(self) -> &'static str {
        match self {
            Trigger::Api => "api",
            Trigger::Schedule => "schedule",
            Trigger::Resume => "resume",
        }
    }

    fn parse(text: &str) -> Option<Trigger> {
        [Trigger::Api, Trigger::Schedule, Trigger::Resume]
            .into_iter()
            .find(|t| t.as_str() == text)
    }
}

/// How the service left the builds it was running.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Left {
    /// It stopped cleanly (Ctrl-C, SIGTERM, [`super::Service::stop`]) and killed the build.
    Stopped,
    /// It died while they ran (killed, out of memory, power loss): found on the next start.
    Died,
}

/// One build as the history keeps it.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildRecord {
    /// The build's id.
    pub id: BuildId,
    /// Dataset name (`dataset.name` of its config).
    pub dataset: String,
    /// Why it was requested.
    pub trigger: Trigger,
    /// Recompute everything, ignoring cached stage outputs.
    pub force: bool,
    /// Send no LLM request.
    pub offline: bool,
    /// Where it is.
    pub state: BuildState,
    /// When it was requested (unix ms).
    pub requested_at: i64,
    /// When it started (unix ms).
    pub started_at: Option<i64>,
    /// When it ended (unix ms).
    pub finished_at: Option<i64>,
    /// Wall time of the build itself, measured on a monotonic clock.
    pub duration_ms: Option<i64>,
    /// The interrupted build this one resumes.
    pub resumes: Option<BuildId>,
    /// The build that resumes this interrupted one.
    pub resumed_by: Option<BuildId>,
    /// The build report (JSON) of a successful build.
    pub report: Option<String>,
    /// Stage progress (JSON list) at the end.
    pub stages: Option<String>,
    /// Why it failed or was interrupted.
    pub error: Option<String>,
    /// The last lines of its log.
    pub log: Vec<String>,
}

/// How a running build ended.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// `Succeeded` or `Failed`.
    pub state: BuildState,
    /// The report JSON when it succeeded.
    pub report: Option<String>,
    /// The error when it failed.
    pub error: Option<String>,
    /// Stage progress JSON.
    pub stages: Option<String>,
    /// Log tail.
    pub log: Vec<String>,
    /// Wall time of the build.
    pub duration_ms: i64,
}

/// Which builds a listing shows.
#[derive(Debug, Clone, Default)]
pub struct ListFilter {
    /// Only this dataset.
    pub dataset: Option<String>,
    /// Only builds in this state.
    pub state: Option<BuildState>,
    /// At most this many, newest first.
    pub limit: usize,
}

/// Errors of the history database.
#[derive(Debug, thiserror::Error)]
pub enum HistoryError {
    /// The state folder cannot be made.
    #[error("cannot create state folder {path}: {source}")]
    Folder {
        /// The folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Another service holds the database.
    #[error(
        "run history {path} is in use by another process (is another `motionforge serve` using this state folder?)"
    )]
    Locked {
        /// The database file.
        path: PathBuf,
    },
    /// SQLite failed.
    #[error("run history {path}: {source}")]
    Sqlite {
        /// The database file.
        path: PathBuf,
        /// The SQLite error.
        source: rusqlite::Error,
    },
    /// A row holds a value this version does not know.
    #[error("run history {path}: build {id} has unknown {column} `{value}`")]
    Corrupt {
        /// The database file.
        path: PathBuf,
        /// The build id.
        id: BuildId,
        /// The column.
        column: &'static str,
        /// The value found.
        value: String,
    },
}

/// The run history database.
#[derive(Debug)]
pub struct History {
    path: PathBuf,
    conn: Mutex<Connection>,
}

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS builds (
    id           INTEGER PRIMARY KEY AUTOINCREMENT,
    dataset      TEXT NOT NULL,
    trigger      TEXT NOT NULL,
    force        INTEGER NOT NULL,
    offline      INTEGER NOT NULL,
    state        TEXT NOT NULL,
    requested_at INTEGER NOT NULL,
    started_at   INTEGER,
    finished_at  INTEGER,
    duration_ms  INTEGER,
    resumes      INTEGER REFERENCES builds(id),
    resumed_by   INTEGER REFERENCES builds(id),
    report       TEXT,
    stages       TEXT,
    error        TEXT,
    log          TEXT NOT NULL DEFAULT '[]'
);
CREATE INDEX IF NOT EXISTS builds_dataset_state ON builds (dataset, state);
";

const COLUMNS: &str = "id, dataset, trigger, force, offline, state, requested_at, started_at, \
     finished_at, duration_ms, resumes, resumed_by, report, stages, error, log";

impl History {
    /// Opens (or creates) the history in `dir`, taking its lock.
    pub fn open(dir: &Path) -> Result<History, HistoryError> {
        std::fs::create_dir_all(dir).map_err(|source| HistoryError::Folder {
            path: dir.to_path_buf(),
            source,
        })?;
        let path = dir.join(HISTORY_FILE);
        let conn = Connection::open(&path).map_err(|source| HistoryError::Sqlite {
            path: path.clone(),
            source,
        })?;
        let history = History {
            path,
            conn: Mutex::new(conn),
        };
        {
            let conn = history.lock();
            // A restarting service may briefly overlap the old one's last write.
            conn.busy_timeout(Duration::from_secs(3))
                .map_err(|e| history.err(e))?;
            conn.pragma_update(None, "locking_mode", "EXCLUSIVE")
                .map_err(|e| history.err(e))?;
            conn.pragma_update(None, "journal_mode", "WAL")
                .map_err(|e| history.err(e))?;
            conn.pragma_update(None, "synchronous", "FULL")
                .map_err(|e| history.err(e))?;
            // The schema write takes the exclusive lock now, so a second service fails here.
            conn.execute_batch(SCHEMA).map_err(|e| history.err(e))?;
        }
        Ok(history)
    }

    /// The database file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn lock(&self) -> MutexGuard<'_, Connection> {
        // A panic while holding the lock leaves no half-done SQLite work (statements are atomic).
        self.conn.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn err(&self, source: rusqlite::Error) -> HistoryError {
        let busy = matches!(
            source.sqlite_error_code(),
            Some(rusqlite::ErrorCode::DatabaseBusy | rusqlite::ErrorCode::DatabaseLocked)
        );
        if busy {
            HistoryError::Locked {
                path: self.path.clone(),
            }
        } else {
            HistoryError::Sqlite {
                path: self.path.clone(),
                source,
            }
        }
    }

    /// Adds a queued build and returns its id.
    pub fn enqueue(
        &self,
        dataset: &str,
        trigger: Trigger,
        force: bool,
        offline: bool,
        resumes: Option<BuildId>,
        now: i64,
    ) -> Result<BuildId, HistoryError> {
        let conn = self.lock();
        conn.execute(
            "INSERT INTO builds (dataset, trigger, force, offline, state, requested_at, resumes) \
             VALUES (?1, ?2, ?3, ?4, 'queued', ?5, ?6)",
            params![dataset, trigger.as_str(), force, offline, now, resumes],
        )
        .map_err(|e| self.err(e))?;
        Ok(conn.last_insert_rowid())
    }

    /// Moves a queued build to running; false when it was not queued.
    pub fn start(&self, id: BuildId, now: i64) -> Result<bool, HistoryError> {
        let n = self
            .lock()
            .execute(
                "UPDATE builds SET state = 'running', started_at = ?2 WHERE id = ?1 AND state = 'queued'",
                params![id, now],
            )
            .map_err(|e| self.err(e))?;
        Ok(n == 1)
    }

    /// Records how a running build ended; false when it was no longer running (the service
    /// marked it interrupted while shutting down).
    pub fn finish(&self, id: BuildId, outcome: &Outcome, now: i64) -> Result<bool, HistoryError> {
        let log = serde_json::to_string(&outcome.log).unwrap_or_else(|_| "[]".into());
        let n = self
            .lock()
            .execute(
                "UPDATE builds SET state = ?2, finished_at = ?3, duration_ms = ?4, report = ?5, \
                 stages = ?6, error = ?7, log = ?8 WHERE id = ?1 AND state = 'running'",
                params![
                    id,
                    outcome.state.as_str(),
                    now,
                    outcome.duration_ms,
                    outcome.report,
                    outcome.stages,
                    outcome.error,
                    log
                ],
            )
            .map_err(|e| self.err(e))?;
        Ok(n == 1)
    }

    /// Ends every running build the service left behind, noting `reason` in its error and log,
    /// and returns them with the state each was given.
    ///
    /// A build is `interrupted` (and [`History::resume_interrupted`] resumes it), except when
    /// the service died ([`Left::Died`]) during a build that was itself resuming an interrupted
    /// one: that build is `failed`, so a build that takes the whole service down is retried once,
    /// not on every restart.
    pub fn interrupt_running(
        &self,
        reason: &str,
        left: Left,
        now: i64,
    ) -> Result<Vec<(BuildId, BuildState)>, HistoryError> {
        let mut conn = self.lock();
        let tx = conn.transaction().map_err(|e| self.err(e))?;
        let rows: Vec<(BuildId, String, Option<BuildId>)> = {
            let mut stmt = tx
                .prepare("SELECT id, log, resumes FROM builds WHERE state = 'running' ORDER BY id")
                .map_err(|e| self.err(e))?;
            stmt.query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
                .and_then(Iterator::collect)
                .map_err(|e| self.err(e))?
        };
        let mut ended = Vec::new();
        for (id, log, resumes) in &rows {
            let (state, error) = match (left, resumes) {
                (Left::Died, Some(first)) => (
                    BuildState::Failed,
                    format!(
                        "{reason}, and this build was itself resuming interrupted build {first}: \
                         interrupted twice; not resumed again, request a new build"
                    ),
                ),
                _ => (BuildState::Interrupted, reason.to_string()),
            };
            let mut lines: Vec<String> = serde_json::from_str(log).unwrap_or_default();
            lines.push(error.clone());
            let excess = lines.len().saturating_sub(LOG_TAIL);
            lines.drain(..excess);
            let log = serde_json::to_string(&lines).unwrap_or_else(|_| "[]".into());
            tx.execute(
                "UPDATE builds SET state = ?2, finished_at = ?3, error = ?4, log = ?5 \
                 WHERE id = ?1",
                params![id, state.as_str(), now, error, log],
            )
            .map_err(|e| self.err(e))?;
            ended.push((*id, state));
        }
        tx.commit().map_err(|e| self.err(e))?;
        Ok(ended)
    }

    /// Queues a `resume` build for each interrupted build of the given datasets that has none
    /// yet, and returns the new builds' ids.
    pub fn resume_interrupted(
        &self,
        datasets: &[&str],
        now: i64,
    ) -> Result<Vec<BuildId>, HistoryError> {
        let mut conn = self.lock();
        let tx = conn.transaction().map_err(|e| self.err(e))?;
        let rows: Vec<(BuildId, String, bool)> = {
            let mut stmt = tx
                .prepare(
                    "SELECT id, dataset, offline FROM builds \
                     WHERE state = 'interrupted' AND resumed_by IS NULL ORDER BY id",
                )
                .map_err(|e| self.err(e))?;
            stmt.query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
                .and_then(Iterator::collect)
                .map_err(|e| self.err(e))?
        };
        let mut added = Vec::new();
        for (id, dataset, offline) in rows {
            if !datasets.contains(&dataset.as_str()) {
                continue;
            }
            // Never forced: a forced build cleared the cache when it started, so what it finished
            // since is fresh and what it did not is missing, and the rerun computes exactly that.
            tx.execute(
                "INSERT INTO builds (dataset, trigger, force, offline, state, requested_at, resumes) \
                 VALUES (?1, 'resume', 0, ?2, 'queued', ?3, ?4)",
                params![dataset, offline, now, id],
            )
            .map_err(|e| self.err(e))?;
            let new = tx.last_insert_rowid();
            tx.execute(
                "UPDATE builds SET resumed_by = ?2 WHERE id = ?1",
                params![id, new],
            )
            .map_err(|e| self.err(e))?;
            added.push(new);
        }
        tx.commit().map_err(|e| self.err(e))?;
        Ok(added)
    }

    /// One build.
    pub fn get(&self, id: BuildId) -> Result<Option<BuildRecord>, HistoryError> {
        let conn = self.lock();
        let raw = conn
            .query_row(
                &format!("SELECT {COLUMNS} FROM builds WHERE id = ?1"),
                [id],
                RawRecord::read,
            )
            .optional()
            .map_err(|e| self.err(e))?;
        raw.map(|r| r.into_record(&self.path)).transpose()
    }

    /// Builds matching `filter`, newest first.
    pub fn list(&self, filter: &ListFilter) -> Result<Vec<BuildRecord>, HistoryError> {
        let conn = self.lock();
        let mut stmt = conn
            .prepare(&format!(
                "SELECT {COLUMNS} FROM builds \
                 WHERE (?1 IS NULL OR dataset = ?1) AND (?2 IS NULL OR state = ?2) \
                 ORDER BY id DESC LIMIT ?3"
            ))
            .map_err(|e| self.err(e))?;
        let limit = i64::try_from(filter.limit).unwrap_or(i64::MAX);
        let raws: Vec<RawRecord> = stmt
            .query_map(
                params![filter.dataset, filter.state.map(BuildState::as_str), limit],
                RawRecord::read,
            )
            .and_then(Iterator::collect)
            .map_err(|e| self.err(e))?;
        raws.into_iter()
            .map(|r| r.into_record(&self.path))
            .collect()
    }

    /// Queued builds of every dataset, oldest first.
    pub fn queued(&self) -> Result<Vec<BuildRecord>, HistoryError> {
        let mut all = self.list(&ListFilter {
            dataset: None,
            state: Some(BuildState::Queued),
            limit: usize::MAX,
        })?;
        all.reverse();
        Ok(all)
    }
}

/// A row as SQLite gives it, before its names are checked.
struct RawRecord {
    id: BuildId,
    dataset: String,
    trigger: String,
    force: bool,
    offline: bool,
    state: String,
    requested_at: i64,
    started_at: Option<i64>,
    finished_at: Option<i64>,
    duration_ms: Option<i64>,
    resumes: Option<BuildId>,
    resumed_by: Option<BuildId>,
    report: Option<String>,
    stages: Option<String>,
    error: Option<String>,
    log: String,
}

impl RawRecord {
    fn read(r: &Row<'_>) -> rusqlite::Result<RawRecord> {
        Ok(RawRecord {
            id: r.get(0)?,
            dataset: r.get(1)?,
            trigger: r.get(2)?,
            force: r.get(3)?,
            offline: r.get(4)?,
            state: r.get(5)?,
            requested_at: r.get(6)?,
            started_at: r.get(7)?,
            finished_at: r.get(8)?,
            duration_ms: r.get(9)?,
            resumes: r.get(10)?,
            resumed_by: r.get(11)?,
            report: r.get(12)?,
            stages: r.get(13)?,
            error: r.get(14)?,
            log: r.get(15)?,
        })
    }

    fn into_record(self, path: &Path) -> Result<BuildRecord, HistoryError> {
        let corrupt = |column, value: &str| HistoryError::Corrupt {
            path: path.to_path_buf(),
            id: self.id,
            column,
            value: value.to_string(),
        };
        let trigger =
            Trigger::parse(&self.trigger).ok_or_else(|| corrupt("trigger", &self.trigger))?;
        let state = BuildState::parse(&self.state).ok_or_else(|| corrupt("state", &self.state))?;
        Ok(BuildRecord {
            id: self.id,
            dataset: self.dataset,
            trigger,
            force: self.force,
            offline: self.offline,
            state,
            requested_at: self.requested_at,
            started_at: self.started_at,
            finished_at: self.finished_at,
            duration_ms: self.duration_ms,
            resumes: self.resumes,
            resumed_by: self.resumed_by,
            report: self.report,
            stages: self.stages,
            error: self.error,
            log: serde_json::from_str(&self.log).unwrap_or_default(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_build_goes_queued_running_succeeded_and_finish_is_ignored_once_interrupted() {
        let dir = tempfile::tempdir().unwrap();
        let h = History::open(dir.path()).unwrap();
        let a = h
            .enqueue("demo", Trigger::Api, false, false, None, 1)
            .unwrap();
        let b = h
            .enqueue("demo", Trigger::Api, true, false, None, 2)
            .unwrap();
        assert!(b > a);
        assert!(h.start(a, 3).unwrap());
        assert!(
            !h.start(a, 4).unwrap(),
            "a running build cannot start again"
        );
        let outcome = Outcome {
            state: BuildState::Succeeded,
            report: Some("{}".into()),
            error: None,
            stages: None,
            log: vec!["done".into()],
            duration_ms: 7,
        };
        assert!(h.finish(a, &outcome, 5).unwrap());
        let rec = h.get(a).unwrap().unwrap();
        assert_eq!(rec.state, BuildState::Succeeded);
        assert_eq!((rec.started_at, rec.finished_at), (Some(3), Some(5)));
        assert_eq!(rec.log, vec!["done".to_string()]);

        assert!(h.start(b, 6).unwrap());
        assert_eq!(
            h.interrupt_running("stopped", Left::Stopped, 7).unwrap(),
            vec![(b, BuildState::Interrupted)]
        );
        assert!(
            !h.finish(b, &outcome, 8).unwrap(),
            "an abandoned build's late end must not overwrite `interrupted`"
        );
        let rec = h.get(b).unwrap().unwrap();
        assert_eq!(rec.state, BuildState::Interrupted);
        assert_eq!(rec.error.as_deref(), Some("stopped"));

        let resumed = h.resume_interrupted(&["demo"], 9).unwrap();
        assert_eq!(resumed.len(), 1);
        let new = h.get(resumed[0]).unwrap().unwrap();
        assert_eq!(
            (new.trigger, new.state, new.resumes, new.force),
            (Trigger::Resume, BuildState::Queued, Some(b), false)
        );
        assert_eq!(h.get(b).unwrap().unwrap().resumed_by, Some(new.id));
        assert!(
            h.resume_interrupted(&["demo"], 10).unwrap().is_empty(),
            "an interrupted build is resumed once"
        );
        assert_eq!(
            h.queued().unwrap().iter().map(|r| r.id).collect::<Vec<_>>(),
            vec![new.id]
        );
    }

    #[test]
    fn a_resume_build_the_service_died_in_fails_instead_of_resuming_again() {
        let dir = tempfile::tempdir().unwrap();
        let h = History::open(dir.path()).unwrap();
        let first = h
            .enqueue("demo", Trigger::Api, false, false, None, 1)
            .unwrap();
        assert!(h.start(first, 2).unwrap());
        assert_eq!(
            h.interrupt_running("died", Left::Died, 3).unwrap(),
            vec![(first, BuildState::Interrupted)],
            "a first interruption is resumed"
        );
        let resume = h.resume_interrupted(&["demo"], 4).unwrap()[0];

        // A clean stop during the resume build keeps it resumable.
        assert!(h.start(resume, 5).unwrap());
        assert_eq!(
            h.interrupt_running("stopped", Left::Stopped, 6).unwrap(),
            vec![(resume, BuildState::Interrupted)]
        );
        let again = h.resume_interrupted(&["demo"], 7).unwrap()[0];
        assert_eq!(h.get(again).unwrap().unwrap().resumes, Some(resume));

        // The service dying during a resume build ends the chain.
        assert!(h.start(again, 8).unwrap());
        assert_eq!(
            h.interrupt_running("died", Left::Died, 9).unwrap(),
            vec![(again, BuildState::Failed)]
        );
        let rec = h.get(again).unwrap().unwrap();
        let error = rec.error.unwrap();
        assert!(error.contains("interrupted twice"), "{error}");
        assert!(error.contains("request a new build"), "{error}");
        assert_eq!(rec.log.last(), Some(&error));
        assert!(h.resume_interrupted(&["demo"], 10).unwrap().is_empty());
        assert!(h.queued().unwrap().is_empty());
    }

    #[test]
    fn a_second_history_on_the_same_folder_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let _first = History::open(dir.path()).unwrap();
        let err = History::open(dir.path()).unwrap_err();
        assert!(matches!(err, HistoryError::Locked { .. }), "{err}");
    }
}
