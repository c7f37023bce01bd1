//! `segment`: a capture and its annotation in, clips out. Each labelled range becomes a
//! `real_single` clip; where simultaneous labels overlap, the overlap also becomes a `real_pair`.
//! Clips are resampled, filtered by length, typed by the taxonomy and given goals. Every dropped
//! segment is counted by reason.

use std::collections::BTreeMap;
use std::sync::Arc;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::config::SegmentConfig;
use crate::motions::MotionRef;
use crate::stage::{CachedStage, CaptureStage, Versioned};
use motionforge_core::base::{DropReason, Dropped, Stamp, Tally};
use motionforge_core::motion::bvh::excerpt;
use motionforge_core::motion::canonical::{canonical_frame, dataset_positions, hand_joint};
use motionforge_core::motion::{BodyPart, Motion, Profile};
use motionforge_sources::annotate::overlap::overlaps;
use motionforge_sources::annotate::span::{CaptureAnnotation, Hand, Note, NoteKind, Span, Time};
use motionforge_sources::annotate::taxonomy::TypeMap;
use motionforge_sources::clip::{Capture, Clip, LoadedClip, SourceKind, Split};

/// Stage name.
pub const NAME: &str = "segment";
/// Bump when the stage's output for the same input changes.
pub const VERSION: u32 = 6;

/// Seconds by which a capture's duration may differ from the duration its annotation states
/// (BABEL's `dur`) before the difference is noted: a wrong frame rate or another file under the
/// same name, not a rounding.
pub const DURATION_TOLERANCE: f64 = 0.25;

/// What the stage reads for one capture.
pub struct SegmentInput<'a> {
    /// The parsed capture.
    pub capture: &'a Capture,
    /// Its annotation.
    pub annotation: &'a CaptureAnnotation,
    /// Annotation format name.
    pub kind: &'a str,
    /// Segmentation rules of the source.
    pub config: &'a SegmentConfig,
    /// Label to motion-type mapping.
    pub types: &'a TypeMap,
    /// The capture's bound skeleton profile.
    pub profile: &'a Profile,
    /// Dataset frame rate.
    pub fps: f64,
}

/// The stage's output for one capture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct SegmentOutput {
    /// Clips, in range order.
    pub clips: Vec<Clip>,
    /// Dropped segments by reason.
    pub drops: Tally<DropReason>,
    /// Labels of single clips that map to no motion type, with counts.
    pub unmapped: BTreeMap<String, usize>,
    /// Annotation quirks met (from the reader and from segmentation).
    pub notes: Vec<Note>,
    /// Every dropped segment, with its file and reason (`drops` counts them).
    pub dropped: Vec<Dropped>,
}

/// The stage as the runner caches it: a capture's clips without their frames, and where the
/// frames went (frame chunks stored as the clips are made).
pub(crate) struct Segment;

impl Versioned for Segment {
    const STAGE: crate::Stage = crate::Stage::Segment;
    const VERSION: u32 = VERSION;
}

impl CachedStage for Segment {
    type Output = (SegmentOutput, Vec<MotionRef>);
}

impl CaptureStage for Segment {}

/// Fingerprint of segmenting one capture.
pub fn fingerprint(
    ingest: &str,
    annotation: &CaptureAnnotation,
    kind: &str,
    config: &SegmentConfig,
    fps: f64,
    types_config: &impl Serialize,
) -> Stamp {
    Segment::fingerprint()
        .text("ingest output", ingest)
        .text("annotation format", kind)
        .json("annotations", annotation)
        .json("config sources.segment", config)
        .json("motion types", types_config)
        .json("config dataset.fps", &fps)
        .stamp()
}

/// Lowercase, `-` and `_` as spaces, single spaces: how labels are compared with config lists.
pub fn normalize_label(s: &str) -> String {
    s.to_lowercase()
        .replace(['-', '_'], " ")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

struct Kept<'a> {
    span: &'a Span,
    start: u64,
    end: u64,
}

/// Runs the stage on one capture, the clips with their frames.
pub fn run(input: &SegmentInput<'_>) -> SegmentOutput {
    run_loaded(input).0
}

/// [`run`], keeping every clip's frames: the output and the motions of its clips, in order.
pub fn run_loaded(input: &SegmentInput<'_>) -> (SegmentOutput, Vec<Motion>) {
    let mut motions = Vec::new();
    let out = run_with(input, |_, motion| {
        motions.push(motion);
        Ok::<(), std::convert::Infallible>(())
    });
    match out {
        Ok(out) => (out, motions),
        Err(never) => match never {},
    }
}

/// Runs the stage on one capture, handing each clip's frames to `take_frames` as soon as the clip
/// is made (in the order of the output's clips), so a caller can move them to disk: however many
/// clips a capture yields, only one's frames are held at a time.
pub fn run_with<E>(
    input: &SegmentInput<'_>,
    mut take_frames: impl FnMut(&Clip, Motion) -> Result<(), E>,
) -> Result<SegmentOutput, E> {
    let mut out = SegmentOutput {
        notes: input
            .annotation
            .notes
            .iter()
            .chain(&input.capture.notes)
            .cloned()
            .collect(),
        ..SegmentOutput::default()
    };
    let timeline = Timeline::of(input);
    if let Some(note) = timeline.duration_mismatch(input) {
        out.notes.push(note);
    }
    let mut drops = Drops {
        file: input.capture.capture.path.clone(),
        dropped: Vec::new(),
    };
    let kept = keep_spans(input, &timeline, &mut drops, &mut out.notes);
    let maker = ClipMaker {
        input,
        capture: std::sync::Arc::new(input.capture.capture.clone()),
    };
    let mut clips: Vec<Clip> = Vec::new();
    for k in &kept {
        match maker.single(k) {
            Ok(LoadedClip { clip, motion }) => {
                if clip.motion_type.is_none() {
                    *out.unmapped.entry(clip.labels[0].clone()).or_insert(0) += 1;
                }
                take_frames(&clip, motion)?;
                clips.push(clip);
            }
            Err(reason) => drops.drop(reason, &k.span.raw_text, Some((k.start, k.end))),
        }
    }
    if input.annotation.simultaneous {
        make_pairs(&maker, &kept, &mut drops, &mut clips, &mut take_frames)?;
    }
    // Identical ranges (two labels on the same frames) must not share an id.
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    for clip in &mut clips {
        let n = seen.entry(clip.clip_id.clone()).or_insert(0);
        *n += 1;
        if *n > 1 {
            clip.clip_id = format!("{}~{n}", clip.clip_id);
        }
    }
    out.drops = drops.dropped.iter().map(|d| d.reason).collect();
    out.dropped = drops.dropped;
    out.clips = clips;
    Ok(out)
}

/// A capture's frames as the annotation's times map onto them: its length and rate, the frames
/// before the annotation's time zero, and the frames trimmed from its start.
struct Timeline {
    len: u64,
    fps: f64,
    offset: i64,
    trim: u64,
}

impl Timeline {
    fn of(input: &SegmentInput<'_>) -> Timeline {
        let fps = input.capture.capture.fps;
        Timeline {
            len: input.capture.motion.num_frames() as u64,
            fps,
            offset: input.config.timeline_offset_frames as i64,
            trim: (input.config.trim_start_seconds * fps).ceil() as u64,
        }
    }

    /// A note when the capture's duration is not the one its annotation states.
    fn duration_mismatch(&self, input: &SegmentInput<'_>) -> Option<Note> {
        let Timeline {
            len, fps, offset, ..
        } = *self;
        let stated = input.annotation.duration.filter(|_| fps > 0.0)?;
        let actual = len.saturating_sub(offset.max(0) as u64) as f64 / fps;
        ((stated - actual).abs() > DURATION_TOLERANCE).then(|| {
            Note::new(
                NoteKind::DurationMismatch,
                format!(
                    "`{}`: {actual:.3} s long ({len} frames at {fps} fps), but {} says {stated} s; \
                     check the frame rate (fps_override, fps_table) or the file",
                    input.capture.capture.path, input.annotation.origin
                ),
            )
        })
    }

    /// The frames a span covers, clamped to the capture (noted) and past the trim; or why it is
    /// dropped.
    fn frames_of(&self, span: &Span, notes: &mut Vec<Note>) -> Result<(u64, u64), DropReason> {
        let len = self.len;
        let shift = |t: Time| match t {
            Time::End | Time::BeforeEnd { .. } => 0,
            _ => self.offset,
        };
        let start = span.start.to_frame(self.fps, len) + shift(span.start);
        let mut end = span.end.to_frame(self.fps, len) + shift(span.end);
        if end > len as i64 {
            notes.push(Note::new(
                NoteKind::EndClamped,
                format!(
                    "`{}` ends at frame {end}, past the capture's {len} frames (clamped)",
                    span.raw_text
                ),
            ));
            end = len as i64;
        }
        if start >= len as i64 {
            return Err(DropReason::PastEnd);
        }
        let start = (start.max(0) as u64).max(self.trim);
        let end = end.max(0) as u64;
        if end <= start {
            return Err(if start == self.trim && self.trim > 0 {
                DropReason::Trimmed
            } else {
                DropReason::EmptyRange
            });
        }
        Ok((start, end))
    }
}

/// The segments dropped from one capture file, in the order they were dropped.
struct Drops {
    file: String,
    dropped: Vec<Dropped>,
}

impl Drops {
    fn drop(&mut self, reason: DropReason, text: &str, frames: Option<(u64, u64)>) {
        self.dropped.push(Dropped {
            file: self.file.clone(),
            reason,
            text: excerpt(text),
            frames,
        });
    }
}

/// The annotation's spans that become clips, in annotation order: spans with a caption, a label
/// not on the drop list and frames in the capture, each identical row kept once.
fn keep_spans<'a>(
    input: &'a SegmentInput<'_>,
    timeline: &Timeline,
    drops: &mut Drops,
    notes: &mut Vec<Note>,
) -> Vec<Kept<'a>> {
    let capture = input.capture;
    let drop_labels: Vec<String> = input
        .config
        .drop_labels
        .iter()
        .map(|l| normalize_label(l))
        .collect();
    let mut kept: Vec<Kept<'_>> = Vec::new();
    // Identical rows (same range, text, label and details) would give identical clips: each is
    // kept once, the others dropped as duplicates with one note per merged group.
    let mut merged: BTreeMap<String, usize> = BTreeMap::new();
    // Per kept span: how many rows it stands for, and the first few row ids.
    let mut groups: Vec<(usize, Vec<String>)> = Vec::new();
    for span in &input.annotation.spans {
        if span.raw_text.trim().is_empty() || span.label.trim().is_empty() {
            drops.drop(DropReason::EmptyText, &span.id, None);
            notes.push(Note::new(
                NoteKind::EmptyText,
                format!(
                    "`{}`: annotation `{}` has an empty caption; skipped",
                    capture.capture.path,
                    excerpt(&span.id)
                ),
            ));
            continue;
        }
        // Whatever the annotation format: one text must not make the labeller and tagger work
        // (and hold memory) in proportion to a damaged file.
        let limit = motionforge_language::caption::MAX_CAPTION_CHARS;
        if span.raw_text.chars().count() > limit || span.label.chars().count() > limit {
            drops.drop(DropReason::LongText, &span.raw_text, None);
            continue;
        }
        if drop_labels.contains(&normalize_label(&span.label))
            || drop_labels.contains(&normalize_label(&span.raw_text))
        {
            drops.drop(DropReason::DroppedLabel, &span.raw_text, None);
            continue;
        }
        let (start, end) = match timeline.frames_of(span, notes) {
            Ok(frames) => frames,
            Err(reason) => {
                drops.drop(reason, &span.raw_text, None);
                continue;
            }
        };
        let key = row_key(span, start, end);
        match merged.get(&key) {
            Some(&at) => {
                let (count, ids) = &mut groups[at];
                *count += 1;
                if ids.len() < 5 {
                    ids.push(span.id.clone());
                }
                drops.drop(DropReason::Duplicate, &span.raw_text, Some((start, end)));
            }
            None => {
                merged.insert(key, kept.len());
                groups.push((1, vec![span.id.clone()]));
                kept.push(Kept { span, start, end });
            }
        }
    }
    note_duplicates(&capture.capture.path, &kept, &groups, notes);
    kept
}

/// What makes two annotation rows identical: range, text, label and details.
fn row_key(span: &Span, start: u64, end: u64) -> String {
    serde_json::to_string(&(
        start,
        end,
        &span.raw_text,
        &span.label,
        &span.categories,
        &span.motion_type,
        &span.hand,
        &span.object,
        &span.grasp,
    ))
    .unwrap_or_default()
}

/// One note per kept span that stands for several identical rows (`groups`: how many, the first
/// few row ids).
fn note_duplicates(
    path: &str,
    kept: &[Kept<'_>],
    groups: &[(usize, Vec<String>)],
    notes: &mut Vec<Note>,
) {
    for (k, (count, ids)) in kept.iter().zip(groups) {
        if *count > 1 {
            let shown: Vec<String> = ids.iter().map(|i| excerpt(i)).collect();
            notes.push(Note::new(
                NoteKind::DuplicateAnnotation,
                format!(
                    "`{}`: `{}` on frames {}-{} appears {count} times (rows {}{}); kept once",
                    path,
                    excerpt(&k.span.raw_text),
                    k.start,
                    k.end,
                    shown.join(", "),
                    if *count > ids.len() { ", ..." } else { "" },
                ),
            ));
        }
    }
}

/// The `real_pair` clips of overlapping kept spans: overlaps of too many actions, or with an
/// excluded label, are dropped.
fn make_pairs<E>(
    maker: &ClipMaker<'_, '_>,
    kept: &[Kept<'_>],
    drops: &mut Drops,
    clips: &mut Vec<Clip>,
    take_frames: &mut impl FnMut(&Clip, Motion) -> Result<(), E>,
) -> Result<(), E> {
    let config = maker.input.config;
    let ranges: Vec<(u64, u64)> = kept.iter().map(|k| (k.start, k.end)).collect();
    let exclude: Vec<String> = config
        .pair_exclude
        .iter()
        .map(|w| normalize_label(w))
        .collect();
    for o in overlaps(&ranges) {
        let texts = || {
            o.members
                .iter()
                .map(|&i| kept[i].span.raw_text.as_str())
                .collect::<Vec<_>>()
                .join(" + ")
        };
        if o.members.len() > config.max_simultaneous {
            drops.drop(
                DropReason::TooManySimultaneous,
                &texts(),
                Some((o.start, o.end)),
            );
            continue;
        }
        let members: Vec<&Kept<'_>> = o.members.iter().map(|&i| &kept[i]).collect();
        let excluded = members.iter().any(|m| {
            let words = normalize_label(&m.span.label);
            exclude
                .iter()
                .any(|x| words.split(' ').any(|w| w == x) || &words == x)
        });
        if excluded {
            drops.drop(DropReason::ExcludedPair, &texts(), Some((o.start, o.end)));
            continue;
        }
        match maker.pair(&members, o.start, o.end) {
            Ok(LoadedClip { clip, motion }) => {
                take_frames(&clip, motion)?;
                clips.push(clip);
            }
            Err(reason) => drops.drop(reason, &texts(), Some((o.start, o.end))),
        }
    }
    Ok(())
}

struct ClipMaker<'a, 'b> {
    input: &'a SegmentInput<'b>,
    /// The capture's reference, shared by every clip cut from it.
    capture: std::sync::Arc<motionforge_sources::clip::CaptureRef>,
}

impl ClipMaker<'_, '_> {
    fn base(&self, start: u64, end: u64) -> Result<LoadedClip, DropReason> {
        let input = self.input;
        let capture = input.capture;
        // The length is known before any frame is made: a wrong rate must cost a drop, not an
        // allocation for the duration it implies.
        let source_frames = (end.min(capture.motion.num_frames() as u64) - start.min(end)) as usize;
        let frames = Motion::resampled_frames(source_frames, capture.capture.fps, input.fps);
        let seconds = frames as f64 / input.fps;
        if seconds < input.config.min_seconds {
            return Err(DropReason::TooShort);
        }
        if seconds > input.config.max_seconds {
            return Err(DropReason::TooLong);
        }
        let motion = capture
            .motion
            .slice(start as usize, end as usize)
            .resample(input.fps);
        let clip = Clip {
            clip_id: format!("{}/{}:{start}-{end}", capture.capture.source, capture.stem),
            kind: SourceKind::RealSingle,
            capture: std::sync::Arc::clone(&self.capture),
            frame_range: (start, end),
            mirrored: false,
            split: Split::default(),
            action: String::new(),
            text: String::new(),
            texts: Vec::new(),
            labels: Vec::new(),
            annotation: input.kind.to_string(),
            annotation_origin: input.annotation.origin.clone(),
            attributes: input.annotation.attributes.clone().into(),
            profile: capture.profile.clone(),
            motion_type: None,
            hand: None,
            object: None,
            goal_pelvis: None,
            goal_hand: None,
            parts: None,
            label_source: None,
            paraphrases: Vec::new(),
            composed_from: Vec::new(),
            composed_parts: Vec::new(),
            plausibility: None,
            skeleton: Arc::clone(&motion.skeleton),
        };
        Ok(LoadedClip { clip, motion })
    }

    fn single(&self, k: &Kept<'_>) -> Result<LoadedClip, DropReason> {
        let LoadedClip { mut clip, motion } = self.base(k.start, k.end)?;
        let span = k.span;
        clip.annotation_origin = format!("{}#{}", clip.annotation_origin, span.id);
        clip.action = span.label.clone();
        clip.text = span.raw_text.clone();
        clip.texts = std::iter::once(&span.raw_text)
            .chain(&span.alternatives)
            .cloned()
            .collect();
        clip.labels = vec![span.label.clone()];
        clip.hand = span.hand;
        clip.object = span.object.clone();
        let kind = span.motion_type.as_deref().unwrap_or(&span.label);
        if let Some(t) = self
            .input
            .types
            .map(kind)
            .or_else(|| self.input.types.map(&span.label))
        {
            clip.motion_type = Some(t.name.clone());
            let (locomotion, hand_goal) = (t.locomotion, t.hand_goal);
            let grasp = span.grasp.map(|g| {
                g.to_frame(clip.capture.fps, k.end)
                    + self.input.config.timeline_offset_frames as i64
            });
            self.goals(
                &mut clip,
                &motion,
                locomotion,
                hand_goal,
                grasp.map(|g| g.clamp(k.start as i64, k.end as i64 - 1) as u64 - k.start),
            );
        }
        Ok(LoadedClip { clip, motion })
    }

    fn pair(&self, members: &[&Kept<'_>], start: u64, end: u64) -> Result<LoadedClip, DropReason> {
        let LoadedClip { mut clip, motion } = self.base(start, end)?;
        clip.kind = SourceKind::RealPair;
        clip.clip_id = format!("{}:pair", clip.clip_id);
        let ids: Vec<&str> = members.iter().map(|m| m.span.id.as_str()).collect();
        clip.annotation_origin = format!("{}#{}", clip.annotation_origin, ids.join("+"));
        clip.texts = members.iter().map(|m| m.span.raw_text.clone()).collect();
        clip.labels = members.iter().map(|m| m.span.label.clone()).collect();
        clip.action = clip.labels.join(" + ");
        clip.text = match clip.texts.as_slice() {
            [a, b] => format!("{a} and {b} at the same time"),
            texts => format!("{} at the same time", texts.join(", ")),
        };
        Ok(LoadedClip { clip, motion })
    }

    /// Pelvis and hand goals in the clip's first-frame canonical frame.
    fn goals(
        &self,
        clip: &mut Clip,
        motion: &Motion,
        locomotion: bool,
        hand_goal: bool,
        grasp_frame: Option<u64>,
    ) {
        let profile = self.input.profile;
        let n = motion.num_joints();
        let frames = motion.num_frames();
        if frames == 0 || !(locomotion || hand_goal) {
            return;
        }
        let positions = dataset_positions(motion, profile);
        let Some(frame) = canonical_frame(&positions[..n], profile) else {
            return;
        };
        if locomotion {
            let p = frame.apply(positions[(frames - 1) * n + profile.root]);
            clip.goal_pelvis = Some([p.x, p.y]);
        }
        if hand_goal && let Some(hand) = clip.hand {
            // Grasp frame at the capture rate -> index in the resampled clip.
            let at = grasp_frame
                .map(|g| ((g as f64 / clip.capture.fps) * self.input.fps).round() as usize)
                .unwrap_or(frames - 1)
                .min(frames - 1);
            let joint = |part| hand_joint(profile, part).map(|j| positions[at * n + j]);
            let p: Option<DVec3> = match hand {
                Hand::Left => joint(BodyPart::LeftArm),
                Hand::Right => joint(BodyPart::RightArm),
                Hand::Both => joint(BodyPart::LeftArm)
                    .zip(joint(BodyPart::RightArm))
                    .map(|(a, b)| (a + b) / 2.0),
            };
            if let Some(p) = p {
                let c = frame.apply(p);
                clip.goal_hand = Some([c.x, c.y, c.z]);
            }
        }
    }
}
