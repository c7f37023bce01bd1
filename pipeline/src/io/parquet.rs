//! Writes clips as a Parquet table (arrow-rs, zstd), streaming one row group at a time.
//!
//! Motion columns are in the dataset frame: metres, x right, y forward, z up (right-handed), see
//! `schemas/clips.md`. Arrays are flat `list<float32>` so any reader reshapes them with one call.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::sync::Arc;

use arrow_array::builder::{
    BooleanBuilder, Float32Builder, ListBuilder, StringBuilder, StructBuilder,
};
use arrow_array::{
    ArrayRef, BooleanArray, Float32Array, Float64Array, Int32Array, Int64Array, ListArray,
    RecordBatch, StringArray, StructArray,
};
use arrow_buffer::{OffsetBuffer, ScalarBuffer};
use arrow_schema::{ArrowError, DataType, Field, Fields};
use glam::{DQuat, DVec3};
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::errors::ParquetError;
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;

use super::schema::{SCHEMA_VERSION, clip_schema};
pub use crate::clip::skeleton_name;
use crate::clip::{Clip, LoadedClip};
use crate::features::{FeatureConfig, Features};
use crate::motion::{Motion, Profile};
use crate::quality::{Plausibility, plausibility};

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
            .map(crate::base::io_hint)
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
        &crate::motion::canonical::dataset_positions(motion, profile),
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
        let world = crate::motion::canonical::dataset_positions(motion, profile);
        let plausibility = clip
            .plausibility
            .or_else(|| Some(plausibility(&world, joints, motion.fps, profile)));
        let dataset = dataset_motion_at(motion, profile, &world);
        let canonical = canonical_positions(&dataset.positions, joints, profile);
        let features = crate::features::features(
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
/// ([`crate::motion::canonical::canonical_frame`], as the goals use). A first frame with no
/// facing direction (hips and shoulders stacked) is only moved over the origin.
fn canonical_positions(positions: &[f32], joints: usize, profile: &Profile) -> Vec<f32> {
    use glam::DVec3;
    let point = |c: &[f32]| DVec3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2]));
    let first: Vec<DVec3> = positions.chunks_exact(3).take(joints).map(point).collect();
    let frame = crate::motion::canonical::canonical_frame(&first, profile).unwrap_or_else(|| {
        let pelvis = first.get(profile.root).copied().unwrap_or_default();
        crate::motion::canonical::CanonicalFrame {
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

/// One row of a per-frame array column (`joint_positions`, `canonical_positions`, ...) as flat
/// f32 values in frame, joint, component order. The one place readers take the column's list
/// layout from: flat lists today, and nested or fixed-size lists (frames x joints x 3) read the
/// same, so a change of layout stays here. `None` for a null row, a row out of range or a column
/// that is not a list of f32.
pub fn frame_values(column: &ArrayRef, row: usize) -> Option<Vec<f32>> {
    use arrow_array::Array;
    use arrow_array::cast::AsArray;
    use arrow_array::types::Float32Type;
    fn flatten(array: &ArrayRef, out: &mut Vec<f32>) -> Option<()> {
        if let Some(values) = array.as_primitive_opt::<Float32Type>() {
            out.extend_from_slice(values.values());
        } else if let Some(list) = array.as_list_opt::<i32>() {
            for i in 0..list.len() {
                flatten(&list.value(i), out)?;
            }
        } else if let Some(list) = array.as_fixed_size_list_opt() {
            for i in 0..list.len() {
                flatten(&list.value(i), out)?;
            }
        } else {
            return None;
        }
        Some(())
    }
    let list = column.as_list_opt::<i32>()?;
    if row >= list.len() || list.is_null(row) {
        return None;
    }
    let mut out = Vec::new();
    flatten(&list.value(row), &mut out)?;
    Some(out)
}

fn list(values: Vec<f32>, lengths: Vec<usize>) -> Result<ArrayRef, ArrowError> {
    let field = Arc::new(Field::new("item", DataType::Float32, false));
    let offsets = checked_offsets(&lengths)?;
    Ok(Arc::new(ListArray::try_new(
        field,
        offsets,
        Arc::new(Float32Array::from(values)),
        None,
    )?))
}

fn checked_offsets(lengths: &[usize]) -> Result<OffsetBuffer<i32>, ArrowError> {
    let mut offsets = Vec::with_capacity(lengths.len() + 1);
    let mut total: i32 = 0;
    offsets.push(0);
    for &l in lengths {
        let l = i32::try_from(l)
            .map_err(|_| ArrowError::ComputeError("list longer than 2^31 values".into()))?;
        total = total.checked_add(l).ok_or_else(|| {
            ArrowError::ComputeError("row group over 2^31 values; lower the row group size".into())
        })?;
        offsets.push(total);
    }
    Ok(OffsetBuffer::new(ScalarBuffer::from(offsets)))
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

fn optional_f32_lists<'a>(rows: impl Iterator<Item = Option<&'a [f32]>>) -> ArrayRef {
    let mut b = ListBuilder::new(Float32Builder::new()).with_field(Arc::new(Field::new(
        "item",
        DataType::Float32,
        false,
    )));
    for row in rows {
        match row {
            Some(values) => {
                b.values().append_slice(values);
                b.append(true);
            }
            None => b.append(false),
        }
    }
    Arc::new(b.finish())
}

/// Six booleans per row in SINC's order: global, torso, left arm, right arm, left leg, right leg.
fn part_lists(rows: impl Iterator<Item = Option<crate::parts::PartSet>>) -> ArrayRef {
    let mut b = ListBuilder::new(BooleanBuilder::new()).with_field(Arc::new(Field::new(
        "item",
        DataType::Boolean,
        false,
    )));
    for row in rows {
        match row {
            Some(parts) => {
                for v in parts.to_vec6() {
                    b.values().append_value(v);
                }
                b.append(true);
            }
            None => b.append(false),
        }
    }
    Arc::new(b.finish())
}

/// A list of 6-boolean part lists per row (the parts each source of a synthetic pair gave).
fn nested_part_lists<'a>(rows: impl Iterator<Item = &'a [crate::parts::PartSet]>) -> ArrayRef {
    let inner = ListBuilder::new(BooleanBuilder::new()).with_field(Arc::new(Field::new(
        "item",
        DataType::Boolean,
        false,
    )));
    let inner_field = Arc::new(Field::new(
        "item",
        DataType::List(Arc::new(Field::new("item", DataType::Boolean, false))),
        false,
    ));
    let mut b = ListBuilder::new(inner).with_field(inner_field);
    for row in rows {
        for parts in row {
            for v in parts.to_vec6() {
                b.values().values().append_value(v);
            }
            b.values().append(true);
        }
        b.append(true);
    }
    Arc::new(b.finish())
}

/// One plausibility metric per row, null when not computed.
fn metric(rows: &[Row<'_>], f: impl Fn(&Plausibility) -> f64) -> ArrayRef {
    Arc::new(Float32Array::from(
        rows.iter()
            .map(|r| r.plausibility.as_ref().map(|p| f(p) as f32))
            .collect::<Vec<_>>(),
    ))
}

fn optional_bool_lists<'a>(rows: impl Iterator<Item = Option<&'a [bool]>>) -> ArrayRef {
    let mut b = ListBuilder::new(BooleanBuilder::new()).with_field(Arc::new(Field::new(
        "item",
        DataType::Boolean,
        false,
    )));
    for row in rows {
        match row {
            Some(values) => {
                for v in values {
                    b.values().append_value(*v);
                }
                b.append(true);
            }
            None => b.append(false),
        }
    }
    Arc::new(b.finish())
}

/// Builds one record batch (a row group) from rows.
pub fn rows_to_batch(rows: &[Row<'_>]) -> Result<RecordBatch, TableError> {
    let schema = Arc::new(clip_schema());
    let clips: Vec<&Clip> = rows.iter().map(|r| r.clip).collect();
    let clips = clips.as_slice();
    let strings = |f: &dyn Fn(&Clip) -> &str| -> ArrayRef {
        Arc::new(StringArray::from_iter_values(clips.iter().map(|c| f(c))))
    };
    let optional_strings = |f: &dyn Fn(&Clip) -> Option<&str>| -> ArrayRef {
        Arc::new(StringArray::from(
            clips.iter().map(|c| f(c)).collect::<Vec<_>>(),
        ))
    };
    let motion_list = |part: fn(&DatasetMotion) -> &[f32]| -> Result<ArrayRef, ArrowError> {
        let lengths: Vec<usize> = rows.iter().map(|r| part(&r.motion).len()).collect();
        let mut values = Vec::with_capacity(lengths.iter().sum());
        for r in rows {
            values.extend_from_slice(part(&r.motion));
        }
        list(values, lengths)
    };
    let derived = |part: fn(&Features) -> Option<&[f32]>| -> ArrayRef {
        optional_f32_lists(rows.iter().map(|r| part(&r.features)))
    };
    let goals = |goal: fn(&Clip) -> Option<Vec<f32>>| -> ArrayRef {
        let values: Vec<Option<Vec<f32>>> = clips.iter().map(|c| goal(c)).collect();
        optional_f32_lists(values.iter().map(Option::as_deref))
    };
    let frame_range = StructArray::try_new(
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
    )?;
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
        for (k, v) in &clip.attributes {
            for (i, text) in [k, v].into_iter().enumerate() {
                if let Some(b) = entries.field_builder::<StringBuilder>(i) {
                    b.append_value(text);
                }
            }
            entries.append(true);
        }
        attributes.append(true);
    }
    // Columns by name: the schema decides their order, so writer and schema cannot drift apart.
    let named: Vec<(&str, ArrayRef)> = vec![
        ("clip_id", strings(&|c| &c.clip_id)),
        ("source_kind", strings(&|c| c.kind.as_str())),
        ("source_name", strings(&|c| &c.capture.source)),
        ("source_path", strings(&|c| &c.capture.path)),
        ("source_sha256", strings(&|c| &c.capture.sha256)),
        (
            "source_fps",
            Arc::new(Float64Array::from_iter_values(
                clips.iter().map(|c| c.capture.fps),
            )),
        ),
        ("frame_range", Arc::new(frame_range)),
        (
            "mirrored",
            Arc::new(BooleanArray::from(
                clips.iter().map(|c| c.mirrored).collect::<Vec<_>>(),
            )),
        ),
        ("split", strings(&|c| c.split.as_str())),
        ("action", strings(&|c| &c.action)),
        ("text", strings(&|c| &c.text)),
        (
            "texts",
            string_lists(clips.iter().map(|c| c.texts.as_slice())),
        ),
        (
            "labels",
            string_lists(clips.iter().map(|c| c.labels.as_slice())),
        ),
        ("annotation_source", strings(&|c| &c.annotation)),
        ("annotation_origin", strings(&|c| &c.annotation_origin)),
        (
            "motion_type",
            optional_strings(&|c| c.motion_type.as_deref()),
        ),
        ("hand", optional_strings(&|c| c.hand.map(|h| h.as_str()))),
        ("object", optional_strings(&|c| c.object.as_deref())),
        (
            "goal_pelvis",
            goals(|c| c.goal_pelvis.map(|g| g.map(|x| x as f32).to_vec())),
        ),
        (
            "goal_hand",
            goals(|c| c.goal_hand.map(|g| g.map(|x| x as f32).to_vec())),
        ),
        ("parts", part_lists(clips.iter().map(|c| c.parts))),
        (
            "label_source",
            Arc::new(StringArray::from(
                clips
                    .iter()
                    .map(|c| c.label_source.as_ref().map(ToString::to_string))
                    .collect::<Vec<_>>(),
            )),
        ),
        (
            "paraphrases",
            string_lists(clips.iter().map(|c| c.paraphrases.as_slice())),
        ),
        (
            "composed_from",
            string_lists(clips.iter().map(|c| c.composed_from.as_slice())),
        ),
        (
            "composed_parts",
            nested_part_lists(clips.iter().map(|c| c.composed_parts.as_slice())),
        ),
        ("foot_skate", metric(rows, |p| p.foot_skate)),
        ("ground_penetration", metric(rows, |p| p.ground_penetration)),
        ("self_distance", metric(rows, |p| p.self_distance)),
        ("lean", metric(rows, |p| p.lean)),
        ("attributes", Arc::new(attributes.finish())),
        (
            "skeleton",
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.skeleton.as_str()),
            )),
        ),
        (
            "fps",
            Arc::new(Float64Array::from_iter_values(rows.iter().map(|r| r.fps))),
        ),
        (
            "num_frames",
            Arc::new(Int32Array::from_iter_values(
                rows.iter().map(|r| r.frames as i32),
            )),
        ),
        (
            "num_joints",
            Arc::new(Int32Array::from_iter_values(
                rows.iter().map(|r| r.joints as i32),
            )),
        ),
        ("joint_positions", motion_list(|m| &m.positions)?),
        ("local_rotations", motion_list(|m| &m.rotations)?),
        ("root_translation", motion_list(|m| &m.root)?),
        ("rotations_6d", derived(|f| f.rotations_6d.as_deref())),
        ("joint_velocities", derived(|f| f.velocities.as_deref())),
        (
            "foot_contacts",
            optional_bool_lists(rows.iter().map(|r| r.features.foot_contacts.as_deref())),
        ),
        ("future_root", derived(|f| f.future_root.as_deref())),
        ("canonical_positions", {
            let lengths: Vec<usize> = rows.iter().map(|r| r.canonical.len()).collect();
            let mut values = Vec::with_capacity(lengths.iter().sum());
            for r in rows {
                values.extend_from_slice(&r.canonical);
            }
            list(values, lengths)?
        }),
    ];
    let columns = crate::io::schema::in_schema_order(&schema, named)?;
    let batch = RecordBatch::try_new(schema, columns)?;
    // Upstream checks (value bounds at ingest) keep every number finite; this is the last guard,
    // so that a missed case fails the write instead of putting NaN or infinity in a dataset.
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
    Ok(batch)
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

/// Every float leaf column of `schema` encoded BYTE_STREAM_SPLIT, without a dictionary, and
/// without statistics when it is a list (per-frame values). Motion
/// floats are nearly unique, so dictionaries only cost time; splitting each value's bytes into
/// separate streams puts the slowly varying exponent and high mantissa bytes together, where zstd
/// finds the redundancy that plain encoding hides (`docs/decisions.md`, "Float encoding").
fn float_encoding(
    schema: &arrow_schema::Schema,
    mut props: parquet::file::properties::WriterPropertiesBuilder,
) -> Result<parquet::file::properties::WriterPropertiesBuilder, ParquetError> {
    let descriptor = parquet::arrow::ArrowSchemaConverter::new().convert(schema)?;
    for column in descriptor.columns() {
        if matches!(
            column.physical_type(),
            parquet::basic::Type::FLOAT | parquet::basic::Type::DOUBLE
        ) {
            let path = column.path().clone();
            // Min and max of a list of frames select nothing (no reader filters on them) and
            // cost a pass over every value; scalar floats (metrics) keep theirs.
            if column.max_rep_level() > 0 {
                props = props.set_column_statistics_enabled(
                    path.clone(),
                    parquet::file::properties::EnabledStatistics::None,
                );
            }
            props = props
                .set_column_dictionary_enabled(path.clone(), false)
                .set_column_encoding(path, parquet::basic::Encoding::BYTE_STREAM_SPLIT);
        }
    }
    Ok(props)
}

pub use crate::config::DEFAULT_ZSTD_LEVEL;

/// Largest data page before compression. A row group's per-frame column is a few MB, which
/// parquet's default (1 MB) cut into several pages, each compressed on its own: one page per
/// column chunk writes faster and compresses a little better (`docs/decisions.md`, "Shard
/// writer: no statistics on frame lists, 8 MB pages").
const PAGE_BYTES: usize = 8 * 1024 * 1024;

/// Clips per row group: large enough for efficient scans, small enough that one group's buffers
/// stay a few tens of MB for long captures.
pub const ROWS_PER_GROUP: usize = 64;

/// A shard of the clip table being written: one row group per [`ShardWriter::write`], with the
/// schema version and the skeletons in the file's `key_value_metadata`, so the file describes
/// itself. Streams: only the row group being encoded is in memory.
pub struct ShardWriter<W: Write + Send> {
    writer: ArrowWriter<W>,
}

impl<W: Write + Send> ShardWriter<W> {
    /// Starts a shard on `out`, compressed with zstd at `zstd_level` (1 to 22).
    pub fn new(
        out: W,
        skeletons_json: &str,
        zstd_level: i32,
    ) -> Result<ShardWriter<W>, TableError> {
        let props = float_encoding(&clip_schema(), WriterProperties::builder())?
            .set_compression(Compression::ZSTD(ZstdLevel::try_new(zstd_level)?))
            .set_max_row_group_row_count(Some(ROWS_PER_GROUP))
            .set_data_page_size_limit(PAGE_BYTES)
            .set_key_value_metadata(Some(vec![
                KeyValue::new(
                    "motionforge.schema_version".to_string(),
                    SCHEMA_VERSION.to_string(),
                ),
                KeyValue::new(
                    "motionforge.skeletons".to_string(),
                    skeletons_json.to_string(),
                ),
            ]))
            .build();
        Ok(ShardWriter {
            writer: ArrowWriter::try_new(out, Arc::new(clip_schema()), Some(props))?,
        })
    }

    /// Encodes `rows` (at most [`ROWS_PER_GROUP`]) as one row group.
    pub fn write(&mut self, rows: &[Row<'_>]) -> Result<(), TableError> {
        self.writer.write(&rows_to_batch(rows)?)?;
        self.writer.flush()?;
        Ok(())
    }

    /// Writes the footer and gives the output back.
    pub fn finish(self) -> Result<W, TableError> {
        Ok(self.writer.into_inner()?)
    }
}

/// Streams clips with their frames into a Parquet file, one row group at a time, at the default
/// zstd level (see [`ShardWriter`]).
pub fn write_clips(
    file: File,
    clips: &[LoadedClip],
    profiles: &BTreeMap<String, Profile>,
    skeletons_json: &str,
    features: &FeatureConfig,
) -> Result<File, TableError> {
    let mut writer = ShardWriter::new(file, skeletons_json, DEFAULT_ZSTD_LEVEL)?;
    for chunk in clips.chunks(ROWS_PER_GROUP) {
        let rows = chunk
            .iter()
            .map(|c| Row::of_clip(c, profiles, features))
            .collect::<Result<Vec<_>, _>>()?;
        writer.write(&rows)?;
    }
    writer.finish()
}

/// Writes task plans, one row per step: `text`, `step_id`, `step`, `category`.
pub fn write_plans(
    file: File,
    plans: &BTreeMap<String, Vec<crate::llm::plans::PlanStep>>,
) -> Result<File, TableError> {
    let schema = Arc::new(arrow_schema::Schema::new(vec![
        Field::new("text", DataType::Utf8, false),
        Field::new("step_id", DataType::Int32, false),
        Field::new("step", DataType::Utf8, false),
        Field::new("category", DataType::Utf8, false),
    ]));
    let rows: Vec<(&String, &crate::llm::plans::PlanStep)> = plans
        .iter()
        .flat_map(|(t, steps)| steps.iter().map(move |s| (t, s)))
        .collect();
    let category = |s: &crate::llm::plans::PlanStep| match s.category {
        crate::llm::plans::StepCategory::Locomotion => "locomotion",
        crate::llm::plans::StepCategory::Grasp => "grasp",
        crate::llm::plans::StepCategory::Interaction => "interaction",
    };
    let batch = RecordBatch::try_new(
        Arc::clone(&schema),
        vec![
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|(t, _)| t.as_str()),
            )),
            Arc::new(Int32Array::from_iter_values(
                rows.iter().map(|(_, s)| s.step_id as i32),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|(_, s)| s.step.as_str()),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|(_, s)| category(s)),
            )),
        ],
    )?;
    let props = WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(3)?))
        .build();
    let mut writer = ArrowWriter::try_new(file, schema, Some(props))?;
    writer.write(&batch)?;
    Ok(writer.into_inner()?)
}

#[cfg(test)]
mod frame_values_tests {
    use super::*;
    use arrow_array::{Array, FixedSizeListArray};

    #[test]
    fn flat_and_nested_layouts_give_the_same_values() {
        // Two rows: 2 frames x 1 joint x 3, then 1 frame x 1 joint x 3.
        let values: Vec<f32> = (0..9).map(|v| v as f32).collect();
        let flat = list(values.clone(), vec![6, 3]).unwrap();
        let item = Arc::new(Field::new("item", DataType::Float32, false));
        let triples = FixedSizeListArray::try_new(
            Arc::clone(&item),
            3,
            Arc::new(Float32Array::from(values.clone())),
            None,
        )
        .unwrap();
        let nested: ArrayRef = Arc::new(
            ListArray::try_new(
                Arc::new(Field::new("item", triples.data_type().clone(), false)),
                checked_offsets(&[2, 1]).unwrap(),
                Arc::new(triples),
                None,
            )
            .unwrap(),
        );
        for row in 0..2 {
            assert_eq!(frame_values(&flat, row), frame_values(&nested, row));
        }
        assert_eq!(frame_values(&nested, 1), Some(vec![6.0, 7.0, 8.0]));
        assert_eq!(frame_values(&flat, 2), None);
    }
}
