//! `mirror`: every clip in, its mirrored copy out: motion and skeleton reflected, and
//! everything that carries a side (texts, labels, motion type, hand, goals) swapped with it.

use serde::{Deserialize, Serialize};

use crate::motions::MotionRef;
use crate::stage::{CachedStage, CaptureStage, Versioned};
use motionforge_core::base::{Reject, RejectReason, Stamp};
use motionforge_core::motion::{BoundProfiles, MirrorPlan, OffsetPolicy, ProfileSpec};
use motionforge_language::parts::PartSet;
use motionforge_language::text::mirror_text;
use motionforge_llm::plans::mirror_paraphrases;
use motionforge_sources::annotate::span::Hand;
use motionforge_sources::annotate::taxonomy::Taxonomy;
use motionforge_sources::clip::Clip;

/// Stage name.
pub const NAME: &str = "mirror";
/// Bump when the stage's output for the same input changes.
pub const VERSION: u32 = 6;

/// The stage as the runner caches it: a capture's mirrored clips without their frames (made
/// from the originals' when read), and where those are.
pub(crate) struct Mirror;

impl Versioned for Mirror {
    const STAGE: crate::Stage = crate::Stage::Mirror;
    const VERSION: u32 = VERSION;
}

impl CachedStage for Mirror {
    type Output = (MirrorOutput, Vec<MotionRef>);

    fn take_rejects(output: &mut Self::Output) -> Vec<Reject> {
        std::mem::take(&mut output.0.rejects)
    }
}

impl CaptureStage for Mirror {}

/// Fingerprint of mirroring one segmented capture.
pub fn fingerprint(
    segment_fingerprint: &str,
    profile: &ProfileSpec,
    types: &impl Serialize,
    offsets: OffsetPolicy,
) -> Stamp {
    Mirror::fingerprint()
        .text("labelled clips", segment_fingerprint)
        .json("skeleton profile", profile)
        .json("motion types", types)
        .json("offsets", &offsets)
        .stamp()
}

/// The stage's output for one ingest item.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct MirrorOutput {
    /// Mirrored clips.
    pub clips: Vec<Clip>,
    /// Clips that could not be mirrored.
    pub rejects: Vec<Reject>,
}

/// Mirrored copies of `clips` (bone offsets mirrored too, so each copy is on the mirrored
/// skeleton); a clip whose skeleton the profile cannot mirror is rejected.
pub fn run(clips: &[Clip], profile: &ProfileSpec, taxonomy: &Taxonomy) -> MirrorOutput {
    run_with(
        clips,
        profile,
        &BoundProfiles::default(),
        taxonomy,
        OffsetPolicy::Mirror,
    )
}

/// [`run`], binding the profile through `bound` (shared by the calls of one build).
pub fn run_with(
    clips: &[Clip],
    profile: &ProfileSpec,
    bound: &BoundProfiles,
    taxonomy: &Taxonomy,
    offsets: OffsetPolicy,
) -> MirrorOutput {
    let mut out = Vec::with_capacity(clips.len());
    let mut rejects = Vec::new();
    for clip in clips {
        let skeleton = &clip.skeleton;
        let plan = bound
            .bind(profile, skeleton)
            .map_err(|e| e.to_string())
            .and_then(|bound| {
                MirrorPlan::from_profile(skeleton, &bound).map_err(|e| e.to_string())
            });
        match plan {
            Ok(plan) => {
                let mut copy = mirror_clip(clip, taxonomy);
                copy.skeleton = plan.skeleton_of_mirror(&clip.skeleton, offsets);
                out.push(copy);
            }
            Err(message) => rejects.push(Reject {
                stage: NAME.to_string(),
                file: clip.capture.path.clone(),
                line: None,
                frame: None,
                reason: RejectReason::Mirror,
                message: format!("cannot mirror clip `{}`: {message}", clip.clip_id),
            }),
        }
    }
    MirrorOutput {
        clips: out,
        rejects,
    }
}

/// The mirrored copy of one clip: everything that carries a side swaps with the motion (whose
/// frames are `plan.mirror` of the clip's; the caller sets the copy's skeleton, which is the
/// clip's until then). The attributes are left as they
/// are: they describe the source capture as annotated (file-name fields, sidecar ids), which a
/// mirror does not change.
pub fn mirror_clip(clip: &Clip, taxonomy: &Taxonomy) -> Clip {
    Clip {
        clip_id: format!("{}:m", clip.clip_id),
        mirrored: !clip.mirrored,
        action: mirror_text(&clip.action),
        text: mirror_text(&clip.text),
        texts: clip.texts.iter().map(|t| mirror_text(t)).collect(),
        labels: clip.labels.iter().map(|t| mirror_text(t)).collect(),
        motion_type: clip
            .motion_type
            .as_deref()
            .map(|t| taxonomy.mirror_of(t).unwrap_or(t).to_string()),
        hand: clip.hand.map(Hand::mirrored),
        goal_pelvis: clip.goal_pelvis.map(|[x, y]| [-x, y]),
        goal_hand: clip.goal_hand.map(|[x, y, z]| [-x, y, z]),
        parts: clip.parts.map(PartSet::mirrored),
        paraphrases: mirror_paraphrases(&clip.paraphrases),
        ..clip.clone()
    }
}
