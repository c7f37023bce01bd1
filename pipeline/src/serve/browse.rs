//! The dataset browser: `GET /` (a page built into the binary) and the read-only endpoints it
//! loads from: the clip listing with filters, one clip's metadata, one clip's motion, the report's
//! files. Every file answered is inside the dataset's own folder.

use std::path::{Component, PathBuf};
use std::sync::Arc;

use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};

use super::Shared;
use super::api::ApiError;
use crate::dataset::{self, ClipFilter, ClipInfo, DatasetError};

/// The page: HTML, CSS and JavaScript in one file, compiled in.
const PAGE: &str = include_str!("browser.html");
/// Clips one listing returns unless `limit` says otherwise.
const DEFAULT_CLIPS: usize = 100;
/// Most clips one listing returns.
const MAX_CLIPS: usize = 1000;

type AppState = Arc<Shared>;

pub(crate) async fn page() -> Response {
    (
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("text/html; charset=utf-8"),
        )],
        PAGE,
    )
        .into_response()
}

/// The dataset folder of a served dataset.
fn folder(shared: &Shared, name: &str) -> Result<PathBuf, ApiError> {
    shared
        .datasets
        .get(name)
        .map(|d| d.config.dataset_dir())
        .ok_or_else(|| super::api::unknown_dataset(shared, name))
}

fn dataset_error(shared: &Shared, e: DatasetError) -> ApiError {
    match e {
        DatasetError::NoClip { clip_id, count, .. } => ApiError::new(
            StatusCode::NOT_FOUND,
            format!(
                "no clip `{}` in this dataset ({count} clips)",
                super::public::excerpt(&clip_id)
            ),
        ),
        DatasetError::NotADataset { .. } => ApiError::new(
            StatusCode::NOT_FOUND,
            "the dataset has no clip table yet: build it first",
        ),
        other => ApiError::internal(shared.shield.text(&other.to_string())),
    }
}

async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, DatasetError> + Send + 'static,
) -> Result<Result<T, DatasetError>, ApiError> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(ApiError::internal)
}

/// The filters and page of `GET /datasets/{name}/clips`.
#[derive(Debug, Deserialize)]
pub(crate) struct ClipQuery {
    split: Option<String>,
    kind: Option<String>,
    #[serde(rename = "type")]
    motion_type: Option<String>,
    text: Option<String>,
    offset: Option<usize>,
    limit: Option<usize>,
}

fn nonempty(v: Option<String>) -> Option<String> {
    v.filter(|s| !s.is_empty())
}

pub(crate) async fn list_clips(
    State(shared): State<AppState>,
    Path(name): Path<String>,
    Query(q): Query<ClipQuery>,
) -> Result<Json<Value>, ApiError> {
    let dir = folder(&shared, &name)?;
    let limit = q.limit.unwrap_or(DEFAULT_CLIPS);
    if limit == 0 || limit > MAX_CLIPS {
        return Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            format!("limit {limit}: expected 1 to {MAX_CLIPS}"),
        ));
    }
    let offset = q.offset.unwrap_or(0);
    let filter = ClipFilter {
        motion_type: nonempty(q.motion_type),
        split: nonempty(q.split),
        kind: nonempty(q.kind),
        text: nonempty(q.text),
    };
    let clips = blocking(move || dataset::list_clips(&dir))
        .await?
        .map_err(|e| dataset_error(&shared, e))?;
    // The choices of each filter over the whole dataset, so a page can offer them.
    let mut types: Vec<&str> = clips
        .iter()
        .filter_map(|c| c.motion_type.as_deref())
        .collect();
    let mut splits: Vec<&str> = clips.iter().map(|c| c.split.as_str()).collect();
    let mut kinds: Vec<&str> = clips.iter().map(|c| c.source_kind.as_str()).collect();
    for v in [&mut types, &mut splits, &mut kinds] {
        v.sort_unstable();
        v.dedup();
    }
    kinds.extend(["mirrored", "original"]);
    let kept: Vec<&ClipInfo> = clips.iter().filter(|c| filter.matches(c)).collect();
    let page: Vec<&ClipInfo> = kept.iter().skip(offset).take(limit).copied().collect();
    Ok(Json(json!({
        "dataset": name,
        "total": kept.len(),
        "offset": offset,
        "limit": limit,
        "choices": { "type": types, "split": splits, "kind": kinds },
        "clips": page,
    })))
}

/// `?id=<clip id>`: clip ids hold `/`, `:` and `+`, so they travel as a query value.
#[derive(Debug, Deserialize)]
pub(crate) struct ClipId {
    id: String,
}

pub(crate) async fn clip_meta(
    State(shared): State<AppState>,
    Path(name): Path<String>,
    Query(q): Query<ClipId>,
) -> Result<Json<Value>, ApiError> {
    let dir = folder(&shared, &name)?;
    let clips = blocking(move || dataset::list_clips(&dir))
        .await?
        .map_err(|e| dataset_error(&shared, e))?;
    let Some(clip) = clips.iter().find(|c| c.clip_id == q.id) else {
        return Err(dataset_error(
            &shared,
            DatasetError::NoClip {
                path: PathBuf::new(),
                clip_id: q.id,
                count: clips.len(),
                hint: String::new(),
            },
        ));
    };
    let mirror = dataset::companion_ids(clip, dataset::Companions::Mirror, &clips);
    let sources = dataset::companion_ids(clip, dataset::Companions::Sources, &clips);
    let mut value = serde_json::to_value(clip).map_err(ApiError::internal)?;
    value["mirror"] = json!(mirror.first());
    value["sources"] = json!(sources);
    value.as_object_mut().map(|o| o.remove("shard"));
    Ok(Json(value))
}

pub(crate) async fn clip_motion(
    State(shared): State<AppState>,
    Path(name): Path<String>,
    Query(q): Query<ClipId>,
) -> Result<Json<Value>, ApiError> {
    let dir = folder(&shared, &name)?;
    let id = q.id.clone();
    let read = blocking(move || {
        let frames = dataset::read_clip(&dir, &id)?;
        let skeletons = dataset::read_skeletons(&dir)?;
        Ok((frames, skeletons))
    })
    .await?;
    let (frames, skeletons) = read.map_err(|e| dataset_error(&shared, e))?;
    let Some(skeleton) = skeletons.get(&frames.info.skeleton) else {
        return Err(ApiError::internal(format!(
            "skeleton `{}` is not in skeletons.json",
            frames.info.skeleton
        )));
    };
    if skeleton.joints.len() != frames.info.joints {
        return Err(ApiError::internal(format!(
            "skeleton `{}` has {} joints, the row of `{}` {}",
            frames.info.skeleton,
            skeleton.joints.len(),
            frames.info.clip_id,
            frames.info.joints
        )));
    }
    let positions = dataset::preview::canonical_positions(&frames, skeleton);
    Ok(Json(json!({
        "clip_id": frames.info.clip_id,
        "fps": frames.info.fps,
        "frames": frames.info.frames,
        "joints": frames.info.joints,
        "names": skeleton.joints.iter().map(|j| &j.name).collect::<Vec<_>>(),
        "parents": skeleton.parents(),
        "parts": skeleton.joints.iter().map(|j| &j.part).collect::<Vec<_>>(),
        "root": skeleton.root,
        "frame": "canonical: the first frame's pelvis on the ground at the origin, facing +y; x right, z up, metres",
        "positions": positions,
    })))
}

/// The report's folder.
fn report_dir(shared: &Shared, name: &str) -> Result<PathBuf, ApiError> {
    Ok(folder(shared, name)?.join("report"))
}

pub(crate) async fn report_files(
    State(shared): State<AppState>,
    Path(name): Path<String>,
) -> Result<Json<Value>, ApiError> {
    let dir = report_dir(&shared, &name)?;
    let files = tokio::task::spawn_blocking(move || {
        let mut found = Vec::new();
        let mut stack = vec![(dir.clone(), String::new())];
        while let Some((at, prefix)) = stack.pop() {
            let Ok(entries) = std::fs::read_dir(&at) else {
                continue;
            };
            for entry in entries.flatten() {
                let file = entry.file_name().to_string_lossy().into_owned();
                if file.starts_with('.') {
                    continue;
                }
                let rel = format!("{prefix}{file}");
                match entry.file_type() {
                    Ok(t) if t.is_dir() => stack.push((entry.path(), format!("{rel}/"))),
                    Ok(t) if t.is_file() => found.push(rel),
                    _ => {}
                }
            }
        }
        found.sort();
        found
    })
    .await
    .map_err(ApiError::internal)?;
    Ok(Json(json!({ "dataset": name, "files": files })))
}

/// `?path=<file under report/>`.
#[derive(Debug, Deserialize)]
pub(crate) struct ReportPath {
    path: String,
}

pub(crate) async fn report_file(
    State(shared): State<AppState>,
    Path(name): Path<String>,
    Query(q): Query<ReportPath>,
) -> Result<Response, ApiError> {
    let dir = report_dir(&shared, &name)?;
    let refused = || {
        ApiError::new(
            StatusCode::BAD_REQUEST,
            format!(
                "path `{}`: expected a file of the report folder, as listed by /datasets/{name}/report",
                super::public::excerpt(&q.path)
            ),
        )
    };
    let relative = std::path::Path::new(&q.path);
    if q.path.is_empty()
        || !relative
            .components()
            .all(|c| matches!(c, Component::Normal(_)))
    {
        return Err(refused());
    }
    let path = dir.join(relative);
    let read = tokio::task::spawn_blocking(move || {
        // Symbolic links may not lead out of the report folder either.
        let (real, base) = (path.canonicalize()?, dir.canonicalize()?);
        if !real.starts_with(&base) || !real.is_file() {
            return Ok(None);
        }
        std::fs::read(&real).map(Some)
    })
    .await
    .map_err(ApiError::internal)?;
    let kind = match relative.extension().and_then(|e| e.to_str()) {
        Some("png") => "image/png",
        Some("svg") => "image/svg+xml",
        Some("json") => "application/json",
        Some("md") => "text/markdown; charset=utf-8",
        _ => "text/plain; charset=utf-8",
    };
    match read {
        Ok(Some(bytes)) => Ok((
            [(header::CONTENT_TYPE, HeaderValue::from_static(kind))],
            bytes,
        )
            .into_response()),
        Ok(None) => Err(refused()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(ApiError::new(
            StatusCode::NOT_FOUND,
            format!(
                "no report file `{}` (build the dataset, or see /datasets/{name}/report)",
                super::public::excerpt(&q.path)
            ),
        )),
        Err(e) => Err(ApiError::internal(e)),
    }
}
