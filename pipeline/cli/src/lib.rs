//! motionforge turns motion-capture recordings into training sets for text-to-motion models:
//! captures in, labelled, mirrored and composed Parquet shards out, with a manifest, a dataset
//! card, normalisation statistics and a statistics report.
//!
//! # The principal types
//!
//! * [`config::Config`]: one build, as written in its TOML file (sources, segmentation, splits,
//!   mirroring, synthetic pairs, features, LLM).
//! * [`motion::Skeleton`] and [`motion::Motion`]: a joint hierarchy and its local rotations and
//!   translations per frame, read from BVH by [`motion::read_bvh`]; a [`motion::Profile`] says
//!   which joint is which (left/right pairs, body parts, axes and units).
//! * [`annotate::span::CaptureAnnotation`]: what an annotation format (file names, BABEL, event
//!   logs, frame-range indexes) says about one capture, as labelled time spans.
//! * [`clip::Capture`] and [`clip::Clip`]: a read capture, and one row of the dataset (its text,
//!   labels, [`parts::PartSet`], provenance and skeleton). A clip holds no frames: the work that
//!   needs them holds a [`clip::LoadedClip`] (the clip and its [`motion::Motion`]), and a build
//!   otherwise keeps them in the stage cache, so a clip without frames cannot pass for an empty
//!   one.
//! * [`build::Stage`], [`build::Workspace`] and [`base::Fingerprint`]: the stages in order, the
//!   per-item stage cache, and the content fingerprint that decides what re-runs.
//! * [`base::Reject`] and [`base::Dropped`]: an input refused (file, line, frame, reason) and a
//!   segment that became no clip; nothing is lost silently.
//!
//! # How one clip travels from a capture to a shard row
//!
//! 1. **Source** ([`source`]): the config's globs find the capture files; each source's
//!    annotations are read once ([`annotate`]).
//! 2. **ingest** ([`stages::ingest`]): the BVH is parsed into a [`clip::Capture`] at its own frame
//!    rate, or refused with a [`base::Reject`].
//! 3. **segment** ([`stages::segment`]): each labelled span becomes a [`clip::Clip`] and its
//!    motion resampled to the dataset rate, typed by the motion-type taxonomy and given its goals;
//!    the motion goes to the stage cache at once, so a build holds clips, not frames.
//! 4. **label, paraphrase, plan** ([`stages::label`], [`stages::augment`]): body parts from the
//!    embedded labeller or an LLM through a cached client ([`llm`]).
//! 5. **mirror** ([`stages::mirror`]): the left/right reflection of motion, texts and labels.
//! 6. **compose** ([`stages::compose`]): synthetic simultaneous pairs stitched by body part,
//!    each checked for plausibility.
//! 7. **write** (the runner, with [`io`]): each row is made once (positions in the dataset frame,
//!    derived features, plausibility of real clips) and rows become Parquet shards per split, with
//!    the manifest, the card and normalisation statistics, staged and switched in atomically;
//!    **report** ([`report`]) then reads the shards back for the statistics report.
//!
//! [`build::build`] runs it all, reusing every cached output whose fingerprint is unchanged.
//!
//! # The crates
//!
//! This library re-exports the modules of the workspace's crates under one name, as `polars`
//! does for its crates: `motionforge-core` ([`base`], [`motion`], [`humanml3d`], [`features`],
//! [`quality`], [`progress`]), `motionforge-language` ([`text`], [`compose_text`], [`caption`],
//! [`parts`]), `motionforge-llm` ([`llm`]), `motionforge-sources` ([`annotate`], [`amass`],
//! [`clip`]), `motionforge-format` ([`io`], [`dataset`]), `motionforge-report` ([`report`]),
//! `motionforge-export` ([`export`]), `motionforge-planner` ([`planner`]), `motionforge-runner`
//! ([`build`], [`config`], [`source`], [`stages`]) and `motionforge-serve` ([`serve`]). They
//! depend on each other one way, in that order (`docs/architecture.md`; `tests/crate_graph.rs`
//! keeps the order); the binary's own modules are [`terminal`] and the commands.
//!
//! # Example
//!
//! ```no_run
//! use std::path::Path;
//! use motionforge::build::{BuildOptions, build};
//! use motionforge::config::Config;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let config = Config::load(Path::new("fixtures/demo.toml"))?;
//! let report = build(&config, &BuildOptions::default())?;
//! println!(
//!     "{} rows from {} captures; {} rejected (see {})",
//!     report.clips,
//!     report.captures,
//!     report.rejects.len(),
//!     report.output.join(motionforge::base::layout::REJECTS_FILE).display()
//! );
//! # Ok(())
//! # }
//! ```
pub use motionforge_core::base;
pub use motionforge_core::features;
pub use motionforge_core::humanml3d;
pub use motionforge_core::motion;
pub use motionforge_core::progress;
pub use motionforge_core::quality;
pub use motionforge_export as export;
pub use motionforge_format::dataset;
pub use motionforge_format::io;
pub use motionforge_language::caption;
pub use motionforge_language::compose_text;
pub use motionforge_language::parts;
pub use motionforge_llm as llm;
pub use motionforge_planner as planner;
pub use motionforge_report as report;
pub use motionforge_runner as build;
pub use motionforge_runner::config;
pub use motionforge_runner::source;
pub use motionforge_runner::stages;
pub use motionforge_serve as serve;
pub use motionforge_sources::amass;
pub use motionforge_sources::annotate;
pub use motionforge_sources::clip;
pub mod terminal;
pub use motionforge_language::text;
