//! The dataset browser of `motionforge serve` in headless Chromium (Debian's `chromium` and
//! `chromium-driver`, driven by Python selenium; `.ci/run` installs them): the page lists the demo's
//! clips, filters them to the counts an independent reader gives, draws a clip beside its mirror,
//! and plays. Screenshots are kept in `target/tmp/browser/`.
mod common;

use common::repo;
use common::service::start_service;
use motionforge::build::{BuildOptions, build};
use motionforge::config::Config;
use serde_json::Value;

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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn browser_endpoints_page_the_clips_answer_f32_motions_and_stay_inside_the_report() {
    use common::service::get;
    let out = tempfile::tempdir().unwrap();
    let state = tempfile::tempdir().unwrap();
    let mut config = Config::load(&repo().join("fixtures/demo.toml")).unwrap();
    config.dataset.output = out.path().to_path_buf();
    let built = config.clone();
    tokio::task::spawn_blocking(move || build(&built, &BuildOptions::default()).unwrap())
        .await
        .unwrap();
    let ds = config.dataset_dir();
    // A file beside the report that must never be answered.
    std::fs::write(ds.join("secret.txt"), "not for the browser").unwrap();
    let (service, base) = start_service(
        state.path(),
        vec![config],
        env!("CARGO_BIN_EXE_motionforge").into(),
        "t0ken",
    )
    .await;
    let client = reqwest::Client::new();

    // Pages of 10 cover the listing once, in order.
    let (status, all) = get(&client, &format!("{base}/datasets/demo/clips?limit=1000")).await;
    assert_eq!(status, 200, "{all}");
    let total = all["total"].as_u64().unwrap() as usize;
    let mut paged = Vec::new();
    for offset in (0..total).step_by(10) {
        let (_, page) = get(
            &client,
            &format!("{base}/datasets/demo/clips?limit=10&offset={offset}"),
        )
        .await;
        paged.extend(page["clips"].as_array().unwrap().iter().cloned());
    }
    assert_eq!(&Value::from(paged), &all["clips"]);
    let (status, _) = get(&client, &format!("{base}/datasets/demo/clips?limit=0")).await;
    assert_eq!(status, 400);

    // One clip: its mirror is named; its motion has frames × joints × 3 numbers, and the first
    // frame's pelvis is on the ground at the origin (the canonical frame).
    let id = "cmu/01_01:1207-2407";
    let (status, meta) = get(&client, &format!("{base}/datasets/demo/clip?id={id}")).await;
    assert_eq!(status, 200, "{meta}");
    assert_eq!(meta["mirror"], format!("{id}:m"));
    let (status, motion) = get(&client, &format!("{base}/datasets/demo/motion?id={id}")).await;
    assert_eq!(status, 200);
    let (frames, joints) = (
        motion["frames"].as_u64().unwrap() as usize,
        motion["joints"].as_u64().unwrap() as usize,
    );
    let positions = motion["positions"].as_array().unwrap();
    assert_eq!((frames, positions.len()), (300, frames * joints * 3));
    let root = motion["names"]
        .as_array()
        .unwrap()
        .iter()
        .position(|n| n == &motion["root"])
        .unwrap();
    for k in 0..2 {
        assert!(positions[root * 3 + k].as_f64().unwrap().abs() < 1e-6);
    }
    let (status, body) = get(&client, &format!("{base}/datasets/demo/motion?id=nope")).await;
    assert_eq!(status, 404, "{body}");

    // The report's files, and nothing outside the report folder.
    let (_, files) = get(&client, &format!("{base}/datasets/demo/report")).await;
    let files: Vec<&str> = files["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    assert!(files.contains(&"report.md") && files.contains(&"gallery/wave.png"));
    let png = client
        .get(format!(
            "{base}/datasets/demo/report/file?path=gallery/wave.png"
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(png.headers()["content-type"], "image/png");
    assert_eq!(&png.bytes().await.unwrap()[1..4], b"PNG");
    for path in [
        "../secret.txt",
        "/etc/passwd",
        "figures/../../secret.txt",
        "",
    ] {
        let (status, body) = get(
            &client,
            &format!("{base}/datasets/demo/report/file?path={path}"),
        )
        .await;
        assert_eq!(status, 400, "{path}: {body}");
        assert!(!body.to_string().contains("not for the browser"));
    }
    service.stop().await.unwrap();
}
