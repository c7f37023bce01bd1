//! `motionforge serve` over real HTTP on loopback: auth, builds of the demo to completion, the
//! per-dataset queue, statistics, history across restarts, recovery of an interrupted build, the
//! OpenAPI description, answers that show no absolute path and errors that are short JSON
//! whatever the request, and the command's clean stop.
use crate::common;

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use motionforge::config::Config;
use motionforge::serve::history::{History, Trigger};
use motionforge::serve::schedule::SystemClock;
use motionforge::serve::{Service, ServiceSetup, Token};
use serde_json::Value;

use common::repo;
use common::service::{get, start_service};

const TOKEN: &str = "s3cret-test-token";
/// Generous: a debug-mode demo build on two busy cores.
const BUILD_TIMEOUT: Duration = Duration::from_secs(600);

fn demo_config(output: &Path) -> Config {
    let mut config = Config::load(&repo().join("fixtures/demo.toml")).unwrap();
    config.dataset.output = output.to_path_buf();
    config
}

async fn start(state: &Path, configs: Vec<Config>) -> (Service, String) {
    start_service(
        state,
        configs,
        env!("CARGO_BIN_EXE_motionforge").into(),
        TOKEN,
    )
    .await
}

async fn post_build(
    client: &reqwest::Client,
    base: &str,
    token: Option<&str>,
    body: &str,
) -> (u16, Value) {
    let mut request = client.post(format!("{base}/builds")).body(body.to_string());
    if let Some(token) = token {
        request = request.header("Authorization", format!("Bearer {token}"));
    }
    let response = request.send().await.unwrap();
    let status = response.status().as_u16();
    (status, response.json().await.unwrap())
}

/// Polls `GET /builds/{id}` every 100 ms until the build is final; on every poll, checks through
/// `GET /builds` that no two builds run at once.
async fn wait_final(client: &reqwest::Client, base: &str, id: i64) -> Value {
    watch_build(client, base, id).await.0
}

/// [`wait_final`], also returning the answers seen while the build was running.
async fn watch_build(client: &reqwest::Client, base: &str, id: i64) -> (Value, Vec<Value>) {
    let start = Instant::now();
    let mut running = Vec::new();
    loop {
        let (status, build) = get(client, &format!("{base}/builds/{id}")).await;
        assert_eq!(status, 200, "{build}");
        if ["succeeded", "failed", "interrupted"].contains(&build["state"].as_str().unwrap()) {
            return (build, running);
        }
        if build["state"] == "running" {
            running.push(build.clone());
        }
        let (_, all) = get(client, &format!("{base}/builds")).await;
        let running = all["builds"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|b| b["state"] == "running")
            .count();
        assert!(
            running <= 1,
            "two builds of one dataset running at once: {all}"
        );
        assert!(
            start.elapsed() < BUILD_TIMEOUT,
            "build {id} not finished after {BUILD_TIMEOUT:?}: {build}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn builds_over_http_with_auth_queue_stats_and_history_across_restarts() {
    let out = tempfile::tempdir().unwrap();
    let state = tempfile::tempdir().unwrap();
    let (service, base) = start(state.path(), vec![demo_config(out.path())]).await;
    let client = reqwest::Client::new();

    let (status, health) = get(&client, &format!("{base}/health")).await;
    assert_eq!((status, &health["status"]), (200, &Value::from("ok")));
    assert_eq!(health["datasets"], serde_json::json!(["demo"]));

    // State-changing calls need the token; nothing is queued without it.
    let (status, body) = post_build(&client, &base, None, r#"{"dataset":"demo"}"#).await;
    assert_eq!(status, 401, "{body}");
    assert!(
        body["error"]
            .as_str()
            .unwrap()
            .contains("missing bearer token")
    );
    let (status, body) = post_build(&client, &base, Some("wrong"), r#"{"dataset":"demo"}"#).await;
    assert_eq!(status, 401, "{body}");
    assert_eq!(body["error"], "wrong bearer token");
    let basic = client
        .post(format!("{base}/builds"))
        .header("Authorization", format!("Basic {TOKEN}"))
        .send()
        .await
        .unwrap();
    assert_eq!(basic.status().as_u16(), 401);
    assert!(basic.headers().contains_key("www-authenticate"));
    let (_, builds) = get(&client, &format!("{base}/builds")).await;
    assert_eq!(builds["builds"], serde_json::json!([]));

    // Not built yet: no statistics.
    let (status, body) = get(&client, &format!("{base}/datasets/demo/stats")).await;
    assert_eq!(status, 404, "{body}");

    // Two builds back to back: the second waits for the first.
    let first = client
        .post(format!("{base}/builds"))
        .bearer_auth(TOKEN)
        .json(&serde_json::json!({"dataset": "demo", "force": false}))
        .send()
        .await
        .unwrap();
    assert_eq!(first.status().as_u16(), 202);
    let first_location = first.headers()["location"].to_str().unwrap().to_string();
    let first: Value = first.json().await.unwrap();
    let id1 = first["id"].as_i64().unwrap();
    assert_eq!(first_location, format!("/builds/{id1}"));
    assert_eq!(first["trigger"], "api");
    // One dataset served: the body may be left out.
    let (status, second) = post_build(&client, &base, Some(TOKEN), "").await;
    assert_eq!(status, 202, "{second}");
    let id2 = second["id"].as_i64().unwrap();
    assert!(id2 > id1);
    assert_eq!(
        second["state"], "queued",
        "the second build must wait: {second}"
    );
    let (_, now2) = get(&client, &format!("{base}/builds/{id2}")).await;
    assert_eq!(now2["state"], "queued", "{now2}");

    let (b1, seen_running) = watch_build(&client, &base, id1).await;
    // While it runs, the answer carries the live log (the build takes over a second here).
    let live = seen_running.first().expect("build 1 seen running");
    assert!(
        live["started_at"].is_string() && live["finished_at"].is_null(),
        "{live}"
    );
    assert!(
        live["log"][0]
            .as_str()
            .unwrap()
            .starts_with(&format!("build {id1} of `demo` started")),
        "{live}"
    );
    let b2 = wait_final(&client, &base, id2).await;
    assert_eq!(b1["state"], "succeeded", "{b1}");
    assert_eq!(b2["state"], "succeeded", "{b2}");
    assert_eq!(b1["counts"]["clips"], 24, "{b1}");
    assert_eq!(b1["counts"]["captures"], 9, "{b1}");
    assert_eq!(b1["counts"]["mirrored"], 10, "{b1}");
    assert_eq!(b1["counts"]["nothing_ran"], false, "{b1}");
    let stages = b1["stages"].as_array().unwrap();
    let names: Vec<&str> = stages
        .iter()
        .map(|s| s["stage"].as_str().unwrap())
        .collect();
    for stage in ["ingest", "segment", "mirror", "write", "report"] {
        assert!(names.contains(&stage), "stage {stage} missing: {names:?}");
    }
    assert!(stages.iter().all(|s| s["finished"] == true), "{b1}");
    let ingest = stages.iter().find(|s| s["stage"] == "ingest").unwrap();
    assert_eq!(
        (ingest["total"].as_u64(), ingest["ran"].as_u64()),
        (Some(9), Some(9))
    );
    let log: Vec<&str> = b1["log"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_str().unwrap())
        .collect();
    assert!(log[0].contains("started"), "{log:?}");
    assert!(log.last().unwrap().contains("succeeded"), "{log:?}");
    // Nothing changed between them: the second reused everything, and ran after the first.
    assert_eq!(b2["counts"]["nothing_ran"], true, "{b2}");
    assert_eq!(b2["counts"]["clips"], 24);
    assert!(
        b2["started_at"].as_str().unwrap() >= b1["finished_at"].as_str().unwrap(),
        "second started before the first finished: {b1} {b2}"
    );
    println!(
        "demo build {} s, rebuild with nothing changed {} s (debug)",
        b1["seconds"], b2["seconds"]
    );

    // Datasets and statistics.
    let (status, datasets) = get(&client, &format!("{base}/datasets")).await;
    assert_eq!(status, 200);
    let demo = &datasets["datasets"][0];
    assert_eq!(demo["name"], "demo");
    assert_eq!(demo["stats_available"], true);
    assert_eq!(demo["last_build"]["id"], id2);
    assert_eq!(demo["queued"], serde_json::json!([]));
    let (status, stats) = get(&client, &format!("{base}/datasets/demo/stats")).await;
    assert_eq!(status, 200);
    let on_disk: Value =
        serde_json::from_slice(&std::fs::read(out.path().join("demo/report/stats.json")).unwrap())
            .unwrap();
    assert_eq!(stats, on_disk);
    for (what, answer) in [("stats", &stats), ("datasets", &datasets), ("build", &b1)] {
        assert_no_absolute_path(answer, out.path(), what);
    }

    // Errors answer JSON with the right status.
    let (status, body) = get(&client, &format!("{base}/datasets/nope/stats")).await;
    assert_eq!(status, 404);
    assert!(
        body["error"]
            .as_str()
            .unwrap()
            .contains("no dataset `nope`")
    );
    for path in ["/builds/9999", "/builds/abc", "/nowhere"] {
        let (status, body) = get(&client, &format!("{base}{path}")).await;
        assert_eq!(status, 404, "{path}: {body}");
        assert!(body["error"].is_string(), "{path}: {body}");
    }
    let (status, body) = post_build(&client, &base, Some(TOKEN), r#"{"dataset":"nope"}"#).await;
    assert_eq!(status, 404, "{body}");
    let (status, body) = post_build(
        &client,
        &base,
        Some(TOKEN),
        r#"{"dataset":"demo","fast":1}"#,
    )
    .await;
    assert_eq!(status, 400, "{body}");
    let (status, body) = get(&client, &format!("{base}/builds?state=done")).await;
    assert_eq!(status, 400, "{body}");
    let (_, page) = get(&client, &format!("{base}/builds?limit=1")).await;
    assert_eq!(page["builds"].as_array().unwrap().len(), 1);

    // A new service on the same state folder finds the history.
    service.stop().await.unwrap();
    let (service, base) = start(state.path(), vec![demo_config(out.path())]).await;
    let (_, builds) = get(&client, &format!("{base}/builds")).await;
    let listed: Vec<(i64, &str)> = builds["builds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| (b["id"].as_i64().unwrap(), b["state"].as_str().unwrap()))
        .collect();
    assert_eq!(listed, vec![(id2, "succeeded"), (id1, "succeeded")]);
    let (_, again) = get(&client, &format!("{base}/builds/{id1}")).await;
    assert_eq!(again["counts"], b1["counts"]);
    assert_eq!(again["stages"], b1["stages"]);
    assert_eq!(again["log"], b1["log"]);
    service.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_build_left_running_is_interrupted_and_resumed_on_start() {
    let out = tempfile::tempdir().unwrap();
    let state = tempfile::tempdir().unwrap();
    // What a crash leaves: one build running, one queued behind it.
    let (crashed, waiting) = {
        let history = History::open(state.path()).unwrap();
        let crashed = history
            .enqueue("demo", Trigger::Api, true, false, None, 1_000)
            .unwrap();
        assert!(history.start(crashed, 2_000).unwrap());
        let waiting = history
            .enqueue("demo", Trigger::Schedule, false, false, None, 3_000)
            .unwrap();
        (crashed, waiting)
    };

    let (service, base) = start(state.path(), vec![demo_config(out.path())]).await;
    let client = reqwest::Client::new();
    let (_, old) = get(&client, &format!("{base}/builds/{crashed}")).await;
    assert_eq!(old["state"], "interrupted", "{old}");
    assert!(old["error"].as_str().unwrap().contains("stopped"), "{old}");
    let resume = old["resumed_by"]
        .as_i64()
        .expect("a resume build is queued");
    assert!(
        resume > waiting,
        "the resume build is queued after the waiting one"
    );

    let (_, new) = get(&client, &format!("{base}/builds/{resume}")).await;
    assert_eq!(new["trigger"], "resume");
    assert_eq!(new["resumes"], crashed);
    assert_eq!(
        new["force"], false,
        "a resume reuses what the forced build finished"
    );

    let w = wait_final(&client, &base, waiting).await;
    let r = wait_final(&client, &base, resume).await;
    assert_eq!(w["state"], "succeeded", "{w}");
    assert_eq!(w["counts"]["clips"], 24, "{w}");
    assert_eq!(r["state"], "succeeded", "{r}");
    assert_eq!(r["counts"]["nothing_ran"], true, "{r}");
    assert!(r["started_at"].as_str().unwrap() >= w["finished_at"].as_str().unwrap());
    service.stop().await.unwrap();

    // Resumed once only: another start adds nothing.
    let (service, base) = start(state.path(), vec![demo_config(out.path())]).await;
    let (_, builds) = get(&client, &format!("{base}/builds")).await;
    assert_eq!(builds["builds"].as_array().unwrap().len(), 3, "{builds}");
    service.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_failed_build_records_its_error_and_the_queue_goes_on() {
    let out = tempfile::tempdir().unwrap();
    let state = tempfile::tempdir().unwrap();
    let mut config = demo_config(out.path());
    config.sources[0].profile = "no-such-skeleton".into();
    let (service, base) = start(state.path(), vec![config]).await;
    let client = reqwest::Client::new();
    let (_, a) = post_build(&client, &base, Some(TOKEN), "").await;
    let (_, b) = post_build(&client, &base, Some(TOKEN), r#"{"force": true}"#).await;
    let a = wait_final(&client, &base, a["id"].as_i64().unwrap()).await;
    let b = wait_final(&client, &base, b["id"].as_i64().unwrap()).await;
    for build in [&a, &b] {
        assert_eq!(build["state"], "failed", "{build}");
        let error = build["error"].as_str().unwrap();
        assert!(error.contains("no-such-skeleton"), "{error}");
        assert!(build["counts"].is_null(), "{build}");
        let log = build["log"].as_array().unwrap();
        assert!(
            log.last()
                .unwrap()
                .as_str()
                .unwrap()
                .starts_with("failed: "),
            "{build}"
        );
    }
    assert_eq!(b["force"], true);
    service.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_two_datasets_a_build_must_name_one() {
    let out = tempfile::tempdir().unwrap();
    let state = tempfile::tempdir().unwrap();
    let mut other = demo_config(out.path());
    other.dataset.name = "demo-copy".into();
    let (service, base) = start(state.path(), vec![demo_config(out.path()), other]).await;
    let client = reqwest::Client::new();
    let (status, body) = post_build(&client, &base, Some(TOKEN), r#"{"force": true}"#).await;
    assert_eq!(status, 400, "{body}");
    assert!(
        body["error"]
            .as_str()
            .unwrap()
            .contains("`dataset` is required"),
        "{body}"
    );
    let (_, datasets) = get(&client, &format!("{base}/datasets")).await;
    let names: Vec<&str> = datasets["datasets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, vec!["demo", "demo-copy"]);
    let (_, builds) = get(&client, &format!("{base}/builds")).await;
    assert_eq!(
        builds["builds"],
        serde_json::json!([]),
        "nothing was queued"
    );
    service.stop().await.unwrap();

    let err = Service::start(
        ServiceSetup {
            datasets: vec![demo_config(out.path()), demo_config(out.path())],
            state_dir: state.path().to_path_buf(),
            token: Token::new(TOKEN).unwrap(),
            clock: Arc::new(SystemClock),
            builder: env!("CARGO_BIN_EXE_motionforge").into(),
        },
        tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap(),
    )
    .await
    .err()
    .expect("two configs of one dataset are refused");
    assert!(err.to_string().contains("`demo`"), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn openapi_describes_exactly_the_routes_served() {
    let text = std::fs::read_to_string(repo().join("docs/openapi.json")).unwrap();
    let doc: Value = serde_json::from_str(&text).unwrap();
    assert!(
        doc["openapi"].as_str().unwrap().starts_with("3.1"),
        "{}",
        doc["openapi"]
    );
    let mut described = BTreeSet::new();
    for (path, item) in doc["paths"].as_object().unwrap() {
        for method in item.as_object().unwrap().keys() {
            if ["get", "post", "put", "patch", "delete", "head", "options"]
                .contains(&method.as_str())
            {
                described.insert((method.to_uppercase(), path.clone()));
            }
        }
    }
    let served: BTreeSet<(String, String)> = motionforge::serve::api::routes()
        .into_iter()
        .map(|(m, p)| (m.to_string(), p.to_string()))
        .collect();
    assert_eq!(described, served, "docs/openapi.json and the router differ");

    // And each described operation reaches a handler (not the no-route fallback).
    let out = tempfile::tempdir().unwrap();
    let state = tempfile::tempdir().unwrap();
    let (service, base) = start(state.path(), vec![demo_config(out.path())]).await;
    let client = reqwest::Client::new();
    for (method, path) in &described {
        let url = format!(
            "{base}{}",
            path.replace("{id}", "1").replace("{name}", "demo")
        );
        let method = reqwest::Method::from_bytes(method.as_bytes()).unwrap();
        let response = client.request(method.clone(), &url).send().await.unwrap();
        let status = response.status().as_u16();
        // The browser page is HTML and its icon SVG; every other answer, errors included, is
        // JSON.
        let text = response.text().await.unwrap();
        let body: Value = if path == "/" {
            assert!(text.starts_with("<!doctype html>"), "{method} {path}");
            Value::Null
        } else if path == "/favicon.svg" {
            assert!(text.starts_with("<svg"), "{method} {path}");
            Value::Null
        } else {
            serde_json::from_str(&text).unwrap()
        };
        assert_ne!(status, 405, "{method} {path}: {body}");
        let error = body["error"].as_str().unwrap_or("");
        assert!(!error.starts_with("no route"), "{method} {path}: {body}");
    }
    service.stop().await.unwrap();
}

#[test]
fn the_command_refuses_to_start_without_a_token_and_stops_cleanly_on_sigterm() {
    use std::io::{BufRead, BufReader};
    use std::process::{Command, Stdio};

    let state = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args([
            "serve",
            "--bind",
            "127.0.0.1:0",
            "--token-env",
            "MOTIONFORGE_TEST_UNSET_TOKEN",
        ])
        .arg("--config")
        .arg(repo().join("fixtures/demo.toml"))
        .arg("--state")
        .arg(state.path())
        .env_remove("MOTIONFORGE_TEST_UNSET_TOKEN")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("MOTIONFORGE_TEST_UNSET_TOKEN"), "{stderr}");

    let mut child = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["serve", "--bind", "127.0.0.1:0"])
        .arg("--config")
        .arg(repo().join("fixtures/demo.toml"))
        .arg("--state")
        .arg(state.path())
        .env("MOTIONFORGE_TOKEN", TOKEN)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let serving = lines
        .by_ref()
        .map(Result::unwrap)
        .find(|l| l.contains("serving"))
        .expect("the service says where it serves");
    let addr = serving.rsplit("http://").next().unwrap().trim().to_string();
    assert_eq!(health_status(&addr), 200);
    let killed = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let rest: Vec<String> = lines.map(Result::unwrap).collect();
    let status = child.wait().unwrap();
    assert!(status.success(), "exit {status:?}: {rest:?}");
    assert!(rest.iter().any(|l| l.contains("stopping")), "{rest:?}");
    assert!(state.path().join("history.sqlite3").is_file());
}

/// Every string inside `value`.
fn strings(value: &Value) -> Vec<&str> {
    match value {
        Value::String(s) => vec![s.as_str()],
        Value::Array(items) => items.iter().flat_map(strings).collect(),
        Value::Object(map) => map
            .iter()
            .flat_map(|(k, v)| std::iter::once(k.as_str()).chain(strings(v)))
            .collect(),
        _ => Vec::new(),
    }
}

/// Asserts that no string of `value` is an absolute path or names the folder `secret`.
fn assert_no_absolute_path(value: &Value, secret: &Path, what: &str) {
    let secret = secret.to_str().unwrap();
    for s in strings(value) {
        assert!(
            !s.starts_with('/') || s.starts_with("/builds/") || s.starts_with("/datasets/"),
            "{what}: absolute path {s:?} in {value}"
        );
        assert!(!s.contains(secret), "{what}: {secret} in {s:?}");
    }
}

/// Sends `request` as is on a new connection and reads the answer to its end: (status, headers,
/// body). For requests an HTTP client would not send.
async fn raw_http(addr: std::net::SocketAddr, request: &[u8]) -> (u16, String, Vec<u8>) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    stream.write_all(request).await.unwrap();
    let mut answer = Vec::new();
    tokio::time::timeout(Duration::from_secs(30), stream.read_to_end(&mut answer))
        .await
        .unwrap_or_else(|_| {
            panic!(
                "no answer to {:?}",
                String::from_utf8_lossy(&request[..request.len().min(80)])
            )
        })
        .unwrap();
    let split = answer
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .unwrap_or_else(|| panic!("no head in {:?}", String::from_utf8_lossy(&answer)));
    let head = String::from_utf8_lossy(&answer[..split]).to_lowercase();
    let status = head[9..12].parse().unwrap();
    (status, head, answer[split + 4..].to_vec())
}

/// Asserts an error answer is `{"error": "..."}` JSON with the status, under 1 KB.
fn assert_json_error(status: u16, head: &str, body: &[u8], expected: u16, what: &str) -> String {
    let text = String::from_utf8_lossy(body);
    assert_eq!(status, expected, "{what}: {head}\n{text}");
    assert!(
        head.contains("content-type: application/json"),
        "{what}: {head}"
    );
    assert!(body.len() < 1024, "{what}: {} bytes: {text}", body.len());
    let json: Value =
        serde_json::from_slice(body).unwrap_or_else(|e| panic!("{what}: {e}: {text}"));
    let error = json["error"]
        .as_str()
        .unwrap_or_else(|| panic!("{what}: {json}"));
    assert!(!error.is_empty(), "{what}");
    error.to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn answers_show_no_absolute_path_and_every_error_is_short_json() {
    let out = tempfile::tempdir().unwrap();
    let state = tempfile::tempdir().unwrap();
    let mut broken = demo_config(out.path());
    broken.dataset.name = "broken".into();
    // Captures that do not exist, named by an absolute path the error will quote.
    broken.sources[0].captures = vec![format!("{}/missing/*.bvh", out.path().display())];
    let (service, base) = start(state.path(), vec![demo_config(out.path()), broken]).await;
    let addr = service.local_addr();
    let client = reqwest::Client::new();

    for path in ["/health", "/datasets", "/datasets/demo/stats", "/builds"] {
        let (_, body) = get(&client, &format!("{base}{path}")).await;
        assert_no_absolute_path(&body, out.path(), path);
    }
    let (_, datasets) = get(&client, &format!("{base}/datasets")).await;
    assert_eq!(datasets["datasets"][1]["name"], "demo");
    assert_eq!(
        datasets["datasets"][1]["output"], "…/demo",
        "a folder outside the working folder shows by its name"
    );
    // A build error quoting absolute paths shows them shortened.
    let (status, queued) = post_build(&client, &base, Some(TOKEN), r#"{"dataset":"broken"}"#).await;
    assert_eq!(status, 202, "{queued}");
    let failed = wait_final(&client, &base, queued["id"].as_i64().unwrap()).await;
    assert_eq!(failed["state"], "failed", "{failed}");
    assert_no_absolute_path(&failed, out.path(), "failed build");
    let (_, listed) = get(&client, &format!("{base}/builds")).await;
    assert_no_absolute_path(&listed, out.path(), "build list");

    // Echoed input is cut to an excerpt: a 100 KB name, in a body and in paths.
    let long = "n".repeat(100_000);
    let response = client
        .post(format!("{base}/builds"))
        .bearer_auth(TOKEN)
        .json(&serde_json::json!({ "dataset": long }))
        .send()
        .await
        .unwrap();
    let status = response.status().as_u16();
    let head = format!(
        "content-type: {}",
        response.headers()["content-type"].to_str().unwrap()
    );
    let body = response.bytes().await.unwrap();
    let error = assert_json_error(status, &head, &body, 404, "100 KB dataset name");
    assert!(error.contains("nnnn…`"), "{error}");
    let long = &long[..60_000];
    for path in [
        format!("/datasets/{long}/stats"),
        format!("/builds/{long}"),
        format!("/{long}"),
        format!("/builds?state={long}"),
        format!("/builds?{long}=1"),
    ] {
        let request = format!("GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
        let (status, head, body) = raw_http(addr, request.as_bytes()).await;
        let expected = if path.contains('?') { 400 } else { 404 };
        assert_json_error(status, &head, &body, expected, &path[..20]);
    }
    let request = format!(
        "POST /builds HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\nContent-Type: application/json\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{{\"{long}\": 1}}",
        long.len() + 7
    );
    let (status, head, body) = raw_http(addr, request.as_bytes()).await;
    assert_json_error(status, &head, &body, 400, "unknown 60 KB field");

    // A body over the limit: refused from its declared length, before it is sent; and, sent
    // without a length (chunked), once the limit is read.
    let limit = motionforge::serve::api::BODY_LIMIT;
    let request = format!(
        "POST /builds HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\nConnection: close\r\nContent-Length: {}\r\n\r\n",
        limit + 1
    );
    let (status, head, body) = raw_http(addr, request.as_bytes()).await;
    let error = assert_json_error(status, &head, &body, 413, "oversized body");
    assert!(error.contains("too large"), "{error}");
    let chunk = "x".repeat(limit + 1);
    let request = format!(
        "POST /builds HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\nConnection: close\r\nTransfer-Encoding: chunked\r\n\r\n{:x}\r\n{chunk}\r\n0\r\n\r\n",
        chunk.len()
    );
    let (status, head, body) = raw_http(addr, request.as_bytes()).await;
    assert_json_error(status, &head, &body, 413, "oversized chunked body");

    // Over hyper's URI limit (65534 bytes): hyper answers by itself, in JSON all the same.
    let request = format!("GET /{} HTTP/1.1\r\nHost: x\r\n\r\n", "u".repeat(70_000));
    let (status, head, body) = raw_http(addr, request.as_bytes()).await;
    let error = assert_json_error(status, &head, &body, 414, "70 KB URI");
    assert!(error.contains("URI too long"), "{error}");
    // And after an answered request on the same connection.
    let request = format!(
        "GET /health HTTP/1.1\r\nHost: x\r\n\r\nGET /{} HTTP/1.1\r\nHost: x\r\n\r\n",
        "u".repeat(70_000)
    );
    let (status, _, body) = raw_http(addr, request.as_bytes()).await;
    assert_eq!(status, 200);
    let second = String::from_utf8_lossy(&body);
    assert!(
        second.contains("HTTP/1.1 414 URI Too Long\r\n")
            && second.contains("content-type: application/json")
            && second.ends_with(
                r#"{"error":"URI too long: the server reads URIs of at most 65534 bytes"}"#
            ),
        "{second}"
    );
    // A request line that does not parse.
    let (status, head, body) = raw_http(addr, b"GARBAGE\r\n\r\n").await;
    assert_json_error(status, &head, &body, 400, "malformed request line");

    // Invalid UTF-8, percent-encoded in a path parameter, and raw in a body.
    for path in ["/datasets/%FF%FE/stats", "/builds/%C3%28"] {
        let request = format!("GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
        let (status, head, body) = raw_http(addr, request.as_bytes()).await;
        assert_json_error(status, &head, &body, 400, path);
    }
    let mut request = format!(
        "POST /builds HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\nConnection: close\r\nContent-Length: 17\r\n\r\n"
    )
    .into_bytes();
    request.extend(b"{\"dataset\": \"\xff\xfe\"}");
    let (status, head, body) = raw_http(addr, &request).await;
    assert_json_error(status, &head, &body, 400, "invalid UTF-8 body");

    let (status, _) = get(&client, &format!("{base}/health")).await;
    assert_eq!(status, 200);
    service.stop().await.unwrap();
}

/// `GET /health` status, from a test without a runtime.
fn health_status(addr: &str) -> u16 {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
        .block_on(async {
            reqwest::get(format!("http://{addr}/health"))
                .await
                .unwrap()
                .status()
                .as_u16()
        })
}

/// The browser's report, column view and icon: the report rendered to HTML with its figures
/// served and nothing else (no file it does not list, no raw HTML, no way out of its folder);
/// every column's statistics over the whole table and its rows a page at a time, in the order of
/// the clip listing.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_report_renders_its_files_stay_listed_and_the_table_pages_with_statistics() {
    let out = tempfile::tempdir().unwrap();
    let state = tempfile::tempdir().unwrap();
    let config = demo_config(out.path());
    let built = config.clone();
    tokio::task::spawn_blocking(move || {
        motionforge::build::build(&built, &motionforge::build::BuildOptions::default()).unwrap()
    })
    .await
    .unwrap();
    let ds = config.dataset_dir();
    let report = ds.join("report");
    // What a tampered report might hold: raw HTML, links out of the folder, a script link; and
    // files the report does not name beside its figures, or leading out of it.
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    let figures = md.lines().filter(|l| l.starts_with("![")).count();
    std::fs::write(
        report.join("report.md"),
        format!(
            "{md}\n<img src=x onerror=alert(1)>\n\n[out](../secret.txt) [run](javascript:alert(1)) \
             ![up](../../secret.txt) [linked](figures/outside.txt)\n"
        ),
    )
    .unwrap();
    std::fs::write(ds.join("secret.txt"), "not for the browser").unwrap();
    std::fs::write(report.join("figures/unlisted.png"), "not listed").unwrap();
    std::os::unix::fs::symlink(ds.join("secret.txt"), report.join("figures/outside.txt")).unwrap();
    let (service, base) = start(state.path(), vec![config]).await;
    let client = reqwest::Client::new();

    let (status, html) = get(&client, &format!("{base}/datasets/demo/report/html")).await;
    assert_eq!(status, 200, "{html}");
    let html = html["html"].as_str().unwrap();
    assert!(html.contains("<table>") && html.contains("<td class=\"right\">"));
    assert_eq!(html.matches("<figure><img src=").count(), figures, "{html}");
    assert_eq!(html.matches("<figcaption>").count(), figures);
    assert!(
        html.contains("&lt;img src=x onerror=alert(1)&gt;"),
        "{html}"
    );
    for bad in ["<img src=x", "javascript:", "secret.txt", "style="] {
        assert!(!html.contains(bad), "{bad} in the rendered report");
    }
    // Every image of the report is served, as what it is.
    let (_, listing) = get(&client, &format!("{base}/datasets/demo/report")).await;
    let listed: Vec<&str> = listing["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    let srcs: Vec<&str> = html
        .split("<img src=\"")
        .skip(1)
        .map(|s| s.split('"').next().unwrap())
        .collect();
    assert_eq!(srcs.len(), figures);
    for src in srcs {
        let path = src.split("path=").nth(1).unwrap();
        assert!(listed.contains(&path), "{path} not in {listed:?}");
        let png = client.get(format!("{base}{src}")).send().await.unwrap();
        assert_eq!(png.status(), 200, "{src}");
        assert_eq!(png.headers()["content-type"], "image/png");
        assert!(
            png.headers()["content-security-policy"]
                .to_str()
                .unwrap()
                .contains("sandbox")
        );
        assert_eq!(&png.bytes().await.unwrap()[1..4], b"PNG");
    }
    assert!(listed.contains(&"report.md") && listed.contains(&"stats.json"));
    // Files the report does not name, and a named link that leads out of the folder: refused.
    assert!(!listed.contains(&"figures/unlisted.png"), "{listed:?}");
    for path in [
        "figures/unlisted.png",
        "figures/outside.txt",
        "../secret.txt",
        "figures/../../secret.txt",
    ] {
        let (status, body) = get(
            &client,
            &format!("{base}/datasets/demo/report/file?path={path}"),
        )
        .await;
        assert_eq!(status, 400, "{path}: {body}");
        assert!(!body.to_string().contains("not for the browser"));
    }

    // The column view: every column of the shards, counted over every row.
    let (status, clips) = get(&client, &format!("{base}/datasets/demo/clips?limit=1000")).await;
    assert_eq!(status, 200);
    let ids: Vec<&str> = clips["clips"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["clip_id"].as_str().unwrap())
        .collect();
    let (status, stats) = get(&client, &format!("{base}/datasets/demo/columns")).await;
    assert_eq!(status, 200, "{stats}");
    assert_eq!(stats["rows"].as_u64(), Some(ids.len() as u64));
    let column = |name: &str| {
        stats["columns"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["name"] == name)
            .unwrap_or_else(|| panic!("no column {name}"))
            .clone()
    };
    let mirrored = clips["clips"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["mirrored"] == true)
        .count();
    let flags = column("mirrored");
    assert_eq!(flags["kind"], "bool");
    assert!(
        flags["top"]
            .as_array()
            .unwrap()
            .contains(&serde_json::json!({ "value": "true", "count": mirrored })),
        "{flags}"
    );
    let id = column("clip_id");
    assert_eq!(
        (id["count"].as_u64(), id["distinct"].as_u64()),
        (Some(ids.len() as u64), Some(ids.len() as u64))
    );
    let frames: Vec<u64> = clips["clips"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["frames"].as_u64().unwrap())
        .collect();
    let n = column("num_frames");
    assert_eq!(n["kind"], "number");
    assert_eq!(n["min"].as_f64(), frames.iter().min().map(|&v| v as f64));
    assert_eq!(n["max"].as_f64(), frames.iter().max().map(|&v| v as f64));
    let mean = frames.iter().sum::<u64>() as f64 / frames.len() as f64;
    assert!((n["mean"].as_f64().unwrap() - mean).abs() < 1e-9, "{n}");
    let untyped = clips["clips"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["motion_type"].is_null())
        .count();
    assert_eq!(
        column("motion_type")["nulls"].as_u64(),
        Some(untyped as u64)
    );
    assert_eq!(column("joint_positions")["shape"], "frames × joints × 3");
    // Input paths in the table show as every answer shows paths.
    assert!(
        !stats.to_string().contains(&*repo().to_string_lossy()),
        "absolute paths in {stats}"
    );

    // Pages of 7 rows cover the table once, in the listing's order; frames as their shape.
    let mut paged = Vec::new();
    for offset in (0..ids.len()).step_by(7) {
        let (status, page) = get(
            &client,
            &format!("{base}/datasets/demo/rows?offset={offset}&limit=7"),
        )
        .await;
        assert_eq!(status, 200, "{page}");
        let names = page["columns"].as_array().unwrap();
        let at = |name: &str| names.iter().position(|n| n == name).unwrap();
        for row in page["rows"].as_array().unwrap() {
            let id = row[at("clip_id")].as_str().unwrap().to_string();
            let shape = format!("{} × {} × 3", row[at("num_frames")], row[at("num_joints")]);
            assert_eq!(row[at("joint_positions")], shape.as_str(), "{id}");
            paged.push(id);
        }
    }
    assert_eq!(paged, ids);
    let (status, past) = get(&client, &format!("{base}/datasets/demo/rows?offset=100000")).await;
    assert_eq!(
        (status, past["rows"].as_array().map(Vec::len)),
        (200, Some(0))
    );
    for limit in [0, 101] {
        let (status, body) =
            get(&client, &format!("{base}/datasets/demo/rows?limit={limit}")).await;
        assert_eq!(status, 400, "{body}");
    }

    let icon = client
        .get(format!("{base}/favicon.svg"))
        .send()
        .await
        .unwrap();
    assert_eq!(icon.status(), 200);
    assert_eq!(icon.headers()["content-type"], "image/svg+xml");
    assert!(icon.text().await.unwrap().starts_with("<svg"));
    service.stop().await.unwrap();
}
