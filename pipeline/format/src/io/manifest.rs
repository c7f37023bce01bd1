//! `manifest.json`: what a built dataset holds (shards with checksums, counts, sources,
//! fingerprints), as one typed value that the writer writes and every reader reads.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use motionforge_core::base::{DropReason, Reject, RejectReason, Tally};
use motionforge_sources::clip::{Clip, SourceKind};

// Fields are declared in alphabetical order: the file's keys have always been sorted, and a
// struct serialises in declaration order.

/// The manifest of a dataset folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Fingerprint of the config's content (not of where the dataset is written).
    pub config_fingerprint: String,
    /// Counts by reason, kind and source.
    pub counts: Counts,
    /// Dataset name.
    pub dataset: String,
    /// The companion files' names.
    pub files: Files,
    /// Frame rate of every clip.
    pub fps: f64,
    /// Clips whose text contradicts what their motion measurably does (issue 16), by clip id;
    /// listed, never fixed. Absent when there are none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub label_contradictions: Vec<motionforge_core::quality::Contradiction>,
    /// The program that wrote it (`motionforge 0.1.0`).
    pub pipeline: String,
    /// Version of the clip table's schema.
    pub schema_version: u32,
    /// The config's seed.
    pub seed: u64,
    /// Every capture a row comes from, with its checksum.
    pub sources: Vec<Source>,
    /// Rows and shards per split.
    #[serde(default)]
    pub splits: BTreeMap<String, SplitShards>,
    /// Fingerprint of the write stage's input.
    pub table_fingerprint: String,
}

/// Counts of the dataset, each by name.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Counts {
    /// Segments dropped, by reason.
    pub drop_reason: Tally<DropReason>,
    /// Rows by label source.
    pub label_source: BTreeMap<String, usize>,
    /// Original single clips by motion type.
    pub motion_type: BTreeMap<String, usize>,
    /// Rejected inputs by reason.
    pub reject_reason: Tally<RejectReason>,
    /// Rows by source kind.
    pub source_kind: Tally<SourceKind>,
}

/// The companion files.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Files {
    /// Task-plan table.
    pub plans: String,
    /// Rejects list.
    pub rejects: String,
    /// Skeleton descriptions.
    pub skeletons: String,
}

/// A capture rows come from.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Source {
    /// Capture path as shown in the table.
    pub path: String,
    /// SHA-256 of the capture file.
    pub sha256: String,
    /// Source name.
    pub source: String,
}

/// One split: its rows and shards.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SplitShards {
    /// Rows in the split.
    pub rows: usize,
    /// Its shards, in order.
    pub shards: Vec<Shard>,
}

/// One shard file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shard {
    /// Size in bytes.
    pub bytes: usize,
    /// Path inside the dataset folder (`data/train-00000-of-00001.parquet`).
    pub file: String,
    /// Rows in the shard.
    pub rows: usize,
    /// SHA-256 of the file.
    pub sha256: String,
}

/// Why a manifest cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    /// The file cannot be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The file is not a manifest.
    #[error("{path}:{line}: not a motionforge manifest: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Line of the problem.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

impl Manifest {
    /// The manifest of `dataset` (its `manifest.json`); `None` when the folder has none (not a
    /// finished dataset), an error when it has one that cannot be read.
    pub fn read(dataset: &Path) -> Result<Option<Manifest>, ManifestError> {
        let path = dataset.join(motionforge_core::base::layout::MANIFEST_FILE);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(ManifestError::Io { path, source }),
        };
        serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|e| ManifestError::Invalid {
                line: e.line(),
                message: e.to_string(),
                path,
            })
    }

    /// The manifest as written: pretty JSON.
    pub fn to_json(&self) -> Vec<u8> {
        serde_json::to_vec_pretty(self).unwrap_or_default()
    }
}

/// Label of clips without a motion type, in `counts.motion_type`.
pub const UNMAPPED: &str = "(unmapped)";
/// Label of clips without parts, in `counts.label_source`.
pub const NO_LABEL: &str = "(none)";

impl Counts {
    /// The counts of a dataset, made once here for the manifest, the card and the build report:
    /// rows by source kind and by label source, original single clips by motion type (mirrors
    /// are the same actions again), rejected inputs by reason, and the segments dropped by reason
    /// as the segment stage counted them.
    pub fn of(clips: &[Clip], rejects: &[Reject], drop_reason: Tally<DropReason>) -> Counts {
        let mut counts = Counts {
            drop_reason,
            reject_reason: rejects.iter().map(|r| r.reason).collect(),
            ..Counts::default()
        };
        for clip in clips {
            counts.source_kind.add(clip.kind);
            let label = clip
                .label_source
                .as_ref()
                .map_or_else(|| NO_LABEL.into(), ToString::to_string);
            *counts.label_source.entry(label).or_insert(0) += 1;
            if !clip.mirrored && clip.kind == SourceKind::RealSingle {
                let t = clip.motion_type.as_deref().unwrap_or(UNMAPPED);
                *counts.motion_type.entry(t.to_string()).or_insert(0) += 1;
            }
        }
        counts
    }
}

/// Rows by action, mirrors left out (a mirror repeats its original's action).
pub fn action_counts(clips: &[Clip]) -> BTreeMap<String, usize> {
    let mut actions: BTreeMap<&str, usize> = BTreeMap::new();
    for clip in clips.iter().filter(|c| !c.mirrored) {
        *actions.entry(clip.action.as_str()).or_insert(0) += 1;
    }
    actions
        .into_iter()
        .map(|(action, n)| (action.to_string(), n))
        .collect()
}

/// What a manifest records of the config a dataset was built from.
#[derive(Debug, Clone)]
pub struct BuiltFrom {
    /// The dataset's name.
    pub dataset: String,
    /// The dataset's frame rate.
    pub fps: f64,
    /// The config's seed.
    pub seed: u64,
    /// Fingerprint of the config's content, without where the dataset is written (the same
    /// config built into another folder gives the same bytes).
    pub config_fingerprint: String,
}

impl Manifest {
    /// The manifest of a dataset built from `from` with rows `clips`, before its shards are
    /// written (`splits` is filled in by the writer).
    pub fn new(from: BuiltFrom, clips: &[Clip], counts: Counts, table_fingerprint: &str) -> Self {
        // Distinct captures first, in `Source` order (path, digest, source name), then copied:
        // a copy per clip, most of them dropped as repeats, left the survivors scattered over the
        // allocator's pages (three clips per capture or more, and this runs on every build).
        let distinct: BTreeSet<(&str, &str, &str)> = clips
            .iter()
            .map(|c| {
                let capture = &*c.capture;
                (
                    capture.path.as_str(),
                    capture.sha256.as_str(),
                    capture.source.as_str(),
                )
            })
            .collect();
        let sources: Vec<Source> = distinct
            .into_iter()
            .map(|(path, sha256, source)| Source {
                path: path.to_string(),
                sha256: sha256.to_string(),
                source: source.to_string(),
            })
            .collect();
        Manifest {
            config_fingerprint: from.config_fingerprint,
            counts,
            dataset: from.dataset,
            files: Files {
                plans: motionforge_core::base::layout::PLANS_FILE.into(),
                rejects: motionforge_core::base::layout::REJECTS_FILE.into(),
                skeletons: motionforge_core::base::layout::SKELETONS_FILE.into(),
            },
            fps: from.fps,
            label_contradictions: Vec::new(),
            pipeline: format!("motionforge {}", env!("CARGO_PKG_VERSION")),
            schema_version: crate::io::schema::SCHEMA_VERSION,
            seed: from.seed,
            sources,
            splits: BTreeMap::new(),
            table_fingerprint: table_fingerprint.to_string(),
        }
    }
}
