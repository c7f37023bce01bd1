//! `motionforge export humanml3d` on the demo dataset: the folder HumanML3D's consumers load.

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use glam::DVec3;
use motionforge::export::{ExportError, ExportOptions, export_humanml3d};
use motionforge::humanml3d::{DIM, NUM_JOINTS, recover_from_ric, vectors};
use motionforge::motion::ProfileSpec;

/// A `.npy` file's shape and values (as f64).
fn npy(path: &Path) -> (Vec<u64>, Vec<f64>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let file = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape = file.shape().to_vec();
    assert_eq!(
        file.dtype().num_bytes(),
        Some(4),
        "{}: float32",
        path.display()
    );
    let values = file.into_vec::<f32>().unwrap();
    (shape, values.into_iter().map(f64::from).collect())
}

fn lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(str::to_string)
        .collect()
}

fn export(dataset: &Path, out: &Path) -> std::process::Output {
    common::run_ok(
        Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .args(["export", "humanml3d", "--dataset"])
            .arg(dataset)
            .arg("--out")
            .arg(out),
    )
}

#[test]
fn the_demo_exports_as_a_humanml3d_folder_whose_files_agree_with_each_other() {
    let dir = tempfile::tempdir().unwrap();
    common::build_demo(dir.path());
    let dataset = dir.path().join("demo");
    let out = dir.path().join("hml3d");
    let run = export(&dataset, &out);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("exported 24 of 24 clips"), "{stdout}");

    // Names: one per row, mirrors `M` + their original's name, in their original's split.
    let table: Vec<Vec<String>> = lines(&out.join("names.csv"))
        .into_iter()
        .skip(1)
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    assert_eq!(table.len(), 24);
    let by_id: BTreeMap<&str, &Vec<String>> = table.iter().map(|r| (r[1].as_str(), r)).collect();
    let all = lines(&out.join("all.txt"));
    assert_eq!(all.len(), 24);
    let mut split_of: BTreeMap<String, String> = BTreeMap::new();
    for split in ["train", "val", "test"] {
        for name in lines(&out.join(format!("{split}.txt"))) {
            assert!(split_of.insert(name, split.to_string()).is_none());
        }
    }
    assert_eq!(split_of.len(), 24, "every name in exactly one split list");
    for row in &table {
        let (name, id, split, mirrored) = (&row[0], &row[1], &row[2], &row[4]);
        assert_eq!(&split_of[name], split);
        if mirrored == "true" {
            let original = by_id[id.strip_suffix(":m").unwrap()];
            assert_eq!(name, &format!("M{}", original[0]));
            assert_eq!(&original[2], split, "a mirror is in its original's split");
        }
    }
    // Originals first, then mirrors, each in order: HumanML3D's list order.
    let mut sorted = all.clone();
    sorted.sort_by_key(|n| (n.starts_with('M'), n.clone()));
    assert_eq!(all, sorted);

    // The three arrays of every clip agree: the vectors are those of `joints/`, and `new_joints`
    // are the positions recovered from the vectors.
    let (mut rows, mut sum) = (0usize, vec![0.0f64; DIM]);
    for name in &all {
        let (vshape, vecs) = npy(&out.join("new_joint_vecs").join(format!("{name}.npy")));
        let (jshape, joints) = npy(&out.join("joints").join(format!("{name}.npy")));
        let (nshape, new_joints) = npy(&out.join("new_joints").join(format!("{name}.npy")));
        let t = jshape[0];
        assert_eq!(jshape, [t, NUM_JOINTS as u64, 3], "{name}");
        assert_eq!(vshape, [t - 1, DIM as u64], "{name}");
        assert_eq!(nshape, [t - 1, NUM_JOINTS as u64, 3], "{name}");
        let positions: Vec<DVec3> = joints
            .chunks_exact(3)
            .map(|p| DVec3::new(p[0], p[1], p[2]))
            .collect();
        let again = vectors(&positions).unwrap();
        let worst = again
            .iter()
            .zip(&vecs)
            .map(|(a, b)| (f64::from(*a) - b).abs())
            .fold(0.0, f64::max);
        assert!(
            worst < 1e-4,
            "{name}: vectors differ from joints/ by {worst}"
        );
        let vecs32: Vec<f32> = vecs.iter().map(|v| *v as f32).collect();
        let recovered = recover_from_ric(&vecs32);
        let worst = recovered
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .zip(&new_joints)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-5, "{name}: new_joints differ by {worst}");
        // Standing on the floor, facing +z at the start, left hip on +x (HumanML3D's frame).
        let floor = new_joints
            .chunks_exact(3)
            .map(|p| p[1])
            .fold(f64::INFINITY, f64::min);
        assert!(
            (-1e-4..0.05).contains(&floor),
            "{name}: lowest joint at {floor}"
        );
        assert!(
            vecs[4] > 0.0 && vecs[7] < 0.0,
            "{name}: left hip +x, right hip -x"
        );
        for row in vecs.chunks_exact(DIM) {
            for (s, v) in sum.iter_mut().zip(row) {
                *s += v;
            }
            rows += 1;
        }
    }
    // Mean over every row; Std averaged within each of HumanML3D's seven groups.
    let (_, mean) = npy(&out.join("Mean.npy"));
    let (_, std) = npy(&out.join("Std.npy"));
    for (k, (m, s)) in mean.iter().zip(&sum).enumerate() {
        assert!((m - s / rows as f64).abs() < 1e-5, "mean column {k}");
    }
    let groups = [0..1, 1..3, 3..4, 4..67, 67..193, 193..259, 259..263];
    for g in groups {
        assert!(
            std[g.clone()]
                .iter()
                .all(|s| *s == std[g.start] && *s > 0.0),
            "{g:?}"
        );
    }
}

#[test]
fn an_existing_folder_is_kept_without_force_and_a_skeleton_without_a_map_is_skipped_by_name() {
    let dir = tempfile::tempdir().unwrap();
    common::build_demo(dir.path());
    let dataset = dir.path().join("demo");
    let out = dir.path().join("hml3d");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("keep.txt"), "mine").unwrap();
    let err = export_humanml3d(&dataset, &out, &ExportOptions::default()).unwrap_err();
    assert!(matches!(err, ExportError::Exists { .. }), "{err}");
    assert!(err.to_string().contains("--force"));
    assert!(out.join("keep.txt").exists());
    // Not an export: --force does not remove someone's folder either.
    let forced = ExportOptions {
        force: true,
        ..ExportOptions::default()
    };
    let err = export_humanml3d(&dataset, &out, &forced).unwrap_err();
    assert!(matches!(err, ExportError::NotAnExport { .. }), "{err}");
    assert!(out.join("keep.txt").exists());
    export_humanml3d(&dataset, &out.join("export"), &ExportOptions::default()).unwrap();
    std::fs::remove_dir_all(&out).unwrap();
    export_humanml3d(&dataset, &out, &ExportOptions::default()).unwrap();
    std::fs::write(out.join("keep.txt"), "a file inside an export").unwrap();

    // The CMU profile without its [smpl22] table: its clips are skipped, naming what is missing,
    // and the rest is exported.
    let mut cmu = ProfileSpec::bundled("cmu").unwrap();
    cmu.smpl22.clear();
    let options = ExportOptions {
        force: true,
        profiles: vec![cmu],
    };
    let summary = export_humanml3d(&dataset, &out, &options).unwrap();
    assert!(!out.join("keep.txt").exists());
    assert_eq!(summary.skipped.len(), 4, "{summary:?}");
    assert!(summary.skipped.iter().all(|s| {
        s.clip_id.starts_with("cmu/")
            && s.reason
                .contains("no `[smpl22]` entry for SMPL joint `pelvis`")
    }));
    assert_eq!(summary.exported, 20);
    assert_eq!(lines(&out.join("all.txt")).len(), 20);

    let missing = export_humanml3d(&dir.path().join("nothing"), &out, &options).unwrap_err();
    assert!(missing.to_string().contains("nothing"), "{missing}");
}

/// How text-to-motion's `Text2MotionDatasetV2` (and T2M-GPT's and MoMask's copies) read a
/// HumanML3D folder, step by step; any exception drops the clip silently there, so here it fails.
const LOADER: &str = r#"
import io, sys, os, numpy as np
root, split = sys.argv[1], sys.argv[2]
def load(*path):
    # Each file is byte for byte what np.save writes for its array (header spelling included).
    path = os.path.join(root, *path)
    array, saved = np.load(path), io.BytesIO()
    np.save(saved, array)
    assert saved.getvalue() == open(path, 'rb').read(), path
    return array
mean, std = load('Mean.npy'), load('Std.npy')
assert mean.shape == (263,) and std.shape == (263,) and (std > 0).all()
names = [l.strip() for l in open(os.path.join(root, split + '.txt'))]
kept = 0
for name in names:
    motion = load('new_joint_vecs', name + '.npy')
    load('new_joints', name + '.npy')
    load('joints', name + '.npy')
    assert motion.ndim == 2 and motion.shape[1] == 263, (name, motion.shape)
    if len(motion) < 40 or len(motion) >= 200:
        continue
    whole = False
    for line in open(os.path.join(root, 'texts', name + '.txt')):
        fields = line.strip().split('#')
        assert len(fields) == 4, (name, line)
        caption, tokens = fields[0], fields[1].split(' ')
        assert caption and tokens, (name, line)
        for t in tokens:
            word, pos = t.split('/')
            assert word.isalpha() and pos.isupper(), (name, t)
        f_tag, to_tag = float(fields[2]), float(fields[3])
        whole = whole or (f_tag == 0.0 and to_tag == 0.0)
    assert whole, name
    normalised = (motion - mean) / std
    assert np.isfinite(normalised).all(), name
    kept += 1
print(kept)
"#;

#[test]
fn every_demo_clip_loads_the_way_text_to_motion_loads_humanml3d() {
    let dir = tempfile::tempdir().unwrap();
    common::build_demo(dir.path());
    let out = dir.path().join("hml3d");
    export(&dir.path().join("demo"), &out);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("export.json")).unwrap()).unwrap();
    assert_eq!(
        summary["captions_refused"].as_array().map(Vec::len),
        Some(0)
    );
    let filtered = summary["filtered_by_loaders"].as_array().unwrap().len();
    let mut kept = 0;
    for split in ["train", "val", "test"] {
        let printed = common::run_python(LOADER, &[out.as_os_str(), split.as_ref()]);
        kept += printed.trim().parse::<usize>().unwrap();
    }
    // Every clip loads except those the loader filters by length, as export.json lists.
    assert_eq!(kept, 24 - filtered);
    assert!(kept > 0);
}

/// Every file under `dir` by relative path, with its bytes.
fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let rel = path.strip_prefix(dir).unwrap().display().to_string();
                files.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

fn export_cmd(dataset: &Path, out: &Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_motionforge"));
    command
        .args(["export", "humanml3d", "--force", "--dataset"])
        .arg(dataset)
        .arg("--out")
        .arg(out);
    command
}

#[test]
fn force_never_removes_the_dataset_the_working_folder_or_a_folder_it_did_not_write() {
    let dir = tempfile::tempdir().unwrap();
    common::build_demo(dir.path());
    let dataset = dir.path().join("demo");
    let before = tree(&dataset);
    let work = dir.path().join("work");
    std::fs::create_dir_all(&work).unwrap();
    std::fs::write(work.join("notes.txt"), "the user's own file").unwrap();
    let work_before = tree(&work);
    // Each is refused as a usage error (exit 2) naming why, and nothing is touched.
    let cases: Vec<(std::path::PathBuf, &str)> = vec![
        (dataset.clone(), "is the dataset folder"),
        (dataset.join("."), "is the dataset folder"),
        (dir.path().to_path_buf(), "holds the"),
        (dataset.join("data"), "lies inside the dataset folder"),
        (dataset.join("new"), "lies inside the dataset folder"),
        (".".into(), "is the working folder"),
        ("..".into(), "holds the working folder"),
    ];
    for (out, why) in cases {
        let run = export_cmd(&dataset, &out)
            .current_dir(&work)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(
            run.status.code(),
            Some(2),
            "--out {}: {stderr}",
            out.display()
        );
        assert!(stderr.contains(why), "--out {}: {stderr}", out.display());
        assert_eq!(tree(&dataset), before, "--out {}", out.display());
        assert_eq!(tree(&work), work_before, "--out {}", out.display());
    }
    // A folder of someone else's files is not replaced, even with --force.
    let run = export_cmd(&dataset, &work)
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("not a finished HumanML3D export"),
        "{stderr}"
    );
    assert_eq!(tree(&work), work_before);
    // The export's own default folder inside the dataset is allowed.
    common::run_ok(
        Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .args(["export", "humanml3d", "--dataset"])
            .arg(&dataset),
    );
    assert!(dataset.join("humanml3d/export.json").is_file());
    // The other commands that write or clear folders keep the same folders.
    let report = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .arg("report")
        .arg(&dataset)
        .args(["-o", "."])
        .current_dir(&work)
        .output()
        .unwrap();
    assert_eq!(report.status.code(), Some(2), "{report:?}");
    assert!(String::from_utf8_lossy(&report.stderr).contains("is the working folder"));
    let preview = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .arg("preview")
        .arg(&dataset)
        .args(["--limit", "1", "-o"])
        .arg(dataset.join("data"))
        .output()
        .unwrap();
    assert_eq!(preview.status.code(), Some(2), "{preview:?}");
    assert!(String::from_utf8_lossy(&preview.stderr).contains("lies inside the dataset folder"));
    assert_eq!(tree(&work), work_before);
    let clean = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["clean", "--config"])
        .arg(common::repo().join("fixtures/demo.toml"))
        .args(["--output", ".."])
        .current_dir(&dataset)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&clean.stderr);
    assert_eq!(clean.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("is the working folder"), "{stderr}");
    assert!(dataset.join("manifest.json").is_file());
}

#[test]
fn a_build_does_not_write_into_the_working_folder_or_a_folder_of_other_files() {
    let dir = tempfile::tempdir().unwrap();
    // A folder named like the dataset, holding someone's files.
    let foreign = dir.path().join("demo");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("README.md"), "someone's readme").unwrap();
    for cwd in [dir.path(), foreign.as_path()] {
        let output = if cwd == foreign { ".." } else { "." };
        let run = Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .args(["build", "--force", "--config"])
            .arg(common::repo().join("fixtures/demo.toml"))
            .args(["--output", output])
            .current_dir(cwd)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains("did not write") || stderr.contains("is the working folder"),
            "{stderr}"
        );
        assert_eq!(
            std::fs::read_to_string(foreign.join("README.md")).unwrap(),
            "someone's readme"
        );
        assert!(!foreign.join(".motionforge").exists());
    }
}

#[test]
fn an_interrupted_forced_export_leaves_the_old_export_or_the_new_one() {
    let dir = tempfile::tempdir().unwrap();
    common::build_demo(dir.path());
    let demo = dir.path().join("demo");
    common::run_ok(
        Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .args(["build", "--config"])
            .arg(common::repo().join("fixtures/humanml3d-joints/build.toml"))
            .arg("--output")
            .arg(dir.path()),
    );
    let small = dir.path().join("hml3d-joints");
    // The two exports a killed run may leave: the old one (of the small dataset) and the new one
    // (of the demo), each made without interruption.
    let old_ref = dir.path().join("old-ref");
    let new_ref = dir.path().join("new-ref");
    common::run_ok(&mut export_cmd(&small, &old_ref));
    common::run_ok(&mut export_cmd(&demo, &new_ref));
    let (old, new) = (tree(&old_ref), tree(&new_ref));
    assert_ne!(old, new);

    // A whole run as the attempts below make it: the demo's export forced over the small one
    // (which also removes the old export at its end).
    let out = dir.path().join("out");
    common::run_ok(&mut export_cmd(&small, &out));
    let started = std::time::Instant::now();
    common::run_ok(&mut export_cmd(&demo, &out));
    let whole = started.elapsed();
    let mut rng = fastrand::Rng::with_seed(30);
    let (mut saw_old, mut saw_new) = (0, 0);
    // At least 20 kills; more, reaching further past a whole run, while one outcome is unseen
    // (a loaded machine stretches a run's end).
    for attempt in 0..60u32 {
        if attempt >= 20 && saw_old > 0 && saw_new > 0 {
            break;
        }
        common::run_ok(&mut export_cmd(&small, &out));
        let mut child = export_cmd(&demo, &out)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        // Anywhere from the start to a little past a whole run.
        let reach = 1.2 + 0.1 * f64::from(attempt.saturating_sub(20));
        let delay = whole.mul_f64(rng.f64() * reach);
        std::thread::sleep(delay);
        let _ = child.kill();
        child.wait().unwrap();
        let found = tree(&out);
        if found == old {
            saw_old += 1;
        } else if found == new {
            saw_new += 1;
        } else {
            panic!(
                "attempt {attempt} (killed after {delay:?}): {} holds {} files, neither export",
                out.display(),
                found.len()
            );
        }
    }
    // Kills landed on both sides of the swap, so the check saw both outcomes.
    assert!(saw_old > 0 && saw_new > 0, "old {saw_old}, new {saw_new}");
    // The next run finishes the job from whatever was left.
    common::run_ok(&mut export_cmd(&demo, &out));
    assert_eq!(tree(&out), new);
}

#[test]
fn split_names_from_a_shard_never_make_paths_outside_the_export() {
    let dir = tempfile::tempdir().unwrap();
    common::build_demo(dir.path());
    let dataset = dir.path().join("demo");
    // A dataset received from someone: its shards name splits that are paths.
    let escape = dir.path().join("escaped");
    let script = r#"
import sys, glob, pyarrow as pa, pyarrow.parquet as pq
for i, path in enumerate(sorted(glob.glob(sys.argv[1] + '/data/*.parquet'))):
    t = pq.read_table(path)
    names = ['../../../x', sys.argv[2], 'all']
    split = [names[(i + r) % 3] if r % 2 == 0 else s for r, s in enumerate(t.column('split').to_pylist())]
    t = t.set_column(t.schema.get_field_index('split'), 'split', pa.array(split, pa.string()))
    pq.write_table(t, path, compression='zstd')
"#;
    common::run_python(script, &[dataset.as_os_str(), escape.join("x").as_os_str()]);
    let out = dir.path().join("hml3d");
    let summary = export_humanml3d(&dataset, &out, &ExportOptions::default()).unwrap();
    assert!(!escape.exists(), "wrote outside --out");
    assert!(!dir.path().join("x.txt").exists() && !Path::new("/x.txt").exists());
    let refused: Vec<&str> = summary
        .skipped
        .iter()
        .map(|s| s.reason.as_str())
        .filter(|r| r.contains("split"))
        .collect();
    assert!(refused.len() >= 3, "{:?}", summary.skipped);
    assert!(refused.iter().any(|r| r.contains("not a plain file name")));
    assert!(refused.iter().any(|r| r.contains("all.txt")));
    // Every file the export wrote is inside it, and the clips with usable splits are listed.
    assert_eq!(summary.exported + summary.skipped.len(), summary.clips);
    assert!(summary.exported > 0);
    let listed = lines(&out.join("all.txt"));
    assert_eq!(listed.len(), summary.exported);
}

#[test]
fn a_clip_without_a_usable_caption_is_left_out_and_every_split_gets_its_list() {
    let dir = tempfile::tempdir().unwrap();
    common::build_demo(dir.path());
    let dataset = dir.path().join("demo");
    // One row whose every caption has a `#` (a caption line cannot hold one), and no test split.
    let script = r#"
import sys, glob, pyarrow as pa, pyarrow.parquet as pq
for path in sorted(glob.glob(sys.argv[1] + '/data/*.parquet')):
    t = pq.read_table(path)
    if path.split('/')[-1].startswith('test'):
        import os; os.remove(path); continue
    ids = t.column('clip_id').to_pylist()
    if 'train' in path.split('/')[-1]:
        first = ids[0]
        def fix(name, values):
            return pa.array([v if i != first else ('# ' + v if isinstance(v, str) else ['#' + x for x in v]) for i, v in zip(ids, values)], t.schema.field(name).type)
        for name in ['text', 'texts', 'paraphrases']:
            t = t.set_column(t.schema.get_field_index(name), name, fix(name, t.column(name).to_pylist()))
        print(first)
    pq.write_table(t, path, compression='zstd')
"#;
    let uncaptioned = common::run_python(script, &[dataset.as_os_str()]);
    let uncaptioned = uncaptioned.trim();
    let out = dir.path().join("hml3d");
    let summary = export_humanml3d(&dataset, &out, &ExportOptions::default()).unwrap();
    let skipped = summary
        .skipped
        .iter()
        .find(|s| s.clip_id == uncaptioned)
        .unwrap_or_else(|| panic!("{uncaptioned} not skipped: {:?}", summary.skipped));
    assert!(
        skipped.reason.contains("no caption could be written"),
        "{skipped:?}"
    );
    // No empty texts file anywhere, and the clip is in no list.
    for entry in std::fs::read_dir(out.join("texts")).unwrap() {
        let path = entry.unwrap().path();
        assert!(
            std::fs::metadata(&path).unwrap().len() > 0,
            "{}",
            path.display()
        );
    }
    let names = std::fs::read_to_string(out.join("names.csv")).unwrap();
    assert!(
        names
            .lines()
            .all(|l| l.split(',').nth(1) != Some(uncaptioned)),
        "{names}"
    );
    // The test split is empty, and its list is there, empty, as T2M-GPT's loader needs.
    for list in ["train.txt", "val.txt", "test.txt", "all.txt"] {
        assert!(out.join(list).is_file(), "{list}");
    }
    assert_eq!(std::fs::read_to_string(out.join("test.txt")).unwrap(), "");
    assert_eq!(lines(&out.join("all.txt")).len(), summary.exported);
}
