//! The workspace's crates depend on each other one way, lowest first (core, language, llm,
//! sources, format, report, export, planner, runner, serve, then the command line): Cargo refuses
//! a cycle, and this test refuses an edge against the declared order, so a lower crate cannot come
//! to depend on a higher one. It also refuses a dependency a crate declares but never names, as
//! `cargo machete` does: a dependency left behind by a move costs every build its compile time.
use crate::common;

/// The workspace's crates, lowest first: a crate may depend only on crates before it. Cargo
/// refuses cycles; this keeps the order the architecture describes (sources, then stages, then
/// sinks), so a lower crate cannot come to depend on a higher one by a new edge either.
const CRATE_ORDER: &[&str] = &[
    "motionforge-core",
    "motionforge-language",
    "motionforge-llm",
    "motionforge-sources",
    "motionforge-format",
    "motionforge-report",
    "motionforge-export",
    "motionforge-planner",
    "motionforge-runner",
    "motionforge-serve",
    "motionforge",
];

/// Each crate's manifest under `pipeline/`: its package name, its internal (path) dependencies
/// and its other dependencies, as written.
fn crates() -> Vec<(String, std::path::PathBuf, Vec<String>, Vec<String>)> {
    let pipeline = common::repo().join("pipeline");
    let mut dirs = Vec::new();
    for entry in std::fs::read_dir(&pipeline).unwrap().flatten() {
        if entry.path().join("Cargo.toml").is_file() {
            dirs.push(entry.path());
        }
    }
    let mut found = Vec::new();
    for dir in dirs {
        let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
        let mut name = String::new();
        let mut internal = Vec::new();
        let mut external = Vec::new();
        let mut section = String::new();
        for line in manifest.lines() {
            let line = line.trim();
            if line.starts_with('[') {
                section = line.to_string();
                continue;
            }
            let Some((key, value)) = line.split_once('=') else {
                continue;
            };
            let key = key.trim().trim_end_matches(".workspace").to_string();
            if section == "[package]" && key == "name" {
                name = value.trim().trim_matches('"').to_string();
            } else if section == "[dependencies]" {
                if value.contains("path =") {
                    internal.push(key);
                } else {
                    external.push(key);
                }
            }
        }
        found.push((name, dir, internal, external));
    }
    found
}

#[test]
fn crates_depend_only_on_lower_crates() {
    let crates = crates();
    assert!(crates.len() >= CRATE_ORDER.len(), "{crates:?}");
    for (name, dir, internal, _) in &crates {
        let rank = CRATE_ORDER
            .iter()
            .position(|c| c == name)
            .unwrap_or_else(|| {
                panic!(
                    "{name} ({}) is not in CRATE_ORDER: place it there",
                    dir.display()
                )
            });
        for dep in internal {
            let dep_rank = CRATE_ORDER.iter().position(|c| c == dep).unwrap();
            assert!(
                dep_rank < rank,
                "{name} depends on {dep}, which is not below it in CRATE_ORDER"
            );
        }
    }
    let (_, _, core_deps, _) = crates
        .iter()
        .find(|(n, ..)| n == "motionforge-core")
        .unwrap();
    assert!(
        core_deps.is_empty(),
        "the core crate depends on {core_deps:?}"
    );
}

/// Every dependency a crate declares is named in its code (`name::`, `use name`), as
/// `cargo machete` checks: a dependency left behind by a move costs build time for nothing.
#[test]
fn no_crate_declares_a_dependency_it_does_not_use() {
    let mut unused = Vec::new();
    for (name, dir, internal, external) in crates() {
        let mut code = String::new();
        let mut stack = vec![dir.join("src")];
        while let Some(d) = stack.pop() {
            for entry in std::fs::read_dir(&d).unwrap().flatten() {
                let path = entry.path();
                if path.is_dir() {
                    stack.push(path);
                } else if path.extension().is_some_and(|e| e == "rs") {
                    code.push_str(&std::fs::read_to_string(&path).unwrap());
                    code.push('\n');
                }
            }
        }
        for dep in internal.iter().chain(&external) {
            let ident = dep.replace('-', "_");
            let named = [
                format!("{ident}::"),
                format!("use {ident}"),
                format!("{ident} as "),
            ]
            .iter()
            .any(|p| code.contains(p.as_str()));
            if !named {
                unused.push(format!("{name}: {dep}"));
            }
        }
    }
    assert!(
        unused.is_empty(),
        "declared but never named in the code: {unused:?}"
    );
}
