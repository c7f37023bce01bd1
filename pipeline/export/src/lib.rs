//! Exports of a built dataset into the layouts other tools read, from its shards alone (no
//! rebuild, no config): HumanML3D's folder for the field's training code and evaluators.
//!
//! Step 6 of a clip's way: its row, read back from the shards, becomes HumanML3D's
//! `new_joints/`, `new_joint_vecs/` and `texts/` files (principal type: [`ExportOptions`]).

pub mod humanml3d;

pub use humanml3d::{ExportError, ExportOptions, ExportSummary, export_humanml3d};
