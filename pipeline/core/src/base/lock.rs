//! The workspace lock: one build (or clean) at a time per dataset folder.
//!
//! The OS file lock on `<dataset>/.motionforge/lock` (`flock` on Unix) is the authority: the
//! kernel releases it when its holder exits, however it exits, so a killed build never blocks the
//! next one. The file's content only describes the holder for error messages. A holder that ends
//! normally empties it, so content found under a free lock means the last holder was killed: that
//! stale lock is reported and taken over, and the temporary files its holder left are removed.

use std::fs::{self, File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use serde::{Deserialize, Serialize};

/// Name of the lock file inside the workspace folder (`.motionforge/`).
pub const LOCK_FILE: &str = "lock";

/// How often a waiting process tries the lock again.
const POLL: Duration = Duration::from_millis(100);

/// Who holds (or last held) a workspace lock, as written into the lock file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Holder {
    /// Process id.
    pub pid: u32,
    /// Host name, when it could be read.
    #[serde(default)]
    pub host: Option<String>,
    /// When the lock was taken (RFC 3339, UTC).
    pub started: String,
    /// The command line of the holder.
    #[serde(default)]
    pub command: String,
}

impl Holder {
    /// This process, now.
    pub fn current() -> Holder {
        Holder {
            pid: std::process::id(),
            host: host_name(),
            started: humantime::format_rfc3339_seconds(SystemTime::now()).to_string(),
            command: std::env::args().collect::<Vec<_>>().join(" "),
        }
    }

    fn describe(&self) -> String {
        let host = self
            .host
            .as_deref()
            .map(|h| format!(" on {h}"))
            .unwrap_or_default();
        let command = if self.command.is_empty() {
            String::new()
        } else {
            format!(" (`{}`)", self.command)
        };
        format!("pid {}{host} since {}{command}", self.pid, self.started)
    }
}

fn host_name() -> Option<String> {
    let name = fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())?;
    let name = name.trim();
    (!name.is_empty()).then(|| name.to_string())
}

/// Why a workspace lock could not be taken.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// The lock file cannot be created or locked (an unwritable or missing folder).
    #[error(
        "{path}: cannot take the workspace lock: {source}{}",
        match super::io_hint(source) {
            "" => "; check that the output folder can be created and written",
            hint => hint,
        }
    )]
    Io {
        /// The lock file (or the folder that could not be created).
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// Another process holds the lock.
    #[error("{}", busy_message(dataset, holder.as_ref(), *waited))]
    Busy {
        /// The dataset folder.
        dataset: PathBuf,
        /// The holder, as its lock file describes it (absent while it is still being written).
        holder: Option<Holder>,
        /// How long this process waited before giving up (`None`: it did not wait).
        waited: Option<Duration>,
    },
}

fn busy_message(dataset: &Path, holder: Option<&Holder>, waited: Option<Duration>) -> String {
    let who = holder
        .map(Holder::describe)
        .unwrap_or_else(|| "another motionforge process".to_string());
    match waited {
        None => format!(
            "dataset folder {} is being built by {who}; wait for it with --wait 30s (or 5m, 1h), or stop that process",
            dataset.display()
        ),
        Some(w) => format!(
            "dataset folder {} is still being built by {who} after waiting {}; wait longer with --wait, or stop that process",
            dataset.display(),
            humantime::format_duration(Duration::from_secs(w.as_secs().max(1)))
        ),
    }
}

/// An exclusive hold on a dataset folder's workspace; released when dropped.
#[derive(Debug)]
pub struct WorkspaceLock {
    file: File,
    path: PathBuf,
    stale: Option<StaleLock>,
}

/// A lock left by a holder that ended without releasing it, taken over by [`WorkspaceLock`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StaleLock {
    /// The dead holder, when its lock file described it.
    pub holder: Option<Holder>,
    /// Its temporary files that were removed.
    pub removed: usize,
}

impl WorkspaceLock {
    /// Takes the lock of `dataset_dir` (creating `.motionforge/` as needed). When another process
    /// holds it: fails at once with `wait = None`, else tries again until `wait` has passed.
    pub fn acquire(dataset_dir: &Path, wait: Option<Duration>) -> Result<WorkspaceLock, LockError> {
        let dir = dataset_dir.join(".motionforge");
        fs::create_dir_all(&dir).map_err(|source| LockError::Io {
            path: dir.clone(),
            source,
        })?;
        let path = dir.join(LOCK_FILE);
        let io = |source| LockError::Io {
            path: path.clone(),
            source,
        };
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io)?;
        let start = Instant::now();
        let mut announced = false;
        loop {
            match file.try_lock() {
                Ok(()) => break,
                Err(fs::TryLockError::WouldBlock) => {
                    let holder = read_holder(&path);
                    let Some(limit) = wait else {
                        return Err(LockError::Busy {
                            dataset: dataset_dir.to_path_buf(),
                            holder,
                            waited: None,
                        });
                    };
                    let waited = start.elapsed();
                    if waited >= limit {
                        return Err(LockError::Busy {
                            dataset: dataset_dir.to_path_buf(),
                            holder,
                            waited: Some(waited),
                        });
                    }
                    if !announced {
                        announced = true;
                        tracing::info!(
                            dataset = %dataset_dir.display(),
                            holder_pid = holder.as_ref().map(|h| h.pid),
                            "dataset folder {} is being built by {}; waiting up to {}",
                            dataset_dir.display(),
                            holder
                                .as_ref()
                                .map(Holder::describe)
                                .unwrap_or_else(|| "another motionforge process".into()),
                            humantime::format_duration(limit)
                        );
                    }
                    std::thread::sleep(POLL.min(limit - waited));
                }
                Err(fs::TryLockError::Error(e)) => return Err(io(e)),
            }
        }
        // Content under a free lock: the last holder never released it.
        let mut previous = String::new();
        file.read_to_string(&mut previous).map_err(io)?;
        let stale = if previous.trim().is_empty() {
            None
        } else {
            let holder = serde_json::from_str::<Holder>(previous.trim()).ok();
            let removed = holder
                .as_ref()
                .map(|h| remove_temp_files(dataset_dir, h.pid))
                .unwrap_or(0);
            tracing::warn!(
                dataset = %dataset_dir.display(),
                stale_pid = holder.as_ref().map(|h| h.pid),
                removed_temp_files = removed,
                "took over a stale lock on {}: {} ended without releasing it (killed?); removed {removed} temporary files it left",
                dataset_dir.display(),
                holder
                    .as_ref()
                    .map(Holder::describe)
                    .unwrap_or_else(|| "its holder".into()),
            );
            Some(StaleLock { holder, removed })
        };
        let me = serde_json::to_string(&Holder::current()).unwrap_or_default();
        file.set_len(0)
            .and_then(|()| file.seek(SeekFrom::Start(0)))
            .and_then(|_| file.write_all(format!("{me}\n").as_bytes()))
            .map_err(io)?;
        Ok(WorkspaceLock { file, path, stale })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The stale lock this one took over, if any.
    pub fn took_over(&self) -> Option<&StaleLock> {
        self.stale.as_ref()
    }
}

impl Drop for WorkspaceLock {
    fn drop(&mut self) {
        // Empty first: a file with content under a free lock reads as a killed holder.
        let _ = self.file.set_len(0);
        let _ = self.file.unlock();
    }
}

/// The holder described by a lock file, if it has a readable description.
pub fn read_holder(path: &Path) -> Option<Holder> {
    let text = fs::read_to_string(path).ok()?;
    serde_json::from_str(text.trim()).ok()
}

/// Removes the temporary files (`.<name>.<n>.<pid>.tmp`, see [`super::temp_path`]) that process `pid`
/// left anywhere under `dir`; returns how many. Only called under the lock, after that process
/// died, so none of them can still be in use.
fn remove_temp_files(dir: &Path, pid: u32) -> usize {
    let suffix = format!(".{pid}.tmp");
    let mut removed = 0;
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        let Ok(entries) = fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            let Ok(kind) = entry.file_type() else {
                continue;
            };
            let name = entry.file_name().to_string_lossy().into_owned();
            if kind.is_dir() {
                stack.push(entry.path());
            } else if kind.is_file()
                && name.starts_with('.')
                // PNG figures keep their extension after the marker (`.x.png.<n>.<pid>.tmp.png`).
                && (name.ends_with(&suffix) || name.contains(&format!("{suffix}.")))
                && fs::remove_file(entry.path()).is_ok()
            {
                removed += 1;
            }
        }
    }
    removed
}
