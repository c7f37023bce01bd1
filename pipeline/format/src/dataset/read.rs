//! Shard rows to [`ClipInfo`] and [`ClipFrames`], every column found by name.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use parquet::file::reader::{ChunkReader, Length};

use super::{ClipInfo, DatasetError, Plausibility, ShardBatch};
use crate::io::schema::Column;
use motionforge_core::motion::BodyPart;

/// Metadata columns a listing decodes (never the frames).
const INFO_COLUMNS: [Column; 25] = [
    Column::ClipId,
    Column::Split,
    Column::SourceKind,
    Column::Mirrored,
    Column::MotionType,
    Column::Action,
    Column::Text,
    Column::Texts,
    Column::Labels,
    Column::Paraphrases,
    Column::Hand,
    Column::Parts,
    Column::LabelSource,
    Column::ComposedFrom,
    Column::ComposedParts,
    Column::GoalPelvis,
    Column::GoalHand,
    Column::FootSkate,
    Column::GroundPenetration,
    Column::SelfDistance,
    Column::Lean,
    Column::Skeleton,
    Column::Fps,
    Column::NumFrames,
    Column::NumJoints,
];

/// One clip's metadata and its frames in the dataset frame (x right, y forward, z up, metres).
#[derive(Debug, Clone, PartialEq)]
pub struct ClipFrames {
    /// The row's metadata.
    pub info: ClipInfo,
    /// `frames × joints × 3` world positions.
    pub positions: Vec<f32>,
    /// `frames × joints × 4` local rotations (x, y, z, w); joint 0's includes the turn from
    /// capture axes to dataset axes.
    pub rotations: Vec<f32>,
    /// `frames × 3` world position of the root-motion joint.
    pub root: Vec<f32>,
}

impl ClipFrames {
    /// The positions of frame `f` (`joints × 3`).
    pub fn frame(&self, f: usize) -> &[f32] {
        let n = self.info.joints * 3;
        &self.positions[f * n..(f + 1) * n]
    }
}

/// A shard opened once, read at explicit offsets (`pread`), so any number of threads read it at
/// the same time without sharing a file position. What it reads stays the file that was opened,
/// even once a rebuild has replaced or removed the shard's name: a reader that opened every shard
/// of one build keeps reading that build.
#[derive(Debug, Clone)]
pub struct OpenShard {
    path: PathBuf,
    file: Arc<File>,
    len: u64,
}

impl OpenShard {
    /// Opens the shard at `path`.
    pub fn open(path: &Path) -> Result<OpenShard, DatasetError> {
        let io = |source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = File::open(path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        Ok(OpenShard {
            path: path.to_path_buf(),
            file: Arc::new(file),
            len,
        })
    }

    /// Where it was opened.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends the metadata of every row to `out` ([`ClipInfo::shard`] relative to `dataset`).
    pub fn read_infos(&self, dataset: &Path, out: &mut Vec<ClipInfo>) -> Result<(), DatasetError> {
        let required = [
            Column::ClipId,
            Column::SourceKind,
            Column::Fps,
            Column::NumFrames,
            Column::NumJoints,
        ];
        for batch in self.read(&INFO_COLUMNS).require(&required).batches()? {
            out.extend(infos_of(dataset, &batch?)?);
        }
        Ok(())
    }

    /// The frames of the row at `row`, which `info` describes ([`read_frames`]).
    pub fn read_frames(&self, info: ClipInfo, row: usize) -> Result<ClipFrames, DatasetError> {
        read_frames_from(self, info, row)
    }
}

impl Length for OpenShard {
    fn len(&self) -> u64 {
        self.len
    }
}

/// A reader of an [`OpenShard`] from an offset on, with a position of its own.
pub struct ShardReader {
    file: Arc<File>,
    at: u64,
}

impl std::io::Read for ShardReader {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.file.read_at(buf, self.at)?;
        self.at += n as u64;
        Ok(n)
    }
}

impl ChunkReader for OpenShard {
    type T = std::io::BufReader<ShardReader>;

    fn get_read(&self, start: u64) -> parquet::errors::Result<Self::T> {
        Ok(std::io::BufReader::new(ShardReader {
            file: self.file.clone(),
            at: start,
        }))
    }

    fn get_bytes(&self, start: u64, length: usize) -> parquet::errors::Result<bytes::Bytes> {
        // The footer gives the ranges: none may reach past the end of the file it came from.
        let end = start
            .checked_add(length as u64)
            .filter(|end| *end <= self.len);
        if end.is_none() {
            return Err(parquet::errors::ParquetError::EOF(format!(
                "{length} bytes at offset {start} run past the end of the {}-byte file",
                self.len
            )));
        }
        let mut buffer = vec![0u8; length];
        self.file.read_exact_at(&mut buffer, start)?;
        Ok(buffer.into())
    }
}

/// Part names of a six-flag vector in SINC's order.
fn part_names(flags: &[bool]) -> Vec<String> {
    BodyPart::ALL
        .iter()
        .zip(flags)
        .filter(|(_, on)| **on)
        .map(|(p, _)| motionforge_language::parts::part_name(*p).to_string())
        .collect()
}

fn required<T>(
    batch: &ShardBatch,
    column: Column,
    values: Vec<Option<T>>,
) -> Result<Vec<T>, DatasetError> {
    values
        .into_iter()
        .enumerate()
        .map(|(i, x)| {
            x.ok_or_else(|| DatasetError::NullValue {
                path: batch.path().to_path_buf(),
                column: column.name(),
                row: batch.first_row() + i,
            })
        })
        .collect()
}

fn infos_of(dataset: &Path, b: &ShardBatch) -> Result<Vec<ClipInfo>, DatasetError> {
    let ids = required(b, Column::ClipId, b.strings(Column::ClipId)?)?;
    let kinds = required(b, Column::SourceKind, b.strings(Column::SourceKind)?)?;
    let splits = b.strings(Column::Split)?;
    let mirrored = b.bools(Column::Mirrored)?;
    let fps = b.floats(Column::Fps)?;
    let count = |column: Column| -> Result<Vec<usize>, DatasetError> {
        Ok(b.ints(column)?
            .into_iter()
            .map(|v| v.and_then(|v| usize::try_from(v).ok()).unwrap_or(0))
            .collect())
    };
    let (frames, joints) = (count(Column::NumFrames)?, count(Column::NumJoints)?);
    let skeleton = b.strings(Column::Skeleton)?;
    let (motion_type, action, text) = (
        b.strings(Column::MotionType)?,
        b.strings(Column::Action)?,
        b.strings(Column::Text)?,
    );
    let (hand, label_source) = (b.strings(Column::Hand)?, b.strings(Column::LabelSource)?);
    let (texts, labels, paraphrases, composed_from) = (
        b.string_lists(Column::Texts)?,
        b.string_lists(Column::Labels)?,
        b.string_lists(Column::Paraphrases)?,
        b.string_lists(Column::ComposedFrom)?,
    );
    let parts = b.bool_lists(Column::Parts)?;
    let composed_parts = b.bool_list_lists(Column::ComposedParts)?;
    let (goal_pelvis, goal_hand) = (
        b.f32_lists(Column::GoalPelvis)?,
        b.f32_lists(Column::GoalHand)?,
    );
    let (skate, ground, distance, lean) = (
        b.f32s(Column::FootSkate)?,
        b.f32s(Column::GroundPenetration)?,
        b.f32s(Column::SelfDistance)?,
        b.f32s(Column::Lean)?,
    );
    let path = b.path();
    let shard = path
        .strip_prefix(dataset)
        .unwrap_or(path)
        .to_string_lossy()
        .into_owned();
    let mut out = Vec::with_capacity(b.num_rows());
    for i in 0..b.num_rows() {
        out.push(ClipInfo {
            clip_id: ids[i].clone(),
            split: splits[i].clone().unwrap_or_default(),
            source_kind: kinds[i].clone(),
            mirrored: mirrored[i].unwrap_or(false),
            motion_type: motion_type[i].clone(),
            action: action[i].clone().unwrap_or_default(),
            text: text[i].clone().unwrap_or_default(),
            texts: texts[i].clone(),
            labels: labels[i].clone(),
            paraphrases: paraphrases[i].clone(),
            hand: hand[i].clone(),
            parts: parts[i].as_deref().map(part_names),
            label_source: label_source[i].clone(),
            composed_from: composed_from[i].clone(),
            composed_parts: composed_parts[i].iter().map(|p| part_names(p)).collect(),
            goal_pelvis: goal_pelvis[i].clone(),
            goal_hand: goal_hand[i].clone(),
            plausibility: Plausibility {
                foot_skate: skate[i],
                ground_penetration: ground[i],
                self_distance: distance[i],
                lean: lean[i],
            },
            skeleton: skeleton[i].clone().unwrap_or_default(),
            fps: fps[i].unwrap_or(f64::NAN),
            frames: frames[i],
            joints: joints[i],
            shard: shard.clone(),
        });
    }
    Ok(out)
}

/// The frames of the row at `row` of the shard `info.shard`, checked against its counts.
pub fn read_frames(dataset: &Path, info: ClipInfo, row: usize) -> Result<ClipFrames, DatasetError> {
    read_frames_from(&OpenShard::open(&dataset.join(&info.shard))?, info, row)
}

/// [`read_frames`] from `shard`.
fn read_frames_from(
    shard: &OpenShard,
    info: ClipInfo,
    row: usize,
) -> Result<ClipFrames, DatasetError> {
    let path = shard.path().to_path_buf();
    let columns = [
        Column::ClipId,
        Column::JointPositions,
        Column::LocalRotations,
        Column::RootTranslation,
    ];
    let bad = |message: String| DatasetError::BadRow {
        path: path.clone(),
        clip_id: info.clip_id.clone(),
        message,
    };
    let frames0 = |b: &ShardBatch, column: Column| {
        crate::io::parquet::frame_values(b.column(column)?, column, 0, info.frames, info.joints)
            .map_err(|e| bad(e.to_string()))
    };
    let mut found = None;
    for batch in shard
        .read(&columns)
        .require(&columns)
        .rows(row, 1)
        .batches()?
    {
        let b = batch?;
        let ids = b.strings(Column::ClipId)?;
        if ids.first().and_then(|id| id.as_deref()) != Some(info.clip_id.as_str()) {
            continue;
        }
        found = Some((
            frames0(&b, Column::JointPositions)?,
            frames0(&b, Column::LocalRotations)?,
            frames0(&b, Column::RootTranslation)?,
        ));
    }
    let (Some(positions), Some(rotations), Some(root)) = found.unwrap_or((None, None, None)) else {
        return Err(bad(format!("row {row} holds no frames")));
    };
    // frame_values checked each column against these counts; an empty clip has nothing to show.
    let (f, j) = (info.frames, info.joints);
    if f == 0 || j == 0 {
        return Err(bad(format!(
            "num_frames {f} and num_joints {j}, expected at least one of each"
        )));
    }
    if let Some(v) = positions.iter().chain(&rotations).find(|v| !v.is_finite()) {
        return Err(bad(format!("a non-finite value ({v}) in the frames")));
    }
    if !(info.fps.is_finite() && info.fps > 0.0) {
        return Err(bad(format!(
            "fps is {}, expected a positive number",
            info.fps
        )));
    }
    Ok(ClipFrames {
        info,
        positions,
        rotations,
        root,
    })
}

/// One clip's metadata and frames, found by id.
pub fn read_clip(dataset: &Path, clip_id: &str) -> Result<ClipFrames, DatasetError> {
    read_clip_in(dataset, &super::list_clips(dataset)?, clip_id)
}

/// [`read_clip`] with the dataset's listing already read ([`super::list_clips`]).
pub fn read_clip_in(
    dataset: &Path,
    clips: &[ClipInfo],
    clip_id: &str,
) -> Result<ClipFrames, DatasetError> {
    let Some(at) = clips.iter().position(|c| c.clip_id == clip_id) else {
        let ids: Vec<String> = clips.iter().map(|c| c.clip_id.clone()).collect();
        return Err(super::no_clip(dataset, clip_id, &ids));
    };
    // Rows before it in the same shard give its row number there.
    let row = clips[..at]
        .iter()
        .filter(|c| c.shard == clips[at].shard)
        .count();
    read_frames(dataset, clips[at].clone(), row)
}
