//! `plan` and `status`: what a build would run and why, without running it.

use motionforge_llm::Unanswered;
use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::steps::{self, BuildState};
use super::{BuildError, BuildOptions, Ledger, Stage, Workspace, output, sinks};
use crate::config::Config;

/// What one stage would do.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StagePlan {
    /// The stage.
    pub stage: Stage,
    /// False when the config turns the stage off (`mirror.enabled`, `synthetic.llm_check`...):
    /// it runs nothing.
    #[serde(default = "on")]
    pub enabled: bool,
    /// Items it covers (captures, or 1 for stages over the whole set) as far as known: items
    /// behind a stale stage are counted there.
    pub items: usize,
    /// Items that would be computed.
    pub to_run: usize,
    /// Why, with how many items each reason covers.
    pub reasons: BTreeMap<StaleReason, usize>,
    /// A few items that would run, with their reason.
    pub examples: Vec<String>,
}

/// A stage is on unless a plan says otherwise (plans written before stages could be off).
fn on() -> bool {
    true
}

impl StagePlan {
    fn new(stage: Stage, enabled: bool) -> StagePlan {
        StagePlan {
            stage,
            enabled,
            items: 0,
            to_run: 0,
            reasons: BTreeMap::new(),
            examples: Vec::new(),
        }
    }

    fn stale(&mut self, key: &str, reason: StaleReason) {
        self.to_run += 1;
        if key != "*" && self.examples.len() < 5 {
            self.examples.push(format!("{key}: {reason}"));
        }
        *self.reasons.entry(reason).or_insert(0) += 1;
    }

    /// True when nothing would run.
    pub fn fresh(&self) -> bool {
        self.to_run == 0
    }
}

/// Why a stage (or one of its items) would run. Shown, and written in `plan --json`, as words
/// (`new`, `changed: file content`); ordered by those words, so reasons list as they always did.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum StaleReason {
    /// The last run did not see the item.
    New,
    /// The item's stamp is the one of the last run, but its cache entry is gone.
    CacheEntryMissing,
    /// These parts of the item's stamp (`file content`, `config dataset.seed`...) differ from the
    /// last run's.
    Changed(Vec<String>),
    /// An earlier stage is stale, so everything after it runs.
    Upstream(Stage),
    /// An LLM stage's text has no cached answer.
    NoCachedAnswer,
    /// Labels whose texts have no cached LLM answer (asked when the build is online).
    LabelsNotCached,
    /// The dataset was never written.
    NeverWritten,
    /// Files of the written dataset were changed or removed since.
    OutputsChanged,
    /// The written rows are not those of the clip table now.
    RowsChanged,
    /// The report is missing or its last run did not finish.
    ReportUnfinished,
}

const NEW: &str = "new";
const CACHE_ENTRY_MISSING: &str = "cache entry missing (cleaned or pruned)";
const CHANGED: &str = "changed: ";
const UPSTREAM: &str = " re-runs first";
const NO_CACHED_ANSWER: &str = "no cached LLM answer";
const LABELS_NOT_CACHED: &str = "texts without a cached LLM answer (asked when online)";
const NEVER_WRITTEN: &str = "never written";
const OUTPUTS_CHANGED: &str = "output files changed or missing";
const ROWS_CHANGED: &str = "rows changed";
const REPORT_UNFINISHED: &str = "report missing or unfinished";

impl std::fmt::Display for StaleReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StaleReason::New => f.write_str(NEW),
            StaleReason::CacheEntryMissing => f.write_str(CACHE_ENTRY_MISSING),
            StaleReason::Changed(parts) => write!(f, "{CHANGED}{}", parts.join(", ")),
            StaleReason::Upstream(stage) => write!(f, "{stage}{UPSTREAM}"),
            StaleReason::NoCachedAnswer => f.write_str(NO_CACHED_ANSWER),
            StaleReason::LabelsNotCached => f.write_str(LABELS_NOT_CACHED),
            StaleReason::NeverWritten => f.write_str(NEVER_WRITTEN),
            StaleReason::OutputsChanged => f.write_str(OUTPUTS_CHANGED),
            StaleReason::RowsChanged => f.write_str(ROWS_CHANGED),
            StaleReason::ReportUnfinished => f.write_str(REPORT_UNFINISHED),
        }
    }
}

impl StaleReason {
    /// The reasons that carry nothing: each read back by its words alone.
    const FIXED: [StaleReason; 8] = [
        StaleReason::New,
        StaleReason::CacheEntryMissing,
        StaleReason::NoCachedAnswer,
        StaleReason::LabelsNotCached,
        StaleReason::NeverWritten,
        StaleReason::OutputsChanged,
        StaleReason::RowsChanged,
        StaleReason::ReportUnfinished,
    ];
}

impl std::str::FromStr for StaleReason {
    type Err = String;

    /// Reads the words back (`plan --json` holds them).
    fn from_str(s: &str) -> Result<StaleReason, String> {
        if let Some(reason) = StaleReason::FIXED.into_iter().find(|r| r.to_string() == s) {
            return Ok(reason);
        }
        if let Some(parts) = s.strip_prefix(CHANGED) {
            return Ok(StaleReason::Changed(
                parts.split(", ").map(str::to_string).collect(),
            ));
        }
        if let Some(stage) = s.strip_suffix(UPSTREAM) {
            return stage.parse().map(StaleReason::Upstream);
        }
        Err(format!("unknown reason to run `{s}`"))
    }
}

impl Ord for StaleReason {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.to_string().cmp(&other.to_string())
    }
}

impl PartialOrd for StaleReason {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Serialize for StaleReason {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for StaleReason {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let words = String::deserialize(deserializer)?;
        words.parse().map_err(serde::de::Error::custom)
    }
}

/// What a build of a config would run, stage by stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Dataset name.
    pub dataset: String,
    /// The dataset folder.
    pub output: PathBuf,
    /// Every stage up to the requested one, in order.
    pub stages: Vec<StagePlan>,
}

impl Plan {
    /// True when a build would reuse everything.
    pub fn nothing_to_run(&self) -> bool {
        self.stages.iter().all(StagePlan::fresh)
    }
}

/// Works out what `build` (or `run` up to `options.through`) would compute, and why, from the
/// stage cache and the ledger of the last run. Reads captures and cached outputs; runs no stage,
/// writes no stage output or dataset file, and sends no LLM request (with an `[llm]` section it
/// opens the response cache, creating the empty file if there is none).
pub fn plan(config: &Config, options: &BuildOptions) -> Result<Plan, BuildError> {
    let options = BuildOptions {
        force: false,
        offline: true,
        ..options.clone()
    };
    let through = options.through.unwrap_or(Stage::Report);
    let mut staged = BuildState::open(config, &options, true)?;
    steps::run_steps(&mut staged, &steps::STAGES)?;
    steps::run_steps(&mut staged, &steps::SINKS)?;
    let workspace: &Workspace = &staged.shared.workspace;
    let ledger = Ledger::load(workspace);
    let seen = workspace.take_seen().into_vec()?;
    let mut plans: BTreeMap<Stage, StagePlan> = Stage::ALL
        .into_iter()
        .filter(|s| *s <= through)
        .map(|s| (s, StagePlan::new(s, enabled(config, s))))
        .collect();
    // Per-item stages: every item seen is fresh (cached) or stale with a reason.
    for entry in &seen {
        let Some(stage) = Stage::ALL.into_iter().find(|s| s.name() == entry.stage) else {
            continue;
        };
        let Some(plan) = plans.get_mut(&stage) else {
            continue;
        };
        plan.items += 1;
        if !workspace.has(&entry.stage, &entry.stamp.fingerprint) {
            plan.stale(
                &entry.key,
                ledger.why(&entry.stage, &entry.key, &entry.stamp),
            );
        }
    }
    count_as_a_build_does(&mut plans, &staged.stages);
    // Whatever comes after the first stale stage re-runs because of it.
    let blocked = staged.blocked;
    if let Some(first) = blocked {
        for (_, plan) in plans.iter_mut().filter(|(s, _)| **s > first) {
            if plan.enabled && plan.to_run == 0 {
                plan.stale("*", StaleReason::Upstream(first));
            }
        }
    }
    // LLM-only stages: texts without a cached answer would be asked.
    let text = &staged.text;
    for (stage, report) in [
        (Stage::Paraphrase, &text.paraphrase),
        (Stage::Plan, &text.plan),
        (Stage::PairCheck, &staged.pair_check),
    ] {
        if let Some(plan) = plans.get_mut(&stage).filter(|p| p.enabled) {
            plan.items = plan.items.max(report.texts);
            // The report keeps reasons as their words; read back, the variant decides.
            let asked: usize = report
                .skipped
                .iter()
                .filter(|(reason, _)| Unanswered::from((*reason).clone()).is_offline_miss())
                .map(|(_, n)| n)
                .sum();
            for _ in 0..asked {
                plan.stale("text", StaleReason::NoCachedAnswer);
            }
        }
    }
    if let Some(label) = plans.get_mut(&Stage::Label) {
        let asked = text
            .label
            .missing
            .iter()
            .filter(|(_, reason)| reason.is_offline_miss())
            .count();
        if asked > 0 {
            *label
                .reasons
                .entry(StaleReason::LabelsNotCached)
                .or_insert(0) += asked;
        }
    }
    if let Some(table) = staged.table.as_ref().filter(|_| through >= Stage::Write) {
        let stamp = &table.stamp;
        let write_fresh = output::written(&staged.output, workspace, &stamp.fingerprint);
        if let Some(plan) = plans.get_mut(&Stage::Write)
            && let Err(why) = write_fresh.clone()
        {
            let reason = match why {
                StaleReason::RowsChanged => ledger.why(Stage::Write.name(), "*", stamp),
                _ => why,
            };
            plan.stale("*", reason);
        }
        if let Some(plan) = plans.get_mut(&Stage::Report) {
            if write_fresh.is_err() {
                plan.stale("*", StaleReason::Upstream(Stage::Write));
            } else if !sinks::report_is_current(
                &staged.output,
                workspace,
                &sinks::report_stamp(&stamp.fingerprint).fingerprint,
            ) {
                plan.stale("*", StaleReason::ReportUnfinished);
            }
        }
    }
    Ok(Plan {
        dataset: config.dataset.name.clone(),
        output: staged.output.clone(),
        stages: plans.into_values().collect(),
    })
}

/// False for a stage the config turns off: it runs nothing, whatever comes before it.
fn enabled(config: &Config, stage: Stage) -> bool {
    match stage {
        Stage::Paraphrase => config.paraphrases.enabled,
        Stage::Plan => config.task_plans.enabled,
        Stage::Mirror => config.mirror.enabled,
        Stage::PairCheck => config.synthetic.enabled && config.synthetic.llm_check,
        _ => true,
    }
}

/// Stages over the whole set have one cache entry, but a build counts their items (clips
/// labelled, pairs composed, as the probe's `runs` say, also when they would run): the plan counts
/// them the same way. Write and report make one dataset and one report, whatever comes before.
fn count_as_a_build_does(plans: &mut BTreeMap<Stage, StagePlan>, runs: &[super::StageRun]) {
    for run in runs {
        let Some(stage) = [Stage::Label, Stage::Compose]
            .into_iter()
            .find(|s| s.name() == run.stage)
        else {
            continue;
        };
        if let Some(plan) = plans.get_mut(&stage) {
            plan.items = run.items;
            if !plan.fresh() {
                plan.to_run = run.items;
                plan.reasons.values_mut().for_each(|n| *n = run.items);
            }
        }
    }
    for stage in [Stage::Write, Stage::Report] {
        if let Some(plan) = plans.get_mut(&stage) {
            plan.items = 1;
        }
    }
}

/// One stage's state: fresh or stale now, and what its last run did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageStatus {
    /// The stage.
    pub stage: Stage,
    /// False when the config turns the stage off: it runs nothing.
    #[serde(default = "on")]
    pub enabled: bool,
    /// True when a build would reuse all of it.
    pub fresh: bool,
    /// Items that would run now.
    pub to_run: usize,
    /// Why they would run.
    pub reasons: BTreeMap<StaleReason, usize>,
    /// When it last ran (seconds since the Unix epoch), if ever.
    pub last_run: Option<u64>,
    /// Items it covered then.
    pub items: usize,
    /// Items it computed then.
    pub ran: usize,
    /// Items it reused then.
    pub reused: usize,
}

/// The state of a dataset: every stage's freshness and last run, and the built dataset's rows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// Dataset name.
    pub dataset: String,
    /// The dataset folder.
    pub output: PathBuf,
    /// Rows per split in the written manifest, in split order (empty when never written).
    pub splits: Vec<(String, u64)>,
    /// Per stage, in order.
    pub stages: Vec<StageStatus>,
}

/// The status of the dataset a config describes (see [`plan`] for what it reads).
pub fn status(config: &Config) -> Result<Status, BuildError> {
    let plan = plan(config, &BuildOptions::default())?;
    let ledger = Ledger::load(&Workspace::new(&plan.output));
    let manifest = motionforge_format::io::manifest::Manifest::read(&plan.output)?;
    let splits = manifest
        .map(|m| {
            // Keyed by split, so listed in split order (train, validation, test, then others).
            let rows: BTreeMap<motionforge_sources::clip::Split, u64> = m
                .splits
                .iter()
                .map(|(k, v)| {
                    (
                        motionforge_sources::clip::Split::new(k.as_str()),
                        v.rows as u64,
                    )
                })
                .collect();
            rows.into_iter().map(|(k, n)| (k.to_string(), n)).collect()
        })
        .unwrap_or_default();
    let stages = plan
        .stages
        .into_iter()
        .map(|p| {
            let last = ledger.stages.get(p.stage.name());
            StageStatus {
                stage: p.stage,
                enabled: p.enabled,
                fresh: p.fresh(),
                to_run: p.to_run,
                reasons: p.reasons,
                last_run: last.map(|l| l.last_run),
                items: last.map_or(0, |l| l.items),
                ran: last.map_or(0, |l| l.ran),
                reused: last.map_or(0, |l| l.reused),
            }
        })
        .collect();
    Ok(Status {
        dataset: plan.dataset,
        output: plan.output,
        splits,
        stages,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_read_back_from_their_words_and_list_in_word_order() {
        let carrying = [
            StaleReason::Changed(vec!["file content".into(), "config dataset.seed".into()]),
            StaleReason::Upstream(Stage::Ingest),
        ];
        let reasons: Vec<StaleReason> = StaleReason::FIXED.into_iter().chain(carrying).collect();
        for reason in &reasons {
            assert_eq!(
                reason.to_string().parse::<StaleReason>().as_ref(),
                Ok(reason)
            );
        }
        assert_eq!(
            StaleReason::Upstream(Stage::Write).to_string(),
            "write re-runs first"
        );
        let counted: BTreeMap<StaleReason, usize> =
            reasons.iter().cloned().map(|r| (r, 1)).collect();
        let json = serde_json::to_string(&counted).unwrap();
        let words: BTreeMap<String, usize> = serde_json::from_str(&json).unwrap();
        assert_eq!(serde_json::to_string(&words).unwrap(), json);
        assert_eq!(
            serde_json::from_str::<BTreeMap<StaleReason, usize>>(&json).unwrap(),
            counted
        );
        assert!("gremlins".parse::<StaleReason>().is_err());
    }
}
