//! SHA-256 digests of capture files, remembered with each file's length and modification time,
//! so that a file whose stat data is unchanged is not read again only to be hashed: the trust
//! make, cargo and git place in stat data. A build reads the bytes of a capture only when a stage
//! must run on it.

use std::collections::BTreeMap;
use std::fs::Metadata;
use std::sync::Mutex;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use super::{Workspace, WorkspaceError, write_atomic};

/// Inside the workspace: the remembered digests.
const DIGESTS_FILE: &str = "file-digests.json";

/// A file modified this recently is not remembered: another write in the same clock tick could
/// change it without changing its stat data (git's "racily clean" case).
const SETTLE: Duration = Duration::from_secs(2);

/// A file's stat data and the digest of its bytes when they were read.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
struct FileStamp {
    len: u64,
    modified_ns: u128,
    sha256: String,
}

/// A file's stat data as the build compares it: length and modification time in nanoseconds.
pub(super) fn stat_data(meta: &Metadata) -> Option<(u64, u128)> {
    let modified = meta.modified().ok()?.duration_since(UNIX_EPOCH).ok()?;
    Some((meta.len(), modified.as_nanos()))
}

/// Digests remembered by the last build, and those seen by this one.
#[derive(Debug, Default)]
pub(super) struct FileDigests {
    known: BTreeMap<String, FileStamp>,
    seen: Mutex<BTreeMap<String, FileStamp>>,
}

impl FileDigests {
    /// The digests `workspace` remembers (none when the file is missing or unreadable).
    pub(super) fn load(workspace: &Workspace) -> FileDigests {
        let known = std::fs::read(workspace.root().join(DIGESTS_FILE))
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())
            .unwrap_or_default();
        FileDigests {
            known,
            seen: Mutex::new(BTreeMap::new()),
        }
    }

    /// The remembered digest of the file at `path` when its length and modification time are
    /// those recorded with it.
    pub(super) fn known(&self, path: &str, meta: &Metadata) -> Option<String> {
        let stamp = self.known.get(path)?;
        let (len, modified_ns) = stat_data(meta)?;
        (stamp.len == len && stamp.modified_ns == modified_ns).then(|| stamp.sha256.clone())
    }

    /// Remembers `sha256` for the file at `path` with stat data `meta`, unless it was modified
    /// too recently to be trusted.
    pub(super) fn record(&self, path: &str, meta: &Metadata, sha256: &str) {
        let Some((len, modified_ns)) = stat_data(meta) else {
            return;
        };
        let settled = SystemTime::now()
            .checked_sub(SETTLE)
            .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
            .is_some_and(|t| modified_ns < t.as_nanos());
        if !settled {
            return;
        }
        if let Ok(mut seen) = self.seen.lock() {
            seen.insert(
                path.to_string(),
                FileStamp {
                    len,
                    modified_ns,
                    sha256: sha256.to_string(),
                },
            );
        }
    }

    /// Writes the digests seen by this build (files no longer found are forgotten), unless they
    /// are those already remembered. Taken by value: nothing reads them after the captures are
    /// read, and a build of many captures would hold two maps of paths until it ends.
    pub(super) fn save(self, workspace: &Workspace) -> Result<(), WorkspaceError> {
        let Ok(seen) = self.seen.into_inner() else {
            return Ok(());
        };
        if workspace.is_probe() || seen == self.known {
            return Ok(());
        }
        let json = serde_json::to_vec(&seen).unwrap_or_default();
        write_atomic(&workspace.root().join(DIGESTS_FILE), &json)
    }
}
