//! Exports of a built dataset into the layouts other tools read, from its shards alone (no
//! rebuild, no config): HumanML3D's folder for the field's training code and evaluators.

pub mod humanml3d;

pub use humanml3d::{ExportError, ExportOptions, ExportSummary, export_humanml3d};
