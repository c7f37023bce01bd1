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

/// Longest reject message kept, in characters: a message quoting a damaged file must not carry
/// the file into `rejects.jsonl`, the build report, the terminal and the service history.
pub const MAX_MESSAGE_CHARS: usize = 400;

impl Reject {
    /// This reject with its message cut to [`MAX_MESSAGE_CHARS`] (marked with `…`).
    pub fn bounded(mut self) -> Reject {
        if let Some((cut, _)) = self.message.char_indices().nth(MAX_MESSAGE_CHARS) {
            self.message.truncate(cut);
            self.message.push('…');
        }
        self
    }
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

/// A segment that became no clip: which file, why, and what it said.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Dropped {
    /// The capture file.
    pub file: String,
    /// Short machine-readable reason (`too_short`, `duplicate`, `empty_text`, ...).
    pub reason: String,
    /// The segment's text (an excerpt), or its annotation id where it has no text.
    pub text: String,
    /// The segment's frame range at the capture's rate, where it got that far.
    pub frames: Option<(u64, u64)>,
}
