//! The build workspace: content fingerprints, the per-item stage cache and atomic writes.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;
use serde::de::DeserializeOwned;
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

/// A content fingerprint: stage name and version, its config, and its inputs' digests.
#[derive(Debug, Clone)]
pub struct Fingerprint(Sha256);

impl Fingerprint {
    /// Starts a fingerprint for a stage at a version.
    pub fn new(stage: &str, version: u32) -> Self {
        let mut h = Sha256::new();
        h.update(stage.as_bytes());
        h.update([0]);
        h.update(version.to_le_bytes());
        Fingerprint(h)
    }

    /// Adds a string (length-prefixed so concatenations cannot collide).
    pub fn text(mut self, s: &str) -> Self {
        self.0.update((s.len() as u64).to_le_bytes());
        self.0.update(s.as_bytes());
        self
    }

    /// Adds a serialisable value through its JSON form (configs, options).
    pub fn json<T: Serialize>(self, value: &T) -> Self {
        let s = serde_json::to_string(value).unwrap_or_default();
        self.text(&s)
    }

    /// The hex digest.
    pub fn finish(self) -> String {
        hex(&self.0.finalize())
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

/// The temporary name used while writing `path`.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
}

/// The per-item stage cache under `<output>/.motionforge/cache/<stage>/<fingerprint>`.
#[derive(Debug, Clone)]
pub struct Workspace {
    root: PathBuf,
}

impl Workspace {
    /// The workspace of an output folder.
    pub fn new(output: &Path) -> Workspace {
        Workspace {
            root: output.join(".motionforge"),
        }
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

    /// Returns the cached output or computes and stores it; the flag says whether it ran.
    pub fn cached<T: Serialize + DeserializeOwned>(
        &self,
        stage: &str,
        fingerprint: &str,
        compute: impl FnOnce() -> T,
    ) -> Result<(T, bool), WorkspaceError> {
        if let Some(v) = self.load(stage, fingerprint) {
            return Ok((v, false));
        }
        let v = compute();
        self.store(stage, fingerprint, &v)?;
        Ok((v, true))
    }

    /// Removes cache entries of `stage` not in `keep` (old fingerprints).
    pub fn prune(&self, stage: &str, keep: &std::collections::BTreeSet<String>) {
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
