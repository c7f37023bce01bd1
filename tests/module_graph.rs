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

/// Every source folder of the workspace: `pipeline/src` and each crate's `pipeline/<crate>/src`.
/// Module names are unique across crates, so a `crate::motion` path names the same module
/// wherever the module lives.
fn source_dirs() -> Vec<std::path::PathBuf> {
    let pipeline = common::repo().join("pipeline");
    let mut dirs = vec![pipeline.join("src")];
    for entry in std::fs::read_dir(&pipeline).unwrap().flatten() {
        let src = entry.path().join("src");
        if src.is_dir() {
            dirs.push(src);
        }
    }
    dirs
}

fn graph() -> BTreeMap<String, BTreeSet<String>> {
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for src in source_dirs() {
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
    assert!(graph.len() > 10, "read too few modules: {graph:?}");
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
fn the_leaf_module_depends_on_nothing_and_data_flows_one_way() {
    let graph = graph();
    assert_eq!(graph.get("base"), Some(&BTreeSet::new()), "{graph:?}");
    // Sources and stages never reach the runner or the sinks that come after them.
    for early in [
        "annotate", "source", "stages", "motion", "parts", "config", "llm",
    ] {
        let reach = reachable(&graph, early);
        for late in ["build", "export", "io", "report", "serve"] {
            assert!(
                !reach.contains(late),
                "`{early}` reaches `{late}`: {graph:?}"
            );
        }
    }
}
