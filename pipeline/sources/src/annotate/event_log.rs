//! LINGO's Motion Planner event log: timestamped rows (`frame` or `time` in seconds) of
//! instructions, grasps and releases, as CSV with a header or as JSON. Instruction events become
//! spans that last until the next instruction starting strictly later (the last one until the end
//! of the capture); instructions starting at the same time are concurrent and overlap. Grasp events
//! set the grasp time (and hand) of the instruction active at that moment.
//!
//! Event logs are stricter than the segment formats: one unreadable row shifts its neighbours'
//! ends, so a bad row is an error naming its line, not a note.

use std::collections::BTreeMap;

use serde_json::Value;

use super::frame_index::{csv_lines, split_csv_line};
use super::span::{
    AnnotationError, AnnotationFault, CaptureAnnotation, Hand, Note, NoteKind, Span, Time, stem_of,
};

/// How an event log is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventLogFormat {
    /// CSV with a header naming the columns (any order).
    Csv,
    /// JSON: an array of event objects, or `{"capture": "...", "events": [...]}`.
    Json,
}

/// The columns (CSV) or keys (JSON) an event log may have.
pub const EVENT_COLUMNS: [&str; 8] = [
    "frame",
    "time",
    "instruction",
    "motion_type",
    "hand",
    "object",
    "event",
    "capture",
];

/// Two starts closer than this (seconds) are the same time.
const SAME_TIME: f64 = 1e-9;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Instruction,
    Grasp,
    Release,
}

impl Kind {
    fn as_str(self) -> &'static str {
        match self {
            Kind::Instruction => "instruction",
            Kind::Grasp => "grasp",
            Kind::Release => "release",
        }
    }
}

/// One row as written: cells by column name, `None` for absent or empty.
struct RawRow {
    /// 1-based data row number (the span id is `row {n}`).
    n: usize,
    /// 1-based line in the file, where known.
    line: Option<u64>,
    cells: BTreeMap<&'static str, String>,
}

/// One row, checked.
struct Event {
    n: usize,
    at: Time,
    secs: f64,
    kind: Kind,
    instruction: String,
    motion_type: Option<String>,
    hand: Option<Hand>,
    object: Option<String>,
    capture: String,
}

/// Reads an event log into per-capture annotations. The capture key is the row's `capture`
/// (or, in JSON, the wrapper's `capture`), else `stem_of(file)`. `fps` places frame rows on the
/// same timeline as second rows; frames are kept as `Time::Frame { frame, fps }`.
pub fn read_event_log(
    text: &str,
    format: EventLogFormat,
    file: &str,
    fps: f64,
) -> Result<BTreeMap<String, CaptureAnnotation>, AnnotationError> {
    let (rows, default_capture, unknown) = match format {
        EventLogFormat::Csv => csv_rows(text, file)?,
        EventLogFormat::Json => json_rows(text, file)?,
    };
    let default_capture = default_capture.unwrap_or_else(|| stem_of(file));
    let mut events = Vec::with_capacity(rows.len());
    for row in rows {
        events.push(check_row(row, file, fps, &default_capture)?);
    }
    let mut by_capture: BTreeMap<String, Vec<Event>> = BTreeMap::new();
    for e in events {
        by_capture.entry(e.capture.clone()).or_default().push(e);
    }
    let mut out = BTreeMap::new();
    for (capture, events) in by_capture {
        let mut annotation = build(&capture, events, file);
        for name in &unknown {
            annotation.notes.push(Note::new(
                NoteKind::UnknownColumn,
                format!(
                    "{file}: column `{name}` is not one of {} (ignored)",
                    EVENT_COLUMNS.join(", ")
                ),
            ));
        }
        out.insert(capture, annotation);
    }
    Ok(out)
}

fn error(file: &str, line: Option<u64>, fault: AnnotationFault) -> AnnotationError {
    AnnotationError {
        file: file.to_string(),
        line,
        fault,
    }
}

/// What is wrong with one event-log row (or JSON event). Cells are quoted as written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RowFault {
    /// A frame below 0.
    #[error("frame {frame} is negative")]
    NegativeFrame {
        /// The frame.
        frame: i64,
    },
    /// A frame cell that is not a whole number.
    #[error("frame `{raw}`: expected a whole frame number")]
    FrameNotWhole {
        /// The cell.
        raw: String,
    },
    /// A time that is negative or not finite.
    #[error("time `{raw}`: expected a finite, non-negative number of seconds")]
    TimeOutOfRange {
        /// The cell.
        raw: String,
    },
    /// A time cell that is not a number.
    #[error("time `{raw}`: expected a number of seconds")]
    TimeNotNumber {
        /// The cell.
        raw: String,
    },
    /// A frame row read at a rate that is not positive.
    #[error("frame rows need a positive frame rate to be placed in time, got {fps}")]
    NoFrameRate {
        /// The rate given.
        fps: f64,
    },
    /// Frame and time both given, more than half a frame apart.
    #[error("frame {frame} ({secs} s at {fps} fps) and time {time} s disagree; give one of them")]
    FrameTimeDisagree {
        /// The frame.
        frame: i64,
        /// The frame in seconds.
        secs: f64,
        /// The rate.
        fps: f64,
        /// The time given.
        time: f64,
    },
    /// Neither frame nor time.
    #[error("has neither a frame nor a time: expected one of them")]
    NoTime,
    /// An `event` cell of an unknown kind.
    #[error("event `{event}`: expected `instruction`, `grasp` or `release`")]
    UnknownEvent {
        /// The cell, lowercased.
        event: String,
    },
    /// A `hand` cell that names no hand.
    #[error("hand `{raw}`: expected `left`, `right` or `both`")]
    UnknownHand {
        /// The cell.
        raw: String,
    },
    /// An instruction event without its text.
    #[error("instruction event with no instruction text: expected the instruction")]
    NoInstruction,
}

/// The name of a known column, as a `'static` key.
fn known(name: &str) -> Option<&'static str> {
    EVENT_COLUMNS.iter().copied().find(|c| *c == name)
}

type Rows = (Vec<RawRow>, Option<String>, Vec<String>);

fn csv_rows(text: &str, file: &str) -> Result<Rows, AnnotationError> {
    let mut lines = csv_lines(text);
    let Some((header_line, header)) = lines.next() else {
        return Err(error(file, None, AnnotationFault::EmptyEventLog));
    };
    let names = split_csv_line(header)
        .map_err(|e| error(file, Some(header_line), AnnotationFault::EventLogHeader(e)))?;
    let mut columns: Vec<Option<&'static str>> = Vec::with_capacity(names.len());
    let mut unknown = Vec::new();
    for name in &names {
        let name = name.trim().to_ascii_lowercase();
        match known(&name) {
            Some(c) if columns.contains(&Some(c)) => {
                return Err(error(
                    file,
                    Some(header_line),
                    AnnotationFault::DuplicateColumn(c),
                ));
            }
            Some(c) => columns.push(Some(c)),
            None => {
                if !name.is_empty() {
                    unknown.push(name);
                }
                columns.push(None);
            }
        }
    }
    if !columns.contains(&Some("instruction")) {
        return Err(error(
            file,
            Some(header_line),
            AnnotationFault::NoInstructionColumn {
                header: header.trim().to_string(),
            },
        ));
    }
    if !columns.contains(&Some("frame")) && !columns.contains(&Some("time")) {
        return Err(error(
            file,
            Some(header_line),
            AnnotationFault::NoTimeColumn {
                header: header.trim().to_string(),
            },
        ));
    }
    let mut rows = Vec::new();
    for (n, (line, text)) in lines.enumerate() {
        let cells =
            split_csv_line(text).map_err(|e| error(file, Some(line), AnnotationFault::Csv(e)))?;
        if cells.len() != columns.len() {
            return Err(error(
                file,
                Some(line),
                AnnotationFault::ColumnCount {
                    expected: columns.len(),
                    found: cells.len(),
                },
            ));
        }
        let cells = columns
            .iter()
            .zip(cells)
            .filter_map(|(c, v)| {
                let v = v.trim();
                c.filter(|_| !v.is_empty()).map(|c| (c, v.to_string()))
            })
            .collect();
        rows.push(RawRow {
            n: n + 1,
            line: Some(line),
            cells,
        });
    }
    Ok((rows, None, unknown))
}

fn json_rows(text: &str, file: &str) -> Result<Rows, AnnotationError> {
    let root: Value = serde_json::from_str(text).map_err(|e| {
        error(
            file,
            Some(e.line() as u64),
            AnnotationFault::Json(e.to_string()),
        )
    })?;
    let (events, capture, wrapped) = match &root {
        Value::Array(events) => (events, None, false),
        Value::Object(map) => {
            let Some(events) = map.get("events").and_then(Value::as_array) else {
                return Err(error(file, None, AnnotationFault::NotEvents));
            };
            let capture = match map.get("capture") {
                None | Some(Value::Null) => None,
                Some(Value::String(s)) if s.trim().is_empty() => None,
                Some(Value::String(s)) => Some(s.trim().to_string()),
                Some(other) => {
                    return Err(error(
                        file,
                        None,
                        AnnotationFault::CaptureNotText {
                            found: other.to_string(),
                        },
                    ));
                }
            };
            (events, capture, true)
        }
        _ => {
            return Err(error(file, None, AnnotationFault::NotEvents));
        }
    };
    let lines = element_lines(text, wrapped);
    let lines = (lines.len() == events.len()).then_some(lines);
    let mut rows = Vec::with_capacity(events.len());
    let mut unknown: Vec<String> = Vec::new();
    for (i, event) in events.iter().enumerate() {
        let line = lines.as_ref().and_then(|l| l.get(i).copied());
        let Some(map) = event.as_object() else {
            return Err(error(
                file,
                line,
                AnnotationFault::EventNotObject {
                    event: i + 1,
                    found: event.to_string(),
                },
            ));
        };
        let mut cells = BTreeMap::new();
        for (key, value) in map {
            let Some(column) = known(key) else {
                if !unknown.contains(key) {
                    unknown.push(key.clone());
                }
                continue;
            };
            let cell = match value {
                Value::Null => continue,
                Value::String(s) => s.trim().to_string(),
                Value::Number(x) => x.to_string(),
                other => {
                    return Err(error(
                        file,
                        line,
                        AnnotationFault::CellNotText {
                            event: i + 1,
                            key: key.clone(),
                            found: other.to_string(),
                        },
                    ));
                }
            };
            if !cell.is_empty() {
                cells.insert(column, cell);
            }
        }
        rows.push(RawRow {
            n: i + 1,
            line,
            cells,
        });
    }
    Ok((rows, capture, unknown))
}

/// 1-based lines where the elements of the events array start: the root array, or (`wrapped`)
/// the array under the root object's `events` key. Run on text serde_json accepted.
fn element_lines(text: &str, wrapped: bool) -> Vec<u64> {
    let bytes = text.as_bytes();
    let target = if wrapped { 2 } else { 1 };
    let mut line = 1u64;
    let mut depth = 0usize;
    let mut in_string = false;
    let mut escaped = false;
    let mut string_start = 0usize;
    let mut last_key: Option<(usize, usize)> = None;
    let mut after_events_key = false;
    let mut in_target = false;
    let mut expect_element = false;
    let mut lines = Vec::new();
    for (i, &b) in bytes.iter().enumerate() {
        if b == b'\n' {
            line += 1;
        }
        if in_string {
            if escaped {
                escaped = false;
            } else if b == b'\\' {
                escaped = true;
            } else if b == b'"' {
                in_string = false;
                if depth == 1 {
                    last_key = Some((string_start, i));
                }
            }
            continue;
        }
        if b.is_ascii_whitespace() {
            continue;
        }
        if in_target && depth == target && expect_element && b != b']' {
            lines.push(line);
            expect_element = false;
        }
        let value_of_events = std::mem::take(&mut after_events_key);
        match b {
            b'"' => {
                in_string = true;
                string_start = i + 1;
            }
            b':' if wrapped && depth == 1 => {
                after_events_key = last_key
                    .and_then(|(s, e)| text.get(s..e))
                    .is_some_and(|k| k == "events");
            }
            b'[' => {
                depth += 1;
                if depth == target && (!wrapped || value_of_events) {
                    // serde_json keeps the last of duplicate keys; so do we.
                    lines.clear();
                    in_target = true;
                    expect_element = true;
                }
            }
            b'{' => depth += 1,
            b']' | b'}' => {
                if depth == target {
                    in_target = false;
                }
                depth = depth.saturating_sub(1);
            }
            b',' if in_target && depth == target => expect_element = true,
            _ => {}
        }
    }
    lines
}

fn check_row(
    row: RawRow,
    file: &str,
    fps: f64,
    default_capture: &str,
) -> Result<Event, AnnotationError> {
    let n = row.n;
    let fail = |fault: RowFault| error(file, row.line, AnnotationFault::Row { row: n, fault });
    let cell = |name: &str| row.cells.get(name).map(String::as_str);
    let frame = match cell("frame") {
        None => None,
        Some(raw) => match raw.parse::<i64>() {
            Ok(f) if f >= 0 => Some(f),
            Ok(frame) => return Err(fail(RowFault::NegativeFrame { frame })),
            Err(_) => {
                return Err(fail(RowFault::FrameNotWhole {
                    raw: raw.to_string(),
                }));
            }
        },
    };
    let time = match cell("time") {
        None => None,
        Some(raw) => match raw.parse::<f64>() {
            Ok(t) if t.is_finite() && t >= 0.0 => Some(t),
            Ok(_) => {
                return Err(fail(RowFault::TimeOutOfRange {
                    raw: raw.to_string(),
                }));
            }
            Err(_) => {
                return Err(fail(RowFault::TimeNotNumber {
                    raw: raw.to_string(),
                }));
            }
        },
    };
    if frame.is_some() && !(fps.is_finite() && fps > 0.0) {
        return Err(fail(RowFault::NoFrameRate { fps }));
    }
    let (at, secs) = match (frame, time) {
        (Some(f), None) => (Time::Frame { frame: f, fps }, f as f64 / fps),
        (None, Some(t)) => (Time::Seconds(t), t),
        (Some(f), Some(t)) => {
            let secs = f as f64 / fps;
            if (secs - t).abs() > 0.5 / fps {
                return Err(fail(RowFault::FrameTimeDisagree {
                    frame: f,
                    secs,
                    fps,
                    time: t,
                }));
            }
            (Time::Frame { frame: f, fps }, secs)
        }
        (None, None) => {
            return Err(fail(RowFault::NoTime));
        }
    };
    let kind = match cell("event").map(str::to_ascii_lowercase).as_deref() {
        None | Some("instruction") => Kind::Instruction,
        Some("grasp") => Kind::Grasp,
        Some("release") => Kind::Release,
        Some(other) => {
            return Err(fail(RowFault::UnknownEvent {
                event: other.to_string(),
            }));
        }
    };
    let hand = match cell("hand") {
        None => None,
        Some(raw) => match Hand::parse(raw) {
            Some(h) => Some(h),
            None => {
                return Err(fail(RowFault::UnknownHand {
                    raw: raw.to_string(),
                }));
            }
        },
    };
    let instruction = cell("instruction").unwrap_or("").to_string();
    if kind == Kind::Instruction && instruction.is_empty() {
        return Err(fail(RowFault::NoInstruction));
    }
    Ok(Event {
        n,
        at,
        secs,
        kind,
        instruction,
        motion_type: cell("motion_type").map(str::to_string),
        hand,
        object: cell("object").map(str::to_string),
        capture: cell("capture").unwrap_or(default_capture).to_string(),
    })
}

fn build(capture: &str, mut events: Vec<Event>, file: &str) -> CaptureAnnotation {
    let mut notes = Vec::new();
    if !events.windows(2).all(|w| w[0].secs <= w[1].secs) {
        notes.push(Note::new(
            NoteKind::Unsorted,
            format!("{file}: events of `{capture}` are not in time order (sorted on read)"),
        ));
    }
    // Stable: events at the same time keep their order in the file.
    events.sort_by(|a, b| a.secs.total_cmp(&b.secs));
    let instructions: Vec<&Event> = events
        .iter()
        .filter(|e| e.kind == Kind::Instruction)
        .collect();
    let mut spans: Vec<Span> = instructions
        .iter()
        .map(|e| {
            let end = instructions
                .iter()
                .find(|next| next.secs > e.secs + SAME_TIME)
                .map_or(Time::End, |next| next.at);
            Span {
                start: e.at,
                end,
                raw_text: e.instruction.clone(),
                label: e
                    .motion_type
                    .clone()
                    .unwrap_or_else(|| e.instruction.clone()),
                categories: Vec::new(),
                motion_type: e.motion_type.clone(),
                hand: e.hand,
                object: e.object.clone(),
                grasp: None,
                id: format!("row {}", e.n),
                alternatives: Vec::new(),
            }
        })
        .collect();
    for e in events.iter().filter(|e| e.kind != Kind::Instruction) {
        // The active group: instructions starting at the latest start at or before the event.
        let Some(latest) = instructions
            .iter()
            .filter(|i| i.secs <= e.secs + SAME_TIME)
            .map(|i| i.secs)
            .next_back()
        else {
            notes.push(Note::new(
                NoteKind::EventBeforeInstruction,
                format!(
                    "{file}: row {} ({} at {:?}) comes before the first instruction of \
                     `{capture}`",
                    e.n,
                    e.kind.as_str(),
                    e.at
                ),
            ));
            continue;
        };
        if e.kind == Kind::Release {
            continue;
        }
        let group: Vec<usize> = instructions
            .iter()
            .enumerate()
            .filter(|(_, i)| (i.secs - latest).abs() <= SAME_TIME)
            .map(|(k, _)| k)
            .collect();
        let chosen = group
            .iter()
            .copied()
            .find(|&k| e.hand.is_some() && spans.get(k).is_some_and(|s| s.hand == e.hand))
            .or_else(|| group.first().copied());
        let Some(span) = chosen.and_then(|k| spans.get_mut(k)) else {
            continue;
        };
        if span.grasp.is_some() {
            notes.push(Note::new(
                NoteKind::SecondGrasp,
                format!(
                    "{file}: row {} grasps again during `{}` ({}); the first grasp is kept",
                    e.n, span.raw_text, span.id
                ),
            ));
            continue;
        }
        span.grasp = Some(e.at);
        if span.hand.is_none() {
            span.hand = e.hand;
        }
        if span.object.is_none() {
            span.object = e.object.clone();
        }
    }
    CaptureAnnotation {
        spans,
        simultaneous: true,
        duration: None,
        origin: format!("{file}#{capture}"),
        notes,
        ..CaptureAnnotation::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn csv(text: &str) -> String {
        read_event_log(text, EventLogFormat::Csv, "log.csv", 30.0)
            .unwrap_err()
            .to_string()
    }

    fn json(text: &str) -> String {
        read_event_log(text, EventLogFormat::Json, "log.json", 30.0)
            .unwrap_err()
            .to_string()
    }

    /// The texts of every CSV event-log fault, as builds show them: they must not change.
    #[test]
    fn every_csv_fault_reads_as_it_always_has() {
        let cases = [
            (
                "",
                "log.csv: empty file: expected a header naming `instruction` and `frame` or `time`",
            ),
            (
                "frame,\"instruction\"x\n",
                "log.csv:1: header: field 2: expected `,` or the line end after the closing quote, found `x`",
            ),
            (
                "frame,Frame,instruction\n",
                "log.csv:1: header names column `frame` twice",
            ),
            (
                "frame,hand\n",
                "log.csv:1: header has no `instruction` column (expected columns among frame, time, instruction, motion_type, hand, object, event, capture), found `frame,hand`",
            ),
            (
                "instruction,hand \n",
                "log.csv:1: header has neither a `frame` nor a `time` column, found `instruction,hand`",
            ),
            (
                "frame,instruction\n\n3,\"walk\n",
                "log.csv:3: field 2 opens a double quote that is not closed on this line",
            ),
            (
                "frame,instruction\n3,wa\"lk\n",
                "log.csv:2: field 2: a double quote inside an unquoted field (quote the whole field and double the quote: `\"\"`)",
            ),
            (
                "frame,instruction\n3,walk,x\n",
                "log.csv:2: expected 2 columns as in the header, found 3",
            ),
            (
                "frame,instruction\n1,a\n-3,walk\n",
                "log.csv:3: row 2: frame -3 is negative",
            ),
            (
                "frame,instruction\n3.5,walk\n",
                "log.csv:2: row 1: frame `3.5`: expected a whole frame number",
            ),
            (
                "time,instruction\ninf,walk\n",
                "log.csv:2: row 1: time `inf`: expected a finite, non-negative number of seconds",
            ),
            (
                "time,instruction\nsoon,walk\n",
                "log.csv:2: row 1: time `soon`: expected a number of seconds",
            ),
            (
                "frame,time,instruction\n30,2.5,walk\n",
                "log.csv:2: row 1: frame 30 (1 s at 30 fps) and time 2.5 s disagree; give one of them",
            ),
            (
                "frame,time,instruction\n,,walk\n",
                "log.csv:2: row 1: has neither a frame nor a time: expected one of them",
            ),
            (
                "frame,instruction,event\n3,walk,jump\n",
                "log.csv:2: row 1: event `jump`: expected `instruction`, `grasp` or `release`",
            ),
            (
                "frame,instruction,hand\n3,walk,middle\n",
                "log.csv:2: row 1: hand `middle`: expected `left`, `right` or `both`",
            ),
            (
                "frame,instruction\n3,\n",
                "log.csv:2: row 1: instruction event with no instruction text: expected the instruction",
            ),
        ];
        for (text, want) in cases {
            assert_eq!(csv(text), want, "{text}");
        }
        let err = read_event_log("frame,instruction\n3,walk\n", EventLogFormat::Csv, "l", 0.0)
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "l:2: row 1: frame rows need a positive frame rate to be placed in time, got 0"
        );
    }

    /// The texts of the JSON event-log faults: they must not change.
    #[test]
    fn every_json_fault_reads_as_it_always_has() {
        let cases = [
            (
                "[1,",
                "log.json:1: not valid JSON: EOF while parsing a value at line 1 column 3",
            ),
            (
                "3",
                "log.json: expected an array of events or an object with an `events` array",
            ),
            (
                "{\"events\": 3}",
                "log.json: expected an array of events or an object with an `events` array",
            ),
            (
                "{\"capture\": 3, \"events\": []}",
                "log.json: `capture` must be a string, found 3",
            ),
            (
                "[\n{\"frame\": 1, \"instruction\": \"a\"},\n[1]\n]",
                "log.json:3: event 2: expected an object, found [1]",
            ),
            (
                "[{\"frame\": [1]}]",
                "log.json:1: event 1: `frame` must be a string or a number, found [1]",
            ),
            (
                "[{\"frame\": -1, \"instruction\": \"a\"}]",
                "log.json:1: row 1: frame -1 is negative",
            ),
        ];
        for (text, want) in cases {
            assert_eq!(json(text), want, "{text}");
        }
        let err = read_event_log(
            "frame,instruction\n1,a\n-3,walk\n",
            EventLogFormat::Csv,
            "l",
            30.0,
        )
        .unwrap_err();
        assert_eq!(err.line, Some(3));
        assert_eq!(
            err.fault,
            AnnotationFault::Row {
                row: 2,
                fault: RowFault::NegativeFrame { frame: -3 }
            }
        );
    }
}
