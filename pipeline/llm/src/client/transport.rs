//! Sending one prompt over HTTP: the request body, one attempt under its deadline, the retries
//! with jittered exponential backoff (and `Retry-After`), the retry of a cut-off answer, and the
//! probe of an endpoint before the first request.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use serde_json::{Value, json};
use tokio::sync::Semaphore;
use tokio::time::Instant;

use super::breaker::CircuitBreaker;
use super::config::Deadlines;
use super::rate_limit::RateLimiter;
use super::response::{BadAnswer, cut_off, parse_answer, parse_retry_after, preview};
use super::{LlmConfig, LlmError, Probe, RequestKind, SamplingParams};

/// The backoff ceiling doubles per retry up to `backoff_seconds × 2^MAX_BACKOFF_DOUBLINGS`.
pub(super) const MAX_BACKOFF_DOUBLINGS: u32 = 6;

/// Longest wait for the probe of an endpoint before the first request: a server that does not
/// answer a listing of its models in this time will not answer prompts either.
const PROBE_TIMEOUT: Duration = Duration::from_secs(5);

/// What request tasks share.
pub(super) struct Shared {
    http: reqwest::Client,
    url: String,
    api_key: Option<String>,
    pub(super) model: String,
    pub(super) kind: RequestKind,
    pub(super) params: SamplingParams,
    max_retries: u32,
    timeout: Duration,
    backoff_seconds: f64,
    max_retry_after: Duration,
    pub(super) semaphore: Semaphore,
    limiter: RateLimiter,
    root: String,
    retry_max_tokens: Option<u32>,
    breaker: CircuitBreaker,
    /// Set after a successful probe: one per client is enough.
    pub(super) probed: AtomicBool,
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
pub(super) struct Reply {
    pub(super) text: String,
    pub(super) finish_reason: String,
    pub(super) max_tokens: u32,
}
impl Shared {
    /// The shared state of a client of a checked `config`.
    pub(super) fn new(
        config: &LlmConfig,
        deadlines: Deadlines,
        api_key: Option<String>,
        http: reqwest::Client,
    ) -> Shared {
        let root = config.root();
        Shared {
            http,
            url: format!("{root}/{}", config.kind.endpoint()),
            api_key,
            model: config.model.clone(),
            kind: config.kind,
            params: config.sampling(),
            max_retries: config.max_retries,
            timeout: deadlines.timeout,
            backoff_seconds: config.backoff_seconds,
            max_retry_after: deadlines.max_retry_after,
            semaphore: Semaphore::new(config.concurrency),
            limiter: RateLimiter::new(config.requests_per_minute),
            root: root.to_string(),
            retry_max_tokens: config.retry_max_tokens,
            breaker: CircuitBreaker::new(config.circuit_breaker_failures),
            probed: AtomicBool::new(false),
        }
    }

    /// One prompt with retries. Holds its concurrency permit through the backoff sleeps, so an
    /// overloaded server sees fewer requests, not the same number reshuffled. An answer cut off by
    /// the token limit is asked once more with `retry_max_tokens` when set, and otherwise fails.
    pub(super) async fn request(&self, prompt: &str) -> Result<Reply, LlmError> {
        let mut body = self.body(prompt);
        let mut max_tokens = self.params.max_tokens;
        let mut attempts = 0;
        loop {
            if self.breaker.is_open() {
                return Err(self.circuit_open("an earlier request".into()));
            }
            attempts += 1;
            self.limiter.wait().await;
            let failure = match self.attempt(&body).await {
                Ok((text, finish_reason)) => {
                    self.breaker.answered();
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
                if self.breaker.connect_failed() {
                    return Err(self.circuit_open(error_chain(e)));
                }
            } else if !matches!(failure, Failure::Timeout) {
                // The server answered something: it is there.
                self.breaker.answered();
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
            failures: self.breaker.limit(),
            message,
        }
    }

    /// `GET {root}/models` within [`PROBE_TIMEOUT`] (or the attempt timeout when shorter).
    pub(super) async fn probe(&self) -> Result<Probe, LlmError> {
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
