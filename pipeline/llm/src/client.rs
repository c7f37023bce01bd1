//! An OpenAI-compatible LLM client (OpenAI, vLLM, llama.cpp's server, Ollama's `/v1`) with bounded
//! concurrency, a request-rate limit, retries with jittered exponential backoff, and a persistent
//! response cache in front.
//!
//! The rest of the pipeline is synchronous, so [`LlmClient::complete_all`] is too: the client owns
//! a small tokio runtime and blocks on it.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use tokio::sync::Semaphore;
use tokio::time::Instant;

use crate::cache::{CacheEntry, CacheKey, ResponseCache};

/// Characters of an error body kept in [`LlmError::Http`].
const BODY_PREVIEW_CHARS: usize = 300;

/// The backoff ceiling doubles per retry up to `backoff_seconds × 2^MAX_BACKOFF_DOUBLINGS`.
const MAX_BACKOFF_DOUBLINGS: u32 = 6;

/// Which OpenAI endpoint a request goes to.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[serde(rename_all = "lowercase")]
pub enum RequestKind {
    /// `POST {base_url}/chat/completions`; the prompt is sent as one user message.
    #[default]
    Chat,
    /// `POST {base_url}/completions`; the prompt is sent as raw text.
    Completion,
}

impl RequestKind {
    /// `chat` or `completion`, as in configs and cache keys.
    pub fn as_str(self) -> &'static str {
        match self {
            RequestKind::Chat => "chat",
            RequestKind::Completion => "completion",
        }
    }

    fn endpoint(self) -> &'static str {
        match self {
            RequestKind::Chat => "chat/completions",
            RequestKind::Completion => "completions",
        }
    }
}

/// The sampling parameters sent with every request; all of them are part of the cache key.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct SamplingParams {
    /// Sampling temperature; 0 is (close to) greedy.
    pub temperature: f64,
    /// Upper bound on generated tokens.
    pub max_tokens: u32,
    /// Sampling seed, sent only when set.
    #[serde(default)]
    pub seed: Option<u64>,
}

fn default_kind() -> RequestKind {
    RequestKind::Chat
}
fn default_max_tokens() -> u32 {
    256
}
fn default_concurrency() -> usize {
    4
}
fn default_requests_per_minute() -> u32 {
    60
}
fn default_max_retries() -> u32 {
    5
}
fn default_timeout_seconds() -> f64 {
    60.0
}
fn default_backoff_seconds() -> f64 {
    1.0
}
fn default_max_retry_after_seconds() -> f64 {
    60.0
}
fn default_circuit_breaker_failures() -> u32 {
    DEFAULT_CIRCUIT_BREAKER_FAILURES
}
fn is_default_breaker(n: &u32) -> bool {
    *n == DEFAULT_CIRCUIT_BREAKER_FAILURES
}

/// Connection failures in a row (over all prompts) after which the client stops sending.
pub const DEFAULT_CIRCUIT_BREAKER_FAILURES: u32 = 3;

/// Longest wait for the probe of an endpoint before the first request: a server that does not
/// answer a listing of its models in this time will not answer prompts either.
const PROBE_TIMEOUT: Duration = Duration::from_secs(5);

/// What the client writes as the finish reason of an answer whose server reported none, so that
/// such entries are told apart from entries of versions that did not record it.
pub const FINISH_UNREPORTED: &str = "unreported";

/// How to reach an OpenAI-compatible server and how to sample from it.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LlmConfig {
    /// The API root including `/v1`, e.g. `http://127.0.0.1:8080/v1`.
    pub base_url: String,
    /// The model name sent in each request.
    pub model: String,
    /// Name of the environment variable holding the API key, sent as `Authorization: Bearer`.
    /// The key itself never appears in configs.
    #[serde(default)]
    pub api_key_env: Option<String>,
    /// Chat or completion endpoint.
    #[serde(default = "default_kind")]
    pub kind: RequestKind,
    /// Sampling temperature.
    #[serde(default)]
    pub temperature: f64,
    /// Upper bound on generated tokens per answer.
    #[serde(default = "default_max_tokens")]
    pub max_tokens: u32,
    /// Sampling seed, if the server supports one.
    #[serde(default)]
    pub seed: Option<u64>,
    /// Requests in flight at once.
    #[serde(default = "default_concurrency")]
    pub concurrency: usize,
    /// Request starts (retries included) allowed per minute.
    #[serde(default = "default_requests_per_minute")]
    pub requests_per_minute: u32,
    /// Retries after the first attempt.
    #[serde(default = "default_max_retries")]
    pub max_retries: u32,
    /// Deadline of one attempt, from sending to the last byte of the answer.
    #[serde(default = "default_timeout_seconds")]
    pub timeout_seconds: f64,
    /// Base of the exponential backoff between retries.
    #[serde(default = "default_backoff_seconds")]
    pub backoff_seconds: f64,
    /// Upper bound on a server's `Retry-After`.
    #[serde(default = "default_max_retry_after_seconds")]
    pub max_retry_after_seconds: f64,
    /// `max_tokens` of the one retry of an answer cut off by the token limit (`finish_reason:
    /// "length"`); larger than `max_tokens`. Without it a cut-off answer fails at once.
    // Skipped when unset so configs without it keep their fingerprint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub retry_max_tokens: Option<u32>,
    /// Connection failures in a row after which the client stops sending (the circuit breaker).
    #[serde(
        default = "default_circuit_breaker_failures",
        skip_serializing_if = "is_default_breaker"
    )]
    pub circuit_breaker_failures: u32,
}

impl LlmConfig {
    /// A config with every optional field at its default.
    pub fn new(base_url: &str, model: &str) -> LlmConfig {
        LlmConfig {
            base_url: base_url.to_string(),
            model: model.to_string(),
            api_key_env: None,
            kind: default_kind(),
            temperature: 0.0,
            max_tokens: default_max_tokens(),
            seed: None,
            concurrency: default_concurrency(),
            requests_per_minute: default_requests_per_minute(),
            max_retries: default_max_retries(),
            timeout_seconds: default_timeout_seconds(),
            backoff_seconds: default_backoff_seconds(),
            max_retry_after_seconds: default_max_retry_after_seconds(),
            retry_max_tokens: None,
            circuit_breaker_failures: DEFAULT_CIRCUIT_BREAKER_FAILURES,
        }
    }

    /// The API root without a trailing `/`.
    pub fn root(&self) -> &str {
        self.base_url.trim_end_matches('/')
    }

    /// The sampling parameters of this config.
    pub fn sampling(&self) -> SamplingParams {
        SamplingParams {
            temperature: self.temperature,
            max_tokens: self.max_tokens,
            seed: self.seed,
        }
    }

    /// The cache key of a prompt under this config. Needs no server or API key, so offline runs
    /// can look answers up.
    pub fn cache_key(&self, prompt: &str) -> CacheKey {
        CacheKey::new(&self.model, self.kind, prompt, &self.sampling())
    }
}

/// Errors of the LLM client. Cloneable because one result answers every duplicate of a prompt:
/// so a lower layer's error (reqwest's, I/O's, the cache's; none is `Clone`) is kept as its text.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LlmError {
    /// A config value is out of range.
    #[error("LLM config: {fault}")]
    Config {
        /// What is wrong.
        fault: ConfigFault,
    },
    /// `api_key_env` names a variable that is unset or empty.
    #[error("environment variable {var} (api_key_env) is not set or empty")]
    MissingApiKey {
        /// The variable name.
        var: String,
    },
    /// The server answered with an error status (the last one, if retried).
    #[error("HTTP {status} after {attempts} attempt(s): {body_preview}")]
    Http {
        /// The status code.
        status: u16,
        /// The start of the response body.
        body_preview: String,
        /// Requests sent for this prompt.
        attempts: u32,
    },
    /// Every attempt exceeded `timeout_seconds`.
    #[error("no answer within the timeout after {attempts} attempt(s)")]
    Timeout {
        /// Requests sent for this prompt.
        attempts: u32,
    },
    /// The connection could not be made or broke mid-request.
    #[error("connection failed after {attempts} attempt(s): {message}")]
    Connect {
        /// The transport's message.
        message: String,
        /// Requests sent for this prompt.
        attempts: u32,
    },
    /// A success status with a body that is not JSON or holds no answer.
    #[error("unusable response after {attempts} attempt(s): {message}")]
    BadResponse {
        /// What is wrong with the body.
        message: String,
        /// Requests sent for this prompt.
        attempts: u32,
    },
    /// The answer was cut off by the token limit (`finish_reason: "length"`), also after the retry
    /// with `retry_max_tokens` when one is configured. Never cached.
    #[error(
        "answer cut off at max_tokens = {max_tokens} (finish_reason \"length\") after {attempts} attempt(s): `{preview}`; raise llm.max_tokens or set llm.retry_max_tokens"
    )]
    Truncated {
        /// The token limit of the last attempt.
        max_tokens: u32,
        /// The start of the cut-off answer.
        preview: String,
        /// Requests sent for this prompt.
        attempts: u32,
    },
    /// The endpoint did not answer the probe sent before the first request: nothing was sent.
    #[error(
        "no LLM server answers at {url}: tried GET {url}/models ({message}). Start one (docs/llm-servers.md, e.g. `llama-server -m model.gguf --port 8080`) and check [llm] base_url, or build with --offline to use cached answers only"
    )]
    Unreachable {
        /// The API root.
        url: String,
        /// Why the probe failed.
        message: String,
    },
    /// The circuit breaker opened: this many connection failures in a row, so nothing more is
    /// sent in this build.
    #[error(
        "stopped sending to {url} after {failures} connection failures in a row (last: {message}); answers received so far are cached: restart the server and build again, or build with --offline"
    )]
    CircuitOpen {
        /// The API root.
        url: String,
        /// Failures in a row.
        failures: u32,
        /// The last transport error.
        message: String,
    },
    /// The answer is not cached and the server may not be asked; returned by callers in offline mode.
    #[error("no cached answer, and the LLM may not be called (offline)")]
    Offline,
    /// An answer arrived but could not be written to the cache; it is withheld so that no result
    /// depends on an answer a later run cannot reproduce.
    #[error("answer not cached: {message}")]
    Cache {
        /// The cache error.
        message: String,
    },
    /// The async runtime could not be started.
    #[error("LLM client: cannot start the async runtime: {message}")]
    Runtime {
        /// The I/O error's text (kept as text: the error is cloned, and `std::io::Error` is not
        /// `Clone`).
        message: String,
    },
    /// The HTTP client could not be built.
    #[error("LLM client: cannot build the HTTP client: {message}")]
    HttpClient {
        /// reqwest's message (kept as text: `reqwest::Error` is not `Clone`).
        message: String,
    },
    /// The task driving the requests (or the probe) panicked.
    #[error("LLM client: {} driver panicked", if *.probe { "probe" } else { "request" })]
    DriverPanicked {
        /// True for the probe, false for the requests.
        probe: bool,
    },
    /// The client's runtime was shut down before the call.
    #[error("LLM client: runtime already shut down")]
    ShutDown,
    /// The semaphore bounding concurrent requests was closed under a request.
    #[error("LLM client: request semaphore closed")]
    SemaphoreClosed,
    /// A request task ended without handing back its result.
    #[error("LLM client: request task ended without a result")]
    TaskLost,
}

impl LlmError {
    /// True when the server is gone (nothing answers, or the circuit breaker opened): asking more
    /// is pointless, so the stage stops with this error instead of falling back prompt by prompt.
    pub fn stops_stage(&self) -> bool {
        matches!(
            self,
            LlmError::Unreachable { .. } | LlmError::CircuitOpen { .. }
        )
    }
}

/// What [`LlmClient::complete_all_observed`] reports while it works.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RequestEvent {
    /// Requests are about to be sent: `to_send` distinct prompts, `cached` answered from the cache.
    Sending {
        /// Prompts answered from the cache.
        cached: usize,
        /// Distinct prompts to send.
        to_send: usize,
    },
    /// One distinct prompt is finished: answered, or failed after its retries.
    Finished {
        /// Whether it was answered.
        ok: bool,
    },
}

/// What the probe of an endpoint found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Probe {
    /// The URL tried (`{base_url}/models`).
    pub url: String,
    /// The HTTP status of the answer (any status shows that a server listens).
    pub status: u16,
    /// How long the answer took.
    pub elapsed: Duration,
    /// The model ids listed, when the answer was OpenAI's model list.
    pub models: Vec<String>,
}

/// One answer, and whether it came from the cache.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Answer {
    /// The model's text.
    pub text: String,
    /// True when no request was sent for it.
    pub from_cache: bool,
}

/// The OpenAI-compatible client. Holds its own tokio runtime; the rate limit carries over between
/// calls of [`complete_all`](LlmClient::complete_all).
pub struct LlmClient {
    config: LlmConfig,
    shared: Arc<Shared>,
    runtime: Option<tokio::runtime::Runtime>,
}

impl std::fmt::Debug for LlmClient {
    // Hand-written so the API key can never end up in a log.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LlmClient")
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

/// What request tasks share.
struct Shared {
    http: reqwest::Client,
    url: String,
    api_key: Option<String>,
    model: String,
    kind: RequestKind,
    params: SamplingParams,
    max_retries: u32,
    timeout: Duration,
    backoff_seconds: f64,
    max_retry_after: Duration,
    semaphore: Semaphore,
    limiter: RateLimiter,
    root: String,
    retry_max_tokens: Option<u32>,
    breaker_limit: u32,
    /// Connection failures in a row, over all prompts; any HTTP answer resets it.
    connect_failures: AtomicU32,
    /// Set when `connect_failures` reached `breaker_limit`: nothing more is sent.
    breaker_open: AtomicBool,
    /// Set after a successful probe: one per client is enough.
    probed: AtomicBool,
}

fn seconds(key: &'static str, value: f64, allow_zero: bool) -> Result<Duration, LlmError> {
    let bad = || LlmError::Config {
        fault: ConfigFault::Seconds {
            key,
            value,
            allow_zero,
        },
    };
    if !allow_zero && value <= 0.0 {
        return Err(bad());
    }
    Duration::try_from_secs_f64(value).map_err(|_| bad())
}

/// Which `[llm]` value is out of range, and the value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigFault {
    /// `base_url` is not an http or https URL.
    #[error("base_url `{url}` is not an http(s) URL")]
    BaseUrl {
        /// The URL as configured.
        url: String,
    },
    /// `model` is empty or blank.
    #[error("model is empty")]
    NoModel,
    /// `temperature` is negative or not finite.
    #[error("temperature must be finite and >= 0, got {0}")]
    Temperature(f64),
    /// A count that must be positive is 0.
    #[error("{key} must be at least 1")]
    Zero {
        /// The config key (`concurrency`, `requests_per_minute`, `circuit_breaker_failures`).
        key: &'static str,
    },
    /// `retry_max_tokens` does not raise `max_tokens`.
    #[error("retry_max_tokens ({retry}) must be larger than max_tokens ({max})")]
    RetryMaxTokens {
        /// `retry_max_tokens`.
        retry: u32,
        /// `max_tokens`.
        max: u32,
    },
    /// A duration is negative (or zero where it must be positive), not finite, or too long.
    #[error(
        "{key} must be a finite number {} seconds, got {value}",
        if *allow_zero { ">= 0" } else { "> 0" }
    )]
    Seconds {
        /// The config key.
        key: &'static str,
        /// The value (for `backoff_seconds`, also its largest doubling).
        value: f64,
        /// Whether 0 is allowed.
        allow_zero: bool,
    },
}

impl LlmClient {
    /// Checks the config, reads the API key from its environment variable and starts the runtime.
    pub fn new(config: LlmConfig) -> Result<LlmClient, LlmError> {
        let config_err = |fault: ConfigFault| Err(LlmError::Config { fault });
        let root = config.base_url.trim_end_matches('/');
        match reqwest::Url::parse(root) {
            Ok(u) if matches!(u.scheme(), "http" | "https") => {}
            _ => {
                return config_err(ConfigFault::BaseUrl {
                    url: config.base_url.clone(),
                });
            }
        }
        if config.model.trim().is_empty() {
            return config_err(ConfigFault::NoModel);
        }
        if !(config.temperature.is_finite() && config.temperature >= 0.0) {
            return config_err(ConfigFault::Temperature(config.temperature));
        }
        if config.concurrency == 0 {
            return config_err(ConfigFault::Zero { key: "concurrency" });
        }
        if config.requests_per_minute == 0 {
            return config_err(ConfigFault::Zero {
                key: "requests_per_minute",
            });
        }
        if config.circuit_breaker_failures == 0 {
            return config_err(ConfigFault::Zero {
                key: "circuit_breaker_failures",
            });
        }
        if let Some(bigger) = config.retry_max_tokens
            && bigger <= config.max_tokens
        {
            return config_err(ConfigFault::RetryMaxTokens {
                retry: bigger,
                max: config.max_tokens,
            });
        }
        let timeout = seconds("timeout_seconds", config.timeout_seconds, false)?;
        let max_retry_after = seconds(
            "max_retry_after_seconds",
            config.max_retry_after_seconds,
            true,
        )?;
        // Check the largest backoff ceiling too, so computing a delay can never fail later.
        seconds("backoff_seconds", config.backoff_seconds, true)?;
        seconds(
            "backoff_seconds",
            config.backoff_seconds * f64::from(1u32 << MAX_BACKOFF_DOUBLINGS),
            true,
        )?;

        let api_key = match &config.api_key_env {
            None => None,
            Some(var) => match std::env::var(var) {
                Ok(key) if !key.trim().is_empty() => Some(key.trim().to_string()),
                _ => return Err(LlmError::MissingApiKey { var: var.clone() }),
            },
        };

        let runtime = tokio::runtime::Builder::new_multi_thread()
            // Requests are I/O-bound; two workers drive hundreds of them.
            .worker_threads(2)
            .thread_name("motionforge-llm")
            .enable_all()
            .build()
            .map_err(|e| LlmError::Runtime {
                message: e.to_string(),
            })?;
        // reqwest's connector registers with the runtime it is built in.
        let http = {
            let _guard = runtime.enter();
            reqwest::Client::builder()
                .user_agent(concat!("motionforge/", env!("CARGO_PKG_VERSION")))
                .build()
                .map_err(|e| LlmError::HttpClient {
                    message: e.to_string(),
                })?
        };

        let shared = Shared {
            http,
            url: format!("{root}/{}", config.kind.endpoint()),
            api_key,
            model: config.model.clone(),
            kind: config.kind,
            params: config.sampling(),
            max_retries: config.max_retries,
            timeout,
            backoff_seconds: config.backoff_seconds,
            max_retry_after,
            semaphore: Semaphore::new(config.concurrency),
            limiter: RateLimiter::new(config.requests_per_minute),
            root: root.to_string(),
            retry_max_tokens: config.retry_max_tokens,
            breaker_limit: config.circuit_breaker_failures,
            connect_failures: AtomicU32::new(0),
            breaker_open: AtomicBool::new(false),
            probed: AtomicBool::new(false),
        };
        Ok(LlmClient {
            config,
            shared: Arc::new(shared),
            runtime: Some(runtime),
        })
    }

    /// The config the client was built from.
    pub fn config(&self) -> &LlmConfig {
        &self.config
    }

    /// The cache key of a prompt under this client's model, endpoint and sampling parameters.
    pub fn key(&self, prompt: &str) -> CacheKey {
        self.config.cache_key(prompt)
    }

    /// Sends every prompt not already in the cache, at most `concurrency` at a time and
    /// `requests_per_minute` overall; identical prompts are sent once. Returns per prompt the
    /// answer or the final error. Answers are written to the cache as they arrive, so a crash
    /// loses at most the requests in flight.
    ///
    /// Blocks the calling thread. Safe to call from inside another tokio runtime: the work then
    /// runs on a helper thread.
    pub fn complete_all(
        &self,
        prompts: &[String],
        cache: &mut ResponseCache,
    ) -> Vec<Result<Answer, LlmError>> {
        self.complete_all_observed(prompts, cache, &|_| {})
    }

    /// [`complete_all`](LlmClient::complete_all), telling `observe` how many prompts will be sent
    /// and when each is finished (for progress bars).
    ///
    /// Before the first request of this client the endpoint is probed (`GET {base_url}/models`,
    /// at most 5 s): when nothing answers, every prompt to send fails with
    /// [`LlmError::Unreachable`] and nothing is sent.
    pub fn complete_all_observed(
        &self,
        prompts: &[String],
        cache: &mut ResponseCache,
        observe: &(dyn Fn(RequestEvent) + Sync),
    ) -> Vec<Result<Answer, LlmError>> {
        self.block(
            || failed_all(prompts.len(), LlmError::DriverPanicked { probe: false }),
            || self.run(prompts, cache, observe),
        )
        .unwrap_or_else(|| failed_all(prompts.len(), LlmError::ShutDown))
    }

    /// Asks the endpoint for its model list (`GET {base_url}/models`, at most 5 s). Any HTTP answer
    /// shows that a server listens; only a connection failure or silence is an error.
    pub fn probe(&self) -> Result<Probe, LlmError> {
        self.block(
            || Err(LlmError::DriverPanicked { probe: true }),
            || self.shared.probe(),
        )
        .unwrap_or(Err(LlmError::ShutDown))
    }

    /// Runs `work` on the client's runtime; on a helper thread when called inside another runtime
    /// (`block_on` panics there). `None` when the runtime is gone.
    fn block<'s, T: Send, F>(
        &'s self,
        panicked: impl FnOnce() -> T,
        work: impl FnOnce() -> F + Send,
    ) -> Option<T>
    where
        F: std::future::Future<Output = T> + 's,
    {
        let runtime = self.runtime.as_ref()?;
        let run = || runtime.block_on(work());
        Some(if tokio::runtime::Handle::try_current().is_ok() {
            std::thread::scope(|s| s.spawn(run).join().unwrap_or_else(|_| panicked()))
        } else {
            run()
        })
    }

    async fn run(
        &self,
        prompts: &[String],
        cache: &mut ResponseCache,
        observe: &(dyn Fn(RequestEvent) + Sync),
    ) -> Vec<Result<Answer, LlmError>> {
        let mut results: Vec<Option<Result<Answer, LlmError>>> = vec![None; prompts.len()];
        // Distinct keys to send, each with the prompt positions it answers.
        let mut pending: Vec<(CacheKey, Vec<usize>)> = Vec::new();
        let mut slot_of: HashMap<CacheKey, usize> = HashMap::new();
        let mut cached = 0;
        for (i, prompt) in prompts.iter().enumerate() {
            let key = self.key(prompt);
            // An entry an earlier version cached without its finish reason may be a cut-off
            // answer: it is asked again once, and the new entry replaces it.
            match cache.get_entry(&key).filter(|e| e.is_settled()) {
                Some(entry) => {
                    cached += 1;
                    results[i] = Some(Ok(Answer {
                        text: entry.response.clone(),
                        from_cache: true,
                    }));
                }
                None => match slot_of.get(&key) {
                    Some(&slot) => pending[slot].1.push(i),
                    None => {
                        slot_of.insert(key.clone(), pending.len());
                        pending.push((key, vec![i]));
                    }
                },
            }
        }
        // Probed before anything is announced: a server that is not there fails every prompt at
        // once, with no progress line per prompt that was never sent.
        if !pending.is_empty()
            && !self.shared.probed.load(Ordering::SeqCst)
            && let Err(e) = self.shared.probe().await
        {
            for (_, positions) in &pending {
                for &i in positions {
                    results[i] = Some(Err(e.clone()));
                }
            }
            return finish(results);
        }
        observe(RequestEvent::Sending {
            cached,
            to_send: pending.len(),
        });

        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
        for (slot, (_, positions)) in pending.iter().enumerate() {
            let shared = Arc::clone(&self.shared);
            let tx = tx.clone();
            let prompt = prompts[positions[0]].clone();
            tokio::spawn(async move {
                let result = match shared.semaphore.acquire().await {
                    Ok(_permit) => shared.request(&prompt).await,
                    Err(_) => Err(LlmError::SemaphoreClosed),
                };
                let _ = tx.send((slot, result));
            });
        }
        drop(tx);

        // The cache is written here, on one task, as answers arrive: no locking, and each answer is
        // durable before the next is taken.
        while let Some((slot, result)) = rx.recv().await {
            let (key, positions) = &pending[slot];
            let outcome = result.and_then(|reply| {
                let prompt = &prompts[positions[0]];
                let params = SamplingParams {
                    max_tokens: reply.max_tokens,
                    ..self.shared.params
                };
                let mut entry = CacheEntry::new(
                    &self.shared.model,
                    self.shared.kind,
                    prompt,
                    &params,
                    reply.text.clone(),
                    "llm",
                );
                entry.finish_reason = Some(reply.finish_reason);
                cache
                    .insert(key.clone(), entry)
                    .map_err(|e| LlmError::Cache {
                        message: e.to_string(),
                    })?;
                Ok(Answer {
                    text: reply.text,
                    from_cache: false,
                })
            });
            observe(RequestEvent::Finished {
                ok: outcome.is_ok(),
            });
            for &i in positions {
                results[i] = Some(outcome.clone());
            }
        }
        finish(results)
    }
}

fn finish(results: Vec<Option<Result<Answer, LlmError>>>) -> Vec<Result<Answer, LlmError>> {
    results
        .into_iter()
        .map(|r| r.unwrap_or(Err(LlmError::TaskLost)))
        .collect()
}

impl Drop for LlmClient {
    fn drop(&mut self) {
        // A plain drop of a runtime panics inside an async context; this never blocks or panics.
        if let Some(rt) = self.runtime.take() {
            rt.shutdown_background();
        }
    }
}

fn failed_all(n: usize, error: LlmError) -> Vec<Result<Answer, LlmError>> {
    vec![Err(error); n]
}

/// Why one attempt failed, before the attempt count is known.
enum Failure {
    Status {
        status: u16,
        body_preview: String,
        retry_after: Option<f64>,
    },
    Timeout,
    Transport(reqwest::Error),
    Bad(BadAnswer),
}

/// Why a success response holds no usable answer.
#[derive(Debug, thiserror::Error)]
enum BadAnswer {
    #[error("body is not JSON ({source}): {preview}")]
    NotJson {
        source: serde_json::Error,
        /// The start of the body.
        preview: String,
    },
    #[error("no choices in response: {preview}")]
    NoChoices {
        /// The start of the body.
        preview: String,
    },
    #[error("{field} is missing or not a string: {preview}")]
    NoText {
        /// Where the answer should be (`choices[0].text`...).
        field: &'static str,
        /// The start of the first choice.
        preview: String,
    },
}

impl Failure {
    /// 429, 5xx, timeouts, broken connections and unusable 200 bodies are retried; a 200 that is
    /// not the documented JSON is a server fault, like a 5xx. Other statuses are the request's fault.
    fn retryable(&self) -> bool {
        match self {
            Failure::Status { status, .. } => *status == 429 || *status >= 500,
            Failure::Timeout | Failure::Transport(_) | Failure::Bad(_) => true,
        }
    }

    fn into_error(self, attempts: u32) -> LlmError {
        match self {
            Failure::Status {
                status,
                body_preview,
                ..
            } => LlmError::Http {
                status,
                body_preview,
                attempts,
            },
            Failure::Timeout => LlmError::Timeout { attempts },
            Failure::Transport(e) => LlmError::Connect {
                message: error_chain(&e),
                attempts,
            },
            Failure::Bad(bad) => LlmError::BadResponse {
                message: bad.to_string(),
                attempts,
            },
        }
    }
}

/// A complete answer: its text, why the server stopped, and the token limit it was asked with.
struct Reply {
    text: String,
    finish_reason: String,
    max_tokens: u32,
}

/// `finish_reason` values that mean the token limit cut the answer: OpenAI's, vLLM's, llama.cpp's
/// and Ollama's `length` on both endpoints, and `max_tokens` of some proxies.
fn cut_off(finish_reason: &str) -> bool {
    matches!(finish_reason, "length" | "max_tokens")
}

impl Shared {
    /// One prompt with retries. Holds its concurrency permit through the backoff sleeps, so an
    /// overloaded server sees fewer requests, not the same number reshuffled. An answer cut off by
    /// the token limit is asked once more with `retry_max_tokens` when set, and otherwise fails.
    async fn request(&self, prompt: &str) -> Result<Reply, LlmError> {
        let mut body = self.body(prompt);
        let mut max_tokens = self.params.max_tokens;
        let mut attempts = 0;
        loop {
            if self.breaker_open.load(Ordering::SeqCst) {
                return Err(self.circuit_open("an earlier request".into()));
            }
            attempts += 1;
            self.limiter.wait().await;
            let failure = match self.attempt(&body).await {
                Ok((text, finish_reason)) => {
                    self.connect_failures.store(0, Ordering::SeqCst);
                    if !cut_off(&finish_reason) {
                        return Ok(Reply {
                            text,
                            finish_reason,
                            max_tokens,
                        });
                    }
                    match self.retry_max_tokens {
                        Some(bigger) if bigger > max_tokens => {
                            max_tokens = bigger;
                            body["max_tokens"] = json!(bigger);
                            continue;
                        }
                        _ => {
                            return Err(LlmError::Truncated {
                                max_tokens,
                                preview: preview(&text),
                                attempts,
                            });
                        }
                    }
                }
                Err(f) => f,
            };
            if let Failure::Transport(e) = &failure {
                let failures = self.connect_failures.fetch_add(1, Ordering::SeqCst) + 1;
                if failures >= self.breaker_limit {
                    self.breaker_open.store(true, Ordering::SeqCst);
                    return Err(self.circuit_open(error_chain(e)));
                }
            } else if !matches!(failure, Failure::Timeout) {
                // The server answered something: it is there.
                self.connect_failures.store(0, Ordering::SeqCst);
            }
            if !failure.retryable() || attempts > self.max_retries {
                return Err(failure.into_error(attempts));
            }
            let delay = match &failure {
                Failure::Status {
                    retry_after: Some(s),
                    ..
                } => Duration::try_from_secs_f64(*s)
                    .map_or(self.max_retry_after, |d| d.min(self.max_retry_after)),
                _ => self.backoff(attempts),
            };
            tokio::time::sleep(delay).await;
        }
    }

    fn circuit_open(&self, message: String) -> LlmError {
        LlmError::CircuitOpen {
            url: self.root.clone(),
            failures: self.breaker_limit,
            message,
        }
    }

    /// `GET {root}/models` within [`PROBE_TIMEOUT`] (or the attempt timeout when shorter).
    async fn probe(&self) -> Result<Probe, LlmError> {
        let url = format!("{}/models", self.root);
        let mut request = self.http.get(&url);
        if let Some(key) = &self.api_key {
            request = request.bearer_auth(key);
        }
        let started = Instant::now();
        let exchange = async {
            let response = request.send().await?;
            let status = response.status().as_u16();
            let bytes = response.bytes().await?;
            Ok::<_, reqwest::Error>((status, bytes))
        };
        let unreachable = |message: String| LlmError::Unreachable {
            url: self.root.clone(),
            message,
        };
        let limit = PROBE_TIMEOUT.min(self.timeout);
        let (status, bytes) = match tokio::time::timeout(limit, exchange).await {
            Err(_) => {
                return Err(unreachable(format!(
                    "no answer within {:.0} s",
                    limit.as_secs_f64()
                )));
            }
            Ok(Err(e)) => return Err(unreachable(error_chain(&e))),
            Ok(Ok(parts)) => parts,
        };
        self.probed.store(true, Ordering::SeqCst);
        let models = serde_json::from_slice::<Value>(&bytes)
            .ok()
            .and_then(|v| {
                v.get("data").and_then(Value::as_array).map(|models| {
                    models
                        .iter()
                        .filter_map(|m| m.get("id").and_then(Value::as_str))
                        .map(str::to_string)
                        .collect()
                })
            })
            .unwrap_or_default();
        Ok(Probe {
            url,
            status,
            elapsed: started.elapsed(),
            models,
        })
    }

    fn body(&self, prompt: &str) -> Value {
        let mut body = json!({
            "model": self.model,
            "temperature": self.params.temperature,
            "max_tokens": self.params.max_tokens,
        });
        match self.kind {
            RequestKind::Chat => {
                body["messages"] = json!([{ "role": "user", "content": prompt }]);
            }
            RequestKind::Completion => body["prompt"] = json!(prompt),
        }
        if let Some(seed) = self.params.seed {
            body["seed"] = json!(seed);
        }
        body
    }

    /// Full jitter: uniform in [0, backoff × 2^(n−1)], the exponent capped, after the n-th attempt.
    fn backoff(&self, attempts: u32) -> Duration {
        let doublings = attempts.saturating_sub(1).min(MAX_BACKOFF_DOUBLINGS);
        let ceiling = self.backoff_seconds * f64::from(1u32 << doublings);
        Duration::try_from_secs_f64(fastrand::f64() * ceiling).unwrap_or_default()
    }

    /// One request: the answer text and its finish reason, or why there is none.
    async fn attempt(&self, body: &Value) -> Result<(String, String), Failure> {
        let mut request = self.http.post(&self.url).json(body);
        if let Some(key) = &self.api_key {
            request = request.bearer_auth(key);
        }
        // One deadline over connecting, sending and reading the whole body.
        let exchange = async {
            let response = request.send().await?;
            let status = response.status().as_u16();
            let retry_after = response
                .headers()
                .get(reqwest::header::RETRY_AFTER)
                .and_then(|v| v.to_str().ok())
                .and_then(parse_retry_after);
            let bytes = response.bytes().await?;
            Ok::<_, reqwest::Error>((status, retry_after, bytes))
        };
        let (status, retry_after, bytes) = match tokio::time::timeout(self.timeout, exchange).await
        {
            Err(_) => return Err(Failure::Timeout),
            Ok(Err(e)) if e.is_timeout() => return Err(Failure::Timeout),
            Ok(Err(e)) => return Err(Failure::Transport(e)),
            Ok(Ok(parts)) => parts,
        };
        if !(200..300).contains(&status) {
            return Err(Failure::Status {
                status,
                body_preview: preview(&String::from_utf8_lossy(&bytes)),
                retry_after,
            });
        }
        parse_answer(self.kind, &bytes).map_err(Failure::Bad)
    }
}

/// `Retry-After` as delay-seconds (decimals accepted). The HTTP-date form is not parsed; such a
/// response falls back to the computed backoff.
fn parse_retry_after(value: &str) -> Option<f64> {
    value
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|s| s.is_finite() && *s >= 0.0)
}

fn parse_answer(kind: RequestKind, bytes: &[u8]) -> Result<(String, String), BadAnswer> {
    let value: Value = serde_json::from_slice(bytes).map_err(|source| BadAnswer::NotJson {
        source,
        preview: preview(&String::from_utf8_lossy(bytes)),
    })?;
    let Some(choice) = value
        .get("choices")
        .and_then(Value::as_array)
        .and_then(|c| c.first())
    else {
        return Err(BadAnswer::NoChoices {
            preview: preview(&value.to_string()),
        });
    };
    let (field, text) = match kind {
        RequestKind::Chat => (
            "choices[0].message.content",
            choice.pointer("/message/content"),
        ),
        RequestKind::Completion => ("choices[0].text", choice.get("text")),
    };
    let Some(text) = text.and_then(Value::as_str) else {
        return Err(BadAnswer::NoText {
            field,
            preview: preview(&choice.to_string()),
        });
    };
    // Both endpoints put `finish_reason` on the choice; a server that sends none (or null) gets
    // FINISH_UNREPORTED, so its answers are not taken for entries of older versions.
    let finish_reason = choice
        .get("finish_reason")
        .and_then(Value::as_str)
        .unwrap_or(FINISH_UNREPORTED);
    Ok((text.to_string(), finish_reason.to_string()))
}

fn preview(text: &str) -> String {
    let mut p: String = text.chars().take(BODY_PREVIEW_CHARS).collect();
    if p.len() < text.len() {
        p.push('…');
    }
    p
}

/// reqwest's top-level message is often just "error sending request"; the cause is further down.
fn error_chain(e: &reqwest::Error) -> String {
    let mut message = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        message.push_str(": ");
        message.push_str(&s.to_string());
        source = s.source();
    }
    message
}

/// Spaces request starts at least 60 s / `requests_per_minute` apart, so no 60-second window
/// holds more than `requests_per_minute` starts. Each caller reserves the next free start time
/// under a lock and sleeps until it. No bursts: servers that enforce per-minute limits often
/// enforce them over shorter periods too.
struct RateLimiter {
    interval: Duration,
    next_free: Mutex<Option<Instant>>,
}

impl RateLimiter {
    fn new(requests_per_minute: u32) -> RateLimiter {
        RateLimiter {
            interval: Duration::from_secs(60) / requests_per_minute.max(1),
            next_free: Mutex::new(None),
        }
    }

    async fn wait(&self) {
        let start = {
            // A poisoned lock only means another task panicked between two plain assignments.
            let mut next = self.next_free.lock().unwrap_or_else(|e| e.into_inner());
            let now = Instant::now();
            let start = next.filter(|&t| t > now).unwrap_or(now);
            *next = Some(start + self.interval);
            start
        };
        tokio::time::sleep_until(start).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The texts of every config fault, as `config check` and builds show them: they must not
    /// change.
    #[test]
    fn every_config_fault_reads_as_it_always_has() {
        let base = || LlmConfig::new("http://h/v1", "m");
        let cases = [
            (
                LlmConfig {
                    base_url: "ftp://h".into(),
                    ..base()
                },
                "LLM config: base_url `ftp://h` is not an http(s) URL",
            ),
            (
                LlmConfig {
                    model: " ".into(),
                    ..base()
                },
                "LLM config: model is empty",
            ),
            (
                LlmConfig {
                    temperature: -1.5,
                    ..base()
                },
                "LLM config: temperature must be finite and >= 0, got -1.5",
            ),
            (
                LlmConfig {
                    temperature: f64::NAN,
                    ..base()
                },
                "LLM config: temperature must be finite and >= 0, got NaN",
            ),
            (
                LlmConfig {
                    concurrency: 0,
                    ..base()
                },
                "LLM config: concurrency must be at least 1",
            ),
            (
                LlmConfig {
                    requests_per_minute: 0,
                    ..base()
                },
                "LLM config: requests_per_minute must be at least 1",
            ),
            (
                LlmConfig {
                    circuit_breaker_failures: 0,
                    ..base()
                },
                "LLM config: circuit_breaker_failures must be at least 1",
            ),
            (
                LlmConfig {
                    max_tokens: 100,
                    retry_max_tokens: Some(90),
                    ..base()
                },
                "LLM config: retry_max_tokens (90) must be larger than max_tokens (100)",
            ),
            (
                LlmConfig {
                    timeout_seconds: 0.0,
                    ..base()
                },
                "LLM config: timeout_seconds must be a finite number > 0 seconds, got 0",
            ),
            (
                LlmConfig {
                    max_retry_after_seconds: -2.5,
                    ..base()
                },
                "LLM config: max_retry_after_seconds must be a finite number >= 0 seconds, got -2.5",
            ),
            (
                LlmConfig {
                    backoff_seconds: f64::INFINITY,
                    ..base()
                },
                "LLM config: backoff_seconds must be a finite number >= 0 seconds, got inf",
            ),
            (
                LlmConfig {
                    backoff_seconds: -1.0,
                    ..base()
                },
                "LLM config: backoff_seconds must be a finite number >= 0 seconds, got -1",
            ),
        ];
        for (config, want) in cases {
            match LlmClient::new(config) {
                Err(err @ LlmError::Config { .. }) => assert_eq!(err.to_string(), want),
                Err(err) => panic!("{err}: not a config error; expected {want}"),
                Ok(_) => panic!("accepted; expected {want}"),
            }
        }
    }
}
