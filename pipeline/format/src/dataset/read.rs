//! Shard rows to [`ClipInfo`] and [`ClipFrames`], every column found by name.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Float64Type, Int32Type};
use arrow_array::{Array, ArrayRef, RecordBatch};
use parquet::arrow::ProjectionMask;
use parquet::arrow::arrow_reader::{ParquetRecordBatchReaderBuilder, RowSelection, RowSelector};
use parquet::file::reader::{ChunkReader, Length};

use super::{ClipInfo, DatasetError, Plausibility};
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

fn table_err(path: &Path, message: impl std::fmt::Display) -> DatasetError {
    DatasetError::Table {
        path: path.to_path_buf(),
        message: message.to_string(),
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
        read_infos_from(dataset, &self.path, self.clone(), out)
    }

    /// The frames of the row at `row`, which `info` describes ([`read_frames`]).
    pub fn read_frames(&self, info: ClipInfo, row: usize) -> Result<ClipFrames, DatasetError> {
        read_frames_from(&self.path, self.clone(), info, row)
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

fn open_err(path: &Path) -> impl Fn(std::io::Error) -> DatasetError + '_ {
    move |source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A reader of `columns` (those the shard has; `required` must all be there) of the shard at
/// `path`, read from `source`.
fn reader<R: ChunkReader + 'static>(
    path: &Path,
    source: R,
    columns: &[Column],
    required: &[Column],
    selection: Option<RowSelection>,
) -> Result<parquet::arrow::arrow_reader::ParquetRecordBatchReader, DatasetError> {
    let builder =
        ParquetRecordBatchReaderBuilder::try_new(source).map_err(|e| table_err(path, e))?;
    let schema = builder.schema().clone();
    for c in required {
        if schema.column_with_name(c.name()).is_none() {
            return Err(table_err(path, format!("no `{}` column", c.name())));
        }
    }
    let indices: Vec<usize> = columns
        .iter()
        .filter_map(|c| schema.index_of(c.name()).ok())
        .collect();
    let mask = ProjectionMask::roots(builder.parquet_schema(), indices);
    let mut builder = builder.with_projection(mask).with_batch_size(256);
    if let Some(s) = selection {
        builder = builder.with_row_selection(s);
    }
    builder.build().map_err(|e| table_err(path, e))
}

/// Typed access to one batch's columns, with errors naming the shard and the column.
struct Batch<'a> {
    path: &'a Path,
    batch: &'a RecordBatch,
}

impl<'a> Batch<'a> {
    fn column(&self, column: Column) -> Option<&'a ArrayRef> {
        self.batch.column_by_name(column.name())
    }

    fn wrong(&self, column: Column, expected: &str) -> DatasetError {
        let name = column.name();
        let found = self
            .column(column)
            .map(|c| c.data_type().to_string())
            .unwrap_or_else(|| "no column".into());
        table_err(
            self.path,
            format!("column `{name}` is {found}, expected {expected}"),
        )
    }

    /// A string column's values (`None` per null row); an absent column is all nulls.
    fn strings(&self, column: Column) -> Result<Vec<Option<String>>, DatasetError> {
        let Some(c) = self.column(column) else {
            return Ok(vec![None; self.batch.num_rows()]);
        };
        let a = c
            .as_string_opt::<i32>()
            .ok_or_else(|| self.wrong(column, "Utf8"))?;
        Ok(a.iter().map(|v| v.map(str::to_string)).collect())
    }

    fn string_lists(&self, column: Column) -> Result<Vec<Vec<String>>, DatasetError> {
        let Some(c) = self.column(column) else {
            return Ok(vec![Vec::new(); self.batch.num_rows()]);
        };
        let list = c
            .as_list_opt::<i32>()
            .ok_or_else(|| self.wrong(column, "List<Utf8>"))?;
        (0..list.len())
            .map(|i| {
                if list.is_null(i) {
                    return Ok(Vec::new());
                }
                let v = list.value(i);
                let s = v
                    .as_string_opt::<i32>()
                    .ok_or_else(|| self.wrong(column, "List<Utf8>"))?;
                Ok(s.iter().flatten().map(str::to_string).collect())
            })
            .collect()
    }

    /// A small vector per row (a goal), as a list or a fixed-size list of Float32.
    fn f32_lists(&self, column: Column) -> Result<Vec<Option<Vec<f32>>>, DatasetError> {
        let Some(c) = self.column(column) else {
            return Ok(vec![None; self.batch.num_rows()]);
        };
        let rows = crate::io::parquet::list_rows(c)
            .ok_or_else(|| self.wrong(column, "a list of Float32"))?;
        rows.into_iter()
            .map(|row| {
                row.map(|v| {
                    v.as_primitive_opt::<Float32Type>()
                        .map(|f| f.values().to_vec())
                        .ok_or_else(|| self.wrong(column, "a list of Float32"))
                })
                .transpose()
            })
            .collect()
    }

    fn bool_lists(&self, column: Column) -> Result<Vec<Option<Vec<bool>>>, DatasetError> {
        let Some(c) = self.column(column) else {
            return Ok(vec![None; self.batch.num_rows()]);
        };
        let rows = crate::io::parquet::list_rows(c)
            .ok_or_else(|| self.wrong(column, "a list of Boolean"))?;
        rows.into_iter()
            .map(|row| {
                row.map(|v| {
                    v.as_boolean_opt()
                        .map(|b| b.iter().map(|x| x.unwrap_or(false)).collect())
                        .ok_or_else(|| self.wrong(column, "a list of Boolean"))
                })
                .transpose()
            })
            .collect()
    }

    /// `composed_parts`: a list of part vectors per row.
    fn bool_list_lists(&self, column: Column) -> Result<Vec<Vec<Vec<bool>>>, DatasetError> {
        let Some(c) = self.column(column) else {
            return Ok(vec![Vec::new(); self.batch.num_rows()]);
        };
        let expected = "a list of lists of Boolean";
        let rows = crate::io::parquet::list_rows(c).ok_or_else(|| self.wrong(column, expected))?;
        rows.into_iter()
            .map(|row| {
                let Some(inner) = row else {
                    return Ok(Vec::new());
                };
                let inner = crate::io::parquet::list_rows(&inner)
                    .ok_or_else(|| self.wrong(column, expected))?;
                inner
                    .into_iter()
                    .map(|v| {
                        v.as_ref()
                            .and_then(|v| v.as_boolean_opt())
                            .map(|b| b.iter().map(|x| x.unwrap_or(false)).collect())
                            .ok_or_else(|| self.wrong(column, expected))
                    })
                    .collect()
            })
            .collect()
    }

    /// Row 0's per-frame values of `name` (`io::parquet::frame_values`: the layout lives there).
    fn frames0(&self, name: Column, info: &ClipInfo) -> Result<Option<Vec<f32>>, DatasetError> {
        let column = self
            .column(name)
            .ok_or_else(|| self.wrong(name, "a per-frame column"))?;
        crate::io::parquet::frame_values(column, name, 0, info.frames, info.joints).map_err(|e| {
            DatasetError::BadRow {
                path: self.path.to_path_buf(),
                clip_id: info.clip_id.clone(),
                message: e.to_string(),
            }
        })
    }

    fn f32s(&self, column: Column) -> Result<Vec<Option<f32>>, DatasetError> {
        let Some(c) = self.column(column) else {
            return Ok(vec![None; self.batch.num_rows()]);
        };
        let a = c
            .as_primitive_opt::<Float32Type>()
            .ok_or_else(|| self.wrong(column, "Float32"))?;
        Ok(a.iter().collect())
    }

    fn required<T>(&self, column: Column, v: Vec<Option<T>>) -> Result<Vec<T>, DatasetError> {
        let name = column.name();
        v.into_iter()
            .enumerate()
            .map(|(i, x)| {
                x.ok_or_else(|| table_err(self.path, format!("`{name}` is null in row {i}")))
            })
            .collect()
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

fn infos_of(
    dataset: &Path,
    path: &Path,
    batch: &RecordBatch,
) -> Result<Vec<ClipInfo>, DatasetError> {
    let b = Batch { path, batch };
    let ids = b.required(Column::ClipId, b.strings(Column::ClipId)?)?;
    let kinds = b.required(Column::SourceKind, b.strings(Column::SourceKind)?)?;
    let splits = b.strings(Column::Split)?;
    let mirrored = match b.column(Column::Mirrored) {
        Some(c) => c
            .as_boolean_opt()
            .ok_or_else(|| b.wrong(Column::Mirrored, "Boolean"))?
            .iter()
            .map(|v| v.unwrap_or(false))
            .collect(),
        None => vec![false; batch.num_rows()],
    };
    let fps: Vec<f64> = b
        .column(Column::Fps)
        .and_then(|c| c.as_primitive_opt::<Float64Type>())
        .ok_or_else(|| b.wrong(Column::Fps, "Float64"))?
        .iter()
        .map(|v| v.unwrap_or(f64::NAN))
        .collect();
    let ints = |column: Column| -> Result<Vec<usize>, DatasetError> {
        Ok(b.column(column)
            .and_then(|c| c.as_primitive_opt::<Int32Type>())
            .ok_or_else(|| b.wrong(column, "Int32"))?
            .iter()
            .map(|v| v.and_then(|v| usize::try_from(v).ok()).unwrap_or(0))
            .collect())
    };
    let (frames, joints) = (ints(Column::NumFrames)?, ints(Column::NumJoints)?);
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
    let shard = path
        .strip_prefix(dataset)
        .unwrap_or(path)
        .to_string_lossy()
        .into_owned();
    let mut out = Vec::with_capacity(batch.num_rows());
    for i in 0..batch.num_rows() {
        out.push(ClipInfo {
            clip_id: ids[i].clone(),
            split: splits[i].clone().unwrap_or_default(),
            source_kind: kinds[i].clone(),
            mirrored: mirrored[i],
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
            fps: fps[i],
            frames: frames[i],
            joints: joints[i],
            shard: shard.clone(),
        });
    }
    Ok(out)
}

/// Appends the metadata of every row of `path` to `out`.
pub(super) fn read_infos(
    dataset: &Path,
    path: &Path,
    out: &mut Vec<ClipInfo>,
) -> Result<(), DatasetError> {
    let file = File::open(path).map_err(open_err(path))?;
    read_infos_from(dataset, path, file, out)
}

/// [`read_infos`] from `source`, the content of the shard at `path`.
fn read_infos_from<R: ChunkReader + 'static>(
    dataset: &Path,
    path: &Path,
    source: R,
    out: &mut Vec<ClipInfo>,
) -> Result<(), DatasetError> {
    let required = [
        Column::ClipId,
        Column::SourceKind,
        Column::Fps,
        Column::NumFrames,
        Column::NumJoints,
    ];
    for batch in reader(path, source, &INFO_COLUMNS, &required, None)? {
        let batch = batch.map_err(|e| table_err(path, e))?;
        out.extend(infos_of(dataset, path, &batch)?);
    }
    Ok(())
}

/// The frames of the row at `row` of the shard `info.shard`, checked against its counts.
pub fn read_frames(dataset: &Path, info: ClipInfo, row: usize) -> Result<ClipFrames, DatasetError> {
    let path = dataset.join(&info.shard);
    let file = File::open(&path).map_err(open_err(&path))?;
    read_frames_from(&path, file, info, row)
}

/// [`read_frames`] from `source`, the content of the shard at `path`.
fn read_frames_from<R: ChunkReader + 'static>(
    path: &Path,
    source: R,
    info: ClipInfo,
    row: usize,
) -> Result<ClipFrames, DatasetError> {
    let path = path.to_path_buf();
    let selection = RowSelection::from(vec![RowSelector::skip(row), RowSelector::select(1)]);
    let columns = [
        Column::ClipId,
        Column::JointPositions,
        Column::LocalRotations,
        Column::RootTranslation,
    ];
    let mut found = None;
    for batch in reader(&path, source, &columns, &columns, Some(selection))? {
        let batch = batch.map_err(|e| table_err(&path, e))?;
        let b = Batch {
            path: &path,
            batch: &batch,
        };
        let ids = b.strings(Column::ClipId)?;
        if ids.first().and_then(|id| id.as_deref()) != Some(info.clip_id.as_str()) {
            continue;
        }
        found = Some((
            b.frames0(Column::JointPositions, &info)?,
            b.frames0(Column::LocalRotations, &info)?,
            b.frames0(Column::RootTranslation, &info)?,
        ));
    }
    let bad = |message: String| DatasetError::BadRow {
        path: path.clone(),
        clip_id: info.clip_id.clone(),
        message,
    };
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
