//! The build runner: runs the stages over every capture, reuses cached work whose fingerprint is
//! unchanged, writes outputs atomically and records what it rejected and why.
//!
//! Principal types: [`config::Config`], [`Stage`], [`Workspace`], [`BuildOptions`] and
//! [`BuildReport`]; the stages are in [`stages`].
//!
//! # A clip's way through this crate
//!
//! Step 7 ties steps 1-6 together: [`source`] finds the capture, [`stages::ingest`] (through the
//! capture's [`stages::ingest::CaptureFormat`]) and [`stages::segment`] read and cut it,
//! [`stages::label`], [`stages::augment`], [`stages::mirror`] and [`stages::compose`] add to the
//! clip, the label check measures its text against its motion, and the write stage hands its row
//! to the format crate. [`build`] (and [`plan()`]) run the stages as one loop over registered steps,
//! one per [`Stage`], reusing every cached item.

pub mod config;
pub mod source;
pub mod stages;

mod capture;
pub mod clean;
mod companions;
mod digests;
mod held;
mod label_check;
mod lookup;
mod motions;
mod output;
mod pack;
mod plan;
mod sinks;
mod stage;
mod steps;
mod synthetic;
mod text;
pub mod workspace;

pub use motionforge_core::base::lock;

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

pub use lookup::{ProfiledClip, collect_clips, find_clip, stored_motion};
pub use motionforge_core::base::{
    Dropped, Fingerprint, Reject, Stamp, WorkspaceError, sha256_hex, temp_path, write_atomic,
    write_atomic_with,
};
pub use plan::{Plan, StagePlan, StageStatus, StaleReason, Status, plan, status};
pub use workspace::{ConfigRecord, Ledger, Miss, SeenStamps, StageLedger, Workspace};

use capture::{Item, Shared};
use motions::MotionIndex;
use steps::BuildState;

use crate::config::Config;
use crate::source::{SourceAnnotations, SourceError};
use crate::stages::{ingest, mirror};
use crate::stages::{label, segment};
use motionforge_core::base::{DropReason, RejectReason, Tally};
use motionforge_core::motion::ProfileSpec;
use motionforge_format::io::parquet::TableError;
use motionforge_sources::annotate::span::Note;
use motionforge_sources::annotate::taxonomy::{Taxonomy, TaxonomyError, TypeMap};
use motionforge_sources::clip::SourceKind;

pub use motionforge_core::base::layout::{
    CARD_FILE, DATA_DIR, MANIFEST_FILE, NORMALIZATION_DIR, PLANS_FILE, REJECTS_FILE, REPORT_FILE,
    REPORT_STATS, SKELETONS_FILE,
};

/// The stages of a build in dependency order: each needs every one before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Read and check capture files.
    Ingest,
    /// Cut captures into clips by their annotations.
    Segment,
    /// Body parts of every text (embedded labeller, LLM or imported answers).
    Label,
    /// Alternative captions (LLM).
    Paraphrase,
    /// Task plans of single actions (LLM).
    Plan,
    /// Left/right mirrored copies of every clip.
    Mirror,
    /// The optional LLM check of the texts of sampled pairs (`synthetic.llm_check`).
    PairCheck,
    /// Synthetic simultaneous-action pairs, measured for plausibility.
    Compose,
    /// Real clips whose motion contradicts their text, listed (and left out with
    /// `label_check.drop`).
    LabelCheck,
    /// Parquet shards, manifest, card, normalisation statistics.
    Write,
    /// Statistics report (tables, figures, stats.json).
    Report,
}

impl Stage {
    /// Every stage, in order.
    pub const ALL: [Stage; 11] = [
        Stage::Ingest,
        Stage::Segment,
        Stage::Label,
        Stage::Paraphrase,
        Stage::Plan,
        Stage::Mirror,
        Stage::PairCheck,
        Stage::Compose,
        Stage::LabelCheck,
        Stage::Write,
        Stage::Report,
    ];

    /// The stage's name in reports, the stage cache, the ledger and on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Stage::Ingest => ingest::NAME,
            Stage::Segment => segment::NAME,
            Stage::Label => label::NAME,
            Stage::Paraphrase => "paraphrase",
            Stage::Plan => "plan",
            Stage::Mirror => mirror::NAME,
            Stage::PairCheck => "pair_check",
            Stage::Compose => crate::stages::compose::NAME,
            Stage::LabelCheck => "label_check",
            Stage::Write => "write",
            Stage::Report => "report",
        }
    }
}

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Stage {
    type Err = String;

    fn from_str(s: &str) -> Result<Stage, String> {
        Stage::ALL
            .into_iter()
            .find(|stage| stage.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Stage::ALL.iter().map(|s| s.name()).collect();
                format!("unknown stage `{s}`; expected one of {}", names.join(", "))
            })
    }
}

/// Errors that stop a build (bad inputs do not: they become rejects).
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// A source cannot be resolved.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// The workspace or an output cannot be written.
    #[error(transparent)]
    Workspace(#[from] WorkspaceError),
    /// Split assignment is inconsistent (a capture in two splits).
    #[error(transparent)]
    Split(#[from] crate::stages::split::SplitError),
    /// The written shards put one capture in two splits.
    #[error(
        "capture `{capture}` appears in splits {splits:?} of the written shards; a capture must be in one split"
    )]
    SplitLeak {
        /// The capture path.
        capture: String,
        /// The splits it appears in.
        splits: Vec<String>,
    },
    /// Normalisation statistics cannot be written.
    #[error(transparent)]
    Normalization(Box<motionforge_format::io::normalization::NormalizationError>),
    /// The embedded labeller's lexicon (`schemas/lexicon.toml`) is invalid.
    #[error(transparent)]
    Lexicon(#[from] motionforge_language::parts::lexicon::LexiconError),
    /// The synthetic-pair composer's word file (`schemas/compose_text.toml`) is invalid.
    #[error(transparent)]
    Words(#[from] motionforge_language::compose_text::WordsError),
    /// The paraphrase check's word file (`schemas/paraphrase.toml`) is invalid.
    #[error(transparent)]
    ParaphraseWords(#[from] motionforge_llm::paraphrase::ParaphraseWordsError),
    /// A dataset's `manifest.json` cannot be read.
    #[error(transparent)]
    Manifest(#[from] motionforge_format::io::manifest::ManifestError),
    /// The statistics report cannot be made (the dataset was written; `build-report.json` says
    /// why in `report_error`).
    #[error("report: {0}")]
    Report(#[source] Box<motionforge_report::ReportError>),
    /// A prompt template does not load or render.
    #[error(transparent)]
    Prompt(#[from] motionforge_llm::prompt::PromptError),
    /// The LLM response cache cannot be opened.
    #[error("{path}: {source}")]
    LlmCache {
        /// The cache file.
        path: PathBuf,
        /// Why.
        source: motionforge_llm::cache::CacheError,
    },
    /// Part labelling cannot run (missing answers with `on_miss = "fail"`, no client, the
    /// server gone).
    #[error(transparent)]
    Labels(Box<crate::stages::label::LabelError>),
    /// A text-augmentation stage cannot run (missing answers, the server gone).
    #[error(transparent)]
    Augment(Box<crate::stages::augment::AugmentError>),
    /// The motion-type taxonomy or mapping is invalid.
    #[error(transparent)]
    Taxonomy(#[from] TaxonomyError),
    /// A held clip's motion cannot be found (internal bookkeeping; `--force` rebuilds it).
    #[error("no motion recorded for clip `{clip}`")]
    NoMotion {
        /// The clip id.
        clip: String,
    },
    /// A row's frames were not read before its row was made (internal bookkeeping).
    #[error("no frames read for `{clip}`")]
    NoFrames {
        /// The clip id.
        clip: String,
    },
    /// A shard's writer finished without writing it (internal bookkeeping).
    #[error("{file}: nothing written")]
    NothingWritten {
        /// The shard, relative to the dataset folder.
        file: String,
    },
    /// A block of held clips does not decode (an internal error).
    #[error("held clips, block {block}: {why} (an internal error; please report it)")]
    HeldClips {
        /// The block's index.
        block: usize,
        /// The decoder's or the check's message.
        why: String,
    },
    /// A held motion cannot be mirrored again.
    #[error("cannot mirror a held motion: {0}")]
    Remirror(#[source] motionforge_core::motion::mirror::MirrorError),
    /// A held clip names a skeleton profile the config does not define.
    #[error("no skeleton profile `{profile}`")]
    NoProfile {
        /// The profile's name.
        profile: String,
    },
    /// A held motion's skeleton no longer binds to its profile. (Not a `#[source]`: a
    /// `ProfileError` among the causes would make the whole a usage mistake, and this is not.)
    #[error("profile `{profile}`: {error}")]
    Rebind {
        /// The profile's name.
        profile: String,
        /// Why it does not bind.
        error: Box<motionforge_core::motion::profile::ProfileError>,
    },
    /// A looked-up clip names a skeleton profile the config does not define.
    #[error("clip `{clip}`: no profile `{profile}`")]
    ClipProfile {
        /// The clip id.
        clip: String,
        /// The profile's name.
        profile: String,
    },
    /// A looked-up clip's skeleton does not bind to its profile (not a `#[source]`, as
    /// [`BuildError::Rebind`]).
    #[error("clip `{clip}`: profile `{profile}` does not fit its skeleton: {error}")]
    ClipProfileFit {
        /// The clip id.
        clip: String,
        /// The profile's name.
        profile: String,
        /// Why it does not bind.
        error: Box<motionforge_core::motion::profile::ProfileError>,
    },
    /// A capture's bytes differ from the digest taken when the build found it.
    #[error("{file}: the file changed during the build; run the build again")]
    CaptureChanged {
        /// The capture, as the build names it.
        file: String,
    },
    /// A capture whose ingest record is cached no longer parses.
    #[error("{file}: the capture read before no longer reads; run the build again with --force")]
    CaptureUnreadable {
        /// The capture, as the build names it.
        file: String,
    },
    /// A stage's cache entry disagrees with itself.
    #[error("the {stage} cache entry is inconsistent; run the build again with --force")]
    InconsistentCache {
        /// The stage's name.
        stage: &'static str,
    },
    /// The dataset folder is one the build must not write into.
    #[error(transparent)]
    Refused(#[from] motionforge_core::base::guard::Refused),
    /// A written shard cannot be read back.
    #[error(transparent)]
    ReadBack(#[from] motionforge_format::dataset::DatasetError),
    /// The table cannot be written.
    #[error("{path}: {source}")]
    Table {
        /// The table path.
        path: PathBuf,
        /// The error.
        source: TableError,
    },
}

impl From<motionforge_format::io::normalization::NormalizationError> for BuildError {
    fn from(e: motionforge_format::io::normalization::NormalizationError) -> Self {
        BuildError::Normalization(Box::new(e))
    }
}

/// What one stage did in a build.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StageRun {
    /// Stage name.
    pub stage: String,
    /// Items the stage covers.
    pub items: usize,
    /// Items computed in this build.
    pub ran: usize,
    /// Items reused from the cache.
    pub reused: usize,
}

/// The outcome of a build, also written as `build-report.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BuildReport {
    /// Dataset name.
    pub dataset: String,
    /// The output folder.
    pub output: PathBuf,
    /// Per-stage work done.
    pub stages: Vec<StageRun>,
    /// Captures found.
    pub captures: usize,
    /// Rows in the clip table.
    pub clips: usize,
    /// Rows that are mirrored copies.
    pub mirrored: usize,
    /// Rows by source kind (`real_single`, `real_pair`, ...), mirrors included.
    pub kinds: Tally<SourceKind>,
    /// Clips per action label (originals only).
    pub actions: BTreeMap<String, usize>,
    /// Single clips per motion type (originals only); `(unmapped)` for labels with no type.
    pub motion_types: BTreeMap<String, usize>,
    /// Labels that map to no motion type, with counts: listed, never merged.
    pub unmapped_labels: BTreeMap<String, usize>,
    /// Segments dropped during segmentation, by reason.
    pub drops_by_reason: Tally<DropReason>,
    /// Every dropped segment: file, reason, text and frames.
    pub drops: Vec<Dropped>,
    /// Rows whose frames are really at another rate than the dataset's, by that rate (fps, two
    /// decimals): clips of AMASS files taken at HumanML3D's stride (`frame_rate = "humanml3d"`),
    /// their mirrors and the synthetic pairs made of them. Absent when there are none.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub clips_by_effective_rate: BTreeMap<String, usize>,
    /// Annotation quirks handled (clamped ends, null labels, ...), by kind.
    pub notes_by_kind: motionforge_core::base::Tally<motionforge_sources::annotate::span::NoteKind>,
    /// Every annotation quirk, for people.
    pub notes: Vec<Note>,
    /// Rejected inputs by reason.
    pub rejects_by_reason: Tally<RejectReason>,
    /// Every rejected input.
    pub rejects: Vec<Reject>,
    /// Body-part labelling: sources, requests, cache hits, flagged answers.
    pub labels: crate::stages::label::LabelReport,
    /// Paraphrases: answered, skipped by reason, rejected lines.
    pub paraphrases: crate::stages::augment::AugmentReport,
    /// Task plans: answered, skipped by reason, rejected plans.
    pub plans: crate::stages::augment::AugmentReport,
    /// Synthetic pairs: candidates, compatible, sampled, composed, dropped by reason.
    pub synthetic: crate::stages::compose::ComposeReport,
    /// The optional LLM check of sampled pairs: asked, answered, skipped.
    pub pair_check: crate::stages::augment::AugmentReport,
    /// Fingerprint of the written table's inputs.
    pub table_fingerprint: String,
    /// Real clips whose motion contradicts their text (turn side, walking direction, hand), in
    /// `clip_id` order. Listed, never fixed; left out of the table with `label_check.drop`.
    #[serde(default)]
    pub label_contradictions: Vec<motionforge_core::quality::Contradiction>,
    /// Rows left out because of them (`label_check.drop`): the clips and the synthetic pairs
    /// made from them.
    #[serde(default)]
    pub label_contradictions_dropped: usize,
    /// Why the statistics report could not be written (the dataset was); the build then fails
    /// after writing this file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub report_error: Option<String>,
}

impl BuildReport {
    /// True when no stage ran any item: everything was reused.
    pub fn nothing_ran(&self) -> bool {
        self.stages.iter().all(|s| s.ran == 0)
    }
}

/// Options of a build.
#[derive(Debug, Clone, Default)]
pub struct BuildOptions {
    /// Ignore the cache and recompute everything.
    pub force: bool,
    /// Send no LLM request: answers come from the response cache only.
    pub offline: bool,
    /// Where stage progress is reported.
    pub progress: motionforge_core::progress::ProgressSink,
    /// Run only up to this stage (and everything it depends on); all stages when `None`.
    pub through: Option<Stage>,
    /// How long to wait for another build of the same dataset folder to finish (`None`: refuse
    /// at once).
    pub lock_wait: Option<std::time::Duration>,
    /// The config file the build was given, recorded in the dataset's workspace so commands
    /// given only the dataset folder (`status <dataset>`) find it; `None` records nothing.
    pub config_file: Option<PathBuf>,
}

/// What every stage shares: each source's profile, annotations and frame-rate table, the motion
/// types, and the file digests remembered from earlier builds (unless `forget_digests`).
fn load_shared(
    config: &Config,
    workspace: Workspace,
    forget_digests: bool,
) -> Result<Shared<'_>, BuildError> {
    let specs: Vec<ProfileSpec> = config
        .sources
        .iter()
        .map(|s| source::resolve_profile(config, s))
        .collect::<Result<_, _>>()?;
    let annotations: Vec<SourceAnnotations> = config
        .sources
        .iter()
        .map(|s| source::load_annotations(config, s))
        .collect::<Result<_, _>>()?;
    let fps_tables: Vec<BTreeMap<String, f64>> = config
        .sources
        .iter()
        .map(|s| source::load_fps_table(config, s))
        .collect::<Result<_, _>>()?;
    let (types, types_digest) = load_types(config)?;
    let digests = if forget_digests {
        digests::FileDigests::default()
    } else {
        digests::FileDigests::load(&workspace)
    };
    Ok(Shared {
        config,
        workspace,
        specs,
        bound: Default::default(),
        skeletons: Default::default(),
        annotations,
        fps_tables,
        types,
        types_digest,
        digests,
    })
}

/// What the per-capture `stage` did over `items`.
fn capture_run(items: &[Item], stage: Stage) -> StageRun {
    let ran: Vec<bool> = items.iter().filter_map(|i| i.ran(stage)).collect();
    StageRun {
        stage: stage.name().into(),
        items: ran.len(),
        ran: ran.iter().filter(|r| **r).count(),
        reused: ran.iter().filter(|r| !**r).count(),
    }
}

/// The first stage a pending (probe-mode) capture stopped at.
fn items_pending_stage(items: &[Item]) -> Option<Stage> {
    items.iter().filter_map(|i| i.pending).min()
}

/// Runs every stage of the build described by `config` and writes the dataset.
pub fn build(config: &Config, options: &BuildOptions) -> Result<BuildReport, BuildError> {
    // Before the lock, which creates `.motionforge/`: a build writes README.md, data/ and more
    // into the dataset folder, so it must not be the working folder or someone else's folder.
    motionforge_core::base::guard::check_owned(
        &config.dataset_dir(),
        clean::made_by_a_build,
        "set [dataset] output and name (or --output) to a folder of the dataset's own",
    )?;
    // One build per dataset folder at a time; released when this function returns.
    let _lock = lock::WorkspaceLock::acquire(&config.dataset_dir(), options.lock_wait)
        .map_err(WorkspaceError::from)?;
    let mut state = BuildState::open(config, options, false)?;
    steps::run_steps(&mut state, &steps::STAGES)?;
    steps::run_steps(&mut state, &steps::SINKS)?;
    let sinks::Finished {
        report,
        workspace,
        stamps,
        report_error,
    } = state.finish();
    // A partial run (`run <stage>`) leaves the last full build's report in place.
    if options.through.unwrap_or(Stage::Report) == Stage::Report {
        let json = serde_json::to_vec_pretty(&report).unwrap_or_default();
        write_atomic(&report.output.join(REPORT_FILE), &json)?;
    }
    save_ledger(&workspace, &report.stages, stamps)?;
    if let Some(file) = &options.config_file {
        workspace::ConfigRecord::save(&workspace, file)?;
    }
    match report_error {
        Some(e) => Err(BuildError::Report(Box::new(e))),
        None => Ok(report),
    }
}

/// Annotation notes counted by kind, and listed up to a bound per kind: the report stays
/// readable and its size bounded.
fn counted_notes(
    notes: Vec<Note>,
) -> (
    motionforge_core::base::Tally<motionforge_sources::annotate::span::NoteKind>,
    Vec<Note>,
) {
    let notes_by_kind = notes.iter().map(|n| n.kind).collect();
    let notes = motionforge_sources::annotate::span::cap_per_kind(
        notes,
        motionforge_sources::annotate::span::NOTES_PER_KIND,
    );
    (notes_by_kind, notes)
}

/// Records what this run did in the workspace ledger: for every stage it ran, when, its counts
/// and each item's stamp (so `plan` can later say what changed). Stages it did not reach keep
/// their earlier record.
fn save_ledger(
    workspace: &Workspace,
    runs: &[StageRun],
    stamps: SeenStamps,
) -> Result<(), BuildError> {
    let stamps = stamps.into_vec()?;
    let mut ledger = Ledger::load(workspace);
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    for run in runs {
        let entries = stamps
            .iter()
            .filter(|m| m.stage == run.stage)
            .map(|m| (m.key.clone(), m.stamp.clone()))
            .collect();
        ledger.stages.insert(
            run.stage.clone(),
            StageLedger {
                last_run: now,
                items: run.items,
                ran: run.ran,
                reused: run.reused,
                entries,
            },
        );
    }
    let json = serde_json::to_vec_pretty(&ledger).unwrap_or_default();
    write_atomic(&workspace.root().join(workspace::LEDGER_FILE), &json)?;
    Ok(())
}

fn add_counts(into: &mut BTreeMap<String, usize>, from: BTreeMap<String, usize>) {
    for (k, v) in from {
        *into.entry(k).or_insert(0) += v;
    }
}

fn load_types(config: &Config) -> Result<(TypeMap, String), BuildError> {
    let cfg = &config.motion_types;
    let (taxonomy, text) = match &cfg.taxonomy {
        Some(path) => {
            let path = config.resolve(path);
            let text = std::fs::read_to_string(&path).map_err(workspace::io_err(&path))?;
            (
                Taxonomy::from_toml(&text, &path.display().to_string())?,
                text,
            )
        }
        None => (
            Taxonomy::bundled()?,
            motionforge_sources::annotate::taxonomy::BUNDLED_TOML.to_string(),
        ),
    };
    let digest = Fingerprint::new("motion_types", 1)
        .text("taxonomy", &text)
        .json("config motion_types", cfg)
        .finish();
    Ok((
        TypeMap::new(taxonomy.with_extra(cfg.extra.clone())?, cfg)?,
        digest,
    ))
}
