//! No input may abort a build: real captures damaged the way users' files are damaged (absurd frame
//! times, claimed frame counts, thousands of joints, values beyond any capture, CR-only line ends,
//! empty captions, thousands of identical annotation rows), built through the binary under a 2 GB
//! address-space limit. Each bad file costs one reject line that names it; the rest is built, and
//! nothing non-finite reaches the dataset.
use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::project::{ConfigSpec, Source};
use common::repo;
use serde_json::Value;

const BIN: &str = env!("CARGO_BIN_EXE_motionforge");

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// The binary under an address-space limit of `mib` MiB.
fn run_limited_to(mib: u64, args: &[&std::ffi::OsStr]) -> Output {
    Command::new("prlimit")
        .arg(format!("--as={}", mib << 20))
        .arg(BIN)
        .args(args)
        .output()
        .expect("prlimit (util-linux) runs the binary")
}

/// The binary under an address-space limit of 2 GiB (`prlimit --as`): an allocation sized by a
/// damaged header fails there instead of taking the machine's memory.
fn run_limited(args: &[&std::ffi::OsStr]) -> Output {
    Command::new("prlimit")
        .arg(format!("--as={}", 2u64 << 30))
        .arg(BIN)
        .args(args)
        .output()
        .expect("prlimit (util-linux) runs the binary")
}

fn bandai(name: &str) -> String {
    std::fs::read_to_string(repo().join(format!(
        "fixtures/bandai-namco-1/data/dataset-1_{name}_001.bvh"
    )))
    .unwrap()
}

/// `text` with the line that starts with `key` replaced by `key value`.
fn set_header(text: &str, key: &str, value: &str) -> String {
    text.lines()
        .map(|l| {
            if l.starts_with(key) {
                format!("{key} {value}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

/// The 1-based line of the first line starting with `key`.
fn line_of(text: &str, key: &str) -> u64 {
    text.lines().position(|l| l.starts_with(key)).unwrap() as u64 + 1
}

struct Case {
    dir: tempfile::TempDir,
}

impl Case {
    fn new() -> Case {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("bandai")).unwrap();
        std::fs::create_dir_all(dir.path().join("cmu")).unwrap();
        Case { dir }
    }

    fn path(&self, rel: &str) -> PathBuf {
        self.dir.path().join(rel)
    }

    /// A Bandai capture (with its real sidecar) under `name`, its text replaced by `text`.
    fn capture(&self, name: &str, text: &str) {
        std::fs::write(self.path(&format!("bandai/dataset-1_{name}_001.bvh")), text).unwrap();
        let sidecar = repo().join("fixtures/bandai-namco-1/data/dataset-1_walk_normal_001.json");
        std::fs::copy(
            sidecar,
            self.path(&format!("bandai/dataset-1_{name}_001.json")),
        )
        .unwrap();
    }

    /// The Bandai captures labelled from their names (and sidecars), mirrored; with the CMU take
    /// and its event log if `with_cmu`.
    fn spec(with_cmu: bool) -> ConfigSpec {
        let spec = ConfigSpec::new("hard").fps(30).seed(7).mirror(true).source(
            Source::new("bandai", "bandai-namco", &["bandai/*.bvh"])
                .filename_labels(
                    "dataset-1_{content}_{style}_{take}",
                    "{content}",
                    "{content}, {style} style",
                )
                .set("labels.sidecar", true),
        );
        if with_cmu {
            spec.source(
                Source::new("cmu", "cmu", &["cmu/01_01.bvh"]).event_log_labels("cmu/01_01.csv"),
            )
        } else {
            spec
        }
    }

    fn config(&self, spec: ConfigSpec) -> PathBuf {
        spec.write(self.path("hard.toml"))
    }

    fn dataset(&self) -> PathBuf {
        self.path("out/hard")
    }

    fn json(&self, name: &str) -> Value {
        let path = self.dataset().join(name);
        serde_json::from_slice(&std::fs::read(&path).unwrap_or_else(|e| {
            panic!("{}: {e}", path.display());
        }))
        .unwrap()
    }

    fn rejects(&self) -> Vec<Value> {
        std::fs::read_to_string(self.dataset().join("rejects.jsonl"))
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    }
}

fn build_args(config: &Path) -> Vec<&std::ffi::OsStr> {
    vec!["build".as_ref(), "--config".as_ref(), config.as_os_str()]
}

fn reject_for<'a>(rejects: &'a [Value], file: &str) -> &'a Value {
    rejects
        .iter()
        .find(|r| r["file"].as_str().is_some_and(|f| f.ends_with(file)))
        .unwrap_or_else(|| panic!("no reject for {file}: {rejects:#?}"))
}

/// Every float in every shard and in the normalisation statistics is finite, read by pyarrow.
fn assert_all_finite(dataset: &Path) {
    let script = r#"
import sys, glob, numpy as np, pyarrow as pa, pyarrow.parquet as pq, pyarrow.compute as pc
def floats(arr):
    t = arr.type
    if pa.types.is_floating(t):
        yield arr
    elif pa.types.is_list(t) or pa.types.is_large_list(t) or pa.types.is_fixed_size_list(t):
        yield from floats(pc.list_flatten(arr))
    elif pa.types.is_struct(t):
        for i in range(t.num_fields):
            yield from floats(pc.struct_field(arr, [i]))
files = sorted(glob.glob(sys.argv[1] + "/data/*.parquet")) + sorted(glob.glob(sys.argv[1] + "/normalization/**/*.parquet", recursive=True))
checked = 0
for f in files:
    t = pq.read_table(f)
    for name in t.column_names:
        for chunk in t.column(name).chunks:
            for a in floats(chunk):
                v = a.to_numpy(zero_copy_only=False)
                v = v[~np.isnan(v)] if a.null_count else v
                assert np.isfinite(v).all(), f"{f}: column {name} holds a value that is not finite"
                checked += len(v)
for f in glob.glob(sys.argv[1] + "/normalization/**/*.npy", recursive=True):
    v = np.load(f)
    assert np.isfinite(v).all(), f
    checked += v.size
print(checked)
"#;
    let out = Command::new(common::python())
        .arg("-c")
        .arg(script)
        .arg(dataset)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let checked: u64 = text(&out.stdout).trim().parse().unwrap();
    assert!(checked > 10_000, "only {checked} values checked");
}

/// Defects 1-4, 6 and 10 of one build: every damaged capture is one reject naming its file and
/// line, identical annotation rows are merged, and the good captures are built, under 2 GB.
#[test]
fn damaged_real_captures_cost_one_reject_each_under_a_2_gb_address_space() {
    let case = Case::new();
    let walk = bandai("walk_normal");
    case.capture("walk_normal", &walk);
    // Defect 1: frame times of 1,000,000 s, 1,000 s and 1e20 s per frame.
    case.capture(
        "bye_normal",
        &set_header(&bandai("bye_normal"), "Frame Time:", "1000000"),
    );
    case.capture(
        "bye_happy",
        &set_header(&bandai("bye_happy"), "Frame Time:", "1000"),
    );
    case.capture("kick_normal", &set_header(&walk, "Frame Time:", "1e20"));
    // Defect 2: a claimed frame count of 1e12, once alone and once with 2,000 added joints.
    case.capture(
        "run_normal",
        &set_header(&bandai("run_normal"), "Frames:", "1000000000000"),
    );
    let joints: String = (0..2_000)
        .map(|i| format!("  JOINT extra{i}\n  {{\n    OFFSET 0 1 0\n    CHANNELS 0\n  }}\n"))
        .collect();
    let many = set_header(&bandai("walk-left_normal"), "Frames:", "1000000000000").replacen(
        "  JOINT Hips",
        &format!("{joints}  JOINT Hips"),
        1,
    );
    case.capture("walk-left_normal", &many);
    // Defect 4: one frame with a root position of 1e300.
    let right = bandai("walk-right_normal");
    let frame_line = line_of(&right, "Frame Time:") + 11;
    let damaged: Vec<String> = right
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i as u64 + 1 == frame_line {
                let mut v: Vec<&str> = l.split_ascii_whitespace().collect();
                v[0] = "1e300";
                v.join(" ")
            } else {
                l.to_string()
            }
        })
        .collect();
    case.capture("walk-right_normal", &(damaged.join("\n") + "\n"));
    // Defect 6: CR-only line ends (a real export format) read like any other file.
    case.capture(
        "byebye_tired",
        &bandai("byebye_tired")
            .replace("\r\n", "\n")
            .replace('\n', "\r"),
    );
    // Defect 10: a sidecar whose caption is blank.
    case.capture("walk_angry", &walk);
    std::fs::write(
        case.path("bandai/dataset-1_walk_angry_001.json"),
        r#"{"content": 0, "style": 3, "text": "   "}"#,
    )
    .unwrap();
    // Defect 3: an event log with 2,000 identical rows (and one other).
    std::fs::copy(
        repo().join("fixtures/cmu/01_01.bvh"),
        case.path("cmu/01_01.bvh"),
    )
    .unwrap();
    let mut log = String::from("time,instruction\n");
    for _ in 0..2_000 {
        log.push_str("1.0,jump forward\n");
    }
    log.push_str("6.0,turn around\n");
    std::fs::write(case.path("cmu/01_01.csv"), log).unwrap();

    let config = case.config(Case::spec(true));
    let out = run_limited(&build_args(&config));
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");

    let rejects = case.rejects();
    for r in &rejects {
        let message = r["message"].as_str().unwrap();
        assert!(message.len() < 500, "unbounded reject message: {message}");
    }
    let frame_time = |name: &str, text: &str| {
        let r = reject_for(&rejects, &format!("dataset-1_{name}_001.bvh"));
        assert_eq!(r["line"], line_of(text, "Frame Time:"), "{r}");
        assert!(
            r["message"]
                .as_str()
                .unwrap()
                .contains("frame time must be between"),
            "{r}"
        );
    };
    frame_time("bye_normal", &bandai("bye_normal"));
    frame_time("bye_happy", &bandai("bye_happy"));
    frame_time("kick_normal", &walk);
    let run = reject_for(&rejects, "dataset-1_run_normal_001.bvh");
    assert!(
        run["message"]
            .as_str()
            .unwrap()
            .contains("header declares 1000000000000 frames, file has"),
        "{run}"
    );
    let many = reject_for(&rejects, "dataset-1_walk-left_normal_001.bvh");
    assert!(
        many["message"]
            .as_str()
            .unwrap()
            .contains("more than 1000 joints"),
        "{many}"
    );
    let value = reject_for(&rejects, "dataset-1_walk-right_normal_001.bvh");
    assert_eq!(value["line"], frame_line, "{value}");
    assert_eq!(value["frame"], 10, "{value}");
    assert!(
        value["message"]
            .as_str()
            .unwrap()
            .contains("joint `joint_Root` channel Xposition is 1e300"),
        "{value}"
    );
    assert_eq!(rejects.len(), 6, "{rejects:#?}");

    let report = case.json("build-report.json");
    // 1,999 identical rows merged into the first, with one note; the blank caption dropped.
    assert_eq!(report["drops_by_reason"]["duplicate"], 1999, "{report:#}");
    assert_eq!(report["notes_by_kind"]["duplicate_annotation"], 1);
    assert_eq!(report["drops_by_reason"]["empty_text"], 1);
    let drops = report["drops"].as_array().unwrap();
    assert!(
        drops
            .iter()
            .all(|d| d["file"].as_str().is_some_and(|f| !f.is_empty()))
    );
    assert!(drops.iter().any(|d| {
        d["reason"] == "empty_text"
            && d["file"]
                .as_str()
                .unwrap()
                .ends_with("dataset-1_walk_angry_001.bvh")
    }));
    assert_eq!(
        drops
            .iter()
            .filter(|d| d["reason"] == "duplicate" && d["text"] == "jump forward")
            .count(),
        1999
    );
    // Built: walk, the CR-only byebye, and CMU's two instructions; each with its mirror.
    let actions = &report["actions"];
    assert_eq!(actions["walk"], 1, "{report:#}");
    assert_eq!(actions["byebye"], 1, "{report:#}");
    assert_eq!(actions["jump forward"], 1, "{report:#}");
    assert_eq!(actions["turn around"], 1, "{report:#}");
    assert_eq!(report["mirrored"], 4);
    assert_all_finite(&case.dataset());
}

/// Defect 1, in the config: absurd frame-rate overrides are config errors (exit 2, naming the
/// key), and in an fps table they reject the capture they name.
#[test]
fn absurd_frame_rate_overrides_are_refused_before_any_work() {
    let case = Case::new();
    case.capture("walk_normal", &bandai("walk_normal"));
    case.capture("kick_normal", &bandai("kick_normal"));
    let config = case.config(Case::spec(false).set_in_source("bandai", "fps_override.*", 0.001));
    let out = run_limited(&build_args(&config));
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("sources[0].fps_override"), "{stderr}");
    assert!(stderr.contains("1 to 10000 fps"), "{stderr}");

    // An fps table (BABEL's featp_2_fps.json form) with an absurd rate for one capture.
    std::fs::write(
        case.path("fps.json"),
        r#"{"dataset-1_kick_normal_001": 0.001, "dataset-1_walk_normal_001": 30}"#,
    )
    .unwrap();
    let config = case.config(Case::spec(false).set_in_source("bandai", "fps_table", "fps.json"));
    let out = run_limited(&build_args(&config));
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let rejects = case.rejects();
    assert_eq!(rejects.len(), 1, "{rejects:#?}");
    let r = reject_for(&rejects, "dataset-1_kick_normal_001.bvh");
    assert_eq!(r["reason"], "fps");
    assert_eq!(case.json("build-report.json")["actions"]["walk"], 1);
}

/// Defect 5: when every capture is rejected, the build still ends cleanly: a clear message, the
/// build report and the rejects, and exit code 4.
#[test]
fn a_build_with_no_rows_says_why_and_exits_4() {
    let case = Case::new();
    let walk = bandai("walk_normal");
    case.capture("walk_normal", &set_header(&walk, "Frame Time:", "1000"));
    case.capture("kick_normal", &set_header(&walk, "Frames:", "1e12"));
    let config = case.config(Case::spec(false));
    let out = run_limited(&build_args(&config));
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(4), "{stderr}");
    assert!(
        stderr.contains("0 clips: every capture was rejected (2 of 2 captures)"),
        "{stderr}"
    );
    assert!(stderr.contains("rejects.jsonl"), "{stderr}");
    assert_eq!(case.rejects().len(), 2);
    let report = case.json("build-report.json");
    assert_eq!(report["clips"], 0);
    assert_eq!(report["rejects"].as_array().unwrap().len(), 2);
    // The folder is a valid, empty dataset: a manifest with no rows, no report of rows that are not.
    let manifest = case.json("manifest.json");
    assert_eq!(manifest["splits"], serde_json::json!({}));
    assert!(!case.dataset().join("report/stats.json").exists());

    // Fixing one capture makes the same folder a dataset again.
    case.capture("walk_normal", &walk);
    let out = run_limited(&build_args(&config));
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(case.dataset().join("report/stats.json").is_file());
}

/// Defect 10: a dataset name the file system cannot hold is a config error, not a failed build.
#[test]
fn a_dataset_name_longer_than_a_file_name_can_be_is_a_config_error() {
    let case = Case::new();
    case.capture("walk_normal", &bandai("walk_normal"));
    let config = case.config(Case::spec(false).name(&"n".repeat(300)));
    let out = Command::new(BIN)
        .args(["config", "check", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    let stderr = text(&out.stderr) + &text(&out.stdout);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("dataset.name"), "{stderr}");
    assert!(stderr.contains("at most 200 characters"), "{stderr}");
}

/// Defect 3, for clips that are not identical: 800 distinct segments over one real capture (a
/// BABEL record of CMU 01_01, each about 9 s) make 1,600 clips with their mirrors. The clips'
/// frames go to disk as they are made and are read back one at a time, so the build stays within
/// 1.2 GB of address space (it needed more than that, and aborted, when a capture's clips were
/// held in memory together).
#[test]
fn many_distinct_clips_of_one_capture_keep_memory_bounded() {
    let case = Case::new();
    std::fs::copy(
        repo().join("fixtures/cmu/01_01.bvh"),
        case.path("cmu/01_01.bvh"),
    )
    .unwrap();
    let labels: Vec<Value> = (0..800)
        .map(|i| {
            serde_json::json!({
                "act_cat": ["walk"],
                "start_t": 0.5,
                "end_t": 9.5 + f64::from(i % 10) * 0.01,
                "proc_label": format!("move {i}"),
                "raw_label": format!("move number {i}"),
                "seg_id": format!("s{i}"),
            })
        })
        .collect();
    let record = serde_json::json!({"1": {
        "babel_sid": 1,
        "dur": 22.9,
        "feat_p": "CMU/CMU/01/01_01_poses.npz",
        "frame_ann": {"labels": labels, "mul_act": true},
        "seq_ann": {"labels": []},
    }});
    std::fs::write(case.path("babel.json"), record.to_string()).unwrap();
    let config = ConfigSpec::new("hard")
        .fps(30)
        .mirror(true)
        .synthetic(false)
        .source(Source::new("cmu", "cmu", &["cmu/01_01.bvh"]).babel_labels("babel.json"))
        .write(case.path("many.toml"));
    let out = run_limited_to(1200, &build_args(&config));
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let report = case.json("build-report.json");
    assert_eq!(report["clips"], 1600, "{report:#}");
    assert_eq!(report["mirrored"], 800);
}

/// A BABEL label of a million characters (no caption-file reader bounds it) costs one drop, and
/// the build stays fast and small: the labeller and tagger never see it.
#[test]
fn a_huge_annotation_text_is_dropped_at_segmentation_under_a_1_gb_address_space() {
    let case = Case::new();
    std::fs::copy(
        repo().join("fixtures/cmu/01_01.bvh"),
        case.path("cmu/01_01.bvh"),
    )
    .unwrap();
    let label = |text: String, start: f64| {
        serde_json::json!({
            "act_cat": ["walk"], "start_t": start, "end_t": start + 3.0,
            "proc_label": text.clone(), "raw_label": text, "seg_id": format!("s{start}"),
        })
    };
    let record = serde_json::json!({"1": {
        "babel_sid": 1, "dur": 22.9, "feat_p": "CMU/CMU/01/01_01_poses.npz",
        "frame_ann": {"labels": [label("walk ".repeat(200_000), 1.0), label("walk forward".into(), 5.0)], "mul_act": true},
        "seq_ann": {"labels": []},
    }});
    std::fs::write(case.path("babel.json"), record.to_string()).unwrap();
    let config = ConfigSpec::new("hard")
        .fps(30)
        .synthetic(false)
        .source(Source::new("cmu", "cmu", &["cmu/01_01.bvh"]).babel_labels("babel.json"))
        .write(case.path("huge.toml"));
    let out = run_limited_to(1024, &build_args(&config));
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let report = case.json("build-report.json");
    assert_eq!(report["drops_by_reason"]["long_text"], 1, "{report:#}");
    // The other label and its mirror.
    assert_eq!(report["clips"], 2, "{report:#}");
}
