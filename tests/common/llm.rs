//! The one fake OpenAI-compatible LLM server of the tests: `GET /v1/models`, `POST
//! /v1/chat/completions` and `/v1/completions` on a free loopback port, answering from a script,
//! by prompt substring, or by a closure, and logging every request. Failure modes: an HTTP status
//! (with `Retry-After`), a delay, a hang, a malformed or cut-off answer, a closed port
//! ([`dead_url`]).

use std::collections::VecDeque;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::extract::State;
use axum::http::{HeaderMap, StatusCode, Uri, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde_json::{Value, json};

/// What the server does with one completion request.
#[derive(Clone, Debug)]
pub(crate) enum Reply {
    /// 200 with `echo: <prompt>`.
    Echo,
    /// 200 with this text and finish reason.
    Answer(String, &'static str),
    /// An error status with a body and optional `Retry-After`.
    Status(u16, &'static str, Option<&'static str>),
    /// Sleep this long, then echo.
    Hang(Duration),
    /// 200 with this body as JSON content type (malformed answers).
    Raw(&'static str),
}

impl Reply {
    /// 200 with this text, finished (`finish_reason: "stop"`).
    pub(crate) fn text(text: impl Into<String>) -> Reply {
        Reply::Answer(text.into(), "stop")
    }

    /// 200 with this text, cut off at `max_tokens` (`finish_reason: "length"`).
    pub(crate) fn cut(text: impl Into<String>) -> Reply {
        Reply::Answer(text.into(), "length")
    }
}

/// One completion request as the server received it.
#[derive(Debug, Clone)]
pub(crate) struct Request {
    pub path: String,
    pub auth: Option<String>,
    pub body: Value,
    pub at: Instant,
}

impl Request {
    /// The chat message or completion prompt.
    pub(crate) fn prompt(&self) -> &str {
        self.body
            .pointer("/messages/0/content")
            .or_else(|| self.body.get("prompt"))
            .and_then(Value::as_str)
            .unwrap_or_default()
    }

    /// `max_tokens`, 0 when not sent.
    pub(crate) fn max_tokens(&self) -> u64 {
        self.body["max_tokens"].as_u64().unwrap_or(0)
    }
}

type Answerer = Box<dyn Fn(&Request) -> Reply + Send + Sync>;

/// How a server to start answers; [`LlmServer::builder`] starts one.
#[must_use]
pub(crate) struct LlmServerBuilder {
    script: Vec<Reply>,
    rules: Vec<(String, Reply)>,
    answer: Option<Answerer>,
    default: Reply,
    delay: Duration,
    api_key: Option<String>,
    models: Option<Vec<String>>,
}

impl LlmServerBuilder {
    /// The first requests' replies, in order (before any rule).
    pub(crate) fn script(mut self, replies: Vec<Reply>) -> Self {
        self.script = replies;
        self
    }

    /// A prompt containing `substring` gets `reply` (the first matching rule wins).
    pub(crate) fn when(mut self, substring: &str, reply: Reply) -> Self {
        self.rules.push((substring.to_string(), reply));
        self
    }

    /// Every request past the script and rules is answered by this closure.
    pub(crate) fn answer(mut self, f: impl Fn(&Request) -> Reply + Send + Sync + 'static) -> Self {
        self.answer = Some(Box::new(f));
        self
    }

    /// Every request past the script and rules gets this reply (default: [`Reply::Echo`]).
    pub(crate) fn default(mut self, reply: Reply) -> Self {
        self.default = reply;
        self
    }

    /// Every completion request waits this long before its reply (to make concurrency
    /// observable).
    pub(crate) fn delay(mut self, delay: Duration) -> Self {
        self.delay = delay;
        self
    }

    /// Requests without `Authorization: Bearer <key>` get a 401.
    pub(crate) fn api_key(mut self, key: &str) -> Self {
        self.api_key = Some(format!("Bearer {key}"));
        self
    }

    /// `GET /v1/models` lists these models (default: `test-model`).
    pub(crate) fn models(mut self, models: &[&str]) -> Self {
        self.models = Some(models.iter().map(|m| m.to_string()).collect());
        self
    }

    /// No `GET /v1/models`: it answers 404, as servers without a model list do.
    pub(crate) fn without_models(mut self) -> Self {
        self.models = None;
        self
    }

    /// Starts it on a free loopback port, on a runtime of its own.
    pub(crate) fn start(self) -> LlmServer {
        let state = Arc::new(ServerState {
            script: Mutex::new(self.script.into()),
            rules: self.rules,
            answer: self.answer,
            default: self.default,
            delay: self.delay,
            expected_auth: self.api_key,
            models: self.models.clone(),
            requests: AtomicUsize::new(0),
            listings: AtomicUsize::new(0),
            in_flight: AtomicUsize::new(0),
            max_in_flight: AtomicUsize::new(0),
            seen: Mutex::new(Vec::new()),
        });
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        let listener = runtime
            .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
            .unwrap();
        let addr = listener.local_addr().unwrap();
        let mut app = Router::new()
            .route("/v1/chat/completions", post(complete))
            .route("/v1/completions", post(complete));
        if self.models.is_some() {
            app = app.route("/v1/models", get(models));
        }
        let app = app.with_state(Arc::clone(&state));
        runtime.spawn(async move { axum::serve(listener, app).await });
        LlmServer {
            state,
            address: addr.to_string(),
            _runtime: runtime,
        }
    }
}

/// A running fake LLM server; stops (its port closes) when dropped.
pub(crate) struct LlmServer {
    state: Arc<ServerState>,
    address: String,
    _runtime: tokio::runtime::Runtime,
}

impl LlmServer {
    /// A server to configure, echoing every prompt unless told otherwise.
    pub(crate) fn builder() -> LlmServerBuilder {
        LlmServerBuilder {
            script: Vec::new(),
            rules: Vec::new(),
            answer: None,
            default: Reply::Echo,
            delay: Duration::ZERO,
            api_key: None,
            models: Some(vec!["test-model".into()]),
        }
    }

    /// A server that echoes every prompt.
    pub(crate) fn echo() -> LlmServer {
        LlmServer::builder().start()
    }

    /// A server answering every request with `f`.
    pub(crate) fn answering(f: impl Fn(&Request) -> Reply + Send + Sync + 'static) -> LlmServer {
        LlmServer::builder().answer(f).start()
    }

    /// `http://127.0.0.1:<port>/v1`, the config's `llm.base_url`.
    pub(crate) fn base_url(&self) -> String {
        format!("http://{}/v1", self.address)
    }

    /// `127.0.0.1:<port>`.
    pub(crate) fn address(&self) -> &str {
        &self.address
    }

    /// How many completion requests it received (model-list requests do not count).
    pub(crate) fn requests(&self) -> usize {
        self.state.requests.load(Ordering::SeqCst)
    }

    /// Model listings answered (`GET /v1/models`: a client probes once before its first request).
    pub(crate) fn listings(&self) -> usize {
        self.state.listings.load(Ordering::SeqCst)
    }

    /// Every completion request received, in order.
    pub(crate) fn seen(&self) -> Vec<Request> {
        self.state.seen.lock().unwrap().clone()
    }

    /// Every prompt received, in order.
    pub(crate) fn prompts(&self) -> Vec<String> {
        self.seen().iter().map(|r| r.prompt().to_string()).collect()
    }

    /// The most requests it answered at once.
    pub(crate) fn max_in_flight(&self) -> usize {
        self.state.max_in_flight.load(Ordering::SeqCst)
    }
}

/// A port that was free a moment ago, as `127.0.0.1:<port>`: nothing listens on it.
pub(crate) fn dead_address() -> String {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.local_addr().unwrap().to_string()
}

/// `http://<dead_address>/v1`: a base URL nothing answers at.
pub(crate) fn dead_url() -> String {
    format!("http://{}/v1", dead_address())
}

struct ServerState {
    script: Mutex<VecDeque<Reply>>,
    rules: Vec<(String, Reply)>,
    answer: Option<Answerer>,
    default: Reply,
    delay: Duration,
    expected_auth: Option<String>,
    models: Option<Vec<String>>,
    requests: AtomicUsize,
    /// `GET /v1/models` answered (the client's probes).
    listings: AtomicUsize,
    in_flight: AtomicUsize,
    max_in_flight: AtomicUsize,
    seen: Mutex<Vec<Request>>,
}

impl ServerState {
    fn reply_to(&self, request: &Request) -> Reply {
        if let Some(reply) = self.script.lock().unwrap().pop_front() {
            return reply;
        }
        let prompt = request.prompt();
        if let Some((_, reply)) = self.rules.iter().find(|(s, _)| prompt.contains(s.as_str())) {
            return reply.clone();
        }
        match &self.answer {
            Some(f) => f(request),
            None => self.default.clone(),
        }
    }
}

struct InFlight(Arc<ServerState>);

impl Drop for InFlight {
    fn drop(&mut self) {
        self.0.in_flight.fetch_sub(1, Ordering::SeqCst);
    }
}

async fn models(State(s): State<Arc<ServerState>>) -> Response {
    s.listings.fetch_add(1, Ordering::SeqCst);
    let data: Vec<Value> = (s.models.iter().flatten())
        .map(|id| json!({"id": id, "object": "model"}))
        .collect();
    Json(json!({"object": "list", "data": data})).into_response()
}

async fn complete(
    State(s): State<Arc<ServerState>>,
    uri: Uri,
    headers: HeaderMap,
    Json(body): Json<Value>,
) -> Response {
    s.requests.fetch_add(1, Ordering::SeqCst);
    let now = s.in_flight.fetch_add(1, Ordering::SeqCst) + 1;
    s.max_in_flight.fetch_max(now, Ordering::SeqCst);
    let _guard = InFlight(Arc::clone(&s));
    let request = Request {
        path: uri.path().to_string(),
        auth: headers
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .map(str::to_string),
        body,
        at: Instant::now(),
    };
    s.seen.lock().unwrap().push(request.clone());
    if let Some(expected) = &s.expected_auth
        && request.auth.as_deref() != Some(expected.as_str())
    {
        return (StatusCode::UNAUTHORIZED, "bad or missing API key").into_response();
    }
    if !s.delay.is_zero() {
        tokio::time::sleep(s.delay).await;
    }
    let chat = request.path.ends_with("/chat/completions");
    let echo = format!("echo: {}", request.prompt());
    match s.reply_to(&request) {
        Reply::Echo => answer(chat, &echo, "stop"),
        Reply::Answer(text, finish_reason) => answer(chat, &text, finish_reason),
        Reply::Status(code, text, retry_after) => {
            let mut r = (StatusCode::from_u16(code).unwrap(), text).into_response();
            if let Some(v) = retry_after {
                r.headers_mut()
                    .insert(header::RETRY_AFTER, v.parse().unwrap());
            }
            r
        }
        Reply::Hang(d) => {
            tokio::time::sleep(d).await;
            answer(chat, &echo, "stop")
        }
        Reply::Raw(text) => ([(header::CONTENT_TYPE, "application/json")], text).into_response(),
    }
}

fn answer(chat: bool, text: &str, finish_reason: &str) -> Response {
    let body = if chat {
        json!({"object": "chat.completion", "choices": [
            {"index": 0, "message": {"role": "assistant", "content": text}, "finish_reason": finish_reason}
        ]})
    } else {
        json!({"object": "text_completion", "choices": [
            {"index": 0, "text": text, "finish_reason": finish_reason}
        ]})
    };
    Json(body).into_response()
}
