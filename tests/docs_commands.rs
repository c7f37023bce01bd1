//! Every fenced shell command in README.md runs, or is checked for what it is: the README's demo
//! build runs with the test's own binary (into a temporary folder instead of `out/`), and the test
//! command (`scripts/test.sh`, which runs this very test) is checked to be what `.ci/run` runs
//! rather than started again. A command this test does not know fails it, so a new one cannot go
//! unrun.

mod common;

use std::path::Path;
use std::process::Command;

/// The shell commands of every ```sh block, without their trailing comments.
fn fenced_commands(markdown: &str) -> Vec<String> {
    let mut commands = Vec::new();
    let mut in_block = false;
    for line in markdown.lines() {
        let trimmed = line.trim();
        if let Some(info) = trimmed.strip_prefix("```") {
            in_block = !in_block && (info == "sh" || info == "bash");
            continue;
        }
        if !in_block || trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let command = trimmed.split(" # ").next().unwrap_or_default().trim();
        commands.push(command.to_string());
    }
    commands
}

fn run_command(command: &str, scratch: &Path) {
    let repo = common::repo();
    if let Some(args) = command.strip_prefix("cargo run --release -- ") {
        // The same program as `cargo run --release` builds, without a nested cargo; the dataset
        // goes to a temporary folder so the test leaves out/ alone.
        let args: Vec<&str> = args.split_whitespace().collect();
        let out = common::run_ok(
            Command::new(env!("CARGO_BIN_EXE_motionforge"))
                .args(&args)
                .arg("--output")
                .arg(scratch)
                .current_dir(&repo),
        );
        if args.first() == Some(&"build") {
            // "builds the demo dataset into out/demo/": its manifest and shards are there.
            let dataset = scratch.join("demo");
            assert!(dataset.join("manifest.json").is_file(), "{command}");
            assert_eq!(common::shards(&dataset).len(), 3, "{command}");
            let summary = String::from_utf8_lossy(&out.stdout);
            assert!(summary.contains("9 captures -> 24 clips"), "{summary}");
        }
    } else if command == "scripts/test.sh" {
        // The test command runs this test: check it is CI's, and exists, instead of recursing.
        let ci = std::fs::read_to_string(repo.join(".ci/run")).unwrap();
        assert!(
            ci.lines().any(|l| l.trim() == "scripts/test.sh"),
            ".ci/run must run the README's test command as written"
        );
        let script = repo.join("scripts/test.sh");
        let mode = std::fs::metadata(&script).unwrap();
        assert!(
            std::os::unix::fs::PermissionsExt::mode(&mode.permissions()) & 0o111 != 0,
            "{} must be executable",
            script.display()
        );
        let text = std::fs::read_to_string(&script).unwrap();
        assert!(text.contains("scripts/python-env.sh") && text.contains("cargo test --workspace"));
    } else {
        panic!("README runs `{command}`, which tests/docs_commands.rs does not know how to run");
    }
}

#[test]
fn every_readme_command_runs() {
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let commands = fenced_commands(&readme);
    assert_eq!(
        commands,
        [
            "cargo run --release -- build --config fixtures/demo.toml",
            "scripts/test.sh"
        ],
        "the README opens with its two commands"
    );
    let scratch = tempfile::tempdir().unwrap();
    for command in &commands {
        run_command(command, scratch.path());
    }
}

#[test]
fn the_user_guides_readme_commands_are_the_readmes() {
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let guide = std::fs::read_to_string(common::repo().join("docs/user-guide.md")).unwrap();
    let (_, section) = guide
        .split_once("## The two README commands")
        .expect("the guide has the section");
    let block: String = section
        .split_once("```sh\n")
        .and_then(|(_, rest)| rest.split_once("```"))
        .map(|(b, _)| format!("```sh\n{b}```"))
        .expect("a sh block");
    assert_eq!(fenced_commands(&block), fenced_commands(&readme));
}
