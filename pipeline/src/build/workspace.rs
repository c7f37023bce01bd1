//! The build workspace: content fingerprints, the per-item stage cache and atomic writes.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use std::collections::BTreeMap;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::motion::skeleton::hex;

/// Errors of the workspace: always name the file involved.
#[derive(Debug, thiserror::Error)]
pub enum WorkspaceError {
    /// An I/O error on a file.
    #[error("{path}: {source}{}", io_hint(source))]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A value could not be serialised for the cache.
    #[error("cannot encode {what}: {message}")]
    Encode {
        /// What was being encoded.
        what: String,
        /// The encoder's message.
        message: String,
    },
    /// Another process is building the same dataset folder, or its lock cannot be taken.
    #[error(transparent)]
    Lock(#[from] super::lock::LockError),
}

/// What to do about the I/O errors a person can fix, for error messages.
pub fn io_hint(error: &std::io::Error) -> &'static str {
    use std::io::ErrorKind;
    match error.kind() {
        ErrorKind::StorageFull | ErrorKind::QuotaExceeded => {
            "; the disk is full: free some space, or build into another folder with --output"
        }
        ErrorKind::FileTooLarge => {
            "; the file size limit was reached (`ulimit -f`, or the file system's limit)"
        }
        ErrorKind::PermissionDenied => {
            "; no permission to write there: fix the folder's permissions, or build into another folder with --output"
        }
        ErrorKind::ReadOnlyFilesystem => {
            "; the file system is read-only: build into another folder with --output"
        }
        ErrorKind::NotADirectory => "; a file stands where this path needs a folder",
        _ => "",
    }
}

pub(crate) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> WorkspaceError + '_ {
    move |source| WorkspaceError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// SHA-256 of bytes, hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// A content fingerprint: stage name and version, its config, and its inputs' digests. Each
/// piece is named, so `plan` can say which one changed since the last run.
#[derive(Debug, Clone)]
pub struct Fingerprint {
    hasher: Sha256,
    parts: BTreeMap<String, String>,
}

/// A finished fingerprint with the digest of each named piece.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Stamp {
    /// The fingerprint (hex).
    pub fingerprint: String,
    /// Digest of each named piece (short hex), by name.
    pub parts: BTreeMap<String, String>,
}

impl Fingerprint {
    /// Starts a fingerprint for a stage at a version.
    pub fn new(stage: &str, version: u32) -> Self {
        let mut h = Sha256::new();
        h.update(stage.as_bytes());
        h.update([0]);
        h.update(version.to_le_bytes());
        Fingerprint {
            hasher: h,
            parts: BTreeMap::from([("stage version".to_string(), version.to_string())]),
        }
    }

    /// Adds a string, named for reports (length-prefixed so concatenations cannot collide).
    pub fn text(mut self, name: &str, s: &str) -> Self {
        self.hasher.update((s.len() as u64).to_le_bytes());
        self.hasher.update(s.as_bytes());
        let digest = sha256_hex(s.as_bytes());
        self.parts
            .insert(name.to_string(), digest[..16.min(digest.len())].to_string());
        self
    }

    /// Adds a serialisable value through its JSON form (configs, options), named for reports.
    pub fn json<T: Serialize>(self, name: &str, value: &T) -> Self {
        let s = serde_json::to_string(value).unwrap_or_default();
        self.text(name, &s)
    }

    /// The hex digest.
    pub fn finish(self) -> String {
        hex(&self.hasher.finalize())
    }

    /// The hex digest with its named pieces.
    pub fn stamp(self) -> Stamp {
        let parts = self.parts.clone();
        Stamp {
            fingerprint: self.finish(),
            parts,
        }
    }
}

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, fsync, rename. An
/// interrupted write leaves at most a `.tmp` file, never a file that looks complete.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WorkspaceError> {
    write_atomic_with(path, |file| file.write_all(bytes))
}

/// Like [`write_atomic`], with a writer callback for streamed output.
pub fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&mut fs::File) -> std::io::Result<()>,
) -> Result<(), WorkspaceError> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    fs::create_dir_all(dir).map_err(io_err(dir))?;
    let tmp = temp_path(path);
    let result = (|| {
        let mut file = fs::File::create(&tmp)?;
        write(&mut file)?;
        file.sync_all()?;
        fs::rename(&tmp, path)
    })();
    if let Err(source) = result {
        let _ = fs::remove_file(&tmp);
        return Err(WorkspaceError::Io {
            path: path.to_path_buf(),
            source,
        });
    }
    // Make the rename itself durable; not every platform can open a folder, so this is best effort.
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// A fresh temporary name for writing `path`: `.<name>.<n>.<pid>.tmp`, with `n` new at every
/// call. Two threads may write the same path at once (content-named frame chunks of two identical
/// captures): with one name per process, one thread's create would truncate the other's file and
/// its rename would then find nothing to rename.
pub fn temp_path(path: &Path) -> PathBuf {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{n}.{}.tmp", std::process::id()))
}

/// The file recording, per stage and item, the fingerprint of the last run.
pub const LEDGER_FILE: &str = "ledger.json";

/// What the last runs of each stage saw: per item, its [`Stamp`]; per stage, when and how much.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Ledger {
    /// By stage name.
    pub stages: BTreeMap<String, StageLedger>,
}

/// One stage's record in the [`Ledger`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StageLedger {
    /// When the stage last ran or was checked fresh (seconds since the Unix epoch).
    pub last_run: u64,
    /// Items covered then.
    pub items: usize,
    /// Items computed then.
    pub ran: usize,
    /// Items reused then.
    pub reused: usize,
    /// The stamp of each item (capture path, or `*` for stages over the whole set).
    pub entries: BTreeMap<String, Stamp>,
}

impl Ledger {
    /// The ledger of a workspace; empty when missing or unreadable (nothing is known, so every
    /// item counts as new).
    pub fn load(workspace: &Workspace) -> Ledger {
        fs::read(workspace.root().join(LEDGER_FILE))
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())
            .unwrap_or_default()
    }

    /// Why an item whose stamp is `now` is not in the cache, compared with the last run.
    pub fn why(&self, stage: &str, key: &str, now: &Stamp) -> String {
        let Some(before) = self.stages.get(stage).and_then(|s| s.entries.get(key)) else {
            return "new".to_string();
        };
        let changed: Vec<&str> = now
            .parts
            .iter()
            .filter(|(name, digest)| before.parts.get(*name) != Some(*digest))
            .map(|(name, _)| name.as_str())
            .chain(
                before
                    .parts
                    .keys()
                    .filter(|name| !now.parts.contains_key(*name))
                    .map(String::as_str),
            )
            .collect();
        if changed.is_empty() {
            "cache entry missing (cleaned or pruned)".to_string()
        } else {
            format!("changed: {}", changed.join(", "))
        }
    }
}

/// A stage item the probe found missing from the cache.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Miss {
    /// Stage name.
    pub stage: String,
    /// Item key.
    pub key: String,
    /// Its stamp now.
    pub stamp: Stamp,
}

/// The per-item stage cache under `<output>/.motionforge/cache/<stage>/<fingerprint>`. In probe
/// mode (for `plan`) nothing is computed or stored: misses are collected instead.
#[derive(Debug, Clone)]
pub struct Workspace {
    root: PathBuf,
    probe: bool,
    seen: std::sync::Arc<std::sync::Mutex<Vec<Miss>>>,
}

impl Workspace {
    /// The workspace of an output folder.
    pub fn new(output: &Path) -> Workspace {
        Workspace {
            root: output.join(".motionforge"),
            probe: false,
            seen: Default::default(),
        }
    }

    /// The same workspace in probe mode: [`Workspace::item`] computes nothing on a miss.
    pub fn probing(output: &Path) -> Workspace {
        Workspace {
            probe: true,
            ..Workspace::new(output)
        }
    }

    /// True in probe mode.
    pub fn is_probe(&self) -> bool {
        self.probe
    }

    /// Every item stamp seen in this run (hits and misses), for the ledger.
    pub fn seen(&self) -> Vec<Miss> {
        self.seen.lock().map(|v| v.clone()).unwrap_or_default()
    }

    /// The cached output of `stage` for item `key`, or computes and stores it; the flag says
    /// whether it ran. In probe mode a miss returns `None` and computes nothing.
    pub fn item<T: Serialize + DeserializeOwned>(
        &self,
        stage: &str,
        key: &str,
        stamp: &Stamp,
        compute: impl FnOnce() -> T,
    ) -> Result<Option<(T, bool)>, WorkspaceError> {
        self.try_item(stage, key, stamp, || Ok::<T, WorkspaceError>(compute()))
    }

    /// Like [`Workspace::item`], for a computation that can fail.
    pub fn try_item<T: Serialize + DeserializeOwned, E: From<WorkspaceError>>(
        &self,
        stage: &str,
        key: &str,
        stamp: &Stamp,
        compute: impl FnOnce() -> Result<T, E>,
    ) -> Result<Option<(T, bool)>, E> {
        if let Ok(mut seen) = self.seen.lock() {
            seen.push(Miss {
                stage: stage.to_string(),
                key: key.to_string(),
                stamp: stamp.clone(),
            });
        }
        if let Some(v) = self.load(stage, &stamp.fingerprint) {
            return Ok(Some((v, false)));
        }
        if self.probe {
            return Ok(None);
        }
        let v = compute()?;
        self.store(stage, &stamp.fingerprint, &v)?;
        Ok(Some((v, true)))
    }

    /// True when `stage` has a cached output under `fingerprint`.
    pub fn has(&self, stage: &str, fingerprint: &str) -> bool {
        self.entry(stage, fingerprint).is_file()
    }

    /// The workspace folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    fn entry(&self, stage: &str, fingerprint: &str) -> PathBuf {
        self.root
            .join("cache")
            .join(stage)
            .join(format!("{fingerprint}.bin"))
    }

    /// A cached stage output, if present and readable. A damaged entry counts as absent, so the
    /// item is recomputed rather than trusted.
    pub fn load<T: DeserializeOwned>(&self, stage: &str, fingerprint: &str) -> Option<T> {
        let bytes = fs::read(self.entry(stage, fingerprint)).ok()?;
        postcard::from_bytes(&bytes).ok()
    }

    /// Stores a stage output atomically.
    pub fn store<T: Serialize>(
        &self,
        stage: &str,
        fingerprint: &str,
        value: &T,
    ) -> Result<(), WorkspaceError> {
        let bytes = postcard::to_stdvec(value).map_err(|e| WorkspaceError::Encode {
            what: format!("{stage} output"),
            message: e.to_string(),
        })?;
        write_atomic(&self.entry(stage, fingerprint), &bytes)
    }

    /// Stores already-encoded bytes under `fingerprint`, unless an entry is there.
    pub fn store_bytes(
        &self,
        stage: &str,
        fingerprint: &str,
        bytes: &[u8],
    ) -> Result<(), WorkspaceError> {
        let path = self.entry(stage, fingerprint);
        if path.is_file() {
            return Ok(());
        }
        write_atomic(&path, bytes)
    }

    /// Removes cache entries of `stage` not in `keep` (old fingerprints).
    pub fn prune(&self, stage: &str, keep: &std::collections::BTreeSet<String>) {
        if self.probe {
            return;
        }
        let dir = self.root.join("cache").join(stage);
        let Ok(entries) = fs::read_dir(&dir) else {
            return;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let stem = path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            if !keep.contains(&stem) {
                let _ = fs::remove_file(&path);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threads_writing_the_same_path_at_once_all_succeed() {
        let dir = std::env::temp_dir().join(format!("mf-atomic-{}", std::process::id()));
        let path = dir.join("chunk.bin");
        let bytes = vec![7u8; 1 << 20];
        std::thread::scope(|s| {
            let handles: Vec<_> = (0..4)
                .map(|_| {
                    s.spawn(|| {
                        (0..20)
                            .map(|_| write_atomic(&path, &bytes))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            for h in handles {
                for result in h.join().unwrap() {
                    result.unwrap();
                }
            }
        });
        assert_eq!(fs::read(&path).unwrap(), bytes);
        let names: Vec<String> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["chunk.bin"], "no temporary file is left");
        fs::remove_dir_all(&dir).unwrap();
    }
}
