//! Annotation formats: where clips' frame ranges and texts come from.
//!
//! Knows nothing of motion math beyond frame counts.

pub mod babel;
pub mod filename;
pub mod span;
