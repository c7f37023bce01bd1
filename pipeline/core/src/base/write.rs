//! Content fingerprints, digests and atomic writes: how every output is named and written.

use std::collections::BTreeMap;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// Bytes as lowercase hexadecimal.
pub fn hex(bytes: &[u8]) -> String {
    // By table: `write!("{b:02x}")` per byte went through the formatter, a few percent of a no-op
    // rebuild (every fingerprint and digest is printed in hex).
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        s.push(char::from(DIGITS[usize::from(b >> 4)]));
        s.push(char::from(DIGITS[usize::from(b & 0x0f)]));
    }
    s
}

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
    #[error("cannot encode {what}: {source}")]
    Encode {
        /// What was being encoded.
        what: String,
        /// The encoder's error.
        source: postcard::Error,
    },
    /// Encoded bytes could not be compressed for the cache.
    #[error("cannot encode {what}: {source}")]
    Compress {
        /// What was being compressed.
        what: String,
        /// The compressor's error.
        source: std::io::Error,
    },
    /// Values a build set aside (in memory or a temporary file) do not come back whole.
    #[error("cannot encode {what}: {problem}")]
    ReadBack {
        /// What was read back.
        what: String,
        /// What failed.
        problem: ReadBackProblem,
    },
    /// Another process is building the same dataset folder, or its lock cannot be taken.
    #[error(transparent)]
    Lock(#[from] super::lock::LockError),
}

/// Why values set aside during a build do not come back.
#[derive(Debug, thiserror::Error)]
pub enum ReadBackProblem {
    /// The temporary file they were spilled to is gone.
    #[error("the spill file is gone")]
    SpillGone,
    /// Reading or decompressing them failed.
    #[error("{0}")]
    Io(#[source] std::io::Error),
    /// They do not decode.
    #[error("{0}")]
    Decode(#[source] postcard::Error),
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

/// Turns an I/O error on `path` into a [`WorkspaceError`] naming it.
pub fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> WorkspaceError + '_ {
    move |source| WorkspaceError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// SHA-256 of bytes, hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// The hex SHA-256 of `value`'s postcard encoding, hashed as it is encoded: a fingerprint over a
/// whole dataset's clips never holds their encoding in memory (at ten times Bandai Namco 2 that
/// encoding was a few hundred MB). `what` names the value in errors.
pub fn encoded_sha256<T: Serialize + ?Sized>(
    value: &T,
    what: &str,
) -> Result<String, WorkspaceError> {
    let hashing =
        postcard::to_io(value, HashingWriter::new(std::io::sink())).map_err(|source| {
            WorkspaceError::Encode {
                what: what.to_string(),
                source,
            }
        })?;
    Ok(hashing.finish().1)
}

/// A writer that hashes (SHA-256) and counts what passes through it, so a file's checksum is known
/// when it is written, without reading it back.
#[derive(Debug)]
pub struct HashingWriter<W> {
    inner: W,
    hasher: Sha256,
    bytes: u64,
}

impl<W: Write> HashingWriter<W> {
    /// Hashes what is written to `inner`.
    pub fn new(inner: W) -> HashingWriter<W> {
        HashingWriter {
            inner,
            hasher: Sha256::new(),
            bytes: 0,
        }
    }

    /// The writer, the hex SHA-256 of everything written and its length in bytes.
    pub fn finish(self) -> (W, String, u64) {
        (self.inner, hex(&self.hasher.finalize()), self.bytes)
    }
}

impl<W: Write> Write for HashingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hasher.update(&buf[..n]);
        self.bytes += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
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
    replace(path, write, true)
}

/// Like [`write_atomic_with`] without the fsyncs, for files that can be made again (the stage
/// cache): the rename still keeps readers from ever seeing a partial file while the system runs,
/// and the caller must be able to tell a file cut short by a crash (the cache's entry footer).
/// Thousands of small cache entries per build made the fsyncs half of the ingest stage's time.
pub fn write_replaceable_with(
    path: &Path,
    write: impl FnOnce(&mut fs::File) -> std::io::Result<()>,
) -> Result<(), WorkspaceError> {
    replace(path, write, false)
}

fn replace(
    path: &Path,
    write: impl FnOnce(&mut fs::File) -> std::io::Result<()>,
    durable: bool,
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
        if durable {
            file.sync_all()?;
        }
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
    if durable && let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// Puts the finished folder `staging` at `out`, replacing the folder `out` held: `out` is at every
/// moment the old folder or the new one, never a mix or a half-removed one. On Linux the two are
/// swapped in one `renameat2(RENAME_EXCHANGE)` and the old one is then removed from where the
/// staging folder was; elsewhere the old folder is first moved aside to a sibling
/// `.<name>.replaced`, which [`restore_replaced`] puts back if the swap was interrupted.
pub fn replace_dir(staging: &Path, out: &Path) -> Result<(), WorkspaceError> {
    if fs::symlink_metadata(out).is_err() {
        return fs::rename(staging, out).map_err(io_err(out));
    }
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    if exchange(staging, out).is_ok() {
        // `staging` now holds the old folder; a failure to remove it leaves a hidden leftover
        // the next run clears, never a damaged output.
        let _ = fs::remove_dir_all(staging);
        return Ok(());
    }
    let aside = sibling(out, "replaced");
    if fs::symlink_metadata(&aside).is_ok() {
        fs::remove_dir_all(&aside).map_err(io_err(&aside))?;
    }
    fs::rename(out, &aside).map_err(io_err(out))?;
    fs::rename(staging, out).map_err(io_err(out))?;
    let _ = fs::remove_dir_all(&aside);
    Ok(())
}

/// Puts back an old folder [`replace_dir`] moved aside and did not get to replace (a run
/// interrupted between its two renames), so `out` is never simply gone.
pub fn restore_replaced(out: &Path) -> Result<(), WorkspaceError> {
    let aside = sibling(out, "replaced");
    if fs::symlink_metadata(out).is_err() && aside.is_dir() {
        fs::rename(&aside, out).map_err(io_err(out))?;
    }
    Ok(())
}

/// `.<name>.<what>` beside `path`: the hidden working names of a folder being replaced.
pub fn sibling(path: &Path, what: &str) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    path.with_file_name(format!(".{name}.{what}"))
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| {
        std::ffi::CString::new(p.as_os_str().as_bytes())
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))
    };
    let (a, b) = (c(a)?, c(b)?);
    // SAFETY: both paths are NUL-terminated C strings that live across the call.
    let rc = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            a.as_ptr(),
            libc::AT_FDCWD,
            b.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_is_lowercase_two_digits_per_byte() {
        assert_eq!(hex(&[0x00, 0x0f, 0xa5, 0xff]), "000fa5ff");
        // FIPS 180-2's example: the fingerprints' digests keep their spelling.
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

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
