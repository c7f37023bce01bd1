//! HumanML3D's frame-range index (`index.csv`: `source_path,start_frame,end_frame,new_name`),
//! frames counted at a rate the config states (20 fps for HumanML3D), `-1` as `end_frame` meaning
//! "to the end of the capture". Each row is an independent crop of one source capture; captions
//! live beside the index in `texts/<new_name without .npy>.txt`.
//!
//! Also holds the small CSV line splitter the annotation readers share (no csv crate): fields
//! separated by commas, optionally double-quoted, `""` inside quotes for a literal quote, CRLF or
//! LF line ends. A field cannot contain a line break.

use std::collections::BTreeMap;

use super::span::{
    AnnotationError, AnnotationFault, CaptureAnnotation, NOT_LISTED, NOTES_PER_KIND, Note,
    NoteKind, Span, Time,
};
use motionforge_language::caption::{MAX_CAPTION_CHARS, over_length};

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

/// Why a CSV line does not split into fields; `column` is the field's 1-based position.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CsvFault {
    /// A quoted field runs to the line end.
    #[error("field {column} opens a double quote that is not closed on this line")]
    UnclosedQuote {
        /// The field.
        column: usize,
    },
    /// Something other than a comma follows a closing quote.
    #[error(
        "field {column}: expected `,` or the line end after the closing quote, found `{found}`"
    )]
    AfterQuote {
        /// The field.
        column: usize,
        /// The character found.
        found: char,
    },
    /// A double quote in the middle of an unquoted field.
    #[error(
        "field {column}: a double quote inside an unquoted field (quote the whole field and double the quote: `\"\"`)"
    )]
    QuoteInField {
        /// The field.
        column: usize,
    },
}

/// Splits one CSV line (without its line end) into fields. Double-quoted fields may contain
/// commas and `""` for a quote; spaces around a quoted field are ignored; unquoted fields are kept
/// as written (callers trim). Errors say what was wrong.
pub fn split_csv_line(line: &str) -> Result<Vec<String>, CsvFault> {
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
                    None => return Err(CsvFault::UnclosedQuote { column }),
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
                Some(found) => return Err(CsvFault::AfterQuote { column, found }),
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
                        return Err(CsvFault::QuoteInField {
                            column: fields.len() + 1,
                        });
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
            fault: AnnotationFault::EmptyIndex,
        });
    };
    let columns = header_columns(header).map_err(|fault| AnnotationError {
        file: file.to_string(),
        line: Some(header_line),
        fault,
    })?;
    let mut rows = Vec::new();
    let mut notes = Vec::new();
    // Only the first bad rows are described: an index of nothing but bad rows must not grow a
    // note per line (a 27 MB one made a 446 MB build report).
    let mut bad = 0usize;
    for (line, text) in lines {
        match read_row(text, line, &columns) {
            Ok(row) => rows.push(row),
            Err(why) => {
                bad += 1;
                if bad <= NOTES_PER_KIND {
                    notes.push(Note::new(NoteKind::BadRow, format!("{file}:{line}: {why}")));
                }
            }
        }
    }
    if bad > NOTES_PER_KIND {
        notes.push(Note::new(
            NOT_LISTED,
            format!(
                "{file}: {} more `bad_row` notes not listed (the first {NOTES_PER_KIND} are)",
                bad - NOTES_PER_KIND
            ),
        ));
    }
    Ok((rows, notes))
}

/// Position of each of [`INDEX_COLUMNS`] in the header (any order, names matched without case).
fn header_columns(header: &str) -> Result<[usize; 4], AnnotationFault> {
    let names = split_csv_line(header).map_err(AnnotationFault::IndexHeader)?;
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
                return Err(AnnotationFault::IndexColumnMissing {
                    header: header.trim().to_string(),
                    column: want,
                });
            }
            _ => return Err(AnnotationFault::IndexColumnTwice { column: want }),
        }
    }
    if names.len() != INDEX_COLUMNS.len() {
        return Err(AnnotationFault::IndexColumnCount {
            found: names.len(),
            header: header.trim().to_string(),
        });
    }
    Ok(at)
}

fn read_row(text: &str, line: u64, columns: &[usize; 4]) -> Result<IndexRow, String> {
    let cells = split_csv_line(text).map_err(|e| e.to_string())?;
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
    let captions = |name: &str| {
        texts(name).map(|caption| {
            vec![CaptionLine {
                caption,
                start: 0.0,
                end: 0.0,
            }]
        })
    };
    index_annotations_with(
        rows,
        &IndexOptions {
            fps,
            humanml3d_cuts: false,
        },
        file,
        key,
        captions,
        default_text,
    )
}

/// How rows of an index cut their captures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IndexOptions {
    /// Rate the index counts frames at (HumanML3D: 20).
    pub fps: f64,
    /// Cut as HumanML3D's `raw_pose_processing` does: [`HUMANML3D_HEAD_TRIMS`] first, then
    /// `[start_frame:end_frame]` as a Python slice (`-1` stops one frame before the end); rows of
    /// `humanact12` files are not cut at all.
    pub humanml3d_cuts: bool,
}

/// HumanML3D's dataset-specific head trims: a capture whose `source_path` contains the name loses
/// that many seconds from its start before the row's frames are counted (`data[3*fps:]`, ...).
pub const HUMANML3D_HEAD_TRIMS: [(&str, f64); 5] = [
    ("Eyes_Japan_Dataset", 3.0),
    ("MPI_HDM05", 3.0),
    ("TotalCapture", 1.0),
    ("MPI_Limits", 1.0),
    ("Transitions_mocap", 0.5),
];

/// The frames HumanML3D trims from the head of `source_path` at `fps` (`int(seconds * fps)` for
/// each name the path contains).
pub fn humanml3d_head_trim(source_path: &str, fps: f64) -> i64 {
    HUMANML3D_HEAD_TRIMS
        .iter()
        .filter(|(name, _)| source_path.contains(name))
        .map(|(_, seconds)| (seconds * fps) as i64)
        .sum()
}

/// Where a row's crop starts and ends on its capture's timeline.
pub fn row_range(row: &IndexRow, options: &IndexOptions) -> (Time, Time) {
    let fps = options.fps;
    if !options.humanml3d_cuts {
        let end = if row.end_frame == -1 {
            Time::End
        } else {
            Time::Frame {
                frame: row.end_frame,
                fps,
            }
        };
        let start = Time::Frame {
            frame: row.start_frame,
            fps,
        };
        return (start, end);
    }
    if row.source_path.contains("humanact12") {
        // HumanML3D keeps these files whole.
        return (Time::Frame { frame: 0, fps }, Time::End);
    }
    let trim = humanml3d_head_trim(&row.source_path, fps);
    let end = if row.end_frame == -1 {
        Time::BeforeEnd { frames: 1, fps }
    } else {
        Time::Frame {
            // Saturating, as rows without a trim are clamped: `end_frame` = i64::MAX means
            // "to the end", not a wrap to a negative frame.
            frame: trim.saturating_add(row.end_frame),
            fps,
        }
    };
    (
        Time::Frame {
            frame: trim.saturating_add(row.start_frame),
            fps,
        },
        end,
    )
}

/// [`index_annotations`] with every caption of a clip: `captions` gives a `new_name`'s caption
/// lines. Lines with `0#0` (the whole clip) make one span whose first caption is its text and
/// the others its alternatives; lines naming a sub-span in seconds make a span of their own per
/// distinct sub-span, cut from the row's crop as HumanML3D's loaders cut it
/// (`motion[int(start*fps):int(end*fps)]`). A row whose captions are all sub-spans gives no
/// whole-clip span, as in HumanML3D.
pub fn index_annotations_with(
    rows: &[IndexRow],
    options: &IndexOptions,
    file: &str,
    key: impl Fn(&str) -> String,
    captions: impl Fn(&str) -> Option<Vec<CaptionLine>>,
    default_text: &str,
) -> BTreeMap<String, CaptureAnnotation> {
    let fps = options.fps;
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
                NoteKind::KeyCollision,
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
            let (start, end) = row_range(row, options);
            let lines = match captions(&row.new_name) {
                Some(lines) if !lines.is_empty() => lines,
                _ => {
                    notes.push(Note::new(
                        NoteKind::NoCaption,
                        format!(
                            "{file}:{}: no caption for `{}`; using `{default_text}`",
                            row.line, row.new_name
                        ),
                    ));
                    vec![CaptionLine {
                        caption: default_text.to_string(),
                        start: 0.0,
                        end: 0.0,
                    }]
                }
            };
            // Captions grouped by the part of the clip they describe, in file order.
            let mut parts: Vec<((f64, f64), Vec<String>)> = Vec::new();
            for line in lines {
                let at = (line.start, line.end);
                match parts.iter_mut().find(|(p, _)| *p == at) {
                    Some((_, texts)) => texts.push(line.caption),
                    None => parts.push((at, vec![line.caption])),
                }
            }
            for ((from, to), mut texts) in parts {
                let text = texts.remove(0);
                let whole = from == 0.0 && to == 0.0;
                let (span_start, span_end, id) = if whole {
                    (start, end, row.new_name.clone())
                } else {
                    let base = match start {
                        Time::Frame { frame, .. } => frame,
                        _ => 0,
                    };
                    let sub_start = base.saturating_add((from * fps) as i64);
                    let mut sub_end = base.saturating_add((to * fps) as i64);
                    if let Time::Frame { frame, .. } = end {
                        sub_end = sub_end.min(frame);
                    }
                    (
                        Time::Frame {
                            frame: sub_start,
                            fps,
                        },
                        Time::Frame {
                            frame: sub_end,
                            fps,
                        },
                        format!("{}#{from}-{to}", row.new_name),
                    )
                };
                spans.push(Span {
                    start: span_start,
                    end: span_end,
                    raw_text: text.clone(),
                    label: text,
                    categories: Vec::new(),
                    motion_type: None,
                    hand: None,
                    object: None,
                    grasp: None,
                    id,
                    alternatives: texts,
                });
            }
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

/// One caption of a HumanML3D caption file: the caption and the part of the clip it describes,
/// in seconds (`0`, `0` for the whole clip).
#[derive(Debug, Clone, PartialEq)]
pub struct CaptionLine {
    /// The caption as written.
    pub caption: String,
    /// Start of the described part, seconds from the clip's start.
    pub start: f64,
    /// Its end; `0` with `start` `0` for the whole clip.
    pub end: f64,
}

/// Every caption of a HumanML3D caption file (`caption#tokens#start#end` per line; a line with
/// fewer fields describes the whole clip): [`read_caption_file`] over the text's bytes.
pub fn read_captions(text: &str, file: &str) -> (Vec<CaptionLine>, Vec<Note>) {
    read_caption_file(text.as_bytes(), file)
}

/// The longest line of a caption file, in bytes, that is read: a caption of
/// [`MAX_CAPTION_CHARS`] characters (at most 4 bytes each) with its tagged tokens and times fits
/// well; a longer line is skipped without being held whole.
pub const MAX_CAPTION_LINE_BYTES: usize = 64 * 1024;

/// Every caption of a HumanML3D caption file read from `reader` (`caption#tokens#start#end` per
/// line; a line with fewer fields describes the whole clip), one line at a time: memory does not
/// grow with a line's length. Lines are skipped, each with a note naming `file` and the line, when
/// their times are not numbers, are negative or end before they start (`bad_caption`), their
/// caption is longer than [`MAX_CAPTION_CHARS`] or the line longer than
/// [`MAX_CAPTION_LINE_BYTES`] (`long_caption`), or their caption or times hold a byte that is not
/// UTF-8 (`caption_encoding`, naming the byte's offset in the file); the other lines are kept.
/// A read error stops the file with a `caption_unreadable` note.
pub fn read_caption_file(
    mut reader: impl std::io::BufRead,
    file: &str,
) -> (Vec<CaptionLine>, Vec<Note>) {
    let mut lines = Vec::new();
    let mut notes = Vec::new();
    let mut line = RawLine::default();
    loop {
        let (used, ends) = match reader.fill_buf() {
            Ok([]) => {
                if line.bytes > 0 {
                    line.finish(file, &mut lines, &mut notes);
                }
                break;
            }
            Ok(buf) => {
                let (part, ends) = match buf.iter().position(|&b| b == b'\n') {
                    Some(i) => (&buf[..i], true),
                    None => (buf, false),
                };
                line.push(part);
                (part.len() + usize::from(ends), ends)
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => {
                notes.push(Note::new(
                    NoteKind::CaptionUnreadable,
                    format!(
                        "{file}:{}: {e}; the file's later lines are not read",
                        line.number + 1
                    ),
                ));
                break;
            }
        };
        reader.consume(used);
        if ends {
            line.finish(file, &mut lines, &mut notes);
        }
    }
    (lines, notes)
}

/// A line of a caption file as it is read: its first [`MAX_CAPTION_LINE_BYTES`] bytes, and what
/// is known of the rest.
#[derive(Default)]
struct RawLine {
    /// The bytes kept.
    kept: Vec<u8>,
    /// Its length in bytes, all of it.
    bytes: u64,
    /// Characters before its first `#` (its caption), while no `#` has been seen.
    caption_chars: u64,
    hash_seen: bool,
    /// Lines finished before it.
    number: u64,
    /// Offset of its first byte in the file.
    start: u64,
}

impl RawLine {
    fn push(&mut self, part: &[u8]) {
        let room = MAX_CAPTION_LINE_BYTES.saturating_sub(self.kept.len());
        self.kept.extend_from_slice(&part[..part.len().min(room)]);
        self.bytes += part.len() as u64;
        if !self.hash_seen {
            let caption = match part.iter().position(|&b| b == b'#') {
                Some(i) => {
                    self.hash_seen = true;
                    &part[..i]
                }
                None => part,
            };
            // UTF-8 continuation bytes are 10xxxxxx; every other byte starts a character.
            self.caption_chars += caption.iter().filter(|&&b| b & 0xc0 != 0x80).count() as u64;
        }
    }

    /// Reads the line into `lines` or a note, and makes ready for the next line.
    fn finish(&mut self, file: &str, lines: &mut Vec<CaptionLine>, notes: &mut Vec<Note>) {
        self.number += 1;
        let number = self.number;
        if self.bytes > MAX_CAPTION_LINE_BYTES as u64 {
            let what = if self.caption_chars > MAX_CAPTION_CHARS as u64 {
                format!(
                    "caption of {} characters is longer than the {MAX_CAPTION_CHARS} a caption \
                     may have",
                    self.caption_chars
                )
            } else {
                format!(
                    "line of {} bytes is longer than the {MAX_CAPTION_LINE_BYTES} a caption line \
                     may have",
                    self.bytes
                )
            };
            notes.push(Note::new(
                NoteKind::LongCaption,
                format!("{file}:{number}: {what}; caption skipped"),
            ));
        } else {
            let (mut line, mut at) = (self.kept.as_slice(), self.start);
            const BOM: &[u8] = "\u{feff}".as_bytes();
            if number == 1
                && let Some(rest) = line.strip_prefix(BOM)
            {
                (line, at) = (rest, at + BOM.len() as u64);
            }
            let line = line.strip_suffix(b"\r").unwrap_or(line);
            if let Some(read) = caption_line_of(line, at, number, file, notes) {
                lines.push(read);
            }
        }
        // The next line starts after this one's line end.
        self.start += self.bytes + 1;
        self.kept.clear();
        self.bytes = 0;
        self.caption_chars = 0;
        self.hash_seen = false;
    }
}

/// One line of a caption file (no line end): its caption and times, or `None` with the reason
/// in `notes`. `at` is the offset of the line's first byte in the file.
fn caption_line_of(
    line: &[u8],
    at: u64,
    number: u64,
    file: &str,
    notes: &mut Vec<Note>,
) -> Option<CaptionLine> {
    let fields: Vec<&[u8]> = line.split(|&b| b == b'#').collect();
    // Only the caption and the times are read; the tagged tokens between them are not.
    let read = if fields.len() >= 4 {
        vec![0, fields.len() - 2, fields.len() - 1]
    } else {
        vec![0]
    };
    let mut text: Vec<&str> = Vec::with_capacity(read.len());
    for i in read {
        let field = fields[i];
        match std::str::from_utf8(field) {
            Ok(t) => text.push(t),
            Err(e) => {
                let offset = fields[..i].iter().map(|f| f.len() as u64 + 1).sum::<u64>()
                    + e.valid_up_to() as u64;
                notes.push(Note::new(
                    NoteKind::CaptionEncoding,
                    format!(
                        "{file}:{number}: byte {} (0x{:02x}) is not UTF-8; caption skipped",
                        at + offset,
                        field[e.valid_up_to()]
                    ),
                ));
                return None;
            }
        }
    }
    let caption = text[0].trim();
    if caption.is_empty() {
        return None;
    }
    if let Some(chars) = over_length(caption) {
        notes.push(Note::new(
            NoteKind::LongCaption,
            format!(
                "{file}:{number}: caption of {chars} characters is longer than the \
                 {MAX_CAPTION_CHARS} a caption may have; caption skipped"
            ),
        ));
        return None;
    }
    let (start, end) = if let [_, start, end] = text[..] {
        let time = |s: &str| s.trim().parse::<f64>().ok().filter(|t| t.is_finite());
        match (time(start), time(end)) {
            (Some(a), Some(b)) if a >= 0.0 && b >= 0.0 && (b > a || (a == 0.0 && b == 0.0)) => {
                (a, b)
            }
            _ => {
                notes.push(Note::new(
                    NoteKind::BadCaption,
                    format!(
                        "{file}:{number}: start#end `{start}#{end}`: expected seconds with end \
                         after start, or 0#0 for the whole clip; caption skipped"
                    ),
                ));
                return None;
            }
        }
    } else {
        (0.0, 0.0)
    };
    Some(CaptionLine {
        caption: caption.to_string(),
        start,
        end,
    })
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The texts of the index and BABEL file faults, as builds show them: they must not change.
    #[test]
    fn every_file_fault_reads_as_it_always_has() {
        let index = |text: &str| read_frame_index(text, "index.csv").unwrap_err().to_string();
        let cases = [
            (
                "\n",
                "index.csv: empty file: expected the header `source_path,start_frame,end_frame,new_name`",
            ),
            (
                "source_path,\"start_frame",
                "index.csv:1: expected the header `source_path,start_frame,end_frame,new_name`: field 2 opens a double quote that is not closed on this line",
            ),
            (
                "source_path,start_frame,new_name ",
                "index.csv:1: expected the header `source_path,start_frame,end_frame,new_name`, found `source_path,start_frame,new_name` (no `end_frame` column)",
            ),
            (
                "source_path,start_frame,end_frame,new_name,Start_Frame",
                "index.csv:1: expected the header `source_path,start_frame,end_frame,new_name`: `start_frame` appears twice",
            ),
            (
                "source_path,start_frame,end_frame,new_name,text",
                "index.csv:1: expected the header `source_path,start_frame,end_frame,new_name`, found 5 columns: `source_path,start_frame,end_frame,new_name,text`",
            ),
        ];
        for (text, want) in cases {
            assert_eq!(index(text), want, "{text}");
        }
        let babel = |text: &str| {
            super::super::babel::read_babel(text, "babel.json")
                .map(|_| ())
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            babel("{"),
            "babel.json:1: not valid JSON: EOF while parsing an object at line 1 column 1"
        );
        assert_eq!(
            babel("[]"),
            "babel.json: expected a JSON object of BABEL records keyed by sequence id"
        );
    }
}
