//! Builds that cannot write: an unwritable output folder, and a full disk (simulated with a file
//! size limit). Each fails with exit code 1 and an error naming the file, and leaves nothing
//! half-written that looks complete: no temporary files, and a manifest (if any) whose shards are
//! exactly the ones in `data/`, with matching checksums.

use crate::common;

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::project::ConfigSpec;
use common::repo;
use motionforge::build::sha256_hex;

const BIN: &str = env!("CARGO_BIN_EXE_motionforge");

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn is_root() -> bool {
    let out = Command::new("id").arg("-u").output().unwrap();
    text(&out.stdout).trim() == "0"
}

/// The binary, run so that file permissions apply to it. Root ignores permission bits, so as
/// root (this machine and CI run as root) it runs as `nobody` through `setpriv`; otherwise as
/// the current user. As `nobody` it runs a copy of the binary, placed in `dir` beside the inputs,
/// so that the checkout's own permissions do not matter.
fn unprivileged(dir: &Path, args: &[&std::ffi::OsStr]) -> Output {
    let mut cmd = if is_root() {
        let bin = dir.join("motionforge");
        std::fs::copy(BIN, &bin).unwrap();
        std::fs::set_permissions(&bin, std::fs::Permissions::from_mode(0o755)).unwrap();
        let mut c = Command::new("setpriv");
        c.args(["--reuid=65534", "--regid=65534", "--clear-groups", "--"])
            .arg(bin);
        c
    } else {
        Command::new(BIN)
    };
    cmd.args(args).current_dir(dir).output().unwrap()
}

/// A copy of `fixtures/` in `dir` that everyone can read; returns the demo config in it.
fn readable_fixtures(dir: &Path) -> PathBuf {
    fn copy(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        std::fs::set_permissions(to, std::fs::Permissions::from_mode(0o755)).unwrap();
        for entry in std::fs::read_dir(from).unwrap().flatten() {
            let target = to.join(entry.file_name());
            if entry.file_type().unwrap().is_dir() {
                copy(&entry.path(), &target);
            } else {
                std::fs::copy(entry.path(), &target).unwrap();
                std::fs::set_permissions(&target, std::fs::Permissions::from_mode(0o644)).unwrap();
            }
        }
    }
    copy(&repo().join("fixtures"), &dir.join("fixtures"));
    dir.join("fixtures/demo.toml")
}

/// The binary under a file size limit: every write past about 64 KiB fails with EFBIG, as on a
/// full disk. The binary itself ignores SIGXFSZ, so the write returns EFBIG instead of the
/// signal killing the process.
fn with_size_limit(blocks_of_512: u32, args: &[&std::ffi::OsStr]) -> Output {
    Command::new("sh")
        .arg("-c")
        .arg(format!(r#"ulimit -f {blocks_of_512}; exec "$0" "$@""#))
        .arg(BIN)
        .args(args)
        .output()
        .unwrap()
}

fn build_args<'a>(config: &'a Path, output: &'a Path) -> Vec<&'a std::ffi::OsStr> {
    vec![
        "build".as_ref(),
        "--config".as_ref(),
        config.as_os_str(),
        "--output".as_ref(),
        output.as_os_str(),
    ]
}

/// Every file of a dataset folder outside `.motionforge/`, with its bytes.
fn dataset_files(dataset: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    files_under(dataset)
        .into_iter()
        .filter(|p| !p.starts_with(dataset.join(".motionforge")))
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect()
}

fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            if e.file_type().unwrap().is_dir() {
                stack.push(e.path());
            } else {
                out.push(e.path());
            }
        }
    }
    out.sort();
    out
}

/// No temporary file anywhere; and when `manifest.json` exists, the shards it lists are exactly
/// the `.parquet` files in `data/`, each with the listed SHA-256.
fn assert_nothing_half_written_looks_complete(dataset: &Path) {
    let temps: Vec<PathBuf> = files_under(dataset)
        .into_iter()
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().contains(".tmp"))
        })
        .collect();
    assert!(temps.is_empty(), "temporary files left: {temps:?}");
    let Ok(manifest) = std::fs::read(dataset.join("manifest.json")) else {
        return;
    };
    let manifest: serde_json::Value = serde_json::from_slice(&manifest).unwrap();
    let mut listed: Vec<(String, String)> = manifest["splits"]
        .as_object()
        .unwrap()
        .values()
        .flat_map(|s| s["shards"].as_array().unwrap().clone())
        .map(|s| {
            (
                s["file"].as_str().unwrap().to_string(),
                s["sha256"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    listed.sort();
    let mut present: Vec<String> = std::fs::read_dir(dataset.join("data"))
        .map(|entries| {
            entries
                .flatten()
                .map(|e| format!("data/{}", e.file_name().to_string_lossy()))
                .filter(|n| n.ends_with(".parquet"))
                .collect()
        })
        .unwrap_or_default();
    present.sort();
    let names: Vec<&String> = listed.iter().map(|(f, _)| f).collect();
    assert_eq!(
        names,
        present.iter().collect::<Vec<_>>(),
        "the manifest must list exactly the shards in data/"
    );
    for (file, sha) in &listed {
        let bytes = std::fs::read(dataset.join(file)).unwrap();
        assert_eq!(
            &sha256_hex(&bytes),
            sha,
            "{file} does not match the manifest"
        );
    }
}

#[test]
fn an_unwritable_output_folder_fails_naming_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let output = dir.path().join("out");
    std::fs::create_dir(&output).unwrap();
    std::fs::set_permissions(&output, std::fs::Permissions::from_mode(0o555)).unwrap();
    let config = readable_fixtures(dir.path());
    let run = unprivileged(dir.path(), &build_args(&config, &output));
    assert_eq!(run.status.code(), Some(1), "{}", text(&run.stderr));
    let err = text(&run.stderr);
    assert!(
        err.contains(&output.join("demo").display().to_string())
            && err.contains("Permission denied")
            && err.contains("no permission to write there"),
        "{err}"
    );
    assert_eq!(std::fs::read_dir(&output).unwrap().count(), 0);
}

#[test]
fn a_dataset_folder_whose_outputs_cannot_be_written_fails_at_the_write_and_leaves_no_manifest() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let output = dir.path().join("out");
    let dataset = output.join("demo");
    // The workspace (lock and stage cache) is writable, the dataset folder itself is not: every
    // stage runs, and the first output write fails.
    std::fs::create_dir_all(dataset.join(".motionforge")).unwrap();
    for (path, mode) in [
        (&output, 0o755),
        (&dataset.join(".motionforge"), 0o777),
        (&dataset, 0o555),
    ] {
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
    }
    let config = readable_fixtures(dir.path());
    let run = unprivileged(dir.path(), &build_args(&config, &output));
    assert_eq!(run.status.code(), Some(1), "{}", text(&run.stderr));
    let err = text(&run.stderr);
    assert!(
        err.contains(&dataset.display().to_string()) && err.contains("Permission denied"),
        "{err}"
    );
    assert!(
        dataset.join(".motionforge/cache").is_dir(),
        "the stages ran before the write failed"
    );
    assert!(!dataset.join("manifest.json").exists());
    assert_nothing_half_written_looks_complete(&dataset);
}

#[test]
fn a_full_disk_on_a_fresh_build_fails_naming_the_file_and_leaves_no_temp_files() {
    let out = tempfile::tempdir().unwrap();
    let config = repo().join("fixtures/demo.toml");
    let run = with_size_limit(128, &build_args(&config, out.path()));
    assert_eq!(run.status.code(), Some(1), "{}", text(&run.stderr));
    let err = text(&run.stderr);
    let dataset = out.path().join("demo");
    assert!(
        err.contains(&format!("error: {}", dataset.display()))
            && err.contains("File too large")
            && err.contains("file size limit"),
        "{err}"
    );
    assert!(!dataset.join("manifest.json").exists());
    assert_nothing_half_written_looks_complete(&dataset);
}

#[test]
fn a_full_disk_while_writing_shards_fails_naming_the_shard_and_leaves_no_partial_shard() {
    let out = tempfile::tempdir().unwrap();
    let config = repo().join("fixtures/demo.toml");
    let first = Command::new(BIN)
        .args(build_args(&config, out.path()))
        .output()
        .unwrap();
    assert!(first.status.success(), "{}", text(&first.stderr));
    let dataset = out.path().join("demo");
    // Keep the stage cache, drop every output: the rebuild reaches the shard writes at once.
    for entry in std::fs::read_dir(&dataset).unwrap().flatten() {
        let path = entry.path();
        if entry.file_name() == ".motionforge" {
            continue;
        }
        if path.is_dir() {
            std::fs::remove_dir_all(&path).unwrap();
        } else {
            std::fs::remove_file(&path).unwrap();
        }
    }
    let run = with_size_limit(128, &build_args(&config, out.path()));
    assert_eq!(run.status.code(), Some(1), "{}", text(&run.stderr));
    let err = text(&run.stderr);
    assert!(
        err.contains(&format!(
            "error: {}",
            dataset.join("data/train-00000-of-00001.parquet").display()
        )) && err.contains("File too large"),
        "{err}"
    );
    assert!(!dataset.join("manifest.json").exists());
    let shards: Vec<PathBuf> = files_under(&dataset.join("data"));
    assert!(shards.is_empty(), "no shard may be left: {shards:?}");
    assert_nothing_half_written_looks_complete(&dataset);

    // With room again, the same folder builds to a consistent dataset.
    let again = Command::new(BIN)
        .args(build_args(&config, out.path()))
        .output()
        .unwrap();
    assert!(again.status.success(), "{}", text(&again.stderr));
    assert!(dataset.join("manifest.json").is_file());
    assert_nothing_half_written_looks_complete(&dataset);
}

/// A rebuild that changes the shard layout and runs out of space part-way. The write stage stages
/// the new dataset in `.motionforge/staging/` and switches only when all of it is written, so the
/// failure leaves the previous dataset complete: its manifest, and exactly its shards, unchanged.
#[test]
fn a_full_disk_during_a_rewrite_leaves_no_shard_the_manifest_does_not_vouch_for() {
    let dir = tempfile::tempdir().unwrap();
    let output = dir.path().join("out");
    let config = ConfigSpec::demo().write(dir.path().join("demo.toml"));
    let first = Command::new(BIN)
        .args(build_args(&config, &output))
        .output()
        .unwrap();
    assert!(first.status.success(), "{}", text(&first.stderr));
    let dataset = output.join("demo");
    let before = dataset_files(&dataset);
    // One clip per shard, and a feature change so every row changes (the opt-in columns make
    // the longest shard large enough to pass the limit below).
    let config = ConfigSpec::demo()
        .shard_bytes(1024)
        .set("features.contact_speed", 0.5)
        .set("features.rotations_6d", true)
        .set("features.velocities", true)
        .write(dir.path().join("demo.toml"));
    // About 400 kB: the first single-clip shards fit, a later, longer one (470 kB) does not.
    let run = with_size_limit(800, &build_args(&config, &output));
    assert_eq!(run.status.code(), Some(1), "{}", text(&run.stderr));
    assert!(text(&run.stderr).contains("File too large"));
    assert_nothing_half_written_looks_complete(&dataset);
    // The previous dataset, file for file and byte for byte (build-report.json is the record of
    // the failed run, written only by a build that finishes).
    assert!(dataset.join("manifest.json").is_file());
    let after = dataset_files(&dataset);
    assert!(before == after, "the previous dataset changed");
}

#[test]
fn a_full_disk_in_the_report_stage_names_the_figure_and_keeps_the_build_report() {
    let out = tempfile::tempdir().unwrap();
    let config = repo().join("fixtures/demo.toml");
    common::run_ok(Command::new(BIN).args(build_args(&config, out.path())));
    let dataset = out.path().join("demo");
    let before: Vec<(PathBuf, Vec<u8>)> = dataset_files(&dataset.join("data"));
    std::fs::remove_dir_all(dataset.join("report")).unwrap();
    std::fs::remove_file(dataset.join("build-report.json")).unwrap();
    // Only the report is made again; its largest figure (over 100 KB) passes the 64 KiB limit.
    let run = with_size_limit(128, &build_args(&config, out.path()));
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert!(
        err.contains("report/figures/") && err.contains(".png") && err.contains("file size limit"),
        "{err}"
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dataset.join("build-report.json")).unwrap()).unwrap();
    let why = report["report_error"].as_str().unwrap_or_default();
    assert!(
        why.contains(".png") && why.contains("file size limit"),
        "{report:#}"
    );
    // The dataset is untouched and nothing half-written looks finished.
    assert_eq!(dataset_files(&dataset.join("data")), before);
    assert!(!dataset.join("report/stats.json").exists());
    assert_nothing_half_written_looks_complete(&dataset);
    // With room again, the next build makes the report and succeeds.
    common::run_ok(Command::new(BIN).args(build_args(&config, out.path())));
    assert!(dataset.join("report/stats.json").exists());
}
