//! BVH reading and writing, in f64, for any Euler channel order, LF or CRLF, tabs and exponents.
//!
//! Why not the `bvh_anim` crate: see `docs/decisions.md` (f32 storage, panics on malformed headers,
//! 2-decimal default output, unsound transitive dependencies). It stays a dev-dependency that
//! cross-checks this reader on every real file.

use std::fmt::Write as _;
use std::sync::Arc;

use glam::{DQuat, DVec3, EulerRot};

use super::motion::Motion;
use super::skeleton::{Channel, Joint, Skeleton};

/// What went wrong while reading a BVH file, with the 1-based line where it was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}{}: {kind}", frame.map(|f| format!(" (frame {f})")).unwrap_or_default())]
pub struct BvhError {
    /// 1-based line number.
    pub line: usize,
    /// 0-based frame index, for errors in the MOTION section.
    pub frame: Option<usize>,
    /// What was expected and what was found.
    pub kind: BvhErrorKind,
}

/// The kinds of BVH read errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BvhErrorKind {
    /// A keyword or value other than the one the grammar needs.
    #[error("expected {expected}, found `{found}`")]
    Unexpected {
        /// What the grammar needs here.
        expected: &'static str,
        /// The token in the file.
        found: String,
    },
    /// The file ended early.
    #[error("file ends where {expected} was expected")]
    UnexpectedEnd {
        /// What the grammar needs here.
        expected: &'static str,
    },
    /// A token that should be a number is not a finite number.
    #[error("expected a finite number for {what}, found `{found}`")]
    BadNumber {
        /// Which value was being read.
        what: &'static str,
        /// The token in the file.
        found: String,
    },
    /// A `CHANNELS` list names an unknown channel.
    #[error(
        "unknown channel `{0}` (expected Xposition, Yposition, Zposition, Xrotation, Yrotation or Zrotation)"
    )]
    UnknownChannel(String),
    /// A motion line has the wrong number of values.
    #[error("expected {expected} channel values (from the HIERARCHY), found {found}")]
    ValueCount {
        /// Channels declared in the hierarchy.
        expected: usize,
        /// Values on the line.
        found: usize,
    },
    /// Fewer motion lines than `Frames:` declares.
    #[error("truncated: header declares {declared} frames, file has {found}")]
    Truncated {
        /// Frames declared in the header.
        declared: usize,
        /// Frames present.
        found: usize,
    },
    /// More motion lines than `Frames:` declares.
    #[error("header declares {declared} frames (line {header_line}), file has {found}")]
    ExtraFrames {
        /// Frames declared in the header.
        declared: usize,
        /// The line of the `Frames:` header.
        header_line: usize,
        /// Frame lines present.
        found: usize,
    },
    /// `Frame Time` is outside the plausible range [`FRAME_TIME_RANGE`].
    #[error(
        "frame time must be between {lo} and {hi} seconds ({fps_lo} to {fps_hi} fps), found {0}",
        lo = FRAME_TIME_RANGE.start(),
        hi = FRAME_TIME_RANGE.end(),
        fps_lo = FPS_RANGE.start(),
        fps_hi = FPS_RANGE.end()
    )]
    FrameTime(f64),
    /// A value beyond [`MAX_MAGNITUDE`]: finite, but far outside any real capture, and large
    /// enough to overflow positions, velocities or statistics computed from it.
    #[error("{what} is {value:e}, beyond the plausible ±{max:e} (a damaged value)", max = MAX_MAGNITUDE)]
    OutOfRange {
        /// Which value (joint and channel, or offset axis).
        what: String,
        /// The value in the file.
        value: f64,
    },
    /// More joints than [`MAX_JOINTS`].
    #[error("more than {max} joints in the HIERARCHY", max = MAX_JOINTS)]
    TooManyJoints,
    /// More frames x joints than [`MAX_JOINT_FRAMES`].
    #[error(
        "capture too long: {frames} frames of {joints} joints exceed the limit of {max} joint-frames; split the capture",
        max = MAX_JOINT_FRAMES
    )]
    TooLarge {
        /// Frames read so far (or declared).
        frames: usize,
        /// Joints of the hierarchy.
        joints: usize,
    },
    /// The hierarchy has no joint.
    #[error("HIERARCHY defines no joint")]
    NoJoints,
}

/// Capture frame rates motionforge accepts, in frames per second, from headers and overrides alike.
/// Real capture systems record between a few and a few thousand frames per second; a value outside
/// this range is a damaged header, and accepting it would size resampling by an absurd duration.
pub const FPS_RANGE: std::ops::RangeInclusive<f64> = 1.0..=10_000.0;

/// `Frame Time` values accepted in a BVH header (seconds): the reciprocal of [`FPS_RANGE`].
pub const FRAME_TIME_RANGE: std::ops::RangeInclusive<f64> = 0.0001..=1.0;

/// Largest magnitude accepted for an offset or channel value (any unit: 10 km in millimetres,
/// a million degrees). Real captures stay orders of magnitude below; anything beyond is damage
/// that would overflow features and statistics downstream.
pub const MAX_MAGNITUDE: f64 = 1e6;

/// Most joints a hierarchy may have. Full-body rigs with fingers and faces stay in the hundreds.
pub const MAX_JOINTS: usize = 1_000;

/// Most frames x joints one capture may hold (about 0.6 GB of decoded motion in f64). Frame
/// lines of joints without channels take no text, so without this bound a small file could
/// claim gigabytes.
pub const MAX_JOINT_FRAMES: usize = 10_000_000;

/// Longest excerpt of a file's text quoted in an error, in characters.
pub const EXCERPT_CHARS: usize = 60;

/// At most [`EXCERPT_CHARS`] characters of `text`, with `…` when cut, so a damaged line (or a
/// whole file on one line) never floods a reject list.
pub fn excerpt(text: &str) -> String {
    match text.char_indices().nth(EXCERPT_CHARS) {
        Some((cut, _)) => format!("{}…", &text[..cut]),
        None => text.to_string(),
    }
}

/// The whitespace-separated words of `line`, as `split_ascii_whitespace` gives them, found with a
/// plain byte loop: the frame lines, most of a capture's bytes, all pass through here.
fn words(line: &str) -> impl Iterator<Item = &str> {
    let bytes = line.as_bytes();
    let mut at = 0usize;
    std::iter::from_fn(move || {
        while bytes.get(at).is_some_and(u8::is_ascii_whitespace) {
            at += 1;
        }
        let from = at;
        while bytes.get(at).is_some_and(|b| !b.is_ascii_whitespace()) {
            at += 1;
        }
        // Both ends sit next to ASCII whitespace or the line's ends: character boundaries.
        line.get(from..at).filter(|w| !w.is_empty())
    })
}

/// Lines of `text` split at LF, CRLF or a lone CR (classic Mac exports end lines with CR only),
/// each with the byte offset where it starts.
fn split_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    let bytes = text.as_bytes();
    let mut start = 0usize;
    std::iter::from_fn(move || {
        if start >= bytes.len() {
            return None;
        }
        let from = start;
        let i = memchr::memchr2(b'\n', b'\r', &bytes[from..]).map_or(bytes.len(), |n| from + n);
        let line = &text[from..i];
        start = if i + 1 < bytes.len() && bytes[i] == b'\r' && bytes[i + 1] == b'\n' {
            i + 2
        } else {
            i + 1
        };
        Some((from, line))
    })
}

/// A read BVH file: its hierarchy, motion and the frame rate its header states.
#[derive(Debug, Clone)]
pub struct Bvh {
    /// The joint hierarchy.
    pub skeleton: Arc<Skeleton>,
    /// The motion at the header's rate.
    pub motion: Motion,
    /// `1 / Frame Time`, snapped to the nearest integer when within 0.01 of it
    /// (`.0083333` means 120 fps, not 120.0048).
    pub header_fps: f64,
    /// The channel values as written in the file (degrees for rotations), frame-major. Passed to
    /// [`write_bvh_with_reference`], they make an unchanged motion write back value for value.
    pub channels: Vec<f64>,
}

struct Tokens<'a> {
    lines: Box<dyn Iterator<Item = (usize, (usize, &'a str))> + 'a>,
    current: std::str::SplitAsciiWhitespace<'a>,
    line: usize,
    rest_offset: usize,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str) -> Self {
        Tokens {
            lines: Box::new(split_lines(text).enumerate()),
            current: "".split_ascii_whitespace(),
            line: 0,
            rest_offset: 0,
        }
    }

    fn next(&mut self) -> Option<&'a str> {
        loop {
            if let Some(tok) = self.current.next() {
                return Some(tok);
            }
            let (i, (start, line)) = self.lines.next()?;
            self.line = i + 1;
            self.rest_offset = start + line.len();
            self.current = line.split_ascii_whitespace();
        }
    }

    fn expect_any(&mut self, expected: &'static str) -> Result<&'a str, BvhError> {
        let line = self.line;
        self.next().ok_or(BvhError {
            line: line.max(1),
            frame: None,
            kind: BvhErrorKind::UnexpectedEnd { expected },
        })
    }

    fn expect(&mut self, keyword: &'static str) -> Result<(), BvhError> {
        let tok = self.expect_any(keyword)?;
        if tok.eq_ignore_ascii_case(keyword) {
            Ok(())
        } else {
            Err(self.unexpected(keyword, tok))
        }
    }

    fn number(&mut self, what: &'static str) -> Result<f64, BvhError> {
        let tok = self.expect_any(what)?;
        parse_finite(tok).ok_or_else(|| {
            self.error(BvhErrorKind::BadNumber {
                what,
                found: excerpt(tok),
            })
        })
    }

    fn unexpected(&self, expected: &'static str, found: &str) -> BvhError {
        self.error(BvhErrorKind::Unexpected {
            expected,
            found: excerpt(found),
        })
    }

    fn error(&self, kind: BvhErrorKind) -> BvhError {
        BvhError {
            line: self.line.max(1),
            frame: None,
            kind,
        }
    }
}

fn parse_finite(tok: &str) -> Option<f64> {
    plain_decimal(tok).or_else(|| tok.parse::<f64>().ok().filter(|v| v.is_finite()))
}

/// Powers of ten that an `f64` holds exactly.
const EXACT_POWERS_OF_TEN: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// `tok` when it is a plain decimal (`-12.345678`, `5.1072e-06`: the forms exporters write channel
/// values in) whose digits fit an `f64` exactly: `None` sends anything else to the standard
/// parser.
///
/// The value is then the integer of its digits times or divided by a power of ten, both exact in
/// an `f64`, and IEEE arithmetic rounds that one operation correctly, so the result is the same
/// `f64` the standard parser gives (Clinger's fast path, which it tries first too) without its
/// general machinery: the frame lines of the captures are most of what a build reads.
fn plain_decimal(tok: &str) -> Option<f64> {
    let bytes = tok.as_bytes();
    let negative = bytes.first() == Some(&b'-');
    let mut i = usize::from(negative);
    let start = i;
    let mut mantissa = 0u64;
    while let Some(&c) = bytes.get(i).filter(|c| c.is_ascii_digit()) {
        mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(c - b'0'));
        i += 1;
    }
    let mut digits = i - start;
    let mut fraction = 0usize;
    if bytes.get(i) == Some(&b'.') {
        i += 1;
        let from = i;
        while let Some(&c) = bytes.get(i).filter(|c| c.is_ascii_digit()) {
            mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(c - b'0'));
            i += 1;
        }
        fraction = i - from;
        digits += fraction;
    }
    // No digits, or more than 19 (the mantissa may have wrapped): the standard parser decides.
    if digits == 0 || digits > 19 || mantissa > 1 << 53 {
        return None;
    }
    let exponent = match bytes.get(i) {
        None => 0,
        Some(b'e' | b'E') => small_exponent(&bytes[i + 1..])?,
        Some(_) => return None,
    };
    let scale = exponent - fraction as i32;
    let power = *EXACT_POWERS_OF_TEN.get(scale.unsigned_abs() as usize)?;
    let value = if scale < 0 {
        mantissa as f64 / power
    } else {
        mantissa as f64 * power
    };
    Some(if negative { -value } else { value })
}

/// The exponent after `e` when it is one or two digits with an optional sign.
fn small_exponent(bytes: &[u8]) -> Option<i32> {
    let (sign, digits) = match bytes.split_first() {
        Some((b'-', rest)) => (-1, rest),
        Some((b'+', rest)) => (1, rest),
        _ => (1, bytes),
    };
    if digits.is_empty() || digits.len() > 2 || !digits.iter().all(u8::is_ascii_digit) {
        return None;
    }
    Some(sign * digits.iter().fold(0, |n, &d| n * 10 + i32::from(d - b'0')))
}

/// Reads a BVH file from its text.
pub fn read_bvh(text: &str) -> Result<Bvh, BvhError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut tokens = Tokens::new(text);
    tokens.expect("HIERARCHY")?;
    let mut joints: Vec<Joint> = Vec::new();
    let tok = tokens.expect_any("ROOT")?;
    if !tok.eq_ignore_ascii_case("ROOT") {
        return Err(tokens.unexpected("ROOT", tok));
    }
    read_joint(&mut tokens, &mut joints, None)?;
    let tok = tokens.expect_any("MOTION")?;
    if !tok.eq_ignore_ascii_case("MOTION") {
        let expected = if tok.eq_ignore_ascii_case("ROOT") {
            "MOTION (files with several ROOT hierarchies are not supported)"
        } else {
            "MOTION"
        };
        return Err(tokens.unexpected(expected, tok));
    }
    if joints.is_empty() {
        return Err(tokens.error(BvhErrorKind::NoJoints));
    }
    tokens.expect("Frames:")?;
    let declared = tokens.number("the frame count")?;
    let frames_line = tokens.line;
    if declared < 0.0 || declared.fract() != 0.0 {
        return Err(tokens.error(BvhErrorKind::BadNumber {
            what: "the frame count",
            found: declared.to_string(),
        }));
    }
    let declared = declared as usize;
    tokens.expect("Frame")?;
    tokens.expect("Time:")?;
    let frame_time = tokens.number("the frame time")?;
    if !FRAME_TIME_RANGE.contains(&frame_time) {
        return Err(tokens.error(BvhErrorKind::FrameTime(frame_time)));
    }
    // Anything after `Frame Time: x` on the same line is an error, caught below as a value line.
    let header_fps = snap_fps(1.0 / frame_time);
    let mut rest_tokens: Vec<&str> = tokens.current.by_ref().collect();
    let first_motion_line = tokens.line + 1;
    let body = &text[tokens.rest_offset.min(text.len())..];
    let body = body
        .strip_prefix("\r\n")
        .or_else(|| body.strip_prefix('\n'))
        .or_else(|| body.strip_prefix('\r'))
        .unwrap_or(body);
    let skeleton = Arc::new(Skeleton { joints });
    let (motion, channels) = read_motion(
        &skeleton,
        body,
        Header {
            first_line: first_motion_line,
            frames_line,
            declared,
            fps: header_fps,
        },
        &mut rest_tokens,
    )?;
    Ok(Bvh {
        skeleton,
        motion,
        header_fps,
        channels,
    })
}

fn snap_fps(fps: f64) -> f64 {
    let rounded = fps.round();
    // Never snap a very slow rate (frame time over 100 s) to 0 fps.
    if rounded > 0.0 && (fps - rounded).abs() < 0.01 {
        rounded
    } else {
        fps
    }
}

/// Reads the joint after `ROOT` and everything nested in it, up to its closing `}`. Iterative, with
/// an explicit stack of open joints, so deeply nested (damaged) hierarchies cannot overflow the
/// call stack.
fn read_joint(
    tokens: &mut Tokens<'_>,
    joints: &mut Vec<Joint>,
    parent: Option<usize>,
) -> Result<(), BvhError> {
    let mut open = vec![read_joint_header(tokens, joints, parent)?];
    while let Some(&index) = open.last() {
        let tok = tokens.expect_any("JOINT, End Site or }")?;
        if tok == "}" {
            open.pop();
        } else if tok.eq_ignore_ascii_case("JOINT") {
            open.push(read_joint_header(tokens, joints, Some(index))?);
        } else if tok.eq_ignore_ascii_case("End") {
            tokens.expect("Site")?;
            tokens.expect("{")?;
            tokens.expect("OFFSET")?;
            joints[index].end_site = Some(read_vec3(tokens)?);
            tokens.expect("}")?;
        } else {
            return Err(tokens.unexpected("JOINT, End Site or }", tok));
        }
    }
    Ok(())
}

/// Reads a joint's name, `{`, `OFFSET` and `CHANNELS`, pushes it and returns its index.
fn read_joint_header(
    tokens: &mut Tokens<'_>,
    joints: &mut Vec<Joint>,
    parent: Option<usize>,
) -> Result<usize, BvhError> {
    let name = tokens.expect_any("a joint name")?;
    if name == "{" || name == "}" {
        return Err(tokens.unexpected("a joint name", name));
    }
    let index = joints.len();
    if index >= MAX_JOINTS {
        return Err(tokens.error(BvhErrorKind::TooManyJoints));
    }
    joints.push(Joint {
        name: name.to_string(),
        parent,
        offset: DVec3::ZERO,
        channels: Vec::new(),
        end_site: None,
    });
    tokens.expect("{")?;
    tokens.expect("OFFSET")?;
    joints[index].offset = read_vec3(tokens)?;
    let tok = tokens.expect_any("CHANNELS")?;
    if !tok.eq_ignore_ascii_case("CHANNELS") {
        return Err(tokens.unexpected("CHANNELS", tok));
    }
    let count = tokens.number("the channel count")?;
    if !(0.0..=6.0).contains(&count) || count.fract() != 0.0 {
        return Err(tokens.error(BvhErrorKind::BadNumber {
            what: "the channel count (0 to 6)",
            found: count.to_string(),
        }));
    }
    for _ in 0..count as usize {
        let tok = tokens.expect_any("a channel name")?;
        let channel = Channel::parse(tok)
            .ok_or_else(|| tokens.error(BvhErrorKind::UnknownChannel(excerpt(tok))))?;
        joints[index].channels.push(channel);
    }
    Ok(index)
}

fn read_vec3(tokens: &mut Tokens<'_>) -> Result<DVec3, BvhError> {
    let mut v = [0.0; 3];
    for (k, what) in ["OFFSET x", "OFFSET y", "OFFSET z"].into_iter().enumerate() {
        v[k] = tokens.number(what)?;
        if v[k].abs() > MAX_MAGNITUDE {
            return Err(tokens.error(BvhErrorKind::OutOfRange {
                what: what.to_string(),
                value: v[k],
            }));
        }
    }
    Ok(DVec3::from_array(v))
}

/// Where each joint's channels sit in a frame's values, precomputed once per skeleton.
pub(crate) struct ChannelLayout {
    /// Per joint: first channel index and the channels.
    joints: Vec<(usize, Vec<Channel>, DVec3)>,
    total: usize,
}

impl ChannelLayout {
    pub(crate) fn new(skeleton: &Skeleton) -> Self {
        let mut start = 0;
        let joints = skeleton
            .joints
            .iter()
            .map(|j| {
                let entry = (start, j.channels.clone(), j.offset);
                start += j.channels.len();
                entry
            })
            .collect();
        ChannelLayout {
            joints,
            total: start,
        }
    }

    /// `joint Xrotation` for the `index`-th value of a frame.
    fn channel_name(&self, skeleton: &Skeleton, index: usize) -> String {
        for (j, (start, channels, _)) in self.joints.iter().enumerate() {
            if let Some(c) = index.checked_sub(*start).and_then(|k| channels.get(k)) {
                return format!("joint `{}` channel {}", skeleton.joints[j].name, c.name());
            }
        }
        format!("channel value {}", index + 1)
    }

    /// Converts one frame of channel values (degrees) into local rotations and translations.
    pub(crate) fn decode(
        &self,
        values: &[f64],
        rotations: &mut Vec<DQuat>,
        translations: &mut Vec<DVec3>,
    ) {
        for (start, channels, offset) in &self.joints {
            let mut t = *offset;
            let mut r = DQuat::IDENTITY;
            for (k, channel) in channels.iter().enumerate() {
                let v = values[start + k];
                if channel.is_position() {
                    t[channel.axis()] = v;
                } else {
                    r *= channel.rotation(v.to_radians());
                }
            }
            rotations.push(r);
            translations.push(t);
        }
    }
}

/// What the MOTION header says.
struct Header {
    /// The line after `Frame Time`.
    first_line: usize,
    /// The line of `Frames:`.
    frames_line: usize,
    /// Frames the header declares.
    declared: usize,
    /// The header's rate.
    fps: f64,
}

fn read_motion(
    skeleton: &Arc<Skeleton>,
    body: &str,
    header: Header,
    leftover: &mut Vec<&str>,
) -> Result<(Motion, Vec<f64>), BvhError> {
    let Header {
        first_line,
        frames_line,
        declared,
        fps,
    } = header;
    let layout = ChannelLayout::new(skeleton);
    let n = skeleton.len();
    if !leftover.is_empty() {
        return Err(BvhError {
            line: first_line - 1,
            frame: None,
            kind: BvhErrorKind::Unexpected {
                expected: "end of line after Frame Time",
                found: excerpt(&leftover.join(" ")),
            },
        });
    }
    leftover.clear();
    // A damaged `Frames:` count must not drive the allocation: a frame line holds every channel
    // value and a separator after each, so the body cannot hold more frames than this.
    let can_hold = body.len() / (2 * layout.total.max(1)) + 1;
    let frames = declared.min(can_hold).min(MAX_JOINT_FRAMES / n.max(1));
    let mut rotations = Vec::with_capacity(frames.saturating_mul(n));
    let mut translations = Vec::with_capacity(frames.saturating_mul(n));
    let mut values = Vec::with_capacity(layout.total);
    let mut channels = Vec::with_capacity(frames.saturating_mul(layout.total));
    let mut frame = 0usize;
    // The Frame Time line, when no line follows it.
    let mut last_line = first_line - 1;
    let mut lines = split_lines(body).enumerate();
    while let Some((i, (_, line))) = lines.next() {
        let line_no = first_line + i;
        last_line = line_no;
        let mut fields = words(line).peekable();
        if fields.peek().is_none() {
            continue;
        }
        let at = FrameLine {
            line: line_no,
            frame,
        };
        if frame == declared {
            // Count every frame line, so the reject says how many the file really holds.
            let extra = lines
                .filter(|(_, (_, l))| l.split_ascii_whitespace().next().is_some())
                .count();
            return Err(at.error(BvhErrorKind::ExtraFrames {
                declared,
                header_line: frames_line,
                found: declared + 1 + extra,
            }));
        }
        if (frame + 1).saturating_mul(n) > MAX_JOINT_FRAMES {
            return Err(at.error(BvhErrorKind::TooLarge {
                frames: declared,
                joints: n,
            }));
        }
        at.read_values(fields, &layout, skeleton, &mut values)?;
        layout.decode(&values, &mut rotations, &mut translations);
        channels.extend_from_slice(&values);
        frame += 1;
    }
    if frame < declared {
        let at = FrameLine {
            line: last_line,
            frame,
        };
        return Err(at.error(BvhErrorKind::Truncated {
            declared,
            found: frame,
        }));
    }
    let motion = Motion {
        skeleton: Arc::clone(skeleton),
        fps,
        rotations,
        translations,
    };
    Ok((motion, channels))
}

/// Where a frame line is: its line number and frame, for its errors.
#[derive(Clone, Copy)]
struct FrameLine {
    line: usize,
    frame: usize,
}

impl FrameLine {
    fn error(self, kind: BvhErrorKind) -> BvhError {
        BvhError {
            line: self.line,
            frame: Some(self.frame),
            kind,
        }
    }

    /// Parses the line's `fields` into `values` (cleared first): finite numbers within
    /// [`MAX_MAGNITUDE`], exactly one per channel of `layout`. Inlined: it runs once per
    /// frame of every capture read.
    #[inline]
    fn read_values<'t>(
        self,
        fields: impl Iterator<Item = &'t str>,
        layout: &ChannelLayout,
        skeleton: &Skeleton,
        values: &mut Vec<f64>,
    ) -> Result<(), BvhError> {
        values.clear();
        for tok in fields {
            let v = parse_finite(tok).ok_or_else(|| {
                self.error(BvhErrorKind::BadNumber {
                    what: "a channel value",
                    found: excerpt(tok),
                })
            })?;
            if v.abs() > MAX_MAGNITUDE {
                return Err(self.error(BvhErrorKind::OutOfRange {
                    what: layout.channel_name(skeleton, values.len()),
                    value: v,
                }));
            }
            values.push(v);
        }
        if values.len() != layout.total {
            return Err(self.error(BvhErrorKind::ValueCount {
                expected: layout.total,
                found: values.len(),
            }));
        }
        Ok(())
    }
}

/// Why a motion cannot be written as BVH.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BvhWriteError {
    /// Writing needs 0 or 3 rotation channels on distinct axes to represent any rotation.
    #[error(
        "joint `{joint}` has rotation channels {channels:?}; writing needs none or three on distinct axes"
    )]
    UnsupportedRotationChannels {
        /// The joint.
        joint: String,
        /// Its rotation channels.
        channels: Vec<&'static str>,
    },
    /// A joint without rotation channels carries a rotation that would be lost.
    #[error("joint `{joint}` has no rotation channels but rotates at frame {frame}")]
    LostRotation {
        /// The joint.
        joint: String,
        /// First frame where it rotates.
        frame: usize,
    },
}

fn euler_order(axes: [usize; 3]) -> Option<EulerRot> {
    Some(match axes {
        [0, 1, 2] => EulerRot::XYZ,
        [0, 2, 1] => EulerRot::XZY,
        [1, 0, 2] => EulerRot::YXZ,
        [1, 2, 0] => EulerRot::YZX,
        [2, 0, 1] => EulerRot::ZXY,
        [2, 1, 0] => EulerRot::ZYX,
        _ => return None,
    })
}

/// Euler angles (radians) for `q` in `order`, choosing among the equivalent triples the one closest
/// to `previous`, so curves stay continuous instead of jumping by 360 degrees.
fn euler_near(q: DQuat, order: EulerRot, previous: Option<[f64; 3]>) -> [f64; 3] {
    use std::f64::consts::{PI, TAU};
    // Into (-π, π]: exporters and Blender expect principal angles, and unbounded continuity
    // winds up near gimbal lock (thousands of degrees on Bandai spines).
    let wrap = |v: f64| {
        let w = v - (v / TAU).round() * TAU;
        if w <= -PI { w + TAU } else { w }
    };
    let (a, b, c) = q.to_euler(order);
    let principal = [wrap(a), b, wrap(c)];
    let Some(prev) = previous else {
        return principal;
    };
    // The other triple for the same rotation; near gimbal lock, capture software often switches
    // to it to keep curves smooth, so following the previous frame reproduces their choice.
    let alternative = [wrap(a + PI), wrap(PI - b), wrap(c + PI)];
    let back = DQuat::from_euler(order, alternative[0], alternative[1], alternative[2]);
    if back.dot(q).abs() < 1.0 - 1e-9 {
        return principal;
    }
    let cost = |t: &[f64; 3]| -> f64 { (0..3).map(|k| wrap(t[k] - prev[k]).abs()).sum() };
    if cost(&alternative) < cost(&principal) {
        alternative
    } else {
        principal
    }
}

/// Writes a motion as BVH text, keeping the skeleton's hierarchy and channel layout. Values are
/// written at full f64 precision (shortest representation that reads back to the same number).
/// Euler angles are principal, following the previous frame where two triples describe the same
/// rotation.
pub fn write_bvh(motion: &Motion) -> Result<String, BvhWriteError> {
    write_bvh_with_reference(motion, None)
}

/// Like [`write_bvh`], but wherever `reference` (channel values as read, [`Bvh::channels`]) holds
/// a triple for the same rotation, that triple is written unchanged, so a motion read and written
/// back keeps the file's own Euler angles, not just its rotations.
pub fn write_bvh_with_reference(
    motion: &Motion,
    reference: Option<&[f64]>,
) -> Result<String, BvhWriteError> {
    let skeleton = &motion.skeleton;
    let mut orders: Vec<Option<(EulerRot, [usize; 3])>> = Vec::with_capacity(skeleton.len());
    for joint in &skeleton.joints {
        let rot: Vec<Channel> = joint
            .channels
            .iter()
            .copied()
            .filter(|c| !c.is_position())
            .collect();
        let order = match rot.len() {
            0 => None,
            3 => {
                let axes = [rot[0].axis(), rot[1].axis(), rot[2].axis()];
                Some((
                    euler_order(axes).ok_or_else(|| unsupported(joint, &rot))?,
                    axes,
                ))
            }
            _ => return Err(unsupported(joint, &rot)),
        };
        orders.push(order);
    }
    let mut out = String::with_capacity(
        64 * skeleton.len() + motion.num_frames() * skeleton.channel_count() * 12,
    );
    out.push_str("HIERARCHY\n");
    write_joint(&mut out, skeleton, 0, 0);
    let _ = write!(
        out,
        "MOTION\nFrames: {}\nFrame Time: {}\n",
        motion.num_frames(),
        1.0 / motion.fps
    );
    let n = skeleton.len();
    let total = skeleton.channel_count();
    let reference = reference.filter(|r| r.len() == total * motion.num_frames());
    let mut previous: Vec<Option<[f64; 3]>> = vec![None; n];
    // Channel values follow the hierarchy as written (depth first), whatever order the joints
    // have in memory: skeletons made from joint positions keep their array's order (SMPL's).
    let mut written = Vec::with_capacity(n);
    let mut stack = vec![0usize];
    while let Some(j) = stack.pop() {
        written.push(j);
        let children: Vec<usize> = skeleton.children(j).collect();
        stack.extend(children.into_iter().rev());
    }
    for f in 0..motion.num_frames() {
        let mut first = true;
        let mut start = f * total;
        for &j in &written {
            let joint = &skeleton.joints[j];
            let q = motion.rotations[f * n + j];
            let t = motion.translations[f * n + j];
            let given = reference.map(|r| &r[start..start + joint.channels.len()]);
            start += joint.channels.len();
            let angles = match orders[j] {
                Some((order, axes)) => {
                    let mut by_axis = [0.0; 3];
                    match given.and_then(|g| same_rotation(joint, g, q)) {
                        Some(degrees) => {
                            by_axis = degrees;
                            previous[j] = Some([0, 1, 2].map(|k| degrees[axes[k]].to_radians()));
                        }
                        None => {
                            let e = euler_near(q, order, previous[j]);
                            previous[j] = Some(e);
                            for k in 0..3 {
                                by_axis[axes[k]] = e[k].to_degrees();
                            }
                        }
                    }
                    by_axis
                }
                None => {
                    if q.angle_between(DQuat::IDENTITY) > 1e-9 {
                        return Err(BvhWriteError::LostRotation {
                            joint: joint.name.clone(),
                            frame: f,
                        });
                    }
                    [0.0; 3]
                }
            };
            for c in &joint.channels {
                let v = if c.is_position() {
                    t[c.axis()]
                } else {
                    angles[c.axis()]
                };
                if !first {
                    out.push(' ');
                }
                first = false;
                // `-0` reads back fine but adds noise to diffs.
                let v = if v == 0.0 { 0.0 } else { v };
                let _ = write!(out, "{v}");
            }
        }
        out.push('\n');
    }
    Ok(out)
}

/// The reference's rotation values by axis (degrees), if they describe rotation `q`.
fn same_rotation(joint: &Joint, values: &[f64], q: DQuat) -> Option<[f64; 3]> {
    let mut r = DQuat::IDENTITY;
    let mut by_axis = [0.0; 3];
    for (c, v) in joint.channels.iter().zip(values) {
        if !c.is_position() {
            r *= c.rotation(v.to_radians());
            by_axis[c.axis()] = *v;
        }
    }
    (r.dot(q).abs() >= 1.0 - 1e-12).then_some(by_axis)
}

fn unsupported(joint: &Joint, rot: &[Channel]) -> BvhWriteError {
    BvhWriteError::UnsupportedRotationChannels {
        joint: joint.name.clone(),
        channels: rot.iter().map(|c| c.name()).collect(),
    }
}

fn write_joint(out: &mut String, skeleton: &Skeleton, j: usize, depth: usize) {
    let joint = &skeleton.joints[j];
    let pad = "\t".repeat(depth);
    let kind = if joint.parent.is_none() {
        "ROOT"
    } else {
        "JOINT"
    };
    let o = joint.offset;
    let _ = writeln!(
        out,
        "{pad}{kind} {}\n{pad}{{\n{pad}\tOFFSET {} {} {}",
        joint.name, o.x, o.y, o.z
    );
    let names: Vec<&str> = joint.channels.iter().map(|c| c.name()).collect();
    let _ = writeln!(out, "{pad}\tCHANNELS {} {}", names.len(), names.join(" "));
    let children: Vec<usize> = skeleton.children(j).collect();
    for c in children {
        write_joint(out, skeleton, c, depth + 1);
    }
    if let Some(e) = joint.end_site {
        let _ = writeln!(
            out,
            "{pad}\tEnd Site\n{pad}\t{{\n{pad}\t\tOFFSET {} {} {}\n{pad}\t}}",
            e.x, e.y, e.z
        );
    }
    let _ = writeln!(out, "{pad}}}");
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The fast path and the standard parser agree bit for bit, or the fast path declines.
    fn same_as_std(tok: &str) {
        let std = tok.parse::<f64>().ok().filter(|v| v.is_finite());
        if let Some(fast) = plain_decimal(tok) {
            let std = std.unwrap_or_else(|| panic!("`{tok}`: fast path {fast}, std refuses it"));
            assert_eq!(fast.to_bits(), std.to_bits(), "`{tok}`");
        }
        assert_eq!(
            parse_finite(tok).map(f64::to_bits),
            std.map(f64::to_bits),
            "`{tok}`"
        );
    }

    #[test]
    fn plain_decimals_parse_as_the_standard_parser_does() {
        for tok in [
            "0",
            "-0",
            "-0.000000",
            "0.0",
            "5.",
            ".5",
            "-.5",
            ".",
            "-",
            "",
            "+1.5",
            "1e3",
            "1.2.3",
            "inf",
            "NaN",
            "-12.345678",
            "9007199254740993",
            "9007199254740992",
            "0.1",
            "123456789012345678",
            "1234567890123456789",
            "12345678901234567890",
            "0.0000000000000000000001",
            "0.00000000000000000000001",
            "1_0",
            "١",
            "5.1072e-06",
            "-1.5E+3",
            "1e",
            "1e+",
            "e5",
            "-e5",
            "1.e5",
            ".e5",
            "1e-22",
            "1e-23",
            "1e22",
            "1e23",
            "123e-5",
            "1e005",
            "9007199254740993e-3",
            "1.5e-0",
            "0e-99",
            "-0.0e1",
        ] {
            same_as_std(tok);
        }
        assert!(plain_decimal("-0.000000").is_some_and(|v| v.is_sign_negative()));
    }

    #[test]
    fn real_channel_values_take_the_fast_path_and_agree() {
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures");
        let mut checked = 0usize;
        for dir in ["bandai-namco-1/data", "bandai-namco-2/data", "cmu"] {
            let Ok(entries) = std::fs::read_dir(format!("{root}/{dir}")) else {
                panic!("fixtures/{dir} is missing");
            };
            for entry in entries.flatten() {
                let path = entry.path();
                if path.extension().is_none_or(|e| e != "bvh") {
                    continue;
                }
                let text = std::fs::read_to_string(&path).unwrap_or_default();
                let body = text.split("Frame Time:").nth(1).unwrap_or_default();
                for tok in body.split_ascii_whitespace().skip(1) {
                    same_as_std(tok);
                    assert!(plain_decimal(tok).is_some(), "{}: `{tok}`", path.display());
                    checked += 1;
                }
            }
        }
        // The ten fixture captures hold 487,140 channel values.
        assert!(checked > 400_000, "only {checked} values checked");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4000))]
        #[test]
        fn decimal_strings_agree(
            negative in any::<bool>(),
            int in "[0-9]{0,12}",
            frac in proptest::option::of("[0-9]{0,12}"),
        ) {
            let tok = format!(
                "{}{int}{}",
                if negative { "-" } else { "" },
                frac.map(|f| format!(".{f}")).unwrap_or_default()
            );
            same_as_std(&tok);
        }

        #[test]
        fn printed_floats_agree(v in any::<f64>(), places in 0usize..10) {
            same_as_std(&format!("{v:.places$}"));
            same_as_std(&format!("{v}"));
            same_as_std(&format!("{v:e}"));
            same_as_std(&format!("{v:.places$e}"));
        }

        #[test]
        fn words_split_as_the_standard_library_does(line in "[ \\t\\x0c0-9a-zé.-]{0,40}") {
            let ours: Vec<&str> = words(&line).collect();
            let std: Vec<&str> = line.split_ascii_whitespace().collect();
            prop_assert_eq!(ours, std);
        }

        #[test]
        fn lines_split_at_each_line_ending(text in "[a\\r\\né ]{0,30}") {
            // A line ends at `\n`, `\r` or `\r\n`; a last line needs no ending.
            let mut expected = Vec::new();
            let mut from = 0;
            let bytes = text.as_bytes();
            while from < bytes.len() {
                let mut end = from;
                while end < bytes.len() && bytes[end] != b'\n' && bytes[end] != b'\r' {
                    end += 1;
                }
                expected.push((from, &text[from..end]));
                from = if bytes.get(end..end + 2) == Some(b"\r\n") { end + 2 } else { end + 1 };
            }
            prop_assert_eq!(split_lines(&text).collect::<Vec<_>>(), expected);
        }

        #[test]
        fn exponent_forms_agree(
            mantissa in "-?[0-9]{1,8}(\\.[0-9]{0,8})?",
            exponent in "[eE][+-]?[0-9]{1,3}",
        ) {
            same_as_std(&format!("{mantissa}{exponent}"));
        }
    }
}
