//! The dataset browser: `GET /` (a page built into the binary) and the read-only endpoints it
//! loads from: the clip listing with filters, one clip's metadata, one clip's motion, the report's
//! files. Every file answered is inside the dataset's own folder.

use std::collections::BTreeSet;
use std::path::{Component, PathBuf};
use std::sync::{Arc, LazyLock};

use axum::extract::{ConnectInfo, Path, Query, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use serde::{Deserialize, Serialize, Serializer};
use serde_json::{Value, json};
use sha2::{Digest, Sha256};

use super::Shared;
use super::api::ApiError;
use super::report;
use motionforge_format::dataset::{self, ClipFilter, ClipInfo, DatasetError};

/// The page: HTML, CSS and JavaScript in one file, compiled in.
const PAGE: &str = include_str!("browser.html");
/// Clips one listing returns unless `limit` says otherwise.
const DEFAULT_CLIPS: usize = 100;
/// Most clips one listing returns.
const MAX_CLIPS: usize = 1000;
/// Rows a page of the column view holds unless `limit` says otherwise.
const DEFAULT_ROWS: usize = 20;
/// Longest name of one file or folder (Linux's `NAME_MAX`, in bytes) a report path may hold.
const MAX_NAME_BYTES: usize = 255;
/// Longest report path (bytes).
const MAX_PATH_BYTES: usize = 1024;

type AppState = Arc<Shared>;

/// The connection a request came on, as the service's listener describes it (absent when the
/// router is called without one, as in unit tests).
type Connection = Option<Extension<ConnectInfo<super::wire::ConnectionWrites>>>;

fn writes(connection: Connection) -> Option<Arc<super::wire::Written>> {
    connection.map(|Extension(ConnectInfo(c))| c.0)
}

/// The text between the first `open` and the `close` after it in the page.
fn inline<'p>(page: &'p str, open: &str, close: &str) -> &'p str {
    page.split_once(open)
        .and_then(|(_, rest)| rest.split_once(close))
        .map_or("", |(inside, _)| inside)
}

/// `'sha256-<base64 of the digest>'`, a CSP source that allows exactly this inline text.
fn csp_hash(text: &str) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let digest = Sha256::digest(text.as_bytes());
    let mut b64 = String::new();
    for chunk in digest.chunks(3) {
        let n = chunk
            .iter()
            .enumerate()
            .fold(0u32, |n, (i, &b)| n | u32::from(b) << (16 - 8 * i));
        for i in 0..4 {
            if i <= chunk.len() {
                b64.push(char::from(ALPHABET[(n >> (18 - 6 * i) & 63) as usize]));
            } else {
                b64.push('=');
            }
        }
    }
    format!("'sha256-{b64}'")
}

/// The page's Content-Security-Policy: its one inline script and one style sheet (by hash), data
/// from this service only, nothing else; no framing.
static PAGE_POLICY: LazyLock<String> = LazyLock::new(|| {
    format!(
        "default-src 'none'; script-src {}; style-src {}; img-src 'self'; connect-src 'self'; \
         base-uri 'none'; form-action 'none'; frame-ancestors 'none'",
        csp_hash(inline(PAGE, "<script>", "</script>")),
        csp_hash(inline(PAGE, "<style>", "</style>")),
    )
});

pub(crate) async fn page() -> Response {
    let mut response = (
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("text/html; charset=utf-8"),
        )],
        PAGE,
    )
        .into_response();
    if let Ok(policy) = HeaderValue::from_str(&PAGE_POLICY) {
        response
            .headers_mut()
            .insert(header::CONTENT_SECURITY_POLICY, policy);
    }
    response
}

/// The page's icon: a stick figure in the player's part colours.
const FAVICON: &str = "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 32 32\">\
<rect width=\"32\" height=\"32\" rx=\"6\" fill=\"#263238\"/>\
<g stroke-width=\"3\" stroke-linecap=\"round\" fill=\"none\">\
<circle cx=\"16\" cy=\"7\" r=\"3\" stroke=\"#fff\"/>\
<path d=\"M16 11v9\" stroke=\"#fff\"/>\
<path d=\"M16 13l-7 4\" stroke=\"#1f5adc\"/><path d=\"M16 13l7-5\" stroke=\"#dc2828\"/>\
<path d=\"M16 20l-5 8\" stroke=\"#00a0aa\"/><path d=\"M16 20l5 8\" stroke=\"#f08c00\"/>\
</g></svg>";

pub(crate) async fn favicon() -> Response {
    (
        [
            (
                header::CONTENT_TYPE,
                HeaderValue::from_static("image/svg+xml"),
            ),
            (
                header::CACHE_CONTROL,
                HeaderValue::from_static("max-age=86400"),
            ),
            (
                header::CONTENT_SECURITY_POLICY,
                HeaderValue::from_static(REPORT_FILE_POLICY),
            ),
        ],
        FAVICON,
    )
        .into_response()
}

/// A JSON answer already serialised (as `Json` would have), holding its heavy-read turn while it
/// is sent.
fn json_answer(body: super::snapshot::HeldAnswer) -> Response {
    (
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/json"),
        )],
        axum::body::Body::new(body),
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

/// The dataset's current snapshot (read once per version of the dataset, shared).
async fn snapshot(shared: &Shared, name: &str) -> Result<Arc<super::snapshot::Snapshot>, ApiError> {
    let dir = folder(shared, name)?;
    shared
        .readers
        .snapshot(name, &dir)
        .await?
        .map_err(|e| dataset_error(shared, e))
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
    connection: Connection,
    Path(name): Path<String>,
    Query(q): Query<ClipQuery>,
) -> Result<Response, ApiError> {
    folder(&shared, &name)?;
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
    let snapshot = snapshot(&shared, &name).await?;
    let body = shared
        .readers
        .answer(writes(connection), move || {
            // The choices of each filter over the whole dataset, so a page can offer them.
            let [types, splits, kinds] = &snapshot.choices;
            let kept: Vec<&ClipInfo> = snapshot
                .clips
                .iter()
                .filter(|c| filter.matches(c))
                .collect();
            let page: Vec<&ClipInfo> = kept.iter().skip(offset).take(limit).copied().collect();
            serde_json::to_vec(&json!({
                "dataset": name,
                "total": kept.len(),
                "offset": offset,
                "limit": limit,
                "choices": { "type": types, "split": splits, "kind": kinds },
                "clips": page,
            }))
            .map_err(ApiError::internal)
        })
        .await?;
    Ok(json_answer(body))
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
    let snapshot = snapshot(&shared, &name).await?;
    let clips = &snapshot.clips;
    let Some(clip) = snapshot.clip(&q.id) else {
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
    let mirror = dataset::companion_ids(clip, dataset::Companions::Mirror, clips);
    let sources = dataset::companion_ids(clip, dataset::Companions::Sources, clips);
    let mut value = serde_json::to_value(clip).map_err(ApiError::internal)?;
    value["mirror"] = json!(mirror.first());
    value["sources"] = json!(sources);
    value.as_object_mut().map(|o| o.remove("shard"));
    Ok(Json(value))
}

pub(crate) async fn clip_motion(
    State(shared): State<AppState>,
    connection: Connection,
    Path(name): Path<String>,
    Query(q): Query<ClipId>,
) -> Result<Response, ApiError> {
    let dir = folder(&shared, &name)?;
    let snapshot = snapshot(&shared, &name).await?;
    let answer = shared.clone();
    let body = shared
        .readers
        .answer(writes(connection), move || {
            let frames = snapshot
                .frames(&dir, &q.id)
                .map_err(|e| dataset_error(&answer, e))?;
            let skeletons = snapshot.skeletons().map_err(ApiError::internal)?;
            motion_answer(&frames, skeletons)
        })
        .await?;
    Ok(json_answer(body))
}

/// `GET /datasets/{name}/motion`'s answer, serialised as it was when built as a JSON value: fields
/// by name, f32 numbers widened to f64 (non-finite ones null).
#[derive(Serialize)]
struct MotionAnswer<'a> {
    clip_id: &'a str,
    fps: f64,
    frame: &'static str,
    frames: usize,
    joints: usize,
    names: Vec<&'a str>,
    parents: Vec<Option<usize>>,
    parts: Vec<Option<motionforge_core::motion::BodyPart>>,
    #[serde(serialize_with = "widened")]
    positions: Vec<f32>,
    root: &'a str,
}

fn widened<S: Serializer>(values: &[f32], s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(
        values
            .iter()
            .map(|&v| v.is_finite().then_some(f64::from(v))),
    )
}

fn motion_answer(
    frames: &dataset::ClipFrames,
    skeletons: &dataset::Skeletons,
) -> Result<Vec<u8>, ApiError> {
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
    let answer = MotionAnswer {
        clip_id: &frames.info.clip_id,
        fps: frames.info.fps,
        frame: "canonical: the first frame's pelvis on the ground at the origin, facing +y; x right, z up, metres",
        frames: frames.info.frames,
        joints: frames.info.joints,
        names: skeleton.joints.iter().map(|j| j.name.as_str()).collect(),
        parents: skeleton.parents(),
        parts: skeleton.joints.iter().map(|j| j.part).collect(),
        positions: dataset::preview::canonical_positions(frames, skeleton),
        root: &skeleton.root,
    };
    serde_json::to_vec(&answer).map_err(ApiError::internal)
}

pub(crate) async fn column_stats(
    State(shared): State<AppState>,
    connection: Connection,
    Path(name): Path<String>,
) -> Result<Response, ApiError> {
    let snapshot = snapshot(&shared, &name).await?;
    let answer = shared.clone();
    let body = shared
        .readers
        .answer(writes(connection), move || {
            // Values may be paths of input files (`source_path`): shown as every answer shows
            // paths.
            snapshot
                .column_statistics()
                .map(|json| {
                    answer
                        .shield
                        .text(&String::from_utf8_lossy(json))
                        .into_owned()
                        .into_bytes()
                })
                .map_err(|e| ApiError::internal(answer.shield.text(e)))
        })
        .await?;
    Ok(json_answer(body))
}

/// The page of `GET /datasets/{name}/rows`.
#[derive(Debug, Deserialize)]
pub(crate) struct RowsQuery {
    offset: Option<usize>,
    limit: Option<usize>,
}

pub(crate) async fn table_rows(
    State(shared): State<AppState>,
    connection: Connection,
    Path(name): Path<String>,
    Query(q): Query<RowsQuery>,
) -> Result<Response, ApiError> {
    let limit = q.limit.unwrap_or(DEFAULT_ROWS);
    if limit == 0 || limit > super::columns::MAX_ROWS {
        return Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            format!("limit {limit}: expected 1 to {}", super::columns::MAX_ROWS),
        ));
    }
    let offset = q.offset.unwrap_or(0);
    let snapshot = snapshot(&shared, &name).await?;
    let answer = shared.clone();
    let body = shared
        .readers
        .answer(writes(connection), move || {
            let mut page = snapshot
                .rows(offset, limit)
                .map_err(|e| ApiError::internal(answer.shield.text(&e)))?;
            page["dataset"] = json!(name);
            page["offset"] = json!(offset);
            page["limit"] = json!(limit);
            let json = serde_json::to_string(&page).map_err(ApiError::internal)?;
            Ok(answer.shield.text(&json).into_owned().into_bytes())
        })
        .await?;
    Ok(json_answer(body))
}

/// The report's folder.
fn report_dir(shared: &Shared, name: &str) -> Result<PathBuf, ApiError> {
    Ok(folder(shared, name)?.join("report"))
}

/// `report.md` of the report folder `dir`, if there is one; at most
/// [`report::MAX_REPORT_BYTES`].
fn read_report_md(dir: &std::path::Path) -> Result<Option<String>, String> {
    use std::io::Read;
    let path = dir.join(report::REPORT_MD);
    let file = match std::fs::File::open(&path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("{}: {e}", path.display())),
    };
    let mut bytes = Vec::new();
    file.take(report::MAX_REPORT_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    if bytes.len() as u64 > report::MAX_REPORT_BYTES {
        return Err(format!(
            "{}: over {} bytes, expected a report",
            path.display(),
            report::MAX_REPORT_BYTES
        ));
    }
    Ok(Some(String::from_utf8_lossy(&bytes).into_owned()))
}

/// The report files a browser may fetch (sorted, relative to the report folder `dir`): the
/// folder's own top-level files and the files `report.md` links to or embeds that are there.
fn report_listing(dir: &std::path::Path) -> Result<Vec<String>, String> {
    let mut found = BTreeSet::new();
    if let Ok(entries) = std::fs::read_dir(dir) {
        for entry in entries.flatten() {
            let file = entry.file_name().to_string_lossy().into_owned();
            if !file.starts_with('.') && entry.file_type().is_ok_and(|t| t.is_file()) {
                found.insert(file);
            }
        }
    }
    if let Some(markdown) = read_report_md(dir)? {
        found.extend(
            report::referenced(&markdown)
                .into_iter()
                .filter(|f| dir.join(f).is_file()),
        );
    }
    Ok(found.into_iter().collect())
}

pub(crate) async fn report_files(
    State(shared): State<AppState>,
    Path(name): Path<String>,
) -> Result<Json<Value>, ApiError> {
    let dir = report_dir(&shared, &name)?;
    let files = shared
        .readers
        .heavy(move || report_listing(&dir))
        .await?
        .map_err(|e| ApiError::internal(shared.shield.text(&e)))?;
    Ok(Json(json!({ "dataset": name, "files": files })))
}

/// The service's address of a report file.
fn report_file_url(name: &str, file: &str) -> String {
    format!(
        "/datasets/{}/report/file?path={}",
        query_escape(name),
        query_escape(file)
    )
}

/// `text` as a URL path segment or query value: unreserved characters and `/` as they are.
fn query_escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for b in text.bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.' | b'~' | b'/') {
            out.push(char::from(b));
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

pub(crate) async fn report_html(
    State(shared): State<AppState>,
    Path(name): Path<String>,
) -> Result<Json<Value>, ApiError> {
    let dir = report_dir(&shared, &name)?;
    let for_urls = name.clone();
    let rendered = shared
        .readers
        .heavy(move || {
            read_report_md(&dir).map(|md| {
                md.map(|md| report::render(&md, &|file| report_file_url(&for_urls, file)))
            })
        })
        .await?
        .map_err(|e| ApiError::internal(shared.shield.text(&e)))?;
    match rendered {
        Some(html) => Ok(Json(json!({ "dataset": name, "html": html }))),
        None => Err(ApiError::new(
            StatusCode::NOT_FOUND,
            format!("dataset `{name}` has no report yet: build it first"),
        )),
    }
}

/// `?path=<file under report/>`.
#[derive(Debug, Deserialize)]
pub(crate) struct ReportPath {
    path: String,
}

/// What a report file may do when opened on its own (an SVG may hold a script): nothing.
const REPORT_FILE_POLICY: &str = "sandbox; default-src 'none'; style-src 'unsafe-inline'";

pub(crate) async fn report_file(
    State(shared): State<AppState>,
    connection: Connection,
    Path(name): Path<String>,
    Query(q): Query<ReportPath>,
) -> Result<Response, ApiError> {
    let dir = report_dir(&shared, &name)?;
    let listing = format!("/datasets/{name}/report");
    let refused = move |path: &str| {
        ApiError::new(
            StatusCode::BAD_REQUEST,
            format!(
                "path `{}`: expected a file of the report, as listed by {listing}",
                super::public::excerpt(path)
            ),
        )
    };
    let relative = std::path::Path::new(&q.path);
    // No file has a NUL or an over-long name: refused here, not failed on by the filesystem.
    if q.path.is_empty()
        || q.path.len() > MAX_PATH_BYTES
        || q.path.contains('\0')
        || !relative
            .components()
            .all(|c| matches!(c, Component::Normal(n) if n.len() <= MAX_NAME_BYTES))
    {
        return Err(refused(&q.path));
    }
    let kind = match relative.extension().and_then(|e| e.to_str()) {
        Some("png") => "image/png",
        Some("svg") => "image/svg+xml",
        Some("json") => "application/json",
        Some("pdf") => "application/pdf",
        Some("md") => "text/markdown; charset=utf-8",
        _ => "text/plain; charset=utf-8",
    };
    let path = dir.join(relative);
    let body = shared
        .readers
        .answer(writes(connection), move || {
            // Symbolic links may not lead out of the report folder either.
            // Only the files the report lists: those of the folder's top level and those
            // `report.md` names.
            let listed = report_listing(&dir).map_err(ApiError::internal)?;
            if !listed.iter().any(|f| f == &q.path) {
                return Err(if path.exists() {
                    refused(&q.path)
                } else {
                    ApiError::new(
                        StatusCode::NOT_FOUND,
                        format!(
                            "no report file `{}` (build the dataset, or see /datasets/{name}/report)",
                            super::public::excerpt(&q.path)
                        ),
                    )
                });
            }
            let read = path.canonicalize().and_then(|real| {
                let base = dir.canonicalize()?;
                if !real.starts_with(&base) || !real.is_file() {
                    return Ok(None);
                }
                std::fs::read(&real).map(Some)
            });
            match read {
                Ok(Some(bytes)) => Ok(bytes),
                Ok(None) => Err(refused(&q.path)),
                // `a.md/b`: a file taken for a folder is a path to nothing, too.
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory
                    ) =>
                {
                    Err(ApiError::new(
                        StatusCode::NOT_FOUND,
                        format!(
                            "no report file `{}` (build the dataset, or see /datasets/{name}/report)",
                            super::public::excerpt(&q.path)
                        ),
                    ))
                }
                Err(e) => Err(ApiError::internal(e)),
            }
        })
        .await?;
    Ok((
        [
            (header::CONTENT_TYPE, HeaderValue::from_static(kind)),
            (
                header::CONTENT_SECURITY_POLICY,
                HeaderValue::from_static(REPORT_FILE_POLICY),
            ),
        ],
        axum::body::Body::new(body),
    )
        .into_response())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_policy_allows_the_pages_one_script_and_one_style_sheet_by_hash() {
        // The sha256 of nothing, as CSP writes it.
        assert_eq!(
            csp_hash(""),
            "'sha256-47DEQpj8HBSa+/TImW+5JCeuQeRkm5NMpJWZG3hSuFU='"
        );
        assert_eq!(
            csp_hash("abc"),
            "'sha256-ungWv48Bz+pBQUDeXa4iI7ADYaOWF3qctBD/YfIAFa0='"
        );
        // Whatever else the page holds inline would be blocked: no second script or style
        // sheet, no style attribute, no handler attribute.
        assert_eq!(PAGE.matches("<script").count(), 1);
        assert_eq!(PAGE.matches("<style").count(), 1);
        assert!(!PAGE.contains(" style=\""));
        assert!(
            !regex::Regex::new(r#"<[^>]* on[a-z]+=""#)
                .unwrap()
                .is_match(PAGE)
        );
        let script = inline(PAGE, "<script>", "</script>");
        assert!(script.contains("loadDatasets()"));
        assert!(PAGE_POLICY.contains(&format!("script-src {};", csp_hash(script))));
        assert!(PAGE_POLICY.contains(&format!(
            "style-src {};",
            csp_hash(inline(PAGE, "<style>", "</style>"))
        )));
    }
}
