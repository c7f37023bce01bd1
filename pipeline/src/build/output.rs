//! The write stage: the clip table and its companions, written atomically, skipped when the last
//! build wrote the same.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{
    BuildError, CLIPS_FILE, PLANS_FILE, REJECTS_FILE, Reject, SKELETONS_FILE, Workspace,
    sha256_hex, workspace, write_atomic, write_atomic_with,
};
use crate::clip::Clip;
use crate::io::parquet::write_clips;
use crate::motion::Profile;

/// What the last write recorded: its inputs' fingerprint and the outputs' checksums.
#[derive(Debug, Default, Serialize, Deserialize)]
struct State {
    table_fingerprint: String,
    outputs: BTreeMap<String, String>,
}

pub(super) fn skeleton_json(
    skeleton: &crate::motion::Skeleton,
    profile: &Profile,
) -> serde_json::Value {
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
pub(super) struct Table<'a> {
    pub(super) plans: &'a BTreeMap<String, Vec<crate::llm::plans::PlanStep>>,
    pub(super) clips: &'a [Clip],
    pub(super) profiles: &'a BTreeMap<String, Profile>,
    pub(super) skeletons: &'a BTreeMap<String, serde_json::Value>,
    pub(super) rejects: &'a [Reject],
}

pub(super) fn write_outputs(
    force: bool,
    output: &Path,
    workspace: &Workspace,
    fingerprint: &str,
    table: &Table<'_>,
) -> Result<bool, BuildError> {
    let Table {
        plans,
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
    let plans_path = output.join(PLANS_FILE);
    let mut plans_error = None;
    write_atomic_with(&plans_path, |file| {
        crate::io::parquet::write_plans(file.try_clone()?, plans)
            .map(|_| ())
            .map_err(|e| {
                plans_error = Some(e);
                std::io::Error::other("plan table encoding failed")
            })
    })
    .map_err(|e| match plans_error.take() {
        Some(source) => BuildError::Table {
            path: plans_path.clone(),
            source,
        },
        None => BuildError::Workspace(e),
    })?;
    for name in [CLIPS_FILE, SKELETONS_FILE, REJECTS_FILE, PLANS_FILE] {
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
