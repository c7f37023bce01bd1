//! Sinks: the clip table schema and its Parquet writer.

pub mod normalization;
pub mod parquet;
pub mod schema;
