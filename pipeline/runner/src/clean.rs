//! Removing a built dataset's outputs, or only its stage cache, under the workspace lock.
//!
//! Only the names a build writes are removed, and only inside the dataset folder: files someone
//! put there, and the LLM response cache (answers cost requests), are left alone.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Duration;

use super::lock::{LockError, WorkspaceLock};
use super::{
    CARD_FILE, DATA_DIR, MANIFEST_FILE, NORMALIZATION_DIR, PLANS_FILE, REJECTS_FILE, REPORT_FILE,
    SKELETONS_FILE,
};

/// The stage cache, inside the dataset folder.
const CACHE: &str = ".motionforge/cache";
/// Remembered digests of capture files, inside the dataset folder.
const DIGESTS: &str = ".motionforge/file-digests.json";
/// What the write stage last wrote, inside the dataset folder.
const STATE: &str = ".motionforge/state.json";
/// The statistics report folder.
const REPORT_DIR: &str = "report";

/// Why a clean did not happen or did not finish.
#[derive(Debug, thiserror::Error)]
pub enum CleanError {
    /// The folder has no `.motionforge/` workspace, so it may not be a build's output.
    #[error(
        "{dir} does not look like a motionforge dataset folder (no .motionforge/ inside); nothing removed. Check the folder given, or --config and --output"
    )]
    NotADataset {
        /// The folder.
        dir: PathBuf,
    },
    /// The folder is, or holds, the working or home folder.
    #[error(transparent)]
    Refused(#[from] motionforge_core::base::guard::Refused),
    /// Another process holds the dataset folder.
    #[error(transparent)]
    Lock(#[from] LockError),
    /// A file or folder could not be removed.
    #[error("{path}: cannot remove: {source}")]
    Io {
        /// What could not be removed.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

/// What a clean removed and left.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CleanReport {
    /// Removed entries, relative to the dataset folder, in removal order.
    pub removed: Vec<String>,
    /// Bytes in the removed files.
    pub bytes: u64,
    /// Entries left in the dataset folder that a build did not write, or that are kept on purpose
    /// (the LLM response cache).
    pub kept: Vec<String>,
}

/// Removes the outputs of the dataset in `dataset_dir` (with `cache_only`, only its stage cache),
/// holding its workspace lock (waiting up to `wait` for a running build). A folder that does not
/// exist is already clean.
pub fn clean(
    dataset_dir: &Path,
    cache_only: bool,
    wait: Option<Duration>,
) -> Result<CleanReport, CleanError> {
    let mut report = CleanReport::default();
    if !dataset_dir.exists() {
        return Ok(report);
    }
    if !dataset_dir.join(".motionforge").is_dir() {
        return Err(CleanError::NotADataset {
            dir: dataset_dir.to_path_buf(),
        });
    }
    motionforge_core::base::guard::check_replaceable(
        dataset_dir,
        &motionforge_core::base::guard::Kept::working_folder(),
        "set --config or --output to the dataset's own folder",
    )?;
    let _lock = WorkspaceLock::acquire(dataset_dir, wait)?;
    let names: Vec<&str> = if cache_only {
        vec![CACHE, DIGESTS]
    } else {
        vec![
            DATA_DIR,
            NORMALIZATION_DIR,
            REPORT_DIR,
            MANIFEST_FILE,
            CARD_FILE,
            SKELETONS_FILE,
            REJECTS_FILE,
            REPORT_FILE,
            PLANS_FILE,
            CACHE,
            DIGESTS,
            STATE,
        ]
    };
    let mut targets: Vec<String> = names.into_iter().map(String::from).collect();
    if !cache_only {
        // Leftovers of interrupted atomic writes (`.<name>.<n>.<pid>.tmp`); none is in use under the
        // lock.
        targets.extend(entry_names(dataset_dir).into_iter().filter(|n| is_temp(n)));
    }
    for name in targets {
        let path = dataset_dir.join(&name);
        let Ok(meta) = fs::symlink_metadata(&path) else {
            continue;
        };
        let io = |source| CleanError::Io {
            path: path.clone(),
            source,
        };
        if meta.is_dir() {
            report.bytes += size_of(&path);
            fs::remove_dir_all(&path).map_err(io)?;
        } else {
            report.bytes += meta.len();
            fs::remove_file(&path).map_err(io)?;
        }
        report.removed.push(name);
    }
    report.kept = entry_names(dataset_dir)
        .into_iter()
        .filter(|n| n != ".motionforge")
        .collect();
    Ok(report)
}

/// True when the folder `dir` was made by a build: it has the workspace (`.motionforge/`) or a
/// dataset manifest, or holds nothing but the LLM response cache (which `labels import` puts
/// there before the first build) and leftovers of atomic writes.
pub fn made_by_a_build(dir: &Path) -> bool {
    if dir.join(".motionforge").is_dir()
        || matches!(
            motionforge_format::io::manifest::Manifest::read(dir),
            Ok(Some(_))
        )
    {
        return true;
    }
    entry_names(dir)
        .iter()
        .all(|n| n == motionforge_core::base::layout::LLM_CACHE_FILE || is_temp(n))
}

fn is_temp(name: &str) -> bool {
    name.starts_with('.') && name.ends_with(".tmp")
}

fn entry_names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = fs::read_dir(dir)
        .map(|entries| {
            entries
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

/// Bytes of the files under `dir`, not following symbolic links.
fn size_of(dir: &Path) -> u64 {
    let mut total = 0;
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        let Ok(entries) = fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            match entry.file_type() {
                Ok(t) if t.is_dir() => stack.push(entry.path()),
                Ok(_) => total += entry.metadata().map(|m| m.len()).unwrap_or(0),
                Err(_) => {}
            }
        }
    }
    total
}
