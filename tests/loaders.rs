//! The demo dataset opened by the loaders its users have: Hugging Face `datasets` (from the
//! dataset card alone, whose features must be what `datasets` infers from the shards) and DuckDB, from `requirements-test.txt`.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::project::ConfigSpec;

#[test]
fn hugging_face_datasets_and_duckdb_open_the_demo() {
    let out = tempfile::tempdir().unwrap();
    common::build_demo(out.path());
    let dataset = out.path().join("demo");
    let script = r#"
import json, os, sys
import numpy as np
root = sys.argv[1]
manifest = json.load(open(os.path.join(root, 'manifest.json')))
expected = {split: entry['rows'] for split, entry in manifest['splits'].items()}

import datasets, yaml
import pyarrow.parquet as pq
# The card's features are what `datasets` itself infers from the shards' schema.
card = yaml.safe_load(open(os.path.join(root, 'README.md')).read().split('---')[1])
shard = os.path.join(root, manifest['splits']['train']['shards'][0]['file'])
inferred = datasets.Features.from_arrow_schema(pq.read_schema(shard))._to_yaml_list()
assert card['dataset_info']['features'] == inferred, 'card features differ from the Parquet schema'
assert [s['name'] for s in card['dataset_info']['splits']] == ['train', 'validation', 'test']
ds = datasets.load_dataset(root)
assert list(ds.keys()) == ['train', 'validation', 'test'], list(ds.keys())
# The card's route and the shards' file names give the same splits (Hugging Face's names).
by_files = datasets.load_dataset('parquet', data_dir=os.path.join(root, 'data'))
assert sorted(by_files.keys()) == sorted(ds.keys()), (list(by_files.keys()), list(ds.keys()))
assert {k: v.num_rows for k, v in by_files.items()} == expected
assert {k: v.num_rows for k, v in ds.items()} == expected, ({k: v.num_rows for k, v in ds.items()}, expected)
train = ds['train'].with_format('numpy')
row = train[0]
frames, joints = int(row['num_frames']), int(row['num_joints'])
assert row['joint_positions'].shape == (frames, joints, 3), row['joint_positions'].shape
attrs = {a['key']: a['value'] for a in ds['train'][0]['attributes']}
assert all(isinstance(v, str) for v in attrs.values()), attrs
synthetic = [r for r in ds['train'] if r['source_kind'] == 'synthetic']
assert synthetic and {a['key'] for a in synthetic[0]['attributes']} == {'start_a', 'start_b', 'action_kept'}

import duckdb
con = duckdb.connect()
pattern = os.path.join(root, 'data', '*.parquet')
counts = dict(con.execute(f"SELECT split, count(*) FROM read_parquet('{pattern}') GROUP BY split").fetchall())
assert counts == expected, (counts, expected)
frames = con.execute(f"SELECT sum(num_frames) FROM read_parquet('{pattern}')").fetchone()[0]
assert frames > 0
print(expected, frames)
"#;
    python_ok(script, &[&dataset], None);
}

/// The dataset card's usage snippet, taken from the demo's `README.md` as a user would copy it,
/// runs beside the dataset folder with `datasets` and numpy only (no PyTorch) and gives a
/// (frames, joints, 3) array of the first train clip, normalised and finite.
#[test]
fn the_cards_snippet_runs_and_gives_frames_joints_3() {
    let out = tempfile::tempdir().unwrap();
    common::build_demo(out.path());
    let dataset = out.path().join("demo");
    let card = std::fs::read_to_string(dataset.join("README.md")).unwrap();
    let (_, after) = card
        .split_once("## Using it")
        .expect("the card has a usage section");
    let (_, code) = after.split_once("```python\n").expect("a Python block");
    let (snippet, _) = code.split_once("```").expect("a closed block");
    // Shaped columns (schema version 9): the array comes as (frames, joints, 3), no reshape.
    assert!(snippet.contains("load_dataset") && !snippet.contains("reshape"));
    // The snippet as written, then checks on what it left in its variables.
    let script = format!(
        "{snippet}\nframes, joints = int(row['num_frames']), int(row['num_joints'])\nassert positions.shape == (frames, joints, 3) and frames > 1, positions.shape\nassert positions.dtype == np.float32 and normalised.shape == positions.shape\nassert np.isfinite(normalised).all()\nimport pyarrow.parquet as pq\nt = pq.read_table(root + '/data', filters=[('split', '=', 'train')])\nassert positions.shape == (t['num_frames'][0].as_py(), t['num_joints'][0].as_py(), 3)\nprint('shape', positions.shape)\n"
    );
    let stdout = python_ok(&script, &[], Some(out.path()));
    assert!(stdout.contains("shape ("), "{stdout}");
}

/// Runs `script` with the tests' Python, Hugging Face offline and a cache of its own, `args`
/// after it, from `dir` (the current folder when `None`); fails with its output unless it
/// succeeds, and gives its standard output.
fn python_ok(script: &str, args: &[&Path], dir: Option<&Path>) -> String {
    let hf_cache = tempfile::tempdir().unwrap();
    let mut command = common::offline_python(hf_cache.path());
    command.args(["-c", script]).args(args);
    if let Some(dir) = dir {
        command.current_dir(dir);
    }
    let run = command
        .output()
        .unwrap_or_else(|e| panic!("{:?}: {e}; {}", common::python(), common::PYTHON_SETUP));
    let stdout = String::from_utf8_lossy(&run.stdout).into_owned();
    assert!(
        run.status.success(),
        "{}\n{stdout}",
        String::from_utf8_lossy(&run.stderr)
    );
    stdout
}

/// The demo's config in `dir` with every derived feature switched on (`rotations_6d` and
/// `joint_velocities` are opt-in), its fixture paths made absolute.
fn demo_with_every_feature(dir: &Path) -> PathBuf {
    ConfigSpec::demo()
        .set("features.rotations_6d", true)
        .set("features.velocities", true)
        .write(dir.join("demo.toml"))
}

/// Without PyTorch: `datasets` `load_dataset(...).with_format("numpy")` gives every per-frame
/// column as an ndarray of its documented shape (`schemas/clips.md`), and the per-clip vectors
/// as short arrays; pyarrow and polars see the same nesting and the same values.
#[test]
fn numpy_format_gives_every_per_frame_column_its_documented_shape() {
    let dir = tempfile::tempdir().unwrap();
    let config = demo_with_every_feature(dir.path());
    common::run_ok(
        Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .args(["build", "--quiet", "--config"])
            .arg(&config)
            .arg("--output")
            .arg(dir.path().join("out")),
    );
    let dataset = dir.path().join("out/demo");
    let script = r#"
import os, sys
import numpy as np, datasets, pyarrow.parquet as pq, polars as pl
root = sys.argv[1]
# The shapes schemas/clips.md documents, per row of n frames and j joints.
SHAPES = {
    'joint_positions': lambda n, j: ((n, j, 3), np.float32),
    'canonical_positions': lambda n, j: ((n, j, 3), np.float32),
    'local_rotations': lambda n, j: ((n, j, 4), np.float32),
    'rotations_6d': lambda n, j: ((n, j, 6), np.float32),
    'joint_velocities': lambda n, j: ((n, j, 3), np.float32),
    'root_translation': lambda n, j: ((n, 3), np.float32),
    'foot_contacts': lambda n, j: ((n, 4), np.bool_),
    'future_root': lambda n, j: ((n, 3, 3), np.float32),
}
ds = datasets.load_dataset(root)
assert 'torch' not in sys.modules, 'the numpy route must not need PyTorch'
table = pq.read_table(os.path.join(root, 'data'))
by_id = {cid: i for i, cid in enumerate(table['clip_id'].to_pylist())}
frame = pl.read_parquet(os.path.join(root, 'data', '*.parquet'))
polars_row = {cid: i for i, cid in enumerate(frame['clip_id'].to_list())}
for name in ['joint_positions', 'canonical_positions', 'local_rotations', 'rotations_6d', 'joint_velocities']:
    assert frame.schema[name] == pl.List(pl.List(pl.Array(pl.Float32, SHAPES[name](0, 0)[0][2]))), (name, frame.schema[name])
assert frame.schema['future_root'] == pl.List(pl.Array(pl.Float32, (3, 3))), frame.schema['future_root']
assert frame.schema['foot_contacts'] == pl.List(pl.Array(pl.Boolean, 4))
assert frame.schema['goal_hand'] == pl.Array(pl.Float32, 3) and frame.schema['parts'] == pl.Array(pl.Boolean, 6)
checked = 0
for split, rows in ds.items():
    rows = rows.with_format('numpy')
    for r in rows:
        n, j = int(r['num_frames']), int(r['num_joints'])
        i, k = by_id[str(r['clip_id'])], polars_row[str(r['clip_id'])]
        for name, shape in SHAPES.items():
            expected, dtype = shape(n, j)
            a = r[name]
            assert isinstance(a, np.ndarray) and a.dtype == dtype and a.shape == expected, (split, r['clip_id'], name, type(a), getattr(a, 'shape', None), expected)
            # pyarrow: the same nesting and values; polars: the frame list, then fixed arrays.
            assert np.array_equal(np.array(table[name][i].as_py(), dtype=dtype), a), name
            p = frame[name][k]
            p = (p.list.to_array(j) if len(expected) == 3 and expected[1] == j else p).to_numpy()
            assert p.shape == expected and np.array_equal(p, a), (name, p.shape)
            checked += 1
        for name, size in [('goal_pelvis', 2), ('goal_hand', 3)]:
            assert r[name] is None or (r[name].shape == (size,) and r[name].dtype == np.float32), (name, r[name])
        assert r['parts'] is None or (r['parts'].shape == (6,) and r['parts'].dtype == np.bool_)
        if r['source_kind'] == 'synthetic':
            assert r['composed_parts'].shape == (2, 6) and r['composed_parts'].dtype == np.bool_
            assert not (r['composed_parts'][0] & r['composed_parts'][1]).any(), 'complementary parts'
assert checked == 8 * table.num_rows, (checked, table.num_rows)
assert sum(1 for g in table['goal_pelvis'].to_pylist() if g is not None) > 0, 'the demo has pelvis goals'
# The nesting keeps the leaf encodings: every float leaf BYTE_STREAM_SPLIT, everything zstd.
floats = 0
for shard in sorted(os.listdir(os.path.join(root, 'data'))):
    meta = pq.ParquetFile(os.path.join(root, 'data', shard)).metadata
    for g in range(meta.num_row_groups):
        for c in range(meta.num_columns):
            col = meta.row_group(g).column(c)
            assert col.compression == 'ZSTD', (shard, col.path_in_schema, col.compression)
            if col.physical_type == 'FLOAT':
                assert 'BYTE_STREAM_SPLIT' in col.encodings, (shard, col.path_in_schema, col.encodings)
                floats += 1
assert floats > 0
print(checked)
"#;
    python_ok(script, &[&dataset], None);
}
