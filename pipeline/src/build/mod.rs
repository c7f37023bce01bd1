//! The build runner: runs the stages over every capture, reuses cached work whose fingerprint is
//! unchanged, writes outputs atomically and records what it rejected and why.

mod reject;
mod workspace;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use reject::Reject;
pub use workspace::{
    Fingerprint, Workspace, WorkspaceError, sha256_hex, temp_path, write_atomic, write_atomic_with,
};

use crate::clip::Clip;
use crate::config::Config;
use crate::io::parquet::{TableError, write_clips};
use crate::motion::{Profile, ProfileSpec};
use crate::source::{self, CaptureFile, SourceError};
use crate::stages::{ingest, mirror};

/// Name of the clip table inside the output folder.
pub const CLIPS_FILE: &str = "clips.parquet";
/// Skeleton descriptions beside the table.
pub const SKELETONS_FILE: &str = "skeletons.json";
/// One JSON object per rejected input.
pub const REJECTS_FILE: &str = "rejects.jsonl";
/// What the last build did.
pub const REPORT_FILE: &str = "build-report.json";

/// Version of the table-writing stage.
const WRITE_VERSION: u32 = 1;

/// Errors that stop a build (bad inputs do not: they become rejects).
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// A source cannot be resolved.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// The workspace or an output cannot be written.
    #[error(transparent)]
    Workspace(#[from] WorkspaceError),
    /// The table cannot be written.
    #[error("{path}: {source}")]
    Table {
        /// The table path.
        path: PathBuf,
        /// The error.
        source: TableError,
    },
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
    /// Clips per action label (originals only).
    pub actions: BTreeMap<String, usize>,
    /// Rejected inputs by reason.
    pub rejects_by_reason: BTreeMap<String, usize>,
    /// Every rejected input.
    pub rejects: Vec<Reject>,
    /// Fingerprint of the written table's inputs.
    pub table_fingerprint: String,
}

impl BuildReport {
    /// True when no stage ran any item: everything was reused.
    pub fn nothing_ran(&self) -> bool {
        self.stages.iter().all(|s| s.ran == 0)
    }
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct State {
    table_fingerprint: String,
    outputs: BTreeMap<String, String>,
}

/// Options of a build.
#[derive(Debug, Clone, Default)]
pub struct BuildOptions {
    /// Ignore the cache and recompute everything.
    pub force: bool,
}

struct Item {
    file: CaptureFile,
    fingerprint: String,
    output: ingest::IngestOutput,
    ran: bool,
}

/// Runs every stage of the build described by `config`.
pub fn build(config: &Config, options: &BuildOptions) -> Result<BuildReport, BuildError> {
    let output = config.output_dir();
    let workspace = Workspace::new(&output);
    if options.force {
        let _ = std::fs::remove_dir_all(workspace.root().join("cache"));
    }
    let files = source::discover(config)?;
    let specs: Vec<ProfileSpec> = config
        .sources
        .iter()
        .map(|s| source::resolve_profile(config, s))
        .collect::<Result<_, _>>()?;

    let items: Vec<Item> = files
        .par_iter()
        .map(|file| ingest_item(config, &specs, &workspace, file))
        .collect::<Result<_, _>>()?;
    let mut stages = vec![StageRun {
        stage: ingest::NAME.into(),
        items: items.len(),
        ran: items.iter().filter(|i| i.ran).count(),
        reused: items.iter().filter(|i| !i.ran).count(),
    }];

    let mut clips: Vec<Clip> = Vec::new();
    let mut rejects: Vec<Reject> = Vec::new();
    let mut fingerprints: Vec<String> = Vec::new();
    for item in &items {
        clips.extend(item.output.clips.iter().cloned());
        rejects.extend(item.output.rejects.iter().cloned());
        fingerprints.push(item.fingerprint.clone());
    }

    if config.mirror.enabled {
        let mirrored: Vec<(String, mirror::MirrorOutput, bool)> = items
            .par_iter()
            .map(|item| {
                let spec = &specs[item.file.source];
                let fp = mirror::fingerprint(&item.fingerprint, spec);
                let (out, ran) = workspace
                    .cached(mirror::NAME, &fp, || mirror::run(&item.output.clips, spec))?;
                Ok((fp, out, ran))
            })
            .collect::<Result<_, WorkspaceError>>()?;
        stages.push(StageRun {
            stage: mirror::NAME.into(),
            items: mirrored.len(),
            ran: mirrored.iter().filter(|m| m.2).count(),
            reused: mirrored.iter().filter(|m| !m.2).count(),
        });
        for (fp, out, _) in mirrored {
            clips.extend(out.clips);
            rejects.extend(out.rejects);
            fingerprints.push(fp);
        }
    }
    for (stage, keep) in [(ingest::NAME, 0usize), (mirror::NAME, items.len())] {
        let live: BTreeSet<String> = fingerprints
            .iter()
            .skip(keep)
            .take(items.len())
            .cloned()
            .collect();
        workspace.prune(stage, &live);
    }

    // Row order: by clip id, so the table does not depend on scheduling or glob order.
    clips.sort_by(|a, b| {
        a.clip_id
            .cmp(&b.clip_id)
            .then(a.capture.path.cmp(&b.capture.path))
    });
    rejects.sort_by(|a, b| (&a.file, a.line, &a.stage).cmp(&(&b.file, b.line, &b.stage)));

    let mut profiles: BTreeMap<String, Profile> = BTreeMap::new();
    let mut skeletons: BTreeMap<String, serde_json::Value> = BTreeMap::new();
    for clip in &clips {
        if profiles.contains_key(&clip.profile) {
            continue;
        }
        if let Some(spec) = specs.iter().find(|s| s.name == clip.profile)
            && let Ok(bound) = spec.bind(&clip.motion.skeleton)
        {
            skeletons.insert(
                clip.profile.clone(),
                skeleton_json(&clip.motion.skeleton, &bound),
            );
            profiles.insert(clip.profile.clone(), bound);
        }
    }
    let table_fingerprint = Fingerprint::new("write", WRITE_VERSION)
        .json(&fingerprints)
        .json(&crate::io::schema::SCHEMA_VERSION)
        .finish();
    let write_ran = write_outputs(
        &output,
        &workspace,
        &table_fingerprint,
        &clips,
        &profiles,
        &skeletons,
        &rejects,
    )?;
    stages.push(StageRun {
        stage: "write".into(),
        items: 1,
        ran: usize::from(write_ran),
        reused: usize::from(!write_ran),
    });

    let mut actions = BTreeMap::new();
    for clip in clips.iter().filter(|c| !c.mirrored) {
        *actions.entry(clip.action.clone()).or_insert(0) += 1;
    }
    let mut rejects_by_reason = BTreeMap::new();
    for r in &rejects {
        *rejects_by_reason.entry(r.reason.clone()).or_insert(0) += 1;
    }
    let report = BuildReport {
        dataset: config.dataset.name.clone(),
        output: output.clone(),
        stages,
        captures: files.len(),
        clips: clips.len(),
        mirrored: clips.iter().filter(|c| c.mirrored).count(),
        actions,
        rejects_by_reason,
        rejects,
        table_fingerprint,
    };
    let json = serde_json::to_vec_pretty(&report).unwrap_or_default();
    write_atomic(&output.join(REPORT_FILE), &json)?;
    Ok(report)
}

fn ingest_item(
    config: &Config,
    specs: &[ProfileSpec],
    workspace: &Workspace,
    file: &CaptureFile,
) -> Result<Item, BuildError> {
    let source = &config.sources[file.source];
    let unreadable = |e: std::io::Error| ingest::IngestOutput {
        clips: Vec::new(),
        rejects: vec![Reject {
            stage: ingest::NAME.into(),
            file: file.display.clone(),
            line: None,
            frame: None,
            reason: "io".into(),
            message: format!("cannot read: {e}"),
        }],
    };
    let bytes = match std::fs::read(&file.path) {
        Ok(b) => b,
        Err(e) => {
            return Ok(Item {
                file: file.clone(),
                fingerprint: Fingerprint::new("unreadable", 0)
                    .text(&file.display)
                    .finish(),
                output: unreadable(e),
                ran: true,
            });
        }
    };
    let uses_sidecar = matches!(
        source.labels,
        crate::config::LabelConfig::Filename { sidecar: true, .. }
    );
    let sidecar = if uses_sidecar {
        std::fs::read(file.path.with_extension("json")).ok()
    } else {
        None
    };
    let input = ingest::CaptureInput {
        file,
        bytes: &bytes,
        sidecar: sidecar.as_deref(),
        source,
        profile: &specs[file.source],
        fps_override: source::fps_override(source, file),
        fps: config.dataset.fps,
    };
    let fingerprint = ingest::fingerprint(&input);
    let (output, ran) = workspace.cached(ingest::NAME, &fingerprint, || ingest::run(&input))?;
    Ok(Item {
        file: file.clone(),
        fingerprint,
        output,
        ran,
    })
}

fn skeleton_json(skeleton: &crate::motion::Skeleton, profile: &Profile) -> serde_json::Value {
    let joints: Vec<serde_json::Value> = skeleton
        .joints
        .iter()
        .enumerate()
        .map(|(j, joint)| {
            let o = joint.offset * profile.unit_scale;
            serde_json::json!({
                "name": joint.name,
                "parent": joint.parent,
                "offset_m": [o.x, o.y, o.z],
                "mirror": skeleton.joints[profile.swap[j]].name,
                "part": profile.part_of[j],
                "role": profile.roles[j],
            })
        })
        .collect();
    serde_json::json!({
        "profile": profile.name,
        "root": skeleton.joints[profile.root].name,
        "capture_axes": { "up": profile.up.to_string(), "forward": profile.forward.to_string() },
        "unit_scale": profile.unit_scale,
        "joints": joints,
    })
}

fn outputs_match(output: &Path, state: &State) -> bool {
    !state.outputs.is_empty()
        && state.outputs.iter().all(|(name, sha)| {
            std::fs::read(output.join(name))
                .map(|b| &sha256_hex(&b) == sha)
                .unwrap_or(false)
        })
}

/// Writes the table and its companions unless the last build wrote the same; returns whether it
/// wrote.
fn write_outputs(
    output: &Path,
    workspace: &Workspace,
    fingerprint: &str,
    clips: &[Clip],
    profiles: &BTreeMap<String, Profile>,
    skeletons: &BTreeMap<String, serde_json::Value>,
    rejects: &[Reject],
) -> Result<bool, BuildError> {
    let state_path = workspace.root().join("state.json");
    let state: State = std::fs::read(&state_path)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or_default();
    if state.table_fingerprint == fingerprint && outputs_match(output, &state) {
        return Ok(false);
    }
    let skeletons_json = serde_json::to_string_pretty(skeletons).unwrap_or_default();
    let table = output.join(CLIPS_FILE);
    let mut table_error = None;
    write_atomic_with(&table, |file| {
        let f = file.try_clone()?;
        write_clips(f, clips, profiles, &skeletons_json)
            .map(|_| ())
            .map_err(|e| {
                table_error = Some(e);
                std::io::Error::other("table encoding failed")
            })
    })
    .map_err(|e| match table_error.take() {
        Some(source) => BuildError::Table {
            path: table.clone(),
            source,
        },
        None => BuildError::Workspace(e),
    })?;
    write_atomic(&output.join(SKELETONS_FILE), skeletons_json.as_bytes())?;
    let mut lines = String::new();
    for r in rejects {
        lines.push_str(&serde_json::to_string(r).unwrap_or_default());
        lines.push('\n');
    }
    write_atomic(&output.join(REJECTS_FILE), lines.as_bytes())?;
    let mut outputs = BTreeMap::new();
    for name in [CLIPS_FILE, SKELETONS_FILE, REJECTS_FILE] {
        let bytes =
            std::fs::read(output.join(name)).map_err(workspace::io_err(&output.join(name)))?;
        outputs.insert(name.to_string(), sha256_hex(&bytes));
    }
    let state = State {
        table_fingerprint: fingerprint.to_string(),
        outputs,
    };
    write_atomic(
        &state_path,
        &serde_json::to_vec_pretty(&state).unwrap_or_default(),
    )?;
    Ok(true)
}
