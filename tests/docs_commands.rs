//! Every fenced block of README.md and docs/getting-started.md is run, or checked for what it is,
//! and the outputs the pages show are compared with what the commands print.
//!
//! Each page runs in its own sandbox: a temporary folder holding a copy of the repository's
//! `fixtures/`, `schemas/` and `prompts/`, so the commands run as written from a repository root
//! (the demo really goes to `out/demo/`) and leave the checkout alone. How each block is treated
//! depends on its info string:
//!
//! - ` ```sh ` / ` ```bash `: every command runs in bash (`-euo pipefail`) from the sandbox's root.
//!   `motionforge` is the binary this test was built with (first on `PATH`), and
//!   `cargo run --release -- ARGS` is mapped to `motionforge ARGS`: the same program, without a
//!   nested cargo. Any other `cargo` command fails the test. `scripts/test.sh`, the README's test
//!   command, runs this very test: it is checked (CI runs it as written, it is executable, it sets
//!   up the Python environment and runs `cargo test --workspace`) rather than started again.
//! - ` ```python `: run with the tests' Python (`MOTIONFORGE_PYTHON`, from `scripts/test.sh`), from
//!   the sandbox's root, with Hugging Face's cache in the sandbox and its network off.
//! - ` ```text output `: the standard output of the block before it, which must match line for
//!   line (a build's wall time, `(1.3 s)`, is the one thing not compared).
//! - ` ```sh install `: the install commands (`cargo build --release`, `cargo install --path
//!   pipeline`), which would rebuild the whole crate in release or write to `~/.cargo/bin`: checked
//!   against the manifests instead (the workspace builds the package in `pipeline/`, whose binary
//!   is `motionforge`, and the page's Rust version is `rust-version`).
//! - ` ```sh serve `: `motionforge serve`, which runs until stopped: started in the background on a
//!   free port (the page's URL is checked to be `--bind`'s default instead), then asked for its
//!   browser page and the demo's clips over HTTP, then stopped.
//!
//! Any other block, or a block without an info string, fails the test, so a new one cannot go
//! unrun; every page's blocks are counted.

use crate::common;

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// A fenced block: its info string, the line of its opening fence, its text.
struct Block {
    info: String,
    line: usize,
    body: String,
}

fn blocks(markdown: &str) -> Vec<Block> {
    let mut blocks = Vec::new();
    let mut open: Option<Block> = None;
    for (index, line) in markdown.lines().enumerate() {
        let trimmed = line.trim();
        if let Some(info) = trimmed.strip_prefix("```") {
            match open.take() {
                Some(block) => blocks.push(block),
                None => {
                    open = Some(Block {
                        info: info.trim().to_string(),
                        line: index + 1,
                        body: String::new(),
                    })
                }
            }
            continue;
        }
        if let Some(block) = open.as_mut() {
            block.body.push_str(line);
            block.body.push('\n');
        }
    }
    assert!(open.is_none(), "a fenced block is never closed");
    blocks
}

/// The commands of a shell block: lines joined over trailing `\`, without blank and comment lines.
fn commands(body: &str) -> Vec<String> {
    let mut commands = Vec::new();
    let mut pending = String::new();
    for line in body.lines() {
        let trimmed = line.trim();
        if pending.is_empty() && (trimmed.is_empty() || trimmed.starts_with('#')) {
            continue;
        }
        if let Some(head) = trimmed.strip_suffix('\\') {
            pending.push_str(head);
            pending.push(' ');
            continue;
        }
        pending.push_str(trimmed);
        commands.push(std::mem::take(&mut pending));
    }
    commands
}

/// A command without its trailing comment.
fn without_comment(command: &str) -> &str {
    command.split(" # ").next().unwrap_or_default().trim()
}

/// The shell commands of every ```sh block, without their trailing comments.
fn fenced_commands(markdown: &str) -> Vec<String> {
    blocks(markdown)
        .iter()
        .filter(|b| b.info == "sh" || b.info == "bash")
        .flat_map(|b| commands(&b.body))
        .map(|c| without_comment(&c).to_string())
        .collect()
}

/// A temporary repository root for one page's commands.
struct Sandbox {
    _dir: tempfile::TempDir,
    root: PathBuf,
    bin: PathBuf,
}

fn sandbox() -> Sandbox {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("motionforge");
    for folder in ["fixtures", "schemas", "prompts"] {
        common::copy_dir(&common::repo().join(folder), &root.join(folder));
    }
    let bin = dir.path().join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_motionforge"), bin.join("motionforge")).unwrap();
    Sandbox {
        _dir: dir,
        root,
        bin,
    }
}

impl Sandbox {
    fn path(&self) -> std::ffi::OsString {
        let mut path = self.bin.clone().into_os_string();
        if let Some(rest) = std::env::var_os("PATH") {
            path.push(":");
            path.push(rest);
        }
        path
    }

    /// A bash command from the sandbox's root, with the test's binary first on PATH.
    fn shell(&self, command: &str) -> Command {
        let mut shell = Command::new("bash");
        shell
            .args(["-euo", "pipefail", "-c", command])
            .current_dir(&self.root)
            .env("PATH", self.path());
        shell
    }
}

/// What running a page did, by kind of block.
#[derive(Default, Debug)]
struct Tally {
    /// Blocks by how they were handled, and commands run or checked.
    counts: BTreeMap<&'static str, usize>,
    /// Blocks handled, whatever their kind.
    blocks: usize,
    /// Standard output of every command run, in order.
    outputs: Vec<(String, String)>,
}

impl Tally {
    fn add(&mut self, kind: &'static str) {
        *self.counts.entry(kind).or_default() += 1;
    }
}

/// `(1.3 s)` and `(12 s)` become `(T s)`: the one part of an output that differs run to run.
fn without_timings(text: &str) -> String {
    let timing = regex::Regex::new(r"\(\d+(\.\d+)? s\)").unwrap();
    text.lines()
        .map(|l| timing.replace_all(l.trim_end(), "(T s)").into_owned())
        .collect::<Vec<_>>()
        .join("\n")
        .trim_end()
        .to_string()
}

/// Runs or checks every block of a page, in a sandbox of its own, returned with what was done.
fn run_page(page: &str) -> (Tally, Sandbox) {
    let markdown = std::fs::read_to_string(common::repo().join(page)).unwrap();
    let sandbox = sandbox();
    let mut tally = Tally::default();
    // The standard output of the last block run, until an output block consumes it.
    let mut last: Option<String> = None;
    let all = blocks(&markdown);
    for block in &all {
        let at = format!("{page}:{}", block.line);
        tally.blocks += 1;
        match block.info.as_str() {
            "sh" | "bash" => {
                let mut out = String::new();
                for command in commands(&block.body) {
                    out.push_str(&run_shell(&sandbox, &command, &at, &mut tally));
                }
                tally.add("shell blocks run");
                last = Some(out);
            }
            "python" => {
                last = Some(run_python(&sandbox, &block.body, &at));
                tally.add("python blocks run");
            }
            "text output" => {
                let actual = last
                    .take()
                    .unwrap_or_else(|| panic!("{at}: an output block with no block run before it"));
                assert_eq!(
                    without_timings(&block.body),
                    without_timings(&actual),
                    "{at}: the page shows an output the commands before it no longer print"
                );
                tally.add("outputs compared");
            }
            "sh install" => {
                check_install(&markdown, &block.body, &at);
                tally.add("install blocks checked");
                last = None;
            }
            "sh serve" => {
                check_serve(&sandbox, &block.body, &at);
                tally.add("serve blocks run in the background");
                last = None;
            }
            other => panic!(
                "{at}: a ```{other} block, which tests/docs_commands.rs does not know how to run or check"
            ),
        }
    }
    // Every arm above either handled its block or failed the test.
    assert_eq!(
        tally.blocks,
        all.len(),
        "{page}: every block is run or checked"
    );
    eprintln!("{page}: {} blocks: {:?}", all.len(), tally.counts);
    (tally, sandbox)
}

/// Runs one shell command of a page; returns its standard output.
fn run_shell(sandbox: &Sandbox, command: &str, at: &str, tally: &mut Tally) -> String {
    let bare = without_comment(command);
    if bare == "scripts/test.sh" {
        check_test_command();
        tally.add("test command checked");
        return String::new();
    }
    let command = match command.strip_prefix("cargo run --release -- ") {
        Some(args) => format!("motionforge {args}"),
        None => command.to_string(),
    };
    assert!(
        !without_comment(&command)
            .split_whitespace()
            .any(|w| w == "cargo"),
        "{at}: `{command}` runs cargo, which this test does not run nested; map it or mark the block"
    );
    let out = sandbox.shell(&command).output().unwrap();
    assert!(
        out.status.success(),
        "{at}: `{command}` failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    tally.add("commands run");
    tally.outputs.push((command, stdout.clone()));
    stdout
}

fn run_python(sandbox: &Sandbox, body: &str, at: &str) -> String {
    let script = sandbox.root.join(".block.py");
    std::fs::write(&script, body).unwrap();
    let hf = sandbox.root.join(".hf-cache");
    let out = common::offline_python(&hf)
        .arg(&script)
        .current_dir(&sandbox.root)
        .output()
        .unwrap_or_else(|e| panic!("{:?}: {e}; {}", common::python(), common::PYTHON_SETUP));
    assert!(
        out.status.success(),
        "{at}: the Python block failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stderr),
        common::PYTHON_SETUP
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The test command runs this test: check that it is CI's and what it does, instead of recursing.
fn check_test_command() {
    let repo = common::repo();
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
}

fn toml_file(path: &Path) -> toml::Table {
    std::fs::read_to_string(path).unwrap().parse().unwrap()
}

/// The install block's commands, checked against the manifests they would build from.
fn check_install(page: &str, body: &str, at: &str) {
    let root = toml_file(&common::repo().join("Cargo.toml"));
    let package = toml_file(&common::repo().join("pipeline/cli/Cargo.toml"));
    let workspace = root["workspace"].as_table().unwrap();
    let members = |key: &str| -> Vec<String> {
        workspace[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m.as_str().unwrap().to_string())
            .collect()
    };
    let bins: Vec<&str> = package["bin"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["name"].as_str().unwrap())
        .collect();
    for command in commands(body) {
        match without_comment(&command) {
            "cargo build --release" => {
                // Built from the root, it builds the default member, pipeline/cli, whose binary
                // target/release/motionforge is the program this test runs in its debug build.
                assert!(members("default-members").contains(&"pipeline/cli".to_string()));
                assert!(bins.contains(&"motionforge"), "{at}: {bins:?}");
                assert!(command.contains("target/release/motionforge"), "{at}");
                assert!(
                    Path::new(env!("CARGO_BIN_EXE_motionforge")).ends_with("motionforge"),
                    "{at}"
                );
            }
            "cargo install --locked --path pipeline/cli" => {
                // --locked: the versions of Cargo.lock, which is committed.
                assert!(common::repo().join("Cargo.lock").is_file(), "{at}");
                assert!(members("members").contains(&"pipeline/cli".to_string()));
                assert_eq!(package["package"]["name"].as_str(), Some("motionforge"));
                assert!(bins.contains(&"motionforge"), "{at}: {bins:?}");
            }
            other => panic!("{at}: install command `{other}` that this test does not check"),
        }
    }
    let version = workspace["package"]["rust-version"].as_str().unwrap();
    assert!(
        page.contains(&format!("Rust toolchain, {version} or newer")),
        "the page's Rust version is not rust-version {version}"
    );
}

/// Status and body of `GET path` from a local server, over HTTP/1.0 (no chunked bodies).
fn http_get(port: u16, path: &str) -> std::io::Result<(u16, String)> {
    let mut stream = std::net::TcpStream::connect(("127.0.0.1", port))?;
    stream.set_read_timeout(Some(Duration::from_secs(30)))?;
    write!(
        stream,
        "GET {path} HTTP/1.0\r\nHost: 127.0.0.1:{port}\r\n\r\n"
    )?;
    let mut response = String::new();
    stream.read_to_string(&mut response)?;
    let (head, body) = response.split_once("\r\n\r\n").unwrap_or((&response, ""));
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    Ok((status, body.to_string()))
}

/// `motionforge serve` in the background on a free port, asked for the browser and the clips.
fn check_serve(sandbox: &Sandbox, body: &str, at: &str) {
    let commands = commands(body);
    assert_eq!(commands.len(), 1, "{at}: one serve command");
    let command = &commands[0];
    let bare = without_comment(command);
    assert!(bare.contains("motionforge serve"), "{at}: {command}");
    // The page sends the reader to --bind's default address.
    let help =
        common::run_ok(Command::new(env!("CARGO_BIN_EXE_motionforge")).args(["serve", "--help"]));
    let help = String::from_utf8(help.stdout).unwrap();
    let default = help
        .split_once("--bind")
        .and_then(|(_, rest)| rest.split_once("[default: "))
        .and_then(|(_, rest)| rest.split_once(']'))
        .map(|(d, _)| d.to_string())
        .expect("serve --help gives --bind's default");
    assert!(
        command.contains(&format!("http://{default}/")),
        "{at}: the page's URL is not the default address {default}"
    );
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut server = sandbox.shell(&format!("{bare} --bind 127.0.0.1:{port}"));
    std::os::unix::process::CommandExt::process_group(&mut server, 0);
    let mut child = server
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if let Ok((200, _)) = http_get(port, "/health") {
                break;
            }
            if let Some(status) = child.try_wait().unwrap() {
                panic!("{at}: the service stopped ({status}) before answering");
            }
            assert!(
                Instant::now() < deadline,
                "{at}: the service never answered"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
        let (status, page) = http_get(port, "/").unwrap();
        assert_eq!(status, 200, "{at}");
        assert!(page.to_lowercase().contains("<html"), "{at}: {page}");
        // The dataset the page built above, seen through the browser's API.
        let (status, clips) = http_get(port, "/datasets/demo/clips?limit=1").unwrap();
        assert_eq!(status, 200, "{at}: {clips}");
        let clips: serde_json::Value = serde_json::from_str(&clips).unwrap();
        assert_eq!(clips["total"], 24, "{at}: {clips}");
    }));
    // Stop the whole group: bash and the service it started.
    let _ = Command::new("kill")
        .args(["-TERM", "--", &format!("-{}", child.id())])
        .status();
    let status = child.wait().unwrap();
    if let Err(panic) = outcome {
        let mut stderr = String::new();
        if let Some(mut err) = child.stderr.take() {
            let _ = err.read_to_string(&mut stderr);
        }
        eprintln!("serve ({status}) said:\n{stderr}");
        std::panic::resume_unwind(panic);
    }
}

#[test]
fn every_readme_command_runs() {
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    assert_eq!(
        fenced_commands(&readme),
        [
            "cargo run --release -- build --config fixtures/demo.toml",
            "scripts/test.sh"
        ],
        "the README opens with its two commands"
    );
    let (tally, sandbox) = run_page("README.md");
    assert_eq!(tally.counts.get("test command checked"), Some(&1));
    let (command, summary) = &tally.outputs[0];
    assert_eq!(
        without_comment(command),
        "motionforge build --config fixtures/demo.toml"
    );
    assert!(summary.contains("9 captures -> 24 clips"), "{summary}");
    // "builds the demo dataset into out/demo/": its manifest and shards are there.
    let dataset = sandbox.root.join("out/demo");
    assert!(dataset.join("manifest.json").is_file());
    assert_eq!(common::shards(&dataset).len(), 3);
}

#[test]
fn every_getting_started_command_runs() {
    let (tally, _sandbox) = run_page("docs/getting-started.md");
    for kind in [
        "commands run",
        "python blocks run",
        "outputs compared",
        "install blocks checked",
        "serve blocks run in the background",
    ] {
        assert!(tally.counts.get(kind).is_some_and(|&n| n > 0), "{kind}");
    }
    let build = tally
        .outputs
        .iter()
        .find(|(c, _)| c.starts_with("motionforge build --config fixtures/demo.toml"))
        .expect("the page builds the demo");
    assert!(build.1.contains("9 captures -> 24 clips"), "{}", build.1);
}

#[test]
fn the_readme_commands_are_documented() {
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let [build, test] = &fenced_commands(&readme)[..] else {
        panic!("two README commands")
    };
    let started = std::fs::read_to_string(common::repo().join("docs/getting-started.md")).unwrap();
    assert!(fenced_commands(&started).contains(build));
    let reference = std::fs::read_to_string(common::repo().join("docs/reference.md")).unwrap();
    let (_, section) = reference
        .split_once("## Running the tests")
        .expect("the reference has the section");
    let section = section.split("\n## ").next().unwrap();
    assert!(fenced_commands(section).contains(test), "{section}");
}

/// The subcommands `--help` lists (`export humanml3d` for a command with subcommands of its own).
fn cli_commands() -> Vec<String> {
    fn listed(args: &[&str]) -> Vec<String> {
        let out = common::run_ok(
            Command::new(env!("CARGO_BIN_EXE_motionforge"))
                .args(args)
                .arg("--help"),
        );
        let help = String::from_utf8(out.stdout).unwrap();
        let Some((_, list)) = help.split_once("Commands:\n") else {
            return Vec::new();
        };
        list.lines()
            .take_while(|l| !l.trim().is_empty())
            .filter(|l| l.starts_with("  ") && !l.starts_with("   "))
            .filter_map(|l| l.split_whitespace().next())
            .filter(|c| *c != "help")
            .map(str::to_string)
            .collect()
    }
    let mut all = Vec::new();
    for command in listed(&[]) {
        let subcommands = listed(&[&command]);
        if subcommands.is_empty() {
            all.push(command);
        } else {
            all.extend(subcommands.iter().map(|s| format!("{command} {s}")));
        }
    }
    all
}

#[test]
fn the_readme_table_and_the_reference_cover_every_command() {
    let commands = cli_commands();
    assert!(commands.len() > 15, "{commands:?}");
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let reference = std::fs::read_to_string(common::repo().join("docs/reference.md")).unwrap();
    let rows: Vec<&str> = readme
        .lines()
        .filter_map(|l| l.strip_prefix("| `"))
        .filter_map(|l| l.split('`').next())
        .collect();
    for command in &commands {
        assert!(
            rows.iter()
                .any(|r| r == command || r.starts_with(&format!("{command} "))),
            "README's command table has no row for `{command}`"
        );
        assert!(
            reference
                .lines()
                .any(|l| l.starts_with("### `") && l.contains(&format!("`{command}`"))),
            "docs/reference.md has no section for `{command}`"
        );
    }
    for row in rows.iter().filter(|r| !r.is_empty()) {
        let name: String = row
            .split_whitespace()
            .take_while(|w| !w.starts_with('<') && !w.starts_with('['))
            .collect::<Vec<_>>()
            .join(" ");
        assert!(
            commands.contains(&name),
            "README's command table lists `{name}`, which `motionforge --help` does not"
        );
    }
}

/// GitHub's anchor for a heading: lowercase, punctuation dropped, spaces as hyphens.
fn anchor(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | ' '))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

#[test]
fn the_pages_files_and_anchors_exist() {
    let path = regex::Regex::new(
        r"`((?:docs|schemas|prompts|scripts|fixtures|tests|tools|pipeline)/[A-Za-z0-9_./-]+)`",
    )
    .unwrap();
    let link = regex::Regex::new(r"\]\(#([^)]+)\)").unwrap();
    for page in ["README.md", "docs/getting-started.md", "docs/reference.md"] {
        let markdown = std::fs::read_to_string(common::repo().join(page)).unwrap();
        for found in path.captures_iter(&markdown) {
            let file = &found[1];
            assert!(
                common::repo().join(file).exists(),
                "{page} names `{file}`, which does not exist"
            );
        }
        let mut in_code = false;
        let mut anchors = Vec::new();
        for line in markdown.lines() {
            if line.trim_start().starts_with("```") {
                in_code = !in_code;
            } else if !in_code && line.starts_with('#') {
                anchors.push(anchor(line.trim_start_matches('#')));
            }
        }
        for found in link.captures_iter(&markdown) {
            assert!(
                anchors.contains(&found[1].to_string()),
                "{page} links to #{}, which no heading makes",
                &found[1]
            );
        }
    }
}

/// The reference quotes some commands' `--help` in full ("`--help` prints:"): the quotes are what
/// the binary prints.
#[test]
fn the_references_help_quotes_are_the_help() {
    let reference = std::fs::read_to_string(common::repo().join("docs/reference.md")).unwrap();
    let mut command: Option<String> = None;
    let mut quoted = 0;
    let mut lines = reference.lines();
    while let Some(line) = lines.next() {
        if let Some(heading) = line.strip_prefix("### `") {
            command = heading.split('`').next().map(str::to_string);
        }
        if !line.trim_end().ends_with("`--help` prints:") {
            continue;
        }
        let command = command.clone().expect("a quote under a command's heading");
        assert_eq!(lines.next().map(str::trim), Some(""));
        assert_eq!(lines.next().map(str::trim), Some("```"));
        let quote: Vec<&str> = lines.by_ref().take_while(|l| l.trim() != "```").collect();
        let out = common::run_ok(
            Command::new(env!("CARGO_BIN_EXE_motionforge"))
                .args(command.split_whitespace())
                .arg("--help"),
        );
        let help = String::from_utf8(out.stdout).unwrap();
        assert_eq!(
            without_timings(&quote.join("\n")),
            without_timings(&help),
            "docs/reference.md quotes `motionforge {command} --help`, which now prints otherwise"
        );
        quoted += 1;
    }
    assert!(quoted >= 2, "the reference quotes {quoted} help texts");
}
