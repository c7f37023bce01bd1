//! Library tests without a build: readers of captures and annotations on real files, the motion core, mirroring, composition, text, captions, labels, plausibility, the taxonomy, and the crate graph.
//!
//! One test binary per group (not one per file): each binary links the whole library, so a few
//! binaries build much faster than one per file. Run one file's tests with its module name as the
//! filter: `cargo test --test motion annotate_readers::`.

mod common;

#[path = "annotate_readers.rs"]
mod annotate_readers;

#[path = "bvh_damaged.rs"]
mod bvh_damaged;

#[path = "bvh_real.rs"]
mod bvh_real;

#[path = "compose_real.rs"]
mod compose_real;

#[path = "compose_text.rs"]
mod compose_text;

#[path = "humanml3d.rs"]
mod humanml3d;

#[path = "humanml3d_captions.rs"]
mod humanml3d_captions;

#[path = "mirror_real.rs"]
mod mirror_real;

#[path = "motion_core.rs"]
mod motion_core;

#[path = "crate_graph.rs"]
mod crate_graph;

#[path = "parts_labels.rs"]
mod parts_labels;

#[path = "quality.rs"]
mod quality;

#[path = "segment_real.rs"]
mod segment_real;

#[path = "taxonomy.rs"]
mod taxonomy;

#[path = "text_mirror.rs"]
mod text_mirror;
