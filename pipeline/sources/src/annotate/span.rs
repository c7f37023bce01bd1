//! The common form every annotation format is read into: labelled time spans per capture.

use serde::{Deserialize, Serialize};

/// A point on a capture's timeline, as the annotation states it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Time {
    /// Seconds from the start of the annotated timeline.
    Seconds(f64),
    /// A frame number at a stated rate (HumanML3D's index is at 20 fps).
    Frame {
        /// Frame number.
        frame: i64,
        /// The rate the number counts at.
        fps: f64,
    },
    /// The end of the capture (`-1` in HumanML3D's index).
    End,
    /// `frames` frames (at the stated rate) before the end of the capture: a Python slice's
    /// negative end (`data[start:-1]` in HumanML3D's cuts).
    BeforeEnd {
        /// Frames before the end.
        frames: i64,
        /// The rate the number counts at.
        fps: f64,
    },
}

impl Time {
    /// The capture frame this time falls in at `fps`, as SINC and TEACH compute it:
    /// `floor(t · fps)`. `End` maps to `len`.
    pub fn to_frame(self, fps: f64, len: u64) -> i64 {
        match self {
            Time::Seconds(t) => (t * fps + 1e-9).floor() as i64,
            Time::Frame { frame, fps: at } => ((frame as f64 / at) * fps + 1e-9).floor() as i64,
            Time::End => len as i64,
            Time::BeforeEnd { frames, fps: at } => {
                len as i64 - ((frames as f64 / at) * fps + 1e-9).floor() as i64
            }
        }
    }
}

/// Which hand an action uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Hand {
    /// Left hand.
    Left,
    /// Right hand.
    Right,
    /// Both hands.
    Both,
}

impl Hand {
    /// Parses `left`, `right`, `both` (any case; `l`, `r`, `lr` too).
    pub fn parse(s: &str) -> Option<Hand> {
        match s.trim().to_ascii_lowercase().as_str() {
            "left" | "l" => Some(Hand::Left),
            "right" | "r" => Some(Hand::Right),
            "both" | "lr" | "left_right" | "left and right" => Some(Hand::Both),
            _ => None,
        }
    }

    /// The other side (both stays both).
    pub fn mirrored(self) -> Hand {
        match self {
            Hand::Left => Hand::Right,
            Hand::Right => Hand::Left,
            Hand::Both => Hand::Both,
        }
    }

    /// Name as written in datasets.
    pub fn as_str(self) -> &'static str {
        match self {
            Hand::Left => "left",
            Hand::Right => "right",
            Hand::Both => "both",
        }
    }
}

/// One labelled span of a capture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Span {
    /// Start of the span.
    pub start: Time,
    /// End of the span (exclusive).
    pub end: Time,
    /// The text as the annotator wrote it.
    pub raw_text: String,
    /// The processed label (BABEL's `proc_label`; the raw text where the format has none).
    pub label: String,
    /// Action categories (BABEL's `act_cat`).
    pub categories: Vec<String>,
    /// Motion type named by the annotation itself (event logs), before the config's mapping.
    pub motion_type: Option<String>,
    /// Hand used, when the annotation says.
    pub hand: Option<Hand>,
    /// Object involved, when the annotation says.
    pub object: Option<String>,
    /// Time of the grasp inside the span (event logs), for hand goals.
    pub grasp: Option<Time>,
    /// Identifier in the source (BABEL `seg_id`, row number, ...).
    pub id: String,
    /// Further captions of the same span by other annotators (HumanML3D's `texts/` files hold
    /// about three per clip); the clip keeps them all, `raw_text` first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub alternatives: Vec<String>,
}

/// Everything an annotation file says about one capture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct CaptureAnnotation {
    /// The labelled spans.
    pub spans: Vec<Span>,
    /// Overlapping spans describe simultaneous actions (BABEL frame labels, event logs); in
    /// frame-range indexes they are independent crops.
    pub simultaneous: bool,
    /// Duration the annotation states for the capture, in seconds.
    pub duration: Option<f64>,
    /// Where the spans came from (file and record), for provenance.
    pub origin: String,
    /// Quirks met while reading (clamped ends, skipped null labels, ...), counted by kind.
    pub notes: Vec<Note>,
    /// Capture-level fields (file-name groups, sidecar keys), carried to every clip.
    #[serde(default)]
    pub attributes: std::collections::BTreeMap<String, String>,
}

/// Something odd in an annotation that was handled, not fatal.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Note {
    /// Short kind (`null_label`, `end_past_duration`, `unsorted`, ...).
    pub kind: String,
    /// Details for people.
    pub message: String,
}

impl Note {
    /// A note of `kind` with a message.
    pub fn new(kind: &str, message: impl Into<String>) -> Note {
        Note {
            kind: kind.to_string(),
            message: message.into(),
        }
    }
}

/// Notes of one kind listed in a build report; the rest are counted in one [`NOT_LISTED`] note,
/// so a file of a million bad rows gives a report of a few hundred lines, not a million.
pub const NOTES_PER_KIND: usize = 200;

/// Kind of the note that counts the notes of another kind left out of a list.
pub const NOT_LISTED: &str = "notes_not_listed";

/// `notes` with at most `limit` of each kind, in their order; for each kind with more, one
/// [`NOT_LISTED`] note at the end says how many more there were.
pub fn cap_per_kind(notes: Vec<Note>, limit: usize) -> Vec<Note> {
    let mut seen: std::collections::BTreeMap<String, usize> = std::collections::BTreeMap::new();
    let mut kept = Vec::with_capacity(notes.len().min(limit.saturating_mul(8)));
    for note in notes {
        let n = seen.entry(note.kind.clone()).or_insert(0);
        *n += 1;
        if *n <= limit || note.kind == NOT_LISTED {
            kept.push(note);
        }
    }
    for (kind, n) in seen {
        if n > limit && kind != NOT_LISTED {
            kept.push(Note::new(
                NOT_LISTED,
                format!(
                    "{} more `{kind}` notes not listed (the first {limit} are)",
                    n - limit
                ),
            ));
        }
    }
    kept
}

/// Why an annotation file cannot be read at all (single bad records become notes or rejects).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}{}: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct AnnotationError {
    /// The annotation file.
    pub file: String,
    /// 1-based line, where known.
    pub line: Option<u64>,
    /// What was expected and found.
    pub message: String,
}

/// The key a capture is found by: its file stem, after the source's path mapping.
pub fn stem_of(path: &str) -> String {
    let name = path.rsplit(['/', '\\']).next().unwrap_or(path);
    let stem = name.split_once('.').map(|(s, _)| s).unwrap_or(name);
    stem.to_string()
}
