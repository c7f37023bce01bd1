//! The sharded training set: layout any loader opens, manifest checksums, splits, rebuilds.
use crate::common;

use std::fs;
use std::process::Command;

use common::project::{ConfigSpec, Project, Source};
use common::*;

/// Builds the demo into a temp folder and returns (temp dir, dataset folder).
fn demo() -> (tempfile::TempDir, std::path::PathBuf) {
    let out = tempfile::tempdir().unwrap();
    build_demo(out.path());
    let dataset = out.path().join("demo");
    (out, dataset)
}

#[test]
fn pyarrow_and_polars_read_the_demo_with_checked_manifest_and_splits() {
    let (_out, dataset) = demo();
    let script = r#"
import glob, hashlib, json, os, sys
import numpy as np, pyarrow.parquet as pq
root = sys.argv[1]
manifest = json.load(open(os.path.join(root, 'manifest.json')))
assert manifest['schema_version'] == 9, manifest['schema_version']
total = 0
captures = {}
for split, entry in manifest['splits'].items():
    rows = 0
    for shard in entry['shards']:
        path = os.path.join(root, shard['file'])
        data = open(path, 'rb').read()
        assert hashlib.sha256(data).hexdigest() == shard['sha256'], path
        assert len(data) == shard['bytes'], path
        t = pq.read_table(path)
        assert t.num_rows == shard['rows'], path
        assert set(t.column('split').to_pylist()) == {split}, path
        # Writer properties (`docs/decisions.md`, "Shard writer"): per-frame float lists carry no
        # min/max statistics, scalar columns keep theirs.
        meta = pq.ParquetFile(path).metadata
        for g in range(meta.num_row_groups):
            group = meta.row_group(g)
            chunks = {group.column(c).path_in_schema: group.column(c) for c in range(group.num_columns)}
            frame_lists = [n for n in chunks if n.split('.')[0] in ('joint_positions', 'local_rotations', 'canonical_positions', 'root_translation')]
            assert len(frame_lists) == 4, sorted(chunks)
            assert not any(chunks[n].is_stats_set for n in frame_lists), path
            assert chunks['num_frames'].is_stats_set, path
        for p in t.column('source_path').to_pylist():
            captures.setdefault(p, set()).add(split)
        rows += t.num_rows
    assert rows == entry['rows'], split
    total += rows
assert all(len(s) == 1 for s in captures.values()), 'a capture in two splits'
files = sorted(glob.glob(os.path.join(root, 'data', '*.parquet')))
listed = sorted(os.path.join(root, s['file']) for e in manifest['splits'].values() for s in e['shards'])
assert files == listed, (files, listed)
t = pq.read_table(os.path.join(root, 'data'))
assert t.num_rows == total
# Per-frame arrays come shaped (version 9): pyarrow's nested lists give the array as is.
def shaped(table, column, i, dtype=np.float64):
    return np.array(table[column][i].as_py(), dtype=dtype)
for i in range(t.num_rows):
    n, j = t['num_frames'][i].as_py(), t['num_joints'][i].as_py()
    assert shaped(t, 'joint_positions', i).shape == (n, j, 3)
    # Opt-in columns (`docs/decisions.md`, "Derived columns"): null unless switched on.
    assert t['rotations_6d'][i].as_py() is None and t['joint_velocities'][i].as_py() is None
    assert shaped(t, 'foot_contacts', i, bool).shape == (n, 4)
    assert shaped(t, 'future_root', i).shape == (n, 3, 3)
    # Canonical positions: the same motion moved rigidly (rotation about z, then a shift), the
    # first frame's pelvis (the root-motion joint, `root_translation`) over the origin.
    world = shaped(t, 'joint_positions', i)
    canon = shaped(t, 'canonical_positions', i)
    assert canon.shape == world.shape
    root0 = shaped(t, 'root_translation', i)[0]
    pelvis = int(np.argmin(np.abs(world[0] - root0).sum(1)))
    assert np.abs(canon[0, pelvis, :2]).max() < 1e-4, canon[0, pelvis]
    assert np.abs(canon[..., 2] - world[..., 2]).max() < 1e-4, 'heights kept'
    d_world = np.linalg.norm(world[:, :, None] - world[:, None, :], axis=-1)
    d_canon = np.linalg.norm(canon[:, :, None] - canon[:, None, :], axis=-1)
    assert np.abs(d_world - d_canon).max() < 1e-4, np.abs(d_world - d_canon).max()
mean = np.load(os.path.join(root, 'normalization', 'bandai-namco', 'joint_positions_mean.npy'))
std = np.load(os.path.join(root, 'normalization', 'bandai-namco', 'joint_positions_std.npy'))
assert mean.shape == (22, 3) and std.shape == (22, 3) and (std > 0).all()
train = t.filter(pq.read_table(os.path.join(root, 'data')).column('split').to_numpy(zero_copy_only=False) == 'train')
pos = np.concatenate([shaped(train, 'joint_positions', i) for i in range(train.num_rows) if train['num_joints'][i].as_py() == 22])
assert np.allclose(pos.mean(0), mean, atol=1e-4), 'mean over the training split'
canon_train = np.concatenate([shaped(train, 'canonical_positions', i) for i in range(train.num_rows) if train['num_joints'][i].as_py() == 22])
canon_mean = np.load(os.path.join(root, 'normalization', 'bandai-namco', 'canonical_positions_mean.npy'))
assert np.allclose(canon_train.mean(0), canon_mean, atol=1e-4), 'canonical mean over the training split'
# Every profile has statistics: CMU has no train rows in the demo, so its come from the first
# split holding it, and normalization.json says which; constant dimensions are named.
summary = json.load(open(os.path.join(root, 'normalization', 'normalization.json')))['profiles']
assert summary['bandai-namco']['split'] == 'train', summary
assert summary['bandai-namco']['frames'] == pos.shape[0], summary
numpy_constant = ['joint %d %s' % (j, 'xyz'[d]) for j in range(22) for d in range(3) if pos.std(0)[j, d] < 1e-6]
assert summary['bandai-namco']['constant'].get('joint_positions', []) == numpy_constant, (summary, numpy_constant)
assert numpy_constant, 'the Bandai rig has a static root coordinate'
everything = pq.read_table(os.path.join(root, 'data'))
cmu_splits = sorted({everything['split'][i].as_py() for i in range(everything.num_rows) if everything['skeleton'][i].as_py().split(':')[0] == 'cmu'})
assert 'train' not in cmu_splits and summary['cmu']['split'] == cmu_splits[0], (summary['cmu'], cmu_splits)
cmu = np.concatenate([shaped(everything, 'joint_positions', i) for i in range(everything.num_rows) if everything['skeleton'][i].as_py().split(':')[0] == 'cmu' and everything['split'][i].as_py() == summary['cmu']['split']])
cmu_mean = np.load(os.path.join(root, 'normalization', 'cmu', 'joint_positions_mean.npy'))
assert np.allclose(cmu.mean(0), cmu_mean, atol=1e-4), 'CMU mean over its split'
norm = pq.read_table(os.path.join(root, 'normalization', 'normalization.parquet')).to_pylist()
assert {r['profile']: r['split'] for r in norm} == {'bandai-namco': 'train', 'cmu': summary['cmu']['split']}
assert sorted('joint %d %s' % (r['joint'], 'xyz'[r['dim']]) for r in norm if r['constant'] and r['profile'] == 'bandai-namco' and r['feature'] == 'joint_positions') == sorted(numpy_constant)
card = open(os.path.join(root, 'README.md')).read()
assert card.startswith('---\n') and 'data_files' in card and 'license' in card
import polars as pl
df = pl.read_parquet(os.path.join(root, 'data', '*.parquet'))
assert df.height == total
print(total)
"#;
    run_python(script, &[&dataset]);
}

/// A project with these Bandai Namco captures, split by `split_file` when given; its config path.
fn scratch(captures: &[&str], split_file: Option<&str>) -> (Project, std::path::PathBuf) {
    let mut spec = ConfigSpec::new("ds").source(Source::bandai1("b"));
    let mut project = Project::new().captures("bandai-namco-1", captures);
    if let Some(text) = split_file {
        spec = spec.set("splits.file", "splits.csv");
        project = project.file("splits.csv", text);
    }
    let project = project.config(spec).build();
    let path = project.config_path();
    (project, path)
}

fn build(config: &std::path::Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["build", "--config"])
        .arg(config)
        .output()
        .unwrap()
}

#[test]
fn one_more_capture_rewrites_only_the_shards_of_its_split() {
    let split_file = "capture,split\ndataset-1_walk_normal_001,train\ndataset-1_bye_normal_001,train\ndataset-1_kick_normal_001,test\ndataset-1_run_normal_001,train\n";
    let (dir, config) = scratch(
        &[
            "dataset-1_walk_normal_001",
            "dataset-1_bye_normal_001",
            "dataset-1_kick_normal_001",
        ],
        Some(split_file),
    );
    assert!(build(&config).status.success());
    let dataset = dir.path().join("out/ds");
    let before: Vec<(std::path::PathBuf, Vec<u8>, std::time::SystemTime)> = shards(&dataset)
        .into_iter()
        .map(|p| {
            (
                p.clone(),
                fs::read(&p).unwrap(),
                fs::metadata(&p).unwrap().modified().unwrap(),
            )
        })
        .collect();
    fs::copy(
        shared_data().join("bandai-namco-1/data/dataset-1_run_normal_001.bvh"),
        dir.path().join("captures/dataset-1_run_normal_001.bvh"),
    )
    .unwrap();
    assert!(build(&config).status.success());
    for (path, bytes, modified) in before {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let same = fs::read(&path).unwrap() == bytes;
        if name.starts_with("test-") {
            assert!(same, "{name} must not change");
            assert_eq!(
                fs::metadata(&path).unwrap().modified().unwrap(),
                modified,
                "{name} was not rewritten"
            );
        } else {
            assert!(!same, "{name} gains the new capture");
        }
    }
}

#[test]
fn a_capture_planted_in_two_splits_makes_the_build_refuse() {
    let split_file = "capture,split\ndataset-1_walk_normal_001,train\ndataset-1_kick_normal_001,validation\ndataset-1_walk_normal_001,test\n";
    let (_dir, config) = scratch(
        &["dataset-1_walk_normal_001", "dataset-1_kick_normal_001"],
        Some(split_file),
    );
    let out = build(&config);
    assert_eq!(out.status.code(), Some(2), "a config mistake");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("splits.csv:4")
            && err.contains("dataset-1_walk_normal_001")
            && err.contains("one split"),
        "{err}"
    );
}

#[test]
fn the_way_the_config_path_is_spelled_does_not_change_the_dataset() {
    let (_a, plain) = demo();
    let out = tempfile::tempdir().unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["build", "--config"])
        .arg(repo().join("pipeline/../fixtures/./demo.toml"))
        .arg("--output")
        .arg(out.path())
        .output()
        .unwrap();
    assert!(run.status.success());
    assert!(table_bytes(&out.path().join("demo")) == table_bytes(&plain));
}

#[test]
fn build_writes_the_report_and_the_report_command_redoes_it_from_the_shards_alone() {
    let (_out, dataset) = demo();
    let stats: serde_json::Value =
        serde_json::from_slice(&fs::read(dataset.join("report/stats.json")).unwrap()).unwrap();
    assert!(stats.is_object());
    for f in [
        "report/report.md",
        "report/tables.tex",
        "report/figures/motion_lengths.png",
        "report/figures/goal_locations.svg",
    ] {
        assert!(dataset.join(f).is_file(), "{f}");
    }
    let elsewhere = tempfile::tempdir().unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .arg("report")
        .arg(&dataset)
        .arg("--output")
        .arg(elsewhere.path())
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        fs::read(elsewhere.path().join("stats.json")).unwrap()
            == fs::read(dataset.join("report/stats.json")).unwrap(),
        "same shards, same report"
    );
}

#[test]
fn opt_in_feature_columns_equal_what_a_reader_derives_from_the_stored_ones() {
    let (dir, config) = scratch(
        &["dataset-1_walk_normal_001", "dataset-1_bye_normal_001"],
        None,
    );
    let mut text = fs::read_to_string(&config).unwrap();
    text.push_str("\n[features]\nrotations_6d = true\nvelocities = true\n");
    fs::write(&config, text).unwrap();
    let run = build(&config);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let script = r#"
import os, sys
import numpy as np, pyarrow.parquet as pq
root = sys.argv[1]
t = pq.read_table(os.path.join(root, 'data'))
assert t.num_rows >= 4
for i in range(t.num_rows):
    n, j, fps = t['num_frames'][i].as_py(), t['num_joints'][i].as_py(), t['fps'][i].as_py()
    # Shaped as stored (version 9): no reshape.
    q = np.array(t['local_rotations'][i].as_py(), dtype=np.float64)
    assert q.shape == (n, j, 4), q.shape
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    # First two columns of each rotation matrix.
    derived6 = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y),
                         2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)], -1)
    r6 = np.array(t['rotations_6d'][i].as_py())
    assert r6.shape == (n, j, 6), r6.shape
    assert np.abs(r6 - derived6).max() < 1e-5, np.abs(r6 - derived6).max()
    p = np.array(t['joint_positions'][i].as_py(), dtype=np.float64)
    v = np.diff(p, axis=0) * fps
    v = np.concatenate([v, v[-1:]], 0)
    vel = np.array(t['joint_velocities'][i].as_py())
    assert vel.shape == (n, j, 3), vel.shape
    assert np.abs(vel - v).max() < 1e-3, np.abs(vel - v).max()
for feature in ['joint_positions', 'rotations_6d', 'joint_velocities']:
    mean = np.load(os.path.join(root, 'normalization', 'bandai-namco', feature + '_mean.npy'))
    assert mean.shape[0] == 22 and np.isfinite(mean).all(), feature
print(t.num_rows)
"#;
    run_python(script, &[&dir.path().join("out/ds")]);
}

/// The shard writer encodes a row group's columns on all the pool's threads (issue 34): the
/// shards must not depend on how many there are.
#[test]
fn one_thread_and_two_threads_write_the_same_shards() {
    let built: Vec<(tempfile::TempDir, std::path::PathBuf)> = ["1", "2"]
        .into_iter()
        .map(|threads| {
            let out = tempfile::tempdir().unwrap();
            run_ok(common::demo_build(out.path()).env("RAYON_NUM_THREADS", threads));
            let dataset = out.path().join("demo");
            (out, dataset)
        })
        .collect();
    assert_same_shards(&built[0].1, &built[1].1, "1 and 2 threads");
}

/// The two datasets have the same shards, byte for byte, and the same manifest.
fn assert_same_shards(one: &std::path::Path, other: &std::path::Path, between: &str) {
    let names = |dataset: &std::path::Path| -> Vec<std::ffi::OsString> {
        shards(dataset)
            .iter()
            .map(|p| p.file_name().unwrap().to_owned())
            .collect()
    };
    assert!(!shards(one).is_empty());
    assert_eq!(names(one), names(other));
    for (a, b) in shards(one).iter().zip(shards(other)) {
        assert!(
            fs::read(a).unwrap() == fs::read(&b).unwrap(),
            "{} differs between {between}",
            a.file_name().unwrap().to_string_lossy()
        );
    }
    assert_eq!(
        fs::read(one.join("manifest.json")).unwrap(),
        fs::read(other.join("manifest.json")).unwrap()
    );
}

/// With more threads than shards, a shard's row groups are read and encoded side by side
/// (issue 34): the groups are still cut at the same rows, so a shard of several row groups is
/// the same bytes on 1 thread and on 16.
#[test]
fn row_groups_encoded_side_by_side_write_the_same_shards() {
    let data = common::shared_data().join("bandai-namco-1").join("data");
    let mut stems: Vec<String> = fs::read_dir(&data)
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            name.strip_suffix(".bvh").map(str::to_string)
        })
        .collect();
    stems.sort();
    // Every other capture: enough rows, with mirrors, for several row groups of 64 in a shard.
    let stems: Vec<&str> = stems
        .iter()
        .step_by(2)
        .take(100)
        .map(String::as_str)
        .collect();
    let built: Vec<(Project, std::path::PathBuf)> = ["1", "16"]
        .into_iter()
        .map(|threads| {
            let project = Project::new()
                .captures("bandai-namco-1", &stems)
                .config(
                    ConfigSpec::new("groups")
                        .mirror(true)
                        .synthetic(true)
                        .source(Source::bandai1("bandai")),
                )
                .build();
            run_ok(
                project
                    .motionforge(&["build", "--config", "build.toml", "-q"])
                    .env("RAYON_NUM_THREADS", threads),
            );
            let dataset = project.dataset();
            (project, dataset)
        })
        .collect();
    let (one, many) = (&built[0].1, &built[1].1);
    let manifest: serde_json::Value =
        serde_json::from_slice(&fs::read(one.join("manifest.json")).unwrap()).unwrap();
    let most_rows = manifest["splits"]
        .as_object()
        .unwrap()
        .values()
        .flat_map(|split| split["shards"].as_array().unwrap())
        .map(|s| s["rows"].as_u64().unwrap())
        .max()
        .unwrap();
    assert!(most_rows > 128, "the largest shard has {most_rows} rows");
    assert_same_shards(one, many, "1 and 16 threads");
}
