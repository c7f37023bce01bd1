//! Stages: each a function from typed inputs to typed outputs, with a fingerprint of what it read.
//! The build runner (the `build` module) handles caching, atomic writes and reporting.

pub mod augment;
pub mod compose;
pub mod ingest;
pub mod label;
pub mod mirror;
pub mod segment;
pub mod split;
