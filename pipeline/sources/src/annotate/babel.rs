//! BABEL JSON (`frame_ann.labels[]` with `start_t`/`end_t` in seconds, `seq_ann` for the whole
//! sequence; the extra files' `frame_anns` and `seq_anns` lists of several annotators' work: the
//! first annotation's spans are cut, and the other annotators' texts become further captions of the
//! spans they cover). Accepts the real quirks: integer times, unsorted labels, `end_t` past the duration,
//! `null` labels, overlapping segments, and the wrapped record shapes of saved notebook outputs.

use std::collections::BTreeMap;

use serde_json::Value;

use super::span::{
    AnnotationError, AnnotationFault, CaptureAnnotation, Note, NoteKind, Span, Time,
};

/// One BABEL sequence record, keyed by its AMASS feature path.
#[derive(Debug, Clone, PartialEq)]
pub struct BabelRecord {
    /// BABEL sequence id.
    pub sid: String,
    /// AMASS path (`CMU/CMU/141/141_05_poses.npz`), when the record has one.
    pub feat_p: Option<String>,
    /// The capture's spans and notes.
    pub annotation: CaptureAnnotation,
}

fn number(v: &Value) -> Option<f64> {
    v.as_f64().filter(|x| x.is_finite())
}

fn string(v: Option<&Value>) -> Option<String> {
    v.and_then(Value::as_str).map(str::to_string)
}

/// Reads a BABEL JSON file: `{sid: record}` as released, or `{"records": {sid: {"record": ...}}}`.
/// Records that cannot be used are returned as notes in a record without spans, never dropped
/// silently.
pub fn read_babel(text: &str, file: &str) -> Result<Vec<BabelRecord>, AnnotationError> {
    let root: Value = serde_json::from_str(text).map_err(|e| AnnotationError {
        file: file.to_string(),
        line: Some(e.line() as u64),
        fault: AnnotationFault::Json(e.to_string()),
    })?;
    let records = root.get("records").unwrap_or(&root);
    let Some(map) = records.as_object() else {
        return Err(AnnotationError {
            file: file.to_string(),
            line: None,
            fault: AnnotationFault::NotBabel,
        });
    };
    let mut out = Vec::new();
    for (sid, value) in map {
        if sid.starts_with('_') {
            continue;
        }
        let record = value.get("record").unwrap_or(value);
        out.push(read_record(sid, record, file));
    }
    Ok(out)
}

fn read_record(sid: &str, record: &Value, file: &str) -> BabelRecord {
    let mut read = RecordReader {
        sid,
        spans: Vec::new(),
        notes: Vec::new(),
        nulls: 0,
    };
    let feat_p = string(record.get("feat_p"));
    let duration = record.get("dur").and_then(number);
    // BABEL's extra files hold several annotators' work per sequence, as lists `frame_anns` and
    // `seq_anns`; the main files hold one `frame_ann` and `seq_ann`. The first annotation's spans
    // are the clips; the others' texts are further captions of the spans they cover (as
    // HumanML3D keeps about three captions per clip), so no annotator's text is lost and no
    // span is cut twice.
    let frame_anns = annotations(record, "frame_ann", "frame_anns");
    let seq_anns = annotations(record, "seq_ann", "seq_anns");
    fn labels_of<'v>(a: &&'v Value) -> Option<&'v Vec<Value>> {
        a.get("labels").and_then(Value::as_array)
    }
    if let Some(labels) = frame_anns.first().and_then(labels_of) {
        read.frame_labels(labels);
        read.several(
            &frame_anns,
            "frame_anns",
            duration,
            RecordReader::frame_labels,
        );
    } else if let Some(rows) = record
        .get("frame_labels_raw_start_end")
        .and_then(Value::as_array)
    {
        read.notebook_rows(rows);
    } else if let Some(seq) = seq_anns.first().and_then(labels_of) {
        read.sequence_labels(seq);
        read.several(
            &seq_anns,
            "seq_anns",
            duration,
            RecordReader::sequence_labels,
        );
    } else {
        read.notes.push(Note::new(
            NoteKind::NoLabels,
            format!("sid {sid}: record has neither frame_ann nor seq_ann labels"),
        ));
    }
    read.finish(duration);
    let RecordReader {
        spans, mut notes, ..
    } = read;
    if feat_p.is_none() {
        notes.push(Note::new(
            NoteKind::NoFeatP,
            format!("sid {sid}: record has no feat_p; it cannot be matched to a capture"),
        ));
    }
    BabelRecord {
        sid: sid.to_string(),
        feat_p,
        annotation: CaptureAnnotation {
            spans,
            simultaneous: true,
            duration,
            origin: format!("{file}#{sid}"),
            notes,
            attributes: BTreeMap::from([("babel_sid".to_string(), sid.to_string())]),
        },
    }
}

/// A span of BABEL text: no motion type, hand, object or grasp yet.
fn babel_span(
    start: Time,
    end: Time,
    raw_text: String,
    label: String,
    categories: Vec<String>,
    id: String,
) -> Span {
    Span {
        start,
        end,
        raw_text,
        label,
        categories,
        motion_type: None,
        hand: None,
        object: None,
        grasp: None,
        id,
        alternatives: Vec::new(),
    }
}

/// One record's spans as they are read, with the notes on them and the labels without text.
struct RecordReader<'a> {
    sid: &'a str,
    spans: Vec<Span>,
    notes: Vec<Note>,
    /// Labels skipped for having no text.
    nulls: usize,
}

impl RecordReader<'_> {
    /// `frame_ann.labels`: one span per label with numeric times and some text.
    fn frame_labels(&mut self, labels: &[Value]) {
        let sid = self.sid;
        for (i, label) in labels.iter().enumerate() {
            let raw = string(label.get("raw_label"));
            let proc = string(label.get("proc_label"));
            let (Some(start), Some(end)) = (
                label.get("start_t").and_then(number),
                label.get("end_t").and_then(number),
            ) else {
                self.notes.push(Note::new(
                    NoteKind::BadTimes,
                    format!("sid {sid}: label {i} has no numeric start_t/end_t"),
                ));
                continue;
            };
            let Some(text) = raw.clone().or_else(|| proc.clone()) else {
                self.nulls += 1;
                continue;
            };
            if label.get("start_t").is_some_and(Value::is_u64)
                || label.get("end_t").is_some_and(Value::is_u64)
            {
                self.notes.push(Note::new(
                    NoteKind::IntegerTimes,
                    format!("sid {sid}: label `{text}` has integer times"),
                ));
            }
            let categories = label
                .get("act_cat")
                .and_then(Value::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(|c| c.as_str().map(str::to_string))
                        .collect()
                })
                .unwrap_or_default();
            self.spans.push(babel_span(
                Time::Seconds(start),
                Time::Seconds(end),
                text.clone(),
                proc.unwrap_or(text),
                categories,
                string(label.get("seg_id")).unwrap_or_else(|| format!("{sid}-{i}")),
            ));
        }
    }

    /// Saved notebook outputs keep frame labels as `[raw_label, start_t, end_t]` rows.
    fn notebook_rows(&mut self, rows: &[Value]) {
        let sid = self.sid;
        for (i, row) in rows.iter().enumerate() {
            let cells = row.as_array();
            let text = cells.and_then(|c| c.first()).and_then(Value::as_str);
            let start = cells.and_then(|c| c.get(1)).and_then(number);
            let end = cells.and_then(|c| c.get(2)).and_then(number);
            match (text, start, end) {
                (Some(t), Some(s), Some(e)) => self.spans.push(babel_span(
                    Time::Seconds(s),
                    Time::Seconds(e),
                    t.to_string(),
                    t.to_string(),
                    Vec::new(),
                    format!("{sid}-{i}"),
                )),
                (None, Some(_), Some(_)) => self.nulls += 1,
                _ => self.notes.push(Note::new(
                    NoteKind::BadTimes,
                    format!("sid {sid}: row {i} is not [label, start, end]"),
                )),
            }
        }
    }

    /// No frame labels: the sequence label covers the whole capture (SINC's `seq`).
    fn sequence_labels(&mut self, seq: &[Value]) {
        let sid = self.sid;
        for (i, label) in seq.iter().enumerate() {
            match string(label.get("raw_label")).or_else(|| string(label.get("proc_label"))) {
                Some(text) => self.spans.push(babel_span(
                    Time::Seconds(0.0),
                    Time::End,
                    text.clone(),
                    string(label.get("proc_label")).unwrap_or(text),
                    Vec::new(),
                    string(label.get("seg_id")).unwrap_or_else(|| format!("{sid}-seq-{i}")),
                )),
                None => self.nulls += 1,
            }
        }
    }

    /// Notes the labels without text, sorts the spans by start time when they are not, and
    /// clamps ends past the record's `duration`, each with a note.
    fn finish(&mut self, duration: Option<f64>) {
        let sid = self.sid;
        let nulls = self.nulls;
        if nulls > 0 {
            self.notes.push(Note::new(
                NoteKind::NullLabel,
                format!("sid {sid}: skipped {nulls} labels with null text"),
            ));
        }
        let sorted = self
            .spans
            .windows(2)
            .all(|w| start_secs(&w[0]) <= start_secs(&w[1]));
        if !sorted {
            self.notes.push(Note::new(
                NoteKind::Unsorted,
                format!("sid {sid}: labels are not in time order (sorted on read)"),
            ));
            self.spans.sort_by(|a, b| {
                start_secs(a)
                    .total_cmp(&start_secs(b))
                    .then(a.id.cmp(&b.id))
            });
        }
        if let Some(dur) = duration {
            for s in &mut self.spans {
                if let Time::Seconds(e) = s.end
                    && e > dur
                {
                    self.notes.push(Note::new(
                        NoteKind::EndPastDuration,
                        format!(
                            "sid {sid}: `{}` ends at {e} s, past the {dur} s duration (clamped)",
                            s.raw_text
                        ),
                    ));
                    s.end = Time::Seconds(dur);
                }
            }
        }
    }
}

/// The record's `single` annotation, else every one of its `several` (BABEL's extra files), in
/// the file's order.
fn annotations<'r>(record: &'r Value, single: &str, several: &str) -> Vec<&'r Value> {
    if let Some(one) = record.get(single).filter(|v| !v.is_null()) {
        return vec![one];
    }
    record
        .get(several)
        .and_then(Value::as_array)
        .map(|list| list.iter().filter(|v| !v.is_null()).collect())
        .unwrap_or_default()
}

/// Temporal overlap from which another annotator's span is the same action as a span of the first
/// annotation: intersection over union of their times.
const SAME_SPAN_IOU: f64 = 0.5;

impl RecordReader<'_> {
    /// The annotations after the first (`list`, read by `read`): each span's text is added to the
    /// first annotation's span it overlaps most, when they overlap by [`SAME_SPAN_IOU`]; a span
    /// overlapping none is noted, not cut.
    fn several(
        &mut self,
        list: &[&Value],
        name: &str,
        duration: Option<f64>,
        read: fn(&mut Self, &[Value]),
    ) {
        let sid = self.sid;
        if list.len() > 1 {
            self.notes.push(Note::new(
                NoteKind::SeveralAnnotations,
                format!(
                    "sid {sid}: {} annotations in `{name}`; the first's spans are cut, the others' texts added to the spans they cover",
                    list.len()
                ),
            ));
        }
        for (k, annotation) in list.iter().enumerate().skip(1) {
            let Some(labels) = annotation.get("labels").and_then(Value::as_array) else {
                continue;
            };
            let mut other = RecordReader {
                sid,
                spans: Vec::new(),
                notes: Vec::new(),
                nulls: 0,
            };
            read(&mut other, labels);
            self.nulls += other.nulls;
            self.notes.append(&mut other.notes);
            for span in other.spans {
                self.add_caption(span, k + 1, duration);
            }
        }
    }

    /// Another annotator's `span` (of annotation `number`) as a further caption of the first
    /// annotation's span it overlaps most.
    fn add_caption(&mut self, span: Span, number: usize, duration: Option<f64>) {
        let interval = |s: &Span| {
            let end = match s.end {
                Time::Seconds(e) => e,
                _ => duration.unwrap_or(f64::MAX),
            };
            (start_secs(s), end)
        };
        let (start, end) = interval(&span);
        let best = self
            .spans
            .iter_mut()
            .map(|s| {
                let (a, b) = interval(s);
                let inter = (end.min(b) - start.max(a)).max(0.0);
                let union = end.max(b) - start.min(a);
                let iou = if union > 0.0 { inter / union } else { 0.0 };
                (iou, s)
            })
            .filter(|(iou, _)| *iou >= SAME_SPAN_IOU)
            .max_by(|x, y| x.0.total_cmp(&y.0));
        match best {
            Some((_, same)) => {
                if same.raw_text != span.raw_text && !same.alternatives.contains(&span.raw_text) {
                    same.alternatives.push(span.raw_text);
                }
            }
            None => self.notes.push(Note::new(
                NoteKind::UnmatchedAnnotation,
                format!(
                    "sid {}: annotation {number}'s `{}` ({start} to {} s) covers no span of the first annotation; not cut",
                    self.sid,
                    span.raw_text,
                    if end == f64::MAX { "the end".to_string() } else { end.to_string() },
                ),
            )),
        }
    }
}

fn start_secs(s: &Span) -> f64 {
    match s.start {
        Time::Seconds(t) => t,
        _ => 0.0,
    }
}
