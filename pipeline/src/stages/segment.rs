//! `segment`: a capture and its annotation in, clips out. Each labelled range becomes a
//! `real_single` clip; where simultaneous labels overlap, the overlap also becomes a `real_pair`.
//! Clips are resampled, filtered by length, typed by the taxonomy and given goals. Every dropped
//! segment is counted by reason.

use std::collections::BTreeMap;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::annotate::overlap::overlaps;
use crate::annotate::span::{CaptureAnnotation, Hand, Note, Span, Time};
use crate::annotate::taxonomy::TypeMap;
use crate::build::{Fingerprint, Stamp};
use crate::clip::{Capture, Clip, SourceKind};
use crate::config::SegmentConfig;
use crate::motion::canonical::{canonical_frame, dataset_positions, hand_joint};
use crate::motion::{BodyPart, Profile};

/// Stage name.
pub const NAME: &str = "segment";
/// Bump when the stage's output for the same input changes.
pub const VERSION: u32 = 2;

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
    pub drops: BTreeMap<String, usize>,
    /// Labels of single clips that map to no motion type, with counts.
    pub unmapped: BTreeMap<String, usize>,
    /// Annotation quirks met (from the reader and from segmentation).
    pub notes: Vec<Note>,
}

/// Fingerprint of segmenting one capture.
pub fn fingerprint(ingest: &str, input: &SegmentInput<'_>, types_config: &impl Serialize) -> Stamp {
    Fingerprint::new(NAME, VERSION)
        .text("ingest output", ingest)
        .text("annotation format", input.kind)
        .json("annotations", input.annotation)
        .json("config sources.segment", input.config)
        .json("motion types", types_config)
        .json("config dataset.fps", &input.fps)
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

/// Runs the stage on one capture.
pub fn run(input: &SegmentInput<'_>) -> SegmentOutput {
    let mut out = SegmentOutput {
        notes: input.annotation.notes.clone(),
        ..SegmentOutput::default()
    };
    let capture = input.capture;
    let len = capture.motion.num_frames() as u64;
    let fps = capture.capture.fps;
    let offset = input.config.timeline_offset_frames as i64;
    let trim = (input.config.trim_start_seconds * fps).ceil() as u64;
    let drop_labels: Vec<String> = input
        .config
        .drop_labels
        .iter()
        .map(|l| normalize_label(l))
        .collect();
    let mut drop = |reason: &str| *out.drops.entry(reason.to_string()).or_insert(0) += 1;

    let mut kept: Vec<Kept<'_>> = Vec::new();
    for span in &input.annotation.spans {
        if drop_labels.contains(&normalize_label(&span.label))
            || drop_labels.contains(&normalize_label(&span.raw_text))
        {
            drop("dropped_label");
            continue;
        }
        let start =
            span.start.to_frame(fps, len) + if span.start == Time::End { 0 } else { offset };
        let mut end = span.end.to_frame(fps, len) + if span.end == Time::End { 0 } else { offset };
        if end > len as i64 {
            out.notes.push(Note::new(
                "end_clamped",
                format!(
                    "`{}` ends at frame {end}, past the capture's {len} frames (clamped)",
                    span.raw_text
                ),
            ));
            end = len as i64;
        }
        if start >= len as i64 {
            drop("past_end");
            continue;
        }
        let start = (start.max(0) as u64).max(trim);
        let end = end.max(0) as u64;
        if end <= start {
            drop(if start == trim && trim > 0 {
                "trimmed"
            } else {
                "empty_range"
            });
            continue;
        }
        kept.push(Kept { span, start, end });
    }

    let positions_cache = ClipMaker { input };
    let mut clips: Vec<Clip> = Vec::new();
    for k in &kept {
        match positions_cache.single(k) {
            Ok(clip) => {
                if clip.motion_type.is_none() {
                    *out.unmapped.entry(clip.labels[0].clone()).or_insert(0) += 1;
                }
                clips.push(clip);
            }
            Err(reason) => drop(reason),
        }
    }
    if input.annotation.simultaneous {
        let ranges: Vec<(u64, u64)> = kept.iter().map(|k| (k.start, k.end)).collect();
        let exclude: Vec<String> = input
            .config
            .pair_exclude
            .iter()
            .map(|w| normalize_label(w))
            .collect();
        for o in overlaps(&ranges) {
            if o.members.len() > input.config.max_simultaneous {
                drop("too_many_simultaneous");
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
                drop("excluded_pair");
                continue;
            }
            match positions_cache.pair(&members, o.start, o.end) {
                Ok(clip) => clips.push(clip),
                Err(reason) => drop(reason),
            }
        }
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
    out.clips = clips;
    out
}

struct ClipMaker<'a, 'b> {
    input: &'a SegmentInput<'b>,
}

impl ClipMaker<'_, '_> {
    fn base(&self, start: u64, end: u64) -> Result<Clip, &'static str> {
        let input = self.input;
        let capture = input.capture;
        let motion = capture
            .motion
            .slice(start as usize, end as usize)
            .resample(input.fps);
        let seconds = motion.num_frames() as f64 / input.fps;
        if seconds < input.config.min_seconds {
            return Err("too_short");
        }
        if seconds > input.config.max_seconds {
            return Err("too_long");
        }
        Ok(Clip {
            clip_id: format!("{}/{}:{start}-{end}", capture.capture.source, capture.stem),
            kind: SourceKind::RealSingle,
            capture: capture.capture.clone(),
            frame_range: (start, end),
            mirrored: false,
            split: String::new(),
            action: String::new(),
            text: String::new(),
            texts: Vec::new(),
            labels: Vec::new(),
            annotation: input.kind.to_string(),
            annotation_origin: input.annotation.origin.clone(),
            attributes: input.annotation.attributes.clone(),
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
            motion,
        })
    }

    fn single(&self, k: &Kept<'_>) -> Result<Clip, &'static str> {
        let mut clip = self.base(k.start, k.end)?;
        let span = k.span;
        clip.annotation_origin = format!("{}#{}", clip.annotation_origin, span.id);
        clip.action = span.label.clone();
        clip.text = span.raw_text.clone();
        clip.texts = vec![span.raw_text.clone()];
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
                locomotion,
                hand_goal,
                grasp.map(|g| g.clamp(k.start as i64, k.end as i64 - 1) as u64 - k.start),
            );
        }
        Ok(clip)
    }

    fn pair(&self, members: &[&Kept<'_>], start: u64, end: u64) -> Result<Clip, &'static str> {
        let mut clip = self.base(start, end)?;
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
        Ok(clip)
    }

    /// Pelvis and hand goals in the clip's first-frame canonical frame.
    fn goals(&self, clip: &mut Clip, locomotion: bool, hand_goal: bool, grasp_frame: Option<u64>) {
        let profile = self.input.profile;
        let n = clip.motion.num_joints();
        let frames = clip.motion.num_frames();
        if frames == 0 || !(locomotion || hand_goal) {
            return;
        }
        let positions = dataset_positions(&clip.motion, profile);
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
