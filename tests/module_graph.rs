//! The library's modules depend on each other one way: read from the source as a reviewer would
//! (every `crate::<module>` path outside comments and test modules, `crate::{a, b}` groups
//! included), the graph of top-level modules has no cycle, and the leaf module `base` depends on
//! nothing. The binary (`main.rs`, `cli/`) may use any module and is not part of the graph.
use crate::common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Top-level module of a file under `src/`: `build/mod.rs` and `build/text.rs` are `build`.
fn module_of(relative: &Path) -> String {
    let first = relative.components().next().unwrap();
    let name = first.as_os_str().to_string_lossy();
    name.trim_end_matches(".rs").to_string()
}

/// The source without comments, and without what follows `#[cfg(test)]` (unit tests may reach
/// anywhere).
fn code(text: &str) -> String {
    let text = text.split("#[cfg(test)]").next().unwrap_or("");
    text.lines()
        .map(|l| match l.find("//") {
            Some(i) => &l[..i],
            None => l,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The top-level modules a piece of code names through `crate::`.
fn uses(code: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    let mut rest = code;
    while let Some(i) = rest.find("crate::") {
        rest = &rest[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            // `crate::{a::X, b, c::{..}}`: the first segment of each top-level item.
            let mut depth = 0;
            let mut item = String::new();
            for ch in group.chars() {
                match ch {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        found.insert(first_segment(&item));
                        item.clear();
                        continue;
                    }
                    _ => {}
                }
                if depth == 0 {
                    item.push(ch);
                }
            }
            found.insert(first_segment(&item));
        } else {
            found.insert(first_segment(rest));
        }
    }
    found.remove("");
    found
}

fn first_segment(path: &str) -> String {
    path.trim()
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .collect()
}

fn graph() -> BTreeMap<String, BTreeSet<String>> {
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    // The crates under `pipeline/` are checked as crates (below); what is still in the library's
    // own folder is checked module by module.
    for src in [common::repo().join("pipeline/src")] {
        let mut stack = vec![src.clone()];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).unwrap().flatten() {
                let path = entry.path();
                if path.is_dir() {
                    stack.push(path);
                    continue;
                }
                if path.extension().is_none_or(|e| e != "rs") {
                    continue;
                }
                let module = module_of(path.strip_prefix(&src).unwrap());
                if ["main", "cli", "lib"].contains(&module.as_str()) {
                    continue;
                }
                let text = std::fs::read_to_string(&path).unwrap();
                let deps = uses(&code(&text));
                let entry = graph.entry(module.clone()).or_default();
                entry.extend(deps.into_iter().filter(|d| *d != module));
            }
        }
    }
    graph
}

fn reachable(graph: &BTreeMap<String, BTreeSet<String>>, from: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut stack: Vec<String> = graph.get(from).into_iter().flatten().cloned().collect();
    while let Some(m) = stack.pop() {
        if seen.insert(m.clone()) {
            stack.extend(graph.get(&m).into_iter().flatten().cloned());
        }
    }
    seen
}

#[test]
fn the_reader_sees_grouped_and_plain_paths_but_not_comments() {
    let sample = "use crate::{motion::{A, B}, parts::PartSet, text};\n\
                  // crate::build is only mentioned here\n\
                  fn f() { crate::io::write(); }\n\
                  #[cfg(test)]\nmod tests { use crate::serve; }";
    assert_eq!(
        uses(&code(sample)),
        ["io", "motion", "parts", "text"]
            .map(String::from)
            .into_iter()
            .collect()
    );
}

#[test]
fn top_level_modules_have_no_mutual_dependency() {
    let graph = graph();
    assert!(graph.len() > 5, "read too few modules: {graph:?}");
    let mut cycles = Vec::new();
    for a in graph.keys() {
        let from_a = reachable(&graph, a);
        if from_a.contains(a) {
            let back: Vec<&String> = from_a
                .iter()
                .filter(|b| *b != a && reachable(&graph, b).contains(a))
                .collect();
            cycles.push(format!("{a} <-> {back:?}"));
        }
    }
    let listing: Vec<String> = graph.iter().map(|(m, d)| format!("{m}: {d:?}")).collect();
    assert!(
        cycles.is_empty(),
        "modules that reach themselves:\n{}\n\ngraph:\n{}",
        cycles.join("\n"),
        listing.join("\n")
    );
}

#[test]
fn data_flows_one_way() {
    let graph = graph();
    // Sources and stages never reach the runner or the sinks that come after them. The file
    // formats (`io`, `dataset`) are a crate below all of them: the config names the shards'
    // compression and the manifest records the config, so stages may use their types.
    for early in ["source", "stages", "config"] {
        let reach = reachable(&graph, early);
        for late in ["build", "export", "report", "serve"] {
            assert!(
                !reach.contains(late),
                "`{early}` reaches `{late}`: {graph:?}"
            );
        }
    }
}

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
    "motionforge",
];

/// Each crate's manifest under `pipeline/`: its package name, its internal (path) dependencies
/// and its other dependencies, as written.
fn crates() -> Vec<(String, std::path::PathBuf, Vec<String>, Vec<String>)> {
    let pipeline = common::repo().join("pipeline");
    let mut dirs = vec![pipeline.clone()];
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
