//! `plan`, `status` and `run <stage>`: what a build would run and why, checked against what the
//! build then does.

use crate::common;

use motionforge::build::{BuildOptions, Plan, Stage, StaleReason, build, plan, status};
use motionforge::config::Config;

use common::project::Project;

/// A copy of the bundled fixtures (so a test may edit a capture) and its config writing into
/// the copy.
fn scratch() -> (Project, Config) {
    let project = Project::new()
        .copy(common::repo().join("fixtures"), "fixtures")
        .build();
    let mut config = Config::load(&project.join("fixtures/demo.toml")).unwrap();
    config.dataset.output = project.join("out");
    (project, config)
}

fn stage(plan: &Plan, stage: Stage) -> &motionforge::build::StagePlan {
    plan.stages.iter().find(|s| s.stage == stage).unwrap()
}

fn ran(report: &motionforge::build::BuildReport, name: &str) -> usize {
    report
        .stages
        .iter()
        .find(|s| s.stage == name)
        .map_or(0, |s| s.ran)
}

#[test]
fn plan_names_new_captures_then_nothing_after_a_build() {
    let (_dir, config) = scratch();
    let before = plan(&config, &BuildOptions::default()).unwrap();
    let ingest = stage(&before, Stage::Ingest);
    assert_eq!(ingest.to_run, 9, "{before:#?}");
    assert_eq!(ingest.reasons.get(&StaleReason::New), Some(&9));
    // Nothing past ingest can be known before it runs.
    assert!(
        stage(&before, Stage::Write)
            .reasons
            .contains_key(&StaleReason::Upstream(Stage::Ingest))
    );
    // Planning computed and wrote nothing.
    assert!(!config.dataset_dir().join("data").exists());

    build(&config, &BuildOptions::default()).unwrap();
    let after = plan(&config, &BuildOptions::default()).unwrap();
    assert!(after.nothing_to_run(), "{after:#?}");
    let status = status(&config).unwrap();
    assert!(
        status
            .stages
            .iter()
            .all(|s| s.fresh && (s.last_run.is_some() || !s.enabled))
    );
    // The demo's pair check is off (no `synthetic.llm_check`): it never ran, and says so.
    let pair_check = status.stages.iter().find(|s| s.stage == Stage::PairCheck);
    assert!(pair_check.is_some_and(|s| !s.enabled && s.last_run.is_none()));
    let rows: u64 = status.splits.iter().map(|(_, n)| n).sum();
    assert_eq!(rows, 24);
    assert_eq!(status.splits[0].0, "train");
}

#[test]
fn plan_says_which_config_key_changed_and_the_build_agrees() {
    let (_dir, mut config) = scratch();
    build(&config, &BuildOptions::default()).unwrap();
    config.dataset.seed += 1;
    let p = plan(&config, &BuildOptions::default()).unwrap();
    for fresh in [Stage::Ingest, Stage::Segment, Stage::Label, Stage::Mirror] {
        assert!(stage(&p, fresh).fresh(), "{fresh} should be fresh: {p:#?}");
    }
    let compose = stage(&p, Stage::Compose);
    assert_eq!(
        compose.reasons.keys().collect::<Vec<_>>(),
        [&StaleReason::Changed(vec!["config dataset.seed".into()])]
    );
    let report = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(ran(&report, "mirror"), 0);
    assert_eq!(ran(&report, "segment"), 0);
    assert!(ran(&report, "compose") > 0);
}

#[test]
fn plan_names_the_capture_whose_file_changed() {
    let (dir, config) = scratch();
    build(&config, &BuildOptions::default()).unwrap();
    let file = dir
        .path()
        .join("fixtures/bandai-namco-1/data/dataset-1_kick_normal_001.bvh");
    // Same motion, one more trailing newline: the bytes (and so the fingerprint) change.
    let mut bytes = std::fs::read(&file).unwrap();
    bytes.push(b'\n');
    std::fs::write(&file, bytes).unwrap();
    let p = plan(&config, &BuildOptions::default()).unwrap();
    let ingest = stage(&p, Stage::Ingest);
    assert_eq!(ingest.to_run, 1, "{p:#?}");
    assert_eq!(
        ingest.reasons.keys().collect::<Vec<_>>(),
        [&StaleReason::Changed(vec!["file content".into()])]
    );
    assert!(ingest.examples[0].contains("dataset-1_kick_normal_001.bvh"));
    let report = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(ran(&report, "ingest"), 1);
}

#[test]
fn run_segment_runs_its_dependencies_and_nothing_after() {
    let (_dir, config) = scratch();
    let report = build(
        &config,
        &BuildOptions {
            through: Some(Stage::Segment),
            ..BuildOptions::default()
        },
    )
    .unwrap();
    let names: Vec<&str> = report.stages.iter().map(|s| s.stage.as_str()).collect();
    assert_eq!(names, ["ingest", "segment"]);
    assert!(!config.dataset_dir().join("data").exists());
    assert!(!config.dataset_dir().join("build-report.json").exists());
    let p = plan(&config, &BuildOptions::default()).unwrap();
    assert!(stage(&p, Stage::Segment).fresh(), "{p:#?}");
    assert!(!stage(&p, Stage::Label).fresh());
    // The full build reuses the segments.
    let full = build(&config, &BuildOptions::default()).unwrap();
    assert_eq!(ran(&full, "segment"), 0);
    assert_eq!(full.clips, 24);
}

#[test]
fn stage_names_parse_and_unknown_ones_are_refused() {
    assert_eq!("mirror".parse::<Stage>(), Ok(Stage::Mirror));
    let err = "mirrors".parse::<Stage>().unwrap_err();
    assert!(err.contains("expected one of ingest, segment"), "{err}");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["run", "segmnt", "--config", "fixtures/demo.toml"])
        .current_dir(common::repo())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown stage `segmnt`"));
}

#[test]
fn the_commands_print_plan_and_status() {
    let out = tempfile::tempdir().unwrap();
    let bin = env!("CARGO_BIN_EXE_motionforge");
    let config = common::repo().join("fixtures/demo.toml");
    let run = |args: &[&str]| {
        std::process::Command::new(bin)
            .args(args)
            .arg("--config")
            .arg(&config)
            .arg("--output")
            .arg(out.path())
            .output()
            .unwrap()
    };
    let segment = run(&["run", "segment"]);
    assert!(
        segment.status.success(),
        "{}",
        String::from_utf8_lossy(&segment.stderr)
    );
    let plan = run(&["--json", "plan"]);
    assert!(plan.status.success());
    let plan: serde_json::Value = serde_json::from_slice(&plan.stdout).unwrap();
    let stages = plan["stages"].as_array().unwrap();
    assert_eq!(stages[1]["stage"], "segment");
    assert_eq!(stages[1]["to_run"], 0);
    assert_eq!(stages[2]["stage"], "label");
    // Counted as the build counts it: ten clips to label, not the stage's one cache entry.
    assert_eq!(stages[2]["reasons"]["new"], 10, "{plan}");
    assert_eq!(stages[2]["to_run"], 10, "{plan}");
    let build = run(&["build"]);
    assert!(build.status.success());
    let status = run(&["status"]);
    let text = String::from_utf8_lossy(&status.stdout);
    assert!(status.status.success());
    assert!(text.contains("train 16, validation 2, test 6"), "{text}");
    // Every stage but the pair check, which the demo turns off.
    assert_eq!(text.matches(" fresh ").count(), 10, "{text}");
    assert_eq!(text.matches(" off ").count(), 1, "{text}");
}
