//! The HTTP routes. Every answer is JSON, errors as `{"error": "..."}` (those of axum's
//! extractors and hyper's own included); calls other than GET need `Authorization: Bearer
//! <token>`. Since reading needs no token, answers show no absolute path and echo at most an
//! excerpt of what the client sent.

use std::collections::BTreeMap;
use std::sync::Arc;

use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, Path, Query, Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{MethodFilter, MethodRouter, on};
use axum::{Json, Router};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::history::{BuildId, BuildRecord, BuildState, ListFilter, Trigger};
use super::log::StageProgress;
use super::public::{excerpt, excerpt_of};
use super::{Shared, rfc3339, say, schedule};
use motionforge_runner::BuildReport;

/// Builds listed by `GET /builds` unless `limit` says otherwise.
const DEFAULT_LIMIT: usize = 50;
/// Most builds one listing returns.
const MAX_LIMIT: usize = 1000;
/// Largest request body read. `POST /builds` needs a few hundred bytes; this is generous.
pub const BODY_LIMIT: usize = 256 * 1024;
/// Longest message of a library error (which may quote the client's input) in an answer.
const MAX_QUOTED_ERROR: usize = 300;

type AppState = Arc<Shared>;

#[derive(Debug, Clone, Copy)]
enum Verb {
    Get,
    Post,
}

impl Verb {
    fn name(self) -> &'static str {
        match self {
            Verb::Get => "GET",
            Verb::Post => "POST",
        }
    }

    fn filter(self) -> MethodFilter {
        match self {
            Verb::Get => MethodFilter::GET,
            Verb::Post => MethodFilter::POST,
        }
    }
}

struct Route {
    verb: Verb,
    path: &'static str,
    handler: MethodRouter<AppState>,
}

fn route<H, T>(verb: Verb, path: &'static str, handler: H) -> Route
where
    H: axum::handler::Handler<T, AppState>,
    T: 'static,
{
    Route {
        verb,
        path,
        handler: on(verb.filter(), handler),
    }
}

/// A GET route: most of the table.
fn get<H, T>(path: &'static str, handler: H) -> Route
where
    H: axum::handler::Handler<T, AppState>,
    T: 'static,
{
    route(Verb::Get, path, handler)
}

/// The one list the router is made from, so [`routes`] is exactly what it serves.
fn table() -> Vec<Route> {
    vec![
        get("/health", health),
        route(Verb::Post, "/builds", create_build),
        get("/builds", list_builds),
        get("/builds/{id}", get_build),
        get("/datasets", list_datasets),
        get("/datasets/{name}/stats", dataset_stats),
        get("/", super::browse::page),
        get("/favicon.svg", super::browse::favicon),
        get("/datasets/{name}/clips", super::browse::list_clips),
        get("/datasets/{name}/clip", super::browse::clip_meta),
        get("/datasets/{name}/motion", super::browse::clip_motion),
        get("/datasets/{name}/columns", super::browse::column_stats),
        get("/datasets/{name}/rows", super::browse::table_rows),
        get("/datasets/{name}/report", super::browse::report_files),
        get("/datasets/{name}/report/html", super::browse::report_html),
        get("/datasets/{name}/report/file", super::browse::report_file),
    ]
}

/// Every `(method, path)` the router serves, paths in OpenAPI form.
pub fn routes() -> Vec<(&'static str, &'static str)> {
    table().iter().map(|r| (r.verb.name(), r.path)).collect()
}

pub(crate) fn router(shared: AppState) -> Router {
    let mut by_path: BTreeMap<&'static str, MethodRouter<AppState>> = BTreeMap::new();
    for r in table() {
        let merged = match by_path.remove(r.path) {
            Some(existing) => existing.merge(r.handler),
            None => r.handler,
        };
        by_path.insert(r.path, merged);
    }
    let mut router = Router::new();
    for (path, handler) in by_path {
        router = router.route(path, handler);
    }
    router
        // route_layer: unknown paths answer 404, not 401.
        .route_layer(middleware::from_fn_with_state(
            shared.clone(),
            require_token,
        ))
        .fallback(no_route)
        .method_not_allowed_fallback(method_not_allowed)
        // Bodies without a length (chunked) are cut at the limit while read.
        .layer(DefaultBodyLimit::max(BODY_LIMIT))
        .layer(middleware::from_fn(refuse_long_bodies))
        // Outside the routes, so it sees every answer: extractor rejections and the body limit too.
        .layer(middleware::from_fn(json_errors))
        .layer(middleware::from_fn(no_sniffing))
        .with_state(shared)
}

/// Marks every answer `X-Content-Type-Options: nosniff`: a browser takes each for the type it
/// says (a report file served as text stays text), never for what its bytes look like.
async fn no_sniffing(request: Request, next: Next) -> Response {
    let mut response = next.run(request).await;
    response.headers_mut().insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    response
}

/// Refuses a body whose declared length is over [`BODY_LIMIT`] before reading any of it.
async fn refuse_long_bodies(request: Request, next: Next) -> Response {
    let declared = request
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().parse::<u64>().ok());
    if declared.is_some_and(|n| n > BODY_LIMIT as u64) {
        return ApiError::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("request body too large: at most {BODY_LIMIT} bytes"),
        )
        .into_response();
    }
    next.run(request).await
}

/// Rewrites an error answer that is not JSON (axum's rejections answer plain text) into the
/// `{"error": "..."}` form every other error has.
async fn json_errors(request: Request, next: Next) -> Response {
    let response = next.run(request).await;
    let status = response.status();
    let is_json = response
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"application/json"));
    if !(status.is_client_error() || status.is_server_error()) || is_json {
        return response;
    }
    let body = axum::body::to_bytes(response.into_body(), 16 * 1024)
        .await
        .unwrap_or_default();
    let text = String::from_utf8_lossy(&body);
    let message = if status == StatusCode::PAYLOAD_TOO_LARGE {
        format!("request body too large: at most {BODY_LIMIT} bytes")
    } else if text.trim().is_empty() {
        status
            .canonical_reason()
            .unwrap_or("request refused")
            .to_string()
    } else {
        excerpt_of(text.trim(), MAX_QUOTED_ERROR).into_owned()
    };
    ApiError::new(status, message).into_response()
}

/// An error answer.
#[derive(Debug)]
pub(crate) struct ApiError {
    status: StatusCode,
    message: String,
}

impl ApiError {
    pub(crate) fn new(status: StatusCode, message: impl Into<String>) -> ApiError {
        ApiError {
            status,
            message: message.into(),
        }
    }

    /// A failure of the service itself: the details (paths, SQLite errors) go to its log, not
    /// to a caller who may not hold the token.
    pub(crate) fn internal(err: impl std::fmt::Display) -> ApiError {
        say(&format!("internal error answering a request: {err}"));
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal error; the service's log has the details",
        )
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut response = (self.status, Json(json!({ "error": self.message }))).into_response();
        if self.status == StatusCode::UNAUTHORIZED {
            response.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Bearer realm=\"motionforge\""),
            );
        }
        response
    }
}

async fn require_token(State(shared): State<AppState>, request: Request, next: Next) -> Response {
    if matches!(
        *request.method(),
        Method::GET | Method::HEAD | Method::OPTIONS
    ) {
        return next.run(request).await;
    }
    match bearer(request.headers()) {
        None => ApiError::new(
            StatusCode::UNAUTHORIZED,
            "missing bearer token: send `Authorization: Bearer <token>` with calls that change state",
        )
        .into_response(),
        Some(token) if shared.token.accepts(token) => next.run(request).await,
        Some(_) => ApiError::new(StatusCode::UNAUTHORIZED, "wrong bearer token").into_response(),
    }
}

/// The token of an `Authorization: Bearer <token>` header.
fn bearer(headers: &HeaderMap) -> Option<&str> {
    let value = headers.get(header::AUTHORIZATION)?.to_str().ok()?;
    let (scheme, token) = value.trim().split_once(' ')?;
    scheme
        .eq_ignore_ascii_case("bearer")
        .then_some(token.trim())
        .filter(|t| !t.is_empty())
}

async fn no_route(method: Method, uri: axum::http::Uri) -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        format!(
            "no route {method} {}; the routes are in docs/openapi.json",
            excerpt(uri.path())
        ),
    )
}

async fn method_not_allowed(method: Method, uri: axum::http::Uri) -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        format!("{} does not accept {method}", excerpt(uri.path())),
    )
}

async fn health(State(shared): State<AppState>) -> Json<Value> {
    Json(json!({
        "status": "ok",
        "version": env!("CARGO_PKG_VERSION"),
        "time": rfc3339(shared.now_ms()),
        "datasets": shared.datasets.keys().collect::<Vec<_>>(),
    }))
}

/// The body of `POST /builds`; every field is optional.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct BuildRequest {
    /// Which dataset; may be left out when the service serves one.
    dataset: Option<String>,
    /// Recompute everything.
    #[serde(default)]
    force: bool,
    /// Send no LLM request.
    #[serde(default)]
    offline: bool,
}

async fn create_build(
    State(shared): State<AppState>,
    body: Bytes,
) -> Result<(StatusCode, HeaderMap, Json<BuildView>), ApiError> {
    let request: BuildRequest = if body.iter().all(u8::is_ascii_whitespace) {
        BuildRequest::default()
    } else {
        serde_json::from_slice(&body).map_err(|e| {
            ApiError::new(
                StatusCode::BAD_REQUEST,
                format!(
                    "body: {}; expected {{\"dataset\": \"<name>\", \"force\": false, \"offline\": false}}",
                    excerpt_of(&e.to_string(), MAX_QUOTED_ERROR)
                ),
            )
        })?
    };
    let dataset = match request.dataset {
        Some(name) => {
            if !shared.datasets.contains_key(&name) {
                return Err(unknown_dataset(&shared, &name));
            }
            name
        }
        None => match shared.datasets.keys().collect::<Vec<_>>()[..] {
            [only] => only.clone(),
            _ => {
                return Err(ApiError::new(
                    StatusCode::BAD_REQUEST,
                    format!(
                        "`dataset` is required: this service serves {}",
                        shared.served_names()
                    ),
                ));
            }
        },
    };
    let id = shared
        .request_build(&dataset, Trigger::Api, request.force, request.offline)
        .map_err(ApiError::internal)?;
    let record = shared
        .history
        .get(id)
        .map_err(ApiError::internal)?
        .ok_or_else(|| ApiError::internal(format!("build {id} vanished")))?;
    let mut headers = HeaderMap::new();
    if let Ok(location) = HeaderValue::from_str(&format!("/builds/{id}")) {
        headers.insert(header::LOCATION, location);
    }
    Ok((
        StatusCode::ACCEPTED,
        headers,
        Json(view(&shared, record, true)),
    ))
}

pub(crate) fn unknown_dataset(shared: &Shared, name: &str) -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        format!(
            "no dataset `{}`; this service serves {}",
            excerpt(name),
            shared.served_names()
        ),
    )
}

async fn list_builds(
    State(shared): State<AppState>,
    Query(query): Query<BTreeMap<String, String>>,
) -> Result<Json<Value>, ApiError> {
    let mut filter = ListFilter {
        dataset: None,
        state: None,
        limit: DEFAULT_LIMIT,
    };
    for (key, value) in query {
        match key.as_str() {
            "dataset" => filter.dataset = Some(value),
            "state" => {
                filter.state = Some(BuildState::parse(&value).ok_or_else(|| {
                    ApiError::new(
                        StatusCode::BAD_REQUEST,
                        format!(
                            "state `{}`: expected queued, running, succeeded, failed or interrupted",
                            excerpt(&value)
                        ),
                    )
                })?);
            }
            "limit" => {
                filter.limit = value
                    .parse::<usize>()
                    .ok()
                    .filter(|n| (1..=MAX_LIMIT).contains(n))
                    .ok_or_else(|| {
                        ApiError::new(
                            StatusCode::BAD_REQUEST,
                            format!(
                                "limit `{}`: expected a whole number from 1 to {MAX_LIMIT}",
                                excerpt(&value)
                            ),
                        )
                    })?;
            }
            other => {
                return Err(ApiError::new(
                    StatusCode::BAD_REQUEST,
                    format!(
                        "unknown query parameter `{}`: expected dataset, state or limit",
                        excerpt(other)
                    ),
                ));
            }
        }
    }
    let builds: Vec<BuildView> = shared
        .history
        .list(&filter)
        .map_err(ApiError::internal)?
        .into_iter()
        .map(|r| view(&shared, r, false))
        .collect();
    Ok(Json(json!({ "builds": builds })))
}

async fn get_build(
    State(shared): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<BuildView>, ApiError> {
    let missing = || {
        ApiError::new(
            StatusCode::NOT_FOUND,
            format!("no build `{}`", excerpt(&id)),
        )
    };
    let number: BuildId = id.parse().map_err(|_| missing())?;
    let record = shared
        .history
        .get(number)
        .map_err(ApiError::internal)?
        .ok_or_else(missing)?;
    Ok(Json(view(&shared, record, true)))
}

/// Counts of a successful build.
#[derive(Debug, Serialize)]
struct Counts {
    captures: usize,
    clips: usize,
    mirrored: usize,
    rejects: usize,
    kinds: BTreeMap<String, usize>,
    nothing_ran: bool,
}

/// A build as the API shows it.
#[derive(Debug, Serialize)]
struct BuildView {
    id: BuildId,
    url: String,
    dataset: String,
    trigger: Trigger,
    force: bool,
    offline: bool,
    state: BuildState,
    requested_at: Option<String>,
    started_at: Option<String>,
    finished_at: Option<String>,
    seconds: Option<f64>,
    resumes: Option<BuildId>,
    resumed_by: Option<BuildId>,
    stages: Vec<StageProgress>,
    counts: Option<Counts>,
    error: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    log: Option<Vec<String>>,
}

fn view(shared: &Shared, record: BuildRecord, with_log: bool) -> BuildView {
    let live = (record.state == BuildState::Running)
        .then(|| shared.live(record.id))
        .flatten();
    let (stages, log) = match &live {
        Some(l) => (l.stages(), l.lines()),
        None => (
            record
                .stages
                .as_deref()
                .and_then(|s| serde_json::from_str(s).ok())
                .unwrap_or_default(),
            record.log,
        ),
    };
    // Build errors and logs name input files; callers need no token, so no absolute path.
    let log: Vec<String> = log
        .iter()
        .map(|l| shared.shield.text(l).into_owned())
        .collect();
    let error = record
        .error
        .as_deref()
        .map(|e| shared.shield.text(e).into_owned());
    let counts = record
        .report
        .as_deref()
        .and_then(|r| serde_json::from_str::<BuildReport>(r).ok())
        .map(|r| Counts {
            captures: r.captures,
            clips: r.clips,
            mirrored: r.mirrored,
            rejects: r.rejects.len(),
            nothing_ran: r.nothing_ran(),
            kinds: r.kinds.to_names(),
        });
    BuildView {
        id: record.id,
        url: format!("/builds/{}", record.id),
        dataset: record.dataset,
        trigger: record.trigger,
        force: record.force,
        offline: record.offline,
        state: record.state,
        requested_at: rfc3339(record.requested_at),
        started_at: record.started_at.and_then(rfc3339),
        finished_at: record.finished_at.and_then(rfc3339),
        seconds: record.duration_ms.map(|ms| ms as f64 / 1000.0),
        resumes: record.resumes,
        resumed_by: record.resumed_by,
        stages,
        counts,
        error,
        log: with_log.then_some(log),
    }
}

async fn list_datasets(State(shared): State<AppState>) -> Result<Json<Value>, ApiError> {
    let now = shared.clock.now();
    let mut out = Vec::new();
    for (name, dataset) in &shared.datasets {
        let of = |state: Option<BuildState>, limit: usize| {
            shared
                .history
                .list(&ListFilter {
                    dataset: Some(name.clone()),
                    state,
                    limit,
                })
                .map_err(ApiError::internal)
        };
        let running = of(Some(BuildState::Running), 1)?.first().map(|r| r.id);
        let mut queued: Vec<BuildId> = of(Some(BuildState::Queued), MAX_LIMIT)?
            .iter()
            .map(|r| r.id)
            .collect();
        queued.sort_unstable();
        let recent = of(None, DEFAULT_LIMIT)?;
        let last = recent.iter().find(|r| r.state.is_final()).map(|r| {
            json!({
                "id": r.id,
                "state": r.state,
                "finished_at": r.finished_at.and_then(rfc3339),
            })
        });
        let folder = dataset.config.dataset_dir();
        out.push(json!({
            "name": name,
            "output": shared.shield.path(&folder),
            "schedule": dataset.schedule.as_ref().map(|(text, _)| text),
            "next_scheduled": dataset
                .schedule
                .as_ref()
                .and_then(|(_, cron)| schedule::next_after(cron, now))
                .map(|t| t.to_rfc3339_opts(chrono::SecondsFormat::Secs, true)),
            "stats_available": folder.join(STATS_FILE).is_file(),
            "stats_url": format!("/datasets/{name}/stats"),
            "running": running,
            "queued": queued,
            "last_build": last,
        }));
    }
    Ok(Json(json!({ "datasets": out })))
}

/// The statistics file of a built dataset, inside its folder.
const STATS_FILE: &str = "report/stats.json";

async fn dataset_stats(
    State(shared): State<AppState>,
    Path(name): Path<String>,
) -> Result<Response, ApiError> {
    let dataset = shared
        .datasets
        .get(&name)
        .ok_or_else(|| unknown_dataset(&shared, &name))?;
    let path = dataset.config.dataset_dir().join(STATS_FILE);
    let read = tokio::task::spawn_blocking({
        let path = path.clone();
        move || std::fs::read(&path)
    })
    .await
    .map_err(ApiError::internal)?;
    match read {
        Ok(bytes) => Ok((
            [(
                header::CONTENT_TYPE,
                HeaderValue::from_static("application/json"),
            )],
            bytes,
        )
            .into_response()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(ApiError::new(
            StatusCode::NOT_FOUND,
            format!(
                "dataset `{name}` has no statistics yet ({} is missing): build it first",
                shared.shield.path(&path)
            ),
        )),
        Err(e) => Err(ApiError::internal(format!("{}: {e}", path.display()))),
    }
}
