//! Builds end to end on real captures (and AMASS files written by the tests) and what they write:
//! layout, reuse, rejects, faults, locks, resumption, the LLM stages and client, the report,
//! exports, the planner, and the readers users open the table with.
//!
//! One test binary per group (not one per file): each binary links the whole library, so a few
//! binaries build much faster than one per file. Run one file's tests with its module name as the
//! filter: `cargo test --test builds build_pipeline::`.

mod common;

#[path = "amass.rs"]
mod amass;

#[path = "build_pipeline.rs"]
mod build_pipeline;

#[path = "dataset_browse.rs"]
mod dataset_browse;

#[path = "dataset_layout.rs"]
mod dataset_layout;

#[path = "hardening.rs"]
mod hardening;

#[path = "humanml3d_build.rs"]
mod humanml3d_build;

#[path = "humanml3d_export.rs"]
mod humanml3d_export;

#[path = "kill_resume.rs"]
mod kill_resume;

#[path = "llm_client.rs"]
mod llm_client;

#[path = "llm_real.rs"]
mod llm_real;

#[path = "llm_stages.rs"]
mod llm_stages;

#[path = "loaders.rs"]
mod loaders;

#[path = "plan_status.rs"]
mod plan_status;

#[path = "planner.rs"]
mod planner;

#[path = "report.rs"]
mod report;

#[path = "synthetic_build.rs"]
mod synthetic_build;

#[path = "workspace_lock.rs"]
mod workspace_lock;

#[path = "write_faults.rs"]
mod write_faults;
