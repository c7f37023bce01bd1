//! Text stages over the whole dataset (each unique text is asked once, however many clips share
//! it): part labels, paraphrases, task plans. They run between segmentation and mirroring, so
//! mirrors inherit mirrored labels and paraphrases. What they ask with (the prompt templates and
//! the LLM response cache) is opened once per build, when a stage first needs it
//! ([`LlmContext`]), and shared with the pair check.

use motionforge_core::base::RejectReason;
use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};

use super::capture::{Item, Shared};
use super::motions::MotionSource;
use super::{BuildError, Reject, Stage, StageRun};
use crate::config::{Config, Labeller};
use crate::stage::{CachedStage, Versioned};
use crate::stages::augment::{self, Asking, AugmentError, AugmentReport};
use crate::stages::label::{self, LabelInput, LabelReport, normalize_text};
use motionforge_language::parts::PartSet;
use motionforge_llm::cache::ResponseCache;
use motionforge_llm::plans::PlanStep;
use motionforge_sources::clip::{Clip, LoadedClip, SourceKind};

/// Bump when label assignment changes for the same inputs. 2: flagged LLM answers follow
/// `part_labels.on_invalid` (the embedded labeller by default) instead of being used.
const LABEL_VERSION: u32 = 2;

/// The label stage as the runner caches it: every clip's body parts and their labeller, for
/// the whole build at once (one entry, key `*`).
pub(crate) struct Labels;

impl Versioned for Labels {
    const STAGE: Stage = Stage::Label;
    const VERSION: u32 = LABEL_VERSION;
}

impl CachedStage for Labels {
    type Output = ClipLabels;
}

/// What the text stages produced.
#[derive(Debug, Default)]
pub(super) struct TextOutcome {
    /// Labelling counts.
    pub(super) label: LabelReport,
    /// Paraphrase counts and skips.
    pub(super) paraphrase: AugmentReport,
    /// Plan counts and skips.
    pub(super) plan: AugmentReport,
    /// Task plans by text.
    pub(super) plans: BTreeMap<String, Vec<PlanStep>>,
    /// Texts whose LLM request failed after its last retry, and plans still invalid after repair.
    pub(super) rejects: Vec<Reject>,
}

fn text_reject(stage: &str, text: &str, reason: RejectReason, message: String) -> Reject {
    Reject {
        stage: stage.to_string(),
        file: format!("text: {text}"),
        line: None,
        frame: None,
        reason,
        message,
    }
}

/// Per-clip labels as cached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub(crate) struct ClipLabels {
    by_clip: BTreeMap<
        String,
        (
            Option<PartSet>,
            Option<motionforge_language::parts::LabelSources>,
        ),
    >,
    report: LabelReport,
}

/// The LLM response cache, when the config can use one (an `[llm]` section or the LLM labeller).
fn open_cache(shared: &Shared<'_>) -> Result<Option<ResponseCache>, BuildError> {
    let config = shared.config;
    let wanted = config.llm.is_some() || config.part_labels.labeller == Labeller::Llm;
    if !wanted {
        return Ok(None);
    }
    let path = config.llm_cache_path();
    ResponseCache::open(&path)
        .map(Some)
        .map_err(|source| BuildError::LlmCache { path, source })
}

/// What the LLM stages ask with: the prompt templates, the response cache and the client, each
/// made once per build.
pub(super) struct LlmContext {
    prompts: motionforge_llm::prompt::Prompts,
    cache: Option<ResponseCache>,
    connection: augment::Connection,
}

impl LlmContext {
    /// The config's prompt templates and its response cache (when it can use one).
    fn open(shared: &Shared<'_>) -> Result<LlmContext, BuildError> {
        Ok(LlmContext {
            prompts: shared.config.prompts()?,
            cache: open_cache(shared)?,
            connection: augment::Connection::default(),
        })
    }

    /// How `stage` asks: its prompts and where its requests go.
    pub(super) fn requests<'c>(
        &'c mut self,
        config: &'c Config,
        stage: Stage,
        offline: bool,
        progress: &'c motionforge_core::progress::ProgressSink,
    ) -> (&'c motionforge_llm::prompt::Prompts, augment::Asker<'c>) {
        let asker = augment::Asker {
            llm: config.llm.as_ref(),
            connection: &self.connection,
            offline,
            cache: self.cache.as_mut(),
            asking: Asking {
                stage: stage.name(),
                progress,
            },
        };
        (&self.prompts, asker)
    }
}

/// The opened [`LlmContext`] in `slot`, opening it on first use.
pub(super) fn llm_context<'s>(
    slot: &'s mut Option<LlmContext>,
    shared: &Shared<'_>,
) -> Result<&'s mut LlmContext, BuildError> {
    let context = match slot.take() {
        Some(context) => context,
        None => LlmContext::open(shared)?,
    };
    Ok(slot.insert(context))
}

/// What a text stage works with: the build's shared state, the LLM context, whether requests may
/// be sent, and where progress goes.
pub(super) struct TextRequests<'a> {
    pub(super) shared: &'a Shared<'a>,
    pub(super) llm: &'a mut LlmContext,
    pub(super) offline: bool,
    pub(super) progress: &'a motionforge_core::progress::ProgressSink,
}

/// Part labels: every unique text labelled once, then each clip's labels from its text and its
/// motion (one cached item for the whole dataset). The stage's run, and false in probe mode when
/// that assignment is not cached (the run then counts what a build would do).
pub(super) fn label(
    asks: TextRequests<'_>,
    motions: &MotionSource,
    items: &mut [Item],
    outcome: &mut TextOutcome,
) -> Result<(StageRun, bool), BuildError> {
    let shared = asks.shared;
    let config = shared.config;
    let mut report = LabelReport::default();
    let clips: Vec<&Clip> = items.iter().flat_map(|i| i.clips.iter()).collect();
    let (prompts, asker) = asks
        .llm
        .requests(config, Stage::Label, asks.offline, asks.progress);
    let input = LabelInput {
        config: &config.part_labels,
        llm: config.llm.as_ref(),
        connection: asker.connection,
        prompts,
        offline: asks.offline,
        progress: asks.progress,
    };
    let labels =
        label::label_texts(&clips, &input, asker.cache, &mut report).map_err(|e| match e {
            label::LabelError::Prompt(p) => BuildError::Prompt(p),
            other => BuildError::Labels(Box::new(other)),
        })?;
    let segment_fps: Vec<&str> = items
        .iter()
        .filter_map(|i| i.fingerprint(Stage::Segment))
        .collect();
    let stamp = Labels::fingerprint()
        .json("part labels", &labels)
        .json("segments", &segment_fps)
        .stamp();
    let n_clips = clips.len();
    let assigned = shared.workspace.run_stage::<Labels, BuildError>(
        "*",
        &stamp,
        |_| true,
        || assign_labels(shared, motions, items, &labels, &report),
    )?;
    let Some((assigned, ran)): Option<(ClipLabels, bool)> = assigned else {
        // Probe mode, not cached: what a build would run, so `plan` counts clips as `build` does.
        let run = StageRun {
            stage: Labels::NAME.into(),
            items: n_clips,
            ran: n_clips,
            reused: 0,
        };
        return Ok((run, false));
    };
    shared
        .workspace
        .prune(Labels::NAME, &BTreeSet::from([stamp.fingerprint]));
    for clip in items.iter_mut().flat_map(|i| i.clips.iter_mut()) {
        if let Some((parts, source)) = assigned.by_clip.get(&clip.clip_id) {
            clip.parts = *parts;
            clip.label_source = source.clone();
        }
    }
    // A request that failed after its last retry is a reject (the text fell back as configured);
    // an offline cache miss is not: it is what offline means.
    for (text, reason) in &report.missing {
        if reason.is_failure() {
            outcome.rejects.push(text_reject(
                Labels::NAME,
                text,
                RejectReason::LlmRequest,
                reason.to_string(),
            ));
        }
    }
    let run = StageRun {
        stage: Labels::NAME.into(),
        items: n_clips,
        ran: if ran { n_clips } else { report.requests },
        reused: if ran { 0 } else { n_clips },
    };
    // Requests, cache hits and the answers' checks are this build's; the rest of the report is the
    // cached assignment's.
    outcome.label = LabelReport {
        requests: report.requests,
        cache_hits: report.cache_hits,
        missing: report.missing,
        checks: report.checks,
        ..assigned.report
    };
    Ok((run, true))
}

/// One capture's labelled clips (id, parts, their sources), its label sources counted, and its
/// velocity agreement summed (value times clips, clips).
type CaptureLabels = (
    Vec<(
        String,
        (
            Option<PartSet>,
            Option<motionforge_language::parts::LabelSources>,
        ),
    )>,
    BTreeMap<String, usize>,
    (f64, usize),
);

/// Each clip's labels from the texts' `labels` and its motion, added to a copy of the texts'
/// `report`.
fn assign_labels(
    shared: &Shared<'_>,
    motions: &MotionSource,
    items: &[Item],
    labels: &BTreeMap<String, label::TextParts>,
    report: &LabelReport,
) -> Result<ClipLabels, BuildError> {
    // One capture's frames at a time (the velocity evidence needs the motions), captures on
    // all cores; the per-capture results are summed afterwards in capture order, so the
    // figures do not depend on scheduling.
    use rayon::prelude::*;
    let per_capture: Vec<CaptureLabels> = items
        .par_iter()
        .map_init(
            || motions.sibling(),
            |motions, item| label_capture(shared, motions, item, labels),
        )
        .collect::<Result<_, _>>()?;
    let mut report = report.clone();
    let mut by_clip = BTreeMap::new();
    let mut agreement = (0.0, 0usize);
    for (labelled, sources, capture_agreement) in per_capture {
        by_clip.extend(labelled);
        for (source, n) in sources {
            *report.sources.entry(source).or_insert(0) += n;
        }
        if capture_agreement.1 > 0 {
            let mean = capture_agreement.0 / capture_agreement.1 as f64;
            agreement.0 += mean * capture_agreement.1 as f64;
            agreement.1 += capture_agreement.1;
        }
    }
    if agreement.1 > 0 {
        report.velocity_agreement = Some((agreement.0 / agreement.1 as f64, agreement.1));
    }
    Ok(ClipLabels { by_clip, report })
}

/// The labels of one capture's clips, read with their frames.
fn label_capture(
    shared: &Shared<'_>,
    motions: &mut MotionSource,
    item: &Item,
    labels: &BTreeMap<String, label::TextParts>,
) -> Result<CaptureLabels, BuildError> {
    let mut labelled = Vec::with_capacity(item.clips.len());
    let mut sources = BTreeMap::new();
    // Per capture, summed in clip order as one call over the capture would.
    let mut capture_agreement = (0.0, 0usize);
    for (clip, at) in item.clips.iter().zip(&item.refs) {
        let mut full = LoadedClip {
            clip: clip.clone(),
            motion: motions.motion(at, &clip.profile)?,
        };
        let mut part = LabelReport::default();
        let one = std::slice::from_mut(&mut full);
        label::apply_labels(one, labels, |c| shared.profile_of(c), &mut part);
        let full = full.clip;
        for (source, n) in part.sources {
            *sources.entry(source).or_insert(0) += n;
        }
        if let Some((value, n)) = part.velocity_agreement {
            capture_agreement.0 += value * n as f64;
            capture_agreement.1 += n;
        }
        labelled.push((full.clip_id, (full.parts, full.label_source)));
    }
    Ok((labelled, sources, capture_agreement))
}

/// Paraphrases of every clip's caption (each unique text asked once).
pub(super) fn paraphrase(
    asks: TextRequests<'_>,
    items: &mut [Item],
    outcome: &mut TextOutcome,
) -> Result<StageRun, BuildError> {
    let config = asks.shared.config;
    let texts: BTreeSet<String> = items
        .iter()
        .flat_map(|i| i.clips.iter().map(|c| normalize_text(&c.text)))
        .collect();
    let mut report = AugmentReport::default();
    let (prompts, asker) =
        asks.llm
            .requests(config, Stage::Paraphrase, asks.offline, asks.progress);
    let found = augment::paraphrase(
        &texts,
        config.paraphrases.n,
        config.paraphrases.on_invalid,
        prompts,
        asker,
        &mut report,
    )
    .map_err(augment_error)?;
    for clip in items.iter_mut().flat_map(|i| i.clips.iter_mut()) {
        clip.paraphrases = found
            .get(&normalize_text(&clip.text))
            .cloned()
            .unwrap_or_default();
    }
    let run = augment_run(Stage::Paraphrase.name(), &report);
    outcome.paraphrase = report;
    Ok(run)
}

/// Task plans of every single action's text (each unique text asked once); plans still invalid
/// after their repair are rejects.
pub(super) fn plan(
    asks: TextRequests<'_>,
    items: &[Item],
    outcome: &mut TextOutcome,
) -> Result<StageRun, BuildError> {
    let texts: BTreeSet<String> = items
        .iter()
        .flat_map(|i| {
            i.clips
                .iter()
                .filter(|c| c.kind == SourceKind::RealSingle)
                .map(|c| normalize_text(&c.text))
        })
        .collect();
    let mut report = AugmentReport::default();
    let (prompts, asker) =
        asks.llm
            .requests(asks.shared.config, Stage::Plan, asks.offline, asks.progress);
    outcome.plans = augment::plan(&texts, prompts, asker, &mut report).map_err(augment_error)?;
    for (text, reason) in &report.rejected {
        outcome.rejects.push(text_reject(
            Stage::Plan.name(),
            text,
            RejectReason::InvalidPlan,
            reason.clone(),
        ));
    }
    let run = augment_run(Stage::Plan.name(), &report);
    outcome.plan = report;
    Ok(run)
}

/// A prompt error stays a prompt error (exit code 2); a server that is gone is an LLM error.
pub(super) fn augment_error(e: AugmentError) -> BuildError {
    match e {
        AugmentError::Prompt(p) => BuildError::Prompt(p),
        other => BuildError::Augment(Box::new(other)),
    }
}

/// An LLM stage's run: texts it covers, asked this build, answered from the cache.
pub(super) fn augment_run(stage: &str, report: &AugmentReport) -> StageRun {
    StageRun {
        stage: stage.into(),
        items: report.texts,
        // Texts, not requests: a plan's repair is a second request for the same text.
        ran: report.asked,
        reused: report.answered.saturating_sub(report.asked),
    }
}
