//! The clip table schema, as a value: printed by `motionforge schema`, documented in
//! `schemas/clips.md`, and compared with `schemas/clips.schema.json` in a test.

use std::sync::Arc;

use arrow_array::ArrayRef;
use arrow_schema::{ArrowError, DataType, Field, Fields, Schema};

/// Version of the clip table layout; bump on any change to columns or their meaning.
pub const SCHEMA_VERSION: u32 = 9;

/// How one row of a per-frame array column nests: frames, then joints when `per_joint`, then the
/// fixed-size `inner` dimensions (`[3]` for a position, `[3, 3]` for `future_root`'s three
/// offsets of three numbers). Stored as lists of lists of fixed-size lists, so that pyarrow,
/// polars and Hugging Face `datasets` give (frames, joints, 3) etc. without a reshape; the joint
/// count is a list rather than fixed because skeletons with different counts share a table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameShape {
    /// A list of joints per frame.
    pub per_joint: bool,
    /// The fixed-size dimensions of each joint (or frame), outermost first.
    pub inner: &'static [i32],
    /// Booleans rather than Float32 (`foot_contacts`).
    pub boolean: bool,
}

impl FrameShape {
    /// Numbers per joint (or per frame when not `per_joint`).
    pub fn width(&self) -> usize {
        self.inner.iter().map(|&n| n as usize).product()
    }

    /// The Arrow type of the column.
    pub fn data_type(&self) -> DataType {
        let mut t = if self.boolean {
            DataType::Boolean
        } else {
            DataType::Float32
        };
        for &n in self.inner.iter().rev() {
            t = DataType::FixedSizeList(item(t), n);
        }
        if self.per_joint {
            t = DataType::List(item(t));
        }
        DataType::List(item(t))
    }
}

const PER_JOINT_3: FrameShape = FrameShape {
    per_joint: true,
    inner: &[3],
    boolean: false,
};

/// A column of the clip table. The schema is built from these, the writer names its arrays with
/// them and every reader (dataset, report, exports) asks for columns through them, so a column
/// cannot be misspelt on one side only.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Column {
    /// `clip_id`: unique id: source, capture, frame range, `:m` when mirrored.
    ClipId,
    /// `source_kind`: `real_single`, `real_pair` or `synthetic` (composed by body part).
    SourceKind,
    /// `source_name`: the build config's source the capture came from.
    SourceName,
    /// `source_path`: capture file, relative to the build config.
    SourcePath,
    /// `source_sha256`: SHA-256 of the capture file.
    SourceSha256,
    /// `source_fps`: the capture's frame rate.
    SourceFps,
    /// `frame_range`: [start, end) in the capture's own frames.
    FrameRange,
    /// `mirrored`: left/right mirrored copy of another row.
    Mirrored,
    /// `split`: train, validation or test, by capture.
    Split,
    /// `action`: the action label.
    Action,
    /// `text`: the caption.
    Text,
    /// `texts`: every caption of the clip.
    Texts,
    /// `labels`: every action label of the clip.
    Labels,
    /// `annotation_source`: annotation format (filename, babel, event_log, frame_index).
    AnnotationSource,
    /// `annotation_origin`: annotation file and span the clip was cut by.
    AnnotationOrigin,
    /// `motion_type`: LINGO motion type of the label.
    MotionType,
    /// `hand`: hand the annotation names (left, right, both).
    Hand,
    /// `object`: object the annotation names.
    Object,
    /// `goal_pelvis`: [x, y] where the pelvis ends, metres, first-frame canonical frame.
    GoalPelvis,
    /// `goal_hand`: [x, y, z] where the hand reaches, metres, first-frame canonical frame.
    GoalHand,
    /// `parts`: body parts used: global, torso, left arm, right arm, left leg, right leg.
    Parts,
    /// `label_source`: which labeller gave `parts`.
    LabelSource,
    /// `paraphrases`: LLM paraphrases of `text`.
    Paraphrases,
    /// `composed_from`: synthetic pairs: the two source clip ids.
    ComposedFrom,
    /// `composed_parts`: synthetic pairs: the parts taken from each source.
    ComposedParts,
    /// `foot_skate`: plausibility: planted-foot speed, m/s.
    FootSkate,
    /// `ground_penetration`: plausibility: deepest joint below the floor, metres.
    GroundPenetration,
    /// `self_distance`: plausibility: closest limb to spine bone distance, metres.
    SelfDistance,
    /// `lean`: plausibility: largest sustained lean, degrees.
    Lean,
    /// `attributes`: capture-level annotation fields (key, value).
    Attributes,
    /// `skeleton`: skeleton id `<profile>:<digest>`, key into skeletons.json.
    Skeleton,
    /// `fps`: the dataset's frame rate.
    Fps,
    /// `num_frames`: frames.
    NumFrames,
    /// `num_joints`: joints (end sites not counted).
    NumJoints,
    /// `joint_positions`: frames x joints x 3 positions, metres (x right, y forward, z up).
    JointPositions,
    /// `local_rotations`: frames x joints x 4 local rotations, quaternions (x, y, z, w).
    LocalRotations,
    /// `root_translation`: frames x 3 root positions, metres.
    RootTranslation,
    /// `rotations_6d`: frames x joints x 6: first two rotation-matrix columns (opt-in).
    Rotations6d,
    /// `joint_velocities`: frames x joints x 3 velocities, m/s (opt-in).
    JointVelocities,
    /// `foot_contacts`: frames x 4 contacts: left ankle, left toe, right ankle, right toe.
    FootContacts,
    /// `future_root`: frames x 3 x 3: root displacement and heading change at +10, +20, +30 frames.
    FutureRoot,
    /// `canonical_positions`: frames x joints x 3 positions in the first frame's canonical frame: pelvis over the origin, facing +y.
    CanonicalPositions,
}

impl Column {
    /// Every column, in the table's order.
    pub const ALL: [Column; 42] = [
        Column::ClipId,
        Column::SourceKind,
        Column::SourceName,
        Column::SourcePath,
        Column::SourceSha256,
        Column::SourceFps,
        Column::FrameRange,
        Column::Mirrored,
        Column::Split,
        Column::Action,
        Column::Text,
        Column::Texts,
        Column::Labels,
        Column::AnnotationSource,
        Column::AnnotationOrigin,
        Column::MotionType,
        Column::Hand,
        Column::Object,
        Column::GoalPelvis,
        Column::GoalHand,
        Column::Parts,
        Column::LabelSource,
        Column::Paraphrases,
        Column::ComposedFrom,
        Column::ComposedParts,
        Column::FootSkate,
        Column::GroundPenetration,
        Column::SelfDistance,
        Column::Lean,
        Column::Attributes,
        Column::Skeleton,
        Column::Fps,
        Column::NumFrames,
        Column::NumJoints,
        Column::JointPositions,
        Column::LocalRotations,
        Column::RootTranslation,
        Column::Rotations6d,
        Column::JointVelocities,
        Column::FootContacts,
        Column::FutureRoot,
        Column::CanonicalPositions,
    ];

    /// The column's name in the table.
    pub const fn name(self) -> &'static str {
        match self {
            Column::ClipId => "clip_id",
            Column::SourceKind => "source_kind",
            Column::SourceName => "source_name",
            Column::SourcePath => "source_path",
            Column::SourceSha256 => "source_sha256",
            Column::SourceFps => "source_fps",
            Column::FrameRange => "frame_range",
            Column::Mirrored => "mirrored",
            Column::Split => "split",
            Column::Action => "action",
            Column::Text => "text",
            Column::Texts => "texts",
            Column::Labels => "labels",
            Column::AnnotationSource => "annotation_source",
            Column::AnnotationOrigin => "annotation_origin",
            Column::MotionType => "motion_type",
            Column::Hand => "hand",
            Column::Object => "object",
            Column::GoalPelvis => "goal_pelvis",
            Column::GoalHand => "goal_hand",
            Column::Parts => "parts",
            Column::LabelSource => "label_source",
            Column::Paraphrases => "paraphrases",
            Column::ComposedFrom => "composed_from",
            Column::ComposedParts => "composed_parts",
            Column::FootSkate => "foot_skate",
            Column::GroundPenetration => "ground_penetration",
            Column::SelfDistance => "self_distance",
            Column::Lean => "lean",
            Column::Attributes => "attributes",
            Column::Skeleton => "skeleton",
            Column::Fps => "fps",
            Column::NumFrames => "num_frames",
            Column::NumJoints => "num_joints",
            Column::JointPositions => "joint_positions",
            Column::LocalRotations => "local_rotations",
            Column::RootTranslation => "root_translation",
            Column::Rotations6d => "rotations_6d",
            Column::JointVelocities => "joint_velocities",
            Column::FootContacts => "foot_contacts",
            Column::FutureRoot => "future_root",
            Column::CanonicalPositions => "canonical_positions",
        }
    }

    /// The column called `name`, if the table has one.
    pub fn from_name(name: &str) -> Option<Column> {
        Column::ALL.into_iter().find(|c| c.name() == name)
    }

    /// What the column holds, in a phrase for the dataset card (`schemas/clips.md` has the details).
    pub const fn meaning(self) -> &'static str {
        match self {
            Column::ClipId => "unique id: source, capture, frame range, `:m` when mirrored",
            Column::SourceKind => {
                "`real_single`, `real_pair` or `synthetic` (composed by body part)"
            }
            Column::SourceName => "the build config's source the capture came from",
            Column::SourcePath => "capture file, relative to the build config",
            Column::SourceSha256 => "SHA-256 of the capture file",
            Column::SourceFps => "the capture's frame rate",
            Column::FrameRange => "[start, end) in the capture's own frames",
            Column::Mirrored => "left/right mirrored copy of another row",
            Column::Split => "train, validation or test, by capture",
            Column::Action => "the action label",
            Column::Text => "the caption",
            Column::Texts => "every caption of the clip",
            Column::Labels => "every action label of the clip",
            Column::AnnotationSource => {
                "annotation format (filename, babel, event_log, frame_index)"
            }
            Column::AnnotationOrigin => "annotation file and span the clip was cut by",
            Column::MotionType => "LINGO motion type of the label",
            Column::Hand => "hand the annotation names (left, right, both)",
            Column::Object => "object the annotation names",
            Column::GoalPelvis => {
                "[x, y] where the pelvis ends, metres, first-frame canonical frame"
            }
            Column::GoalHand => {
                "[x, y, z] where the hand reaches, metres, first-frame canonical frame"
            }
            Column::Parts => {
                "body parts used: global, torso, left arm, right arm, left leg, right leg"
            }
            Column::LabelSource => "which labeller gave `parts`",
            Column::Paraphrases => "LLM paraphrases of `text`",
            Column::ComposedFrom => "synthetic pairs: the two source clip ids",
            Column::ComposedParts => "synthetic pairs: the parts taken from each source",
            Column::FootSkate => "plausibility: planted-foot speed, m/s",
            Column::GroundPenetration => "plausibility: deepest joint below the floor, metres",
            Column::SelfDistance => "plausibility: closest limb to spine bone distance, metres",
            Column::Lean => "plausibility: largest sustained lean, degrees",
            Column::Attributes => "capture-level annotation fields (key, value)",
            Column::Skeleton => "skeleton id `<profile>:<digest>`, key into skeletons.json",
            Column::Fps => "the dataset's frame rate",
            Column::NumFrames => "frames",
            Column::NumJoints => "joints (end sites not counted)",
            Column::JointPositions => {
                "frames x joints x 3 positions, metres (x right, y forward, z up)"
            }
            Column::LocalRotations => {
                "frames x joints x 4 local rotations, quaternions (x, y, z, w)"
            }
            Column::RootTranslation => "frames x 3 root positions, metres",
            Column::Rotations6d => {
                "frames x joints x 6: first two rotation-matrix columns (opt-in)"
            }
            Column::JointVelocities => "frames x joints x 3 velocities, m/s (opt-in)",
            Column::FootContacts => {
                "frames x 4 contacts: left ankle, left toe, right ankle, right toe"
            }
            Column::FutureRoot => {
                "frames x 3 x 3: root displacement and heading change at +10, +20, +30 frames"
            }
            Column::CanonicalPositions => {
                "frames x joints x 3 positions in the first frame's canonical frame: pelvis over the origin, facing +y"
            }
        }
    }

    /// The shape of a per-frame array column, `None` for the others.
    pub fn frame_shape(self) -> Option<FrameShape> {
        FRAME_COLUMNS
            .iter()
            .find(|(c, _)| *c == self)
            .map(|(_, shape)| *shape)
    }

    /// The column's Arrow field: name, type and nullability.
    pub fn field(self) -> Field {
        let name = self.name();
        match self {
            Column::ClipId => Field::new(name, DataType::Utf8, false),
            Column::SourceKind => Field::new(name, DataType::Utf8, false),
            Column::SourceName => Field::new(name, DataType::Utf8, false),
            Column::SourcePath => Field::new(name, DataType::Utf8, false),
            Column::SourceSha256 => Field::new(name, DataType::Utf8, false),
            Column::SourceFps => Field::new(name, DataType::Float64, false),
            Column::FrameRange => Field::new(name, DataType::Struct(frame_range_fields()), false),
            Column::Mirrored => Field::new(name, DataType::Boolean, false),
            Column::Split => Field::new(name, DataType::Utf8, false),
            Column::Action => Field::new(name, DataType::Utf8, false),
            Column::Text => Field::new(name, DataType::Utf8, false),
            Column::Texts => list_utf8(name),
            Column::Labels => list_utf8(name),
            Column::AnnotationSource => Field::new(name, DataType::Utf8, false),
            Column::AnnotationOrigin => Field::new(name, DataType::Utf8, false),
            Column::MotionType => Field::new(name, DataType::Utf8, true),
            Column::Hand => Field::new(name, DataType::Utf8, true),
            Column::Object => Field::new(name, DataType::Utf8, true),
            Column::GoalPelvis => fixed(name, DataType::Float32, 2),
            Column::GoalHand => fixed(name, DataType::Float32, 3),
            Column::Parts => fixed(name, DataType::Boolean, 6),
            Column::LabelSource => Field::new(name, DataType::Utf8, true),
            Column::Paraphrases => list_utf8(name),
            Column::ComposedFrom => list_utf8(name),
            Column::ComposedParts => Field::new(
                name,
                DataType::List(item(DataType::FixedSizeList(item(DataType::Boolean), 6))),
                false,
            ),
            Column::FootSkate => Field::new(name, DataType::Float32, true),
            Column::GroundPenetration => Field::new(name, DataType::Float32, true),
            Column::SelfDistance => Field::new(name, DataType::Float32, true),
            Column::Lean => Field::new(name, DataType::Float32, true),
            Column::Attributes => Field::new(name, attributes_type(), false),
            Column::Skeleton => Field::new(name, DataType::Utf8, false),
            Column::Fps => Field::new(name, DataType::Float64, false),
            Column::NumFrames => Field::new(name, DataType::Int32, false),
            Column::NumJoints => Field::new(name, DataType::Int32, false),
            Column::JointPositions => frames(self, false),
            Column::LocalRotations => frames(self, false),
            Column::RootTranslation => frames(self, false),
            Column::Rotations6d => frames(self, true),
            Column::JointVelocities => frames(self, true),
            Column::FootContacts => frames(self, true),
            Column::FutureRoot => frames(self, true),
            Column::CanonicalPositions => frames(self, false),
        }
    }
}

/// The per-frame array columns and their shapes, in schema order.
pub const FRAME_COLUMNS: [(Column, FrameShape); 8] = [
    (Column::JointPositions, PER_JOINT_3),
    (
        Column::LocalRotations,
        FrameShape {
            per_joint: true,
            inner: &[4],
            boolean: false,
        },
    ),
    (
        Column::RootTranslation,
        FrameShape {
            per_joint: false,
            inner: &[3],
            boolean: false,
        },
    ),
    (
        Column::Rotations6d,
        FrameShape {
            per_joint: true,
            inner: &[6],
            boolean: false,
        },
    ),
    (Column::JointVelocities, PER_JOINT_3),
    (
        Column::FootContacts,
        FrameShape {
            per_joint: false,
            inner: &[4],
            boolean: true,
        },
    ),
    (
        Column::FutureRoot,
        FrameShape {
            per_joint: false,
            inner: &[3, 3],
            boolean: false,
        },
    ),
    (Column::CanonicalPositions, PER_JOINT_3),
];

/// The shape of per-frame column `name`, `None` for any other column (readers of a table whose
/// columns are known only by name).
pub fn frame_shape(name: &str) -> Option<FrameShape> {
    Column::from_name(name).and_then(Column::frame_shape)
}

/// A list's (or fixed-size list's) element: named `item` as pyarrow names it, never null.
fn item(data_type: DataType) -> Arc<Field> {
    Arc::new(Field::new("item", data_type, false))
}

/// A per-frame column; nullable for the opt-in features.
fn frames(column: Column, nullable: bool) -> Field {
    let shape = column.frame_shape().unwrap_or(PER_JOINT_3);
    Field::new(column.name(), shape.data_type(), nullable)
}

fn list_utf8(name: &str) -> Field {
    Field::new(name, DataType::List(item(DataType::Utf8)), false)
}

/// A small fixed-length vector of a clip (a goal, the six parts), null when the clip has none.
fn fixed(name: &str, data_type: DataType, n: i32) -> Field {
    Field::new(name, DataType::FixedSizeList(item(data_type), n), true)
}

/// The fields of one `attributes` entry.
pub fn attribute_fields() -> Fields {
    Fields::from(vec![
        Field::new("key", DataType::Utf8, false),
        Field::new("value", DataType::Utf8, false),
    ])
}

/// The fields of `frame_range`.
pub fn frame_range_fields() -> Fields {
    Fields::from(vec![
        Field::new("start", DataType::Int64, false),
        Field::new("end", DataType::Int64, false),
    ])
}

/// `attributes`: a list of key/value structs rather than an Arrow map: the same bytes on disk,
/// and readers without map support (Hugging Face `datasets`) open it.
fn attributes_type() -> DataType {
    DataType::List(item(DataType::Struct(attribute_fields())))
}

/// The Arrow schema of a clip table: every [`Column`]'s field, in order.
pub fn clip_schema() -> Schema {
    Schema::new(Column::ALL.map(Column::field).to_vec())
}

/// What column `name` holds, in a phrase for the dataset card; empty for a name the table lacks.
pub fn column_meaning(name: &str) -> &'static str {
    Column::from_name(name).map_or("", Column::meaning)
}

/// The schema as JSON (name, type, nullable per column), for docs and checks.
pub fn clip_schema_json() -> serde_json::Value {
    let fields: Vec<serde_json::Value> = clip_schema()
        .fields()
        .iter()
        .map(|f| {
            serde_json::json!({
                "name": f.name(),
                "type": f.data_type().to_string(),
                "nullable": f.is_nullable(),
            })
        })
        .collect();
    serde_json::json!({ "table": "clips", "version": SCHEMA_VERSION, "fields": fields })
}

/// `named` columns in the order of `schema`'s fields, matched by name: every field must have
/// exactly one column and every column a field, so the writer cannot drift from the schema.
pub fn in_schema_order(
    schema: &Schema,
    named: Vec<(&str, ArrayRef)>,
) -> Result<Vec<ArrayRef>, ArrowError> {
    let mut by_name: std::collections::BTreeMap<&str, ArrayRef> = std::collections::BTreeMap::new();
    for (name, column) in named {
        if by_name.insert(name, column).is_some() {
            return Err(ArrowError::SchemaError(format!(
                "column `{name}` given twice"
            )));
        }
    }
    let columns = schema
        .fields()
        .iter()
        .map(|f| {
            by_name.remove(f.name().as_str()).ok_or_else(|| {
                ArrowError::SchemaError(format!("no column for schema field `{}`", f.name()))
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    match by_name.keys().next() {
        Some(extra) => Err(ArrowError::SchemaError(format!(
            "column `{extra}` is not in the schema"
        ))),
        None => Ok(columns),
    }
}

#[cfg(test)]
mod order_tests {
    use super::*;
    use arrow_array::Int32Array;

    #[test]
    fn columns_are_matched_by_name_and_every_mismatch_is_an_error() {
        let schema = Schema::new(vec![
            Field::new("a", DataType::Int32, false),
            Field::new("b", DataType::Int32, false),
        ]);
        let col = |v: i32| -> ArrayRef { Arc::new(Int32Array::from(vec![v])) };
        let ordered = in_schema_order(&schema, vec![("b", col(2)), ("a", col(1))]).unwrap();
        assert_eq!(ordered[0].as_ref(), col(1).as_ref());
        assert!(in_schema_order(&schema, vec![("a", col(1))]).is_err());
        assert!(
            in_schema_order(&schema, vec![("a", col(1)), ("b", col(2)), ("c", col(3))]).is_err()
        );
        assert!(
            in_schema_order(&schema, vec![("a", col(1)), ("a", col(1)), ("b", col(2))]).is_err()
        );
    }

    #[test]
    fn every_per_frame_column_has_its_shapes_type_in_the_schema() {
        let schema = clip_schema();
        for (column, shape) in FRAME_COLUMNS {
            let field = schema.field_with_name(column.name()).unwrap();
            assert_eq!(field.data_type(), &shape.data_type(), "{column:?}");
        }
        assert_eq!(
            frame_shape("joint_positions")
                .unwrap()
                .data_type()
                .to_string(),
            DataType::List(item(DataType::List(item(DataType::FixedSizeList(
                item(DataType::Float32),
                3
            )))))
            .to_string()
        );
        assert_eq!(frame_shape("future_root").unwrap().width(), 9);
        assert_eq!(frame_shape("clip_id"), None);
    }

    #[test]
    fn every_column_is_one_schema_field_in_order_and_found_by_its_name() {
        let schema = clip_schema();
        assert_eq!(schema.fields().len(), Column::ALL.len());
        for (field, column) in schema.fields().iter().zip(Column::ALL) {
            assert_eq!(field.name(), column.name());
            assert_eq!(Column::from_name(field.name()), Some(column));
        }
        assert_eq!(Column::from_name("joint_position"), None);
    }

    #[test]
    fn every_column_has_a_meaning_for_the_card() {
        for f in clip_schema().fields() {
            assert!(!column_meaning(f.name()).is_empty(), "{}", f.name());
        }
    }
}
