//! motionforge: a dataset builder for text-to-motion research.
pub mod annotate;
pub mod build;
pub mod clip;
pub mod compose_text;
pub mod config;
pub mod features;
pub mod io;
pub mod llm;
pub mod motion;
pub mod parts;
pub mod progress;
pub mod quality;
pub mod report;
pub mod source;
pub mod stages;
pub mod terminal;
pub mod text;
