//! The commands' implementations, grouped by concern; `main.rs` parses and dispatches.

pub(crate) mod bench_build;
pub(crate) mod browse;
pub(crate) mod labels;
pub(crate) mod session;
pub(crate) mod summary;
pub(crate) mod tools;
