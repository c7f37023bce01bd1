//! The demo dataset opened by the loaders its users have: Hugging Face `datasets` (from the
//! dataset card alone, whose features must be what `datasets` infers from the shards) and DuckDB, from `requirements-test.txt`.

mod common;

use std::process::Command;

#[test]
fn hugging_face_datasets_and_duckdb_open_the_demo() {
    let out = tempfile::tempdir().unwrap();
    common::build_demo(out.path());
    let dataset = out.path().join("demo");
    let hf_cache = tempfile::tempdir().unwrap();
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
assert np.asarray(row['joint_positions']).reshape(frames, joints, 3).shape == (frames, joints, 3)
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
    let run = Command::new(common::python())
        .args(["-c", script])
        .arg(&dataset)
        .env("HF_DATASETS_OFFLINE", "1")
        .env("HF_HUB_OFFLINE", "1")
        .env("HF_HOME", hf_cache.path())
        .output()
        .unwrap_or_else(|e| panic!("{:?}: {e}; {}", common::python(), common::PYTHON_SETUP));
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
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
    assert!(snippet.contains("load_dataset") && snippet.contains("reshape"));
    // The snippet as written, then checks on what it left in its variables.
    let script = format!(
        "{snippet}\nassert positions.shape == (frames, joints, 3) and frames > 1, positions.shape\nassert np.isfinite(normalised).all()\nimport pyarrow.parquet as pq\nt = pq.read_table(root + '/data', filters=[('split', '=', 'train')])\nassert positions.shape == (t['num_frames'][0].as_py(), t['num_joints'][0].as_py(), 3)\nprint('shape', positions.shape)\n"
    );
    let hf_cache = tempfile::tempdir().unwrap();
    let run = Command::new(common::python())
        .args(["-c", &script])
        .current_dir(out.path())
        .env("HF_DATASETS_OFFLINE", "1")
        .env("HF_HUB_OFFLINE", "1")
        .env("HF_HOME", hf_cache.path())
        .output()
        .unwrap_or_else(|e| panic!("{:?}: {e}; {}", common::python(), common::PYTHON_SETUP));
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{}\n{stdout}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.contains("shape ("), "{stdout}");
}
