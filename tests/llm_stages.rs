//! The LLM stages inside a build: a real OpenAI-compatible server on loopback, the response cache,
//! `--offline`, imported SINC answers, and the embedded labeller when no LLM is configured.
use crate::common;

use std::fs;
use std::process::Command;
use std::sync::{Arc, Mutex};

use common::llm::{LlmServer, Reply, dead_url};
use common::project::{ConfigSpec, Project, Source};
use common::*;
use motionforge::build::{BuildOptions, BuildReport, build};
use motionforge::config::Config;
use serde_json::{Value, json};

/// How the server misbehaves.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Mode {
    /// Answers like a capable model.
    Good,
    /// Every part-label request gets a 500.
    FailLabels,
    /// Paraphrases as a small model gave them: template tokens, links, more lines than asked.
    JunkParaphrases,
    /// Paraphrases cut off (`finish_reason: "length"`) below 400 tokens; part labels always.
    Truncated,
    /// Every part-label answer has words outside the list or no part at all.
    FlaggedLabels,
}

/// The action text a paraphrase prompt asks about.
fn paraphrase_text(prompt: &str) -> String {
    prompt
        .split("motion: \"")
        .nth(1)
        .and_then(|rest| rest.split('"').next())
        .unwrap_or_default()
        .to_string()
}

/// The answer and its finish reason.
fn reply_for(prompt: &str, mode: Mode, max_tokens: u64) -> (String, &'static str) {
    let labels = prompt.contains("body parts involved");
    let paraphrase = prompt.contains("different descriptions");
    match mode {
        Mode::JunkParaphrases if paraphrase && paraphrase_text(prompt) == "kick" => {
            // A bare newline, as Gemma 3 270M answered with the Llama 2 chat format.
            return ("\n".into(), "stop");
        }
        Mode::JunkParaphrases if paraphrase => {
            let t = paraphrase_text(prompt);
            return (
                format!(
                    "[/INST]\n[IMG]http://www.youtube.com/watch?v=x1[/IMG]\n1. A person does a {t} slowly.\n2. Someone does a {t} with energy.\n3. The person sits down.\n4. A person does a {t} again.\n5. Someone does a {t} twice.\n6. A {t} happens.\n7. A {t} is done.\n8. One more {t}."
                ),
                "stop",
            );
        }
        Mode::Truncated if labels => return ("Answer: right ar".into(), "length"),
        Mode::Truncated if paraphrase && max_tokens < 400 => {
            return ("someone performs guide, chil".into(), "length");
        }
        Mode::FlaggedLabels if labels => {
            return if prompt.contains("action of: walk?") {
                (
                    "question what are the body parts involved in the action".into(),
                    "stop",
                )
            } else {
                ("Answer: right arm\nthe soul".into(), "stop")
            };
        }
        _ => {}
    }
    (answer_for(prompt), "stop")
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
        let t = paraphrase_text(prompt);
        return format!(
            "1. A person does a {t} calmly.\n2. Someone turns to the left during the {t}.\n3. The {t} is performed once.\n4. A person does a {t} calmly."
        );
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

/// A chat server that answers like a (well-behaved) model, by prompt kind, unless `mode` says.
fn start(mode: Mode) -> LlmServer {
    LlmServer::answering(move |request| {
        let prompt = request.prompt();
        if mode == Mode::FailLabels && prompt.contains("body parts involved") {
            return Reply::Status(500, "overloaded", None);
        }
        let (content, finish_reason) = reply_for(prompt, mode, request.max_tokens());
        Reply::Answer(content, finish_reason)
    })
}

/// Progress events of a build, as words.
#[derive(Default)]
struct Recorder(Mutex<Vec<String>>);

impl motionforge::progress::Progress for Recorder {
    fn requests_started(&self, stage: &str, total: u64) {
        self.0
            .lock()
            .unwrap()
            .push(format!("requests {stage} {total}"));
    }
    fn advanced(&self, stage: &str, n: u64) {
        self.0.lock().unwrap().push(format!("advanced {stage} {n}"));
    }
    fn failed(&self, stage: &str, n: u64) {
        self.0.lock().unwrap().push(format!("failed {stage} {n}"));
    }
}

/// A scratch build of three real Bandai captures with the given config.
fn scratch(spec: ConfigSpec) -> (Project, Config) {
    let project = Project::new()
        .captures("bandai-namco-1", &WALK_KICK_BYE)
        .config(spec)
        .build();
    let config = project.load();
    (project, config)
}

/// The three captures labelled from their file names, no LLM.
fn spec() -> ConfigSpec {
    ConfigSpec::new("llm").source(Source::bandai1("bandai"))
}

/// [`spec`] with `[llm]` at `server` and its part labeller.
fn llm_spec(server: &LlmServer) -> ConfigSpec {
    spec()
        .set("part_labels.labeller", "llm")
        .llm(&server.base_url())
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
    let server = start(Mode::Good);
    let (dir, config) = scratch(llm_spec(&server));
    let first = build(&config, &BuildOptions::default()).unwrap();
    // 3 texts x (labels + paraphrases + plans) + 3 plan repairs.
    assert_eq!(server.requests(), 12, "{:?}", server.prompts());
    // One client for the build's LLM stages (one rate limit, one circuit breaker): one probe.
    assert_eq!(server.listings(), 1);
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
        rejected.contains(&"more alternatives than asked")
            && rejected.contains(&"changes the side words (left/right)"),
        "{rejected:?}"
    );
    // The kick's flagged answer fell back to the embedded labeller.
    assert_eq!(first.labels.checks.accepted, 2);
    assert_eq!(first.labels.checks.fell_back, 1);

    let out = dir.path().join("out/llm");
    let table = pyarrow_rows(&out.join("data"), "clip_id,parts,label_source,paraphrases");
    let walk = table
        .iter()
        .find(|r| r.contains("walk_normal_001:0-195|"))
        .unwrap();
    assert!(walk.contains("[False, False, True, True, False, False]|llm:test-model|['A person does a walk calmly.', 'The walk is performed once.']"), "{walk}");
    let kick = table
        .iter()
        .find(|r| r.contains("kick_normal_001:") && !r.contains(":m|"))
        .unwrap();
    assert!(kick.contains("|embedded:lexicon|"), "{kick}");
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
    let server = start(Mode::Good);
    let (_dir, config) = scratch(llm_spec(&server));
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
    let (_dir, config) = scratch(llm_spec(&server).set("part_labels.on_miss", "fail"));
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
    let (dir, config) = scratch(spec());
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
    // No server listens here: any request would fail the labels and show up as `missing`.
    let spec = ConfigSpec::new("imported")
        .set("part_labels.labeller", "llm")
        .set("part_labels.offline", true)
        .set("llm.base_url", dead_url())
        .set("llm.model", "text-davinci-003")
        .set("llm.kind", "completion")
        .set("llm.max_tokens", 256)
        .source(
            Source::new("cmu", "cmu", &["captures/*.bvh"])
                .set("labels.kind", "frame_index")
                .set("labels.path", "index.csv")
                .set("labels.fps", 20)
                .set("labels.default_text", "jump forward")
                .set("segment.timeline_offset_frames", 1),
        );
    let project = Project::new()
        .copy(shared_data().join("cmu/01_01.bvh"), "captures/01_01.bvh")
        .copy(
            repo().join("fixtures/humanml3d/index-cmu-01_01.csv"),
            "index.csv",
        )
        .config(spec)
        .build();
    let config_path = project.config_path();
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
    let server = start(Mode::FailLabels);
    let (_dir, config) = scratch(llm_spec(&server).set("llm.max_retries", 2));
    let recorder = Arc::new(Recorder::default());
    let report = build(
        &config,
        &BuildOptions {
            progress: motionforge::progress::ProgressSink::new(recorder.clone()),
            ..BuildOptions::default()
        },
    )
    .unwrap();
    // The label stage showed its requests as they went: 3 sent, 3 failed.
    let events = recorder.0.lock().unwrap().clone();
    assert!(
        events.contains(&"requests label 3".to_string()),
        "{events:?}"
    );
    assert_eq!(
        events.iter().filter(|e| *e == "advanced label 1").count(),
        3
    );
    assert_eq!(events.iter().filter(|e| *e == "failed label 1").count(), 3);
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
    let server = start(Mode::Good);
    let spec = llm_spec(&server)
        .set("part_labels.labeller", "embedded")
        .set("splits.ratios.train", 1.0)
        .set("synthetic.exhaustive", true)
        .set("synthetic.llm_check", true)
        .set("task_plans.enabled", false)
        .set("paraphrases.enabled", false);
    let (_dir, config) = scratch(spec);
    let first = build(&config, &BuildOptions::default()).unwrap();
    let asked = server.requests();
    assert!(asked > 0, "pairs were asked about");
    assert_eq!(first.pair_check.requests, asked);
    // The pair check is a stage of its own: each distinct text pair asked once.
    let run = stage(&first, "pair_check");
    assert_eq!((run.items, run.ran), (first.pair_check.texts, asked));
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

/// `build-report.json` of a built scratch dataset.
fn report_json(dir: &Project) -> Value {
    let text = fs::read_to_string(dir.path().join("out/llm/build-report.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn junk_paraphrases_are_refused_by_reason_counted_and_settled() {
    let server = start(Mode::JunkParaphrases);
    let spec = llm_spec(&server).set("task_plans.enabled", false);
    let (dir, config) = scratch(spec.clone());
    let first = build(&config, &BuildOptions::default()).unwrap();
    // Walk and bye: two template lines, two good lines, a line about sitting (the third asked),
    // and five lines beyond the three asked. Kick: an empty answer.
    let checks = &first.paraphrases.checks;
    assert_eq!(checks.accepted, 4, "{checks:?}");
    assert_eq!(
        checks.rejected_by_reason.to_names(),
        [
            ("action", 2),
            ("beyond_count", 10),
            ("empty", 1),
            ("markup", 4)
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect(),
        "{:?}",
        first.paraphrases.rejected
    );
    assert_eq!((checks.dropped, checks.kept), (17, 0));
    let json = report_json(&dir);
    let reasons = &json["paraphrases"]["checks"]["rejected_by_reason"];
    assert_eq!(
        (&reasons["markup"], &reasons["empty"]),
        (&json!(4), &json!(1))
    );
    assert_eq!(json["paraphrases"]["checks"]["dropped"], 17);
    let table = pyarrow_rows(&dir.path().join("out/llm/data"), "clip_id,paraphrases");
    let walk = table
        .iter()
        .find(|r| r.contains("walk_normal_001:0-195|"))
        .unwrap();
    assert!(
        walk.ends_with("|['A person does a walk slowly.', 'Someone does a walk with energy.']"),
        "{walk}"
    );
    assert!(
        table
            .iter()
            .all(|r| !r.contains("INST") && !r.contains("http")),
        "{table:?}"
    );
    let asked = server.requests();
    let second = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(
        server.requests(),
        asked,
        "settled answers are not asked again"
    );
    assert!(second.nothing_ran(), "{:?}", second.stages);
    assert_eq!(second.paraphrases.checks, first.paraphrases.checks);

    // `keep` keeps the refused lines (duplicates aside) and counts them.
    let (_dir, config) = scratch(spec.set("paraphrases.on_invalid", "keep"));
    let kept = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(
        (
            kept.paraphrases.checks.kept,
            kept.paraphrases.checks.dropped
        ),
        (16, 1),
        "an empty answer has nothing to keep"
    );
}

#[test]
fn cut_off_answers_are_retried_with_more_tokens_never_cached_and_asked_again() {
    let server = start(Mode::Truncated);
    let (dir, config) = scratch(llm_spec(&server).set("llm.retry_max_tokens", 400));
    let first = build(&config, &BuildOptions::default()).unwrap();
    // Labels: cut off at 256 and at 400 (2 each); paraphrases: cut off at 256, whole at 400 (2
    // each); plans: 3 and 3 repairs.
    assert_eq!(server.requests(), 18, "{:?}", server.prompts());
    assert_eq!(first.labels.checks.truncated, 3);
    assert_eq!(first.paraphrases.checks.truncated, 0);
    assert_eq!(first.paraphrases.answered, 3);
    let label_rejects: Vec<_> = first
        .rejects
        .iter()
        .filter(|r| r.stage == "label")
        .collect();
    assert_eq!(label_rejects.len(), 3);
    assert!(
        label_rejects
            .iter()
            .all(|r| r.message.contains("cut off at max_tokens = 400")),
        "{label_rejects:?}"
    );
    assert!(
        first
            .labels
            .sources
            .keys()
            .all(|s| s.starts_with("embedded:")),
        "{:?}",
        first.labels.sources
    );
    assert_eq!(report_json(&dir)["labels"]["checks"]["truncated"], 3);
    let cache = fs::read_to_string(dir.path().join("out/llm/llm-cache.jsonl")).unwrap();
    assert_eq!(
        cache.lines().count(),
        9,
        "3 paraphrases, 3 plans, 3 repairs"
    );
    assert!(!cache.contains("guide, chil") && !cache.contains("right ar\""));
    assert!(
        cache
            .lines()
            .all(|l| l.contains(r#""finish_reason":"stop""#)),
        "{cache}"
    );
    assert_eq!(cache.matches(r#""max_tokens":400"#).count(), 3);
    // The rebuild asks only the labels again (cut off: not settled), 2 requests each.
    let second = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(server.requests(), 24);
    assert_eq!(second.paraphrases.requests + second.plans.requests, 0);
    assert_eq!(second.labels.requests, 0, "no label was answered");
}

#[test]
fn flagged_labels_fall_back_drop_or_stay_as_configured() {
    let server = start(Mode::FlaggedLabels);
    let base = llm_spec(&server)
        .set("task_plans.enabled", false)
        .set("paraphrases.enabled", false);
    let originals = |dir: &Project| -> Vec<String> {
        let mut rows: Vec<String> = pyarrow_rows(
            &dir.path().join("out/llm/data"),
            "clip_id,parts,label_source",
        )
        .into_iter()
        .filter(|r| r.starts_with("bandai/") && !r.contains(":m|"))
        .collect();
        rows.sort();
        rows
    };

    // Default: the embedded labeller, and the label source says so.
    let (dir, config) = scratch(base.clone());
    let report = build(&config, &BuildOptions::default()).unwrap();
    let c = &report.labels.checks;
    assert_eq!(c.accepted, 0);
    assert_eq!(c.rejected_by_reason.get("no_part"), Some(&1), "{c:?}");
    assert_eq!(c.rejected_by_reason.get("off_list"), Some(&2), "{c:?}");
    assert_eq!((c.fell_back, c.dropped, c.kept), (3, 0, 0));
    assert_eq!(report.labels.flagged.len(), 3);
    let rows = originals(&dir);
    assert_eq!(rows.len(), 3, "{rows:?}");
    assert!(rows.iter().all(|r| r.contains("|embedded:")), "{rows:?}");
    let asked = server.requests();
    build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(server.requests(), asked, "flagged answers are settled too");

    // drop: no parts at all.
    let (dir, config) = scratch(base.clone().set("part_labels.on_invalid", "drop"));
    let report = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(report.labels.checks.dropped, 3);
    let rows = originals(&dir);
    assert!(rows.iter().all(|r| r.ends_with("|None|None")), "{rows:?}");

    // keep: the answer's parts, marked as the LLM's; the answer with no part gets the motion's.
    let keep = base.set("part_labels.on_invalid", "keep");
    let (dir, config) = scratch(keep.clone());
    let report = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(report.labels.checks.kept, 3);
    let rows = originals(&dir);
    let bye = rows.iter().find(|r| r.contains("bye_normal")).unwrap();
    assert!(
        bye.ends_with("|[False, False, False, True, False, False]|llm:test-model"),
        "{bye}"
    );
    let walk = rows.iter().find(|r| r.contains("walk_normal")).unwrap();
    assert!(walk.ends_with("|embedded:velocity"), "{walk}");

    // Paraphrases have no embedded fallback: the config says so.
    let path = keep
        .set("paraphrases.on_invalid", "embedded")
        .write(dir.join("bad.toml"));
    let err = Config::load(&path).unwrap_err().to_string();
    assert!(
        err.contains("paraphrases.on_invalid") && err.contains("no embedded paraphraser"),
        "{err}"
    );
}

#[test]
fn a_dead_endpoint_stops_the_build_within_seconds_with_one_clear_error() {
    let url = dead_url();
    // Retries and backoff at their defaults: 6 attempts per prompt, up to a minute apart.
    let (dir, config) = scratch(
        spec()
            .set("part_labels.labeller", "llm")
            .set("llm.base_url", url.as_str())
            .set("llm.model", "m"),
    );
    let t = std::time::Instant::now();
    let err = build(&config, &BuildOptions::default())
        .unwrap_err()
        .to_string();
    let elapsed = t.elapsed();
    assert!(
        elapsed < std::time::Duration::from_secs(10),
        "took {elapsed:?}"
    );
    assert!(
        err.starts_with("label: no LLM server answers at ")
            && err.contains(&format!("GET {url}/models"))
            && err.contains("--offline"),
        "{err}"
    );

    // The binary: exit code 1, the error once, in seconds.
    let t = std::time::Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["build", "--config"])
        .arg(dir.config_path())
        .output()
        .unwrap();
    assert!(t.elapsed() < std::time::Duration::from_secs(10));
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        stderr.matches("no LLM server answers").count(),
        1,
        "{stderr}"
    );

    // `config check --probe` tries it too; without --probe the config is fine.
    let check = |probe: bool| {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_motionforge"));
        cmd.args(["config", "check", "--config"])
            .arg(dir.config_path());
        if probe {
            cmd.arg("--probe");
        }
        cmd.output().unwrap()
    };
    assert!(check(false).status.success());
    let probed = check(true);
    assert_eq!(probed.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&probed.stderr).contains("no LLM server answers"));

    // With a server there, the probe says what answered (one without a model list).
    let server = LlmServer::builder().without_models().start();
    let (dir, _config) = scratch(llm_spec(&server));
    let out = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["config", "check", "--probe", "--config"])
        .arg(dir.config_path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains(&format!(
            "answered GET {}/models with HTTP 404",
            server.base_url()
        )),
        "{stdout}"
    );
    assert_eq!(server.requests(), 0, "the probe sends no prompt");
}
