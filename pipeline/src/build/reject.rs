//! Rejected inputs: what was refused, where, and why. Every reject lands in `rejects.jsonl`.

use serde::{Deserialize, Serialize};

/// One refused input.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Reject {
    /// The stage that refused it.
    pub stage: String,
    /// The input file.
    pub file: String,
    /// 1-based line in that file, where known. (Always serialised, `null` when unknown: the
    /// stage cache uses a format without field names, where skipped fields cannot be decoded.)
    pub line: Option<u64>,
    /// 0-based frame, where known.
    pub frame: Option<u64>,
    /// Short machine-readable reason (`bvh`, `label_pattern`, `profile`, ...).
    pub reason: String,
    /// What was expected and found, for people.
    pub message: String,
}

impl std::fmt::Display for Reject {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        write!(f, ": {}", self.message)
    }
}
