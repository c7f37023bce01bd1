//! The demo dataset opened by the loaders its users have: Hugging Face `datasets` (from the
//! dataset card alone, whose features must be what `datasets` infers from the shards) and DuckDB. `.ci/run` installs both.

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
assert [s['name'] for s in card['dataset_info']['splits']] == ['train', 'val', 'test']
ds = datasets.load_dataset(root)
assert list(ds.keys()) == ['train', 'val', 'test'], list(ds.keys())
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
    let run = Command::new("python3")
        .args(["-c", script])
        .arg(&dataset)
        .env("HF_DATASETS_OFFLINE", "1")
        .env("HF_HUB_OFFLINE", "1")
        .env("HF_HOME", hf_cache.path())
        .output()
        .expect("python3 must be installed");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}
