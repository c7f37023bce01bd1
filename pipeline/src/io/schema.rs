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

/// The per-frame array columns and their shapes, in schema order.
pub const FRAME_COLUMNS: [(&str, FrameShape); 8] = [
    ("joint_positions", PER_JOINT_3),
    (
        "local_rotations",
        FrameShape {
            per_joint: true,
            inner: &[4],
            boolean: false,
        },
    ),
    (
        "root_translation",
        FrameShape {
            per_joint: false,
            inner: &[3],
            boolean: false,
        },
    ),
    (
        "rotations_6d",
        FrameShape {
            per_joint: true,
            inner: &[6],
            boolean: false,
        },
    ),
    ("joint_velocities", PER_JOINT_3),
    (
        "foot_contacts",
        FrameShape {
            per_joint: false,
            inner: &[4],
            boolean: true,
        },
    ),
    (
        "future_root",
        FrameShape {
            per_joint: false,
            inner: &[3, 3],
            boolean: false,
        },
    ),
    ("canonical_positions", PER_JOINT_3),
];

/// The shape of per-frame column `name`, `None` for any other column.
pub fn frame_shape(name: &str) -> Option<FrameShape> {
    FRAME_COLUMNS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, shape)| *shape)
}

/// A list's (or fixed-size list's) element: named `item` as pyarrow names it, never null.
fn item(data_type: DataType) -> Arc<Field> {
    Arc::new(Field::new("item", data_type, false))
}

/// A per-frame column; nullable for the opt-in features.
fn frames(name: &str, nullable: bool) -> Field {
    let shape = frame_shape(name).unwrap_or(PER_JOINT_3);
    Field::new(name, shape.data_type(), nullable)
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

/// The Arrow schema of a clip table.
pub fn clip_schema() -> Schema {
    let frame_range = Fields::from(vec![
        Field::new("start", DataType::Int64, false),
        Field::new("end", DataType::Int64, false),
    ]);
    // A list of key/value structs rather than an Arrow map: the same bytes on disk, and readers
    // without map support (Hugging Face `datasets`) open it.
    let attributes = DataType::List(Arc::new(Field::new(
        "item",
        DataType::Struct(attribute_fields()),
        false,
    )));
    Schema::new(vec![
        Field::new("clip_id", DataType::Utf8, false),
        Field::new("source_kind", DataType::Utf8, false),
        Field::new("source_name", DataType::Utf8, false),
        Field::new("source_path", DataType::Utf8, false),
        Field::new("source_sha256", DataType::Utf8, false),
        Field::new("source_fps", DataType::Float64, false),
        Field::new("frame_range", DataType::Struct(frame_range), false),
        Field::new("mirrored", DataType::Boolean, false),
        Field::new("split", DataType::Utf8, false),
        Field::new("action", DataType::Utf8, false),
        Field::new("text", DataType::Utf8, false),
        list_utf8("texts"),
        list_utf8("labels"),
        Field::new("annotation_source", DataType::Utf8, false),
        Field::new("annotation_origin", DataType::Utf8, false),
        Field::new("motion_type", DataType::Utf8, true),
        Field::new("hand", DataType::Utf8, true),
        Field::new("object", DataType::Utf8, true),
        fixed("goal_pelvis", DataType::Float32, 2),
        fixed("goal_hand", DataType::Float32, 3),
        fixed("parts", DataType::Boolean, 6),
        Field::new("label_source", DataType::Utf8, true),
        list_utf8("paraphrases"),
        list_utf8("composed_from"),
        Field::new(
            "composed_parts",
            DataType::List(item(DataType::FixedSizeList(item(DataType::Boolean), 6))),
            false,
        ),
        Field::new("foot_skate", DataType::Float32, true),
        Field::new("ground_penetration", DataType::Float32, true),
        Field::new("self_distance", DataType::Float32, true),
        Field::new("lean", DataType::Float32, true),
        Field::new("attributes", attributes, false),
        Field::new("skeleton", DataType::Utf8, false),
        Field::new("fps", DataType::Float64, false),
        Field::new("num_frames", DataType::Int32, false),
        Field::new("num_joints", DataType::Int32, false),
        frames("joint_positions", false),
        frames("local_rotations", false),
        frames("root_translation", false),
        frames("rotations_6d", true),
        frames("joint_velocities", true),
        frames("foot_contacts", true),
        frames("future_root", true),
        frames("canonical_positions", false),
    ])
}

/// What a column holds, in a phrase for the dataset card (`schemas/clips.md` has the details).
pub fn column_meaning(name: &str) -> &'static str {
    match name {
        "clip_id" => "unique id: source, capture, frame range, `:m` when mirrored",
        "source_kind" => "`real_single`, `real_pair` or `synthetic` (composed by body part)",
        "source_name" => "the build config's source the capture came from",
        "source_path" => "capture file, relative to the build config",
        "source_sha256" => "SHA-256 of the capture file",
        "source_fps" => "the capture's frame rate",
        "frame_range" => "[start, end) in the capture's own frames",
        "mirrored" => "left/right mirrored copy of another row",
        "split" => "train, validation or test, by capture",
        "action" => "the action label",
        "text" => "the caption",
        "texts" => "every caption of the clip",
        "labels" => "every action label of the clip",
        "annotation_source" => "annotation format (filename, babel, event_log, frame_index)",
        "annotation_origin" => "annotation file and span the clip was cut by",
        "motion_type" => "LINGO motion type of the label",
        "hand" => "hand the annotation names (left, right, both)",
        "object" => "object the annotation names",
        "goal_pelvis" => "[x, y] where the pelvis ends, metres, first-frame canonical frame",
        "goal_hand" => "[x, y, z] where the hand reaches, metres, first-frame canonical frame",
        "parts" => "body parts used: global, torso, left arm, right arm, left leg, right leg",
        "label_source" => "which labeller gave `parts`",
        "paraphrases" => "LLM paraphrases of `text`",
        "composed_from" => "synthetic pairs: the two source clip ids",
        "composed_parts" => "synthetic pairs: the parts taken from each source",
        "foot_skate" => "plausibility: planted-foot speed, m/s",
        "ground_penetration" => "plausibility: deepest joint below the floor, metres",
        "self_distance" => "plausibility: closest limb to spine bone distance, metres",
        "lean" => "plausibility: largest sustained lean, degrees",
        "attributes" => "capture-level annotation fields (key, value)",
        "skeleton" => "skeleton id `<profile>:<digest>`, key into skeletons.json",
        "fps" => "the dataset's frame rate",
        "num_frames" => "frames",
        "num_joints" => "joints (end sites not counted)",
        "joint_positions" => "frames x joints x 3 positions, metres (x right, y forward, z up)",
        "local_rotations" => "frames x joints x 4 local rotations, quaternions (x, y, z, w)",
        "root_translation" => "frames x 3 root positions, metres",
        "rotations_6d" => "frames x joints x 6: first two rotation-matrix columns (opt-in)",
        "joint_velocities" => "frames x joints x 3 velocities, m/s (opt-in)",
        "foot_contacts" => "frames x 4 contacts: left ankle, left toe, right ankle, right toe",
        "future_root" => {
            "frames x 3 x 3: root displacement and heading change at +10, +20, +30 frames"
        }
        "canonical_positions" => {
            "frames x joints x 3 positions in the first frame's canonical frame: pelvis over the origin, facing +y"
        }
        _ => "",
    }
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
        for (name, shape) in FRAME_COLUMNS {
            let field = schema.field_with_name(name).unwrap();
            assert_eq!(field.data_type(), &shape.data_type(), "{name}");
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
    fn every_column_has_a_meaning_for_the_card() {
        for f in clip_schema().fields() {
            assert!(!column_meaning(f.name()).is_empty(), "{}", f.name());
        }
    }
}
