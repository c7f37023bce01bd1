//! The build runner: runs the stages over every capture, reuses cached work whose fingerprint is
//! unchanged, writes outputs atomically and records what it rejected and why.

mod reject;
pub mod workspace;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use reject::Reject;
pub use workspace::{
    Fingerprint, Workspace, WorkspaceError, sha256_hex, temp_path, write_atomic, write_atomic_with,
};

use crate::annotate::filename::filename_annotation;
use crate::annotate::span::Note;
use crate::annotate::taxonomy::{Taxonomy, TaxonomyError, TypeMap};
use crate::clip::{Clip, SourceKind};
use crate::config::Config;
use crate::io::parquet::{TableError, write_clips};
use crate::motion::{Profile, ProfileSpec};
use crate::source::{self, CaptureFile, SourceAnnotations, SourceError};
use crate::stages::segment::{self, SegmentOutput};
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
    /// The motion-type taxonomy or mapping is invalid.
    #[error(transparent)]
    Taxonomy(#[from] TaxonomyError),
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
    /// Rows by source kind (`real_single`, `real_pair`, ...), mirrors included.
    pub kinds: BTreeMap<String, usize>,
    /// Clips per action label (originals only).
    pub actions: BTreeMap<String, usize>,
    /// Single clips per motion type (originals only); `(unmapped)` for labels with no type.
    pub motion_types: BTreeMap<String, usize>,
    /// Labels that map to no motion type, with counts: listed, never merged.
    pub unmapped_labels: BTreeMap<String, usize>,
    /// Segments dropped during segmentation, by reason.
    pub drops_by_reason: BTreeMap<String, usize>,
    /// Annotation quirks handled (clamped ends, null labels, ...), by kind.
    pub notes_by_kind: BTreeMap<String, usize>,
    /// Every annotation quirk, for people.
    pub notes: Vec<Note>,
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

/// What the per-capture stages produced for one capture.
#[derive(Default)]
struct Item {
    ran: [bool; 3],
    fingerprints: Vec<(&'static str, String)>,
    clips: Vec<Clip>,
    rejects: Vec<Reject>,
    segment: SegmentOutput,
}

/// Everything the per-capture stages share.
struct Shared<'a> {
    config: &'a Config,
    workspace: Workspace,
    specs: Vec<ProfileSpec>,
    annotations: Vec<SourceAnnotations>,
    fps_tables: Vec<BTreeMap<String, f64>>,
    types: TypeMap,
    /// Digest of the taxonomy's content and the mapping config: a taxonomy edit re-runs segments.
    types_digest: String,
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
    let shared = Shared {
        config,
        workspace,
        specs,
        annotations,
        fps_tables,
        types,
        types_digest,
    };

    let items: Vec<Item> = files
        .par_iter()
        .map(|file| run_capture(&shared, file))
        .collect::<Result<_, _>>()?;

    let mut stages = Vec::new();
    let names = [ingest::NAME, segment::NAME, mirror::NAME];
    for (k, name) in names.iter().enumerate() {
        if k == 2 && !config.mirror.enabled {
            continue;
        }
        let covered: Vec<&Item> = items
            .iter()
            .filter(|i| i.fingerprints.iter().any(|(s, _)| s == name))
            .collect();
        stages.push(StageRun {
            stage: (*name).into(),
            items: covered.len(),
            ran: covered.iter().filter(|i| i.ran[k]).count(),
            reused: covered.iter().filter(|i| !i.ran[k]).count(),
        });
    }
    for name in names {
        let live: BTreeSet<String> = items
            .iter()
            .flat_map(|i| {
                i.fingerprints
                    .iter()
                    .filter(|(s, _)| *s == name)
                    .map(|(_, f)| f.clone())
            })
            .collect();
        shared.workspace.prune(name, &live);
    }

    let mut clips: Vec<Clip> = Vec::new();
    let mut rejects: Vec<Reject> = Vec::new();
    let mut fingerprints: Vec<String> = Vec::new();
    let mut drops_by_reason = BTreeMap::new();
    let mut unmapped_labels = BTreeMap::new();
    let mut notes: Vec<Note> = Vec::new();
    for item in items {
        clips.extend(item.clips);
        rejects.extend(item.rejects);
        fingerprints.extend(item.fingerprints.into_iter().map(|(_, f)| f));
        add_counts(&mut drops_by_reason, item.segment.drops);
        add_counts(&mut unmapped_labels, item.segment.unmapped);
        notes.extend(item.segment.notes);
    }
    let mut matched: BTreeSet<(usize, String)> = BTreeSet::new();
    for file in &files {
        matched.insert((file.source, file.stem()));
    }
    for (index, ann) in shared.annotations.iter().enumerate() {
        if let SourceAnnotations::Indexed {
            by_key,
            notes: file_notes,
        } = ann
        {
            notes.extend(file_notes.iter().cloned());
            for key in by_key
                .keys()
                .filter(|k| !matched.contains(&(index, (*k).clone())))
            {
                notes.push(Note::new(
                    "annotation_without_capture",
                    format!(
                        "source `{}`: annotations for `{key}` match no capture file",
                        config.sources[index].name
                    ),
                ));
            }
        }
    }

    // Row order: by clip id, so the table does not depend on scheduling or glob order.
    clips.sort_by(|a, b| {
        a.clip_id
            .cmp(&b.clip_id)
            .then(a.capture.path.cmp(&b.capture.path))
    });
    rejects.sort_by(|a, b| (&a.file, a.line, &a.stage).cmp(&(&b.file, b.line, &b.stage)));
    notes.sort();

    let mut profiles: BTreeMap<String, Profile> = BTreeMap::new();
    let mut skeletons: BTreeMap<String, serde_json::Value> = BTreeMap::new();
    for clip in &clips {
        if profiles.contains_key(&clip.profile) {
            continue;
        }
        if let Some(spec) = shared.specs.iter().find(|s| s.name == clip.profile)
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
    let table = Table {
        clips: &clips,
        profiles: &profiles,
        skeletons: &skeletons,
        rejects: &rejects,
    };
    let write_ran = write_outputs(
        options.force,
        &output,
        &shared.workspace,
        &table_fingerprint,
        &table,
    )?;
    stages.push(StageRun {
        stage: "write".into(),
        items: 1,
        ran: usize::from(write_ran),
        reused: usize::from(!write_ran),
    });

    let mut actions = BTreeMap::new();
    let mut motion_types = BTreeMap::new();
    let mut kinds = BTreeMap::new();
    for clip in &clips {
        *kinds.entry(clip.kind.as_str().to_string()).or_insert(0) += 1;
        if clip.mirrored {
            continue;
        }
        *actions.entry(clip.action.clone()).or_insert(0) += 1;
        if clip.kind == SourceKind::RealSingle {
            let t = clip
                .motion_type
                .clone()
                .unwrap_or_else(|| "(unmapped)".into());
            *motion_types.entry(t).or_insert(0) += 1;
        }
    }
    let mut rejects_by_reason = BTreeMap::new();
    for r in &rejects {
        *rejects_by_reason.entry(r.reason.clone()).or_insert(0) += 1;
    }
    let mut notes_by_kind = BTreeMap::new();
    for n in &notes {
        *notes_by_kind.entry(n.kind.clone()).or_insert(0) += 1;
    }
    let report = BuildReport {
        dataset: config.dataset.name.clone(),
        output: output.clone(),
        stages,
        captures: files.len(),
        clips: clips.len(),
        mirrored: clips.iter().filter(|c| c.mirrored).count(),
        kinds,
        actions,
        motion_types,
        unmapped_labels,
        drops_by_reason,
        notes_by_kind,
        notes,
        rejects_by_reason,
        rejects,
        table_fingerprint,
    };
    let json = serde_json::to_vec_pretty(&report).unwrap_or_default();
    write_atomic(&output.join(REPORT_FILE), &json)?;
    Ok(report)
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
            crate::annotate::taxonomy::BUNDLED_TOML.to_string(),
        ),
    };
    let digest = Fingerprint::new("motion_types", 1)
        .text(&text)
        .json(cfg)
        .finish();
    Ok((
        TypeMap::new(taxonomy.with_extra(cfg.extra.clone())?, cfg)?,
        digest,
    ))
}

/// Runs ingest, segment and mirror for one capture, reusing cached outputs.
fn run_capture(shared: &Shared<'_>, file: &CaptureFile) -> Result<Item, BuildError> {
    let config = shared.config;
    let source = &config.sources[file.source];
    let spec = &shared.specs[file.source];
    let mut item = Item::default();
    let bytes = match std::fs::read(&file.path) {
        Ok(b) => b,
        Err(e) => {
            item.rejects.push(ingest::reject(
                ingest::NAME,
                file,
                "io",
                format!("cannot read: {e}"),
                None,
                None,
            ));
            return Ok(item);
        }
    };
    let input = ingest::CaptureInput {
        file,
        bytes: &bytes,
        source: &source.name,
        profile: spec,
        fps_override: source::fps_override(source, &shared.fps_tables[file.source], file),
    };
    let ingest_fp = ingest::fingerprint(&input);
    let (ingested, ran): (ingest::IngestOutput, bool) =
        shared
            .workspace
            .cached(ingest::NAME, &ingest_fp, || ingest::run(&input))?;
    item.ran[0] = ran;
    item.fingerprints.push((ingest::NAME, ingest_fp.clone()));
    item.rejects.extend(ingested.rejects);
    let Some(capture) = ingested.capture else {
        return Ok(item);
    };
    drop(bytes);

    let annotation = match &shared.annotations[file.source] {
        SourceAnnotations::Filename {
            pattern,
            action,
            text,
            sidecar,
        } => {
            let side = if *sidecar {
                std::fs::read(file.path.with_extension("json")).ok()
            } else {
                None
            };
            match filename_annotation(pattern, action, text, &capture.stem, side.as_deref()) {
                Ok(a) => a,
                Err(refusal) => {
                    item.rejects.push(ingest::reject(
                        segment::NAME,
                        file,
                        refusal.reason,
                        refusal.message,
                        None,
                        None,
                    ));
                    return Ok(item);
                }
            }
        }
        SourceAnnotations::Indexed { by_key, .. } => match by_key.get(&capture.stem) {
            Some(a) => a.clone(),
            None => {
                let message = format!(
                    "no annotation for capture `{}` in the source's {} files",
                    capture.stem,
                    source.labels.kind()
                );
                item.rejects.push(ingest::reject(
                    segment::NAME,
                    file,
                    "no_annotation",
                    message,
                    None,
                    None,
                ));
                return Ok(item);
            }
        },
    };
    let profile = match spec.bind(&capture.motion.skeleton) {
        Ok(p) => p,
        Err(e) => {
            item.rejects.push(ingest::reject(
                segment::NAME,
                file,
                "profile",
                e.to_string(),
                None,
                None,
            ));
            return Ok(item);
        }
    };
    let seg_input = segment::SegmentInput {
        capture: &capture,
        annotation: &annotation,
        kind: source.labels.kind(),
        config: &source.segment,
        types: &shared.types,
        profile: &profile,
        fps: config.dataset.fps,
    };
    let seg_fp = segment::fingerprint(&ingest_fp, &seg_input, &shared.types_digest);
    let (segmented, ran): (SegmentOutput, bool) =
        shared
            .workspace
            .cached(segment::NAME, &seg_fp, || segment::run(&seg_input))?;
    item.ran[1] = ran;
    item.fingerprints.push((segment::NAME, seg_fp.clone()));

    if config.mirror.enabled {
        let fp = mirror::fingerprint(&seg_fp, spec, &shared.types_digest);
        let (mirrored, ran): (mirror::MirrorOutput, bool) =
            shared.workspace.cached(mirror::NAME, &fp, || {
                mirror::run(&segmented.clips, spec, shared.types.taxonomy())
            })?;
        item.ran[2] = ran;
        item.fingerprints.push((mirror::NAME, fp));
        item.clips.extend(mirrored.clips);
        item.rejects.extend(mirrored.rejects);
    }
    item.clips.extend(segmented.clips.iter().cloned());
    item.segment = segmented;
    item.segment.clips.clear();
    Ok(item)
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
/// What the write stage writes.
struct Table<'a> {
    clips: &'a [Clip],
    profiles: &'a BTreeMap<String, Profile>,
    skeletons: &'a BTreeMap<String, serde_json::Value>,
    rejects: &'a [Reject],
}

fn write_outputs(
    force: bool,
    output: &Path,
    workspace: &Workspace,
    fingerprint: &str,
    table: &Table<'_>,
) -> Result<bool, BuildError> {
    let Table {
        clips,
        profiles,
        skeletons,
        rejects,
    } = *table;
    let state_path = workspace.root().join("state.json");
    let state: State = std::fs::read(&state_path)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or_default();
    if !force && state.table_fingerprint == fingerprint && outputs_match(output, &state) {
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
