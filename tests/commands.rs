//! The binary as users run it: commands, flags, help and exit codes, the commands the docs show, the service and its browser.
//!
//! One test binary per group (not one per file): each binary links the whole library, so a few
//! binaries build much faster than one per file. Run one file's tests with its module name as the
//! filter: `cargo test --test commands browser::`.

mod common;

#[path = "browser.rs"]
mod browser;

#[path = "cli.rs"]
mod cli;

#[path = "docs_commands.rs"]
mod docs_commands;

#[path = "serve_api.rs"]
mod serve_api;

#[path = "serve_isolation.rs"]
mod serve_isolation;

#[path = "serve_schedule.rs"]
mod serve_schedule;
