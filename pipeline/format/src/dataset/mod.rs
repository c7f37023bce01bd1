//! A built dataset read back from its folder alone (shards and `skeletons.json`): the one reader
//! of clip tables (finding the shards, reading the columns a caller names, typed decoding:
//! [`OpenShard::read`], [`ShardBatch`]), the clip listing with its filters, one clip's metadata
//! and frames, its motion on its own skeleton (for `export-bvh`) and stick-figure previews. Used
//! by `clips`, `export-bvh`, `preview`, the report and its gallery, the planner, the exports, the
//! service, the build's check of its own shards and `bench-build`; it reads, never writes a
//! dataset.
//!
//! Columns are found by name in each shard's schema, never by position, so a table with added
//! columns still reads.

pub mod preview;
mod read;
pub mod skeletons;
mod table;

use std::path::{Path, PathBuf};

use serde::Serialize;

pub use read::{ClipFrames, OpenShard, ShardReader, read_clip, read_clip_in, read_frames};
pub use skeletons::{SkeletonEntry, Skeletons, SkeletonsError, read_skeletons};
pub use table::{ShardBatch, ShardRead, find_clip_tables, open_clip_tables};

/// Why a dataset folder, or a clip in it, cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A file cannot be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A shard cannot be opened or decoded as Parquet.
    #[error("{}: {source}", path.display())]
    Parquet {
        /// The shard.
        path: PathBuf,
        /// The error.
        source: parquet::errors::ParquetError,
    },
    /// A batch of a shard's rows cannot be decoded.
    #[error("{}: {source}", path.display())]
    Arrow {
        /// The shard.
        path: PathBuf,
        /// The error.
        source: arrow_schema::ArrowError,
    },
    /// A column the read needs is not in the shard.
    #[error("{}: no column `{column}` (is this a motionforge clip table?)", path.display())]
    MissingColumn {
        /// The shard.
        path: PathBuf,
        /// The column.
        column: &'static str,
    },
    /// A column has a type the reader does not accept.
    #[error("{}: column `{column}` has type {found}, expected {expected}", path.display())]
    ColumnType {
        /// The shard.
        path: PathBuf,
        /// The column.
        column: &'static str,
        /// Its Arrow type.
        found: String,
        /// What the reader accepts.
        expected: &'static str,
    },
    /// A column that must have a value is null.
    #[error("{}: `{column}` is null in row {row}", path.display())]
    NullValue {
        /// The shard.
        path: PathBuf,
        /// The column.
        column: &'static str,
        /// The row, from 0 in the shard.
        row: usize,
    },
    /// `skeletons.json` cannot be read or does not describe the skeletons.
    #[error(transparent)]
    Skeletons(#[from] SkeletonsError),
    /// The folder holds no clip table.
    #[error("{}: no clip table (data/*.parquet); build the dataset first", path.display())]
    NotADataset {
        /// The folder.
        path: PathBuf,
    },
    /// No row has this clip id.
    #[error("no clip `{clip_id}` in {} ({count} clips){hint}", path.display())]
    NoClip {
        /// The dataset folder.
        path: PathBuf,
        /// The id asked for.
        clip_id: String,
        /// Rows in the dataset.
        count: usize,
        /// Near ids, as `; did you mean ...`, or empty.
        hint: String,
    },
    /// A preview cannot be drawn or encoded.
    #[error("preview: {message}")]
    Render {
        /// What went wrong.
        message: String,
    },
    /// A row's frames are not what its own counts say.
    #[error("{}: clip `{clip_id}`: {message}", path.display())]
    BadRow {
        /// The shard.
        path: PathBuf,
        /// The row's clip id.
        clip_id: String,
        /// What is inconsistent.
        message: String,
    },
}

/// One row's metadata: everything but its frames.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClipInfo {
    /// The `clip_id` column.
    pub clip_id: String,
    /// `train`, `val`, `test` or the config's own split names.
    pub split: String,
    /// `real_single`, `real_pair` or `synthetic`.
    pub source_kind: String,
    /// A mirrored copy.
    pub mirrored: bool,
    /// The motion type (LINGO taxonomy), if it has one.
    pub motion_type: Option<String>,
    /// The annotation's action label.
    pub action: String,
    /// The caption.
    pub text: String,
    /// Every text of the clip.
    pub texts: Vec<String>,
    /// The annotation's labels.
    pub labels: Vec<String>,
    /// Paraphrases of the caption.
    pub paraphrases: Vec<String>,
    /// The hand of a hand goal (`left`, `right`).
    pub hand: Option<String>,
    /// Body parts the text moves, by name (`left_arm`, ...).
    pub parts: Option<Vec<String>>,
    /// Where the parts came from.
    pub label_source: Option<String>,
    /// A synthetic pair's two source clip ids.
    pub composed_from: Vec<String>,
    /// The parts each source gave to a synthetic pair, by name.
    pub composed_parts: Vec<Vec<String>>,
    /// Pelvis goal (x, y) in the clip's canonical frame, metres.
    pub goal_pelvis: Option<Vec<f32>>,
    /// Hand goal in the clip's canonical frame, metres.
    pub goal_hand: Option<Vec<f32>>,
    /// Plausibility metrics: foot skate, ground penetration, self distance, lean.
    pub plausibility: Plausibility,
    /// The `skeleton` column: the key of the clip's skeleton in `skeletons.json`.
    pub skeleton: String,
    /// Frames per second.
    pub fps: f64,
    /// Frames.
    pub frames: usize,
    /// Joints per frame.
    pub joints: usize,
    /// The shard holding the row, relative to the dataset folder.
    pub shard: String,
}

/// A row's plausibility columns (null where the table has none).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Plausibility {
    /// Foot skating, metres per second of foot slide in contact.
    pub foot_skate: Option<f32>,
    /// Ground penetration, metres.
    pub ground_penetration: Option<f32>,
    /// Smallest distance between non-adjacent body parts, metres.
    pub self_distance: Option<f32>,
    /// Torso lean, degrees.
    pub lean: Option<f32>,
}

/// Which clips a listing keeps: every given filter must match.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ClipFilter {
    /// The motion type, exactly.
    pub motion_type: Option<String>,
    /// The split, exactly.
    pub split: Option<String>,
    /// The source kind, exactly (`real_single`, `real_pair`, `synthetic`), or `mirrored` for
    /// mirrored copies and `original` for the rest.
    pub kind: Option<String>,
    /// A substring of the clip id, motion type, action, caption, texts or paraphrases
    /// (case-insensitive).
    pub text: Option<String>,
}

impl ClipFilter {
    /// Does `clip` pass every filter?
    pub fn matches(&self, clip: &ClipInfo) -> bool {
        if let Some(t) = &self.motion_type
            && clip.motion_type.as_deref() != Some(t.as_str())
        {
            return false;
        }
        if let Some(s) = &self.split
            && &clip.split != s
        {
            return false;
        }
        if let Some(k) = &self.kind {
            let ok = match k.as_str() {
                "mirrored" => clip.mirrored,
                "original" => !clip.mirrored,
                other => clip.source_kind == other,
            };
            if !ok {
                return false;
            }
        }
        if let Some(needle) = &self.text {
            let needle = needle.to_lowercase();
            let hit = std::iter::once(&clip.clip_id)
                .chain(&clip.motion_type)
                .chain(std::iter::once(&clip.action))
                .chain(std::iter::once(&clip.text))
                .chain(&clip.texts)
                .chain(&clip.paraphrases)
                .any(|s| s.to_lowercase().contains(&needle));
            if !hit {
                return false;
            }
        }
        true
    }
}

/// The clip tables of a dataset folder: its shards, `data/*.parquet` ([`find_clip_tables`] of
/// `data/`), sorted by name; at least one.
pub fn shards(dataset: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    Ok(open_shards(dataset)?
        .into_iter()
        .map(|shard| shard.path().to_path_buf())
        .collect())
}

/// [`shards`], opened: what they hold stays the build that was listed, whatever replaces them.
pub fn open_shards(dataset: &Path) -> Result<Vec<OpenShard>, DatasetError> {
    let dir = dataset.join(motionforge_core::base::layout::DATA_DIR);
    let not_a_dataset = || DatasetError::NotADataset {
        path: dataset.to_path_buf(),
    };
    if !dir.is_dir() {
        return Err(not_a_dataset());
    }
    let found = open_clip_tables(&dir)?;
    if found.is_empty() {
        return Err(not_a_dataset());
    }
    Ok(found)
}

/// Every row's metadata, in shard order and then row order.
pub fn list_clips(dataset: &Path) -> Result<Vec<ClipInfo>, DatasetError> {
    let mut out = Vec::new();
    for shard in open_shards(dataset)? {
        shard.read_infos(dataset, &mut out)?;
    }
    Ok(out)
}

/// The clips that pass `filter`, at most `limit` of them.
pub fn find_clips(
    dataset: &Path,
    filter: &ClipFilter,
    limit: Option<usize>,
) -> Result<Vec<ClipInfo>, DatasetError> {
    let mut clips = list_clips(dataset)?;
    clips.retain(|c| filter.matches(c));
    if let Some(n) = limit {
        clips.truncate(n);
    }
    Ok(clips)
}

/// `NoClip` for `clip_id`, with up to five ids that contain it (or that it contains) as a hint.
pub(crate) fn no_clip(dataset: &Path, clip_id: &str, ids: &[String]) -> DatasetError {
    DatasetError::NoClip {
        path: dataset.to_path_buf(),
        clip_id: clip_id.to_string(),
        count: ids.len(),
        hint: near_clip_ids(clip_id, ids),
    }
}

/// `; did you mean a, b` with up to five of `ids` that contain `clip_id` (or that it contains),
/// or that differ from it by a character or two, or empty when none does: the hint after a clip
/// id that is not in a dataset.
pub fn near_clip_ids(clip_id: &str, ids: &[String]) -> String {
    // Ids that contain what was typed (or are contained in it) first, in table order; then the
    // ids closest to it letter by letter (a mistyped frame range, a missing `:m`), closest first.
    let mut near: Vec<&str> = ids
        .iter()
        .map(String::as_str)
        .filter(|id| id.contains(clip_id) || clip_id.contains(*id))
        .take(NEAR_IDS)
        .collect();
    if near.len() < NEAR_IDS {
        let mut scored: Vec<(f64, &str)> = ids
            .iter()
            .map(String::as_str)
            .filter(|id| !near.contains(id))
            .map(|id| (strsim::normalized_levenshtein(clip_id, id), id))
            .filter(|(score, _)| *score >= NEAR_SIMILARITY)
            .collect();
        scored.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(b.1)));
        near.extend(
            scored
                .into_iter()
                .map(|(_, id)| id)
                .take(NEAR_IDS - near.len()),
        );
    }
    if near.is_empty() {
        String::new()
    } else {
        format!("; did you mean {}", near.join(", "))
    }
}

/// Ids suggested for one that is not in the dataset, at most.
const NEAR_IDS: usize = 5;
/// Letter-by-letter similarity (normalised Levenshtein, 1 for equal ids) from which an id is
/// suggested: one or two characters off in a typical id of 20 to 40.
const NEAR_SIMILARITY: f64 = 0.85;

/// Which clips a preview draws beside a clip.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Companions {
    /// The clip alone.
    #[default]
    None,
    /// The clip and its mirror (or, for a mirror, its original).
    Mirror,
    /// A synthetic pair and its two sources (nothing for other clips).
    Sources,
}

/// The ids to draw beside `clip`, those in `clips` only.
pub fn companion_ids(clip: &ClipInfo, with: Companions, clips: &[ClipInfo]) -> Vec<String> {
    let wanted: Vec<String> = match with {
        Companions::None => Vec::new(),
        Companions::Mirror => vec![match clip.clip_id.strip_suffix(":m") {
            Some(original) if clip.mirrored => original.to_string(),
            _ => format!("{}:m", clip.clip_id),
        }],
        Companions::Sources => clip.composed_from.clone(),
    };
    wanted
        .into_iter()
        .filter(|id| clips.iter().any(|c| &c.clip_id == id))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::near_clip_ids;

    fn ids() -> Vec<String> {
        [
            "cmu/01_01:115-1315",
            "cmu/01_01:115-1315:m",
            "cmu/01_01:1207-2407",
            "bandai-namco-1/dataset-1_walk-left_normal_001:0-135",
        ]
        .map(String::from)
        .to_vec()
    }

    #[test]
    fn a_typo_in_the_frames_suggests_the_ids_a_character_or_two_away() {
        let hint = near_clip_ids("cmu/01_01:115-1351", &ids());
        assert_eq!(
            hint,
            "; did you mean cmu/01_01:115-1315, cmu/01_01:115-1315:m"
        );
    }

    #[test]
    fn a_part_of_an_id_suggests_the_ids_containing_it_first() {
        let hint = near_clip_ids("walk-left", &ids());
        assert_eq!(
            hint,
            "; did you mean bandai-namco-1/dataset-1_walk-left_normal_001:0-135"
        );
        assert_eq!(near_clip_ids("nothing/like/it:1-2", &ids()), "");
    }
}
