//! The commands' implementations, grouped by concern; `main.rs` parses and dispatches.

pub(crate) mod bench_build;
pub(crate) mod browse;
pub(crate) mod labels;
pub(crate) mod session;
pub(crate) mod summary;
pub(crate) mod tools;

/// A mistake in how a command was called that clap cannot see (a value valid only for the
/// dataset at hand, an option another one requires): exit code 2, as clap's own.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub(crate) struct UsageError(pub(crate) String);
