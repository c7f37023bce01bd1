//! Sinks: the clip table schema and its Parquet writer.

pub mod manifest;
pub mod normalization;
pub mod parquet;
pub mod schema;
