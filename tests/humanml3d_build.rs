//! Joint-position captures in a build (`fixtures/humanml3d-joints/`): HumanML3D's arrays read,
//! cut by its index as HumanML3D cuts them, captioned from caption files, mirrored, exported as
//! HumanML3D and as BVH, checked against HumanML3D's own arrays in `../shared`.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::DVec3;
use motionforge::annotate::frame_index::{
    IndexOptions, IndexRow, humanml3d_head_trim, read_captions, read_frame_index, row_range,
};
use motionforge::annotate::span::Time;
use motionforge::base::RejectReason;
use motionforge::config::{PositionLayoutName, PositionsConfig};
use motionforge::motion::{ProfileSpec, SignedAxis, read_bvh};
use motionforge::source::CaptureFile;
use motionforge::stages::ingest;

use common::project::{ConfigSpec, Project};

/// A `.npy` file's shape and values (as f64).
fn npy(path: &Path) -> (Vec<u64>, Vec<f64>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let file = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape = file.shape().to_vec();
    let values = match file.dtype().num_bytes() {
        Some(8) => file.into_vec::<f64>().unwrap(),
        _ => file
            .into_vec::<f32>()
            .unwrap()
            .into_iter()
            .map(f64::from)
            .collect(),
    };
    (shape, values)
}

/// Frames of the first 22 joints of a `frames × joints × 3` array.
fn body(path: &Path) -> Vec<[DVec3; 22]> {
    let (shape, v) = npy(path);
    let joints = shape[1] as usize;
    v.chunks_exact(joints * 3)
        .map(|f| std::array::from_fn(|j| DVec3::new(f[3 * j], f[3 * j + 1], f[3 * j + 2])))
        .collect()
}

fn max_distance(a: &[[DVec3; 22]], b: &[[DVec3; 22]]) -> f64 {
    assert_eq!(a.len(), b.len(), "frame counts");
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| p.distance(*q)))
        .fold(0.0, f64::max)
}

/// HumanML3D's mirror (`swap_left_right`): x negated, left and right joints swapped.
fn humanml3d_mirror(frames: &[[DVec3; 22]]) -> Vec<[DVec3; 22]> {
    const SWAP: [usize; 22] = [
        0, 2, 1, 3, 5, 4, 6, 8, 7, 9, 11, 10, 12, 14, 13, 15, 17, 16, 19, 18, 21, 20,
    ];
    frames
        .iter()
        .map(|f| std::array::from_fn(|j| f[SWAP[j]] * DVec3::new(-1.0, 1.0, 1.0)))
        .collect()
}

/// A copy of the fixture folder whose dataset goes to `<copy>/out`.
fn fixture_copy() -> (Project, PathBuf) {
    let config = Path::new("humanml3d-joints/build.toml");
    let bundled = ConfigSpec::from_file(&common::repo().join("fixtures").join(config));
    let project = Project::new()
        .fixture("humanml3d-joints")
        .config_at(config, bundled.output("out"))
        .build();
    let config = project.join(config);
    (project, config)
}

fn motionforge() -> Command {
    Command::new(env!("CARGO_BIN_EXE_motionforge"))
}

fn lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(str::to_string)
        .collect()
}

#[test]
fn humanml3d_arrays_build_cut_mirror_and_export_back_to_humanml3d_s_own_positions() {
    let (_dir, config) = fixture_copy();
    let root = config.parent().unwrap().to_path_buf();
    common::run_ok(motionforge().args(["build", "--config"]).arg(&config));
    let dataset = root.join("out/hml3d-joints");
    let rejects = std::fs::read_to_string(dataset.join("rejects.jsonl")).unwrap();
    assert!(rejects.trim().is_empty(), "{rejects}");

    let out = root.join("hml3d");
    common::run_ok(
        motionforge()
            .args(["export", "humanml3d", "--dataset"])
            .arg(&dataset)
            .arg("--out")
            .arg(&out),
    );
    // name -> clip id.
    let names: Vec<(String, String)> = lines(&out.join("names.csv"))
        .into_iter()
        .skip(1)
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            (cells[0].to_string(), cells[1].to_string())
        })
        .collect();
    let name_of = |clip: &str| {
        names
            .iter()
            .find(|(_, c)| c == clip)
            .map(|(n, _)| n.clone())
            .unwrap_or_else(|| panic!("no clip `{clip}` in {names:?}"))
    };
    let capture = "humanml3d-pose-data/WalkInCounterClockwiseCircle02_poses";
    let whole = name_of(&format!("{capture}:0-180"));
    let sub = name_of(&format!("{capture}:20-90"));
    let mirrored = name_of(&format!("{capture}:0-180:m"));
    let tennis = name_of("humanml3d-new-joints/012314:0-170");
    assert_eq!(names.len(), 6, "three clips and their mirrors: {names:?}");

    // The pose_data array (x negated back), cut by index row 23 as HumanML3D cuts it, read
    // through IK and exported: HumanML3D's own joints/000021.npy.
    let reference = body(&common::shared_data().join("humanml3d/joints/000021.npy"));
    let exported = body(&out.join("joints").join(format!("{whole}.npy")));
    let d = max_distance(&exported, &reference);
    assert!(d < 1e-5, "000021 off by {d} m");
    // The caption file's sub-span 1.0#4.5 s: frames 20-90 of the clip.
    let exported = body(&out.join("joints").join(format!("{sub}.npy")));
    let d = max_distance(&exported, &reference[20..90]);
    assert!(d < 1e-5, "sub-span off by {d} m");
    // The 22-joint new_joints array, read as a capture of its own.
    let new_joints = body(&common::shared_data().join("humanml3d/HumanML3D/new_joints/012314.npy"));
    let exported = body(&out.join("joints").join(format!("{tennis}.npy")));
    let d = max_distance(&exported, &new_joints);
    assert!(d < 1e-5, "012314 off by {d} m");
    // The mirror is HumanML3D's swap_left_right: mirrors are exact reflections on the mirrored
    // skeleton (issue 16), so the body's own left/right asymmetry is reflected too.
    let exported = body(&out.join("joints").join(format!("{mirrored}.npy")));
    let d = max_distance(&exported, &humanml3d_mirror(&reference));
    assert!(d < 1e-5, "mirror off by {d} m");
    let from_original = max_distance(&exported, &reference);
    assert!(
        from_original > 0.05,
        "the mirror is a copy of the original ({from_original} m)"
    );

    // Every whole-clip caption kept (two lines), the sub-span's caption on its own clip, and
    // mirrored captions on the mirror.
    let texts = lines(&out.join("texts").join(format!("{whole}.txt")));
    assert_eq!(texts.len(), 2, "{texts:?}");
    assert!(texts[0].starts_with("a person walks in a counterclockwise circle.#"));
    assert!(texts[1].starts_with("someone walks around in a circle to their left.#"));
    let texts = lines(&out.join("texts").join(format!("{sub}.txt")));
    assert_eq!(texts.len(), 1, "{texts:?}");
    assert!(texts[0].starts_with("a person walks forward while curving to the left.#"));
    let texts = lines(&out.join("texts").join(format!("{mirrored}.txt")));
    assert!(
        texts[0].starts_with("a person walks in a clockwise circle.#"),
        "{texts:?}"
    );
    let (shape, _) = npy(&out.join("new_joint_vecs").join(format!("{whole}.npy")));
    assert_eq!(shape, vec![179, 263]);

    // BVH export of a joint-position clip: its forward kinematics gives the positions back.
    let bvh_path = root.join("whole.bvh");
    common::run_ok(
        motionforge()
            .args(["export-bvh", "--config"])
            .arg(&config)
            .args(["--clip", &format!("{capture}:0-180"), "--output"])
            .arg(&bvh_path),
    );
    let bvh = read_bvh(&std::fs::read_to_string(&bvh_path).unwrap()).unwrap();
    assert_eq!(bvh.motion.num_frames(), 180);
    assert_eq!(bvh.header_fps, 20.0);
    let pose = bvh.motion.forward_kinematics();
    let n = pose.joints;
    assert_eq!(n, 22);
    // The file lists joints depth first; SMPL's order is by name.
    let smpl = ProfileSpec::bundled("smpl-22").unwrap().joints;
    let at: Vec<usize> = smpl
        .iter()
        .map(|name| {
            bvh.skeleton
                .joints
                .iter()
                .position(|j| &j.name == name)
                .unwrap_or_else(|| panic!("no joint {name} in the BVH"))
        })
        .collect();
    let from_bvh: Vec<[DVec3; 22]> = pose
        .positions
        .chunks_exact(n)
        .map(|f| std::array::from_fn(|j| f[at[j]]))
        .collect();
    let d = max_distance(&from_bvh, &reference);
    assert!(d < 1e-4, "BVH off by {d} m");
}

fn positions(layout: PositionLayoutName, negate_x: bool) -> PositionsConfig {
    PositionsConfig {
        layout,
        up: SignedAxis {
            axis: 1,
            negative: false,
        },
        forward: SignedAxis {
            axis: 2,
            negative: false,
        },
        units: 1.0,
        fps: 20.0,
        negate_x,
        bone_tolerance: 0.05,
    }
}

fn ingest_bytes(path: &Path, bytes: &[u8], config: &PositionsConfig) -> ingest::IngestOutput {
    let file = CaptureFile {
        source: 0,
        path: path.to_path_buf(),
        display: path.file_name().unwrap().to_string_lossy().into_owned(),
    };
    let spec = ProfileSpec::bundled("smpl-22").unwrap();
    ingest::run(&ingest::CaptureInput {
        file: &file,
        bytes,
        sha256: "test",
        source: "test",
        profile: &spec,
        fps_override: None,
        format: config,
    })
}

#[test]
fn a_capture_whose_bones_wander_is_rejected_naming_file_frame_and_bone() {
    let path = common::shared_data().join("humanml3d/joints/000021.npy");
    let mut bytes = std::fs::read(&path).unwrap();
    let config = positions(PositionLayoutName::SmplH52, false);
    // As it is: read, bones constant, nothing to report.
    let out = ingest_bytes(&path, &bytes, &config);
    let capture = out.capture.expect("000021 reads");
    assert!(out.rejects.is_empty());
    assert!(capture.notes.is_empty(), "{:?}", capture.notes);
    assert_eq!(capture.motion.num_frames(), 180);
    assert_eq!(capture.capture.fps, 20.0);

    // Left wrist (joint 20) of frame 50 moved 10 cm along x: its forearm bone stretches.
    let header = 10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let at = header + ((50 * 52 + 20) * 3) * 8;
    let x = f64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) + 0.10;
    bytes[at..at + 8].copy_from_slice(&x.to_le_bytes());
    let out = ingest_bytes(&path, &bytes, &config);
    assert!(out.capture.is_none());
    let reject = &out.rejects[0];
    assert_eq!(reject.reason, RejectReason::Positions);
    assert_eq!(reject.file, "000021.npy");
    assert_eq!(reject.frame, Some(50));
    assert!(reject.message.contains("left_wrist"), "{}", reject.message);

    // A looser tolerance takes it, and the IK residual is reported.
    let loose = PositionsConfig {
        bone_tolerance: 0.9,
        ..config.clone()
    };
    let out = ingest_bytes(&path, &bytes, &loose);
    let capture = out.capture.expect("read with a loose tolerance");
    let note = &capture.notes[0];
    assert_eq!(note.kind, "ik_residual");
    assert!(note.message.contains("frame 50"), "{}", note.message);

    // The wrong layout is refused, naming both counts.
    let out = ingest_bytes(&path, &bytes, &positions(PositionLayoutName::Smpl22, false));
    assert!(
        out.rejects[0].message.contains("52 joints"),
        "{:?}",
        out.rejects
    );
}

#[test]
fn humanml3d_cuts_trim_dataset_heads_and_slice_as_python_does() {
    let index = common::shared_data().join("humanml3d/index.csv");
    let (rows, notes) =
        read_frame_index(&std::fs::read_to_string(&index).unwrap(), "index.csv").unwrap();
    assert!(notes.is_empty());
    let cuts = IndexOptions {
        fps: 20.0,
        humanml3d_cuts: true,
    };
    let row = |name: &str| rows.iter().find(|r| r.new_name == name).unwrap();
    let frames = |name: &str, len: u64| {
        let (s, e) = row_range(row(name), &cuts);
        (s.to_frame(20.0, len), e.to_frame(20.0, len))
    };
    // 012314: Eyes_Japan_Dataset, data[60:][149:320].
    assert_eq!(frames("012314.npy", 1000), (209, 380));
    // 000021: KIT, no trim.
    assert_eq!(frames("000021.npy", 1000), (0, 180));
    // Every trimmed dataset of the real index, with the trim HumanML3D applies.
    for (dataset, trim) in [
        ("Eyes_Japan_Dataset", 60),
        ("MPI_HDM05", 60),
        ("TotalCapture", 20),
        ("MPI_Limits", 20),
        ("Transitions_mocap", 10),
    ] {
        let r = rows
            .iter()
            .find(|r| r.source_path.contains(dataset))
            .unwrap_or_else(|| panic!("no {dataset} row in the real index"));
        assert_eq!(humanml3d_head_trim(&r.source_path, 20.0), trim, "{dataset}");
        let (s, _) = row_range(r, &cuts);
        assert_eq!(s.to_frame(20.0, 100_000), r.start_frame + trim, "{dataset}");
    }
    // `-1`: Python's data[start:-1] stops one frame before the end; without the option, the end.
    // (No AMASS row of the real index ends at -1; this one is written for the test.)
    let open = IndexRow {
        source_path: "./pose_data/MPI_Limits/03099/op2_poses.npy".into(),
        start_frame: 0,
        end_frame: -1,
        new_name: "x.npy".into(),
        line: 2,
    };
    let open = &open;
    let (s, _) = row_range(open, &cuts);
    assert_eq!(s.to_frame(20.0, 500), 20);
    let (_, e) = row_range(open, &cuts);
    assert_eq!(e.to_frame(20.0, 500), 499);
    let plain = IndexOptions {
        fps: 20.0,
        humanml3d_cuts: false,
    };
    assert_eq!(row_range(open, &plain).1, Time::End);
    // humanact12 files are kept whole.
    let act = rows
        .iter()
        .find(|r| r.source_path.contains("humanact12"))
        .unwrap();
    let (s, e) = row_range(act, &cuts);
    assert_eq!((s.to_frame(20.0, 77), e.to_frame(20.0, 77)), (0, 77));
}

#[test]
fn caption_files_give_every_caption_and_their_sub_spans() {
    let text = "\u{feff}a man walks.#a/DET man/NOUN walk/VERB#0.0#0.0\r\n\
                he waves.#he/PRON wave/VERB#1.5#3.0\n\
                #only/ADV tokens#0.0#0.0\n\
                bad times#x#3.0#1.0\n\
                not a number#x#a#2\n\
                plain caption line\n";
    let (lines, notes) = read_captions(text, "texts/000001.txt");
    let got: Vec<(&str, f64, f64)> = lines
        .iter()
        .map(|l| (l.caption.as_str(), l.start, l.end))
        .collect();
    assert_eq!(
        got,
        vec![
            ("a man walks.", 0.0, 0.0),
            ("he waves.", 1.5, 3.0),
            ("plain caption line", 0.0, 0.0),
        ]
    );
    assert_eq!(notes.len(), 2);
    assert!(
        notes[0].message.starts_with("texts/000001.txt:4:"),
        "{:?}",
        notes[0]
    );
    assert!(
        notes[1].message.starts_with("texts/000001.txt:5:"),
        "{:?}",
        notes[1]
    );
}

/// Builds `config` through the binary under a 1 GiB address-space limit, which must succeed: a
/// build whose memory grows with one damaged input fails here instead of taking the machine.
fn build_in_1_gib(config: &Path) {
    let mut limited = Command::new("prlimit");
    limited
        .arg(format!("--as={}", 1u64 << 30))
        .arg(env!("CARGO_BIN_EXE_motionforge"));
    build_ok(limited, config, "");
}

/// Runs `build --config <config>` with `command` (the binary, or a wrapper of it), which must
/// succeed; `what` heads the failure message.
fn build_ok(mut command: Command, config: &Path, what: &str) {
    let run = command
        .args(["build", "--config"])
        .arg(config)
        .output()
        .expect("the binary runs");
    assert!(
        run.status.success(),
        "{what}{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

/// Sets one float64 value of a C-order `.npy` file (version 1 header) in place.
use npyz::WriterBuilder;

fn set_f64(path: &Path, index: usize, value: f64) {
    let mut bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..6], b"\x93NUMPY");
    let header = 10 + usize::from(u16::from_le_bytes([bytes[8], bytes[9]]));
    let at = header + index * 8;
    bytes[at..at + 8].copy_from_slice(&value.to_le_bytes());
    std::fs::write(path, bytes).unwrap();
}

const POSE_DATA: &str = "pose_data/KIT/4/WalkInCounterClockwiseCircle02_poses.npy";

#[test]
fn one_huge_value_in_a_joint_array_rejects_that_capture_at_ingest_and_the_build_goes_on() {
    let (_dir, config) = fixture_copy();
    let root = config.parent().unwrap();
    // Frame 5, joint 3, x of the (180, 52, 3) float64 array: finite, and its square is not.
    set_f64(&root.join(POSE_DATA), (5 * 52 + 3) * 3, 1e200);
    build_ok(motionforge(), &config, "");
    let dataset = root.join("out/hml3d-joints");
    let rejects: Vec<serde_json::Value> = lines(&dataset.join("rejects.jsonl"))
        .iter()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(rejects.len(), 1, "{rejects:?}");
    let reject = &rejects[0];
    assert_eq!(reject["reason"], "positions", "{reject}");
    assert!(
        reject["file"].as_str().unwrap().ends_with(POSE_DATA),
        "{reject}"
    );
    assert_eq!(reject["frame"], 5, "{reject}");
    let message = reject["message"].as_str().unwrap();
    assert!(
        message.contains("joint 3") && message.contains("1e200"),
        "{message}"
    );
    // The other source's capture is built: it and its mirror.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dataset.join("build-report.json")).unwrap())
            .unwrap();
    assert_eq!(report["clips"], 2, "{report:#}");

    // The same bound for the units that scale the values.
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(&config, text.replacen("units = 1.0", "units = 1e160", 1)).unwrap();
    let check = motionforge()
        .args(["config", "check", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&check.stderr);
    assert_eq!(check.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("units") && stderr.contains("1e160"),
        "{stderr}"
    );
}

#[test]
fn an_index_changed_back_and_forth_never_leaves_the_cache_naming_a_removed_entry() {
    let (_dir, config) = fixture_copy();
    let root = config.parent().unwrap();
    // Eight short captures beside the long one (20-frame pieces of the real 012314 array): the
    // long capture's frames are most of the frame chunks' bytes while its clips are a small part
    // of the segment outputs, so a changed cut makes pruning rewrite the chunks' pack (dropping
    // its old chunk) and leave the segment pack, old output included, as it is.
    let source = root.join("new_joints/012314.npy");
    let bytes = std::fs::read(&source).unwrap();
    let array = npyz::NpyFile::new(&bytes[..]).unwrap();
    let values = array.into_vec::<f32>().unwrap();
    for piece in 0..8 {
        let frames = &values[piece * 20 * 66..(piece + 1) * 20 * 66];
        let mut out = Vec::new();
        let mut writer = npyz::WriteOptions::<f32>::new()
            .default_dtype()
            .shape(&[20, 22, 3])
            .writer(&mut out)
            .begin_nd()
            .unwrap();
        writer.extend(frames.iter().copied()).unwrap();
        writer.finish().unwrap();
        let name = format!("piece{piece}");
        std::fs::write(root.join(format!("new_joints/{name}.npy")), out).unwrap();
        std::fs::write(
            root.join(format!("new_joints/{name}.json")),
            format!(r#"{{"action": "tennis serve", "text": "part {piece} of a tennis serve"}}"#),
        )
        .unwrap();
    }
    std::fs::remove_file(&source).unwrap();
    std::fs::remove_file(root.join("new_joints/012314.json")).unwrap();
    let index = root.join("index.csv");
    let header = "source_path,start_frame,end_frame,new_name\n";
    let row = |start: u32, end: u32| format!("{header}./{POSE_DATA},{start},{end},000021.npy\n");
    // Each build changes only the index; earlier cuts come back after others replaced them, so
    // a still-findable old segment output names frame chunks a later build removed.
    let cuts = [
        (0, 180),
        (10, 150),
        (0, 180),
        (20, 100),
        (10, 150),
        (0, 180),
        (30, 170),
        (20, 100),
        (0, 180),
    ];
    let mut frames = Vec::new();
    for (i, (start, end)) in cuts.into_iter().enumerate() {
        std::fs::write(&index, row(start, end)).unwrap();
        build_ok(
            motionforge(),
            &config,
            &format!("build {i} ({start}..{end}): "),
        );
        let dataset = config.parent().unwrap().join("out/hml3d-joints");
        frames.push(common::table_bytes(&dataset));
    }
    // And the same cut gives the same table every time it comes back.
    assert_eq!(frames[0], frames[2]);
    assert_eq!(frames[0], frames[8]);
    assert_eq!(frames[1], frames[4]);
    assert_eq!(frames[3], frames[7]);
}

#[test]
fn an_index_of_bad_rows_gives_a_bounded_report_under_a_1_gb_address_space() {
    let (_dir, config) = fixture_copy();
    let root = config.parent().unwrap();
    let mut text = std::fs::read_to_string(root.join("index.csv")).unwrap();
    // About 27 MB of rows that cannot be read (a start after the end), as the audit's file.
    let bad = format!("./{POSE_DATA},90,10,{}.npy\n", "x".repeat(40));
    while text.len() < 27 << 20 {
        text.push_str(&bad);
    }
    let rows = text.lines().count() - 2;
    std::fs::write(root.join("index.csv"), &text).unwrap();
    build_in_1_gib(&config);
    let path = root.join("out/hml3d-joints/build-report.json");
    let size = std::fs::metadata(&path).unwrap().len();
    assert!(size < 1 << 20, "build-report.json is {size} bytes");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let notes = report["notes"].as_array().unwrap();
    let bad_rows = notes.iter().filter(|n| n["kind"] == "bad_row").count();
    assert_eq!(bad_rows, motionforge::annotate::span::NOTES_PER_KIND);
    let rest = notes
        .iter()
        .find(|n| n["kind"] == motionforge::annotate::span::NOT_LISTED.as_str())
        .unwrap_or_else(|| panic!("no count of the notes left out: {notes:?}"));
    let expected = format!(
        "{} more `bad_row` notes",
        rows - motionforge::annotate::span::NOTES_PER_KIND
    );
    assert!(
        rest["message"].as_str().unwrap().contains(&expected),
        "{rest}: expected {expected}"
    );
    // The good row is still built.
    assert!(report["clips"].as_u64().unwrap() >= 2, "{report:#}");
}

#[test]
fn a_head_trim_with_the_largest_end_frame_clamps_instead_of_wrapping() {
    let row = IndexRow {
        source_path: "./pose_data/MPI_HDM05/dg/HDM_dg_01-01_01_120_poses.npy".into(),
        start_frame: 0,
        end_frame: i64::MAX,
        new_name: "000001.npy".into(),
        line: 2,
    };
    let options = IndexOptions {
        fps: 20.0,
        humanml3d_cuts: true,
    };
    let (start, end) = row_range(&row, &options);
    assert_eq!(
        start,
        Time::Frame {
            frame: 60,
            fps: 20.0
        }
    );
    assert_eq!(
        end,
        Time::Frame {
            frame: i64::MAX,
            fps: 20.0
        }
    );
}

/// A version-1 `.npy` file with this header and these value bytes.
fn npy_file(descr: &str, fortran: bool, shape: &str, data: &[u8]) -> Vec<u8> {
    let fortran = if fortran { "True" } else { "False" };
    let mut header =
        format!("{{'descr': '{descr}', 'fortran_order': {fortran}, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

/// The real 012314 clip's (170, 22, 3) float32 values.
fn real_values() -> Vec<f32> {
    let bytes =
        std::fs::read(common::repo().join("fixtures/humanml3d-joints/new_joints/012314.npy"))
            .unwrap();
    npyz::NpyFile::new(&bytes[..])
        .unwrap()
        .into_vec::<f32>()
        .unwrap()
}

fn le(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

#[test]
fn damaged_joint_arrays_cost_one_reject_each_under_a_1_gb_address_space() {
    let (_dir, config) = fixture_copy();
    let root = config.parent().unwrap();
    let dir = root.join("new_joints");
    let good = std::fs::read(dir.join("012314.npy")).unwrap();
    let values = real_values();
    let with = |frame: usize, v: f32| {
        let mut copy = values.clone();
        copy[frame * 66 + 4] = v;
        le(&copy)
    };
    let be: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    let cases: Vec<(&str, Vec<u8>, Option<&str>)> = vec![
        ("header-cut", good[..30].to_vec(), Some("not a NumPy")),
        (
            "data-cut",
            good[..good.len() / 2].to_vec(),
            Some("promises"),
        ),
        (
            "int32",
            npy_file("<i4", false, "(170, 22, 3)", &le(&values)),
            Some("float32"),
        ),
        (
            "joints21",
            npy_file("<f4", false, "(170, 21, 3)", &le(&values[..170 * 63])),
            Some("21 joints"),
        ),
        (
            "flat22",
            npy_file("<f4", false, "(170, 22)", &le(&values[..170 * 22])),
            Some("shape"),
        ),
        (
            "four-d",
            npy_file("<f4", false, "(170, 22, 3, 1)", &le(&values)),
            Some("shape"),
        ),
        (
            "no-frames",
            npy_file("<f4", false, "(0, 22, 3)", &[]),
            Some("no frames"),
        ),
        (
            "nan",
            npy_file("<f4", false, "(170, 22, 3)", &with(3, f32::NAN)),
            Some("frame 3"),
        ),
        (
            "inf",
            npy_file("<f4", false, "(170, 22, 3)", &with(4, f32::INFINITY)),
            Some("frame 4"),
        ),
        (
            "huge",
            npy_file("<f4", false, "(170, 22, 3)", &with(5, 1e30)),
            Some("frame 5"),
        ),
        (
            "claims-1e12",
            npy_file("<f4", false, "(1000000000000, 22, 3)", &le(&values)),
            Some("promises"),
        ),
        (
            "fortran",
            npy_file("<f4", true, "(170, 22, 3)", &le(&values)),
            Some("Fortran"),
        ),
        // Readable: big-endian values are the same numbers, and one frame is a capture.
        (
            "big-endian",
            npy_file(">f4", false, "(170, 22, 3)", &be),
            None,
        ),
        (
            "one-frame",
            npy_file("<f4", false, "(1, 22, 3)", &le(&values[..66])),
            None,
        ),
    ];
    for (name, bytes, _) in &cases {
        std::fs::write(dir.join(format!("{name}.npy")), bytes).unwrap();
        std::fs::write(
            dir.join(format!("{name}.json")),
            r#"{"action": "tennis serve", "text": "a person serves"}"#,
        )
        .unwrap();
    }
    build_in_1_gib(&config);
    let dataset = root.join("out/hml3d-joints");
    let rejects: Vec<serde_json::Value> = lines(&dataset.join("rejects.jsonl"))
        .iter()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    for (name, _, why) in &cases {
        let file = format!("new_joints/{name}.npy");
        let found: Vec<&serde_json::Value> = rejects
            .iter()
            .filter(|r| r["file"].as_str().is_some_and(|f| f.ends_with(&file)))
            .collect();
        match why {
            Some(why) => {
                assert_eq!(found.len(), 1, "{name}: {rejects:?}");
                let message = found[0]["message"].as_str().unwrap();
                assert!(message.contains(why), "{name}: {message}");
            }
            None => assert!(found.is_empty(), "{name}: {found:?}"),
        }
    }
    assert_eq!(rejects.len(), 12, "{rejects:?}");
    // The big-endian copy is the real clip: its row holds the same positions as the original's.
    let ids = common::pyarrow_rows(&dataset.join("data"), "clip_id");
    assert!(ids.iter().any(|i| i.contains("big-endian")), "{ids:?}");
}

mod fuzz {
    use super::*;
    use motionforge::motion::npy::read_joint_positions;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 1000, ..ProptestConfig::default() })]

        /// Any bytes (a real file with bytes changed, cut or appended): an error or an array
        /// whose every value is finite and within range, never a panic or a huge allocation.
        #[test]
        fn the_joint_array_reader_never_panics_or_trusts_a_header(
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..12),
            cut in proptest::option::of(any::<prop::sample::Index>()),
            extra in proptest::collection::vec(any::<u8>(), 0..64),
            shape in prop_oneof![
                Just("(170, 22, 3)".to_string()),
                (0u64..u64::MAX, 0u64..100, 0u64..5).prop_map(|(a, b, c)| format!("({a}, {b}, {c})")),
                (0u64..u64::MAX, 0u64..200).prop_map(|(a, b)| format!("({a}, {b})")),
                Just("()".to_string()),
            ],
            descr in prop::sample::select(vec!["<f4", "<f8", ">f4", ">f8", "<i4", "|u1", "<f2", "<c8"]),
        ) {
            let values = real_values();
            let mut bytes = npy_file(descr, false, &shape, &le(&values));
            for (at, b) in edits {
                let i = at.index(bytes.len());
                bytes[i] = b;
            }
            if let Some(at) = cut {
                bytes.truncate(at.index(bytes.len() + 1));
            }
            bytes.extend(extra);
            if let Ok(array) = read_joint_positions(&bytes) {
                prop_assert_eq!(array.positions.len(), array.frames * array.joints);
                prop_assert!(array.positions.iter().all(|p| p.is_finite() && p.abs().max_element() <= 1e6));
            }
        }
    }
}
