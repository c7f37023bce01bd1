//! The build as a loop over its steps: each step is one stage (or the pass between stages that
//! gathers every capture's clips), run on what the steps before it left in the [`BuildState`].
//! Adding a stage is a [`Step`] and its line in [`STEPS`]; what a stage caches goes through
//! [`crate::stage::CachedStage`]. The write and report stages, which only `build` runs (never
//! `plan`), follow in `write_and_report`.

use std::collections::{BTreeMap, BTreeSet};

use rayon::prelude::*;

use super::{
    BuildError, BuildOptions, BuildState, Gathered, Item, MotionIndex, Stage, Staged, Workspace,
    add_counts, capture, capture_run, items_pending_stage, load_shared, motions, source, synthetic,
    text,
};
use crate::config::Config;
use crate::stages::{ingest, mirror};
use motionforge_core::base::{Dropped, Reject, Tally};
use motionforge_sources::annotate::span::Note;
use motionforge_sources::clip::Clip;

/// One step of the build.
pub(super) trait Step: Sync {
    /// Runs the step on the build so far.
    fn run(&self, build: &mut BuildState<'_, '_>) -> Result<(), BuildError>;
}

/// Ingest and segment, capture by capture; each clip's split.
struct IngestAndSegment;
/// Body-part labels, paraphrases and task plans of the clips' texts.
struct TextStages;
/// Mirrored copies, capture by capture; the per-capture caches pruned.
struct MirrorCopies;
/// Every capture's clips, drops, notes and rejects in one sorted list.
struct Gather;
/// Synthetic pairs, with their plausibility and the optional LLM check.
struct Compose;

impl Step for IngestAndSegment {
    fn run(&self, build: &mut BuildState<'_, '_>) -> Result<(), BuildError> {
        build.ingest_and_segment()
    }
}

impl Step for TextStages {
    fn run(&self, build: &mut BuildState<'_, '_>) -> Result<(), BuildError> {
        build.text_stages()
    }
}

impl Step for MirrorCopies {
    fn run(&self, build: &mut BuildState<'_, '_>) -> Result<(), BuildError> {
        build.mirror()
    }
}

impl Step for Gather {
    fn run(&self, build: &mut BuildState<'_, '_>) -> Result<(), BuildError> {
        build.gather();
        Ok(())
    }
}

impl Step for Compose {
    fn run(&self, build: &mut BuildState<'_, '_>) -> Result<(), BuildError> {
        build.compose()
    }
}

/// The build's steps up to the write stage, in order.
pub(super) const STEPS: [&dyn Step; 5] = [
    &IngestAndSegment,
    &TextStages,
    &MirrorCopies,
    &Gather,
    &Compose,
];

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
            upstream_pending: false,
            stages: Vec::new(),
            text: text::TextOutcome::default(),
            gathered: Gathered::default(),
            blocked: None,
            compose: Default::default(),
            pair_check: Default::default(),
        })
    }

    /// Ingest and segment, capture by capture on all cores; then each clip's split, by capture,
    /// set before labelling so every later copy (mirror, pair) inherits it.
    fn ingest_and_segment(&mut self) -> Result<(), BuildError> {
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
        self.upstream_pending = items.iter().any(|i| i.pending.is_some());
        let splits = crate::stages::split::Splits::from_config(self.config)?;
        for clip in items.iter_mut().flat_map(|i| i.clips.iter_mut()) {
            splits.assign(clip);
        }
        self.stages
            .push(capture_run(&items, Stage::Ingest, progress));
        if self.through >= Stage::Segment {
            self.stages
                .push(capture_run(&items, Stage::Segment, progress));
        }
        self.items = items;
        Ok(())
    }

    /// The text stages (labels, paraphrases, plans), unless a capture's upstream output is
    /// pending.
    fn text_stages(&mut self) -> Result<(), BuildError> {
        let progress = &self.options.progress;
        let text = if self.through >= Stage::Label && !self.upstream_pending {
            text::run(
                &self.shared,
                &self.motions,
                &mut self.items,
                self.options.offline || self.probe,
                self.through,
                progress,
            )?
        } else {
            text::TextOutcome {
                pending: self.upstream_pending,
                ..Default::default()
            }
        };
        for run in &text.runs {
            progress.stage_finished(&run.stage, run.ran as u64, run.reused as u64);
        }
        self.stages.extend(text.runs.iter().cloned());
        self.text = text;
        Ok(())
    }

    /// Mirrored copies of every capture's labelled clips, on all cores (mirroring on, reached,
    /// and the labels known); then the per-capture stage caches pruned, and in probe mode the
    /// first stage whose output is missing.
    fn mirror(&mut self) -> Result<(), BuildError> {
        let run_mirror =
            self.config.mirror.enabled && self.through >= Stage::Mirror && !self.text.pending;
        if run_mirror {
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
        }
        let mirror_pending = self.items.iter().any(|i| i.pending == Some(Stage::Mirror));
        let first_pending = items_pending_stage(&self.items);
        self.prune_stage_caches();
        if run_mirror {
            let run = capture_run(&self.items, Stage::Mirror, &self.options.progress);
            self.stages.push(run);
        }
        self.blocked = if self.upstream_pending {
            first_pending
        } else if self.text.pending {
            Some(Stage::Label)
        } else if mirror_pending {
            Some(Stage::Mirror)
        } else {
            None
        };
        Ok(())
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

    /// Takes every capture's clips, drops, notes and rejects (with the text stages' rejects),
    /// each sorted so the outputs do not depend on scheduling or glob order.
    fn gather(&mut self) {
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
    }

    /// Synthetic pairs from the labelled originals and mirrors, unless an earlier stage is
    /// `blocked` (probe mode), which it becomes when the pairs themselves are not cached.
    fn compose(&mut self) -> Result<(), BuildError> {
        if self.through < Stage::Compose || self.blocked.is_some() {
            return Ok(());
        }
        let progress = &self.options.progress;
        let gathered = &mut self.gathered;
        progress.stage_started(crate::stages::compose::NAME, gathered.clips.len() as u64);
        match synthetic::compose(
            &self.shared,
            &self.motions,
            &mut gathered.clips,
            &mut gathered.index,
            self.options.offline || self.probe,
            progress,
        )? {
            Some((report, check, run)) => {
                progress.stage_finished(&run.stage, run.ran as u64, run.reused as u64);
                self.compose = report;
                self.pair_check = check;
                self.stages.push(run);
            }
            None => {
                // Probe mode, not cached: the pairs a build would compose (sampling is cheap,
                // composing is not), so `plan` counts them as `build` does.
                let clips: Vec<&Clip> = gathered.clips.iter().collect();
                let (_, sampled) = crate::stages::compose::sample(
                    &clips,
                    &self.config.synthetic,
                    self.config.dataset.seed,
                    |c| c.split.clone(),
                );
                self.stages.push(super::StageRun {
                    stage: crate::stages::compose::NAME.into(),
                    items: sampled.sampled,
                    ran: sampled.sampled,
                    reused: 0,
                });
                self.blocked = Some(Stage::Compose);
            }
        }
        Ok(())
    }

    /// What the steps produced, for the write stage.
    pub(super) fn staged(self) -> Staged<'a> {
        let gathered = self.gathered;
        Staged {
            output: self.output,
            files: self.files.len(),
            stages: self.stages,
            clips: gathered.clips,
            rejects: gathered.rejects,
            notes: gathered.notes,
            drops_by_reason: gathered.drops_by_reason,
            drops: gathered.drops,
            unmapped_labels: gathered.unmapped_labels,
            text: self.text,
            compose: self.compose,
            pair_check: self.pair_check,
            blocked: self.blocked,
            index: gathered.index,
            shared: self.shared,
        }
    }
}
