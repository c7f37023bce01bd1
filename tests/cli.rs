//! The command line: global flags (`-q`, `-v`, `--json`), stage progress (log lines and bars),
//! `config check`, `clean`, and the documented exit codes.

use crate::common;

use std::io;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::project::ConfigSpec;
use common::repo;
use indicatif::{ProgressDrawTarget, TermLike};
use motionforge::config::Config;
use motionforge::progress::Progress;
use motionforge::terminal::{BarProgress, LogOptions, LogProgress, MemoryWriter, subscriber};

const BIN: &str = env!("CARGO_BIN_EXE_motionforge");

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn run(args: &[&str], cwd: &Path) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

fn demo() -> String {
    repo().join("fixtures/demo.toml").display().to_string()
}

fn lines(s: &str) -> Vec<&str> {
    s.lines().filter(|l| !l.trim().is_empty()).collect()
}

// ---- flags -----------------------------------------------------------------------------------

#[test]
fn help_documents_the_exit_codes() {
    let out = run(&["--help"], &repo());
    assert!(out.status.success());
    let help = text(&out.stdout);
    for needle in [
        "Exit codes:",
        "0  success",
        "1  failure",
        "2  usage or config error",
        "3  build --strict",
        "--quiet",
        "--verbose",
        "--json",
    ] {
        assert!(
            help.contains(needle),
            "`{needle}` missing from --help:\n{help}"
        );
    }
}

#[test]
fn quiet_prints_nothing_json_prints_the_report_and_json_lines_and_default_prints_both_kinds() {
    let out = tempfile::tempdir().unwrap();
    let o = out.path().display().to_string();
    let quiet = run(
        &["-q", "build", "--config", &demo(), "--output", &o],
        &repo(),
    );
    assert!(quiet.status.success(), "{}", text(&quiet.stderr));
    assert_eq!(text(&quiet.stdout), "", "-q prints no summary");
    assert_eq!(
        text(&quiet.stderr),
        "",
        "-q prints no progress or info lines"
    );
    assert!(out.path().join("demo/manifest.json").is_file());

    // `--json` is global: after the subcommand, as it always was for `build`, or before it.
    for args in [
        vec!["build", "--json", "--config", &demo(), "--output", &o],
        vec!["--json", "build", "--config", &demo(), "--output", &o],
    ] {
        let json = run(&args, &repo());
        assert!(json.status.success(), "{}", text(&json.stderr));
        let report: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
        assert_eq!(report["clips"], 24);
        let logged: Vec<serde_json::Value> = lines(&text(&json.stderr))
            .iter()
            .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
            .collect();
        assert!(
            logged.iter().any(|v| v["level"] == "INFO"
                && v["message"]
                    .as_str()
                    .is_some_and(|m| m.starts_with("building demo into"))
                && v["dataset"] == "demo"),
            "{logged:?}"
        );
        assert!(logged.iter().all(|v| v["timestamp"].is_string()));
    }

    let plain = run(&["build", "--config", &demo(), "--output", &o], &repo());
    assert!(plain.status.success());
    assert!(text(&plain.stdout).contains("nothing changed since the last build"));
    let err = text(&plain.stderr);
    assert!(
        err.lines()
            .next()
            .is_some_and(|l| l.starts_with("building demo into")),
        "{err}"
    );
    assert!(
        err.lines().all(|l| !l.starts_with('{')),
        "plain, not JSON: {err}"
    );
}

/// Leaf commands under `prefix`, read from `--help`'s "Commands:" lists (hidden ones excluded).
fn leaf_commands(prefix: &[String]) -> Vec<Vec<String>> {
    let mut args = prefix.to_vec();
    args.push("--help".into());
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let help = text(&run(&args, &repo()).stdout);
    let Some((_, list)) = help.split_once("Commands:\n") else {
        return vec![prefix.to_vec()];
    };
    let names: Vec<String> = list
        .lines()
        .take_while(|l| l.starts_with("  "))
        // Two spaces start a command; deeper lines continue a wrapped description.
        .filter(|l| !l.starts_with("   "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|n| *n != "help")
        .map(str::to_string)
        .collect();
    assert!(!names.is_empty(), "{help}");
    let mut leaves = vec![prefix.to_vec()];
    for name in names {
        let mut sub = prefix.to_vec();
        sub.push(name);
        leaves.extend(leaf_commands(&sub));
    }
    leaves
}

#[test]
fn every_commands_help_ends_with_examples() {
    let commands = leaf_commands(&[]);
    assert!(commands.len() > 20, "{commands:?}");
    for command in commands {
        let mut args: Vec<&str> = command.iter().map(String::as_str).collect();
        args.push("--help");
        let help = text(&run(&args, &repo()).stdout);
        let (_, examples) = help
            .split_once("\nExamples:\n")
            .unwrap_or_else(|| panic!("`{}` has no examples:\n{help}", args.join(" ")));
        // The first example line, past any `# what this does` comment above it.
        let first = examples
            .lines()
            .map(str::trim_start)
            .find(|l| !l.starts_with('#'))
            .unwrap_or_default();
        assert!(
            first.starts_with("motionforge ")
                || first.contains("| motionforge ")
                || first.contains(" motionforge "),
            "`{}`: the examples run motionforge: {first}",
            args.join(" ")
        );
        // A copied line runs: an example is never wrapped by the help's width, only continued
        // with `\` (the exit codes follow the examples, after a blank line).
        let examples = examples.split("\n\n").next().unwrap_or_default();
        let mut continued = false;
        for line in examples.lines() {
            let l = line.trim_start();
            assert!(
                continued || l.starts_with('#') || l.contains("motionforge "),
                "`{}`: an example line that is neither a command nor continued with `\\`: {line:?}",
                args.join(" ")
            );
            continued = l.ends_with('\\');
        }
    }
}

#[test]
fn a_build_prints_one_summary_with_the_splits_and_why_stages_were_skipped() {
    let out = tempfile::tempdir().unwrap();
    let o = out.path().display().to_string();
    let first = run(&["build", "--config", &demo(), "--output", &o], &repo());
    assert!(first.status.success(), "{}", text(&first.stderr));
    let (summary, err) = (text(&first.stdout), text(&first.stderr));
    // Stage results once, on standard output; standard error says only what is being built.
    assert_eq!(lines(&err).len(), 1, "{err}");
    assert!(err.starts_with("building demo into"), "{err}");
    assert!(
        summary.contains("    ingest  ran 9 of 9 (0 reused)"),
        "{summary}"
    );
    assert!(
        summary.contains("splits: train 16, validation 2, test 6\n"),
        "{summary}"
    );
    // Every profile's normalisation source, CMU's from test (it has no train rows).
    assert!(
        summary.contains("normalisation bandai-namco: over train (")
            && summary.contains("normalisation cmu: over test ("),
        "{summary}"
    );
    assert!(
        summary.contains("paraphrase  skipped (no LLM configured)")
            && summary.contains("      plan  skipped (no LLM configured)"),
        "{summary}"
    );
    // --force reruns everything, the report too.
    let forced = run(
        &["build", "--config", &demo(), "--output", &o, "--force"],
        &repo(),
    );
    let summary = text(&forced.stdout);
    assert!(summary.contains("    report  ran 1 of 1"), "{summary}");
    assert!(!summary.contains("up to date"), "{summary}");
}

#[test]
fn quiet_and_verbose_together_are_a_usage_error() {
    let out = run(&["-q", "-v", "schema"], &repo());
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("cannot be used with"));
}

#[test]
fn errors_are_json_lines_with_json() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["--json", "build"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    let line: serde_json::Value = serde_json::from_str(text(&out.stderr).trim()).unwrap();
    assert_eq!(line["level"], "ERROR");
    assert_eq!(line["exit_code"], 2);
    assert!(
        line["message"]
            .as_str()
            .unwrap()
            .contains("no motionforge.toml")
    );
}

// ---- progress --------------------------------------------------------------------------------

fn stage_run(progress: &dyn Progress) {
    progress.stage_started("ingest", 10);
    for _ in 0..10 {
        progress.advanced("ingest", 1);
    }
    progress.stage_finished("ingest", 7, 3);
    progress.stage_started("compose", 0);
    progress.stage_finished("compose", 0, 5);
}

fn logged(options: LogOptions, f: impl FnOnce()) -> String {
    let memory = MemoryWriter::default();
    tracing::subscriber::with_default(subscriber(&options, memory.clone()), f);
    memory.text()
}

#[test]
fn log_progress_prints_one_line_per_finished_stage() {
    let out = logged(LogOptions::default(), || stage_run(&LogProgress::new()));
    let l = lines(&out);
    assert_eq!(l.len(), 2, "{out}");
    assert!(l[0].starts_with("ingest: ran 7, reused 3 in "), "{out}");
    assert!(l[0].ends_with(" s"), "{out}");
    assert!(l[1].starts_with("compose: up to date, 5 reused"), "{out}");
}

#[test]
fn verbose_progress_adds_starts_tenths_and_fields() {
    let out = logged(
        LogOptions {
            verbose: 1,
            ..LogOptions::default()
        },
        || stage_run(&LogProgress::new()),
    );
    assert!(
        out.contains("debug: ingest: started, 10 items (stage=\"ingest\", total=10)"),
        "{out}"
    );
    // Tenths 1..9 (the tenth tenth is the finish line).
    assert_eq!(out.matches("debug: ingest: ").count(), 1 + 9, "{out}");
    assert!(out.contains("ingest: ran 7, reused 3 in"), "{out}");
}

#[test]
fn json_progress_lines_carry_the_stage_counts() {
    let out = logged(
        LogOptions {
            json: true,
            ..LogOptions::default()
        },
        || stage_run(&LogProgress::new()),
    );
    let events: Vec<serde_json::Value> = lines(&out)
        .iter()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(events.len(), 2, "{out}");
    assert_eq!(events[0]["stage"], "ingest");
    assert_eq!(events[0]["ran"], 7);
    assert_eq!(events[0]["reused"], 3);
    assert_eq!(events[0]["level"], "INFO");
    assert_eq!(events[0]["target"], "motionforge::progress");
    assert!(events[0]["seconds"].is_f64());
}

#[test]
fn quiet_progress_shows_warnings_only() {
    let out = logged(
        LogOptions {
            quiet: true,
            ..LogOptions::default()
        },
        || {
            stage_run(&LogProgress::new());
            tracing::warn!("disk nearly full");
        },
    );
    assert_eq!(out, "warning: disk nearly full\n");
}

#[test]
fn bars_are_only_for_a_terminal_without_json_or_quiet() {
    let plain = LogOptions::default();
    assert!(plain.bars(true));
    assert!(!plain.bars(false));
    assert!(
        !LogOptions {
            json: true,
            ..plain
        }
        .bars(true)
    );
    assert!(
        !LogOptions {
            quiet: true,
            ..plain
        }
        .bars(true)
    );
}

/// A terminal in memory: what indicatif draws, line by line.
#[derive(Debug, Clone, Default)]
struct Screen(Arc<Mutex<Vec<String>>>);

impl Screen {
    fn text(&self) -> String {
        self.0.lock().unwrap().join("\n")
    }
}

impl TermLike for Screen {
    fn width(&self) -> u16 {
        120
    }
    fn move_cursor_up(&self, _: usize) -> io::Result<()> {
        Ok(())
    }
    fn move_cursor_down(&self, _: usize) -> io::Result<()> {
        Ok(())
    }
    fn move_cursor_right(&self, _: usize) -> io::Result<()> {
        Ok(())
    }
    fn move_cursor_left(&self, _: usize) -> io::Result<()> {
        Ok(())
    }
    fn write_line(&self, s: &str) -> io::Result<()> {
        self.0.lock().unwrap().push(s.to_string());
        Ok(())
    }
    fn write_str(&self, s: &str) -> io::Result<()> {
        self.0.lock().unwrap().push(s.to_string());
        Ok(())
    }
    fn clear_line(&self) -> io::Result<()> {
        Ok(())
    }
    fn flush(&self) -> io::Result<()> {
        Ok(())
    }
}

#[test]
fn bars_count_items_with_an_eta_and_disappear_when_the_stage_ends() {
    let screen = Screen::default();
    let bars =
        BarProgress::with_draw_target(ProgressDrawTarget::term_like(Box::new(screen.clone())));
    bars.stage_started("ingest", 9);
    bars.advanced("ingest", 3);
    assert_eq!(bars.position("ingest"), Some((3, Some(9))));
    // The steady tick redraws within a quarter of a second.
    std::thread::sleep(Duration::from_millis(600));
    let drawn = screen.text();
    assert!(
        drawn.contains("ingest [") && drawn.contains("3/9") && drawn.contains("ETA"),
        "{drawn}"
    );
    bars.stage_started("compose", 0);
    std::thread::sleep(Duration::from_millis(600));
    assert!(screen.text().contains("compose"), "{}", screen.text());
    bars.stage_finished("ingest", 9, 0);
    bars.stage_finished("compose", 0, 1);
    assert_eq!(bars.position("ingest"), None);
    assert_eq!(bars.position("compose"), None);
}

/// An LLM stage: 5 requests, 2 of them failing.
fn request_run(progress: &dyn Progress) {
    progress.requests_started("label", 5);
    for i in 0..5 {
        // As the client reports a failed request: the failure, then the count.
        if i % 2 == 1 {
            progress.failed("label", 1);
        }
        progress.advanced("label", 1);
        // Requests take time; the rate and ETA need some.
        std::thread::sleep(Duration::from_millis(20));
    }
    progress.stage_finished("label", 5, 0);
}

#[test]
fn llm_stages_log_requests_rate_errors_and_eta() {
    let out = logged(LogOptions::default(), || request_run(&LogProgress::new()));
    let l = lines(&out);
    assert_eq!(l[0], "label: sending 5 LLM requests", "{out}");
    // A line per tenth crossed (every request here), the last one being the finish line.
    assert_eq!(l.len(), 1 + 4 + 1, "{out}");
    assert!(
        l[2].starts_with("label: 2 of 5 requests, ") && l[2].contains("/s, 1 error, ETA "),
        "{out}"
    );
    assert!(
        l[4].contains("4 of 5 requests") && l[4].contains("2 errors"),
        "{out}"
    );
    assert!(l[5].starts_with("label: ran 5, reused 0 in "), "{out}");
}

#[test]
fn llm_stage_bars_show_requests_rate_errors_and_eta() {
    let screen = Screen::default();
    let bars =
        BarProgress::with_draw_target(ProgressDrawTarget::term_like(Box::new(screen.clone())));
    bars.requests_started("label", 4);
    bars.advanced("label", 1);
    bars.failed("label", 1);
    bars.advanced("label", 1);
    std::thread::sleep(Duration::from_millis(600));
    let drawn = screen.text();
    assert!(
        drawn.contains("label [")
            && drawn.contains("2/4 requests")
            && drawn.contains("/s")
            && drawn.contains("1 error,")
            && drawn.contains("ETA"),
        "{drawn}"
    );
    bars.stage_finished("label", 4, 0);
    assert_eq!(bars.position("label"), None);
}

// ---- config check ----------------------------------------------------------------------------

#[test]
fn config_check_accepts_the_demo_with_a_one_line_summary() {
    let out = run(&["config", "check", "--config", &demo()], &repo());
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert_eq!(lines(&stdout).len(), 1, "{stdout}");
    assert!(
        stdout.contains(": OK: dataset `demo`")
            && stdout.contains("2 sources with 9 captures")
            && stdout.contains("30 fps")
            && stdout.contains("seed 42"),
        "{stdout}"
    );
}

const BAD: &str = r#"[dataset]
name = "x"
output = "out"
fps = 0

[splits]
ratios = { train = 0.8, val = 0.3 }

[[sources]]
name = "s"
captures = ["missing/*.bvh"]
profile = "nosuch"
[sources.labels]
kind = "filename"
pattern = "{a}"
action = "{a}"
text = "{a}"
"#;

#[test]
fn config_check_lists_every_problem_with_file_line_key_value_and_expectation() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bad.toml"), BAD).unwrap();
    let out = run(&["config", "check", "-c", "bad.toml"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    for needle in [
        "config bad.toml has 4 problems:",
        "bad.toml:4: dataset.fps: 0: expected a frame rate above 0",
        "bad.toml:7: splits.ratios: { train = 0.8, val = 0.3 }: expected shares that sum to 1 (they sum to 1.1)",
        "bad.toml:11: sources[0].captures[0]: \"missing/*.bvh\": expected a pattern that matches capture files",
        "folder missing does not exist",
        "bad.toml:12: sources[0].profile: \"nosuch\": expected a bundled profile",
    ] {
        assert!(err.contains(needle), "`{needle}` missing:\n{err}");
    }

    let json = run(&["config", "check", "-c", "bad.toml", "--json"], dir.path());
    assert_eq!(json.status.code(), Some(2));
    let v: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    assert_eq!(v["ok"], false);
    let problems = v["problems"].as_array().unwrap();
    assert_eq!(problems.len(), 4);
    assert_eq!(problems[0]["key"], "dataset.fps");
    assert_eq!(problems[0]["line"], 4);
}

#[test]
fn a_build_with_missing_inputs_lists_them_all_before_doing_any_work() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("motionforge.toml"),
        BAD.replace("fps = 0", "fps = 30")
            .replace("val = 0.3", "val = 0.2"),
    )
    .unwrap();
    let out = run(&["build"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    assert!(
        err.contains("has 2 problems")
            && err.contains("sources[0].captures[0]")
            && err.contains("sources[0].profile"),
        "{err}"
    );
    assert!(!dir.path().join("out").exists(), "nothing was written");
}

#[test]
fn a_missing_default_config_says_so_and_suggests_config() {
    let dir = tempfile::tempdir().unwrap();
    for args in [
        vec!["build"],
        vec!["config", "check"],
        vec!["clean"],
        vec!["export-bvh", "--clip", "x"],
    ] {
        let out = run(&args, dir.path());
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = text(&out.stderr);
        assert!(
            err.contains("no motionforge.toml in the working folder") && err.contains("--config"),
            "{args:?}: {err}"
        );
    }
    let out = run(&["build", "--config", "elsewhere.toml"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("config elsewhere.toml not found"));
}

#[test]
fn type_errors_name_the_line_and_key() {
    let err = Config::parse(
        "[dataset]\nname = \"x\"\noutput = \"o\"\nfps = \"thirty\"\n",
        Path::new("c.toml"),
    )
    .unwrap_err()
    .to_string();
    assert_eq!(
        err,
        "config c.toml:4: dataset.fps: invalid type: string \"thirty\", expected f64"
    );
    let err = Config::parse(
        "[dataset]\nname = \"x\"\noutput = \"o\"\n[[sources]]\nname = \"s\"\ncaptures = [\"*.bvh\"]\nprofile = \"cmu\"\n[sources.labels]\nkind = \"filename\"\npattern = \"{a}\"\naction = \"{a}\"\ntext = \"{a}\"\n[sources.segment]\nmax_simultaneous = -2\n",
        Path::new("c.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.starts_with("config c.toml:14: sources[0].segment.max_simultaneous: invalid value"),
        "{err}"
    );
}

/// A config that loads, with every table written out.
const FULL: &str = r#"llm_cache = "cache.jsonl"
[dataset]
name = "x"
output = "out"
[mirror]
[motion_types]
[features]
[splits]
[synthetic]
[synthetic.thresholds]
max_foot_skate = 0.4
max_ground_penetration = 0.03
min_self_distance = 0.03
max_lean = 25
[part_labels]
[task_plans]
[paraphrases]
[llm]
base_url = "http://127.0.0.1:9/v1"
model = "m"
[[sources]]
name = "s"
captures = ["*.bvh"]
profile = "cmu"
[sources.labels]
kind = "filename"
pattern = "{a}"
action = "{a}"
text = "{a}"
[sources.segment]
"#;

#[test]
fn unknown_keys_are_rejected_in_every_table() {
    Config::parse(FULL, Path::new("c.toml")).unwrap();
    let headers: Vec<(usize, &str)> = FULL
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with('['))
        .collect();
    assert_eq!(headers.len(), 14);
    for (at, header) in headers.into_iter().chain([(0, "top level")]) {
        let mut text: Vec<&str> = FULL.lines().collect();
        let at = if header == "top level" { 0 } else { at + 1 };
        text.insert(at, "bogus_key = 1");
        let err = Config::parse(&text.join("\n"), Path::new("c.toml"))
            .expect_err(header)
            .to_string();
        assert!(
            err.contains(&format!("c.toml:{}:", at + 1))
                && err.contains("unknown field `bogus_key`"),
            "{header}: {err}"
        );
    }
}

#[test]
fn value_checks_report_every_problem_at_once() {
    let text = FULL
        .replace("name = \"x\"", "name = \"..\"")
        .replace("[features]", "[features]\ncontact_speed = 0")
        .replace(
            "[splits]",
            "[splits]\nratios = { train = 1.5, \"a/b\" = -0.5 }",
        )
        .replace("max_lean = 25", "max_lean = 200")
        .replace(
            "base_url = \"http://127.0.0.1:9/v1\"",
            "base_url = \"ftp://x\"",
        )
        .replace(
            "[sources.segment]",
            "[sources.segment]\nmin_seconds = 3\nmax_seconds = 2",
        );
    let err = Config::parse(&text, Path::new("c.toml")).unwrap_err();
    let motionforge::config::ConfigError::Invalid { problems, .. } = &err else {
        panic!("{err}");
    };
    let keys: Vec<&str> = problems.iter().map(|p| p.key.as_str()).collect();
    assert_eq!(
        keys,
        [
            "dataset.name",
            "features.contact_speed",
            "splits.ratios.\"a/b\"",
            "splits.ratios.\"a/b\"",
            "splits.ratios.train",
            "synthetic.thresholds.max_lean",
            "llm.base_url",
            "sources[0].segment.max_seconds",
        ],
        "{err}"
    );
    assert!(
        problems.iter().all(|p| p.line.is_some()),
        "every problem has its line: {err}"
    );
}

// ---- clean -----------------------------------------------------------------------------------

fn built_demo() -> (tempfile::TempDir, PathBuf) {
    let out = tempfile::tempdir().unwrap();
    common::build_demo(out.path());
    let dataset = out.path().join("demo");
    (out, dataset)
}

fn clean(out: &Path, extra: &[&str]) -> Output {
    let (o, d) = (out.display().to_string(), demo());
    let mut args = vec!["clean", "--config", &d, "--output", &o];
    args.extend_from_slice(extra);
    run(&args, &repo())
}

#[test]
fn clean_cache_only_removes_the_stage_cache_and_nothing_else() {
    let (out, dataset) = built_demo();
    let run_ = clean(out.path(), &["--cache-only"]);
    assert!(run_.status.success(), "{}", text(&run_.stderr));
    assert!(!dataset.join(".motionforge/cache").exists());
    assert!(dataset.join("manifest.json").is_file());
    assert_eq!(common::shards(&dataset).len(), 3);
    assert!(text(&run_.stdout).contains("removed .motionforge/cache"));
    // The stages recompute; the outputs they would write are the same, so none is rewritten.
    let rebuilt = common::build_demo(out.path());
    let summary = text(&rebuilt.stdout);
    assert!(
        summary.contains("ingest  ran 9 of 9") && summary.contains("write  up to date"),
        "{summary}"
    );
}

#[test]
fn clean_removes_the_outputs_but_keeps_the_llm_cache_and_foreign_files() {
    let (out, dataset) = built_demo();
    std::fs::write(dataset.join("llm-cache.jsonl"), "{}\n").unwrap();
    std::fs::write(dataset.join("notes.txt"), "mine").unwrap();
    std::fs::write(out.path().join("beside.txt"), "not in the dataset").unwrap();
    std::fs::write(dataset.join(".manifest.json.4242.tmp"), "left over").unwrap();
    let run_ = clean(out.path(), &[]);
    assert!(run_.status.success(), "{}", text(&run_.stderr));
    for gone in [
        "data",
        "normalization",
        "report",
        "manifest.json",
        "README.md",
        "skeletons.json",
        "rejects.jsonl",
        "build-report.json",
        "plans.parquet",
        ".motionforge/cache",
        ".motionforge/state.json",
        ".manifest.json.4242.tmp",
    ] {
        assert!(!dataset.join(gone).exists(), "{gone} must be removed");
    }
    for kept in ["llm-cache.jsonl", "notes.txt"] {
        assert!(dataset.join(kept).is_file(), "{kept} must be kept");
    }
    assert!(out.path().join("beside.txt").is_file());
    let stdout = text(&run_.stdout);
    assert!(
        stdout.contains("kept: llm-cache.jsonl, notes.txt"),
        "{stdout}"
    );
    let again = clean(out.path(), &[]);
    assert!(
        text(&again.stdout).contains("nothing to clean"),
        "{}",
        text(&again.stdout)
    );
    let rebuilt = common::build_demo(out.path());
    assert!(text(&rebuilt.stdout).contains("write  ran 1 of 1"));
}

#[test]
fn clean_refuses_a_folder_that_is_not_a_dataset() {
    let out = tempfile::tempdir().unwrap();
    let dir = out.path().join("demo");
    std::fs::create_dir_all(dir.join("data")).unwrap();
    std::fs::write(dir.join("README.md"), "someone's project").unwrap();
    let run_ = clean(out.path(), &[]);
    assert_eq!(run_.status.code(), Some(2));
    assert!(
        text(&run_.stderr).contains("does not look like a motionforge dataset folder"),
        "{}",
        text(&run_.stderr)
    );
    assert!(dir.join("README.md").is_file() && dir.join("data").is_dir());
}

#[test]
fn clean_does_not_run_while_a_build_holds_the_dataset() {
    let (out, dataset) = built_demo();
    let _held = motionforge::build::lock::WorkspaceLock::acquire(&dataset, None).unwrap();
    let run_ = clean(out.path(), &[]);
    assert_eq!(run_.status.code(), Some(1));
    assert!(text(&run_.stderr).contains("is being built by pid"));
    assert!(dataset.join("manifest.json").is_file());
}

// ---- bench --build -----------------------------------------------------------------------------

/// The number right after `prefix` on the first line of `text` that starts with it.
fn number_after(text: &str, prefix: &str) -> f64 {
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix(prefix))
        .unwrap_or_else(|| panic!("no `{prefix}` in:\n{text}"));
    let token: String = line
        .trim_start()
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.' || *c == ',')
        .filter(|c| *c != ',')
        .collect();
    token
        .parse()
        .unwrap_or_else(|e| panic!("`{prefix}` not followed by a number ({e}) in:\n{text}"))
}

fn bandai2_subset() -> String {
    common::shared_data()
        .join("bandai-namco-2-subset/data")
        .display()
        .to_string()
}

#[test]
fn bench_build_times_every_stage_beside_the_bare_scan() {
    let out = run(
        &[
            "bench",
            "--build",
            "--data",
            &bandai2_subset(),
            "--repeat",
            "1",
        ],
        &repo(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    // Timings are not asserted: only that every stage is named and every figure is there.
    let stages: Vec<&str> = stdout
        .lines()
        .skip_while(|l| !l.starts_with("stage "))
        .take_while(|l| !l.starts_with("total "))
        .collect();
    for stage in [
        "ingest", "segment", "label", "mirror", "compose", "write", "report",
    ] {
        assert!(
            stages
                .iter()
                .any(|l| l.split_whitespace().any(|w| w == stage)),
            "no row for `{stage}` in:\n{stdout}"
        );
    }
    assert!(
        stdout.contains("dataset-2_{content}_{style}_{take}"),
        "{stdout}"
    );
    for prefix in [
        "ratio:",
        "total",
        "bare scan:",
        "frames/s per core:",
        "no-op rebuild:",
        "plan:",
        "peak RSS: full build",
        "stage cache:",
        "shards:",
    ] {
        assert!(
            number_after(&stdout, prefix) > 0.0,
            "`{prefix}` is not positive in:\n{stdout}"
        );
    }
    assert!(stdout.contains("x the bare scan"), "{stdout}");
    assert!(
        stdout.contains("nothing ran"),
        "the rebuild is a no-op:\n{stdout}"
    );
}

#[test]
fn bench_build_json_lists_the_copies_and_keeps_the_folder() {
    let keep = tempfile::tempdir().unwrap();
    let k = keep.path().join("bench").display().to_string();
    let out = run(
        &[
            "--json",
            "bench",
            "--build",
            "--data",
            &bandai2_subset(),
            "--repeat",
            "1",
            "--copies",
            "2",
            "--keep",
            &k,
        ],
        &repo(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let value: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let captures = common::bvh_files(&common::shared_data().join("bandai-namco-2-subset/data"));
    assert_eq!(value["copies"], 2);
    assert_eq!(value["captures"], 2 * captures.len());
    for key in [
        "ratio",
        "frames_per_second_per_core",
        "input_frames",
        "input_bytes",
        "shard_bytes",
        "cache_bytes_total",
    ] {
        assert!(
            value[key].as_f64().is_some_and(|v| v > 0.0),
            "{key}: {}",
            value[key]
        );
    }
    let stages = value["full_build"]["runs"][0]["stages"].as_array().unwrap();
    assert!(stages.iter().any(|s| s["stage"] == "write"));
    assert!(value["noop_rebuild"]["nothing_ran"].as_bool().unwrap());
    // The scan read the bytes once per copy.
    assert_eq!(value["scan"]["bytes"], value["input_bytes"]);
    let config = std::fs::read_to_string(keep.path().join("bench/bench.toml")).unwrap();
    assert!(config.contains("name = \"bn2-1\"") && config.contains("name = \"bn2-2\""));
    assert!(keep.path().join("bench/out/bench/manifest.json").is_file());
    // A second run into the kept folder is allowed; a foreign non-empty folder is refused.
    let foreign = tempfile::tempdir().unwrap();
    std::fs::write(foreign.path().join("notes.txt"), "mine").unwrap();
    let refused = run(
        &[
            "bench",
            "--build",
            "--data",
            &bandai2_subset(),
            "--keep",
            &foreign.path().display().to_string(),
        ],
        &repo(),
    );
    assert!(!refused.status.success());
    assert!(
        text(&refused.stderr).contains("not empty"),
        "{}",
        text(&refused.stderr)
    );
    assert!(foreign.path().join("notes.txt").is_file());
}

#[test]
fn bench_build_bvhio_times_bvhio_beside_the_build() {
    // Two captures (with their sidecars): bvhio is slow, and only the figures are checked.
    let dir = tempfile::tempdir().unwrap();
    let subset = common::shared_data().join("bandai-namco-2-subset/data");
    for bvh in common::bvh_files(&subset).iter().take(2) {
        for file in [bvh.clone(), bvh.with_extension("json")] {
            std::fs::copy(&file, dir.path().join(file.file_name().unwrap())).unwrap();
        }
    }
    let python = common::python();
    let out = run(
        &[
            "bench",
            "--build",
            "--bvhio",
            "--python",
            python.to_str().unwrap(),
            "--data",
            dir.path().to_str().unwrap(),
            "--repeat",
            "1",
        ],
        &repo(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    for prefix in ["bvhio:", "against bvhio:"] {
        assert!(
            number_after(&stdout, prefix) > 0.0,
            "`{prefix}` is not positive in:\n{stdout}"
        );
    }
    let line = stdout.lines().find(|l| l.starts_with("bvhio:")).unwrap();
    // bvhio read the same two files, every frame of them.
    assert!(line.contains("reading 2 files"), "{line}");
    let frames: u64 = common::bvh_files(&subset)
        .iter()
        .take(2)
        .map(|f| {
            let text = std::fs::read_to_string(f).unwrap();
            let line = text
                .lines()
                .find_map(|l| l.trim().strip_prefix("Frames:"))
                .unwrap();
            line.trim().parse::<u64>().unwrap()
        })
        .sum();
    assert!(line.contains(&format!("({frames} frames)")), "{line}");
    assert!(stdout.contains("target at least 20x"), "{stdout}");
    // Copies would make the build read more than bvhio: refused.
    let refused = run(
        &[
            "bench",
            "--build",
            "--bvhio",
            "--copies",
            "2",
            "--data",
            dir.path().to_str().unwrap(),
        ],
        &repo(),
    );
    assert!(!refused.status.success());
    assert!(
        text(&refused.stderr).contains("--copies"),
        "{}",
        text(&refused.stderr)
    );
}

#[test]
fn bench_export_times_the_export_beside_the_numpy_reference() {
    let dir = tempfile::tempdir().unwrap();
    common::build_demo(dir.path());
    let ds = dir.path().join("demo");
    let python = common::python();
    let out = run(
        &[
            "bench",
            "--export",
            ds.to_str().unwrap(),
            "--repeat",
            "1",
            "--python",
            python.to_str().unwrap(),
        ],
        &repo(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    // Timings are not asserted: every figure is there and positive.
    for prefix in [
        "export:",
        "reference:",
        "per CPU second:",
        "per wall second:",
        "vectors alone:",
    ] {
        assert!(
            number_after(&stdout, prefix) > 0.0,
            "`{prefix}` is not positive in:\n{stdout}"
        );
    }
    // Both sides in both units, and the load they ran under.
    for (needle, lines) in [
        ("rows/s wall", 2),
        ("rows per CPU second", 3),
        ("load average:", 1),
    ] {
        assert_eq!(
            stdout.matches(needle).count(),
            lines,
            "`{needle}` in:\n{stdout}"
        );
    }
    // The reference computed the same rows as the export (float32 rounding apart).
    let json = run(
        &[
            "--json",
            "bench",
            "--export",
            ds.to_str().unwrap(),
            "--repeat",
            "1",
            "--python",
            python.to_str().unwrap(),
        ],
        &repo(),
    );
    assert!(json.status.success(), "{}", text(&json.stderr));
    let value: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    let rows = value["rows"].as_u64().unwrap();
    assert!(rows > 0, "{value}");
    assert_eq!(value["reference"]["rows"].as_u64(), Some(rows), "{value}");
    assert_eq!(
        value["agreement"]["rows_compared"].as_u64(),
        Some(rows),
        "{value}"
    );
    assert_eq!(value["agreement"]["shape_mismatches"], 0, "{value}");
    let diff = value["agreement"]["max_abs_diff"].as_f64().unwrap();
    assert!(
        diff < 1e-3,
        "the reference differs from the export by {diff}: {value}"
    );
    // Without a Python, the bench says how to get one.
    let missing = Command::new(BIN)
        .args(["bench", "--export", ds.to_str().unwrap()])
        .env_remove("MOTIONFORGE_PYTHON")
        .output()
        .unwrap();
    assert!(!missing.status.success());
    assert!(
        text(&missing.stderr).contains("MOTIONFORGE_PYTHON"),
        "{}",
        text(&missing.stderr)
    );
}

#[test]
fn bench_captions_tags_each_distinct_caption_of_the_file() {
    let file = common::shared_data().join("sinc/clean_labels.txt");
    let distinct: std::collections::BTreeSet<String> = std::fs::read_to_string(&file)
        .unwrap()
        .lines()
        .map(|l| l.trim().to_string())
        .filter(|l| !l.is_empty())
        .collect();
    let out = run(
        &["bench", "--captions", &file.display().to_string()],
        &repo(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    // Timings are not asserted: the count, nothing refused, both passes reported.
    assert_eq!(
        number_after(&stdout, "") as usize,
        distinct.len(),
        "{stdout}"
    );
    assert!(stdout.contains("0 refused"), "{stdout}");
    assert!(
        stdout.contains("first pass") && stdout.contains("(remembered)"),
        "{stdout}"
    );
    let missing = run(&["bench", "--captions", "no/such/file.txt"], &repo());
    assert!(!missing.status.success());
    assert!(text(&missing.stderr).contains("no/such/file.txt"));
}

#[test]
fn filter_values_a_dataset_does_not_have_and_missing_options_are_usage_errors_listing_choices() {
    let dir = tempfile::tempdir().unwrap();
    common::build_demo(dir.path());
    let dataset = dir.path().join("demo");
    let ds = dataset.to_str().unwrap();
    let out = run(&["clips", ds, "--type", "nosuchtype"], dir.path());
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    // The types the demo has are listed, so the user can pick one.
    assert!(
        err.contains("nosuchtype") && err.contains("walk forward") && err.contains("wave"),
        "{err}"
    );
    let out = run(&["clips", ds, "--split", "dev"], dir.path());
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("train"), "{}", text(&out.stderr));
    let out = run(&["clips", ds, "--kind", "bogus"], dir.path());
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("real_single") && err.contains("mirrored"),
        "{err}"
    );
    let out = run(
        &["preview", ds, "--type", "nosuchtype", "-o", "p"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let out = run(
        &["preview", ds, "--clip", "cmu/01_01", "-o", "p"],
        dir.path(),
    );
    assert!(
        text(&out.stderr).contains("did you mean cmu/01_01:"),
        "{}",
        text(&out.stderr)
    );
    let out = run(
        &["prompt", "render", "pair_compat", "--text", "walk"],
        dir.path(),
    );
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("--second"), "{err}");
    // A type the dataset has still filters.
    let out = run(&["clips", ds, "--type", "wave", "--json"], dir.path());
    assert!(out.status.success());
    let clips: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(!clips.as_array().unwrap().is_empty());
}

#[test]
fn a_run_that_stops_early_says_nothing_was_written_and_an_empty_stage_says_it_had_nothing_to_do() {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo();
    let out = run(
        &["run", "segment", "--config", &demo, "--output", "."],
        dir.path(),
    );
    let printed = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        printed.contains("9 captures -> 10 clips (0 mirrored), not written"),
        "{printed}"
    );
    assert!(
        !printed.contains("part labels:") && !printed.contains("synthetic pairs:"),
        "{printed}"
    );
    assert!(!dir.path().join("demo/data").exists());
    // On a new folder, the stages behind ingest have no count yet: not "1 of 1".
    let out = run(
        &["plan", "--config", &demo, "--output", "fresh"],
        dir.path(),
    );
    let printed = text(&out.stdout);
    assert!(
        printed.contains("segment  all to run: ingest re-runs first\n"),
        "{printed}"
    );
    for stage in ["segment", "label", "compose"] {
        assert!(
            !printed.contains(&format!("{stage}  1 of 1 to run")),
            "{printed}"
        );
    }
    // The HumanML3D fixture has no compatible pair: its first build has nothing to compose.
    let config = repo().join("fixtures/humanml3d-joints/build.toml");
    let out = run(
        &[
            "build",
            "--config",
            config.to_str().unwrap(),
            "--output",
            ".",
        ],
        dir.path(),
    );
    let printed = text(&out.stdout);
    assert!(printed.contains("compose  nothing to do"), "{printed}");
    assert!(!printed.contains("up to date"), "{printed}");
}

#[test]
fn report_export_bvh_preview_and_export_answer_json_with_json() {
    let dir = tempfile::tempdir().unwrap();
    common::build_demo(dir.path());
    let ds = dir.path().join("demo");
    let ds = ds.to_str().unwrap();
    let out = run(&["report", ds, "--json"], dir.path());
    assert!(out.status.success(), "{}", text(&out.stderr));
    let value: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let files = value["files"].as_array().unwrap();
    assert!(
        files
            .iter()
            .any(|f| f.as_str().unwrap().ends_with("stats.json")),
        "{value}"
    );
    let out = run(
        &["export-bvh", ds, "--clip", "cmu/01_01:115-1315", "--json"],
        dir.path(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let value: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(value["path"], "cmu_01_01_115-1315.bvh", "{value}");
    assert!(value["frames"].as_u64().unwrap() > 0, "{value}");
    assert!(dir.path().join("cmu_01_01_115-1315.bvh").is_file());

    // preview and export humanml3d answer one JSON object too, naming every file they wrote.
    let out = run(
        &[
            "preview",
            ds,
            "--clip",
            "cmu/01_01:115-1315",
            "--with",
            "mirror",
            "--json",
            "-o",
            "pv",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let value: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let previews = value["previews"].as_array().unwrap();
    assert_eq!(previews.len(), 1, "{value}");
    assert_eq!(
        previews[0]["panels"],
        serde_json::json!(["cmu/01_01:115-1315", "cmu/01_01:115-1315:m"]),
        "{value}"
    );
    for key in ["gif", "png"] {
        let path = dir.path().join(previews[0][key].as_str().unwrap());
        assert!(path.is_file(), "{key}: {value}");
    }
    let out = run(
        &["export", "humanml3d", ds, "--json", "-o", "hml"],
        dir.path(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let value: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let exported = value["exported"].as_u64().unwrap();
    assert!(exported > 0, "{value}");
    let joints = std::fs::read_dir(dir.path().join("hml/new_joints"))
        .unwrap()
        .count();
    assert_eq!(joints as u64, exported, "{value}");
    assert_eq!(value["output"], "hml", "{value}");
}

// ---- one command grammar ---------------------------------------------------------------------

/// The commands that read a built dataset folder, each with what else it needs to run.
const DATASET_COMMANDS: [&[&str]; 6] = [
    &["clips"],
    &["preview", "--limit", "1"],
    &["export-bvh"],
    &["report"],
    &["export", "humanml3d"],
    &[
        "plan-session",
        "--scene",
        "schemas/scenes/living-room.toml",
        "--seed",
        "8",
    ],
];

#[test]
fn every_command_takes_the_dataset_first_and_writes_where_o_says() {
    // --help: the dataset folder is the first positional argument, `-o, --output` is listed by
    // every command that writes or looks at a build's output, and no old spelling is shown.
    for command in DATASET_COMMANDS {
        let mut args = vec![command[0]];
        if command[0] == "export" {
            args.push("humanml3d");
        }
        args.push("--help");
        let help = text(&run(&args, &repo()).stdout);
        let (_, arguments) = help.split_once("Arguments:\n").unwrap_or_default();
        let first = arguments.split_whitespace().next().unwrap_or_default();
        assert!(
            first.trim_matches(['<', '>', '[', ']']) == "DATASET",
            "`{}`: the first positional argument is the dataset folder:\n{help}",
            args.join(" ")
        );
        assert!(
            !help.contains("--dataset") && !help.contains("--out "),
            "`{}` shows no old spelling:\n{help}",
            args.join(" ")
        );
    }
    for command in [
        &["build"][..],
        &["run"],
        &["plan"],
        &["status"],
        &["clean"],
        &["config", "check"],
        &["export-bvh"],
        &["preview"],
        &["report"],
        &["export", "humanml3d"],
        &["plan-session"],
    ] {
        let mut args = command.to_vec();
        args.push("--help");
        let help = text(&run(&args, &repo()).stdout);
        assert!(
            help.contains("  -o, --output <"),
            "`{}` has -o/--output:\n{help}",
            args.join(" ")
        );
    }

    // Run: each command given the dataset first, and -o where it writes.
    let (out, dataset) = built_demo();
    let d = dataset.display().to_string();
    let listed = run(&["clips", &d, "--json", "--limit", "1"], &repo());
    assert!(listed.status.success(), "{}", text(&listed.stderr));
    let clips: serde_json::Value = serde_json::from_slice(&listed.stdout).unwrap();
    let clip = clips[0]["clip_id"].as_str().unwrap().to_string();
    let target = |name: &str| out.path().join(name).display().to_string();
    for command in DATASET_COMMANDS {
        let mut args: Vec<String> = command[..1].iter().map(|s| s.to_string()).collect();
        let mut rest: Vec<String> = command[1..].iter().map(|s| s.to_string()).collect();
        if command[0] == "export" {
            args.push(rest.remove(0));
        }
        args.push(d.clone());
        args.extend(rest);
        let written = match command[0] {
            "clips" => None,
            "export-bvh" => {
                args.extend(["--clip".to_string(), clip.clone()]);
                Some(target("clip.bvh"))
            }
            name => Some(target(name)),
        };
        if let Some(path) = &written {
            args.extend(["-o".to_string(), path.clone()]);
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let output = run(&args, &repo());
        assert!(
            output.status.success(),
            "`{}`: {}",
            args.join(" "),
            text(&output.stderr)
        );
        assert!(
            !text(&output.stderr).contains("deprecated"),
            "`{}`: {}",
            args.join(" "),
            text(&output.stderr)
        );
        if let Some(path) = written {
            assert!(
                Path::new(&path).exists(),
                "`{}` wrote {path}",
                args.join(" ")
            );
        }
    }
}

#[test]
fn the_old_spellings_still_work_and_warn_naming_the_new_one() {
    let (out, dataset) = built_demo();
    let d = dataset.display().to_string();
    let old = out.path().join("old").display().to_string();
    let new = out.path().join("new").display().to_string();
    let exported = run(
        &["export", "humanml3d", "--dataset", &d, "--out", &old],
        &repo(),
    );
    assert!(exported.status.success(), "{}", text(&exported.stderr));
    let stderr = text(&exported.stderr);
    assert!(
        stderr.contains("`--dataset` is deprecated")
            && stderr.contains("motionforge export humanml3d <DATASET>")
            && stderr.contains("`--out` is deprecated")
            && stderr.contains("--output"),
        "{stderr}"
    );
    let again = run(&["export", "humanml3d", &d, "-o", &new], &repo());
    assert!(again.status.success(), "{}", text(&again.stderr));
    for file in ["Mean.npy", "train.txt", "all.txt"] {
        assert_eq!(
            std::fs::read(Path::new(&old).join(file)).unwrap(),
            std::fs::read(Path::new(&new).join(file)).unwrap(),
            "{file}: the old spelling does what the new one does"
        );
    }

    let session = |dir: &str, dataset_args: &[&str]| {
        let mut args = vec!["plan-session"];
        args.extend_from_slice(dataset_args);
        args.extend([
            "--scene",
            "schemas/scenes/living-room.toml",
            "--seed",
            "8",
            "-o",
            dir,
        ]);
        run(&args, &repo())
    };
    let old_dir = out.path().join("s-old").display().to_string();
    let new_dir = out.path().join("s-new").display().to_string();
    let planned = session(&old_dir, &["--dataset", &d]);
    assert!(planned.status.success(), "{}", text(&planned.stderr));
    let stderr = text(&planned.stderr);
    assert!(
        stderr.contains("`--dataset` is deprecated")
            && stderr.contains("motionforge plan-session <DATASET>"),
        "{stderr}"
    );
    let planned = session(&new_dir, &[&d]);
    assert!(planned.status.success(), "{}", text(&planned.stderr));
    assert_eq!(
        std::fs::read(Path::new(&old_dir).join("living-room-8.csv")).unwrap(),
        std::fs::read(Path::new(&new_dir).join("living-room-8.csv")).unwrap()
    );
    // Both spellings at once is a usage error.
    let both = run(
        &["export", "humanml3d", &d, "--dataset", &d, "-o", &new],
        &repo(),
    );
    assert_eq!(both.status.code(), Some(2), "{}", text(&both.stderr));
}

// ---- an LLM server that is not there -----------------------------------------------------------

#[test]
fn a_dead_llm_server_stops_the_build_at_once_without_a_progress_line_per_prompt() {
    let dir = tempfile::tempdir().unwrap();
    let url = crate::common::llm::dead_url();
    ConfigSpec::demo()
        .set("llm.base_url", url.as_str())
        .set("llm.model", "m")
        .set("part_labels.labeller", "llm")
        .write(dir.path().join("llm.toml"));
    let out = run(&["build", "--config", "llm.toml"], dir.path());
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!("label: no LLM server answers at {url}")),
        "{err}"
    );
    // Nothing is sent, so no line announces or counts requests ("label: sending 9 LLM requests",
    // "label: 1 of 9 requests, ... 1 error").
    assert!(
        !err.lines().any(|l| l.starts_with("label:")),
        "no progress line of requests never sent:\n{err}"
    );
}

#[test]
fn every_commands_help_runs_and_status_and_clean_take_the_dataset_folder_first() {
    for command in leaf_commands(&[]) {
        let mut args: Vec<&str> = command.iter().map(String::as_str).collect();
        args.push("--help");
        let out = run(&args, &repo());
        assert!(
            out.status.success(),
            "`{}`: {}",
            args.join(" "),
            text(&out.stderr)
        );
    }
    for command in ["status", "clean"] {
        let help = text(&run(&[command, "--help"], &repo()).stdout);
        let (_, arguments) = help.split_once("Arguments:\n").unwrap_or_default();
        let first = arguments.split_whitespace().next().unwrap_or_default();
        assert_eq!(
            first.trim_matches(['<', '>', '[', ']']),
            "DATASET",
            "`{command}`: the first positional argument is the dataset folder:\n{help}"
        );
    }

    let (out, dataset) = built_demo();
    let d = dataset.display().to_string();
    let o = out.path().display().to_string();
    // The folder alone finds the config its build was given: the same status as with --config.
    let by_folder = run(&["status", &d, "--json"], &repo());
    assert!(by_folder.status.success(), "{}", text(&by_folder.stderr));
    let by_config = run(
        &["status", "--config", &demo(), "--output", &o, "--json"],
        &repo(),
    );
    assert!(by_config.status.success(), "{}", text(&by_config.stderr));
    let by_folder: serde_json::Value = serde_json::from_slice(&by_folder.stdout).unwrap();
    let by_config: serde_json::Value = serde_json::from_slice(&by_config.stdout).unwrap();
    assert_eq!(by_folder, by_config);
    assert_eq!(by_folder["stages"][0]["fresh"], true, "{by_folder}");
    // A config naming another dataset is a usage error, as is a folder that is no dataset.
    let other = repo().join("fixtures/humanml3d-joints/build.toml");
    let wrong = run(
        &["status", &d, "--config", other.to_str().unwrap()],
        &repo(),
    );
    assert_eq!(wrong.status.code(), Some(2), "{}", text(&wrong.stderr));
    assert!(
        text(&wrong.stderr).contains("hml3d-joints"),
        "{}",
        text(&wrong.stderr)
    );
    let not_a_dataset = run(&["status", &o], &repo());
    assert_eq!(not_a_dataset.status.code(), Some(2));
    // A folder whose build recorded no config (built by an older release) asks for --config.
    std::fs::remove_file(dataset.join(".motionforge/config.json")).unwrap();
    let unrecorded = run(&["status", &d], &repo());
    assert_eq!(
        unrecorded.status.code(),
        Some(2),
        "{}",
        text(&unrecorded.stderr)
    );
    assert!(
        text(&unrecorded.stderr).contains("pass --config"),
        "{}",
        text(&unrecorded.stderr)
    );
    let given = run(&["status", &d, "--config", &demo()], &repo());
    assert!(given.status.success(), "{}", text(&given.stderr));

    // clean: the folder alone, as with --config.
    let cleaned = run(&["clean", &d, "--cache-only"], &repo());
    assert!(cleaned.status.success(), "{}", text(&cleaned.stderr));
    assert!(!dataset.join(".motionforge/cache").exists());
    assert!(dataset.join("data").is_dir());
    let cleaned = run(&["clean", &d], &repo());
    assert!(cleaned.status.success(), "{}", text(&cleaned.stderr));
    assert!(!dataset.join("data").exists() && !dataset.join("manifest.json").exists());
    // The folder and a config at once is a usage error.
    let both = run(&["clean", &d, "--config", &demo()], &repo());
    assert_eq!(both.status.code(), Some(2), "{}", text(&both.stderr));
}

/// `motionforge <args>` on a terminal (a pseudo-terminal made by util-linux `script`) `columns`
/// wide; what it printed, without the terminal's carriage returns.
fn on_terminal(args: &[&str], columns: usize) -> String {
    let command = std::iter::once(BIN)
        .chain(args.iter().copied())
        .map(|a| format!("'{a}'"))
        .collect::<Vec<_>>()
        .join(" ");
    let out = Command::new("script")
        .args(["-qec", &command, "/dev/null"])
        .env("COLUMNS", columns.to_string())
        .output()
        .expect("util-linux `script` runs the command on a pseudo-terminal");
    assert!(out.status.success(), "{}", text(&out.stderr));
    text(&out.stdout).replace('\r', "")
}

#[test]
fn clips_fits_the_terminal_and_prints_whole_ids_when_piped_or_wide() {
    let (_out, dataset) = built_demo();
    let d = dataset.display().to_string();
    let longest = "synthetic/bandai-namco-1/dataset-1_walk-left_normal_001:0-135:m+bandai-namco-1/dataset-1_bye_normal_001:0-111:m";
    let table = on_terminal(&["clips", &d], 120);
    let rows = lines(&table);
    assert_eq!(rows.len(), 25, "{table}");
    for row in &rows {
        assert!(
            row.chars().count() <= 120,
            "{} wide: {row}",
            row.chars().count()
        );
    }
    assert!(!table.contains(longest), "{table}");
    // Cut in the middle: the start and the end of the id stay, so a mirror's `:m` shows.
    assert!(
        rows.iter()
            .any(|r| r.starts_with("synthetic/") && r.contains('…') && r.contains(":0-111:m ")),
        "{table}"
    );
    // Whole with --wide on a terminal, and whenever the output is not a terminal.
    let wide = on_terminal(&["clips", &d, "--wide"], 120);
    assert!(wide.contains(longest) && !wide.contains('…'), "{wide}");
    let piped = run(&["clips", &d], &repo());
    assert!(
        text(&piped.stdout).contains(longest),
        "{}",
        text(&piped.stdout)
    );
    let json = on_terminal(&["clips", &d, "--json"], 120);
    assert!(json.contains(longest), "{json}");
}

// ---- plan counts as build does ---------------------------------------------------------------

/// `plan --json` then `build --json` with the config `config` in `dir`: every stage the plan
/// gives a count for has the build's count, and would run what the build then ran. The plan.
fn plan_then_build(dir: &Path, config: &str) -> serde_json::Value {
    let planned = run(&["--json", "plan", "--config", config], dir);
    assert!(planned.status.success(), "{}", text(&planned.stderr));
    let plan: serde_json::Value = serde_json::from_slice(&planned.stdout).unwrap();
    let built = run(&["--json", "build", "--config", config], dir);
    assert!(built.status.success(), "{}", text(&built.stderr));
    let report: serde_json::Value = serde_json::from_slice(&built.stdout).unwrap();
    for planned in plan["stages"].as_array().unwrap() {
        // 0: not known before an earlier stage runs ("all to run").
        if planned["items"] == 0 {
            continue;
        }
        let name = planned["stage"].as_str().unwrap();
        let built = report["stages"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["stage"] == name)
            .unwrap_or_else(|| panic!("{name} planned, not in the build's report: {report}"));
        assert_eq!(
            planned["items"], built["items"],
            "{name}: plan {plan}\nbuild {report}"
        );
        assert_eq!(
            planned["to_run"], built["ran"],
            "{name}: plan {plan}\nbuild {report}"
        );
    }
    plan
}

#[test]
fn plan_counts_every_stage_as_the_next_build_does_also_after_a_seed_change() {
    let dir = tempfile::tempdir().unwrap();
    ConfigSpec::demo().write(dir.path().join("demo.toml"));
    let first = plan_then_build(dir.path(), "demo.toml");
    assert_eq!(first["stages"][0]["to_run"], 9, "{first}");
    let again = plan_then_build(dir.path(), "demo.toml");
    let label = &again["stages"][2];
    assert_eq!(label["stage"], "label");
    assert_eq!(
        label["items"], 10,
        "ten clips labelled, not one cache entry: {again}"
    );

    ConfigSpec::demo()
        .seed(7)
        .write(dir.path().join("seeded.toml"));
    let through = run(
        &["plan", "--config", "seeded.toml", "--through", "label"],
        dir.path(),
    );
    let printed = text(&through.stdout);
    assert!(
        printed.contains("nothing to run through label")
            && !printed.contains("a build would reuse everything"),
        "{printed}"
    );
    let after_seed = plan_then_build(dir.path(), "seeded.toml");
    // Every stage is known after a seed change, and compose re-runs its newly sampled pairs. Not
    // the pair check, which the demo turns off, nor the label check, which comes after compose
    // (its drops take the pairs made of a dropped clip with it).
    for stage in after_seed["stages"].as_array().unwrap() {
        if stage["enabled"] == false || stage["stage"] == "label_check" {
            continue;
        }
        assert_ne!(stage["items"], 0, "{after_seed}");
    }
    let compose = &after_seed["stages"][7];
    assert_eq!(compose["stage"], "compose");
    assert!(compose["to_run"].as_u64().unwrap() > 1, "{after_seed}");
}
