//! Every fenced block of README.md, docs/getting-started.md, docs/reference.md and docs/service.md
//! is run, or checked for what it is, and the outputs the pages show are compared with what the
//! commands print.
//!
//! Each page runs in its own sandbox: a temporary folder holding a copy of the repository's
//! `fixtures/`, `schemas/`, `prompts/` and `docs/examples/`, with `../shared` beside it (a link to
//! the real one), so the commands run as written from a repository root (the demo really goes to
//! `out/demo/`) and leave the checkout alone. How each block is treated depends on its info string:
//!
//! - ` ```sh ` / ` ```bash `: every command runs in bash (`-euo pipefail`) from the sandbox's root.
//!   `motionforge` is the binary this test was built with (first on `PATH`), and
//!   `cargo run --release -- ARGS` is mapped to `motionforge ARGS`: the same program, without a
//!   nested cargo. Any other `cargo` command fails the test. `scripts/test.sh [ARGS]`, the README's
//!   test command, runs this very test: it is checked (CI runs it as written, it is executable, it
//!   sets up the Python environment and runs `cargo test --workspace`, a `--test` binary and module
//!   it names exist) rather than started again.
//! - ` ```python `: run with the tests' Python (`MOTIONFORGE_PYTHON`, from `scripts/test.sh`), from
//!   the sandbox's root, with Hugging Face's cache in the sandbox and its network off. ` ```sql `:
//!   the query run by DuckDB in that Python.
//! - ` ```text output `: the standard output of the block before it, which must match line for
//!   line (volatile parts aside, below; a line `...` stands for any lines, `...` in a line for any
//!   text).
//! - ` ```console `: a transcript: each `$ ` line runs (standard error joined to standard output)
//!   and what follows it is compared as for `text output`; a command whose output starts with
//!   `error:` must fail, any other must succeed. `console llm-stub=ADDR` runs it while a stub LLM
//!   server answers `GET /v1/models` in place of the page's `ADDR` (a port of its own, put into
//!   the files the page wrote and taken out of the output again); `console llm-dead=ADDR` with
//!   nothing listening there.
//! - `pending=NAME` after `text output` or `console`: the page states what the program should do
//!   and does not yet (a program bug, not a doc error). The block still runs and is compared; it
//!   must still differ, so the marker goes once the program is fixed.
//! - ` ```sh install `: the install commands (`cargo build --release`, `cargo install --locked
//!   --path pipeline/cli`, the clone), which would rebuild the whole crate in release or write to
//!   `~/.cargo/bin`: checked against the manifests instead (the workspace builds the package in
//!   `pipeline/cli`, whose binary is `motionforge`, and the page's Rust version is `rust-version`).
//! - ` ```sh serve `: `motionforge serve`, which runs until stopped: started in the background on a
//!   free port (the page's address is checked to be `--bind`'s default instead), asked for its
//!   browser page and, when the demo is built, its clips, and kept running for the page's
//!   ` ```sh curl ` blocks (every `curl` line sent to it: answers are JSON without `error`, a
//!   comment `# {...}` is compared with the answer, `# poll until "S"` repeats the call until the
//!   state is `S`) and ` ```json response GET PATH ` blocks (the JSON shown is compared with the
//!   answer: every field shown, volatile ones aside), until the page ends.
//! - ` ```sh synopsis `: a command's usage: the command exists and every option shown is in its
//!   `--help`. ` ```text help `: a command's `--help` quoted in full, compared with the binary's.
//! - ` ```toml `: a part of a config: it parses, and merged into `fixtures/demo.toml` it passes
//!   `config check` (a `[[sources]]` part: no key or type error). ` ```toml FILE `: the file the
//!   next blocks use, written into the sandbox. ` ```toml excerpt FILE `: every key shown has the
//!   value of the repository's `FILE`.
//! - ` ```text example ` and ` ```jsonl example `: messages from situations a sandbox cannot make
//!   (another host holding a lock, a full disk): every run of three or more plain words is in the
//!   program's source, and a `jsonl` line is a JSON object.
//! - ` ```text tree DIR `: the folder's top level is the tree's (an entry not on disk says it is
//!   `not in the demo`). ` ```csv excerpt FILE `: the file's header, and rows of its width.
//! - ` ```cron `, ` ```ini systemd `, ` ```sh system `: crontab lines (five time fields, and the
//!   `motionforge` command's options in its `--help`), unit files (sections and keys, the
//!   `ExecStart` options likewise), and `systemctl`/`journalctl` lines naming units the page
//!   defines.
//!
//! Volatile parts, never compared: a wall time (`(1.3 s)`, `in 0.4 s`, `in 3 ms`), a clock time
//! (`2026-11-21 08:13 UTC`, RFC 3339), and the JSON fields `timestamp`, `time`, `seconds`,
//! `requested`, `started`, `finished`, `wall_seconds`.
//!
//! Any other block, or a block without an info string, fails the test, so a new one cannot go
//! unrun; every page's blocks are counted.

use crate::common;

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// A fenced block: its info string, the line of its opening fence, its text, and the command of
/// the `### \`command\`` heading it is under.
struct Block {
    info: String,
    line: usize,
    body: String,
    heading: Option<String>,
    /// The opening fence's indentation (a block in a list item), not part of the text.
    indent: usize,
}

fn blocks(markdown: &str) -> Vec<Block> {
    let mut blocks = Vec::new();
    let mut open: Option<Block> = None;
    let mut heading = None;
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
                        heading: heading.clone(),
                        indent: line.len() - line.trim_start().len(),
                    })
                }
            }
            continue;
        }
        match open.as_mut() {
            Some(block) => {
                let indent = line.len() - line.trim_start().len();
                block.body.push_str(&line[indent.min(block.indent)..]);
                block.body.push('\n');
            }
            None if line.starts_with("### `") => {
                heading = line[5..].split('`').next().map(str::to_string);
            }
            None if line.starts_with('#') => heading = None,
            None => {}
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

/// A command's trailing comment, if any.
fn comment(command: &str) -> Option<&str> {
    command.split_once(" # ").map(|(_, c)| c.trim())
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
    for folder in ["fixtures", "schemas", "prompts", "docs/examples"] {
        common::copy_dir(&common::repo().join(folder), &root.join(folder));
    }
    // The pages name the shared data as `../shared/data`, from the repository root.
    let shared = common::shared_data();
    std::os::unix::fs::symlink(shared.parent().unwrap(), dir.path().join("shared")).unwrap();
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

    /// `motionforge ARGS` run from the sandbox's root; its standard output, failing on an error.
    fn motionforge(&self, args: &[&str]) -> String {
        let out = common::run_ok(
            Command::new(env!("CARGO_BIN_EXE_motionforge"))
                .args(args)
                .current_dir(&self.root),
        );
        String::from_utf8(out.stdout).unwrap()
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

/// A page being run: its sandbox, what was done, and what later blocks use.
struct PageRun {
    page: String,
    markdown: String,
    sandbox: Sandbox,
    tally: Tally,
    /// The standard output of the last block run, until an output block consumes it.
    last: Option<String>,
    /// The service a `sh serve` block started, until the page ends.
    server: Option<Server>,
    /// Variables the page exported, for the commands after.
    env: Vec<(String, String)>,
    /// Files written by `toml FILE` blocks.
    files: Vec<PathBuf>,
}

/// The volatile parts of a line (wall and clock times) replaced by placeholders.
fn without_timings(text: &str) -> String {
    static VOLATILE: OnceLock<Vec<(regex::Regex, &str)>> = OnceLock::new();
    let volatile = VOLATILE.get_or_init(|| {
        [
            (r"\(\d+(\.\d+)? s\)", "(T s)"),
            (r"\bin \d+(\.\d+)? s\b", "in T s"),
            (r"\bin \d+ ms\b", "in T ms"),
            (
                r"\d{4}-\d\d-\d\d[ T]\d\d:\d\d(:\d\d(\.\d+)?)?Z?( UTC)?",
                "<time>",
            ),
        ]
        .into_iter()
        .map(|(pattern, by)| (regex::Regex::new(pattern).unwrap(), by))
        .collect()
    });
    text.lines()
        .map(|l| {
            volatile
                .iter()
                .fold(l.trim_end().to_string(), |line, (re, by)| {
                    re.replace_all(&line, *by).into_owned()
                })
        })
        .collect::<Vec<_>>()
        .join("\n")
        .trim_end()
        .to_string()
}

/// JSON fields that differ run to run (times), never compared.
const VOLATILE_FIELDS: [&str; 7] = [
    "timestamp",
    "time",
    "seconds",
    "requested",
    "started",
    "finished",
    "wall_seconds",
];

/// Every field of `shown` is in `actual` with the same value (volatile fields and timings aside).
fn json_shown_in(shown: &serde_json::Value, actual: &serde_json::Value) -> bool {
    use serde_json::Value;
    match (shown, actual) {
        (Value::Object(shown), Value::Object(actual)) => shown.iter().all(|(key, value)| {
            VOLATILE_FIELDS.contains(&key.as_str())
                || actual.get(key).is_some_and(|a| json_shown_in(value, a))
        }),
        (Value::Array(shown), Value::Array(actual)) => {
            shown.len() == actual.len()
                && shown.iter().zip(actual).all(|(s, a)| json_shown_in(s, a))
        }
        (Value::String(shown), Value::String(actual)) => {
            without_timings(shown) == without_timings(actual)
        }
        _ => shown == actual,
    }
}

/// One shown line against one printed line: JSON objects field by field, `...` as any text.
fn line_matches(shown: &str, actual: &str) -> bool {
    if let (true, Ok(s), Ok(a)) = (
        shown.starts_with("{"),
        serde_json::from_str::<serde_json::Value>(shown),
        serde_json::from_str::<serde_json::Value>(actual),
    ) {
        return json_shown_in(&s, &a);
    }
    if !shown.contains("...") {
        return shown == actual;
    }
    let pattern: Vec<String> = shown.split("...").map(regex::escape).collect();
    regex::Regex::new(&format!("^{}$", pattern.join(".*")))
        .unwrap()
        .is_match(actual)
}

/// The lines a page shows against the lines printed; a shown line `...` stands for any lines.
fn lines_match(shown: &[&str], actual: &[&str]) -> bool {
    match shown.split_first() {
        None => actual.is_empty(),
        Some((first, rest)) if first.trim() == "..." => {
            (0..=actual.len()).any(|skip| lines_match(rest, &actual[skip..]))
        }
        Some((first, rest)) => actual
            .split_first()
            .is_some_and(|(a, more)| line_matches(first, a) && lines_match(rest, more)),
    }
}

/// Compares a shown output with a printed one; with `pending`, they must still differ.
fn compare_output(shown: &str, actual: &str, at: &str, pending: Option<&str>, tally: &mut Tally) {
    let shown = without_timings(shown);
    let actual = without_timings(actual);
    let matches = lines_match(
        &shown.lines().collect::<Vec<_>>(),
        &actual.lines().collect::<Vec<_>>(),
    );
    match pending {
        Some(name) => {
            assert!(
                !matches,
                "{at}: the program now prints what the page promises: remove `pending={name}`"
            );
            eprintln!(
                "{at}: pending={name}: the page promises\n{shown}\nthe program prints\n{actual}"
            );
            tally.add("pending program fixes run");
        }
        None if !matches => assert_eq!(
            shown, actual,
            "{at}: the page shows an output the commands no longer print"
        ),
        None => tally.add("outputs compared"),
    }
}

/// The `pending=NAME` word of an info string.
fn pending<'a>(words: &[&'a str]) -> Option<&'a str> {
    words.iter().find_map(|w| w.strip_prefix("pending="))
}

/// Runs or checks every block of a page, in a sandbox of its own, returned with what was done.
fn run_page(page: &str) -> (Tally, Sandbox) {
    let markdown = std::fs::read_to_string(common::repo().join(page)).unwrap();
    let mut run = PageRun {
        page: page.to_string(),
        markdown,
        sandbox: sandbox(),
        tally: Tally::default(),
        last: None,
        server: None,
        env: Vec::new(),
        files: Vec::new(),
    };
    let all = blocks(&run.markdown);
    let started = Instant::now();
    for block in &all {
        let block_started = Instant::now();
        run_block(&mut run, block);
        let seconds = block_started.elapsed().as_secs_f64();
        if seconds > 1.0 {
            // CI has 2 cores: the slow blocks are the ones to keep an eye on.
            eprintln!(
                "{page}:{}: {} block took {seconds:.1} s",
                block.line, block.info
            );
        }
    }
    // Every arm of run_block either handled its block or failed the test.
    assert_eq!(
        run.tally.blocks,
        all.len(),
        "{page}: every block is run or checked"
    );
    eprintln!(
        "{page}: {} blocks in {:.1} s: {:?}",
        all.len(),
        started.elapsed().as_secs_f64(),
        run.tally.counts
    );
    drop(run.server.take());
    (run.tally, run.sandbox)
}

/// Runs or checks one block as its info string says.
fn run_block(run: &mut PageRun, block: &Block) {
    let at = format!("{}:{}", run.page, block.line);
    let words: Vec<&str> = block.info.split_whitespace().collect();
    run.tally.blocks += 1;
    let mut output = None;
    match words.as_slice() {
        ["sh"] | ["bash"] => {
            let mut out = String::new();
            for command in commands(&block.body) {
                out.push_str(&run_shell(run, &command, &at));
            }
            run.tally.add("shell blocks run");
            output = Some(out);
        }
        ["python"] => {
            output = Some(run_python(&run.sandbox, &block.body, &at));
            run.tally.add("python blocks run");
        }
        ["sql"] => {
            let script = format!(
                "import duckdb\nprint(duckdb.sql({:?}).fetchall())\n",
                block.body
            );
            output = Some(run_python(&run.sandbox, &script, &at));
            run.tally.add("sql blocks run");
        }
        ["text", "output", rest @ ..] => {
            let actual = run
                .last
                .take()
                .unwrap_or_else(|| panic!("{at}: an output block with no block run before it"));
            compare_output(&block.body, &actual, &at, pending(rest), &mut run.tally);
        }
        ["console", rest @ ..] => run_console(run, block, &at, rest),
        ["text", "help"] => {
            check_help_quote(block, &at);
            run.tally.add("help quotes compared");
        }
        ["sh", "install"] => {
            check_install(&run.markdown, &block.body, &at);
            run.tally.add("install blocks checked");
        }
        ["sh", "serve"] => {
            drop(run.server.take());
            run.server = Some(start_serve(run, &block.body, &at));
            run.tally.add("serve blocks run in the background");
        }
        ["sh", "curl"] => run_curl(run, &block.body, &at),
        ["json", "response", "GET", path] => check_response(run, path, &block.body, &at),
        ["sh", "synopsis"] => {
            for command in commands(&block.body) {
                check_invocation(&command, &at);
            }
            run.tally.add("synopses checked against --help");
        }
        ["toml"] => check_toml_part(run, &block.body, &at),
        ["toml", "excerpt", file] => {
            check_toml_excerpt(&block.body, file, &at);
            run.tally.add("toml excerpts compared");
        }
        ["toml", file] => {
            let _: toml::Table = block.body.parse().unwrap_or_else(|e| panic!("{at}: {e}"));
            let path = run.sandbox.root.join(file);
            std::fs::write(&path, &block.body).unwrap();
            run.files.push(path);
            run.tally.add("toml files written");
        }
        ["text", "example"] | ["jsonl", "example"] => {
            if words[0] == "jsonl" {
                for line in block.body.lines() {
                    let value: serde_json::Value =
                        serde_json::from_str(line).unwrap_or_else(|e| panic!("{at}: {e}: {line}"));
                    assert!(value.is_object(), "{at}: {line}");
                }
            }
            check_wording(&block.body, &at);
            run.tally.add("examples' wording checked");
        }
        ["text", "tree", dir] => check_tree(&run.sandbox, dir, &block.body, &at),
        ["csv", "excerpt", file] => check_csv_excerpt(&run.sandbox, file, &block.body, &at),
        ["cron"] | ["ini", "systemd"] | ["sh", "system"] => {
            check_system(&run.markdown, words[0], &block.body, &at);
            run.tally.add("system files and commands checked");
        }
        _ => panic!(
            "{at}: a ```{} block, which tests/docs_commands.rs does not know how to run or check",
            block.info
        ),
    }
    run.last = output;
}

/// Runs one shell command of a page; returns its standard output.
fn run_shell(run: &mut PageRun, command: &str, at: &str) -> String {
    let bare = without_comment(command);
    if let Some(args) = bare.strip_prefix("scripts/test.sh") {
        check_test_command(args, at);
        run.tally.add("test command checked");
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
    let out = run
        .sandbox
        .shell(&command)
        .envs(run.env.iter().cloned())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{at}: `{command}` failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    run.tally.add("commands run");
    run.tally.outputs.push((command, stdout.clone()));
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

/// A transcript: `$ command` lines, each followed by what it prints.
fn run_console(run: &mut PageRun, block: &Block, at: &str, words: &[&str]) {
    let mut steps: Vec<(String, String)> = Vec::new();
    for line in block.body.lines() {
        match line.strip_prefix("$ ") {
            Some(command) => steps.push((command.to_string(), String::new())),
            None => {
                let (_, shown) = steps
                    .last_mut()
                    .unwrap_or_else(|| panic!("{at}: a transcript starts with `$ `"));
                shown.push_str(line);
                shown.push('\n');
            }
        }
    }
    // A stub LLM server, or a free port nothing listens on, in place of the page's address.
    let llm = words.iter().find_map(|w| {
        w.strip_prefix("llm-stub=")
            .map(|a| (a, true))
            .or_else(|| w.strip_prefix("llm-dead=").map(|a| (a, false)))
    });
    let stub = llm.map(|(page_address, answers)| {
        let stub = LlmStub::start(answers);
        for file in &run.files {
            let text = std::fs::read_to_string(file).unwrap();
            std::fs::write(file, text.replace(page_address, &stub.address)).unwrap();
        }
        (page_address, stub)
    });
    for (command, shown) in &steps {
        let bare = without_comment(command);
        let bare = match &stub {
            Some((page_address, stub)) => bare.replace(page_address, &stub.address),
            None => bare.to_string(),
        };
        let out = run
            .sandbox
            .shell(&format!("{{ {bare} ; }} 2>&1"))
            .envs(run.env.iter().cloned())
            .output()
            .unwrap();
        let mut printed = String::from_utf8(out.stdout).unwrap();
        if let Some((page_address, stub)) = &stub {
            printed = printed.replace(&stub.address, page_address);
        }
        let fails = shown.trim_start().starts_with("error:");
        assert_eq!(
            !out.status.success(),
            fails,
            "{at}: `{bare}` exited with {} and printed:\n{printed}",
            out.status
        );
        compare_output(shown, &printed, at, pending(words), &mut run.tally);
        run.tally.add("commands run");
    }
    if let Some((page_address, stub)) = stub {
        for file in &run.files {
            let text = std::fs::read_to_string(file).unwrap();
            std::fs::write(file, text.replace(&stub.address, page_address)).unwrap();
        }
    }
    run.tally.add("transcripts run");
}

/// The fake LLM server serving the page's model, or a free port nothing listens on.
struct LlmStub {
    address: String,
    _server: Option<common::llm::LlmServer>,
}

impl LlmStub {
    fn start(answers: bool) -> LlmStub {
        if !answers {
            return LlmStub {
                address: common::llm::dead_address(),
                _server: None,
            };
        }
        let server = common::llm::LlmServer::builder()
            .models(&["gemma-3-270m"])
            .start();
        LlmStub {
            address: server.address().to_string(),
            _server: Some(server),
        }
    }
}

/// The test command runs this test: check that it is CI's and what it does, instead of recursing.
fn check_test_command(args: &str, at: &str) {
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
    assert!(
        text.contains("scripts/python-env.sh") && text.contains("cargo test --workspace \"$@\"")
    );
    // `--test BINARY MODULE::`: the test binary's hub declares that module.
    let args: Vec<&str> = args.split_whitespace().collect();
    if let ["--test", binary, rest @ ..] = args.as_slice() {
        let hub = std::fs::read_to_string(repo.join(format!("tests/{binary}.rs")))
            .unwrap_or_else(|e| panic!("{at}: no test binary `{binary}`: {e}"));
        for filter in rest {
            let module = filter.trim_end_matches("::");
            assert!(
                hub.contains(&format!("mod {module};")),
                "{at}: tests/{binary}.rs has no module `{module}`"
            );
        }
    } else {
        assert!(
            args.is_empty(),
            "{at}: test arguments {args:?} this test does not check"
        );
    }
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
            // The clone, into the folder the next line enters.
            "git clone <repository URL> motionforge" | "cd motionforge" => {}
            other => panic!("{at}: install command `{other}` that this test does not check"),
        }
    }
    let version = workspace["package"]["rust-version"].as_str().unwrap();
    assert!(
        page.contains(&format!("Rust toolchain, {version} or newer")),
        "the page's Rust version is not rust-version {version}"
    );
}

/// Status and body of a request to a local server, over HTTP/1.0 (no chunked bodies).
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

/// `motionforge serve` running in the background, stopped (with its builds) when dropped.
struct Server {
    child: std::process::Child,
    port: u16,
}

impl Drop for Server {
    fn drop(&mut self) {
        // Stop the whole group: bash and the service it started.
        let _ = Command::new("kill")
            .args(["-TERM", "--", &format!("-{}", self.child.id())])
            .status();
        let _ = self.child.wait();
    }
}

/// `--bind`'s default address, from `serve --help`.
fn default_bind() -> String {
    let help =
        common::run_ok(Command::new(env!("CARGO_BIN_EXE_motionforge")).args(["serve", "--help"]));
    let help = String::from_utf8(help.stdout).unwrap();
    help.split_once("--bind")
        .and_then(|(_, rest)| rest.split_once("[default: "))
        .and_then(|(_, rest)| rest.split_once(']'))
        .map(|(d, _)| d.to_string())
        .expect("serve --help gives --bind's default")
}

/// Starts the block's `motionforge serve` on a free port and asks it for the browser (and the
/// demo's clips when the demo is built); `export` lines before it set variables for the page.
fn start_serve(run: &mut PageRun, body: &str, at: &str) -> Server {
    let mut serve = None;
    for command in commands(body) {
        let bare = without_comment(&command);
        if let Some(assignment) = bare.strip_prefix("export ") {
            let (name, _) = assignment.split_once('=').expect("export NAME=VALUE");
            let value = run
                .sandbox
                .shell(&format!("{bare}; printf %s \"${name}\""))
                .output()
                .unwrap();
            let value = String::from_utf8(value.stdout).unwrap();
            assert!(!value.is_empty(), "{at}: {bare}");
            run.env.push((name.to_string(), value));
        } else {
            assert!(serve.is_none(), "{at}: one serve command");
            serve = Some(command);
        }
    }
    let command = serve.unwrap_or_else(|| panic!("{at}: no serve command"));
    let bare = without_comment(&command);
    assert!(bare.contains("motionforge serve"), "{at}: {command}");
    // The page sends the reader to --bind's default address.
    let default = default_bind();
    assert!(
        comment(&command).is_some_and(|c| c.contains(&default)),
        "{at}: the page's address is not the default address {default}"
    );
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut shell = run
        .sandbox
        .shell(&format!("{bare} --bind 127.0.0.1:{port}"));
    std::os::unix::process::CommandExt::process_group(&mut shell, 0);
    let child = shell
        .envs(run.env.iter().cloned())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut server = Server { child, port };
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        check_server_answers(&mut server, &run.sandbox, at)
    }));
    if let Err(panic) = outcome {
        let err = server.child.stderr.take();
        drop(server);
        let mut stderr = String::new();
        if let Some(mut err) = err {
            let _ = err.read_to_string(&mut stderr);
        }
        eprintln!("serve said:\n{stderr}");
        std::panic::resume_unwind(panic);
    }
    server
}

/// The service answers its health check, its browser page, and the built demo's clips.
fn check_server_answers(server: &mut Server, sandbox: &Sandbox, at: &str) {
    let port = server.port;
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if let Ok((200, _)) = http_get(port, "/health") {
            break;
        }
        if let Some(status) = server.child.try_wait().unwrap() {
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
    if sandbox.root.join("out/demo/manifest.json").is_file() {
        // The dataset the page built, seen through the browser's API as `clips --json` sees it.
        let listed: serde_json::Value =
            serde_json::from_str(&sandbox.motionforge(&["clips", "out/demo", "--json"])).unwrap();
        let (status, clips) = http_get(port, "/datasets/demo/clips?limit=1").unwrap();
        assert_eq!(status, 200, "{at}: {clips}");
        let clips: serde_json::Value = serde_json::from_str(&clips).unwrap();
        assert_eq!(
            clips["total"].as_u64(),
            listed.as_array().map(|a| a.len() as u64),
            "{at}: {clips}"
        );
    }
}

/// The page's `curl` lines, sent to the running service.
fn run_curl(run: &mut PageRun, body: &str, at: &str) {
    let port = run
        .server
        .as_ref()
        .unwrap_or_else(|| panic!("{at}: curl lines with no `sh serve` block before them"))
        .port;
    let default = default_bind();
    let mut prelude = String::new();
    let assignment = regex::Regex::new(r"^[A-Z_]+=").unwrap();
    for command in commands(body) {
        let bare = without_comment(&command);
        if !bare.starts_with("curl ") {
            // `NAME=value` lines the curl lines use.
            assert!(assignment.is_match(bare), "{at}: `{bare}` in a curl block");
            prelude.push_str(bare);
            prelude.push('\n');
            continue;
        }
        let local = bare
            .replace(
                &format!("localhost:{}", default.rsplit(':').next().unwrap()),
                &default,
            )
            .replace(&default, &format!("127.0.0.1:{port}"));
        let poll = comment(&command)
            .and_then(|c| c.strip_prefix("poll until \""))
            .and_then(|c| c.split('"').next());
        let deadline = Instant::now() + Duration::from_secs(120);
        let answer = loop {
            let out = run
                .sandbox
                .shell(&format!("{prelude}{local}"))
                .envs(run.env.iter().cloned())
                .output()
                .unwrap();
            assert!(out.status.success(), "{at}: `{local}` failed");
            let text = String::from_utf8(out.stdout).unwrap();
            let answer: serde_json::Value = serde_json::from_str(&text)
                .unwrap_or_else(|e| panic!("{at}: `{local}` answered {text}: {e}"));
            assert!(
                answer.get("error").is_none_or(|e| e.is_null()),
                "{at}: `{local}`: {answer}"
            );
            match poll {
                Some(state) if answer["state"] != state => {
                    assert!(
                        !matches!(answer["state"].as_str(), Some("failed" | "interrupted")),
                        "{at}: {answer}"
                    );
                    assert!(Instant::now() < deadline, "{at}: never {state}: {answer}");
                    std::thread::sleep(Duration::from_millis(200));
                }
                _ => break answer,
            }
        };
        if let Some(shown) = comment(&command).filter(|c| c.starts_with('{')) {
            let shown: serde_json::Value = serde_json::from_str(&shown.replace(", ...", ""))
                .unwrap_or_else(|e| panic!("{at}: the comment {shown}: {e}"));
            assert!(
                json_shown_in(&shown, &answer),
                "{at}: `{bare}` shows {shown}, the service answers {answer}"
            );
            run.tally.add("answers compared");
        }
        run.tally.add("curl lines sent");
    }
}

/// A JSON answer the page shows, against the running service's answer to `GET path`.
fn check_response(run: &mut PageRun, path: &str, body: &str, at: &str) {
    let port = run
        .server
        .as_ref()
        .unwrap_or_else(|| panic!("{at}: an answer with no `sh serve` block before it"))
        .port;
    let shown: serde_json::Value =
        serde_json::from_str(body).unwrap_or_else(|e| panic!("{at}: {e}"));
    let (status, answer) = http_get(port, path).unwrap();
    assert_eq!(status, 200, "{at}: {answer}");
    let answer: serde_json::Value = serde_json::from_str(&answer).unwrap();
    assert!(
        json_shown_in(&shown, &answer),
        "{at}: the page shows {shown}, GET {path} answers {answer}"
    );
    run.tally.add("answers compared");
}

/// The subcommands `--help` lists (`export humanml3d` for a command with subcommands of its own).
fn cli_commands() -> &'static [String] {
    static COMMANDS: OnceLock<Vec<String>> = OnceLock::new();
    COMMANDS.get_or_init(|| {
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
    })
}

/// A `motionforge` invocation in a usage line, a crontab or a unit file: the command exists and
/// every option shown is in its `--help`.
fn check_invocation(line: &str, at: &str) {
    let bare = without_comment(line);
    let words: Vec<&str> = bare.split_whitespace().collect();
    let start = (0..words.len())
        .position(|i| {
            // The binary, not a folder of that name (`cd /srv/motionforge`).
            let word = words[i];
            (word == "motionforge" || word.ends_with("/motionforge"))
                && (i == 0 || words[i - 1] != "cd")
        })
        .unwrap_or_else(|| panic!("{at}: `{bare}` does not run motionforge"));
    let mut rest: Vec<&str> = words[start + 1..]
        .iter()
        .copied()
        .take_while(|w| !matches!(*w, ">>" | ">" | "|" | "||" | "&&" | ";"))
        .collect();
    let globals: Vec<&str> = rest
        .iter()
        .copied()
        .take_while(|w| w.starts_with('-'))
        .collect();
    rest.drain(..globals.len());
    let command = cli_commands()
        .iter()
        .filter(|c| {
            let c: Vec<&str> = c.split_whitespace().collect();
            rest.starts_with(&c)
        })
        .max_by_key(|c| c.len())
        .unwrap_or_else(|| panic!("{at}: `{bare}` names no motionforge command"));
    let out = common::run_ok(
        Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .args(command.split_whitespace())
            .arg("--help"),
    );
    let help = String::from_utf8(out.stdout).unwrap();
    let option = regex::Regex::new(r"(?:^|[\s\[(|,])(--?[a-zA-Z][a-zA-Z0-9-]*)").unwrap();
    let options = globals.join(" ") + " " + &rest.join(" ");
    for found in option.captures_iter(&options) {
        let flag = &found[1];
        let listed = regex::Regex::new(&format!(
            r"(?m)(^|[\s,]){}([\s,=<.]|$)",
            regex::escape(flag)
        ))
        .unwrap();
        assert!(
            listed.is_match(&help),
            "{at}: `{bare}` uses {flag}, which `motionforge {command} --help` does not list"
        );
    }
}

/// A quote of a command's `--help`, under its `### \`command\`` heading.
fn check_help_quote(block: &Block, at: &str) {
    let command = block
        .heading
        .as_deref()
        .unwrap_or_else(|| panic!("{at}: a help quote under no command's heading"));
    let out = common::run_ok(
        Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .args(command.split_whitespace())
            .arg("--help"),
    );
    let help = String::from_utf8(out.stdout).unwrap();
    assert_eq!(
        without_timings(&block.body),
        without_timings(&help),
        "{at} quotes `motionforge {command} --help`, which now prints otherwise"
    );
}

/// A part of a config: it parses, and merged into the demo's config, `config check` takes it.
fn check_toml_part(run: &mut PageRun, body: &str, at: &str) {
    let part: toml::Table = body.parse().unwrap_or_else(|e| panic!("{at}: {e}"));
    let fixtures = run.sandbox.root.join("fixtures");
    let mut config = toml_file(&fixtures.join("demo.toml"));
    let sources = part.contains_key("sources");
    if sources {
        // Its captures are the reader's, not here: only the keys and their types are checked.
        config.remove("sources");
    }
    merge(&mut config, part);
    let file = fixtures.join(".block.toml");
    std::fs::write(&file, toml::to_string(&config).unwrap()).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["config", "check", "--config", "fixtures/.block.toml"])
        .current_dir(&run.sandbox.root)
        .output()
        .unwrap();
    std::fs::remove_file(&file).unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    if sources {
        for mistake in [
            "unknown field",
            "unknown variant",
            "invalid type",
            "missing field",
            "parse error",
        ] {
            assert!(!stderr.contains(mistake), "{at}: {stderr}");
        }
        run.tally.add("toml sources checked for keys and types");
    } else {
        assert!(
            out.status.success(),
            "{at}: config check refuses it: {stderr}"
        );
        run.tally.add("toml parts checked by config check");
    }
}

/// `part` merged into `config`, table by table.
fn merge(config: &mut toml::Table, part: toml::Table) {
    for (key, value) in part {
        match (config.get_mut(&key), value) {
            (Some(toml::Value::Table(into)), toml::Value::Table(from)) => merge(into, from),
            (_, value) => {
                config.insert(key, value);
            }
        }
    }
}

/// Every key shown has the repository file's value (an array of tables item by item).
fn check_toml_excerpt(body: &str, file: &str, at: &str) {
    fn shown_in(shown: &toml::Value, actual: &toml::Value) -> bool {
        match (shown, actual) {
            (toml::Value::Table(s), toml::Value::Table(a)) => s
                .iter()
                .all(|(k, v)| a.get(k).is_some_and(|av| shown_in(v, av))),
            (toml::Value::Array(s), toml::Value::Array(a)) if s.iter().all(|v| v.is_table()) => {
                s.len() <= a.len() && s.iter().zip(a).all(|(sv, av)| shown_in(sv, av))
            }
            _ => shown == actual,
        }
    }
    let shown: toml::Table = body.parse().unwrap_or_else(|e| panic!("{at}: {e}"));
    let actual = toml_file(&common::repo().join(file));
    assert!(
        shown_in(&toml::Value::Table(shown), &toml::Value::Table(actual)),
        "{at}: the excerpt differs from {file}"
    );
}

/// The program's source text, string continuations joined and spaces collapsed.
fn program_source() -> &'static str {
    static SOURCE: OnceLock<String> = OnceLock::new();
    SOURCE.get_or_init(|| {
        fn walk(dir: &Path, text: &mut String) {
            for entry in std::fs::read_dir(dir).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    walk(&path, text);
                } else if path.extension().is_some_and(|e| e == "rs") {
                    text.push_str(&std::fs::read_to_string(&path).unwrap());
                }
            }
        }
        let mut text = String::new();
        walk(&common::repo().join("pipeline"), &mut text);
        let continued = regex::Regex::new(r"\\\n\s*")
            .unwrap()
            .replace_all(&text, "");
        regex::Regex::new(r"\s+")
            .unwrap()
            .replace_all(&continued, " ")
            .into_owned()
    })
}

/// A phrase of the program's: in its source, or pieces of messages put together, each piece
/// next to a placeholder or at the start of a string (`is being built by {who}` and `"pid {}`).
fn is_wording(phrase: &str) -> bool {
    // What serde and the TOML parser say, quoted in the program's config errors.
    const LIBRARY_WORDING: [&str; 5] = [
        "parse error at line",
        "invalid type: string",
        "unknown field",
        "unknown variant",
        "unclosed table, expected",
    ];
    // `value`: the first word may be what a placeholder before it printed (`folder nothing does`).
    fn pieces(words: &[&str], source: &str, value: bool) -> bool {
        if words.is_empty() || source.contains(&words.join(" ")) {
            return true;
        }
        if value && pieces(&words[1..], source, false) {
            return true;
        }
        (1..words.len()).any(|cut| {
            let piece = words[..cut].join(" ");
            let before_placeholder = source.contains(&format!("{piece} {{"));
            (before_placeholder
                || [format!("\"{piece}\""), format!("}} {piece}")]
                    .iter()
                    .any(|p| source.contains(p.as_str())))
                && pieces(&words[cut..], source, before_placeholder)
        })
    }
    LIBRARY_WORDING.contains(&phrase)
        || pieces(
            &phrase.split(' ').collect::<Vec<_>>(),
            program_source(),
            false,
        )
}

/// Every run of three or more plain lowercase words of an example is in the program's source.
fn check_wording(text: &str, at: &str) {
    let plain = regex::Regex::new(r"^[a-z]+(['-][a-z]+)*[,;:]?$").unwrap();
    let mut phrases = 0;
    for line in text.lines() {
        let mut run: Vec<&str> = Vec::new();
        // `error: ` and `warning: ` are the binary's prefix to every message.
        let message = ["error: ", "warning: "]
            .iter()
            .find_map(|p| line.strip_prefix(p))
            .unwrap_or(line);
        let words = message.split_whitespace().chain(std::iter::once("|"));
        for word in words {
            if plain.is_match(word) {
                run.push(word);
                continue;
            }
            if run.len() >= 3 {
                let phrase = run.join(" ");
                let phrase = phrase.trim_end_matches([',', ';', ':']);
                assert!(
                    is_wording(phrase),
                    "{at}: \"{phrase}\" is not the program's wording:\n{line}"
                );
                phrases += 1;
            }
            run.clear();
        }
    }
    assert!(phrases > 0, "{at}: an example with nothing to check");
}

/// A tree of a folder: its top level, against the folder's.
fn check_tree(sandbox: &Sandbox, dir: &str, body: &str, at: &str) {
    let entry = regex::Regex::new(r"^[├└]── (\S+)").unwrap();
    let shown: Vec<(String, &str)> = body
        .lines()
        .filter_map(|l| {
            entry
                .captures(l)
                .map(|c| (c[1].trim_end_matches('/').to_string(), l))
        })
        .collect();
    let actual: Vec<String> = std::fs::read_dir(sandbox.root.join(dir))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    for name in &actual {
        assert!(
            shown.iter().any(|(s, _)| s == name),
            "{at}: {dir} holds {name}, which the tree does not show"
        );
    }
    for (name, line) in &shown {
        assert!(
            actual.contains(name) || line.contains("not in the demo"),
            "{at}: the tree shows {name}, which {dir} does not hold"
        );
    }
}

/// An excerpt of a CSV file the page wrote: its header, and rows as wide.
fn check_csv_excerpt(sandbox: &Sandbox, file: &str, body: &str, at: &str) {
    let written = std::fs::read_to_string(sandbox.root.join(file))
        .unwrap_or_else(|e| panic!("{at}: {file}: {e}"));
    let header = written.lines().next().unwrap();
    let mut lines = body.lines();
    assert_eq!(lines.next(), Some(header), "{at}: the header of {file}");
    let width = header.split(',').count();
    for line in lines.filter(|l| l.trim() != "...") {
        assert_eq!(line.split(',').count(), width, "{at}: {line}");
    }
}

/// Crontab lines, unit files and systemctl lines: their form, and the motionforge they run.
fn check_system(page: &str, kind: &str, body: &str, at: &str) {
    let time = regex::Regex::new(r"^[\d*/,-]+$").unwrap();
    for line in body.lines().map(str::trim) {
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        match kind {
            "cron" => {
                let fields: Vec<&str> = line.split_whitespace().collect();
                assert!(fields.len() > 5, "{at}: {line}");
                assert!(fields[..5].iter().all(|f| time.is_match(f)), "{at}: {line}");
                check_invocation(&fields[5..].join(" "), at);
            }
            "ini" if line.starts_with('[') => assert!(line.ends_with(']'), "{at}: {line}"),
            "ini" => {
                let (key, value) = line
                    .split_once('=')
                    .unwrap_or_else(|| panic!("{at}: `{line}` is not KEY=VALUE"));
                assert!(
                    key.chars().all(|c| c.is_ascii_alphanumeric()),
                    "{at}: {line}"
                );
                if key == "ExecStart" {
                    check_invocation(value, at);
                }
            }
            _ => {
                for part in without_comment(line).split("&&") {
                    let words: Vec<&str> = part.split_whitespace().collect();
                    let words = words.strip_prefix(&["sudo"][..]).unwrap_or(&words);
                    let units: Vec<&str> = match words {
                        ["systemctl", _verb, rest @ ..] => rest
                            .iter()
                            .copied()
                            .filter(|w| !w.starts_with('-'))
                            .collect(),
                        ["journalctl", rest @ ..] => rest
                            .windows(2)
                            .filter(|pair| pair[0] == "-u")
                            .map(|pair| pair[1])
                            .collect(),
                        _ => panic!("{at}: `{line}` is not a systemctl or journalctl line"),
                    };
                    // Every unit it names is one whose file the page gives.
                    for unit in units {
                        let file = if unit.contains('.') {
                            unit.to_string()
                        } else {
                            format!("{unit}.service")
                        };
                        assert!(
                            page.contains(&format!("/etc/systemd/system/{file}")),
                            "{at}: `{line}` names {file}, which the page does not define"
                        );
                    }
                }
            }
        }
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
    for command in commands {
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
    for page in [
        "README.md",
        "docs/getting-started.md",
        "docs/reference.md",
        "docs/service.md",
    ] {
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

/// The reference quotes some commands' `--help` in full (```text help blocks): the quotes are
/// what the binary prints.
#[test]
fn the_references_help_quotes_are_the_help() {
    let reference = std::fs::read_to_string(common::repo().join("docs/reference.md")).unwrap();
    let mut quoted = 0;
    for block in blocks(&reference).iter().filter(|b| b.info == "text help") {
        check_help_quote(block, &format!("docs/reference.md:{}", block.line));
        quoted += 1;
    }
    assert!(quoted >= 2, "the reference quotes {quoted} help texts");
}

#[test]
fn every_reference_block_runs_or_is_checked() {
    let (tally, sandbox) = run_page("docs/reference.md");
    for kind in [
        "commands run",
        "transcripts run",
        "outputs compared",
        "synopses checked against --help",
        "help quotes compared",
        "toml parts checked by config check",
        "toml excerpts compared",
        "examples' wording checked",
        "serve blocks run in the background",
        "python blocks run",
        "sql blocks run",
    ] {
        assert!(
            tally.counts.get(kind).is_some_and(|&n| n > 0),
            "{kind}: {:?}",
            tally.counts
        );
    }
    // `labels import` fills the cache of the dataset folder the reference names.
    assert!(
        sandbox
            .root
            .join("out/sinc-labels/llm-cache.jsonl")
            .is_file()
    );
}

#[test]
fn every_service_block_runs_or_is_checked() {
    let (tally, _sandbox) = run_page("docs/service.md");
    for kind in [
        "serve blocks run in the background",
        "curl lines sent",
        "answers compared",
        "toml parts checked by config check",
    ] {
        assert!(
            tally.counts.get(kind).is_some_and(|&n| n > 0),
            "{kind}: {:?}",
            tally.counts
        );
    }
}
