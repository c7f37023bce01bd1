//! `plan` and `status`: what a build would run and why, without running it.

use motionforge_llm::Unanswered;
use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::{
    BuildError, BuildOptions, Ledger, Stage, Workspace, output, report_is_current, run_stages,
    table_stamp,
};
use crate::config::Config;

/// What one stage would do.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StagePlan {
    /// The stage.
    pub stage: Stage,
    /// Items it covers (captures, or 1 for stages over the whole set) as far as known: items
    /// behind a stale stage are counted there.
    pub items: usize,
    /// Items that would be computed.
    pub to_run: usize,
    /// Why, with how many items each reason covers.
    pub reasons: BTreeMap<String, usize>,
    /// A few items that would run, with their reason.
    pub examples: Vec<String>,
}

impl StagePlan {
    fn new(stage: Stage) -> StagePlan {
        StagePlan {
            stage,
            items: 0,
            to_run: 0,
            reasons: BTreeMap::new(),
            examples: Vec::new(),
        }
    }

    fn stale(&mut self, key: &str, reason: String) {
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
    let staged = run_stages(config, &options, true)?;
    let workspace: &Workspace = &staged.shared.workspace;
    let ledger = Ledger::load(workspace);
    let seen = workspace.take_seen().into_vec()?;
    let mut plans: BTreeMap<Stage, StagePlan> = Stage::ALL
        .into_iter()
        .filter(|s| *s <= through)
        .map(|s| (s, StagePlan::new(s)))
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
        for (stage, plan) in plans.iter_mut().filter(|(s, _)| **s > first) {
            if !config.mirror.enabled && *stage == Stage::Mirror {
                continue;
            }
            if plan.to_run == 0 {
                plan.stale("*", format!("{first} re-runs first"));
            }
        }
    }
    // LLM-only stages: texts without a cached answer would be asked.
    let text = &staged.text;
    for (stage, report, enabled) in [
        (
            Stage::Paraphrase,
            &text.paraphrase,
            config.paraphrases.enabled,
        ),
        (Stage::Plan, &text.plan, config.task_plans.enabled),
    ] {
        if let Some(plan) = plans.get_mut(&stage).filter(|_| enabled) {
            plan.items = plan.items.max(report.texts);
            let asked: usize = report
                .skipped
                .iter()
                .filter(|(reason, _)| **reason == Unanswered::Offline.to_string())
                .map(|(_, n)| n)
                .sum();
            for _ in 0..asked {
                plan.stale("text", "no cached LLM answer".to_string());
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
                .entry("texts without a cached LLM answer (asked when online)".to_string())
                .or_insert(0) += asked;
        }
    }
    if blocked.is_none() && through >= Stage::Write {
        let stamp = table_stamp(config, &staged.clips, &staged.index, &text.plans)?;
        let write_fresh = output::written(&staged.output, workspace, &stamp.fingerprint);
        if let Some(plan) = plans.get_mut(&Stage::Write)
            && let Err(why) = write_fresh.clone()
        {
            let reason = match why.as_str() {
                "rows changed" => ledger.why(Stage::Write.name(), "*", &stamp),
                _ => why,
            };
            plan.stale("*", reason);
        }
        if let Some(plan) = plans.get_mut(&Stage::Report) {
            if write_fresh.is_err() {
                plan.stale("*", "write re-runs first".to_string());
            } else if !report_is_current(&staged.output, workspace, &stamp.fingerprint) {
                plan.stale("*", "report missing or unfinished".to_string());
            }
        }
    }
    Ok(Plan {
        dataset: config.dataset.name.clone(),
        output: staged.output.clone(),
        stages: plans.into_values().collect(),
    })
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
    /// True when a build would reuse all of it.
    pub fresh: bool,
    /// Items that would run now.
    pub to_run: usize,
    /// Why they would run.
    pub reasons: BTreeMap<String, usize>,
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
