//! Once, against a real LLM server (llama.cpp with Gemma 3 270M; recipe in docs/llm-real-run.md).
//! Ignored by default: run with
//! `MOTIONFORGE_LLM_URL=http://127.0.0.1:8081/v1 cargo test --test builds llm_real:: -- --ignored --nocapture`.
use crate::common;

use std::fs;

use common::project::{ConfigSpec, Project, Source};
use common::*;
use motionforge::build::{BuildOptions, build};

#[test]
#[ignore = "needs a local OpenAI-compatible server; see docs/llm-real-run.md"]
fn a_real_server_labels_paraphrases_and_plans_and_a_rebuild_asks_nothing() {
    let url = std::env::var("MOTIONFORGE_LLM_URL")
        .expect("set MOTIONFORGE_LLM_URL, e.g. http://127.0.0.1:8081/v1");
    let model = std::env::var("MOTIONFORGE_LLM_MODEL").unwrap_or_else(|_| "gemma-3-270m".into());
    let spec = ConfigSpec::new("real-llm")
        .set("part_labels.labeller", "llm")
        .set("paraphrases.n", 3)
        .set("llm.base_url", url)
        .set("llm.model", model)
        .set("llm.temperature", 0)
        .set("llm.max_tokens", 200)
        .set("llm.retry_max_tokens", 400)
        .set("llm.seed", 7)
        .set("llm.concurrency", 1)
        .set("llm.requests_per_minute", 600)
        .set("llm.timeout_seconds", 120)
        .source(Source::bandai1("bandai").set("labels.text", "a person does a {content}"));
    let dir = Project::new()
        .captures("bandai-namco-1", &WALK_KICK_BYE)
        .config(spec)
        .build();
    let config = dir.load();
    let first = build(&config, &BuildOptions::default()).unwrap();
    println!(
        "labels: {:#?}\nparaphrases: {:#?}\nplans: {:#?}",
        first.labels, first.paraphrases, first.plans
    );
    for (stage, c) in [
        ("labels", &first.labels.checks),
        ("paraphrases", &first.paraphrases.checks),
        ("plans", &first.plans.checks),
    ] {
        println!(
            "{stage}: accepted {}, rejected {:?}, fell back {}, dropped {}, kept {}, cut off {}",
            c.accepted, c.rejected_by_reason, c.fell_back, c.dropped, c.kept, c.truncated
        );
    }
    // What the model said, as cached (cut-off answers are not).
    let cache = dir.path().join("out/real-llm/llm-cache.jsonl");
    for line in fs::read_to_string(&cache).unwrap_or_default().lines() {
        let record: serde_json::Value = serde_json::from_str(line).unwrap();
        println!(
            "cached ({}): {:?} -> {:?}",
            record["finish_reason"], record["prompt_preview"], record["response"]
        );
    }
    let l = &first.labels;
    // Every label answer is accounted for: accepted, refused (and handled), or cut off.
    assert_eq!(
        l.checks.accepted + l.checks.rejected() + l.checks.truncated,
        3,
        "{l:?}"
    );
    assert_eq!(
        l.checks.rejected(),
        l.checks.fell_back,
        "on_invalid = embedded"
    );
    // One request per unique text at least: answered, or failed (cut off) and listed.
    assert!(l.requests + l.missing.len() >= 3, "{l:?}");
    assert!(first.paraphrases.requests + first.paraphrases.skipped.values().sum::<usize>() >= 3);
    // The rebuild asks only what was not settled: answers cut off even with retry_max_tokens.
    let unsettled = l.checks.truncated + first.paraphrases.checks.truncated;
    let second = build(&config, &BuildOptions::default()).unwrap();
    let asked = second.labels.requests + second.paraphrases.requests + second.plans.requests;
    assert!(
        asked <= 2 * unsettled + first.plans.checks.truncated * 2,
        "asked {asked}"
    );
    if unsettled == 0 && first.plans.checks.truncated == 0 {
        assert_eq!(asked, 0);
        assert!(second.nothing_ran(), "{:?}", second.stages);
    }
}
