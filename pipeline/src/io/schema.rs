//! The clip table schema, as a value: printed by `motionforge schema`, documented in
//! `schemas/clips.md`, and compared with `schemas/clips.schema.json` in a test.

use std::sync::Arc;

use arrow_schema::{DataType, Field, Fields, Schema};

/// Version of the clip table layout; bump on any change to columns or their meaning.
pub const SCHEMA_VERSION: u32 = 7;

fn list_f32(name: &str) -> Field {
    Field::new(
        name,
        DataType::List(Arc::new(Field::new("item", DataType::Float32, false))),
        false,
    )
}

fn list_utf8(name: &str) -> Field {
    Field::new(
        name,
        DataType::List(Arc::new(Field::new("item", DataType::Utf8, false))),
        false,
    )
}

fn goal(name: &str) -> Field {
    Field::new(
        name,
        DataType::List(Arc::new(Field::new("item", DataType::Float32, false))),
        true,
    )
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
        goal("goal_pelvis"),
        goal("goal_hand"),
        Field::new(
            "parts",
            DataType::List(Arc::new(Field::new("item", DataType::Boolean, false))),
            true,
        ),
        Field::new("label_source", DataType::Utf8, true),
        list_utf8("paraphrases"),
        list_utf8("composed_from"),
        Field::new(
            "composed_parts",
            DataType::List(Arc::new(Field::new(
                "item",
                DataType::List(Arc::new(Field::new("item", DataType::Boolean, false))),
                false,
            ))),
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
        list_f32("joint_positions"),
        list_f32("local_rotations"),
        list_f32("root_translation"),
        goal("rotations_6d"),
        goal("joint_velocities"),
        Field::new(
            "foot_contacts",
            DataType::List(Arc::new(Field::new("item", DataType::Boolean, false))),
            true,
        ),
        goal("future_root"),
    ])
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
