//! The common form every annotation format is read into: labelled time spans per capture.

use serde::{Deserialize, Serialize};

use super::event_log::{EVENT_COLUMNS, RowFault};
use super::frame_index::{CsvFault, INDEX_COLUMNS};

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
    /// What it is about.
    pub kind: NoteKind,
    /// Details for people.
    pub message: String,
}

impl Note {
    /// A note of `kind` with a message.
    pub fn new(kind: NoteKind, message: impl Into<String>) -> Note {
        Note {
            kind,
            message: message.into(),
        }
    }
}

/// What an annotation note is about: a closed set, written by its name (`null_label`, ...) in
/// build reports and in the stage cache alike, and ordered by that name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum NoteKind {
    /// A BABEL label or notebook row without numeric times (skipped).
    BadTimes,
    /// A BABEL label with integer times.
    IntegerTimes,
    /// Labels without text, skipped.
    NullLabel,
    /// Labels or events out of time order (sorted on read).
    Unsorted,
    /// A span ending past the record's duration (clamped).
    EndPastDuration,
    /// A BABEL record without `feat_p`: it cannot be matched to a capture.
    NoFeatP,
    /// A BABEL record with neither frame nor sequence labels.
    NoLabels,
    /// A BABEL record of several annotators' work.
    SeveralAnnotations,
    /// Another annotator's span that covers no span of the first annotation.
    UnmatchedAnnotation,
    /// An event-log column the reader does not know (ignored).
    UnknownColumn,
    /// An event-log event before any instruction.
    EventBeforeInstruction,
    /// A second grasp in one event-log instruction.
    SecondGrasp,
    /// A frame-index row that cannot be read.
    BadRow,
    /// A frame-index row without a caption.
    NoCaption,
    /// Two frame-index rows with the same key.
    KeyCollision,
    /// A caption line whose `start#end` are not seconds with the end after the start.
    BadCaption,
    /// A caption over 4,000 characters or a line over 64 KiB.
    LongCaption,
    /// A caption file byte that is not UTF-8.
    CaptionEncoding,
    /// A caption file that cannot be read.
    CaptionUnreadable,
    /// A joint-position capture whose bone lengths are not constant.
    IkResidual,
    /// An AMASS file taken at HumanML3D's stride whose rate is not 20 fps.
    AmassEffectiveRate,
    /// A segment ending past its capture (clamped).
    EndClamped,
    /// A segment without text.
    EmptyText,
    /// The same span annotated twice.
    DuplicateAnnotation,
    /// A capture whose length differs from its annotation's duration.
    DurationMismatch,
    /// An annotation naming no capture the globs found.
    AnnotationWithoutCapture,
    /// An AMASS `shape.npz` or `*_stagei.npz` the globs matched (skipped).
    AmassNotAMotion,
    /// How many notes of another kind a list leaves out.
    NotesNotListed,
}

impl NoteKind {
    /// The kind as written in `build-report.json` (`docs/formats.md`).
    pub fn as_str(self) -> &'static str {
        match self {
            NoteKind::BadTimes => "bad_times",
            NoteKind::IntegerTimes => "integer_times",
            NoteKind::NullLabel => "null_label",
            NoteKind::Unsorted => "unsorted",
            NoteKind::EndPastDuration => "end_past_duration",
            NoteKind::NoFeatP => "no_feat_p",
            NoteKind::NoLabels => "no_labels",
            NoteKind::SeveralAnnotations => "several_annotations",
            NoteKind::UnmatchedAnnotation => "unmatched_annotation",
            NoteKind::UnknownColumn => "unknown_column",
            NoteKind::EventBeforeInstruction => "event_before_instruction",
            NoteKind::SecondGrasp => "second_grasp",
            NoteKind::BadRow => "bad_row",
            NoteKind::NoCaption => "no_caption",
            NoteKind::KeyCollision => "key_collision",
            NoteKind::BadCaption => "bad_caption",
            NoteKind::LongCaption => "long_caption",
            NoteKind::CaptionEncoding => "caption_encoding",
            NoteKind::CaptionUnreadable => "caption_unreadable",
            NoteKind::IkResidual => "ik_residual",
            NoteKind::AmassEffectiveRate => "amass_effective_rate",
            NoteKind::EndClamped => "end_clamped",
            NoteKind::EmptyText => "empty_text",
            NoteKind::DuplicateAnnotation => "duplicate_annotation",
            NoteKind::DurationMismatch => "duration_mismatch",
            NoteKind::AnnotationWithoutCapture => "annotation_without_capture",
            NoteKind::AmassNotAMotion => "amass_not_a_motion",
            NoteKind::NotesNotListed => "notes_not_listed",
        }
    }
}

impl motionforge_core::base::Named for NoteKind {
    const ALL: &'static [NoteKind] = &[
        NoteKind::BadTimes,
        NoteKind::IntegerTimes,
        NoteKind::NullLabel,
        NoteKind::Unsorted,
        NoteKind::EndPastDuration,
        NoteKind::NoFeatP,
        NoteKind::NoLabels,
        NoteKind::SeveralAnnotations,
        NoteKind::UnmatchedAnnotation,
        NoteKind::UnknownColumn,
        NoteKind::EventBeforeInstruction,
        NoteKind::SecondGrasp,
        NoteKind::BadRow,
        NoteKind::NoCaption,
        NoteKind::KeyCollision,
        NoteKind::BadCaption,
        NoteKind::LongCaption,
        NoteKind::CaptionEncoding,
        NoteKind::CaptionUnreadable,
        NoteKind::IkResidual,
        NoteKind::AmassEffectiveRate,
        NoteKind::EndClamped,
        NoteKind::EmptyText,
        NoteKind::DuplicateAnnotation,
        NoteKind::DurationMismatch,
        NoteKind::AnnotationWithoutCapture,
        NoteKind::AmassNotAMotion,
        NoteKind::NotesNotListed,
    ];

    fn name(self) -> &'static str {
        self.as_str()
    }
}

impl std::fmt::Display for NoteKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl PartialEq<str> for NoteKind {
    fn eq(&self, other: &str) -> bool {
        self.as_str() == other
    }
}

impl PartialEq<&str> for NoteKind {
    fn eq(&self, other: &&str) -> bool {
        self.as_str() == *other
    }
}

/// By name, so notes sort as they did when their kinds were strings.
impl Ord for NoteKind {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.as_str().cmp(other.as_str())
    }
}

impl PartialOrd for NoteKind {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// As its name: the JSON and the stage cache's bytes are those of the string it replaces.
impl Serialize for NoteKind {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

impl<'de> Deserialize<'de> for NoteKind {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = std::borrow::Cow::<'de, str>::deserialize(deserializer)?;
        <NoteKind as motionforge_core::base::Named>::from_name(&name)
            .ok_or_else(|| serde::de::Error::custom(format!("unknown note kind `{name}`")))
    }
}

/// Notes of one kind listed in a build report; the rest are counted in one [`NOT_LISTED`] note,
/// so a file of a million bad rows gives a report of a few hundred lines, not a million.
pub const NOTES_PER_KIND: usize = 200;

/// Kind of the note that counts the notes of another kind left out of a list.
pub const NOT_LISTED: NoteKind = NoteKind::NotesNotListed;

/// `notes` with at most `limit` of each kind, in their order; for each kind with more, one
/// [`NOT_LISTED`] note at the end says how many more there were.
pub fn cap_per_kind(notes: Vec<Note>, limit: usize) -> Vec<Note> {
    let mut seen: std::collections::BTreeMap<NoteKind, usize> = std::collections::BTreeMap::new();
    let mut kept = Vec::with_capacity(notes.len().min(limit.saturating_mul(8)));
    for note in notes {
        let n = seen.entry(note.kind).or_insert(0);
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
#[error("{file}{}: {fault}", line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct AnnotationError {
    /// The annotation file.
    pub file: String,
    /// 1-based line, where known.
    pub line: Option<u64>,
    /// What was expected and found.
    pub fault: AnnotationFault,
}

/// What makes an annotation file unreadable as a whole. Texts quoted from the file (a header,
/// a JSON value, a column name) are kept as they are: they are data, not kinds of fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AnnotationFault {
    /// The file is not JSON.
    #[error("not valid JSON: {0}")]
    Json(
        /// serde_json's message (kept as text: it names the line and column, and
        /// `serde_json::Error` is not `Clone`).
        String,
    ),
    /// An event log with no header line.
    #[error("empty file: expected a header naming `instruction` and `frame` or `time`")]
    EmptyEventLog,
    /// An event log's header line does not split into fields.
    #[error("header: {0}")]
    EventLogHeader(CsvFault),
    /// An event log's header names a column twice.
    #[error("header names column `{0}` twice")]
    DuplicateColumn(&'static str),
    /// An event log's header has no `instruction` column.
    #[error(
        "header has no `instruction` column (expected columns among {}), found `{header}`",
        EVENT_COLUMNS.join(", ")
    )]
    NoInstructionColumn {
        /// The header line, trimmed.
        header: String,
    },
    /// An event log's header has neither `frame` nor `time`.
    #[error("header has neither a `frame` nor a `time` column, found `{header}`")]
    NoTimeColumn {
        /// The header line, trimmed.
        header: String,
    },
    /// A CSV row does not split into fields.
    #[error("{0}")]
    Csv(CsvFault),
    /// A CSV row with more or fewer fields than the header.
    #[error("expected {expected} columns as in the header, found {found}")]
    ColumnCount {
        /// The header's columns.
        expected: usize,
        /// The row's fields.
        found: usize,
    },
    /// A JSON event log that is neither an array nor an object with an `events` array.
    #[error("expected an array of events or an object with an `events` array")]
    NotEvents,
    /// A JSON event log whose `capture` is not a string.
    #[error("`capture` must be a string, found {found}")]
    CaptureNotText {
        /// The value, as JSON.
        found: String,
    },
    /// A JSON event that is not an object.
    #[error("event {event}: expected an object, found {found}")]
    EventNotObject {
        /// The event's 1-based position.
        event: usize,
        /// The event, as JSON.
        found: String,
    },
    /// A JSON event's known key whose value is neither a string nor a number.
    #[error("event {event}: `{key}` must be a string or a number, found {found}")]
    CellNotText {
        /// The event's 1-based position.
        event: usize,
        /// The key.
        key: String,
        /// The value, as JSON.
        found: String,
    },
    /// An event-log row that cannot be used.
    #[error("row {row}: {fault}")]
    Row {
        /// The row's 1-based number (data rows, or events).
        row: usize,
        /// What is wrong with it.
        fault: RowFault,
    },
    /// A frame index with no header line.
    #[error("empty file: expected the header `{}`", INDEX_COLUMNS.join(","))]
    EmptyIndex,
    /// A frame index's header line does not split into fields.
    #[error("expected the header `{columns}`: {0}", columns = INDEX_COLUMNS.join(","))]
    IndexHeader(CsvFault),
    /// A frame index's header lacks one of the columns.
    #[error(
        "expected the header `{}`, found `{header}` (no `{column}` column)",
        INDEX_COLUMNS.join(",")
    )]
    IndexColumnMissing {
        /// The header line, trimmed.
        header: String,
        /// The missing column.
        column: &'static str,
    },
    /// A frame index's header names a column twice.
    #[error("expected the header `{}`: `{column}` appears twice", INDEX_COLUMNS.join(","))]
    IndexColumnTwice {
        /// The repeated column.
        column: &'static str,
    },
    /// A frame index's header has other columns besides the four.
    #[error(
        "expected the header `{}`, found {found} columns: `{header}`",
        INDEX_COLUMNS.join(",")
    )]
    IndexColumnCount {
        /// Columns in the header.
        found: usize,
        /// The header line, trimmed.
        header: String,
    },
    /// A BABEL file whose root (or `records`) is not an object.
    #[error("expected a JSON object of BABEL records keyed by sequence id")]
    NotBabel,
}

/// The key a capture is found by: its file stem, after the source's path mapping.
pub fn stem_of(path: &str) -> String {
    let name = path.rsplit(['/', '\\']).next().unwrap_or(path);
    let stem = name.split_once('.').map(|(s, _)| s).unwrap_or(name);
    stem.to_string()
}
