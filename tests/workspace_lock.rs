//! The workspace lock: a second build of the same dataset folder is refused (or waits), and a
//! lock left by a killed process is taken over.

use crate::common;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use motionforge::build::lock::{Holder, LockError, WorkspaceLock};

fn build_cmd(output: &Path, extra: &[&str]) -> Command {
    let mut cmd = common::demo_build(output);
    cmd.args(extra);
    cmd
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn lock_file(dataset: &Path) -> PathBuf {
    dataset.join(".motionforge/lock")
}

/// A process id that is certainly not running: a child that has exited and been reaped.
fn dead_pid() -> u32 {
    let mut child = Command::new("true").spawn().unwrap();
    let pid = child.id();
    child.wait().unwrap();
    pid
}

#[test]
fn a_second_build_is_refused_with_the_holder_and_what_to_do() {
    let out = tempfile::tempdir().unwrap();
    let dataset = out.path().join("demo");
    let held = WorkspaceLock::acquire(&dataset, None).unwrap();
    let run = build_cmd(out.path(), &[]).output().unwrap();
    assert_eq!(run.status.code(), Some(1), "{}", text(&run.stderr));
    let err = text(&run.stderr);
    assert!(
        err.contains(&format!("dataset folder {}", dataset.display()))
            && err.contains(&format!("is being built by pid {}", std::process::id()))
            && err.contains("--wait"),
        "{err}"
    );
    assert!(
        !dataset.join("data").exists() && !dataset.join(".motionforge/cache").exists(),
        "a refused build must not start working"
    );
    drop(held);
    let run = build_cmd(out.path(), &[]).output().unwrap();
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert!(dataset.join("manifest.json").is_file());
    assert_eq!(
        std::fs::read_to_string(lock_file(&dataset)).unwrap(),
        "",
        "a build that ends normally empties the lock file"
    );
}

#[test]
fn with_wait_the_build_waits_for_the_holder_then_runs() {
    let out = tempfile::tempdir().unwrap();
    let dataset = out.path().join("demo");
    let held = WorkspaceLock::acquire(&dataset, None).unwrap();
    let start = Instant::now();
    let mut child = build_cmd(out.path(), &["--wait", "60s"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the build must wait while the lock is held"
    );
    assert!(!dataset.join("data").exists());
    drop(held);
    let run = child.wait_with_output().unwrap();
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert!(start.elapsed() >= Duration::from_millis(1500));
    assert!(
        text(&run.stderr).contains("waiting up to 1m"),
        "{}",
        text(&run.stderr)
    );
    assert!(dataset.join("manifest.json").is_file());
}

#[test]
fn wait_gives_up_after_its_duration() {
    let out = tempfile::tempdir().unwrap();
    let dataset = out.path().join("demo");
    let _held = WorkspaceLock::acquire(&dataset, None).unwrap();
    let start = Instant::now();
    let run = build_cmd(out.path(), &["--wait", "1s"]).output().unwrap();
    assert_eq!(run.status.code(), Some(1));
    assert!(start.elapsed() >= Duration::from_secs(1));
    let err = text(&run.stderr);
    assert!(
        err.contains("is still being built by pid") && err.contains("after waiting 1s"),
        "{err}"
    );
}

#[test]
fn a_bad_wait_value_is_a_usage_error() {
    let out = tempfile::tempdir().unwrap();
    let run = build_cmd(out.path(), &["--wait", "soon"]).output().unwrap();
    assert_eq!(run.status.code(), Some(2));
    assert!(text(&run.stderr).contains("30s"), "{}", text(&run.stderr));
}

#[test]
fn the_lock_excludes_other_holders_in_the_same_process_and_is_released_on_drop() {
    let dir = tempfile::tempdir().unwrap();
    let first = WorkspaceLock::acquire(dir.path(), None).unwrap();
    assert!(first.took_over().is_none());
    let holder: Holder =
        serde_json::from_str(&std::fs::read_to_string(first.path()).unwrap()).unwrap();
    assert_eq!(holder.pid, std::process::id());
    assert!(holder.started.ends_with('Z'), "{}", holder.started);
    match WorkspaceLock::acquire(dir.path(), Some(Duration::from_millis(300))) {
        Err(LockError::Busy {
            holder: Some(h),
            waited: Some(w),
            ..
        }) => {
            assert_eq!(h.pid, std::process::id());
            assert!(w >= Duration::from_millis(300));
        }
        other => panic!("expected Busy, got {other:?}"),
    }
    drop(first);
    let again = WorkspaceLock::acquire(dir.path(), None).unwrap();
    assert!(again.took_over().is_none(), "a released lock is not stale");
}

#[test]
fn a_lock_file_left_by_a_dead_process_is_taken_over_and_its_temp_files_removed() {
    let out = tempfile::tempdir().unwrap();
    let dataset = out.path().join("demo");
    std::fs::create_dir_all(dataset.join(".motionforge")).unwrap();
    let pid = dead_pid();
    let holder = Holder {
        pid,
        host: Some("elsewhere".into()),
        started: "2026-01-01T00:00:00Z".into(),
        command: "motionforge build".into(),
    };
    std::fs::write(lock_file(&dataset), serde_json::to_string(&holder).unwrap()).unwrap();
    // What an atomic write interrupted by the kill leaves, and a temp file of another process.
    std::fs::create_dir_all(dataset.join("data")).unwrap();
    let leftover = dataset.join(format!("data/.train-00000-of-00001.parquet.{pid}.tmp"));
    std::fs::write(&leftover, b"half a shard").unwrap();
    let foreign = dataset.join(format!(".notes.{}.tmp", pid + 1));
    std::fs::write(&foreign, b"not ours").unwrap();

    let run = build_cmd(out.path(), &[]).output().unwrap();
    assert!(run.status.success(), "{}", text(&run.stderr));
    let err = text(&run.stderr);
    assert!(
        err.contains("warning: took over a stale lock")
            && err.contains(&format!("pid {pid} on elsewhere"))
            && err.contains("removed 1 temporary files"),
        "{err}"
    );
    assert!(!leftover.exists(), "the dead holder's temp file is removed");
    assert!(foreign.exists(), "other processes' files are left alone");
    assert_eq!(std::fs::read_to_string(lock_file(&dataset)).unwrap(), "");
}

/// A real holder in another process: a shell holds the lock with flock(1), the build is refused,
/// then the shell is killed with SIGKILL (no chance to clean up) and the next build takes over.
#[test]
fn a_killed_holder_does_not_block_the_next_build() {
    let out = tempfile::tempdir().unwrap();
    let dataset = out.path().join("demo");
    std::fs::create_dir_all(dataset.join(".motionforge")).unwrap();
    std::fs::write(lock_file(&dataset), "").unwrap();
    let mut holder = Command::new("sh")
        .arg("-c")
        .arg(
            r#"exec 9<>"$0"; flock -x 9 || exit 1; printf '{"pid":%s,"started":"2026-01-01T00:00:00Z","command":"sh holder"}\n' $$ >&9; echo locked; exec sleep 120"#,
        )
        .arg(lock_file(&dataset))
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(holder.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert_eq!(line.trim(), "locked");
    let pid = holder.id();

    let refused: Output = build_cmd(out.path(), &[]).output().unwrap();
    assert_eq!(refused.status.code(), Some(1));
    assert!(
        text(&refused.stderr).contains(&format!("is being built by pid {pid}")),
        "{}",
        text(&refused.stderr)
    );

    holder.kill().unwrap();
    holder.wait().unwrap();
    let run = build_cmd(out.path(), &[]).output().unwrap();
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert!(
        text(&run.stderr).contains(&format!("took over a stale lock on {}", dataset.display()))
            && text(&run.stderr).contains(&format!("pid {pid}")),
        "{}",
        text(&run.stderr)
    );
}
