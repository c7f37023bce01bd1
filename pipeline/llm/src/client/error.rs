//! The errors of the LLM client ([`LlmError`]): of its config, of the server and its answers, of
//! the cache, and of the client's own runtime.

use super::ConfigFault;

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
