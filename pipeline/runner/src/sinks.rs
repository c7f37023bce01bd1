//! The build's last steps: the table as it will be written (its stamp, its companion files and
//! what the build report says of its rows), the write stage and the report stage; then the build
//! report of the whole run.

use std::collections::BTreeMap;
use std::path::Path;

use super::steps::BuildState;
use super::{
    BuildError, BuildReport, Miss, MotionIndex, REPORT_STATS, SeenStamps, Stage, StageRun, Stamp,
    Workspace, companions, counted_notes, output, workspace, write_atomic,
};
use crate::config::Config;
use crate::stage::Versioned;
use motionforge_core::quality::Contradiction;
use motionforge_sources::clip::Clip;

/// The write stage: the shards and their companion files.
struct Shards;

impl Versioned for Shards {
    const STAGE: Stage = Stage::Write;
    /// Bump when the rows or files written for the same table change.
    const VERSION: u32 = 4;
}

/// The report stage: the statistics report of the written shards.
struct StatsReport;

impl Versioned for StatsReport {
    const STAGE: Stage = Stage::Report;
    /// Bump when the report made of the same shards changes.
    const VERSION: u32 = 1;
}

/// What the label check found, and how many rows it left out.
#[derive(Debug, Default)]
pub(super) struct LabelFindings {
    /// Real clips whose motion contradicts their text, in `clip_id` order.
    pub(super) contradictions: Vec<Contradiction>,
    /// Rows left out because of them (`label_check.drop`).
    pub(super) dropped: usize,
}

/// The table as the write stage will write it.
pub(super) struct Tabulated {
    /// The write stage's stamp: the rows, the plans and the config they are written with.
    pub(super) stamp: Stamp,
    /// The manifest (without its shards), the card and the settings of the files (not made in
    /// probe mode).
    companions: Option<companions::Companions>,
    /// Rows of the table, and of them mirrored copies.
    clips: usize,
    mirrored: usize,
    clips_by_effective_rate: BTreeMap<String, usize>,
    actions: BTreeMap<String, usize>,
}

/// What the write and report stages leave for the build report and the ledger.
#[derive(Default)]
pub(super) struct Written {
    /// The write stage's stamp, when it ran or was reused.
    stamp: Option<Stamp>,
    /// Why the statistics report could not be made, when it could not.
    report_error: Option<motionforge_report::ReportError>,
}

/// A finished build: its report, and what the ledger records of it.
pub(super) struct Finished {
    pub(super) report: BuildReport,
    pub(super) workspace: Workspace,
    /// Every stamp this build saw, the table's among them when it was written.
    pub(super) stamps: SeenStamps,
    /// Why the statistics report could not be made, when it could not.
    pub(super) report_error: Option<motionforge_report::ReportError>,
}

impl BuildState<'_, '_> {
    /// The table's stamp, and outside probe mode its companion files and the counts of its rows
    /// (also when the run stops before `write`: the build report gives them). Nothing when an
    /// earlier stage is blocked, or when `plan` stops before `write`.
    pub(super) fn tabulate(&mut self) -> Result<Vec<StageRun>, BuildError> {
        if self.blocked.is_some() || (self.probe && self.through < Stage::Write) {
            return Ok(Vec::new());
        }
        let gathered = &self.gathered;
        let clips = &gathered.clips;
        let stamp = table_stamp(self.config, clips, &gathered.index, &self.text.plans)?;
        let companions = (!self.probe).then(|| {
            companions::Companions::of(
                self.config,
                clips,
                &gathered.rejects,
                gathered.drops_by_reason.clone(),
                &self.label_check.contradictions,
                &stamp.fingerprint,
            )
        });
        self.table = Some(Tabulated {
            stamp,
            companions,
            clips: clips.len(),
            mirrored: clips.iter().filter(|c| c.mirrored).count(),
            clips_by_effective_rate: effective_rate_counts(clips),
            actions: motionforge_format::io::manifest::action_counts(clips),
        });
        Ok(Vec::new())
    }

    /// The write stage: shards, manifest, card, normalisation statistics, unless the files on
    /// disk are those of the same table. The clips are taken (written a shard at a time).
    pub(super) fn write(&mut self) -> Result<Vec<StageRun>, BuildError> {
        let Some(table) = &self.table else {
            return Ok(Vec::new());
        };
        let Some(companions) = &table.companions else {
            return Ok(Vec::new());
        };
        self.options.progress.stage_started(Shards::NAME, 1);
        let clips = std::mem::take(&mut self.gathered.clips);
        let index = std::mem::take(&mut self.gathered.index);
        let (profiles, skeletons) = companions::skeletons_of(&self.shared, &clips);
        let files = output::Table {
            plans: &self.text.plans,
            profiles: &profiles,
            skeletons: &skeletons,
            rejects: &self.gathered.rejects,
            motions: &self.motions,
        };
        let ran = output::write_outputs(
            self.options.force,
            &self.output,
            &self.shared.workspace,
            &table.stamp.fingerprint,
            &files,
            companions,
            output::Rows { clips, index },
        )?;
        self.written.stamp = Some(table.stamp.clone());
        Ok(vec![single_run(Stage::Write, ran)])
    }

    /// The report stage: the statistics report of the written shards, made again when they
    /// changed or it is missing, removed when the table has no rows. A failed report is kept, not
    /// raised: the dataset is written by now, and the build report records it.
    pub(super) fn report(&mut self) -> Result<Vec<StageRun>, BuildError> {
        let Some(table) = &self.table else {
            return Ok(Vec::new());
        };
        let progress = &self.options.progress;
        let workspace = &self.shared.workspace;
        let marker = workspace.root().join(REPORT_MARKER);
        if table.clips == 0 {
            // Nothing to describe: a report of an earlier build would describe rows that are gone.
            let stale = self.output.join("report");
            if stale.exists() {
                std::fs::remove_dir_all(&stale).map_err(workspace::io_err(&stale))?;
            }
            let _ = std::fs::remove_file(&marker);
            progress.stage_started(StatsReport::NAME, 0);
            let run = StageRun {
                stage: StatsReport::NAME.into(),
                items: 0,
                ran: 0,
                reused: 0,
            };
            return Ok(vec![run]);
        }
        progress.stage_started(StatsReport::NAME, 1);
        let stamp = report_stamp(&table.stamp.fingerprint);
        let ran =
            self.options.force || !report_is_current(&self.output, workspace, &stamp.fingerprint);
        if ran {
            let _ = std::fs::remove_file(&marker);
            // The dataset is written by now: a failed report (a full disk) is recorded in
            // build-report.json and fails the build after it, rather than losing both.
            match motionforge_report::report_dataset(&self.output, None) {
                Ok(_) => write_atomic(&marker, stamp.fingerprint.as_bytes())?,
                Err(e) => self.written.report_error = Some(e),
            }
        }
        Ok(vec![single_run(Stage::Report, ran)])
    }

    /// The build report of the whole run, and what the ledger records of it.
    pub(super) fn finish(self) -> Finished {
        let (notes_by_kind, notes) = counted_notes(self.gathered.notes);
        let workspace = self.shared.workspace;
        let mut stamps = workspace.take_seen();
        if let Some(stamp) = self.written.stamp {
            stamps.push(Miss {
                stage: Shards::NAME.into(),
                key: "*".into(),
                stamp,
            });
        }
        let table = self.table;
        let counts = table
            .as_ref()
            .and_then(|t| t.companions.as_ref())
            .map(|c| c.manifest.counts.clone())
            .unwrap_or_default();
        let report = BuildReport {
            label_contradictions: self.label_check.contradictions,
            label_contradictions_dropped: self.label_check.dropped,
            dataset: self.config.dataset.name.clone(),
            output: self.output,
            stages: self.stages,
            captures: self.files.len(),
            clips: table.as_ref().map_or(0, |t| t.clips),
            mirrored: table.as_ref().map_or(0, |t| t.mirrored),
            kinds: counts.source_kind,
            motion_types: counts.motion_type,
            rejects_by_reason: counts.reject_reason,
            unmapped_labels: self.gathered.unmapped_labels,
            drops_by_reason: self.gathered.drops_by_reason,
            drops: self.gathered.drops,
            notes_by_kind,
            notes,
            rejects: self.gathered.rejects,
            labels: self.text.label,
            paraphrases: self.text.paraphrase,
            plans: self.text.plan,
            synthetic: self.compose,
            pair_check: self.pair_check,
            table_fingerprint: table
                .as_ref()
                .map(|t| t.stamp.fingerprint.clone())
                .unwrap_or_default(),
            report_error: self.written.report_error.as_ref().map(ToString::to_string),
            clips_by_effective_rate: table
                .as_ref()
                .map(|t| t.clips_by_effective_rate.clone())
                .unwrap_or_default(),
            actions: table.map(|t| t.actions).unwrap_or_default(),
        };
        Finished {
            report,
            workspace,
            stamps,
            report_error: self.written.report_error,
        }
    }
}

/// Rows whose frames are at another rate than they are labelled, by that rate: clips whose
/// capture has an effective rate, and synthetic pairs made of such a clip.
fn effective_rate_counts(clips: &[Clip]) -> BTreeMap<String, usize> {
    let rate_of: std::collections::HashMap<&str, f64> = clips
        .iter()
        .filter_map(|c| c.capture.effective_fps.map(|r| (c.clip_id.as_str(), r)))
        .collect();
    let mut counts = BTreeMap::new();
    for clip in clips {
        let rate = clip.capture.effective_fps.or_else(|| {
            clip.composed_from
                .iter()
                .find_map(|id| rate_of.get(id.as_str()).copied())
        });
        if let Some(rate) = rate {
            *counts.entry(format!("{rate:.2}")).or_insert(0) += 1;
        }
    }
    counts
}

/// The run of a stage with one item (write, report).
fn single_run(stage: Stage, ran: bool) -> StageRun {
    StageRun {
        stage: stage.name().into(),
        items: 1,
        ran: usize::from(ran),
        reused: usize::from(!ran),
    }
}

/// Inside the workspace: the stamp the report in `report/` was made under.
const REPORT_MARKER: &str = "report-of";

/// The report stage's stamp: the written table's and the stage's version.
pub(super) fn report_stamp(table_fingerprint: &str) -> Stamp {
    StatsReport::fingerprint()
        .text("table", table_fingerprint)
        .stamp()
}

/// True when `report/` is complete and made under `fingerprint` (a crash between writing the
/// shards and finishing the report leaves it stale, not current).
pub(super) fn report_is_current(output: &Path, workspace: &Workspace, fingerprint: &str) -> bool {
    output.join(REPORT_STATS).is_file()
        && std::fs::read_to_string(workspace.root().join(REPORT_MARKER))
            .is_ok_and(|f| f == fingerprint)
}

/// The write stage's stamp: the table's input is exactly its rows (and the plans), so their
/// encoding is the fingerprint.
pub(super) fn table_stamp(
    config: &Config,
    clips: &[Clip],
    index: &MotionIndex,
    plans: &BTreeMap<String, Vec<motionforge_llm::plans::PlanStep>>,
) -> Result<Stamp, BuildError> {
    // The rows without frames, and where their frames are (stage outputs named by content).
    let encoded = motionforge_core::base::encoded_sha256(&(clips, index), "clip table")?;
    Ok(Shards::fingerprint()
        .text("rows", &encoded)
        .json("config features", &config.features)
        .json("config dataset.shard_bytes", &config.dataset.shard_bytes)
        .json("config dataset.zstd_level", &config.dataset.zstd_level)
        .json("task plans", plans)
        .json(
            "schema version",
            &motionforge_format::io::schema::SCHEMA_VERSION,
        )
        .stamp())
}
