//! LLM access for motionforge, knowing nothing of clips or motion: prompt templates and their data
//! ([`prompt`]), an OpenAI-compatible client with concurrency, rate limit, retries and a circuit
//! breaker ([`client`]), the append-only response cache ([`cache`]), and the checks of
//! what comes back: paraphrases ([`paraphrase`]) and task plans ([`plans`]).

pub mod cache;
pub mod client;
pub mod paraphrase;
pub mod plans;
pub mod prompt;
pub mod unanswered;

pub use unanswered::Unanswered;
