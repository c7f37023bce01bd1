//! Shared helpers for integration tests: where the real data lives, and reading it.
#![allow(dead_code)]

pub(crate) mod llm;
pub(crate) mod project;
pub(crate) mod service;

use std::path::{Path, PathBuf};

use motionforge::motion::{Bvh, read_bvh};

/// The repository root.
pub(crate) fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `../shared/data` beside the repository (or `MOTIONFORGE_SHARED_DATA`). Tests that need it fail
/// loudly when it is missing rather than skipping into a pass.
pub(crate) fn shared_data() -> PathBuf {
    let dir = std::env::var_os("MOTIONFORGE_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("../shared/data"));
    assert!(
        dir.is_dir(),
        "real data not found at {}: clone the repo beside ../shared or set MOTIONFORGE_SHARED_DATA",
        dir.display()
    );
    dir
}

/// Sorted `.bvh` files in a folder.
pub(crate) fn bvh_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "bvh"))
        .collect();
    files.sort();
    files
}

/// Reads a BVH file, panicking with the path on error.
pub(crate) fn load(path: &Path) -> Bvh {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    read_bvh(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A Bandai Namco dataset-1 capture by content/style/take.
pub(crate) fn bandai1(content: &str, style: &str) -> PathBuf {
    shared_data().join(format!(
        "bandai-namco-1/data/dataset-1_{content}_{style}_001.bvh"
    ))
}

/// A Bandai Namco dataset-2 subset capture.
pub(crate) fn bandai2(content: &str, take: u32) -> PathBuf {
    shared_data().join(format!(
        "bandai-namco-2-subset/data/dataset-2_{content}_normal_{take:03}.bvh"
    ))
}

/// The Parquet shards of a built dataset folder, sorted by name.
pub(crate) fn shards(dataset: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dataset.join("data"))
        .unwrap_or_else(|e| panic!("{}: {e}", dataset.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "parquet"))
        .collect();
    files.sort();
    files
}

/// All shard bytes of a dataset, concatenated in name order: equal bytes, equal datasets.
pub(crate) fn table_bytes(dataset: &Path) -> Vec<u8> {
    shards(dataset)
        .iter()
        .flat_map(|p| std::fs::read(p).unwrap())
        .collect()
}

/// Columns of a Parquet file or folder of shards, read with pyarrow (an independent reader,
/// from `requirements-test.txt`): one `|`-joined line per row.
pub(crate) fn pyarrow_rows(table: &Path, columns: &str) -> Vec<String> {
    let script = format!(
        "import pyarrow.parquet as pq, sys\nt = pq.read_table(sys.argv[1], columns='{columns}'.split(','))\nfor r in t.to_pylist(): print('|'.join(str(r[c]) for c in '{columns}'.split(',')))"
    );
    let out = std::process::Command::new(python())
        .arg("-c")
        .arg(script)
        .arg(table)
        .output()
        .unwrap_or_else(|e| panic!("{:?}: {e}; {PYTHON_SETUP}", python()));
    assert!(
        out.status.success(),
        "pyarrow failed: {}\n{PYTHON_SETUP}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

/// The Python that runs the independent readers: `MOTIONFORGE_PYTHON`, set by `scripts/test.sh` to
/// its virtual environment built from `requirements-test.txt`.
pub(crate) fn python() -> std::ffi::OsString {
    // Not the system `python3`: its packages (or their absence) would decide what a test checks.
    std::env::var_os("MOTIONFORGE_PYTHON").unwrap_or_else(|| {
        panic!(
            "MOTIONFORGE_PYTHON is not set: run the tests with scripts/test.sh, which makes the \
             tests' Python environment from requirements-test.txt and sets it (or set it yourself \
             to `$(scripts/python-env.sh)`)"
        )
    })
}

/// How to install what a failing Python check was missing.
pub(crate) const PYTHON_SETUP: &str = "run the tests with scripts/test.sh, which makes a Python environment from requirements-test.txt";

/// Runs `command`, failing the test with its standard error unless it succeeds.
pub(crate) fn run_ok(command: &mut std::process::Command) -> std::process::Output {
    let out = command.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The binary set to build the bundled demo (`fixtures/demo.toml`, in place) into `output`; its
/// dataset folder is `output/demo`. More arguments (`--json`, `--wait`) may follow.
pub(crate) fn demo_build(output: &Path) -> std::process::Command {
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_motionforge"));
    command
        .args(["build", "--config"])
        .arg(repo().join("fixtures/demo.toml"))
        .arg("--output")
        .arg(output);
    command
}

/// Builds the demo config into `output` with the binary; its dataset folder is `output/demo`.
pub(crate) fn build_demo(output: &Path) -> std::process::Output {
    run_ok(&mut demo_build(output))
}

/// The walk, kick and bye takes most LLM-stage tests label.
pub(crate) const WALK_KICK_BYE: [&str; 3] = [
    "dataset-1_walk_normal_001",
    "dataset-1_kick_normal_001",
    "dataset-1_bye_normal_001",
];

/// Runs a Python script (the readers `requirements-test.txt` lists) with `args`, fails the test with its
/// standard error unless it succeeds, and returns its standard output.
pub(crate) fn run_python<S: AsRef<std::ffi::OsStr>>(script: &str, args: &[S]) -> String {
    let out = std::process::Command::new(python())
        .args(["-c", script])
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{:?}: {e}; {PYTHON_SETUP}", python()));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Copies the folder `from` into `to`, recursively (a sandbox copy of fixtures or a dataset).
pub(crate) fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

/// The tests' Python ([`python`]) with Hugging Face offline and its cache in `hf_home`, so a test
/// neither reaches the network nor reads or fills the user's cache.
pub(crate) fn offline_python(hf_home: &Path) -> std::process::Command {
    let mut command = std::process::Command::new(python());
    command
        .env("HF_DATASETS_OFFLINE", "1")
        .env("HF_HUB_OFFLINE", "1")
        .env("HF_HOME", hf_home);
    command
}
