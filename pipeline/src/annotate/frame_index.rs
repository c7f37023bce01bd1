//! HumanML3D's frame-range index (`index.csv`: `source_path,start_frame,end_frame,new_name`),
//! frames counted at a rate the config states (20 fps for HumanML3D), `-1` as `end_frame` meaning
//! "to the end of the capture". Each row is an independent crop of one source capture; captions
//! live beside the index in `texts/<new_name without .npy>.txt`.
//!
//! Also holds the small CSV line splitter the annotation readers share (no csv crate): fields
//! separated by commas, optionally double-quoted, `""` inside quotes for a literal quote, CRLF or
//! LF line ends. A field cannot contain a line break.

use std::collections::BTreeMap;

use super::span::{AnnotationError, CaptureAnnotation, Note, Span, Time};

/// The header columns, in HumanML3D's order.
pub const INDEX_COLUMNS: [&str; 4] = ["source_path", "start_frame", "end_frame", "new_name"];

/// One data row of a frame-range index.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IndexRow {
    /// Path of the source capture as the index writes it (`./pose_data/CMU/01/01_01_poses.npy`).
    pub source_path: String,
    /// First frame of the crop, at the index's rate.
    pub start_frame: i64,
    /// Frame the crop ends at (exclusive), or `-1` for the end of the capture.
    pub end_frame: i64,
    /// Name of the cropped clip (`004041.npy`); its caption file is named after it.
    pub new_name: String,
    /// 1-based line of the row in the file.
    pub line: u64,
}

/// Splits one CSV line (without its line end) into fields. Double-quoted fields may contain
/// commas and `""` for a quote; spaces around a quoted field are ignored; unquoted fields are kept
/// as written (callers trim). Errors say what was wrong.
pub fn split_csv_line(line: &str) -> Result<Vec<String>, String> {
    let line = line.strip_suffix('\r').unwrap_or(line);
    let mut fields = Vec::new();
    let mut chars = line.chars().peekable();
    loop {
        // One field: skip blanks before a possible opening quote.
        let mut field = String::new();
        let mut lead = String::new();
        while let Some(&c) = chars.peek() {
            if c == ' ' || c == '\t' {
                lead.push(c);
                chars.next();
            } else {
                break;
            }
        }
        if chars.peek() == Some(&'"') {
            chars.next();
            let column = fields.len() + 1;
            loop {
                match chars.next() {
                    Some('"') => {
                        if chars.peek() == Some(&'"') {
                            chars.next();
                            field.push('"');
                        } else {
                            break;
                        }
                    }
                    Some(c) => field.push(c),
                    None => {
                        return Err(format!(
                            "field {column} opens a double quote that is not closed on this line"
                        ));
                    }
                }
            }
            while let Some(&c) = chars.peek() {
                if c == ' ' || c == '\t' {
                    chars.next();
                } else {
                    break;
                }
            }
            match chars.next() {
                None => {
                    fields.push(field);
                    return Ok(fields);
                }
                Some(',') => fields.push(field),
                Some(c) => {
                    return Err(format!(
                        "field {column}: expected `,` or the line end after the closing quote, \
                         found `{c}`"
                    ));
                }
            }
        } else {
            field.push_str(&lead);
            loop {
                match chars.next() {
                    None => {
                        fields.push(field);
                        return Ok(fields);
                    }
                    Some(',') => {
                        fields.push(field);
                        break;
                    }
                    Some('"') => {
                        return Err(format!(
                            "field {}: a double quote inside an unquoted field (quote the whole \
                             field and double the quote: `\"\"`)",
                            fields.len() + 1
                        ));
                    }
                    Some(c) => field.push(c),
                }
            }
        }
    }
}

/// The lines of a CSV text with their 1-based numbers, a leading byte-order mark removed, blank
/// lines skipped.
pub fn csv_lines(text: &str) -> impl Iterator<Item = (u64, &str)> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    text.split('\n')
        .enumerate()
        .map(|(i, l)| (i as u64 + 1, l.strip_suffix('\r').unwrap_or(l)))
        .filter(|(_, l)| !l.trim().is_empty())
}

/// Reads a frame-range index. A missing or wrong header is an error; rows that cannot be used
/// (wrong column count, frames that are not integers, a negative start, an end before the start,
/// empty names) become `bad_row` notes naming their line, and the other rows are kept.
pub fn read_frame_index(
    text: &str,
    file: &str,
) -> Result<(Vec<IndexRow>, Vec<Note>), AnnotationError> {
    let mut lines = csv_lines(text);
    let Some((header_line, header)) = lines.next() else {
        return Err(AnnotationError {
            file: file.to_string(),
            line: None,
            message: format!(
                "empty file: expected the header `{}`",
                INDEX_COLUMNS.join(",")
            ),
        });
    };
    let columns = header_columns(header).map_err(|message| AnnotationError {
        file: file.to_string(),
        line: Some(header_line),
        message,
    })?;
    let mut rows = Vec::new();
    let mut notes = Vec::new();
    for (line, text) in lines {
        match read_row(text, line, &columns) {
            Ok(row) => rows.push(row),
            Err(why) => notes.push(Note::new("bad_row", format!("{file}:{line}: {why}"))),
        }
    }
    Ok((rows, notes))
}

/// Position of each of [`INDEX_COLUMNS`] in the header (any order, names matched without case).
fn header_columns(header: &str) -> Result<[usize; 4], String> {
    let expected = || format!("expected the header `{}`", INDEX_COLUMNS.join(","));
    let names = split_csv_line(header).map_err(|e| format!("{}: {e}", expected()))?;
    let names: Vec<String> = names
        .iter()
        .map(|n| n.trim().to_ascii_lowercase())
        .collect();
    let mut at = [0usize; 4];
    for (slot, want) in at.iter_mut().zip(INDEX_COLUMNS) {
        let found: Vec<usize> = names
            .iter()
            .enumerate()
            .filter(|(_, n)| n.as_str() == want)
            .map(|(i, _)| i)
            .collect();
        match found.as_slice() {
            [i] => *slot = *i,
            [] => {
                return Err(format!(
                    "{}, found `{}` (no `{want}` column)",
                    expected(),
                    header.trim()
                ));
            }
            _ => return Err(format!("{}: `{want}` appears twice", expected())),
        }
    }
    if names.len() != INDEX_COLUMNS.len() {
        return Err(format!(
            "{}, found {} columns: `{}`",
            expected(),
            names.len(),
            header.trim()
        ));
    }
    Ok(at)
}

fn read_row(text: &str, line: u64, columns: &[usize; 4]) -> Result<IndexRow, String> {
    let cells = split_csv_line(text)?;
    if cells.len() != INDEX_COLUMNS.len() {
        return Err(format!(
            "expected {} columns ({}), found {}",
            INDEX_COLUMNS.len(),
            INDEX_COLUMNS.join(","),
            cells.len()
        ));
    }
    let cell = |i: usize| cells.get(columns[i]).map(|c| c.trim()).unwrap_or("");
    let source_path = cell(0);
    let new_name = cell(3);
    if source_path.is_empty() {
        return Err("source_path is empty".into());
    }
    if new_name.is_empty() {
        return Err("new_name is empty".into());
    }
    let frame = |i: usize| {
        let raw = cell(i);
        raw.parse::<i64>().map_err(|_| {
            format!(
                "{} `{raw}` is not an integer frame number",
                INDEX_COLUMNS[i]
            )
        })
    };
    let start_frame = frame(1)?;
    let end_frame = frame(2)?;
    if start_frame < 0 {
        return Err(format!("start_frame {start_frame} is negative"));
    }
    if end_frame < -1 {
        return Err(format!(
            "end_frame {end_frame}: expected a frame number or -1 for the end of the capture"
        ));
    }
    if end_frame != -1 && start_frame > end_frame {
        return Err(format!(
            "start_frame {start_frame} is after end_frame {end_frame}"
        ));
    }
    Ok(IndexRow {
        source_path: source_path.to_string(),
        start_frame,
        end_frame,
        new_name: new_name.to_string(),
        line,
    })
}

/// Groups rows into per-capture annotations. `key` maps a `source_path` to a capture key, `fps` is
/// the rate the index counts frames at, `texts` gives the caption for a `new_name` (called with
/// the name as written, `004041.npy`) when one is known, and `default_text` is used otherwise
/// (with a `no_caption` note). Spans are ordered by start frame, then by line; `simultaneous` is
/// false (rows are independent crops). Two different source paths mapped to one key are merged,
/// with a `key_collision` note.
pub fn index_annotations(
    rows: &[IndexRow],
    fps: f64,
    file: &str,
    key: impl Fn(&str) -> String,
    texts: impl Fn(&str) -> Option<String>,
    default_text: &str,
) -> BTreeMap<String, CaptureAnnotation> {
    let mut groups: BTreeMap<String, Vec<&IndexRow>> = BTreeMap::new();
    for row in rows {
        groups.entry(key(&row.source_path)).or_default().push(row);
    }
    let mut out = BTreeMap::new();
    for (capture, mut group) in groups {
        group.sort_by_key(|r| r.line);
        let origin = group
            .first()
            .map(|r| format!("{file}:{}", r.line))
            .unwrap_or_else(|| file.to_string());
        let mut notes = Vec::new();
        if let Some(first) = group.first()
            && let Some(other) = group.iter().find(|r| r.source_path != first.source_path)
        {
            notes.push(Note::new(
                "key_collision",
                format!(
                    "{file}:{}: `{}` maps to capture `{capture}` like `{}` (line {}); their rows \
                     are merged",
                    other.line, other.source_path, first.source_path, first.line
                ),
            ));
        }
        group.sort_by_key(|r| (r.start_frame, r.line));
        let mut spans = Vec::with_capacity(group.len());
        for row in group {
            let text = match texts(&row.new_name) {
                Some(t) => t,
                None => {
                    notes.push(Note::new(
                        "no_caption",
                        format!(
                            "{file}:{}: no caption for `{}`; using `{default_text}`",
                            row.line, row.new_name
                        ),
                    ));
                    default_text.to_string()
                }
            };
            spans.push(Span {
                start: Time::Frame {
                    frame: row.start_frame,
                    fps,
                },
                end: if row.end_frame == -1 {
                    Time::End
                } else {
                    Time::Frame {
                        frame: row.end_frame,
                        fps,
                    }
                },
                raw_text: text.clone(),
                label: text,
                categories: Vec::new(),
                motion_type: None,
                hand: None,
                object: None,
                grasp: None,
                id: row.new_name.clone(),
            });
        }
        out.insert(
            capture,
            CaptureAnnotation {
                spans,
                simultaneous: false,
                duration: None,
                origin,
                notes,
                ..CaptureAnnotation::default()
            },
        );
    }
    out
}

/// The first caption of a HumanML3D caption file (lines `caption#tokens#start#end`; a line
/// without `#` is taken whole). `None` when no line has a caption.
pub fn read_caption(text: &str) -> Option<String> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    text.lines()
        .map(|l| l.split('#').next().unwrap_or(l).trim())
        .find(|c| !c.is_empty())
        .map(str::to_string)
}
