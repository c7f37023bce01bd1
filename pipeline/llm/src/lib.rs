//! LLM access for motionforge, knowing nothing of clips or motion: prompt templates and their data
//! ([`prompt`]), an OpenAI-compatible client with concurrency, rate limit, retries and a circuit
//! breaker ([`client`]), the append-only response cache ([`cache`]), and the checks of
//! what comes back: paraphrases ([`paraphrase`]) and task plans ([`plans`]).
//!
//! Principal types: [`prompt::Prompts`], [`client::LlmClient`] and [`client::LlmConfig`],
//! [`cache::ResponseCache`], [`plans::PlanStep`].
//!
//! # A clip's way through this crate
//!
//! Step 3, only with an LLM configured: the clip's text is sent once (through the cache) for its
//! body parts, paraphrases and task plan; the answers are checked here before a stage uses them.

pub mod cache;
pub mod client;
pub mod paraphrase;
pub mod plans;
pub mod prompt;
pub mod unanswered;

pub use unanswered::Unanswered;
