//! Sinks: the clip table schema and its Parquet writer.

pub mod parquet;
pub mod schema;
