//! Sinks: the clip table schema and its Parquet writer, and the files written beside the shards
//! (manifest, normalisation statistics, `skeletons.json`).

pub mod manifest;
pub mod normalization;
pub mod parquet;
pub mod schema;
pub mod skeletons;
