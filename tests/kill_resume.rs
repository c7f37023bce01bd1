//! Kill a build with SIGKILL at several moments, start it again: it finishes, reuses what was
//! done, and its dataset is byte-identical to an uninterrupted build's.

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

fn start(output: &Path) -> Child {
    common::demo_build(output)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Every file of the dataset folder by relative path, except the build's own bookkeeping
/// (`.motionforge/` cache and ledger, and `build-report.json`, whose counts say what was reused).
fn dataset_files(dataset: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dataset.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            let rel = path
                .strip_prefix(dataset)
                .unwrap()
                .to_string_lossy()
                .into_owned();
            if rel == ".motionforge" || rel == "build-report.json" {
                continue;
            }
            if path.is_dir() {
                stack.push(path);
            } else {
                files.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

/// Moments of a build, each seen as a file or folder appearing in the dataset folder.
const POINTS: [&str; 8] = [
    ".motionforge/cache/ingest",
    ".motionforge/cache/segment",
    ".motionforge/cache/mirror",
    ".motionforge/cache/compose",
    "data",
    "normalization",
    "manifest.json",
    "report/figures",
];

/// Starts a build and kills it (SIGKILL) as soon as `point` appears; true when the build was
/// still running then, false when it finished (or the point never came) first.
fn kill_at(output: &Path, point: &str) -> bool {
    let mut child = start(output);
    let watched = output.join("demo").join(point);
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        if child.try_wait().unwrap().is_some() {
            return false;
        }
        if watched.exists() || Instant::now() > deadline {
            break;
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    let running = child.try_wait().unwrap().is_none();
    child.kill().unwrap();
    child.wait().unwrap();
    running
}

/// What an interrupted build left must not look complete when it is not: a manifest, once
/// there, lists shards that exist with its checksums.
fn assert_consistent(dataset: &Path) {
    let Ok(bytes) = std::fs::read(dataset.join("manifest.json")) else {
        return;
    };
    let manifest: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    for split in manifest["splits"].as_object().unwrap().values() {
        for shard in split["shards"].as_array().unwrap() {
            let path = dataset.join(shard["file"].as_str().unwrap());
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(
                motionforge::build::sha256_hex(&bytes),
                shard["sha256"].as_str().unwrap(),
                "{}",
                path.display()
            );
        }
    }
}

fn assert_same(dataset: &Path, expected: &BTreeMap<String, Vec<u8>>, what: &str) {
    let got = dataset_files(dataset);
    let differ: Vec<&String> = expected
        .keys()
        .chain(got.keys())
        .filter(|k| got.get(*k) != expected.get(*k))
        .collect();
    assert!(
        differ.is_empty(),
        "{what} then resumed: these files differ from an uninterrupted build: {differ:?}"
    );
}

/// Runs a build to the end; its report (stage counts) as JSON.
fn finish(output: &Path) -> serde_json::Value {
    let out = common::demo_build(output).arg("--json").output().unwrap();
    assert!(
        out.status.success(),
        "resumed build failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Items of `stage` the build took from the cache.
fn reused(report: &serde_json::Value, stage: &str) -> u64 {
    report["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["stage"] == stage)
        .map_or(0, |s| s["reused"].as_u64().unwrap())
}

/// What a build killed at `point` must have finished, so its resumption reuses it: per stage,
/// the fewest items reused. Captures are ingested and segmented in parallel, all before
/// mirroring starts; compose follows the mirrors, write follows compose.
fn finished_before(point: &str) -> Vec<(&'static str, u64)> {
    let order = POINTS.iter().position(|p| *p == point).unwrap();
    let mut done = Vec::new();
    if order >= 1 {
        done.push(("ingest", 1));
    }
    if order >= 2 {
        done = vec![("ingest", 9), ("segment", 9)];
    }
    if order >= 3 {
        done.push(("mirror", 9));
    }
    if order >= 4 {
        done.push(("compose", 5));
    }
    done
}

#[test]
fn killed_builds_resume_to_identical_bytes() {
    let reference = tempfile::tempdir().unwrap();
    finish(reference.path());
    let expected = dataset_files(&reference.path().join("demo"));
    assert!(expected.keys().any(|k| k.starts_with("data/")));

    // Each point from an empty folder: every one must really interrupt a build, or the test
    // proves nothing there.
    for point in POINTS {
        let dir = tempfile::tempdir().unwrap();
        assert!(
            kill_at(dir.path(), point),
            "the build finished before `{point}` appeared"
        );
        assert_consistent(&dir.path().join("demo"));
        let report = finish(dir.path());
        for (stage, least) in finished_before(point) {
            assert!(
                reused(&report, stage) >= least,
                "killed at `{point}`: the resumed build reused {} {stage} items, expected at least {least}",
                reused(&report, stage)
            );
        }
        assert_same(
            &dir.path().join("demo"),
            &expected,
            &format!("killed at `{point}`"),
        );
    }
    // One folder killed at every point in turn (each run resumes the one before), then finished.
    let chained = tempfile::tempdir().unwrap();
    for point in POINTS {
        kill_at(chained.path(), point);
        assert_consistent(&chained.path().join("demo"));
    }
    finish(chained.path());
    assert_same(
        &chained.path().join("demo"),
        &expected,
        "killed at every point in turn",
    );
}

#[test]
fn a_resumed_build_reuses_finished_work() {
    let dir = tempfile::tempdir().unwrap();
    finish(dir.path());
    // A kill right after a complete build leaves everything reusable: the next run re-runs
    // nothing.
    let out = common::demo_build(dir.path())
        .arg("--json")
        .output()
        .unwrap();
    assert!(out.status.success());
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for stage in report["stages"].as_array().unwrap() {
        assert_eq!(stage["ran"], 0, "{stage}");
    }
}
