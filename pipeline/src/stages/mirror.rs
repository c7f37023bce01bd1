//! `mirror`: every clip in, its mirrored copy out: motion reflected on the same skeleton, and
//! everything that carries a side (texts, labels, attributes) swapped with it.

use serde::{Deserialize, Serialize};

use crate::build::{Fingerprint, Reject};
use crate::clip::Clip;
use crate::motion::{MirrorPlan, OffsetPolicy, ProfileSpec};
use crate::text::mirror_text;

/// Stage name.
pub const NAME: &str = "mirror";
/// Bump when the stage's output for the same input changes.
pub const VERSION: u32 = 1;

/// Fingerprint of mirroring one ingest item.
pub fn fingerprint(ingest_fingerprint: &str, profile: &ProfileSpec) -> String {
    Fingerprint::new(NAME, VERSION)
        .text(ingest_fingerprint)
        .json(profile)
        .finish()
}

/// The stage's output for one ingest item.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct MirrorOutput {
    /// Mirrored clips.
    pub clips: Vec<Clip>,
    /// Clips that could not be mirrored.
    pub rejects: Vec<Reject>,
}

/// Mirrored copies of `clips`; a clip whose skeleton the profile cannot mirror is rejected.
pub fn run(clips: &[Clip], profile: &ProfileSpec) -> MirrorOutput {
    let mut out = Vec::with_capacity(clips.len());
    let mut rejects = Vec::new();
    for clip in clips {
        let skeleton = &clip.motion.skeleton;
        let plan = profile
            .bind(skeleton)
            .map_err(|e| e.to_string())
            .and_then(|bound| {
                MirrorPlan::from_profile(skeleton, &bound).map_err(|e| e.to_string())
            });
        match plan {
            Ok(plan) => out.push(mirror_clip(clip, &plan)),
            Err(message) => rejects.push(Reject {
                stage: NAME.to_string(),
                file: clip.capture.path.clone(),
                line: None,
                frame: None,
                reason: "mirror".to_string(),
                message: format!("cannot mirror clip `{}`: {message}", clip.clip_id),
            }),
        }
    }
    MirrorOutput {
        clips: out,
        rejects,
    }
}

/// The mirrored copy of one clip.
pub fn mirror_clip(clip: &Clip, plan: &MirrorPlan) -> Clip {
    Clip {
        clip_id: format!("{}:m", clip.clip_id),
        mirrored: !clip.mirrored,
        action: mirror_text(&clip.action),
        text: mirror_text(&clip.text),
        attributes: clip
            .attributes
            .iter()
            .map(|(k, v)| (k.clone(), mirror_text(v)))
            .collect(),
        motion: plan.mirror(&clip.motion, OffsetPolicy::Keep),
        ..clip.clone()
    }
}
