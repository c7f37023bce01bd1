//! The dataset browser of `motionforge serve` in headless Chromium (Debian's `chromium` and
//! `chromium-driver`, driven by Python selenium; `.ci/run` installs them): the page lists the demo's
//! clips, filters them to the counts an independent reader gives, draws a clip beside its mirror,
//! and plays. Screenshots are kept in `target/tmp/browser/`.
mod common;

use common::repo;
use common::service::start_service;
use motionforge::build::{BuildOptions, build};
use motionforge::config::Config;

const SCRIPT: &str = include_str!("browser/check_page.py");

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_filters_plays_and_draws_a_clip_beside_its_mirror() {
    let out = tempfile::tempdir().unwrap();
    let state = tempfile::tempdir().unwrap();
    let mut config = Config::load(&repo().join("fixtures/demo.toml")).unwrap();
    config.dataset.output = out.path().to_path_buf();
    let built = config.clone();
    tokio::task::spawn_blocking(move || build(&built, &BuildOptions::default()).unwrap())
        .await
        .unwrap();
    // Expected counts from the report's reader, not from the code the page calls.
    let tables = motionforge::report::find_clip_tables(&config.dataset_dir()).unwrap();
    let rows = motionforge::report::read_rows(&tables).unwrap();
    let count =
        |f: &dyn Fn(&motionforge::report::ClipRow) -> bool| rows.iter().filter(|r| f(r)).count();
    let filters = serde_json::json!([
        [
            "filter-type",
            "wave",
            count(&|r| r.motion_type.as_deref() == Some("wave"))
        ],
        ["filter-split", "train", count(&|r| r.split == "train")],
        [
            "filter-kind",
            "synthetic",
            count(&|r| r.source_kind == "synthetic")
        ],
        ["filter-kind", "mirrored", count(&|r| r.mirrored)],
    ]);
    let expected = serde_json::json!({
        "all": rows.len(),
        "filters": filters,
        "text": ["byebye", count(&|r| r.clip_id.contains("byebye"))],
    });
    assert!(rows.len() >= 20 && count(&|r| r.source_kind == "synthetic") > 0);

    let (service, base) = start_service(
        state.path(),
        vec![config],
        env!("CARGO_BIN_EXE_motionforge").into(),
        "t0ken",
    )
    .await;
    let shots = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("browser");
    let args = vec![
        base.clone(),
        expected.to_string(),
        "bandai-namco-1/dataset-1_walk-left_normal_001:0-135".to_string(),
        shots.display().to_string(),
    ];
    let summary = tokio::task::spawn_blocking(move || common::run_python(SCRIPT, &args))
        .await
        .unwrap();
    eprintln!("{summary}");
    let summary: serde_json::Value = serde_json::from_str(summary.trim()).unwrap();
    assert!(summary["frame_after_play"].as_u64().unwrap() > 0);
    for shot in ["browser-paused.png", "browser-playing.png"] {
        let bytes = std::fs::read(shots.join(shot)).unwrap();
        assert!(bytes.len() > 10_000 && &bytes[1..4] == b"PNG", "{shot}");
    }
    service.stop().await.unwrap();
}
