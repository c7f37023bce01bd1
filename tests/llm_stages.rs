//! The LLM stages inside a build: a real OpenAI-compatible server on loopback, the response cache,
//! `--offline`, imported SINC answers, and the embedded labeller when no LLM is configured.
mod common;

use std::fs;
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use axum::extract::State;
use axum::routing::post;
use axum::{Json, Router};
use common::*;
use motionforge::build::{BuildOptions, BuildReport, build};
use motionforge::config::Config;
use serde_json::{Value, json};

/// A chat server that answers like a (well-behaved) model, by prompt kind, and counts requests.
struct Server {
    base_url: String,
    requests: Arc<AtomicUsize>,
    prompts: Arc<Mutex<Vec<String>>>,
    _runtime: tokio::runtime::Runtime,
}

#[derive(Clone)]
struct ServerState {
    requests: Arc<AtomicUsize>,
    prompts: Arc<Mutex<Vec<String>>>,
    /// Answer every part-label request with a 500.
    fail_labels: bool,
}

fn answer_for(prompt: &str) -> String {
    if prompt.contains("body parts involved") {
        // One answer with a word outside the list, to see it flagged.
        if prompt.contains("action of: kick?") {
            return "Answer: right leg\nhips and the soul".into();
        }
        return "Answer: right arm\nleft arm".into();
    }
    if prompt.contains("different descriptions") {
        return "1. A person does it calmly.\n2. Someone turns to the left while doing it.\n3. A person does it calmly.\n4. The motion is performed once.".into();
    }
    if prompt.contains("at the same time:") {
        // The kick uses the legs: say no to any pair with it.
        return if prompt.contains("kick") {
            "No.".into()
        } else {
            "Yes".into()
        };
    }
    if prompt.contains("target action") {
        // The first answer for every text is invalid (ids from 0); the repair request is fixed.
        if prompt.contains("Your answer was not valid") {
            return r#"[{"step": "stand still", "step_id": 1, "category": "locomotion"}, {"step": "do it", "step_id": 2, "category": "interaction"}]"#.into();
        }
        return r#"[{"step": "stand still", "step_id": 0, "category": "locomotion"}]"#.into();
    }
    "I do not understand.".into()
}

async fn chat(
    State(state): State<ServerState>,
    Json(body): Json<Value>,
) -> axum::response::Response {
    use axum::response::IntoResponse;
    state.requests.fetch_add(1, Ordering::SeqCst);
    let prompt = body["messages"][0]["content"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    state.prompts.lock().unwrap().push(prompt.clone());
    if state.fail_labels && prompt.contains("body parts involved") {
        return (axum::http::StatusCode::INTERNAL_SERVER_ERROR, "overloaded").into_response();
    }
    let content = answer_for(&prompt);
    Json(json!({"choices": [{"index": 0, "message": {"role": "assistant", "content": content}}]}))
        .into_response()
}

impl Server {
    fn start() -> Server {
        Server::start_with(false)
    }

    fn start_with(fail_labels: bool) -> Server {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .unwrap();
        let listener = runtime
            .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
            .unwrap();
        let addr = listener.local_addr().unwrap();
        let state = ServerState {
            requests: Arc::default(),
            prompts: Arc::default(),
            fail_labels,
        };
        let app = Router::new()
            .route("/v1/chat/completions", post(chat))
            .with_state(state.clone());
        runtime.spawn(async move { axum::serve(listener, app).await });
        Server {
            base_url: format!("http://{addr}/v1"),
            requests: state.requests,
            prompts: state.prompts,
            _runtime: runtime,
        }
    }

    fn requests(&self) -> usize {
        self.requests.load(Ordering::SeqCst)
    }
}

/// A scratch build of three real Bandai captures with the given extra config.
fn scratch(extra: &str) -> (tempfile::TempDir, Config) {
    let dir = bandai1_scratch(&WALK_KICK_BYE);
    let text = format!(
        r#"
[dataset]
name = "llm"
output = "out"
{extra}

[[sources]]
name = "bandai"
captures = ["captures/*.bvh"]
profile = "bandai-namco"
[sources.labels]
kind = "filename"
pattern = "dataset-1_{{content}}_{{style}}_{{take}}"
action = "{{content}}"
text = "{{content}}"
"#
    );
    let path = dir.path().join("build.toml");
    fs::write(&path, text).unwrap();
    let config = Config::load(&path).unwrap();
    (dir, config)
}

fn llm_section(server: &Server) -> String {
    format!(
        "[part_labels]\nlabeller = \"llm\"\n\n[llm]\nbase_url = \"{}\"\nmodel = \"test-model\"\nrequests_per_minute = 6000\nbackoff_seconds = 0.01\n",
        server.base_url
    )
}

fn stage<'a>(report: &'a BuildReport, name: &str) -> &'a motionforge::build::StageRun {
    report
        .stages
        .iter()
        .find(|s| s.stage == name)
        .unwrap_or_else(|| panic!("no stage {name}: {:?}", report.stages))
}

#[test]
fn llm_stages_ask_each_text_once_and_a_rebuild_sends_nothing() {
    let server = Server::start();
    let (dir, config) = scratch(&llm_section(&server));
    let first = build(&config, &BuildOptions::default()).unwrap();
    // 3 texts x (labels + paraphrases + plans) + 3 plan repairs.
    assert_eq!(
        server.requests(),
        12,
        "{:?}",
        server.prompts.lock().unwrap()
    );
    assert_eq!(first.labels.requests, 3);
    assert_eq!(
        first.labels.flagged.len(),
        1,
        "the kick answer has words outside the list"
    );
    // `hips` maps to global; `the soul` is flagged, not guessed.
    assert!(
        first.labels.flagged[0].1.contains("soul"),
        "{:?}",
        first.labels.flagged
    );
    assert_eq!(
        first.plans.answered, 3,
        "every plan valid after one repair: {:?}",
        first.plans.rejected
    );
    let rejected: Vec<&str> = first
        .paraphrases
        .rejected
        .iter()
        .map(|(_, r)| r.as_str())
        .collect();
    assert!(
        rejected.contains(&"duplicate")
            && rejected.contains(&"changes the side words (left/right)"),
        "{rejected:?}"
    );

    let out = dir.path().join("out/llm");
    let table = pyarrow_rows(&out.join("data"), "clip_id,parts,label_source,paraphrases");
    let walk = table
        .iter()
        .find(|r| r.contains("walk_normal_001:0-195|"))
        .unwrap();
    assert!(walk.contains("[False, False, True, True, False, False]|llm:test-model|['A person does it calmly.', 'The motion is performed once.']"), "{walk}");
    let walk_m = table
        .iter()
        .find(|r| r.contains("walk_normal_001:0-195:m|"))
        .unwrap();
    assert!(
        walk_m.contains("[False, False, True, True, False, False]|llm:test-model"),
        "arms mirror onto arms: {walk_m}"
    );
    let plans = pyarrow_rows(&out.join("plans.parquet"), "text,step_id,step,category");
    assert_eq!(plans.len(), 6, "{plans:?}");
    assert!(
        plans.contains(&"walk|2|do it|interaction".to_string()),
        "{plans:?}"
    );

    // Nothing changed: no request, no stage re-run.
    let second = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(server.requests(), 12);
    assert!(second.nothing_ran(), "{:?}", second.stages);
    assert_eq!(
        stage(&second, "label").reused,
        3,
        "the three original clips keep their labels"
    );

    // A restart of everything but the cache file: still no request, same table.
    let before = table_bytes(&out);
    fs::remove_dir_all(out.join(".motionforge")).unwrap();
    build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(server.requests(), 12);
    assert!(table_bytes(&out) == before, "same answers, same bytes");
}

#[test]
fn offline_sends_nothing_and_falls_back_as_configured() {
    let server = Server::start();
    let (_dir, config) = scratch(&llm_section(&server));
    let report = build(
        &config,
        &BuildOptions {
            offline: true,
            ..BuildOptions::default()
        },
    )
    .unwrap();
    assert_eq!(server.requests(), 0);
    assert_eq!(report.labels.missing.len(), 3);
    assert!(
        report
            .labels
            .sources
            .keys()
            .all(|s| s.starts_with("embedded:")),
        "{:?}",
        report.labels.sources
    );
    assert_eq!(
        report
            .paraphrases
            .skipped
            .get("offline and not in the cache"),
        Some(&3)
    );
    // With on_miss = "fail", the build stops and lists the texts.
    let (_dir, config) = scratch(&format!(
        "{}\n",
        llm_section(&server).replace(
            "labeller = \"llm\"",
            "labeller = \"llm\"\non_miss = \"fail\""
        )
    ));
    let err = build(
        &config,
        &BuildOptions {
            offline: true,
            ..BuildOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("3 texts have no cached LLM answer") && err.contains("walk"),
        "{err}"
    );
    assert_eq!(server.requests(), 0);
}

#[test]
fn without_an_llm_the_embedded_labeller_labels_and_skips_are_reported() {
    let (dir, config) = scratch("");
    let report = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(
        report.paraphrases.skipped.get("no LLM configured"),
        Some(&3)
    );
    assert_eq!(report.plans.skipped.get("no LLM configured"), Some(&3));
    assert!(
        !dir.path().join("out/llm/llm-cache.jsonl").exists(),
        "no cache file without an LLM"
    );
    let table = pyarrow_rows(
        &dir.path().join("out/llm/data"),
        "clip_id,parts,label_source",
    );
    for row in table.iter().filter(|r| !r.starts_with("synthetic/")) {
        assert!(
            row.contains("|embedded:"),
            "every clip labelled by the embedded labeller: {row}"
        );
    }
    let walk = table
        .iter()
        .find(|r| r.contains("walk_normal_001:0-195|"))
        .unwrap();
    assert!(
        walk.contains("[True, False, False, False, True, True]"),
        "walk: global and both legs: {walk}"
    );
}

#[test]
fn imported_sinc_answers_label_a_build_without_a_request() {
    let dir = tempfile::tempdir().unwrap();
    fs::create_dir_all(dir.path().join("captures")).unwrap();
    fs::copy(
        shared_data().join("cmu/01_01.bvh"),
        dir.path().join("captures/01_01.bvh"),
    )
    .unwrap();
    fs::copy(
        repo().join("fixtures/humanml3d/index-cmu-01_01.csv"),
        dir.path().join("index.csv"),
    )
    .unwrap();
    // No server listens here: any request would fail the labels and show up as `missing`.
    let config_text = r#"
[dataset]
name = "imported"
output = "out"

[part_labels]
labeller = "llm"
offline = true

[llm]
base_url = "http://127.0.0.1:9/v1"
model = "text-davinci-003"
kind = "completion"
max_tokens = 256

[[sources]]
name = "cmu"
captures = ["captures/*.bvh"]
profile = "cmu"
[sources.labels]
kind = "frame_index"
path = "index.csv"
fps = 20
default_text = "jump forward"
[sources.segment]
timeline_offset_frames = 1
"#;
    let config_path = dir.path().join("build.toml");
    fs::write(&config_path, config_text).unwrap();
    let import = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["labels", "import"])
        .arg(shared_data().join("sinc/gpt3-labels-list.json"))
        .arg("--config")
        .arg(&config_path)
        .output()
        .unwrap();
    assert!(
        import.status.success(),
        "{}",
        String::from_utf8_lossy(&import.stderr)
    );
    let printed = String::from_utf8(import.stdout).unwrap();
    // 6,518 texts; two differ only in case or spacing and share one prompt.
    assert!(
        printed.contains("imported 6517 answers") && printed.contains("(1 already there)"),
        "{printed}"
    );
    assert!(
        printed.contains("12 answers use words outside the prompt's list"),
        "{printed}"
    );
    let config = Config::load(&config_path).unwrap();
    let report = build(
        &config,
        &BuildOptions {
            offline: true,
            ..BuildOptions::default()
        },
    )
    .unwrap();
    assert!(
        report.labels.missing.is_empty(),
        "{:?}",
        report.labels.missing
    );
    assert_eq!(report.labels.cache_hits, 1);
    // Both crops are labelled from the import (sources count originals; mirrors inherit them).
    assert_eq!(
        report.labels.sources.get("import:gpt3-labels-list.json"),
        Some(&2),
        "{:?}",
        report.labels.sources
    );
}

#[test]
fn labels_eval_puts_gpt3_and_the_embedded_labeller_side_by_side() {
    let out = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["labels", "eval", "--gold"])
        .arg(shared_data().join("sinc/part-labels-gold-dev.json"))
        .arg("--source")
        .arg(shared_data().join("sinc/gpt3-labels-list.json"))
        .args(["--source", "embedded", "--json"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let mean = |source: &str| v[source]["mean"].as_f64().unwrap();
    let gpt3 = shared_data()
        .join("sinc/gpt3-labels-list.json")
        .display()
        .to_string();
    assert!((mean(&gpt3) - 0.8913).abs() < 1e-3, "{v}");
    assert!(
        mean("embedded") >= mean(&gpt3),
        "the embedded labeller reaches GPT-3's accuracy: {v}"
    );
}

#[test]
fn prompt_render_prints_the_exact_prompt_and_names_unknown_templates() {
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .args(args)
            .output()
            .unwrap()
    };
    let out = run(&[
        "prompt",
        "render",
        "part_labels",
        "--text",
        "wave with the right hand",
    ]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.starts_with("The instructions for this task are to choose\n"));
    assert!(text.ends_with("action of: wave with the right hand?\n"));
    let out = run(&["prompt", "render", "task_plan", "--text", "watch TV"]);
    assert!(
        String::from_utf8(out.stdout)
            .unwrap()
            // Texts are asked normalised (lowercase, single spaces), as the build asks them.
            .contains("The target action is: watch tv.")
    );
    let out = run(&["prompt", "render", "haiku", "--text", "x"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no prompt template `haiku`"));
}

#[test]
fn a_request_that_fails_after_its_retries_is_rejected_and_the_build_goes_on() {
    let server = Server::start_with(true);
    let extra = llm_section(&server).replace(
        "backoff_seconds = 0.01",
        "backoff_seconds = 0.01\nmax_retries = 2",
    );
    let (_dir, config) = scratch(&extra);
    let report = build(&config, &BuildOptions::default()).unwrap();
    let label_rejects: Vec<_> = report
        .rejects
        .iter()
        .filter(|r| r.stage == "label")
        .collect();
    assert_eq!(
        label_rejects.len(),
        3,
        "{:?} / missing {:?} / sources {:?}",
        report.rejects,
        report.labels.missing,
        report.labels.sources
    );
    assert!(
        label_rejects
            .iter()
            .all(|r| r.reason.as_str() == "llm_request" && r.message.contains("500")),
        "{label_rejects:?}"
    );
    // The clips were still labelled, by the configured fallback, and the other stages ran.
    assert!(
        report
            .labels
            .sources
            .keys()
            .all(|s| s.starts_with("embedded:")),
        "{:?}",
        report.labels.sources
    );
    assert_eq!(report.kinds.get("real_single"), Some(&6));
    assert_eq!(report.plans.answered, 3);
}

#[test]
fn the_optional_llm_pair_check_drops_pairs_it_says_no_to() {
    let server = Server::start();
    let extra = format!(
        "[splits]\nratios = {{ train = 1.0 }}\n\n[synthetic]\nexhaustive = true\nllm_check = true\n\n[task_plans]\nenabled = false\n\n[paraphrases]\nenabled = false\n\n{}",
        llm_section(&server).replace("labeller = \"llm\"", "labeller = \"embedded\"")
    );
    let (_dir, config) = scratch(&extra);
    let first = build(&config, &BuildOptions::default()).unwrap();
    let asked = server.requests();
    assert!(asked > 0, "pairs were asked about");
    assert_eq!(first.pair_check.requests, asked);
    let vetoed = first
        .synthetic
        .dropped
        .get("llm_incompatible")
        .copied()
        .unwrap_or(0);
    assert!(vetoed > 0, "{:?}", first.synthetic);
    assert_eq!(
        first.synthetic.sampled,
        first.synthetic.composed + first.synthetic.dropped.values().sum::<usize>()
    );
    let again = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(server.requests(), asked, "answers come from the cache");
    assert!(again.nothing_ran(), "{:?}", again.stages);
}
