//! An OpenAI-compatible LLM client (OpenAI, vLLM, llama.cpp's server, Ollama's `/v1`) with bounded
//! concurrency, a request-rate limit, retries with jittered exponential backoff, and a persistent
//! response cache in front.
//!
//! The rest of the pipeline is synchronous, so [`LlmClient::complete_all`] is too: the client owns
//! a small tokio runtime and blocks on it.
//!
//! By concern: the config and its checks (`config.rs`), the errors (`error.rs`), sending a prompt
//! with retries and the probe (`transport.rs`), the circuit breaker (`breaker.rs`), the rate limit
//! (`rate_limit.rs`), reading a response (`response.rs`); here the client itself, which answers
//! from the cache and sends the rest.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use crate::cache::{CacheEntry, CacheKey, ResponseCache};
use transport::Shared;

mod breaker;
mod config;
mod error;
mod rate_limit;
mod response;
mod transport;

pub use config::{
    ConfigFault, DEFAULT_CIRCUIT_BREAKER_FAILURES, LlmConfig, RequestKind, SamplingParams,
};
pub use error::LlmError;
pub use response::FINISH_UNREPORTED;

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

impl LlmClient {
    /// Checks the config, reads the API key from its environment variable and starts the runtime.
    pub fn new(config: LlmConfig) -> Result<LlmClient, LlmError> {
        let deadlines = config.check()?;
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

        let shared = Shared::new(&config, deadlines, api_key, http);
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
