//! `motionforge serve` runs each build in a process of its own: a build that aborts fails alone
//! (the service answers on, records the signal and the last lines, and does not resume it), a
//! stop kills the build process, a resume build the service died in is not resumed again, a
//! real build goes through the binary's `serve-build`, and that process stops when the service
//! is gone.
use crate::common;

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use motionforge::config::Config;
use motionforge::serve::Service;
use motionforge::serve::history::{History, Left, Trigger};
use motionforge::serve::worker::Job;
use serde_json::Value;

use common::repo;
use common::service::{get, start_service};

const TOKEN: &str = "isolation-token";
/// Generous: a debug-mode demo build on two busy cores.
const TIMEOUT: Duration = Duration::from_secs(600);

fn demo_config(output: &Path) -> Config {
    let mut config = Config::load(&repo().join("fixtures/demo.toml")).unwrap();
    config.dataset.output = output.to_path_buf();
    config
}

fn real_builder() -> PathBuf {
    env!("CARGO_BIN_EXE_motionforge").into()
}

/// Writes an executable shell script.
fn script(dir: &Path, name: &str, body: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, format!("#!/bin/sh\n{body}")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path
}

async fn start(state: &Path, config: Config, builder: PathBuf) -> (Service, String) {
    start_service(state, vec![config], builder, TOKEN).await
}

async fn request_build(client: &reqwest::Client, base: &str) -> i64 {
    let response = client
        .post(format!("{base}/builds"))
        .bearer_auth(TOKEN)
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 202);
    let body: Value = response.json().await.unwrap();
    body["id"].as_i64().unwrap()
}

/// Polls `GET /builds/{id}` every 50 ms until `done` holds for it.
async fn poll_build(
    client: &reqwest::Client,
    base: &str,
    id: i64,
    done: impl Fn(&Value) -> bool,
) -> Value {
    let start = Instant::now();
    loop {
        let (status, build) = get(client, &format!("{base}/builds/{id}")).await;
        assert_eq!(status, 200, "{build}");
        if done(&build) {
            return build;
        }
        assert!(start.elapsed() < TIMEOUT, "build {id} stuck: {build}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn is_final(build: &Value) -> bool {
    ["succeeded", "failed", "interrupted"].contains(&build["state"].as_str().unwrap_or(""))
}

/// Polls the filesystem every 20 ms, up to 30 s, until `path` exists.
async fn wait_for_file(path: &Path) {
    let start = Instant::now();
    while !path.exists() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "{} never appeared",
            path.display()
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// True while `pid` is a live process (not gone, not a zombie).
fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| {
            s.rsplit_once(')')
                .map(|(_, rest)| !rest.trim_start().starts_with('Z'))
        })
        .unwrap_or(false)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_build_that_aborts_fails_alone_and_is_not_resumed() {
    let tmp = tempfile::tempdir().unwrap();
    let state = tmp.path().join("state");
    let go = tmp.path().join("go");
    let job_copy = tmp.path().join("job.json");
    // What a build that runs out of memory looks like from outside: some output, then SIGABRT.
    // It waits for `go` so the test can call the service while it runs.
    let builder = script(
        tmp.path(),
        "aborting-builder",
        &format!(
            r#"ulimit -c 0
[ "$1" = serve-build ] && [ "$2" = --job ] && cp "$3" '{job}'
echo '{{"event":"stage_started","stage":"ingest","total":3}}'
echo "reading captures"
echo "allocating 64 GiB for the mirror table" >&2
n=0
while [ ! -e '{go}' ] && [ $n -lt 600 ]; do sleep 0.05; n=$((n+1)); done
echo "memory allocation of 68719476736 bytes failed" >&2
kill -ABRT $$
"#,
            job = job_copy.display(),
            go = go.display()
        ),
    );
    let (service, base) = start(&state, demo_config(tmp.path()), builder.clone()).await;
    let client = reqwest::Client::new();
    let id = request_build(&client, &base).await;

    let running = poll_build(&client, &base, id, |b| {
        b["state"] == "running" && b["log"].to_string().contains("allocating 64 GiB")
    })
    .await;
    assert_eq!(running["stages"][0]["stage"], "ingest", "{running}");
    assert_eq!(running["stages"][0]["total"], 3, "{running}");
    let (status, health) = get(&client, &format!("{base}/health")).await;
    assert_eq!((status, &health["status"]), (200, &Value::from("ok")));
    // The service handed the build its job: the dataset's config and the options.
    let job: Job = serde_json::from_slice(&std::fs::read(&job_copy).unwrap()).unwrap();
    assert_eq!((job.build, job.force), (id, false));
    assert_eq!(job.config().dataset_dir(), tmp.path().join("demo"));

    std::fs::write(&go, "").unwrap();
    let build = poll_build(&client, &base, id, is_final).await;
    assert_eq!(build["state"], "failed", "{build}");
    let error = build["error"].as_str().unwrap();
    assert!(
        error.contains("killed by signal 6 (SIGABRT)"),
        "the reason names the signal: {error}"
    );
    for line in [
        "reading captures",
        "allocating 64 GiB for the mirror table",
        "memory allocation of 68719476736 bytes failed",
    ] {
        assert!(error.contains(line), "the reason quotes `{line}`: {error}");
        assert!(build["log"].to_string().contains(line), "{build}");
    }
    let log = build["log"].as_array().unwrap();
    assert!(
        log.last()
            .unwrap()
            .as_str()
            .unwrap()
            .starts_with("failed: "),
        "{build}"
    );
    let (status, _) = get(&client, &format!("{base}/health")).await;
    assert_eq!(status, 200, "the service outlives the build");
    service.stop().await.unwrap();

    // A restart does not run it again: it failed, it was not interrupted.
    let (service, base) = start(&state, demo_config(tmp.path()), builder).await;
    let (_, builds) = get(&client, &format!("{base}/builds")).await;
    let builds = builds["builds"].as_array().unwrap();
    assert_eq!(builds.len(), 1, "nothing queued at restart: {builds:?}");
    assert_eq!(builds[0]["state"], "failed");
    assert!(builds[0]["resumed_by"].is_null());
    let leftover: Vec<_> = std::fs::read_dir(state.join("jobs")).unwrap().collect();
    assert!(leftover.is_empty(), "job files left: {leftover:?}");
    service.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stop_kills_the_build_process_and_the_next_start_resumes_the_build() {
    let tmp = tempfile::tempdir().unwrap();
    let state = tmp.path().join("state");
    let pid_file = tmp.path().join("pid");
    let builder = script(
        tmp.path(),
        "slow-builder",
        &format!(
            "echo $$ > '{pid}.tmp' && mv '{pid}.tmp' '{pid}'\necho 'building slowly'\nexec sleep 600\n",
            pid = pid_file.display()
        ),
    );
    let (service, base) = start(&state, demo_config(tmp.path()), builder.clone()).await;
    let client = reqwest::Client::new();
    let id = request_build(&client, &base).await;
    wait_for_file(&pid_file).await;
    let pid: u32 = std::fs::read_to_string(&pid_file)
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    assert!(alive(pid));
    service.stop().await.unwrap();
    let start_wait = Instant::now();
    while alive(pid) {
        assert!(
            start_wait.elapsed() < Duration::from_secs(10),
            "build process {pid} outlived the service's stop"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }

    std::fs::remove_file(&pid_file).unwrap();
    let (service, base) = start(&state, demo_config(tmp.path()), builder).await;
    let (_, old) = get(&client, &format!("{base}/builds/{id}")).await;
    assert_eq!(old["state"], "interrupted", "{old}");
    let resume = old["resumed_by"].as_i64().expect("a resume build follows");
    let new = poll_build(&client, &base, resume, |b| b["state"] == "running").await;
    assert_eq!(new["trigger"], "resume");
    wait_for_file(&pid_file).await;
    service.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_resume_build_the_service_died_in_is_failed_not_resumed_again() {
    let tmp = tempfile::tempdir().unwrap();
    let state = tmp.path().join("state");
    // The service died in build `first`, resumed it with `second`, and died again.
    let (first, second) = {
        let history = History::open(&state).unwrap();
        let first = history
            .enqueue("demo", Trigger::Api, false, false, None, 1_000)
            .unwrap();
        assert!(history.start(first, 2_000).unwrap());
        history
            .interrupt_running(
                "the service stopped while this build ran",
                Left::Died,
                3_000,
            )
            .unwrap();
        let second = history.resume_interrupted(&["demo"], 3_000).unwrap()[0];
        assert!(history.start(second, 4_000).unwrap());
        (first, second)
    };

    let (service, base) = start(&state, demo_config(tmp.path()), real_builder()).await;
    let client = reqwest::Client::new();
    let (_, b) = get(&client, &format!("{base}/builds/{second}")).await;
    assert_eq!(b["state"], "failed", "{b}");
    assert_eq!(b["resumes"], first, "{b}");
    let error = b["error"].as_str().unwrap();
    assert!(
        error.contains("interrupted twice; not resumed again, request a new build"),
        "{error}"
    );
    assert!(b["resumed_by"].is_null(), "{b}");
    let (_, builds) = get(&client, &format!("{base}/builds")).await;
    assert_eq!(
        builds["builds"].as_array().unwrap().len(),
        2,
        "no third build: {builds}"
    );
    service.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_real_build_runs_in_a_serve_build_process_and_records_its_report() {
    let tmp = tempfile::tempdir().unwrap();
    let state = tmp.path().join("state");
    let ran = tmp.path().join("wrapper-ran");
    // The real binary behind a wrapper that leaves a trace: the build went through a process.
    let builder = script(
        tmp.path(),
        "wrapper",
        &format!(
            "echo \"$@\" > '{ran}'\nexec '{real}' \"$@\"\n",
            ran = ran.display(),
            real = real_builder().display()
        ),
    );
    let (service, base) = start(&state, demo_config(tmp.path()), builder).await;
    let client = reqwest::Client::new();
    let id = request_build(&client, &base).await;
    let build = poll_build(&client, &base, id, is_final).await;
    assert_eq!(build["state"], "succeeded", "{build}");
    assert_eq!(build["counts"]["clips"], 24, "{build}");
    assert_eq!(build["counts"]["captures"], 9, "{build}");
    let stages = build["stages"].as_array().unwrap();
    assert!(
        stages
            .iter()
            .any(|s| s["stage"] == "ingest" && s["ran"] == 9),
        "{build}"
    );
    assert!(stages.iter().all(|s| s["finished"] == true), "{build}");
    let log: Vec<&str> = build["log"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_str().unwrap())
        .collect();
    assert!(
        log.contains(&"ingest: finished, 9 ran, 0 reused"),
        "{log:?}"
    );
    assert!(log.last().unwrap().starts_with("succeeded in"), "{log:?}");
    let args = std::fs::read_to_string(&ran).unwrap();
    assert!(args.starts_with("serve-build --job "), "{args}");
    assert!(tmp.path().join("demo/report/stats.json").is_file());
    assert_eq!(
        std::fs::read_dir(state.join("jobs")).unwrap().count(),
        0,
        "the job and report files are removed"
    );
    // Stored, not only live: the history row has the report.
    service.stop().await.unwrap();
    let history = History::open(&state).unwrap();
    let record = history.get(id).unwrap().unwrap();
    let report: Value = serde_json::from_str(record.report.as_deref().unwrap()).unwrap();
    assert_eq!(report["clips"], 24);
}

#[test]
fn a_build_process_stops_when_the_service_is_gone() {
    let tmp = tempfile::tempdir().unwrap();
    let job = Job {
        build: 1,
        config: demo_config(tmp.path()),
        base_dir: demo_config(tmp.path()).base_dir,
        force: true,
        offline: true,
        report: tmp.path().join("report.json"),
    };
    let job_file = tmp.path().join("job.json");
    std::fs::write(&job_file, serde_json::to_vec(&job).unwrap()).unwrap();
    // Standard input already at its end, as when the service that held it was killed.
    let out = std::process::Command::new(real_builder())
        .args(["serve-build", "--job"])
        .arg(&job_file)
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("the service is gone"), "{stderr}");
    assert!(!tmp.path().join("report.json").exists());
}

#[test]
fn a_build_process_reports_a_failed_build_as_an_event_and_exit_code_1() {
    let tmp = tempfile::tempdir().unwrap();
    let job_file = tmp.path().join("job.json");
    std::fs::write(&job_file, "{\"not\": \"a job\"}").unwrap();
    let mut child = std::process::Command::new(real_builder())
        .args(["serve-build", "--job"])
        .arg(&job_file)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let _stdin = child.stdin.take();
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let last: Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    assert_eq!(last["event"], "failed", "{stdout}");
    assert!(
        last["message"].as_str().unwrap().contains("is not valid"),
        "{stdout}"
    );
}

/// The service killed with SIGKILL mid-build leaves its build process behind: it must stop as
/// soon as its standard input closes (not build on, holding the dataset's lock), and a service
/// restarted at once must resume the build, not fail it on the lock the orphan still holds.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_service_killed_mid_build_and_restarted_at_once_resumes_the_build() {
    use common::service::{ServeProcess, demo_config_file};
    let tmp = tempfile::tempdir().unwrap();
    let state = tmp.path().join("state");
    let config = demo_config_file(tmp.path(), &tmp.path().join("out"));
    let dataset = tmp.path().join("out/demo");
    let client = reqwest::Client::new();

    let first = ServeProcess::start(&config, &state, TOKEN);
    let id = request_build(&client, &first.base).await;
    // The build process is at work once its first stage writes to the cache.
    wait_for_file(&dataset.join(".motionforge/cache/ingest")).await;
    let orphan = motionforge::base::lock::read_holder(&dataset.join(".motionforge/lock"))
        .expect("the build process holds the dataset's lock")
        .pid;
    drop(first); // SIGKILL
    let second = ServeProcess::start(&config, &state, TOKEN);
    let orphan_alive_at_restart = alive(orphan);

    let (_, old) = get(&client, &format!("{}/builds/{id}", second.base)).await;
    assert_eq!(old["state"], "interrupted", "killed mid-build: {old}");
    let resume = old["resumed_by"].as_i64().expect("a resume build follows");
    let build = poll_build(&client, &second.base, resume, is_final).await;
    assert_eq!(
        build["state"], "succeeded",
        "the resume build (orphan alive at restart: {orphan_alive_at_restart}): {build}"
    );
    // The orphan stopped instead of finishing the dataset behind the service's back.
    let wrote = build["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["stage"] == "write")
        .map(|s| s["ran"].clone());
    assert_eq!(
        wrote,
        Some(Value::from(1)),
        "the resume build wrote: {build}"
    );
    assert!(!alive(orphan), "the orphaned build process is gone");
    let clips = build["counts"]["clips"].as_u64().unwrap();
    assert!(
        clips > 0 && dataset.join("manifest.json").is_file(),
        "{build}"
    );
    let (status, listed) = get(
        &client,
        &format!("{}/datasets/demo/clips?limit=1", second.base),
    )
    .await;
    assert_eq!(
        (status, listed["total"].as_u64()),
        (200, Some(clips)),
        "{listed}"
    );
    eprintln!("orphan alive at restart: {orphan_alive_at_restart}");
    second.stop();
}

/// A build process waits for the dataset's lock ([`motionforge::serve::worker::LOCK_WAIT`])
/// instead of failing at once: whoever holds it (a build process of a killed service, a build
/// run by hand) is about to let go.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_build_waits_for_the_dataset_lock_held_elsewhere() {
    let tmp = tempfile::tempdir().unwrap();
    let state = tmp.path().join("state");
    let config = demo_config(tmp.path());
    let held =
        motionforge::base::lock::WorkspaceLock::acquire(&config.dataset_dir(), None).unwrap();
    let (service, base) = start(&state, config, real_builder()).await;
    let client = reqwest::Client::new();
    let id = request_build(&client, &base).await;
    poll_build(&client, &base, id, |b| {
        b["log"].to_string().contains("waiting up to")
    })
    .await;
    drop(held);
    let build = poll_build(&client, &base, id, is_final).await;
    assert_eq!(build["state"], "succeeded", "{build}");
    service.stop().await.unwrap();
}
