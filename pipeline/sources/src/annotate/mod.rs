//! Annotation formats: where clips' frame ranges and texts come from.
//!
//! Knows nothing of motion math beyond frame counts.

pub mod babel;
pub mod event_log;
pub mod filename;
pub mod frame_index;
pub mod overlap;
pub mod span;
pub mod taxonomy;
