//! The build as a loop over its steps: each step is one stage (or a pass between stages, such as
//! the one that gathers every capture's clips), run on what the steps before it left in the
//! [`BuildState`]. The loop decides which steps a run reaches (`--through`, and in probe mode the
//! first stage whose output is missing), and reports and records every stage's run. Adding a
//! stage is a [`Step`] and its line in [`STAGES`] or [`SINKS`]; what a stage caches goes through
//! [`crate::stage::CachedStage`].

use std::collections::{BTreeMap, BTreeSet};

use rayon::prelude::*;

use super::{
    BuildError, BuildOptions, Item, MotionIndex, Stage, StageRun, Workspace, add_counts, capture,
    capture_run, items_pending_stage, label_check, load_shared, motions, sinks, source, synthetic,
    text,
};
use crate::config::Config;
use crate::stages::{ingest, mirror};
use motionforge_core::base::{DropReason, Dropped, Reject, Tally};
use motionforge_sources::annotate::span::Note;
use motionforge_sources::clip::Clip;

/// One step of the build.
pub(super) trait Step: Sync {
    /// The stage the step runs (the first, for a step that runs two); `None` for a pass between
    /// stages, which every run reaches.
    fn stage(&self) -> Option<Stage>;

    /// False for the stages only a build runs (write, report): `plan` works theirs out from the
    /// table's stamp and the files on disk.
    fn probes(&self) -> bool {
        true
    }

    /// Runs the step on the build so far; the runs of the stages it ran.
    fn run(&self, build: &mut BuildState<'_, '_>) -> Result<Vec<StageRun>, BuildError>;
}

/// A step: its stage, whether `plan` runs it, and the [`BuildState`] method that runs it.
macro_rules! step {
    ($name:ident, $stage:expr, probes: $probes:expr, $method:ident, $doc:literal) => {
        #[doc = $doc]
        struct $name;

        impl Step for $name {
            fn stage(&self) -> Option<Stage> {
                $stage
            }

            fn probes(&self) -> bool {
                $probes
            }

            fn run(&self, build: &mut BuildState<'_, '_>) -> Result<Vec<StageRun>, BuildError> {
                build.$method()
            }
        }
    };
}

step!(IngestAndSegment, Some(Stage::Ingest), probes: true, ingest_and_segment,
    "Ingest and segment, capture by capture; each clip's split.");
step!(Label, Some(Stage::Label), probes: true, label,
    "Body-part labels of the clips' texts.");
step!(Paraphrase, Some(Stage::Paraphrase), probes: true, paraphrase,
    "Paraphrases of the clips' texts.");
step!(Plan, Some(Stage::Plan), probes: true, plan_texts,
    "Task plans of the single actions' texts.");
step!(MirrorCopies, Some(Stage::Mirror), probes: true, mirror,
    "Mirrored copies, capture by capture.");
step!(Gather, None, probes: true, gather,
    "The per-capture caches pruned; every capture's clips, drops, notes and rejects in one sorted list.");
step!(PairCheck, Some(Stage::PairCheck), probes: true, pair_check,
    "The optional LLM check of the texts of the pairs compose will sample.");
step!(Compose, Some(Stage::Compose), probes: true, compose,
    "Synthetic pairs, with their plausibility.");
step!(LabelCheck, Some(Stage::LabelCheck), probes: true, label_check,
    "Real clips whose motion contradicts their text; left out with `label_check.drop`.");
step!(Tabulate, None, probes: true, tabulate,
    "The table's stamp, and what the build report and the write stage say of its rows.");
step!(Write, Some(Stage::Write), probes: false, write,
    "Shards, manifest, card, normalisation statistics.");
step!(Report, Some(Stage::Report), probes: false, report,
    "The statistics report of the written shards.");

/// The build's stages up to the table, in order.
pub(super) const STAGES: [&dyn Step; 9] = [
    &IngestAndSegment,
    &Label,
    &Paraphrase,
    &Plan,
    &MirrorCopies,
    &Gather,
    &PairCheck,
    &Compose,
    &LabelCheck,
];

/// The build's steps from the table on: the sinks.
pub(super) const SINKS: [&dyn Step; 3] = [&Tabulate, &Write, &Report];

/// Runs every one of `steps` the build reaches: those of stages up to `--through`, in probe mode
/// only those `plan` runs, and none of a stage after the first one whose output is missing
/// (probe mode). Every stage's run is reported as finished and kept for the build report and
/// ledger.
pub(super) fn run_steps(
    build: &mut BuildState<'_, '_>,
    steps: &[&dyn Step],
) -> Result<(), BuildError> {
    for step in steps {
        if let Some(stage) = step.stage() {
            let reached = stage <= build.through
                && build.blocked.is_none()
                && (step.probes() || !build.probe);
            if !reached {
                continue;
            }
        }
        for run in step.run(build)? {
            build
                .options
                .progress
                .stage_finished(&run.stage, run.ran as u64, run.reused as u64);
            build.stages.push(run);
        }
    }
    Ok(())
}

/// The clips as a build of `config` would write them, and where their frames are: every stage
/// up to the table run (reusing the stage cache), nothing written but cache entries.
pub(super) fn run_stages<'a, 'o>(
    config: &'a Config,
    options: &'o BuildOptions,
) -> Result<BuildState<'a, 'o>, BuildError> {
    let mut build = BuildState::open(config, options, false)?;
    run_steps(&mut build, &STAGES)?;
    Ok(build)
}

/// What a build carries from stage to stage: what every stage shares, each capture's item, the
/// clips once gathered, and what each stage did.
pub(super) struct BuildState<'a, 'o> {
    pub(super) config: &'a Config,
    pub(super) options: &'o BuildOptions,
    /// Plan mode: nothing that is not cached runs.
    pub(super) probe: bool,
    /// The last stage to run.
    pub(super) through: Stage,
    /// The dataset folder.
    pub(super) output: std::path::PathBuf,
    pub(super) files: Vec<source::CaptureFile>,
    pub(super) shared: capture::Shared<'a>,
    /// Where the held clips' frames are read from.
    pub(super) motions: motions::MotionSource,
    /// One per capture file, in discovery order (empty once gathered).
    items: Vec<Item>,
    /// What each stage did; in probe mode, a whole-set stage (label, compose) whose output is not
    /// cached counts what it would run.
    pub(super) stages: Vec<StageRun>,
    /// What the LLM stages ask with, once one of them has run.
    llm: Option<text::LlmContext>,
    /// What the text stages did.
    pub(super) text: text::TextOutcome,
    /// Every capture's clips, once gathered.
    pub(super) gathered: Gathered,
    /// In probe mode: the first stage whose output is not cached.
    pub(super) blocked: Option<Stage>,
    /// Text pairs the pair check said no to.
    vetoed: synthetic::Vetoes,
    /// What the LLM pair check did.
    pub(super) pair_check: crate::stages::augment::AugmentReport,
    /// What the compose stage did.
    pub(super) compose: crate::stages::compose::ComposeReport,
    /// What the label check found, and the rows it left out.
    pub(super) label_check: sinks::LabelFindings,
    /// The table as it will be written (unless an earlier stage is blocked).
    pub(super) table: Option<sinks::Tabulated>,
    /// What the write and report stages did.
    pub(super) written: sinks::Written,
}

/// How an LLM stage asks: the build's LLM context in `llm` (opened on first use), and whether it
/// may send requests (not offline, not in probe mode).
fn asks<'s>(
    llm: &'s mut Option<text::LlmContext>,
    shared: &'s capture::Shared<'_>,
    options: &'s BuildOptions,
    probe: bool,
) -> Result<text::TextRequests<'s>, BuildError> {
    Ok(text::TextRequests {
        llm: text::llm_context(llm, shared)?,
        shared,
        offline: options.offline || probe,
        progress: &options.progress,
    })
}

/// Every clip of the captures, originals and mirrors, with where their frames are, and what
/// the stages dropped, noted and rejected, in their report order.
#[derive(Default)]
pub(super) struct Gathered {
    pub(super) clips: Vec<Clip>,
    pub(super) index: MotionIndex,
    pub(super) rejects: Vec<Reject>,
    pub(super) drops_by_reason: Tally<DropReason>,
    pub(super) drops: Vec<Dropped>,
    pub(super) unmapped_labels: BTreeMap<String, usize>,
    pub(super) notes: Vec<Note>,
}

impl<'a, 'o> BuildState<'a, 'o> {
    /// The workspace (its stage cache cleared by `--force`), the checked word lists, the capture
    /// files, and what every stage shares: profiles, annotations, frame-rate tables, motion types
    /// and remembered file digests.
    pub(super) fn open(
        config: &'a Config,
        options: &'o BuildOptions,
        probe: bool,
    ) -> Result<BuildState<'a, 'o>, BuildError> {
        let output = config.dataset_dir();
        let workspace = if probe {
            Workspace::probing(&output)
        } else {
            Workspace::new(&output)
        };
        if options.force && !probe {
            let _ = std::fs::remove_dir_all(workspace.root().join("cache"));
        }
        motionforge_language::parts::lexicon::check_lexicon()?;
        motionforge_language::compose_text::check_words()?;
        motionforge_llm::paraphrase::check_words()?;
        let files = source::discover(config)?;
        // `--force` trusts nothing remembered: every capture is read and hashed again.
        let shared = load_shared(config, workspace, options.force && !probe)?;
        let motions = shared.motions();
        Ok(BuildState {
            config,
            options,
            probe,
            through: options.through.unwrap_or(Stage::Report),
            output,
            files,
            shared,
            motions,
            items: Vec::new(),
            stages: Vec::new(),
            llm: None,
            text: text::TextOutcome::default(),
            gathered: Gathered::default(),
            blocked: None,
            vetoed: Default::default(),
            pair_check: Default::default(),
            compose: Default::default(),
            label_check: Default::default(),
            table: None,
            written: Default::default(),
        })
    }

    /// Ingest and segment, capture by capture on all cores; then each clip's split, by capture,
    /// set before labelling so every later copy (mirror, pair) inherits it. In probe mode, a
    /// capture whose ingest or segment output is not cached blocks what follows.
    fn ingest_and_segment(&mut self) -> Result<Vec<StageRun>, BuildError> {
        let progress = &self.options.progress;
        progress.stage_started(ingest::NAME, self.files.len() as u64);
        let shared = &self.shared;
        let mut items: Vec<Item> = self
            .files
            .par_iter()
            .map(|file| {
                let item = capture::segment_capture(shared, file);
                progress.advanced(ingest::NAME, 1);
                item
            })
            .collect::<Result<_, _>>()?;
        std::mem::take(&mut self.shared.digests).save(&self.shared.workspace)?;
        self.blocked = items_pending_stage(&items);
        let splits = crate::stages::split::Splits::from_config(self.config)?;
        for clip in items.iter_mut().flat_map(|i| i.clips.iter_mut()) {
            splits.assign(clip);
        }
        let mut runs = vec![capture_run(&items, Stage::Ingest)];
        if self.through >= Stage::Segment {
            runs.push(capture_run(&items, Stage::Segment));
        }
        self.items = items;
        Ok(runs)
    }

    /// Runs a text stage with how it asks (the LLM context, opened on first use, and this build's
    /// options), the capture items, what the text stages did so far and where frames are read.
    fn text_stage<R>(
        &mut self,
        stage: impl FnOnce(
            text::TextRequests<'_>,
            &mut [Item],
            &mut text::TextOutcome,
            &motions::MotionSource,
        ) -> Result<R, BuildError>,
    ) -> Result<R, BuildError> {
        let asks = asks(&mut self.llm, &self.shared, self.options, self.probe)?;
        stage(asks, &mut self.items, &mut self.text, &self.motions)
    }

    /// Part labels of the clips' texts; in probe mode, blocked when their assignment is not
    /// cached.
    fn label(&mut self) -> Result<Vec<StageRun>, BuildError> {
        let (run, assigned) =
            self.text_stage(|asks, items, text, motions| text::label(asks, motions, items, text))?;
        if !assigned {
            self.blocked = Some(Stage::Label);
        }
        Ok(vec![run])
    }

    /// Paraphrases of the clips' texts, when `paraphrases.enabled`.
    fn paraphrase(&mut self) -> Result<Vec<StageRun>, BuildError> {
        if !self.config.paraphrases.enabled {
            return Ok(Vec::new());
        }
        let run = self.text_stage(|asks, items, text, _| text::paraphrase(asks, items, text))?;
        Ok(vec![run])
    }

    /// Task plans of the single actions' texts, when `task_plans.enabled`.
    fn plan_texts(&mut self) -> Result<Vec<StageRun>, BuildError> {
        if !self.config.task_plans.enabled {
            return Ok(Vec::new());
        }
        let run = self.text_stage(|asks, items, text, _| text::plan(asks, items, text))?;
        Ok(vec![run])
    }

    /// Mirrored copies of every capture's labelled clips, on all cores, when `mirror.enabled`;
    /// in probe mode, blocked when a capture's copies are not cached.
    fn mirror(&mut self) -> Result<Vec<StageRun>, BuildError> {
        if !self.config.mirror.enabled {
            return Ok(Vec::new());
        }
        let progress = &self.options.progress;
        let shared = &self.shared;
        progress.stage_started(mirror::NAME, self.items.len() as u64);
        self.items
            .par_iter_mut()
            .map(|item| {
                let done = capture::mirror_capture(shared, item);
                progress.advanced(mirror::NAME, 1);
                done
            })
            .collect::<Result<Vec<()>, _>>()?;
        if self.items.iter().any(|i| i.pending == Some(Stage::Mirror)) {
            self.blocked = Some(Stage::Mirror);
        }
        Ok(vec![capture_run(&self.items, Stage::Mirror)])
    }

    /// Removes from the stage cache the per-capture outputs and frame chunks no capture of this
    /// build uses.
    fn prune_stage_caches(&self) {
        let workspace = &self.shared.workspace;
        for stage in [Stage::Ingest, Stage::Segment, Stage::Mirror] {
            let live: BTreeSet<String> = self
                .items
                .iter()
                .filter_map(|i| i.fingerprint(stage))
                .map(str::to_string)
                .collect();
            workspace.prune(stage.name(), &live);
        }

        // Frame chunks that no held clip points to belong to outputs that are gone.
        let live: BTreeSet<String> = self
            .items
            .iter()
            .flat_map(|i| i.refs.iter().chain(&i.mirrored_refs))
            .flat_map(|r| r.chunks())
            .map(|(_, fingerprint)| fingerprint.to_string())
            .collect();
        workspace.prune(motions::SEGMENT_CHUNKS, &live);
        for retired in motions::RETIRED_CHUNKS {
            workspace.prune(retired, &BTreeSet::new());
        }
    }

    /// The per-capture stage caches pruned; then every capture's clips, drops, notes and rejects
    /// (with the text stages' rejects) taken, each sorted so the outputs do not depend on
    /// scheduling or glob order.
    fn gather(&mut self) -> Result<Vec<StageRun>, BuildError> {
        self.prune_stage_caches();
        let items = std::mem::take(&mut self.items);
        // Exactly: grown by doubling, the list kept up to a third of its capacity (a `Clip` is a few
        // hundred bytes before its strings) unused until the synthetic pairs are added.
        let mut clips: Vec<Clip> =
            Vec::with_capacity(items.iter().map(|i| i.clips.len() + i.mirrored.len()).sum());
        let mut index = MotionIndex::new();
        let mut rejects: Vec<Reject> = Vec::new();
        let mut drops_by_reason = Tally::new();
        let mut drops: Vec<Dropped> = Vec::new();
        let mut unmapped_labels = BTreeMap::new();
        let mut notes: Vec<Note> = Vec::new();
        for item in items {
            for (clip, at) in item
                .clips
                .iter()
                .zip(item.refs)
                .chain(item.mirrored.iter().zip(item.mirrored_refs))
            {
                index.insert(motions::key(clip), at);
            }
            clips.extend(item.clips);
            clips.extend(item.mirrored);
            rejects.extend(item.rejects);
            drops_by_reason.merge(&item.segment.drops);
            drops.extend(item.segment.dropped);
            add_counts(&mut unmapped_labels, item.segment.unmapped);
            notes.extend(item.segment.notes);
        }
        notes.extend(source::annotation_notes(
            self.config,
            &self.shared.annotations,
            &self.files,
        ));

        rejects.extend(self.text.rejects.iter().cloned());
        let mut rejects: Vec<Reject> = rejects.into_iter().map(Reject::bounded).collect();
        // Row order: by clip id, so the table does not depend on scheduling or glob order.
        clips.sort_by(|a, b| {
            a.clip_id
                .cmp(&b.clip_id)
                .then(a.capture.path.cmp(&b.capture.path))
        });
        rejects.sort_by(|a, b| (&a.file, a.line, &a.stage).cmp(&(&b.file, b.line, &b.stage)));
        notes.sort();
        drops.sort();
        self.gathered = Gathered {
            clips,
            index,
            rejects,
            drops_by_reason,
            drops,
            unmapped_labels,
            notes,
        };
        Ok(Vec::new())
    }

    /// The LLM pair check, when `synthetic.enabled` and `synthetic.llm_check`: the text pairs of
    /// the pairs compose will sample, asked through the response cache.
    fn pair_check(&mut self) -> Result<Vec<StageRun>, BuildError> {
        let synthetic = &self.config.synthetic;
        if !synthetic.enabled || !synthetic.llm_check {
            return Ok(Vec::new());
        }
        let asks = asks(&mut self.llm, &self.shared, self.options, self.probe)?;
        let (vetoed, report) = synthetic::llm_vetoes(asks, &self.gathered.clips)?;
        let run = text::augment_run(Stage::PairCheck.name(), &report);
        self.vetoed = vetoed;
        self.pair_check = report;
        Ok(vec![run])
    }

    /// Synthetic pairs from the labelled originals and mirrors; in probe mode, blocked when the
    /// pairs are not cached.
    fn compose(&mut self) -> Result<Vec<StageRun>, BuildError> {
        // No LLM stage follows: the response cache is let go before the build's peak.
        self.llm = None;
        let progress = &self.options.progress;
        let gathered = &mut self.gathered;
        progress.stage_started(crate::stages::compose::NAME, gathered.clips.len() as u64);
        let composed = synthetic::compose(
            &self.shared,
            &self.motions,
            &mut gathered.clips,
            &mut gathered.index,
            &self.vetoed,
        )?;
        if let Some((report, run)) = composed {
            self.compose = report;
            return Ok(vec![run]);
        }
        // Probe mode, not cached: the pairs a build would compose (sampling is cheap, composing
        // is not), so `plan` counts them as `build` does.
        let clips: Vec<&Clip> = gathered.clips.iter().collect();
        let (_, sampled) = crate::stages::compose::sample(
            &clips,
            &self.config.synthetic,
            self.config.dataset.seed,
            |c| c.split.clone(),
        );
        self.blocked = Some(Stage::Compose);
        Ok(vec![StageRun {
            stage: crate::stages::compose::NAME.into(),
            items: sampled.sampled,
            ran: sampled.sampled,
            reused: 0,
        }])
    }

    /// The check of texts against motions, dropping contradicting rows with `label_check.drop`;
    /// in probe mode, blocked when a capture's findings are not cached.
    fn label_check(&mut self) -> Result<Vec<StageRun>, BuildError> {
        let gathered = &mut self.gathered;
        let Some((contradictions, run)) = label_check::contradicting_labels(
            &self.shared,
            &self.motions,
            &gathered.clips,
            &gathered.index,
            &self.options.progress,
        )?
        else {
            self.blocked = Some(Stage::LabelCheck);
            return Ok(Vec::new());
        };
        let dropped = if self.config.label_check.drop {
            label_check::drop_contradicting(&mut gathered.clips, &contradictions)
        } else {
            0
        };
        self.label_check = sinks::LabelFindings {
            contradictions,
            dropped,
        };
        Ok(vec![run])
    }
}
