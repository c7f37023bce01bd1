//! Writes clips as a Parquet table (arrow-rs, zstd), streaming one row group at a time.
//!
//! Motion columns are in the dataset frame: metres, x right, y forward, z up (right-handed), see
//! `schemas/clips.md`. Per-frame arrays nest as frames, joints, then fixed-size lists of
//! components ([`FrameShape`](super::schema::FrameShape)), so readers get shaped arrays.

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::builder::{ListBuilder, StringBuilder, StructBuilder};
use arrow_array::{
    ArrayRef, BooleanArray, FixedSizeListArray, Float32Array, Float64Array, Int32Array, Int64Array,
    ListArray, RecordBatch, StringArray, StructArray,
};
use arrow_buffer::{NullBuffer, OffsetBuffer, ScalarBuffer};
use arrow_schema::{ArrowError, DataType, Field, Fields};
use glam::{DQuat, DVec3};
use parquet::errors::ParquetError;

use super::schema::{Column, SCHEMA_VERSION, clip_schema};
use motionforge_core::features::{FeatureConfig, Features};
use motionforge_core::motion::{Motion, Profile};
use motionforge_core::quality::{Plausibility, plausibility};
pub use motionforge_sources::clip::skeleton_name;

mod writer;
pub use self::writer::{
    DEFAULT_ZSTD_LEVEL, PAGE_BYTES, ROWS_PER_GROUP, ShardWriter, shard_properties, write_clips,
    write_plans,
};
use motionforge_sources::clip::{Clip, LoadedClip};

/// Errors writing a table.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    /// Arrow rejected the arrays (a schema mismatch: a bug, reported rather than hidden).
    #[error("building the clip table: {0}")]
    Arrow(#[from] ArrowError),
    /// Parquet encoding or I/O failed.
    #[error("writing Parquet: {0}{hint}", hint = parquet_hint(.0))]
    Parquet(#[from] ParquetError),
    /// A value that is NaN or infinite (never written).
    #[error("clip `{clip}`: column `{column}` would hold a value that is not finite; not written")]
    NonFinite {
        /// The clip.
        clip: String,
        /// The column.
        column: String,
    },
    /// A clip's skeleton profile was not supplied.
    #[error("clip `{clip}` uses skeleton profile `{profile}`, which the writer was not given")]
    MissingProfile {
        /// The clip.
        clip: String,
        /// The profile.
        profile: String,
    },
}

/// What to do about an I/O error under a Parquet error (a full disk, no permission), if anything.
fn parquet_hint(error: &ParquetError) -> &'static str {
    match error {
        ParquetError::External(e) => e
            .downcast_ref::<std::io::Error>()
            .map(motionforge_core::base::io_hint)
            .unwrap_or(""),
        _ => "",
    }
}

/// A clip's motion in the dataset frame, as the table stores it.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetMotion {
    /// `frames × joints × 3` positions in metres.
    pub positions: Vec<f32>,
    /// `frames × joints × 4` local rotations (x, y, z, w), `w ≥ 0`; joint 0 includes the turn from
    /// capture axes to dataset axes.
    pub rotations: Vec<f32>,
    /// `frames × 3` world position of the root-motion joint in metres.
    pub root: Vec<f32>,
}

/// Converts a motion from capture units and axes to the dataset frame.
pub fn dataset_motion(motion: &Motion, profile: &Profile) -> DatasetMotion {
    dataset_motion_at(
        motion,
        profile,
        &motionforge_core::motion::canonical::dataset_positions(motion, profile),
    )
}

/// [`dataset_motion`] from the motion's world positions in the dataset frame, already computed
/// (`motion::canonical::dataset_positions`), in f64.
fn dataset_motion_at(motion: &Motion, profile: &Profile, world: &[DVec3]) -> DatasetMotion {
    let axes = profile.to_dataset_axes();
    let n = motion.num_joints();
    let mut positions = Vec::with_capacity(world.len() * 3);
    for q in world {
        positions.extend([q.x as f32, q.y as f32, q.z as f32]);
    }
    let mut rotations = Vec::with_capacity(motion.rotations.len() * 4);
    for (i, r) in motion.rotations.iter().enumerate() {
        let r = if i % n == 0 { axes * *r } else { *r };
        let r: DQuat = if r.w < 0.0 { -r } else { r };
        rotations.extend([r.x as f32, r.y as f32, r.z as f32, r.w as f32]);
    }
    let frames = world.len() / n.max(1);
    let mut root = Vec::with_capacity(frames * 3);
    for f in 0..frames {
        let at = (f * n + profile.root) * 3;
        root.extend_from_slice(&positions[at..at + 3]);
    }
    DatasetMotion {
        positions,
        rotations,
        root,
    }
}

/// One row of the clip table before encoding: the clip's metadata beside its motion in the
/// dataset frame and its derived features. Both are computed once per row, and the shard and the
/// normalisation statistics read the same values.
#[derive(Debug, Clone)]
pub struct Row<'a> {
    /// The clip's metadata. Its `motion` is not read: the frames are in `motion` below.
    pub clip: &'a Clip,
    /// The `skeleton` column (profile and skeleton digest).
    pub skeleton: String,
    /// Frames per second of the motion.
    pub fps: f64,
    /// Joints per frame.
    pub joints: usize,
    /// Frames.
    pub frames: usize,
    /// Positions, rotations and root in the dataset frame.
    pub motion: DatasetMotion,
    /// `frames × joints × 3` positions in the clip's first-frame canonical frame (what a
    /// trainer feeds a model: the start over the origin, facing +y).
    pub canonical: Vec<f32>,
    /// The derived feature columns that are switched on.
    pub features: Features,
    /// Plausibility metrics: the clip's own when it has them (a synthetic pair, measured when it
    /// was composed), otherwise measured here from the same positions as the row's.
    pub plausibility: Option<Plausibility>,
}

impl<'a> Row<'a> {
    /// The row of `clip` whose frames are `motion` (on a skeleton of `profile`).
    pub fn new(
        clip: &'a Clip,
        motion: &Motion,
        profile: &Profile,
        config: &FeatureConfig,
    ) -> Row<'a> {
        let joints = motion.num_joints();
        let world = motionforge_core::motion::canonical::dataset_positions(motion, profile);
        let plausibility = clip
            .plausibility
            .as_deref()
            .copied()
            .or_else(|| Some(plausibility(&world, joints, motion.fps, profile)));
        let dataset = dataset_motion_at(motion, profile, &world);
        let canonical = canonical_positions(&dataset.positions, joints, profile);
        let features = motionforge_core::features::features(
            &dataset.positions,
            &dataset.rotations,
            joints,
            motion.fps,
            profile,
            config,
        );
        Row {
            clip,
            skeleton: skeleton_name(&clip.profile, &motion.skeleton),
            fps: motion.fps,
            joints,
            frames: motion.num_frames(),
            motion: dataset,
            canonical,
            features,
            plausibility,
        }
    }

    /// The row of a clip with its frames, with its profile looked up in `profiles`.
    pub fn of_clip(
        loaded: &'a LoadedClip,
        profiles: &BTreeMap<String, Profile>,
        config: &FeatureConfig,
    ) -> Result<Row<'a>, TableError> {
        let clip = &loaded.clip;
        let profile = profiles
            .get(&clip.profile)
            .ok_or_else(|| TableError::MissingProfile {
                clip: clip.clip_id.clone(),
                profile: clip.profile.clone(),
            })?;
        Ok(Row::new(clip, &loaded.motion, profile, config))
    }
}

/// Dataset-frame positions (`frames × joints × 3`) in the first frame's canonical frame
/// ([`motionforge_core::motion::canonical::canonical_frame`], as the goals use). A first frame with no
/// facing direction (hips and shoulders stacked) is only moved over the origin.
fn canonical_positions(positions: &[f32], joints: usize, profile: &Profile) -> Vec<f32> {
    use glam::DVec3;
    let point = |c: &[f32]| DVec3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2]));
    let first: Vec<DVec3> = positions.chunks_exact(3).take(joints).map(point).collect();
    let frame = motionforge_core::motion::canonical::canonical_frame(&first, profile)
        .unwrap_or_else(|| {
            let pelvis = first.get(profile.root).copied().unwrap_or_default();
            motionforge_core::motion::canonical::CanonicalFrame {
                origin: DVec3::new(pelvis.x, pelvis.y, 0.0),
                rotation: glam::DQuat::IDENTITY,
            }
        });
    let mut out = Vec::with_capacity(positions.len());
    for c in positions.chunks_exact(3) {
        let p = frame.apply(point(c));
        out.extend_from_slice(&[p.x as f32, p.y as f32, p.z as f32]);
    }
    out
}

/// Why a per-frame column could not be read (callers add the file).
#[derive(Debug, thiserror::Error)]
pub enum FrameColumnError {
    /// The column's type is neither this version's nesting nor version 8's flat list.
    #[error(
        "column `{column}` is {found}, expected {expected} (clip table version {SCHEMA_VERSION}) or List<Float32> (version 8); rebuild the dataset with this motionforge"
    )]
    Layout {
        /// The column.
        column: String,
        /// Its type in the file.
        found: String,
        /// The type this version writes.
        expected: String,
    },
    /// A row whose nesting or length does not match its `num_frames` and `num_joints`.
    #[error("column `{column}`, row {row}: {message}")]
    Shape {
        /// The column.
        column: String,
        /// The row in the batch.
        row: usize,
        /// What was found and expected.
        message: String,
    },
}

/// True when `a` and `b` nest the same lists and fixed-size lists over the same leaf type, field
/// names and nullability aside (another writer, pyarrow say, may mark items nullable).
fn same_nesting(a: &DataType, b: &DataType) -> bool {
    match (a, b) {
        (DataType::List(x), DataType::List(y)) => same_nesting(x.data_type(), y.data_type()),
        (DataType::FixedSizeList(x, n), DataType::FixedSizeList(y, m)) => {
            n == m && same_nesting(x.data_type(), y.data_type())
        }
        _ => a == b,
    }
}

/// One row of per-frame Float32 column `name` (`joint_positions`, `canonical_positions`,
/// `local_rotations`, `root_translation`, ...) as flat values in frame, joint, component order,
/// checked against the row's `frames` and `joints` (ignored for a column without joints). The one
/// place readers take the columns' layout from ([`FrameShape`](super::schema::FrameShape)):
/// this version's nested lists, and version 8's flat `List<Float32>` (same values, same order).
/// `Ok(None)` for a null row (an opt-in feature that is off).
pub fn frame_values(
    column: &ArrayRef,
    name: Column,
    row: usize,
    frames: usize,
    joints: usize,
) -> Result<Option<Vec<f32>>, FrameColumnError> {
    use arrow_array::Array;
    use arrow_array::cast::AsArray;
    use arrow_array::types::Float32Type;
    let shape = |message: String| FrameColumnError::Shape {
        column: name.name().to_string(),
        row,
        message,
    };
    let layout = || FrameColumnError::Layout {
        column: name.name().to_string(),
        found: column.data_type().to_string(),
        expected: name
            .frame_shape()
            .map(|s| s.data_type().to_string())
            .unwrap_or_else(|| "a per-frame column".into()),
    };
    let Some(expected) = name.frame_shape().filter(|s| !s.boolean) else {
        return Err(layout());
    };
    let flat = DataType::List(Arc::new(Field::new("item", DataType::Float32, true)));
    let nested = same_nesting(column.data_type(), &expected.data_type());
    if !nested && !same_nesting(column.data_type(), &flat) {
        return Err(layout());
    }
    let Some(top) = column.as_list_opt::<i32>() else {
        return Err(layout());
    };
    if row >= top.len() {
        return Err(shape(format!("no such row (the batch has {})", top.len())));
    }
    if top.is_null(row) {
        return Ok(None);
    }
    // The row's range of the next level down, narrowed level by level to the leaf values.
    let offsets = top.value_offsets();
    let (mut start, mut end) = (offsets[row] as usize, offsets[row + 1] as usize);
    let mut level = top.values();
    let joints = if expected.per_joint { joints } else { 1 };
    let per_frame = joints * expected.width();
    if nested && end - start != frames {
        return Err(shape(format!("{} frames, expected {frames}", end - start)));
    }
    loop {
        if level.null_count() > 0 {
            return Err(shape("a null inside the frames".into()));
        }
        if let Some(list) = level.as_list_opt::<i32>() {
            let offsets = &list.value_offsets()[start..=end];
            if let Some(bad) = offsets
                .windows(2)
                .find(|w| (w[1] - w[0]) as usize != joints)
            {
                return Err(shape(format!(
                    "a frame of {} joints, expected {joints}",
                    bad[1] - bad[0]
                )));
            }
            (start, end) = (offsets[0] as usize, offsets[end - start] as usize);
            level = list.values();
        } else if let Some(fixed) = level.as_fixed_size_list_opt() {
            (start, end) = (fixed.value_offset_at(start), fixed.value_offset_at(end));
            level = fixed.values();
        } else if let Some(values) = level.as_primitive_opt::<Float32Type>() {
            let values = &values.values()[start..end];
            if frames.checked_mul(per_frame) != Some(values.len()) {
                return Err(shape(format!(
                    "{} values, expected num_frames {frames} × {per_frame}",
                    values.len()
                )));
            }
            return Ok(Some(values.to_vec()));
        } else {
            return Err(layout());
        }
    }
}

/// Each row's items of a list or fixed-size list column (`goal_pelvis`, `parts`,
/// `composed_parts`'s outer list, `texts`): `None` for a null row; `None` overall when the column
/// is not a list. Readers take small per-clip vectors through this, so either list form reads.
pub fn list_rows(column: &ArrayRef) -> Option<Vec<Option<ArrayRef>>> {
    use arrow_array::Array;
    use arrow_array::cast::AsArray;
    let row = |valid: bool, value: ArrayRef| valid.then_some(value);
    if let Some(list) = column.as_list_opt::<i32>() {
        return Some(
            (0..list.len())
                .map(|i| row(list.is_valid(i), list.value(i)))
                .collect(),
        );
    }
    if let Some(list) = column.as_list_opt::<i64>() {
        return Some(
            (0..list.len())
                .map(|i| row(list.is_valid(i), list.value(i)))
                .collect(),
        );
    }
    let list = column.as_fixed_size_list_opt()?;
    Some(
        (0..list.len())
            .map(|i| row(list.is_valid(i), list.value(i)))
            .collect(),
    )
}

/// Offsets of lists with these lengths, checked against Arrow's 2^31 limit.
fn checked_offsets(lengths: impl Iterator<Item = usize>) -> Result<OffsetBuffer<i32>, ArrowError> {
    let mut offsets = Vec::with_capacity(lengths.size_hint().0 + 1);
    let mut total: i32 = 0;
    offsets.push(0);
    for l in lengths {
        let l = i32::try_from(l)
            .map_err(|_| ArrowError::ComputeError("list longer than 2^31 values".into()))?;
        total = total.checked_add(l).ok_or_else(|| {
            ArrowError::ComputeError("row group over 2^31 values; lower the row group size".into())
        })?;
        offsets.push(total);
    }
    Ok(OffsetBuffer::new(ScalarBuffer::from(offsets)))
}

/// A validity buffer, `None` when every row is valid (Arrow's cheaper form of the same).
fn validity(valid: &[bool]) -> Option<NullBuffer> {
    valid
        .iter()
        .any(|v| !v)
        .then(|| NullBuffer::from(valid.to_vec()))
}

/// `values` (already in frame, joint, component order) wrapped in the fixed-size lists of
/// `inner`, innermost first, without copying.
fn fixed_lists(mut values: ArrayRef, inner: &[i32]) -> Result<ArrayRef, ArrowError> {
    for &n in inner.iter().rev() {
        let field = Arc::new(Field::new("item", values.data_type().clone(), false));
        values = Arc::new(FixedSizeListArray::try_new(field, n, values, None)?);
    }
    Ok(values)
}

/// One per-frame column of `name`'s [`FrameShape`](super::schema::FrameShape) from each row's
/// flat values and counts (`None` for a null row). The leaf values go into one buffer and the
/// nesting is offsets over it (no element-by-element builder): frames per row, joints per frame.
fn frame_column(
    column: Column,
    leaf: ArrayRef,
    rows: &[Option<(usize, usize, usize)>],
) -> Result<ArrayRef, ArrowError> {
    let name = column.name();
    let shape = column
        .frame_shape()
        .ok_or_else(|| ArrowError::SchemaError(format!("`{name}` is not a per-frame column")))?;
    // Each row's values must fill its frames exactly: a mismatch here is a bug, not bad input.
    let mut total = 0usize;
    for (frames, joints, len) in rows.iter().flatten() {
        let joints = if shape.per_joint { *joints } else { 1 };
        if frames * joints * shape.width() != *len {
            return Err(ArrowError::ComputeError(format!(
                "`{name}`: {len} values for {frames} frames × {joints} joints × {}",
                shape.width()
            )));
        }
        total += len;
    }
    if total != leaf.len() {
        return Err(ArrowError::ComputeError(format!(
            "`{name}`: {} values, rows give {total}",
            leaf.len()
        )));
    }
    let mut values = fixed_lists(leaf, shape.inner)?;
    if shape.per_joint {
        let per_frame = rows
            .iter()
            .flatten()
            .flat_map(|&(frames, joints, _)| std::iter::repeat_n(joints, frames));
        let field = Arc::new(Field::new("item", values.data_type().clone(), false));
        values = Arc::new(ListArray::try_new(
            field,
            checked_offsets(per_frame)?,
            values,
            None,
        )?);
    }
    let field = Arc::new(Field::new("item", values.data_type().clone(), false));
    let valid: Vec<bool> = rows.iter().map(Option::is_some).collect();
    Ok(Arc::new(ListArray::try_new(
        field,
        checked_offsets(rows.iter().map(|r| r.map_or(0, |(frames, _, _)| frames)))?,
        values,
        validity(&valid),
    )?))
}

/// A Float32 per-frame column from each row's values (`None`: a null row).
fn f32_frames<'r, 'c>(
    name: Column,
    rows: &'r [Row<'c>],
    part: impl Fn(&'r Row<'c>) -> Option<&'r [f32]>,
) -> Result<ArrayRef, ArrowError> {
    let parts: Vec<Option<&[f32]>> = rows.iter().map(part).collect();
    let mut values = Vec::with_capacity(parts.iter().flatten().map(|v| v.len()).sum());
    for v in parts.iter().flatten() {
        values.extend_from_slice(v);
    }
    let counts: Vec<Option<(usize, usize, usize)>> = rows
        .iter()
        .zip(&parts)
        .map(|(r, v)| v.map(|v| (r.frames, r.joints, v.len())))
        .collect();
    frame_column(name, Arc::new(Float32Array::from(values)), &counts)
}

fn string_lists<'a>(rows: impl Iterator<Item = &'a [String]>) -> ArrayRef {
    let mut b = ListBuilder::new(StringBuilder::new()).with_field(Arc::new(Field::new(
        "item",
        DataType::Utf8,
        false,
    )));
    for row in rows {
        for s in row {
            b.values().append_value(s);
        }
        b.append(true);
    }
    Arc::new(b.finish())
}

/// A fixed-size list per row (a goal, the six parts), null where a row has none: the slot of a
/// null row holds `filler` values, as Arrow's fixed-size lists need.
fn fixed_per_row<T: Copy>(
    rows: &[Option<Vec<T>>],
    n: usize,
    filler: T,
    leaf: impl Fn(Vec<T>) -> ArrayRef,
) -> Result<ArrayRef, ArrowError> {
    let mut values = Vec::with_capacity(rows.len() * n);
    for row in rows {
        match row {
            Some(v) if v.len() == n => values.extend_from_slice(v),
            Some(v) => {
                return Err(ArrowError::ComputeError(format!(
                    "{} values where a fixed-size list holds {n}",
                    v.len()
                )));
            }
            None => values.extend(std::iter::repeat_n(filler, n)),
        }
    }
    let values = leaf(values);
    let field = Arc::new(Field::new("item", values.data_type().clone(), false));
    let valid: Vec<bool> = rows.iter().map(Option::is_some).collect();
    Ok(Arc::new(FixedSizeListArray::try_new(
        field,
        n as i32,
        values,
        validity(&valid),
    )?))
}

fn bools(values: Vec<bool>) -> ArrayRef {
    Arc::new(BooleanArray::from(values))
}

fn floats(values: Vec<f32>) -> ArrayRef {
    Arc::new(Float32Array::from(values))
}

/// Six booleans per row in SINC's order: global, torso, left arm, right arm, left leg, right leg.
fn part_lists(
    rows: impl Iterator<Item = Option<motionforge_language::parts::PartSet>>,
) -> Result<ArrayRef, ArrowError> {
    let rows: Vec<Option<Vec<bool>>> = rows.map(|p| p.map(|p| p.to_vec6().to_vec())).collect();
    fixed_per_row(&rows, 6, false, bools)
}

/// A list of six-boolean part vectors per row (the parts each source of a synthetic pair gave).
fn nested_part_lists<'a>(
    rows: impl Iterator<Item = &'a [motionforge_language::parts::PartSet]>,
) -> Result<ArrayRef, ArrowError> {
    let rows: Vec<&[motionforge_language::parts::PartSet]> = rows.collect();
    let mut values = Vec::new();
    for parts in &rows {
        for p in *parts {
            values.extend(p.to_vec6());
        }
    }
    let values = fixed_lists(bools(values), &[6])?;
    let field = Arc::new(Field::new("item", values.data_type().clone(), false));
    Ok(Arc::new(ListArray::try_new(
        field,
        checked_offsets(rows.iter().map(|p| p.len()))?,
        values,
        None,
    )?))
}

/// One plausibility metric per row, null when not computed.
fn metric(rows: &[Row<'_>], f: impl Fn(&Plausibility) -> f64) -> ArrayRef {
    Arc::new(Float32Array::from(
        rows.iter()
            .map(|r| r.plausibility.as_ref().map(|p| f(p) as f32))
            .collect::<Vec<_>>(),
    ))
}

/// `foot_contacts`: four booleans per frame, null when the feature is off.
fn contact_column(rows: &[Row<'_>]) -> Result<ArrayRef, ArrowError> {
    let parts: Vec<Option<&[bool]>> = rows
        .iter()
        .map(|r| r.features.foot_contacts.as_deref())
        .collect();
    let values: Vec<bool> = parts
        .iter()
        .flatten()
        .flat_map(|v| v.iter().copied())
        .collect();
    let counts: Vec<Option<(usize, usize, usize)>> = rows
        .iter()
        .zip(&parts)
        .map(|(r, v)| v.map(|v| (r.frames, r.joints, v.len())))
        .collect();
    frame_column(Column::FootContacts, bools(values), &counts)
}

/// Builds one record batch (a row group) from rows.
pub fn rows_to_batch(rows: &[Row<'_>]) -> Result<RecordBatch, TableError> {
    let schema = Arc::new(clip_schema());
    let clips: Vec<&Clip> = rows.iter().map(|r| r.clip).collect();
    // Columns by name: the schema decides their order, so writer and schema cannot drift apart.
    let mut named = clip_columns(&clips)?;
    named.extend(row_columns(rows)?);
    let columns = crate::io::schema::in_schema_order(
        &schema,
        named.into_iter().map(|(c, a)| (c.name(), a)).collect(),
    )?;
    let batch = RecordBatch::try_new(schema, columns)?;
    check_finite(&batch, &clips)?;
    Ok(batch)
}

/// The columns of the clips' metadata: provenance, texts, labels, goals, attributes.
fn clip_columns(clips: &[&Clip]) -> Result<Vec<(Column, ArrayRef)>, TableError> {
    let strings = |f: &dyn Fn(&Clip) -> &str| -> ArrayRef {
        Arc::new(StringArray::from_iter_values(clips.iter().map(|c| f(c))))
    };
    let optional_strings = |f: &dyn Fn(&Clip) -> Option<&str>| -> ArrayRef {
        Arc::new(StringArray::from(
            clips.iter().map(|c| f(c)).collect::<Vec<_>>(),
        ))
    };
    let goals = |goal: fn(&Clip) -> Option<Vec<f32>>, n: usize| {
        let values: Vec<Option<Vec<f32>>> = clips.iter().map(|c| goal(c)).collect();
        fixed_per_row(&values, n, 0.0, floats)
    };
    let frame_range = frame_range_column(clips)?;
    let attributes = attributes_column(clips);
    Ok(vec![
        (Column::ClipId, strings(&|c| &c.clip_id)),
        (Column::SourceKind, strings(&|c| c.kind.as_str())),
        (Column::SourceName, strings(&|c| &c.capture.source)),
        (Column::SourcePath, strings(&|c| &c.capture.path)),
        (Column::SourceSha256, strings(&|c| &c.capture.sha256)),
        (
            Column::SourceFps,
            Arc::new(Float64Array::from_iter_values(
                clips.iter().map(|c| c.capture.fps),
            )),
        ),
        (Column::FrameRange, Arc::new(frame_range)),
        (
            Column::Mirrored,
            Arc::new(BooleanArray::from(
                clips.iter().map(|c| c.mirrored).collect::<Vec<_>>(),
            )),
        ),
        (Column::Split, strings(&|c| c.split.as_str())),
        (Column::Action, strings(&|c| &c.action)),
        (Column::Text, strings(&|c| &c.text)),
        (
            Column::Texts,
            string_lists(clips.iter().map(|c| c.texts.as_slice())),
        ),
        (
            Column::Labels,
            string_lists(clips.iter().map(|c| c.labels.as_slice())),
        ),
        (Column::AnnotationSource, strings(&|c| &c.annotation)),
        (Column::AnnotationOrigin, strings(&|c| &c.annotation_origin)),
        (
            Column::MotionType,
            optional_strings(&|c| c.motion_type.as_deref()),
        ),
        (
            Column::Hand,
            optional_strings(&|c| c.hand.map(|h| h.as_str())),
        ),
        (Column::Object, optional_strings(&|c| c.object.as_deref())),
        (
            Column::GoalPelvis,
            goals(|c| c.goal_pelvis.map(|g| g.map(|x| x as f32).to_vec()), 2)?,
        ),
        (
            Column::GoalHand,
            goals(|c| c.goal_hand.map(|g| g.map(|x| x as f32).to_vec()), 3)?,
        ),
        (Column::Parts, part_lists(clips.iter().map(|c| c.parts))?),
        (
            Column::LabelSource,
            Arc::new(StringArray::from(
                clips
                    .iter()
                    .map(|c| c.label_source.as_ref().map(ToString::to_string))
                    .collect::<Vec<_>>(),
            )),
        ),
        (
            Column::Paraphrases,
            string_lists(clips.iter().map(|c| c.paraphrases.as_slice())),
        ),
        (
            Column::ComposedFrom,
            string_lists(clips.iter().map(|c| c.composed_from.as_slice())),
        ),
        (
            Column::ComposedParts,
            nested_part_lists(clips.iter().map(|c| c.composed_parts.as_slice()))?,
        ),
        (Column::Attributes, attributes),
    ])
}

/// The columns made per row from its motion: plausibility, skeleton, and the per-frame arrays.
fn row_columns(rows: &[Row<'_>]) -> Result<Vec<(Column, ArrayRef)>, TableError> {
    Ok(vec![
        (Column::FootSkate, metric(rows, |p| p.foot_skate)),
        (
            Column::GroundPenetration,
            metric(rows, |p| p.ground_penetration),
        ),
        (Column::SelfDistance, metric(rows, |p| p.self_distance)),
        (Column::Lean, metric(rows, |p| p.lean)),
        (
            Column::Skeleton,
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.skeleton.as_str()),
            )),
        ),
        (
            Column::Fps,
            Arc::new(Float64Array::from_iter_values(rows.iter().map(|r| r.fps))),
        ),
        (
            Column::NumFrames,
            Arc::new(Int32Array::from_iter_values(
                rows.iter().map(|r| r.frames as i32),
            )),
        ),
        (
            Column::NumJoints,
            Arc::new(Int32Array::from_iter_values(
                rows.iter().map(|r| r.joints as i32),
            )),
        ),
        (
            Column::JointPositions,
            f32_frames(Column::JointPositions, rows, |r| Some(&r.motion.positions))?,
        ),
        (
            Column::LocalRotations,
            f32_frames(Column::LocalRotations, rows, |r| Some(&r.motion.rotations))?,
        ),
        (
            Column::RootTranslation,
            f32_frames(Column::RootTranslation, rows, |r| Some(&r.motion.root))?,
        ),
        (
            Column::Rotations6d,
            f32_frames(Column::Rotations6d, rows, |r| {
                r.features.rotations_6d.as_deref()
            })?,
        ),
        (
            Column::JointVelocities,
            f32_frames(Column::JointVelocities, rows, |r| {
                r.features.velocities.as_deref()
            })?,
        ),
        (Column::FootContacts, contact_column(rows)?),
        (
            Column::FutureRoot,
            f32_frames(Column::FutureRoot, rows, |r| {
                r.features.future_root.as_deref()
            })?,
        ),
        (
            Column::CanonicalPositions,
            f32_frames(Column::CanonicalPositions, rows, |r| Some(&r.canonical))?,
        ),
    ])
}

/// `frame_range`: each clip's first and last frame in its capture.
fn frame_range_column(clips: &[&Clip]) -> Result<StructArray, TableError> {
    Ok(StructArray::try_new(
        Fields::from(vec![
            Field::new("start", DataType::Int64, false),
            Field::new("end", DataType::Int64, false),
        ]),
        vec![
            Arc::new(Int64Array::from_iter_values(
                clips.iter().map(|c| c.frame_range.0 as i64),
            )) as ArrayRef,
            Arc::new(Int64Array::from_iter_values(
                clips.iter().map(|c| c.frame_range.1 as i64),
            )),
        ],
        None,
    )?)
}

/// `attributes`: each clip's key-value pairs, as a list of structs.
fn attributes_column(clips: &[&Clip]) -> ArrayRef {
    let entry = StructBuilder::new(
        crate::io::schema::attribute_fields(),
        vec![
            Box::new(StringBuilder::new()) as Box<dyn arrow_array::builder::ArrayBuilder>,
            Box::new(StringBuilder::new()),
        ],
    );
    let mut attributes = ListBuilder::new(entry).with_field(Arc::new(Field::new(
        "item",
        DataType::Struct(crate::io::schema::attribute_fields()),
        false,
    )));
    for clip in clips {
        let entries = attributes.values();
        for (k, v) in clip.attributes.iter() {
            for (i, text) in [k, v].into_iter().enumerate() {
                if let Some(b) = entries.field_builder::<StringBuilder>(i) {
                    b.append_value(text);
                }
            }
            entries.append(true);
        }
        attributes.append(true);
    }
    Arc::new(attributes.finish())
}

/// Upstream checks (value bounds at ingest) keep every number finite; this is the last guard,
/// so that a missed case fails the write instead of putting NaN or infinity in a dataset.
fn check_finite(batch: &RecordBatch, clips: &[&Clip]) -> Result<(), TableError> {
    for (c, column) in batch.columns().iter().enumerate() {
        if all_finite(column.as_ref()) {
            continue;
        }
        for (r, clip) in clips.iter().enumerate() {
            if !all_finite(column.slice(r, 1).as_ref()) {
                return Err(TableError::NonFinite {
                    clip: clip.clip_id.clone(),
                    column: batch.schema().field(c).name().clone(),
                });
            }
        }
    }
    Ok(())
}

/// True when every float in `array` (nested lists and structs included) is finite.
fn all_finite(array: &dyn arrow_array::Array) -> bool {
    use arrow_array::cast::AsArray;
    use arrow_array::types::{Float32Type, Float64Type};
    match array.data_type() {
        DataType::Float32 => array
            .as_primitive::<Float32Type>()
            .iter()
            .all(|v| v.is_none_or(f32::is_finite)),
        DataType::Float64 => array
            .as_primitive::<Float64Type>()
            .iter()
            .all(|v| v.is_none_or(f64::is_finite)),
        DataType::List(_) => {
            let list = array.as_list::<i32>();
            let offsets = list.value_offsets();
            let (start, end) = (offsets[0] as usize, offsets[offsets.len() - 1] as usize);
            all_finite(list.values().slice(start, end - start).as_ref())
        }
        DataType::FixedSizeList(_, _) => all_finite(array.as_fixed_size_list().values().as_ref()),
        DataType::Struct(_) => array
            .as_struct()
            .columns()
            .iter()
            .all(|c| all_finite(c.as_ref())),
        _ => true,
    }
}

#[cfg(test)]
mod frame_values_tests {
    use super::*;
    use arrow_array::Array;

    /// Two rows of `joint_positions`: 2 frames × 2 joints × 3, then 1 frame × 1 joint × 3.
    fn two_rows() -> (Vec<f32>, ArrayRef) {
        let values: Vec<f32> = (0..15).map(|v| v as f32).collect();
        let column = frame_column(
            Column::JointPositions,
            floats(values.clone()),
            &[Some((2, 2, 12)), Some((1, 1, 3))],
        )
        .unwrap();
        (values, column)
    }

    #[test]
    fn nested_rows_read_back_in_frame_joint_component_order() {
        let (values, column) = two_rows();
        assert_eq!(
            column.data_type(),
            &Column::JointPositions.frame_shape().unwrap().data_type()
        );
        let read = |row, frames, joints| {
            frame_values(&column, Column::JointPositions, row, frames, joints)
        };
        assert_eq!(read(0, 2, 2).unwrap(), Some(values[..12].to_vec()));
        assert_eq!(read(1, 1, 1).unwrap(), Some(values[12..].to_vec()));
        // Counts that disagree with the nesting are refused, not reinterpreted.
        assert!(matches!(read(0, 2, 3), Err(FrameColumnError::Shape { .. })));
        assert!(matches!(read(0, 1, 2), Err(FrameColumnError::Shape { .. })));
        assert!(matches!(read(2, 1, 1), Err(FrameColumnError::Shape { .. })));
        // The same column sliced (as a reader's batch may be) reads the same.
        let sliced = column.slice(1, 1);
        assert_eq!(
            frame_values(&sliced, Column::JointPositions, 0, 1, 1).unwrap(),
            Some(values[12..].to_vec())
        );
    }

    #[test]
    fn null_rows_and_per_frame_shapes() {
        let values: Vec<f32> = (0..18).map(|v| v as f32).collect();
        let column = frame_column(
            Column::FutureRoot,
            floats(values.clone()),
            &[None, Some((2, 5, 18))],
        )
        .unwrap();
        assert_eq!(
            frame_values(&column, Column::FutureRoot, 0, 3, 5).unwrap(),
            None
        );
        assert_eq!(
            frame_values(&column, Column::FutureRoot, 1, 2, 5).unwrap(),
            Some(values)
        );
        assert!(column.is_null(0));
        // Values that do not fill the frames are a bug caught at the writer.
        assert!(
            frame_column(Column::FutureRoot, floats(vec![0.0; 9]), &[Some((2, 1, 9))]).is_err()
        );
    }

    #[test]
    fn a_version_8_flat_column_reads_and_any_other_layout_is_refused() {
        let values: Vec<f32> = (0..12).map(|v| v as f32).collect();
        let flat: ArrayRef = Arc::new(
            ListArray::try_new(
                Arc::new(Field::new("item", DataType::Float32, false)),
                checked_offsets([12usize].into_iter()).unwrap(),
                floats(values.clone()),
                None,
            )
            .unwrap(),
        );
        assert_eq!(
            frame_values(&flat, Column::JointPositions, 0, 2, 2).unwrap(),
            Some(values.clone())
        );
        assert!(matches!(
            frame_values(&flat, Column::JointPositions, 0, 3, 2),
            Err(FrameColumnError::Shape { .. })
        ));
        // Rotations stored where positions belong: four per joint, not three.
        let (_, positions) = two_rows();
        let err = frame_values(&positions, Column::LocalRotations, 0, 2, 2).unwrap_err();
        assert!(matches!(err, FrameColumnError::Layout { .. }), "{err}");
        assert!(err.to_string().contains("`local_rotations`"), "{err}");
        let float64: ArrayRef = Arc::new(Float64Array::from(vec![1.0]));
        assert!(matches!(
            frame_values(&float64, Column::JointPositions, 0, 1, 1),
            Err(FrameColumnError::Layout { .. })
        ));
    }
}
