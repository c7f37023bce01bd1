//! The build end to end on real captures: outputs, reuse of unchanged work, rejects, determinism.
use crate::common;

use std::fs;
use std::path::{Path, PathBuf};

use common::project::{ConfigSpec, Project, Source};
use common::*;
use motionforge::build::{BuildOptions, BuildReport, build};
use motionforge::config::Config;

/// Real captures (and their sidecars) copied into a fresh project with a config for them.
struct Scratch {
    project: Project,
}

/// The captures in `captures/` as the source `name`, labelled from their file names and sidecars.
fn bandai_source(name: &str) -> Source {
    Source::new(name, "bandai-namco", &["captures/*.bvh"])
        .filename_labels(
            "dataset-1_{content}_{style}_{take}",
            "{content}",
            "{content}, {style} style",
        )
        .set("labels.sidecar", true)
}

/// The scratch config: one source, 30 fps.
fn scratch_spec() -> ConfigSpec {
    ConfigSpec::new("scratch")
        .fps(30)
        .source(bandai_source("bandai-namco-1"))
}

impl Scratch {
    fn new(captures: &[&str]) -> Scratch {
        let project = Project::new()
            .captures_with("bandai-namco-1", captures, &["bvh", "json"])
            .config(scratch_spec())
            .build();
        Scratch { project }
    }

    fn captures(&self) -> PathBuf {
        self.project.join("captures")
    }

    fn config_path(&self) -> PathBuf {
        self.project.config_path()
    }

    /// The dataset folder, `<output>/<name>`.
    fn out(&self) -> PathBuf {
        self.project.join("out/scratch")
    }

    fn build(&self) -> BuildReport {
        let config = Config::load(&self.config_path()).unwrap();
        build(&config, &BuildOptions::default()).unwrap()
    }
}

fn ran(report: &BuildReport, stage: &str) -> usize {
    report
        .stages
        .iter()
        .find(|s| s.stage == stage)
        .map(|s| s.ran)
        .unwrap_or(usize::MAX)
}

const THREE: [&str; 3] = [
    "dataset-1_walk-left_normal_001",
    "dataset-1_walk_normal_001",
    "dataset-1_bye_happy_001",
];

#[test]
fn build_writes_originals_and_mirrors_and_reuses_unchanged_work() {
    let s = Scratch::new(&THREE);
    let first = s.build();
    assert_eq!(first.captures, 3);
    assert_eq!(
        first.kinds.get("real_single"),
        Some(&6),
        "3 clips and their mirrors"
    );
    assert_eq!(first.mirrored, 3);
    assert!(first.rejects.is_empty(), "{:?}", first.rejects);
    assert_eq!(
        (
            ran(&first, "ingest"),
            ran(&first, "mirror"),
            ran(&first, "write")
        ),
        (3, 3, 1)
    );

    let again = s.build();
    assert!(
        again.nothing_ran(),
        "second build re-ran work: {:?}",
        again.stages
    );

    // Change one capture: only its items re-run, and the table is rewritten.
    let path = s.captures().join("dataset-1_walk_normal_001.bvh");
    let text = fs::read_to_string(&path).unwrap();
    fs::write(
        &path,
        text.replacen("Frame Time:\t0.0333333", "Frame Time:\t0.0333334", 1),
    )
    .unwrap();
    let third = s.build();
    assert_eq!(
        (
            ran(&third, "ingest"),
            ran(&third, "mirror"),
            ran(&third, "write")
        ),
        (1, 1, 1)
    );

    // A deleted output is noticed and rewritten even though no input changed.
    let shard = shards(&s.out())[0].clone();
    fs::remove_file(&shard).unwrap();
    let fourth = s.build();
    assert_eq!(ran(&fourth, "write"), 1);
    assert!(shard.is_file());
}

#[test]
fn same_inputs_give_byte_identical_tables() {
    let a = Scratch::new(&THREE);
    let b = Scratch::new(&[THREE[2], THREE[0], THREE[1]]);
    a.build();
    b.build();
    let ta = table_bytes(&a.out());
    let tb = table_bytes(&b.out());
    assert!(ta == tb, "tables differ between identical builds");
    // And a forced rebuild reproduces the same bytes.
    let config = Config::load(&a.config_path()).unwrap();
    build(
        &config,
        &BuildOptions {
            force: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(table_bytes(&a.out()) == ta);
}

#[test]
fn bad_captures_are_rejected_with_file_and_line_and_the_build_goes_on() {
    let s = Scratch::new(&THREE);
    let real =
        fs::read_to_string(shared_data().join("bandai-namco-1/data/dataset-1_kick_normal_001.bvh"))
            .unwrap();
    let lines: Vec<&str> = real.lines().collect();
    let motion_at = lines.iter().position(|l| l.starts_with("MOTION")).unwrap();
    let write = |name: &str, text: String| {
        fs::write(
            s.captures()
                .join(format!("dataset-1_{name}_normal_001.bvh")),
            text,
        )
        .unwrap()
    };
    // Truncated: the last 50 lines lost.
    write("truncated", lines[..lines.len() - 50].join("\n"));
    // A motion line with one value missing.
    let mut short = lines.clone();
    let cut = short[motion_at + 5]
        .trim_end()
        .rsplit_once(' ')
        .unwrap()
        .0
        .to_string();
    short[motion_at + 5] = &cut;
    write("short-line", short.join("\n"));
    // Text where a number belongs.
    write(
        "text-number",
        real.replacen("OFFSET 0 93.9241 -3", "OFFSET 0 ninety -3", 1),
    );
    // No MOTION section.
    write("no-motion", lines[..motion_at].join("\n"));
    // A name the label pattern does not match.
    fs::write(s.captures().join("kick.bvh"), &real).unwrap();

    let report = s.build();
    assert_eq!(
        report.kinds.get("real_single"),
        Some(&6),
        "good captures still built; rejects: {:#?}",
        report.rejects
    );
    let find = |file: &str| {
        report
            .rejects
            .iter()
            .find(|r| r.file.contains(file))
            .unwrap_or_else(|| panic!("no reject for {file}: {:?}", report.rejects))
    };
    let truncated = find("truncated");
    assert_eq!(truncated.reason.as_str(), "bvh");
    assert!(truncated.message.contains("truncated"), "{truncated}");
    let short = find("short-line");
    assert_eq!(short.line, Some(motion_at as u64 + 6));
    assert_eq!(short.frame, Some(2));
    assert!(short.message.contains("expected 132"), "{short}");
    let text = find("text-number");
    assert_eq!(text.line, Some(8));
    assert!(text.message.contains("ninety"), "{text}");
    let missing = find("no-motion");
    assert!(missing.message.contains("MOTION"), "{missing}");
    let pattern = find("kick.bvh");
    assert_eq!(pattern.reason.as_str(), "label_pattern");
    assert!(
        pattern
            .message
            .contains("dataset-1_{content}_{style}_{take}"),
        "{pattern}"
    );

    // The rejects file lists the same, one JSON object per line.
    let listed = fs::read_to_string(s.out().join("rejects.jsonl")).unwrap();
    assert_eq!(listed.lines().count(), report.rejects.len());
    assert_eq!(report.rejects.len(), 5);
    // Rejected inputs are cached like the rest: a second build re-runs nothing.
    let again = s.build();
    assert!(again.nothing_ran(), "{:?}", again.stages);
    assert_eq!(again.rejects, report.rejects);
    // No temporary file is left behind.
    for entry in fs::read_dir(s.out()).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.ends_with(".tmp"), "left over: {name}");
    }
}

#[test]
fn mirrored_rows_carry_mirrored_labels() {
    let s = Scratch::new(&THREE[..1]);
    s.build();
    let rows = pyarrow_rows(&s.out().join("data"), "clip_id,mirrored,action,text");
    assert_eq!(
        rows,
        vec![
            "bandai-namco-1/dataset-1_walk-left_normal_001:0-135|False|walk-left|walk left, normal style",
            "bandai-namco-1/dataset-1_walk-left_normal_001:0-135:m|True|walk-right|walk right, normal style",
        ]
    );
}

#[test]
fn pyarrow_and_polars_read_positions_as_frames_by_joints_by_3() {
    let s = Scratch::new(&THREE);
    let report = s.build();
    let script = r#"
import sys, numpy as np, pyarrow.parquet as pq, polars as pl
t = pq.read_table(sys.argv[1])
assert t.num_rows == int(sys.argv[2]), t.num_rows
for i in range(t.num_rows):
    n, j = t['num_frames'][i].as_py(), t['num_joints'][i].as_py()
    p = np.array(t['joint_positions'][i].as_py())
    q = np.array(t['local_rotations'][i].as_py())
    r = np.array(t['root_translation'][i].as_py())
    assert (p.shape, q.shape, r.shape) == ((n, j, 3), (n, j, 4), (n, 3)), (p.shape, q.shape, r.shape)
    assert np.allclose(np.linalg.norm(q, axis=-1), 1, atol=1e-5)
    assert 1.2 < p[0, :, 2].max() - p[0, :, 2].min() < 2.0, 'body height in metres, z up'
    assert np.allclose(r, p[:, 1, :]), 'root translation is the Hips position'
df = pl.read_parquet(sys.argv[1])
assert df.schema['joint_positions'] == pl.List(pl.List(pl.Array(pl.Float32, 3))), df.schema['joint_positions']
# One clip's frames: a list (frames) of joint lists; fixing the joint count gives the ndarray.
first = df['joint_positions'][0].list.to_array(df['num_joints'][0]).to_numpy()
assert first.shape == (df['num_frames'][0], df['num_joints'][0], 3), first.shape
assert np.allclose(first, np.array(t['joint_positions'][0].as_py()))
print('ok')
"#;
    run_python(
        script,
        &[
            s.out().join("data").into_os_string(),
            report.clips.to_string().into(),
        ],
    );
}

#[test]
fn the_schema_in_schemas_matches_the_writer() {
    let documented: serde_json::Value = serde_json::from_str(
        &fs::read_to_string(repo().join("schemas/clips.schema.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(
        documented,
        motionforge::io::schema::clip_schema_json(),
        "run `motionforge schema > schemas/clips.schema.json` and document the change in schemas/clips.md"
    );
}

#[test]
fn config_errors_name_the_key_and_what_was_expected() {
    let err = Config::parse("[dataset]\nname = \"x\"\noutput = \"o\"\nfps = -3\n[[sources]]\nname = \"s\"\ncaptures = [\"*.bvh\"]\nprofile = \"cmu\"\n[sources.labels]\nkind = \"filename\"\npattern = \"{a}\"\naction = \"{a}\"\ntext = \"{a}\"\n", Path::new("c.toml")).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("c.toml") && msg.contains("dataset.fps") && msg.contains("-3"),
        "{msg}"
    );
    let err = Config::parse(
        "[dataset]\nname = \"x\"\noutptu = \"o\"\n",
        Path::new("c.toml"),
    )
    .unwrap_err();
    assert!(err.to_string().contains("outptu"), "{err}");
}

#[test]
fn demo_build_segments_the_long_capture_and_prints_counts() {
    let out = tempfile::tempdir().unwrap();
    let run = build_demo(out.path());
    let printed = String::from_utf8(run.stdout).unwrap();
    assert!(
        printed.contains("motion types (originals):") && printed.contains("walk forward 1"),
        "{printed}"
    );
    assert!(printed.contains("dropped segments:"), "{printed}");
    let report: serde_json::Value =
        serde_json::from_slice(&fs::read(out.path().join("demo/build-report.json")).unwrap())
            .unwrap();
    assert_eq!(report["captures"], 9);
    assert_eq!(
        report["clips"], 24,
        "10 clips, their mirrors, 4 synthetic pairs within splits (a fifth, kick:m + bye:m, keeps 0.34 of the kick and is dropped as action_cut)"
    );
    let rows = pyarrow_rows(
        &out.path().join("demo/data"),
        "clip_id,annotation_source,frame_range",
    );
    let cmu: Vec<&String> = rows
        .iter()
        .filter(|r| r.starts_with("cmu/01_01:"))
        .collect();
    assert_eq!(
        cmu.len(),
        4,
        "two crops of CMU 01_01 and their mirrors: {rows:?}"
    );
    assert!(cmu.iter().all(|r| r.contains("frame_index")));
    assert!(
        cmu.iter().any(|r| r.contains("'start': 115, 'end': 1315")),
        "{cmu:?}"
    );
}

#[test]
fn the_same_captures_under_two_source_names_build() {
    // Identical captures give identical, content-named frame chunks, which two threads then write
    // at the same moment; each write has a temporary file of its own (`temp_path`).
    let s = Scratch::new(&THREE);
    let two = scratch_spec().source(bandai_source("copy"));
    fs::write(s.config_path(), two.render()).unwrap();
    for _ in 0..3 {
        let _ = fs::remove_dir_all(s.out());
        let report = s.build();
        assert_eq!(report.captures, 6);
        assert_eq!(report.mirrored, 6, "{:?}", report.rejects);
    }
}

/// Bytes of every file under `dir`.
fn folder_bytes(dir: &Path) -> u64 {
    let Ok(entries) = fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .map(|e| {
            let path = e.path();
            if path.is_dir() {
                folder_bytes(&path)
            } else {
                e.metadata().map_or(0, |m| m.len())
            }
        })
        .sum()
}

#[test]
fn a_changed_annotation_resegments_from_the_ingest_record_and_matches_a_fresh_build() {
    let s = Scratch::new(&THREE);
    s.build();
    // The cache keeps each segmented clip's frames once: no parsed captures, no mirrored or
    // synthetic frames (made again when read), so it stays under the size of the captures.
    let cache = s.out().join(".motionforge/cache");
    for gone in ["mirror-motions", "synthetic"] {
        assert!(!cache.join(gone).exists(), "{gone} should not be stored");
    }
    let input = folder_bytes(&s.captures());
    let cached = folder_bytes(&cache);
    assert!(
        cached < input,
        "stage cache {cached} bytes for {input} bytes of captures"
    );

    // A new sidecar value changes the capture's annotation: the capture is not ingested again,
    // its segments are cut again from the file, and the table is what a fresh build writes.
    let sidecar = s.captures().join("dataset-1_bye_happy_001.json");
    fs::write(&sidecar, r#"{"content": 7, "style": 2}"#).unwrap();
    let again = s.build();
    assert_eq!(
        (
            ran(&again, "ingest"),
            ran(&again, "segment"),
            ran(&again, "write")
        ),
        (0, 1, 1)
    );
    let fresh = Scratch::new(&THREE);
    fs::copy(
        &sidecar,
        fresh.captures().join("dataset-1_bye_happy_001.json"),
    )
    .unwrap();
    fresh.build();
    assert!(
        table_bytes(&s.out()) == table_bytes(&fresh.out()),
        "the incremental table differs from a fresh build's"
    );
}

/// Sets `path`'s modification time `ago` in the past.
fn age(path: &Path, ago: std::time::Duration) {
    let file = fs::OpenOptions::new().append(true).open(path).unwrap();
    file.set_modified(std::time::SystemTime::now() - ago)
        .unwrap();
}

#[test]
fn capture_digests_are_remembered_by_stat_data_and_a_modified_capture_is_still_noticed() {
    let s = Scratch::new(&THREE);
    let hour = std::time::Duration::from_secs(3600);
    for name in THREE {
        age(&s.captures().join(format!("{name}.bvh")), hour);
    }
    let first = s.build();
    let digests = s.out().join(".motionforge/file-digests.json");
    let remembered: serde_json::Value =
        serde_json::from_slice(&fs::read(&digests).unwrap()).unwrap();
    assert_eq!(remembered.as_object().map(|o| o.len()), Some(3));
    assert!(s.build().nothing_ran());

    // New content with a new modification time: read, hashed, ingested again.
    let path = s.captures().join("dataset-1_walk_normal_001.bvh");
    let text = fs::read_to_string(&path).unwrap();
    fs::write(
        &path,
        text.replacen("Frame Time:\t0.0333333", "Frame Time:\t0.0333334", 1),
    )
    .unwrap();
    age(&path, hour / 2);
    let second = s.build();
    assert_eq!((ran(&second, "ingest"), ran(&second, "write")), (1, 1));
    assert_ne!(
        first.table_fingerprint, second.table_fingerprint,
        "the edited capture must change the table"
    );

    // A file modified moments ago is not remembered (its stat data could still change within
    // the same clock tick), so the next build hashes it again.
    fs::write(&path, &text).unwrap();
    let third = s.build();
    assert_eq!(ran(&third, "ingest"), 1);
    assert_eq!(third.table_fingerprint, first.table_fingerprint);
    let remembered: serde_json::Value =
        serde_json::from_slice(&fs::read(&digests).unwrap()).unwrap();
    assert_eq!(remembered.as_object().map(|o| o.len()), Some(2));
}

#[test]
fn zstd_levels_from_the_fast_range_to_22_are_accepted_and_others_refused_by_name() {
    let path = repo().join("fixtures/demo.toml");
    let demo = fs::read_to_string(&path).unwrap();
    let with = |level: i32| {
        demo.replacen(
            "seed = 42\n",
            &format!("seed = 42\nzstd_level = {level}\n"),
            1,
        )
    };
    for level in [-7, -1, 1, 22] {
        let config = Config::parse(&with(level), &path)
            .unwrap_or_else(|e| panic!("level {level} refused: {e}"));
        assert_eq!(config.dataset.zstd_level, level);
    }
    for level in [-8, 0, 23] {
        let err = Config::parse(&with(level), &path).unwrap_err().to_string();
        assert!(
            err.contains("zstd_level") && err.contains(&level.to_string()),
            "level {level}: {err}"
        );
    }
}

#[test]
fn a_fast_zstd_level_writes_shards_with_the_same_rows() {
    let path = repo().join("fixtures/demo.toml");
    let demo = fs::read_to_string(&path).unwrap();
    let fast = demo.replacen("seed = 42\n", "seed = 42\nzstd_level = -5\n", 1);
    let dir = tempfile::tempdir().unwrap();
    let built = |text: &str, name: &str| {
        let mut config = Config::parse(text, &path).unwrap();
        config.dataset.output = dir.path().join(name);
        build(&config, &BuildOptions::default()).unwrap();
        config.dataset.output.join("demo")
    };
    let a = built(&demo, "level1");
    let b = built(&fast, "fast");
    let (sa, sb) = (shards(&a), shards(&b));
    assert_eq!(sa.len(), sb.len());
    let read = |p: &Path| {
        let file = fs::File::open(p).unwrap();
        let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
            .unwrap()
            .build()
            .unwrap();
        reader.map(|b| b.unwrap()).collect::<Vec<_>>()
    };
    for (x, y) in sa.iter().zip(&sb) {
        assert_ne!(
            fs::read(x).unwrap(),
            fs::read(y).unwrap(),
            "the level reached the file"
        );
        assert_eq!(read(x), read(y), "{}", x.display());
    }
}
