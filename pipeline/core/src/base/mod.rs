//! The leaf types every other module builds on: content fingerprints and digests, atomic writes
//! and the workspace lock, what a build refuses and drops, the names of a dataset's files, and what a
//! command may replace.
//! Depends on no other module of the crate.

pub mod guard;
pub mod layout;
pub mod lock;
mod reject;
pub mod tally;
pub mod toml_path;
mod write;

pub use reject::{DropReason, Dropped, MAX_MESSAGE_CHARS, Reject, RejectReason};
pub use tally::{Named, Tally};
pub use write::{
    Fingerprint, HashingWriter, ReadBackProblem, Stamp, WorkspaceError, encoded_sha256, hex,
    io_err, io_hint, replace_dir, restore_replaced, sha256_hex, sibling, temp_path, write_atomic,
    write_atomic_with, write_replaceable_with,
};

/// `path` with `.` removed and `dir/..` folded lexically (no file system access), so paths print
/// the way people wrote them and `strip_prefix` sees through them.
pub fn lexical_path(path: &std::path::Path) -> std::path::PathBuf {
    use std::path::Component;
    let mut out: Vec<Component<'_>> = Vec::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir if matches!(out.last(), Some(Component::Normal(_))) => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out.iter().collect()
}

/// A string that lives as long as the program: for vocabularies read once at start.
pub fn leak(s: String) -> &'static str {
    Box::leak(s.into_boxed_str())
}
