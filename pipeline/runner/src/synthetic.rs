//! The runner's side of the pair check and the compose stage: the texts of sampled pairs asked
//! of the LLM, the compose stage's stamp over the clips it pairs (and the pair check's vetoes),
//! its cached output, and the composites' frames added to the motion index.

use std::collections::BTreeSet;

use super::capture::Shared;
use super::motions::{self, MotionIndex, MotionSource};
use super::{BuildError, Stage, StageRun, label, text};
use crate::stage::{CachedStage, Versioned};
use motionforge_sources::clip::Clip;

/// The compose stage's cache entry: the synthetic clips (their skeletons in the table), where
/// their frames come from, and each distinct skeleton once.
type ComposeEntry = (
    crate::stages::compose::ComposeOutput,
    Vec<motions::MotionRef>,
    motionforge_sources::clip::SkeletonTable,
);

/// The compose stage as the runner caches it: the whole build's synthetic pairs at once (one
/// entry, key `*`).
pub(crate) struct Compose;

impl Versioned for Compose {
    const STAGE: Stage = Stage::Compose;
    const VERSION: u32 = crate::stages::compose::VERSION;
}

impl CachedStage for Compose {
    type Output = ComposeEntry;
}

/// Text pairs the LLM said cannot be done at once (normalised first and second text).
pub(super) type Vetoes = BTreeSet<(String, String)>;

/// Runs the compose stage over `clips` (adding plausibility metrics and the synthetic pairs),
/// leaving out the pairs whose texts are `vetoed`; `None` in probe mode when its output is not
/// cached.
pub(super) fn compose(
    shared: &Shared<'_>,
    motions: &MotionSource,
    clips: &mut Vec<Clip>,
    index: &mut MotionIndex,
    vetoed: &Vetoes,
) -> Result<Option<(crate::stages::compose::ComposeReport, StageRun)>, BuildError> {
    let config = shared.config;
    let all: Vec<&Clip> = clips.iter().collect();
    // The clips without frames, and where their frames are: together, the stage's input.
    let encoded = motionforge_core::base::encoded_sha256(&(&all, &*index), "clips to compose")?;
    let stamp = Compose::fingerprint()
        .text("clips", &encoded)
        .json("config synthetic", &config.synthetic)
        .json("config dataset.seed", &config.dataset.seed)
        .json("llm pair check", vetoed)
        .stamp();
    let composed = shared.workspace.run_stage::<Compose, BuildError>(
        "*",
        &stamp,
        |_| true,
        || {
            let mut refs: Vec<motions::MotionRef> = Vec::new();
            let out = crate::stages::compose::run(
                &all,
                &config.synthetic,
                config.dataset.seed,
                |c| c.split.clone(),
                |c| shared.profile_of(c),
                |c| motions.motion_of(c, index),
                |a, b| {
                    let key = (
                        label::normalize_text(&a.text),
                        label::normalize_text(&b.text),
                    );
                    vetoed.contains(&key)
                },
                |clip, recipe| {
                    // The composite's skeleton is a copy made when its source was read (a
                    // mirror's); held clips share one copy of each.
                    shared.skeletons.share(&mut clip.skeleton);
                    let source = |c: &Clip| {
                        index
                            .get(&motions::key(c))
                            .cloned()
                            .ok_or_else(|| BuildError::NoMotion {
                                clip: c.clip_id.clone(),
                            })
                    };
                    refs.push(motions::MotionRef::Composed {
                        first: Box::new(source(recipe.first)?),
                        first_parts: recipe.first_parts,
                        second: Box::new(source(recipe.second)?),
                        second_parts: recipe.second_parts,
                        start: match recipe.trim {
                            motionforge_core::motion::compose::Trim::Start => None,
                            motionforge_core::motion::compose::Trim::At(s) => Some(s as u32),
                        },
                        frames: recipe.frames as u32,
                    });
                    Ok::<(), BuildError>(())
                },
            )?;
            let mut out = out;
            // Stored with each distinct skeleton once, not once per synthetic clip.
            let skeletons = motionforge_sources::clip::SkeletonTable::take_all(&mut out.clips);
            Ok::<_, BuildError>((out, refs, skeletons))
        },
    )?;
    let Some(((mut composed, refs, skeletons), ran)): Option<(ComposeEntry, bool)> = composed
    else {
        return Ok(None);
    };
    if !skeletons.give_all(&mut composed.clips) || refs.len() != composed.clips.len() {
        return Err(BuildError::InconsistentCache {
            stage: Compose::NAME,
        });
    }
    shared
        .workspace
        .prune(Compose::NAME, &BTreeSet::from([stamp.fingerprint]));
    let run = StageRun {
        stage: Compose::NAME.into(),
        items: composed.report.sampled,
        ran: if ran { composed.report.sampled } else { 0 },
        reused: if ran { 0 } else { composed.report.sampled },
    };
    for (clip, at) in composed.clips.iter().zip(refs) {
        index.insert(motions::key(clip), at);
    }
    let mut composed_clips = composed.clips;
    for clip in &mut composed_clips {
        shared.skeletons.share(&mut clip.skeleton);
    }
    // Exactly: growing by doubling left up to half the clip list (about 1 KB per clip) unused.
    clips.reserve_exact(composed_clips.len());
    clips.extend(composed_clips);
    clips.sort_by(|a, b| {
        a.clip_id
            .cmp(&b.clip_id)
            .then(a.capture.path.cmp(&b.capture.path))
    });
    Ok(Some((composed.report, run)))
}

/// The pair check: the text pairs of the pairs the compose stage will sample, asked of the LLM
/// (through the response cache); the pairs it says cannot be done at once, and what asking did.
pub(super) fn llm_vetoes(
    asks: text::TextRequests<'_>,
    clips: &[Clip],
) -> Result<(Vetoes, crate::stages::augment::AugmentReport), BuildError> {
    let config = asks.shared.config;
    let mut report = crate::stages::augment::AugmentReport::default();
    let clips: Vec<&Clip> = clips.iter().collect();
    let texts =
        crate::stages::compose::texts_to_check(&clips, &config.synthetic, config.dataset.seed);
    let (prompts, asker) = asks
        .llm
        .requests(config, Stage::PairCheck, asks.offline, asks.progress);
    let vetoed = crate::stages::augment::incompatible_pairs(&texts, prompts, asker, &mut report)
        .map_err(text::augment_error)?;
    Ok((vetoed, report))
}
