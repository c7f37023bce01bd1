//! The leaf types every other module builds on: content fingerprints and digests, atomic writes
//! and the workspace lock, what a build refuses and drops, and the names of a dataset's files.
//! Depends on no other module of the crate.

pub mod layout;
pub mod lock;
mod reject;
mod write;

pub use reject::{DropReason, Dropped, MAX_MESSAGE_CHARS, Reject, RejectReason};
pub use write::{
    Fingerprint, Stamp, WorkspaceError, hex, io_err, io_hint, sha256_hex, temp_path, write_atomic,
    write_atomic_with,
};
