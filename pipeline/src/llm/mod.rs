//! LLM access: prompt templates, an OpenAI-compatible client with a persistent response cache,
//! and parsers for the answers. Knows nothing of clips or motion.

pub mod cache;
pub mod client;
pub mod paraphrase;
pub mod plans;
pub mod prompt;
pub mod unanswered;

pub use unanswered::Unanswered;
