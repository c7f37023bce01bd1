//! The LLM client and response cache over real HTTP on loopback: a scripted axum server plays an
//! OpenAI-compatible endpoint (success, 429 with Retry-After, 5xx, hangs, malformed bodies, 400s)
//! and counts what it receives.

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use serde_json::json;

use crate::common::llm::{LlmServer, Reply, Request, dead_url};
use motionforge::llm::cache::{CacheEntry, CacheKey, ResponseCache};
use motionforge::llm::client::{
    Answer, LlmClient, LlmConfig, LlmError, RequestKind, SamplingParams,
};

/// A config for `server` that retries fast and is not rate limited in practice.
fn fast_config(server: &LlmServer) -> LlmConfig {
    LlmConfig {
        requests_per_minute: 600_000,
        backoff_seconds: 0.01,
        timeout_seconds: 10.0,
        max_retries: 3,
        ..LlmConfig::new(&server.base_url(), "test-model")
    }
}

/// Below `limit` max tokens, a cut-off answer (`finish_reason: "length"`); else an echo.
fn cut_below(limit: u64) -> impl Fn(&Request) -> Reply + Send + Sync + 'static {
    move |request| {
        if request.max_tokens() < limit {
            Reply::cut("someone performs guide, chil")
        } else {
            Reply::Echo
        }
    }
}

fn strings(items: &[&str]) -> Vec<String> {
    items.iter().map(|s| s.to_string()).collect()
}

fn open_cache(dir: &Path) -> ResponseCache {
    ResponseCache::open(&dir.join("llm").join("responses.jsonl")).unwrap()
}

fn answer(r: &Result<Answer, LlmError>) -> &Answer {
    r.as_ref()
        .unwrap_or_else(|e| panic!("expected an answer, got {e}"))
}

#[test]
fn chat_success_sends_the_documented_request() {
    let server = LlmServer::echo();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        seed: Some(7),
        temperature: 0.5,
        max_tokens: 32,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let results = client.complete_all(&strings(&["hello"]), &mut cache);
    assert_eq!(
        answer(&results[0]),
        &Answer {
            text: "echo: hello".into(),
            from_cache: false
        }
    );
    assert_eq!(server.requests(), 1);
    let seen = &server.seen()[0];
    assert_eq!(seen.path, "/v1/chat/completions");
    assert_eq!(seen.auth, None, "no api_key_env, no Authorization header");
    assert_eq!(seen.body["model"], "test-model");
    assert_eq!(
        seen.body["messages"],
        json!([{"role": "user", "content": "hello"}])
    );
    assert_eq!(seen.body["temperature"], 0.5);
    assert_eq!(seen.body["max_tokens"], 32);
    assert_eq!(seen.body["seed"], 7);
    assert_eq!(cache.len(), 1);
    assert_eq!(cache.get(&client.key("hello")), Some("echo: hello"));
    let entry = cache.get_entry(&client.key("hello")).unwrap();
    assert_eq!(entry.source, "llm");
    assert_eq!(entry.kind, RequestKind::Chat);
    assert_eq!(entry.prompt_preview, "hello");
}

#[test]
fn completion_success_uses_the_completions_endpoint() {
    let server = LlmServer::echo();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        kind: RequestKind::Completion,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let results = client.complete_all(&strings(&["once upon"]), &mut cache);
    assert_eq!(answer(&results[0]).text, "echo: once upon");
    let seen = &server.seen()[0];
    assert_eq!(seen.path, "/v1/completions");
    assert_eq!(seen.body["prompt"], "once upon");
    assert!(seen.body.get("messages").is_none());
    assert!(
        seen.body.get("seed").is_none(),
        "seed is only sent when set"
    );
    // Chat and completion answers are cached apart.
    let chat_key = LlmConfig::new(&server.base_url(), "test-model").cache_key("once upon");
    assert_ne!(client.key("once upon"), chat_key);
}

#[test]
fn retry_after_on_429_is_respected() {
    let server = LlmServer::builder()
        .script(vec![Reply::Status(429, "slow down", Some("1"))])
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let client = LlmClient::new(fast_config(&server)).unwrap();
    let t = Instant::now();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    let elapsed = t.elapsed();
    assert_eq!(answer(&results[0]).text, "echo: p");
    assert_eq!(server.requests(), 2);
    let seen = server.seen();
    let gap = seen[1].at - seen[0].at;
    assert!(gap >= Duration::from_secs(1), "retried after {gap:?}");
    assert!(elapsed >= Duration::from_secs(1));
    assert!(elapsed < Duration::from_secs(5), "took {elapsed:?}");
}

#[test]
fn retry_after_is_capped_by_config() {
    let server = LlmServer::builder()
        .script(vec![Reply::Status(503, "loading model", Some("30"))])
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        max_retry_after_seconds: 0.2,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let t = Instant::now();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    assert_eq!(answer(&results[0]).text, "echo: p");
    let seen = server.seen();
    let gap = seen[1].at - seen[0].at;
    assert!(gap >= Duration::from_millis(200), "retried after {gap:?}");
    assert!(t.elapsed() < Duration::from_secs(5));
}

#[test]
fn server_errors_are_retried_then_succeed() {
    let server = LlmServer::builder()
        .script(vec![
            Reply::Status(500, "boom", None),
            Reply::Status(500, "boom", None),
        ])
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let client = LlmClient::new(fast_config(&server)).unwrap();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    assert_eq!(answer(&results[0]).text, "echo: p");
    assert_eq!(server.requests(), 3);
    assert_eq!(cache.len(), 1);
}

#[test]
fn server_errors_exhaust_retries() {
    let server = LlmServer::builder()
        .default(Reply::Status(502, "bad gateway", None))
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        max_retries: 2,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    assert_eq!(
        results[0],
        Err(LlmError::Http {
            status: 502,
            body_preview: "bad gateway".into(),
            attempts: 3
        })
    );
    assert_eq!(server.requests(), 3);
    assert!(cache.is_empty());
}

#[test]
fn hanging_response_times_out_then_retry_succeeds() {
    let server = LlmServer::builder()
        .script(vec![Reply::Hang(Duration::from_secs(5))])
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        timeout_seconds: 0.3,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let t = Instant::now();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    let elapsed = t.elapsed();
    assert_eq!(answer(&results[0]).text, "echo: p");
    assert_eq!(server.requests(), 2);
    assert!(elapsed >= Duration::from_millis(300), "took {elapsed:?}");
    assert!(elapsed < Duration::from_secs(3), "took {elapsed:?}");
}

#[test]
fn hanging_every_time_gives_timeout() {
    let server = LlmServer::builder()
        .default(Reply::Hang(Duration::from_secs(5)))
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        timeout_seconds: 0.2,
        max_retries: 1,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    assert_eq!(results[0], Err(LlmError::Timeout { attempts: 2 }));
    assert_eq!(server.requests(), 2);
}

#[test]
fn malformed_json_is_retried() {
    let server = LlmServer::builder()
        .script(vec![Reply::Raw("{\"choices\": [ {\"mess")])
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let client = LlmClient::new(fast_config(&server)).unwrap();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    assert_eq!(answer(&results[0]).text, "echo: p");
    assert_eq!(server.requests(), 2);
}

#[test]
fn malformed_json_every_time_is_a_bad_response() {
    let server = LlmServer::builder()
        .default(Reply::Raw("<html>not json</html>"))
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        max_retries: 1,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    match &results[0] {
        Err(LlmError::BadResponse { message, attempts }) => {
            assert_eq!(*attempts, 2);
            assert!(message.contains("not JSON"), "{message}");
            assert!(message.contains("<html>"), "{message}");
        }
        other => panic!("expected BadResponse, got {other:?}"),
    }
    assert!(cache.is_empty());
}

#[test]
fn no_choices_is_a_bad_response_after_retries() {
    let server = LlmServer::builder()
        .default(Reply::Raw(
            r#"{"object": "chat.completion", "choices": []}"#,
        ))
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        max_retries: 2,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    match &results[0] {
        Err(LlmError::BadResponse { message, attempts }) => {
            assert_eq!(*attempts, 3);
            assert!(message.contains("no choices"), "{message}");
        }
        other => panic!("expected BadResponse, got {other:?}"),
    }
    assert_eq!(server.requests(), 3);
    assert!(cache.is_empty());
}

#[test]
fn client_error_is_not_retried() {
    let body = "{\"error\": {\"message\": \"model 'test-model' not found\"}}";
    let server = LlmServer::builder()
        .default(Reply::Status(400, body, None))
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let client = LlmClient::new(fast_config(&server)).unwrap();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    match &results[0] {
        Err(
            e @ LlmError::Http {
                status,
                body_preview,
                attempts,
            },
        ) => {
            assert_eq!(*status, 400);
            assert_eq!(*attempts, 1);
            assert!(body_preview.contains("not found"), "{body_preview}");
            assert!(e.to_string().contains("HTTP 400"), "{e}");
        }
        other => panic!("expected Http, got {other:?}"),
    }
    assert_eq!(server.requests(), 1);
}

#[test]
fn nothing_listening_fails_the_probe_at_once_and_sends_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let url = dead_url();
    let config = LlmConfig {
        backoff_seconds: 1.0,
        max_retries: 5,
        ..LlmConfig::new(&url, "m")
    };
    let client = LlmClient::new(config).unwrap();
    let t = Instant::now();
    let results = client.complete_all(&strings(&["p", "q", "r"]), &mut cache);
    let elapsed = t.elapsed();
    // Without the probe: 3 prompts x 6 attempts with up to 63 s of backoff each.
    assert!(elapsed < Duration::from_secs(2), "took {elapsed:?}");
    for r in &results {
        match r {
            Err(e @ LlmError::Unreachable { url: u, .. }) => {
                assert_eq!(u, &url);
                assert!(e.stops_stage());
                let text = e.to_string();
                assert!(
                    text.contains(&format!("GET {url}/models"))
                        && text.contains("--offline")
                        && text.contains("llama-server"),
                    "{text}"
                );
            }
            other => panic!("expected Unreachable, got {other:?}"),
        }
    }
    assert_eq!(cache.len(), 0);
    assert!(matches!(client.probe(), Err(LlmError::Unreachable { .. })));
}

#[test]
fn the_circuit_breaker_stops_sending_when_the_server_goes_away() {
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let server = LlmServer::echo();
    let config = LlmConfig {
        max_retries: 5,
        backoff_seconds: 0.05,
        concurrency: 1,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let probe = client.probe().unwrap();
    assert_eq!(probe.url, format!("{}/models", server.base_url()));
    assert!(client.complete_all(&strings(&["first"]), &mut cache)[0].is_ok());
    drop(server);
    let prompts: Vec<String> = (0..20).map(|i| format!("p{i}")).collect();
    let t = Instant::now();
    let results = client.complete_all(&prompts, &mut cache);
    let open = results
        .iter()
        .filter(|r| matches!(r, Err(LlmError::CircuitOpen { failures: 3, .. })))
        .count();
    assert_eq!(open, 20, "{:?}", &results[..2]);
    // Without the breaker: 20 prompts x 6 attempts, each waiting its backoff.
    assert!(
        t.elapsed() < Duration::from_secs(3),
        "took {:?}",
        t.elapsed()
    );
}

#[test]
fn a_cut_off_answer_fails_and_is_not_cached() {
    for kind in [RequestKind::Chat, RequestKind::Completion] {
        let server = LlmServer::answering(cut_below(100));
        let dir = tempfile::tempdir().unwrap();
        let mut cache = open_cache(dir.path());
        let config = LlmConfig {
            kind,
            max_tokens: 64,
            ..fast_config(&server)
        };
        let client = LlmClient::new(config).unwrap();
        let results = client.complete_all(&strings(&["p"]), &mut cache);
        match &results[0] {
            Err(
                e @ LlmError::Truncated {
                    max_tokens: 64,
                    attempts: 1,
                    preview,
                },
            ) => {
                assert_eq!(preview, "someone performs guide, chil");
                assert!(!e.stops_stage());
            }
            other => panic!("{kind:?}: expected Truncated, got {other:?}"),
        }
        assert_eq!(server.requests(), 1, "not retried with the same limit");
        assert_eq!(cache.len(), 0, "never cached");
        // Not settled: the next run asks again.
        client.complete_all(&strings(&["p"]), &mut cache);
        assert_eq!(server.requests(), 2);
    }
}

#[test]
fn a_cut_off_answer_is_asked_once_more_with_retry_max_tokens() {
    let server = LlmServer::answering(cut_below(100));
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        max_tokens: 64,
        retry_max_tokens: Some(200),
        ..fast_config(&server)
    };
    let client = LlmClient::new(config.clone()).unwrap();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    assert_eq!(answer(&results[0]).text, "echo: p");
    let seen = server.seen();
    assert_eq!(seen.len(), 2);
    assert_eq!(seen[0].body["max_tokens"], 64);
    assert_eq!(seen[1].body["max_tokens"], 200);
    // Cached under the config's key, with what was asked and why the server stopped.
    let entry = cache.get_entry(&config.cache_key("p")).unwrap();
    assert_eq!(entry.params.max_tokens, 200);
    assert_eq!(entry.finish_reason.as_deref(), Some("stop"));
    drop(cache);
    let text = std::fs::read_to_string(dir.path().join("llm/responses.jsonl")).unwrap();
    assert!(text.contains(r#""finish_reason":"stop""#), "{text}");
    let mut cache = open_cache(dir.path());
    let again = client.complete_all(&strings(&["p"]), &mut cache);
    assert!(answer(&again[0]).from_cache);
    assert_eq!(server.requests(), 2, "settled: no request on the rebuild");
    // Still cut off at the larger limit: one retry only, then the error.
    let server = LlmServer::answering(cut_below(1000));
    let client = LlmClient::new(LlmConfig {
        max_tokens: 64,
        retry_max_tokens: Some(200),
        ..fast_config(&server)
    })
    .unwrap();
    let results = client.complete_all(&strings(&["q"]), &mut open_cache(dir.path()));
    assert!(
        matches!(
            &results[0],
            Err(LlmError::Truncated {
                max_tokens: 200,
                attempts: 2,
                ..
            })
        ),
        "{results:?}"
    );
    assert_eq!(server.requests(), 2);
}

#[test]
fn entries_cached_without_a_finish_reason_are_asked_again_once() {
    let server = LlmServer::echo();
    let dir = tempfile::tempdir().unwrap();
    let config = fast_config(&server);
    // A line as an earlier version wrote it: no finish_reason, a cut-off answer cached as good;
    // and an imported answer, which has none either and must be kept.
    let old = format!(
        "{{\"key\":\"{}\",\"model\":\"test-model\",\"kind\":\"chat\",\"params\":{{\"temperature\":0.0,\"max_tokens\":256,\"seed\":null}},\"prompt_sha256\":\"x\",\"prompt_preview\":\"walk\",\"response\":\"someone performs guide, chil\",\"source\":\"llm\"}}\n{{\"key\":\"{}\",\"model\":\"test-model\",\"kind\":\"chat\",\"params\":{{\"temperature\":0.0,\"max_tokens\":256,\"seed\":null}},\"prompt_sha256\":\"y\",\"prompt_preview\":\"kick\",\"response\":\"right leg\",\"source\":\"import:gpt3.json\"}}\n",
        config.cache_key("walk"),
        config.cache_key("kick")
    );
    std::fs::create_dir_all(dir.path().join("llm")).unwrap();
    std::fs::write(dir.path().join("llm/responses.jsonl"), old).unwrap();
    let mut cache = open_cache(dir.path());
    assert_eq!(cache.len(), 2, "old lines load");
    assert_eq!(cache.corrupt_lines(), 0);
    // Offline readers still see the old answer.
    assert_eq!(
        cache.get(&config.cache_key("walk")),
        Some("someone performs guide, chil")
    );
    let client = LlmClient::new(config.clone()).unwrap();
    let results = client.complete_all(&strings(&["walk", "kick"]), &mut cache);
    assert_eq!(answer(&results[0]).text, "echo: walk");
    assert!(!answer(&results[0]).from_cache);
    assert_eq!(answer(&results[1]).text, "right leg");
    assert!(answer(&results[1]).from_cache, "imports are final");
    assert_eq!(server.requests(), 1);
    drop(cache);
    let mut cache = open_cache(dir.path());
    let again = client.complete_all(&strings(&["walk", "kick"]), &mut cache);
    assert!(again.iter().all(|r| answer(r).from_cache));
    assert_eq!(server.requests(), 1, "asked once, then settled");
}

#[test]
fn identical_prompts_in_a_batch_are_sent_once() {
    let server = LlmServer::echo();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let client = LlmClient::new(fast_config(&server)).unwrap();
    let prompts = strings(&["a", "b", "a", "a", "b"]);
    let results = client.complete_all(&prompts, &mut cache);
    assert_eq!(server.requests(), 2);
    for (p, r) in prompts.iter().zip(&results) {
        assert_eq!(answer(r).text, format!("echo: {p}"));
    }
    assert_eq!(cache.len(), 2);
}

#[test]
fn concurrency_limit_is_respected() {
    let server = LlmServer::builder()
        .delay(Duration::from_millis(150))
        .start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        concurrency: 3,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let prompts: Vec<String> = (0..12).map(|i| format!("prompt {i}")).collect();
    let results = client.complete_all(&prompts, &mut cache);
    assert!(results.iter().all(Result::is_ok));
    assert_eq!(server.requests(), 12);
    assert_eq!(server.max_in_flight(), 3);
}

#[test]
fn request_starts_are_spaced_by_the_rate_limit() {
    let server = LlmServer::echo();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    // 600 per minute: one start every 100 ms.
    let config = LlmConfig {
        concurrency: 5,
        requests_per_minute: 600,
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let prompts: Vec<String> = (0..5).map(|i| format!("prompt {i}")).collect();
    let results = client.complete_all(&prompts, &mut cache);
    assert!(results.iter().all(Result::is_ok));
    let mut times: Vec<Instant> = server.seen().iter().map(|s| s.at).collect();
    times.sort();
    for pair in times.windows(2) {
        let gap = pair[1] - pair[0];
        // The limiter spaces starts 100 ms apart on the client; the slack absorbs scheduling
        // delays between a start and its arrival on a loaded machine.
        assert!(gap >= Duration::from_millis(50), "starts {gap:?} apart");
    }
    assert!(times[4] - times[0] >= Duration::from_millis(350));
}

#[test]
fn second_run_is_served_from_the_cache() {
    let server = LlmServer::echo();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let client = LlmClient::new(fast_config(&server)).unwrap();
    let prompts = strings(&["x", "y", "z"]);
    let first = client.complete_all(&prompts, &mut cache);
    assert!(first.iter().all(|r| !answer(r).from_cache));
    assert_eq!(server.requests(), 3);
    let second = client.complete_all(&prompts, &mut cache);
    assert_eq!(server.requests(), 3, "no request on the second run");
    for (a, b) in first.iter().zip(&second) {
        assert_eq!(answer(a).text, answer(b).text);
        assert!(answer(b).from_cache);
    }
}

#[test]
fn cache_survives_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let prompts = strings(&["walk forward", "wave the left hand"]);
    let config;
    {
        let server = LlmServer::echo();
        config = fast_config(&server);
        let mut cache = open_cache(dir.path());
        let client = LlmClient::new(config.clone()).unwrap();
        let results = client.complete_all(&prompts, &mut cache);
        assert!(results.iter().all(Result::is_ok));
    }
    // Everything from the first "process" is gone; a server that would fail every request stands
    // where the old one was configured.
    let failing = LlmServer::builder()
        .default(Reply::Status(500, "must not be called", None))
        .start();
    let mut cache = open_cache(dir.path());
    assert_eq!(cache.len(), 2);
    assert_eq!(cache.recovered_partial_lines(), 0);
    let client = LlmClient::new(LlmConfig {
        base_url: failing.base_url(),
        ..config
    })
    .unwrap();
    let results = client.complete_all(&prompts, &mut cache);
    assert_eq!(failing.requests(), 0);
    for (p, r) in prompts.iter().zip(&results) {
        assert_eq!(
            answer(r),
            &Answer {
                text: format!("echo: {p}"),
                from_cache: true
            }
        );
    }
}

fn entry(prompt: &str, response: &str) -> (CacheKey, CacheEntry) {
    let params = SamplingParams {
        temperature: 0.0,
        max_tokens: 64,
        seed: Some(1),
    };
    (
        CacheKey::new("m", RequestKind::Chat, prompt, &params),
        CacheEntry::new(
            "m",
            RequestKind::Chat,
            prompt,
            &params,
            response.into(),
            "llm",
        ),
    )
}

#[test]
fn partial_last_line_is_recovered_and_truncated() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("responses.jsonl");
    {
        let mut cache = ResponseCache::open(&path).unwrap();
        for i in 0..3 {
            let (k, e) = entry(&format!("prompt {i}"), &format!("answer {i}"));
            cache.insert(k, e).unwrap();
        }
    }
    let complete = std::fs::read(&path).unwrap();
    assert_eq!(complete.iter().filter(|&&b| b == b'\n').count(), 3);
    // A crash mid-append: half of a fourth record, no newline.
    let (k, e) = entry("prompt 3", "answer 3");
    let mut line = serde_json::to_vec(&json!({"key": k.as_str(), "response": e.response})).unwrap();
    line.truncate(line.len() / 2);
    std::fs::OpenOptions::new()
        .append(true)
        .open(&path)
        .unwrap()
        .write_all(&line)
        .unwrap();

    let mut cache = ResponseCache::open(&path).unwrap();
    assert_eq!(cache.recovered_partial_lines(), 1);
    assert_eq!(cache.corrupt_lines(), 0);
    assert_eq!(cache.len(), 3);
    for i in 0..3 {
        let (k, _) = entry(&format!("prompt {i}"), "");
        assert_eq!(cache.get(&k), Some(format!("answer {i}").as_str()));
    }
    assert_eq!(std::fs::read(&path).unwrap(), complete, "torn line cut off");

    // Appending after recovery yields a file that reopens cleanly.
    cache.insert(k.clone(), e).unwrap();
    drop(cache);
    let cache = ResponseCache::open(&path).unwrap();
    assert_eq!(cache.recovered_partial_lines(), 0);
    assert_eq!(cache.len(), 4);
    assert_eq!(cache.get(&k), Some("answer 3"));
}

#[test]
fn record_missing_only_its_newline_is_kept() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("responses.jsonl");
    {
        let mut cache = ResponseCache::open(&path).unwrap();
        let (k, e) = entry("a", "first");
        cache.insert(k, e).unwrap();
        let (k, e) = entry("b", "second");
        cache.insert(k, e).unwrap();
    }
    let mut bytes = std::fs::read(&path).unwrap();
    assert_eq!(bytes.pop(), Some(b'\n'));
    std::fs::write(&path, &bytes).unwrap();
    let cache = ResponseCache::open(&path).unwrap();
    assert_eq!(cache.recovered_partial_lines(), 0);
    assert_eq!(cache.len(), 2);
    assert!(std::fs::read(&path).unwrap().ends_with(b"}\n"));
}

#[test]
fn later_entries_win_and_corrupt_lines_are_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir
        .path()
        .join("nested")
        .join("deeper")
        .join("responses.jsonl");
    {
        let mut cache = ResponseCache::open(&path).unwrap();
        let (k, e) = entry("a", "old");
        cache.insert(k, e).unwrap();
    }
    std::fs::OpenOptions::new()
        .append(true)
        .open(&path)
        .unwrap()
        .write_all(b"this is not json\n")
        .unwrap();
    {
        let mut cache = ResponseCache::open(&path).unwrap();
        assert_eq!(cache.corrupt_lines(), 1);
        let (k, e) = entry("a", "new");
        cache.insert(k, e).unwrap();
    }
    let cache = ResponseCache::open(&path).unwrap();
    assert_eq!(cache.len(), 1);
    assert_eq!(cache.corrupt_lines(), 1);
    assert_eq!(cache.get(&entry("a", "").0), Some("new"));
}

#[test]
fn cache_keys_separate_every_field() {
    let p = SamplingParams {
        temperature: 0.0,
        max_tokens: 64,
        seed: None,
    };
    let base = CacheKey::new("m", RequestKind::Chat, "ab", &p);
    assert_eq!(base, CacheKey::new("m", RequestKind::Chat, "ab", &p));
    assert_eq!(base.as_str().len(), 64);
    let others = [
        CacheKey::new("ma", RequestKind::Chat, "b", &p),
        CacheKey::new("m", RequestKind::Completion, "ab", &p),
        CacheKey::new("m", RequestKind::Chat, "ab ", &p),
        CacheKey::new(
            "m",
            RequestKind::Chat,
            "ab",
            &SamplingParams {
                temperature: 0.7,
                ..p
            },
        ),
        CacheKey::new(
            "m",
            RequestKind::Chat,
            "ab",
            &SamplingParams {
                max_tokens: 65,
                ..p
            },
        ),
        CacheKey::new(
            "m",
            RequestKind::Chat,
            "ab",
            &SamplingParams { seed: Some(0), ..p },
        ),
    ];
    for k in others {
        assert_ne!(base, k);
    }
}

#[test]
fn api_key_is_sent_as_bearer() {
    const VAR: &str = "MOTIONFORGE_TEST_LLM_CLIENT_API_KEY";
    // SAFETY: the variable is used by this test only, and Rust's own environment accesses
    // (std::env::var, also used by reqwest) are serialised by std's lock.
    unsafe { std::env::set_var(VAR, "sk-test-123") };
    let server = LlmServer::builder().api_key("sk-test-123").start();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let config = LlmConfig {
        api_key_env: Some(VAR.into()),
        ..fast_config(&server)
    };
    let client = LlmClient::new(config).unwrap();
    let results = client.complete_all(&strings(&["p"]), &mut cache);
    assert_eq!(answer(&results[0]).text, "echo: p");
    assert_eq!(server.seen()[0].auth.as_deref(), Some("Bearer sk-test-123"));
    assert!(!format!("{client:?}").contains("sk-test-123"));
}

#[test]
fn missing_api_key_variable_is_an_error() {
    let mut config = LlmConfig::new("http://127.0.0.1:9/v1", "m");
    config.api_key_env = Some("MOTIONFORGE_TEST_LLM_KEY_THAT_IS_NEVER_SET".into());
    match LlmClient::new(config) {
        Err(LlmError::MissingApiKey { var }) => {
            assert_eq!(var, "MOTIONFORGE_TEST_LLM_KEY_THAT_IS_NEVER_SET")
        }
        other => panic!("expected MissingApiKey, got {other:?}"),
    }
}

#[test]
fn config_defaults_and_validation() {
    let config: LlmConfig =
        serde_json::from_str(r#"{"base_url": "http://127.0.0.1:8080/v1", "model": "qwen"}"#)
            .unwrap();
    assert_eq!(config, LlmConfig::new("http://127.0.0.1:8080/v1", "qwen"));
    assert_eq!(config.kind, RequestKind::Chat);
    assert_eq!(config.max_tokens, 256);
    assert_eq!(config.concurrency, 4);
    assert_eq!(config.requests_per_minute, 60);
    assert_eq!(config.max_retries, 5);
    assert_eq!(config.timeout_seconds, 60.0);
    assert_eq!(config.backoff_seconds, 1.0);
    assert_eq!(config.max_retry_after_seconds, 60.0);
    let kind: LlmConfig = serde_json::from_str(
        r#"{"base_url": "http://h/v1", "model": "m", "kind": "completion", "seed": 3}"#,
    )
    .unwrap();
    assert_eq!(kind.kind, RequestKind::Completion);
    assert_eq!(kind.seed, Some(3));
    assert!(
        serde_json::from_str::<LlmConfig>(r#"{"base_url": "x", "model": "m", "temprature": 1}"#)
            .is_err(),
        "unknown fields are rejected"
    );
    let bad = [
        LlmConfig::new("ftp://h/v1", "m"),
        LlmConfig::new("http://h/v1", " "),
        LlmConfig {
            concurrency: 0,
            ..LlmConfig::new("http://h/v1", "m")
        },
        LlmConfig {
            requests_per_minute: 0,
            ..LlmConfig::new("http://h/v1", "m")
        },
        LlmConfig {
            timeout_seconds: 0.0,
            ..LlmConfig::new("http://h/v1", "m")
        },
        LlmConfig {
            backoff_seconds: f64::NAN,
            ..LlmConfig::new("http://h/v1", "m")
        },
        LlmConfig {
            temperature: -1.0,
            ..LlmConfig::new("http://h/v1", "m")
        },
        LlmConfig {
            max_tokens: 100,
            retry_max_tokens: Some(100),
            ..LlmConfig::new("http://h/v1", "m")
        },
        LlmConfig {
            circuit_breaker_failures: 0,
            ..LlmConfig::new("http://h/v1", "m")
        },
    ];
    for config in bad {
        assert!(
            matches!(LlmClient::new(config.clone()), Err(LlmError::Config { .. })),
            "{config:?} accepted"
        );
    }
}

#[test]
fn works_when_called_from_inside_a_runtime() {
    let server = LlmServer::echo();
    let dir = tempfile::tempdir().unwrap();
    let mut cache = open_cache(dir.path());
    let client = LlmClient::new(fast_config(&server)).unwrap();
    let outer = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let results = outer.block_on(async {
        let results = client.complete_all(&strings(&["p"]), &mut cache);
        // Dropping the client inside an async context must not panic either.
        drop(client);
        results
    });
    assert_eq!(answer(&results[0]).text, "echo: p");
}

#[test]
fn docs_config_examples_parse() {
    let doc = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/llm-servers.md"),
    )
    .unwrap();
    let blocks: Vec<&str> = doc
        .split("```toml\n")
        .skip(1)
        .map(|rest| rest.split("```").next().unwrap())
        .collect();
    assert_eq!(blocks.len(), 5, "one example per server");
    for block in blocks {
        let config: LlmConfig =
            toml::from_str(block).unwrap_or_else(|e| panic!("{e}\nin:\n{block}"));
        assert!(config.base_url.ends_with("/v1"), "{block}");
    }
}
