//! The `[llm]` config ([`LlmConfig`]) with its defaults, the request kind and sampling parameters
//! it sends, and its checks: the range of every value, each fault a [`ConfigFault`].

use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::LlmError;
use super::transport::MAX_BACKOFF_DOUBLINGS;
use crate::cache::CacheKey;

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

    pub(super) fn endpoint(self) -> &'static str {
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

/// The durations of a checked config.
pub(super) struct Deadlines {
    /// Deadline of one attempt.
    pub(super) timeout: Duration,
    /// Upper bound on a server's `Retry-After`.
    pub(super) max_retry_after: Duration,
}

impl LlmConfig {
    /// Every value in range (what [`LlmClient::new`](super::LlmClient::new) checks), or the
    /// first fault found.
    pub(super) fn check(&self) -> Result<Deadlines, LlmError> {
        let config_err = |fault: ConfigFault| Err(LlmError::Config { fault });
        match reqwest::Url::parse(self.root()) {
            Ok(u) if matches!(u.scheme(), "http" | "https") => {}
            _ => {
                return config_err(ConfigFault::BaseUrl {
                    url: self.base_url.clone(),
                });
            }
        }
        if self.model.trim().is_empty() {
            return config_err(ConfigFault::NoModel);
        }
        if !(self.temperature.is_finite() && self.temperature >= 0.0) {
            return config_err(ConfigFault::Temperature(self.temperature));
        }
        if self.concurrency == 0 {
            return config_err(ConfigFault::Zero { key: "concurrency" });
        }
        if self.requests_per_minute == 0 {
            return config_err(ConfigFault::Zero {
                key: "requests_per_minute",
            });
        }
        if self.circuit_breaker_failures == 0 {
            return config_err(ConfigFault::Zero {
                key: "circuit_breaker_failures",
            });
        }
        if let Some(bigger) = self.retry_max_tokens
            && bigger <= self.max_tokens
        {
            return config_err(ConfigFault::RetryMaxTokens {
                retry: bigger,
                max: self.max_tokens,
            });
        }
        let timeout = seconds("timeout_seconds", self.timeout_seconds, false)?;
        let max_retry_after = seconds(
            "max_retry_after_seconds",
            self.max_retry_after_seconds,
            true,
        )?;
        // Check the largest backoff ceiling too, so computing a delay can never fail later.
        seconds("backoff_seconds", self.backoff_seconds, true)?;
        seconds(
            "backoff_seconds",
            self.backoff_seconds * f64::from(1u32 << MAX_BACKOFF_DOUBLINGS),
            true,
        )?;
        Ok(Deadlines {
            timeout,
            max_retry_after,
        })
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::LlmClient;

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
