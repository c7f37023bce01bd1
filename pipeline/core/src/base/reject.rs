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
    /// Why, in one machine-readable word (`bvh`, `label_pattern`, `profile`, ...).
    pub reason: RejectReason,
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
    /// Why it became no clip.
    pub reason: DropReason,
    /// The segment's text (an excerpt), or its annotation id where it has no text.
    pub text: String,
    /// The segment's frame range at the capture's rate, where it got that far.
    pub frames: Option<(u64, u64)>,
}

/// Generates a reason enum that serialises (and prints) as its snake_case name.
macro_rules! reasons {
    ($(#[$meta:meta])* $name:ident { $($(#[$vmeta:meta])* $variant:ident => $text:literal,)* }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
        #[serde(rename_all = "snake_case")]
        pub enum $name {
            $($(#[$vmeta])* $variant,)*
        }

        impl $name {
            /// Every reason, in declaration order.
            pub const ALL: &'static [$name] = &[$($name::$variant,)*];

            /// The reason as written in `rejects.jsonl` and `build-report.json`.
            pub fn as_str(self) -> &'static str {
                match self {
                    $($name::$variant => $text,)*
                }
            }
        }

        impl crate::base::tally::Named for $name {
            const ALL: &'static [$name] = $name::ALL;

            fn name(self) -> &'static str {
                self.as_str()
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.as_str())
            }
        }
    };
}

reasons! {
    /// Why an input was refused (`docs/formats.md`, "Reject reasons").
    RejectReason {
        /// The file cannot be read.
        Io => "io",
        /// The file is not UTF-8.
        Encoding => "encoding",
        /// The BVH does not parse, or holds implausible values.
        Bvh => "bvh",
        /// A frame-rate override outside the plausible range.
        Fps => "fps",
        /// The skeleton profile does not fit the capture.
        Profile => "profile",
        /// The capture has no frames.
        Empty => "empty",
        /// The file name does not match the label pattern.
        LabelPattern => "label_pattern",
        /// The sidecar JSON is not an object.
        Sidecar => "sidecar",
        /// A label template names a field the file name does not give.
        LabelTemplate => "label_template",
        /// No annotation names the capture.
        NoAnnotation => "no_annotation",
        /// An LLM request failed after its last retry.
        LlmRequest => "llm_request",
        /// A task plan still invalid after one repair.
        InvalidPlan => "invalid_plan",
        /// The profile cannot mirror the skeleton.
        Mirror => "mirror",
        /// A joint-position array that does not read, does not fit its layout, or whose bone
        /// lengths wander beyond the tolerance.
        Positions => "positions",
        /// An AMASS `.npz` that does not read (a key missing, damaged or of the wrong shape, no
        /// frame rate, a NaN pose), or whose body model is missing or does not fit.
        Amass => "amass",
    }
}

reasons! {
    /// Why a segment became no clip (`docs/formats.md`, segment drop reasons).
    DropReason {
        /// Its label is in `drop_labels`.
        DroppedLabel => "dropped_label",
        /// Its caption is empty or blank.
        EmptyText => "empty_text",
        /// Its caption or label is longer than a caption may be (`humanml3d::caption::MAX_CAPTION_CHARS`).
        LongText => "long_text",
        /// It starts past the capture's end.
        PastEnd => "past_end",
        /// The start trim removes all of it.
        Trimmed => "trimmed",
        /// It ends where it starts (or before).
        EmptyRange => "empty_range",
        /// An identical row of the same capture came first.
        Duplicate => "duplicate",
        /// Shorter than `min_seconds` after resampling.
        TooShort => "too_short",
        /// Longer than `max_seconds` after resampling.
        TooLong => "too_long",
        /// More simultaneous actions than `max_simultaneous`.
        TooManySimultaneous => "too_many_simultaneous",
        /// A real pair with a word of `pair_exclude`.
        ExcludedPair => "excluded_pair",
    }
}
