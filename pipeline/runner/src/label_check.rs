//! The label check: real clips whose motion contradicts what their text claims, measured once
//! per capture and cached.

use std::collections::{BTreeMap, BTreeSet};

use rayon::prelude::*;

use super::capture::Shared;
use super::motions::{self, MotionIndex, MotionSource};
use super::{BuildError, Stage, StageRun, sha256_hex};
use crate::stage::{CachedStage, Versioned};
use motionforge_core::progress::ProgressSink;
use motionforge_sources::clip::Clip;

/// The label check as the runner caches it: the findings of one capture's claiming clips (key:
/// the capture path; stage-cache folder `label_check`).
struct LabelCheck;

impl Versioned for LabelCheck {
    const STAGE: Stage = Stage::LabelCheck;
    /// Bump when `quality::contradictions` changes.
    const VERSION: u32 = 1;
}

impl CachedStage for LabelCheck {
    type Output = Vec<motionforge_core::quality::Contradiction>;
}

/// The stage-cache folder of the label check before it was a stage of its own (emptied).
const RETIRED_FOLDER: &str = "label-check";

/// What the label check found: the contradictions and the stage's run.
pub(super) type Findings = (Vec<motionforge_core::quality::Contradiction>, StageRun);

/// The real single clips (mirrors included) whose motion contradicts what their text says
/// (`quality::contradictions`), in `clip_id` order. Only clips whose text makes a claim the
/// motion can be measured for are read. The findings are cached per capture, keyed by those
/// clips (texts, skeletons, where their frames are) and the mirror's offset policy, so a rebuild
/// reads no frames; captures are checked on all cores. `None` in probe mode when a capture's
/// findings are not cached.
pub(super) fn contradicting_labels(
    shared: &Shared<'_>,
    motions: &MotionSource,
    clips: &[Clip],
    index: &MotionIndex,
    progress: &ProgressSink,
) -> Result<Option<Findings>, BuildError> {
    let mut by_capture: BTreeMap<(&str, &str), Vec<&Clip>> = BTreeMap::new();
    for clip in clips.iter().filter(|c| {
        c.kind == motionforge_sources::clip::SourceKind::RealSingle
            && motionforge_core::quality::claims(&c.text)
                != motionforge_core::quality::Claims::default()
    }) {
        by_capture
            .entry((clip.capture.source.as_str(), clip.capture.path.as_str()))
            .or_default()
            .push(clip);
    }
    // The skeleton profiles the clips are measured with.
    let profiles = sha256_hex(&serde_json::to_vec(&shared.specs).unwrap_or_default());
    progress.stage_started(LabelCheck::NAME, by_capture.len() as u64);
    let checked = by_capture
        .par_iter()
        // Each thread reads with its own memory of recent chunks.
        .map_init(
            || motions.sibling(),
            |motions, ((_, path), held)| {
                let refs: Vec<Option<&motions::MotionRef>> =
                    held.iter().map(|c| index.get(&motions::key(c))).collect();
                let encoded =
                    motionforge_core::base::encoded_sha256(&(held, &refs), "clips to check")?;
                let stamp = LabelCheck::fingerprint()
                    .text("clips", &encoded)
                    .json("config mirror.offsets", &shared.config.mirror.offsets)
                    .text("skeleton profiles", &profiles)
                    .stamp();
                let found = shared.workspace.run_stage::<LabelCheck, BuildError>(
                    path,
                    &stamp,
                    |_| true,
                    || {
                        let mut out = Vec::new();
                        for clip in held {
                            let Some(profile) = shared.profile_of(clip) else {
                                continue;
                            };
                            let motion = motions.motion_of(clip, index)?;
                            let positions = motionforge_core::motion::canonical::dataset_positions(
                                &motion, &profile,
                            );
                            out.extend(motionforge_core::quality::contradictions(
                                &clip.clip_id,
                                &clip.text,
                                &positions,
                                motion.num_joints(),
                                motion.fps,
                                &profile,
                            ));
                        }
                        Ok(out)
                    },
                )?;
                progress.advanced(LabelCheck::NAME, 1);
                Ok::<_, BuildError>((stamp.fingerprint, found))
            },
        )
        .collect::<Result<Vec<_>, BuildError>>()?;
    let live: BTreeSet<String> = checked.iter().map(|(f, _)| f.clone()).collect();
    shared.workspace.prune(LabelCheck::NAME, &live);
    shared.workspace.prune(RETIRED_FOLDER, &BTreeSet::new());
    let mut run = StageRun {
        stage: LabelCheck::NAME.into(),
        items: checked.len(),
        ran: 0,
        reused: 0,
    };
    let mut out: Vec<motionforge_core::quality::Contradiction> = Vec::new();
    for (_, found) in checked {
        let Some((found, ran)) = found else {
            return Ok(None);
        };
        if ran {
            run.ran += 1;
        } else {
            run.reused += 1;
        }
        out.extend(found);
    }
    out.sort_by(|a, b| {
        a.clip_id
            .cmp(&b.clip_id)
            .then_with(|| a.claim.cmp(&b.claim))
    });
    Ok(Some((out, run)))
}

/// Leaves out of `clips` the ones in `contradictions` and the synthetic pairs made from them;
/// how many rows that removed.
pub(super) fn drop_contradicting(
    clips: &mut Vec<Clip>,
    contradictions: &[motionforge_core::quality::Contradiction],
) -> usize {
    if contradictions.is_empty() {
        return 0;
    }
    let wrong: BTreeSet<&str> = contradictions.iter().map(|c| c.clip_id.as_str()).collect();
    let before = clips.len();
    clips.retain(|c| {
        !wrong.contains(c.clip_id.as_str())
            && !c.composed_from.iter().any(|id| wrong.contains(id.as_str()))
    });
    before - clips.len()
}
