//! Skeleton profiles, forward kinematics, resampling and the CLI around them, on real data.
use crate::common;

use std::process::Command;

use common::project::{ConfigSpec, Source};
use common::*;
use glam::{DQuat, DVec3, EulerRot};
use motionforge::motion::*;

#[test]
fn smpl_22_pairs_match_humanml3d_swap_chains() {
    let spec = ProfileSpec::bundled("smpl-22").unwrap();
    let skeleton = spec
        .skeleton()
        .expect("smpl-22 lists its joints and parents");
    let profile = spec.bind(&skeleton).unwrap();
    // HumanML3D's swap_left_right chains (raw_pose_processing.ipynb).
    let right = [2, 5, 8, 11, 14, 17, 19, 21];
    let left = [1, 4, 7, 10, 13, 16, 18, 20];
    for (l, r) in left.iter().zip(right) {
        assert_eq!(profile.swap[*l], r);
        assert_eq!(profile.swap[r], *l);
    }
    for centre in [0, 3, 6, 9, 12, 15] {
        assert_eq!(profile.swap[centre], centre);
    }
    // SINC's part map (sinc/info/joints.py: smpl_bps).
    let part = |p: BodyPart| profile.joints_of(p).collect::<Vec<_>>();
    assert_eq!(part(BodyPart::Global), vec![0]);
    assert_eq!(part(BodyPart::Torso), vec![3, 6, 9, 12, 15]);
    assert_eq!(part(BodyPart::LeftArm), vec![13, 16, 18, 20]);
    assert_eq!(part(BodyPart::RightLeg), vec![2, 5, 8, 11]);
}

#[test]
fn bundled_profiles_bind_to_their_real_skeletons_with_every_joint_in_a_part() {
    for (profile, path) in [
        ("bandai-namco", bandai1("walk", "normal")),
        ("bandai-namco", bandai2("wave-left-hand", 1)),
        ("cmu", shared_data().join("cmu/01_01.bvh")),
    ] {
        let bvh = load(&path);
        let bound = ProfileSpec::bundled(profile)
            .unwrap()
            .bind(&bvh.skeleton)
            .unwrap();
        for (j, part) in bound.part_of.iter().enumerate() {
            assert!(
                part.is_some(),
                "{profile}: joint {} has no body part",
                bvh.skeleton.joints[j].name
            );
        }
        for (j, &s) in bound.swap.iter().enumerate() {
            // Partners sit in mirrored parts.
            assert_eq!(bound.part_of[s], bound.part_of[j].map(BodyPart::mirrored));
        }
        assert!(
            bound.reflections.iter().all(Option::is_some),
            "{profile} is calibrated for every joint"
        );
    }
}

#[test]
fn profile_pairs_can_be_overridden_and_bad_pairs_are_refused() {
    let bvh = load(&bandai1("walk", "normal"));
    let mut spec = ProfileSpec::bundled("bandai-namco").unwrap();
    // Pairing a hand with a foot breaks the mirrored hierarchy: refused with the joint names.
    spec.pairs.insert("Hand_L".into(), "Foot_R".into());
    let err = spec.bind(&bvh.skeleton).unwrap_err();
    assert!(
        matches!(
            err,
            motionforge::motion::profile::ProfileError::Asymmetric { .. }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("not symmetric"), "{err}");
}

#[test]
fn forward_kinematics_matches_hand_computed_chain() {
    // First frame of CMU 01_01 is an added T-pose with a few known root values; compute the left
    // upper leg by hand from the channel values and offsets.
    let bvh = load(&shared_data().join("cmu/01_01.bvh"));
    let sk = &bvh.skeleton;
    let pose = bvh.motion.forward_kinematics();
    let hips = sk.index_of("Hips").unwrap();
    let lhip = sk.index_of("LHipJoint").unwrap();
    let lup = sk.index_of("LeftUpLeg").unwrap();
    let frame = 1;
    let text = std::fs::read_to_string(shared_data().join("cmu/01_01.bvh")).unwrap();
    let line = text
        .lines()
        .skip_while(|l| !l.starts_with("Frame Time"))
        .nth(frame + 1)
        .unwrap();
    let v: Vec<f64> = line
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    let zyx = |a: &[f64]| {
        DQuat::from_euler(
            EulerRot::ZYX,
            a[0].to_radians(),
            a[1].to_radians(),
            a[2].to_radians(),
        )
    };
    let root_t = DVec3::new(v[0], v[1], v[2]);
    let root_r = zyx(&v[3..6]);
    let lhip_r = zyx(&v[6..9]);
    let expected =
        root_t + root_r * sk.joints[lhip].offset + root_r * lhip_r * sk.joints[lup].offset;
    assert!((pose.position(frame, hips) - root_t).length() < 1e-12);
    assert!((pose.position(frame, lup) - expected).length() < 1e-9);
}

#[test]
fn resampling_cmu_from_120_to_30_fps_keeps_every_fourth_frame() {
    let bvh = load(&shared_data().join("cmu/01_01.bvh"));
    assert_eq!(bvh.header_fps, 120.0);
    let n = bvh.motion.num_frames();
    let at30 = bvh.motion.resample(30.0);
    assert_eq!(at30.fps, 30.0);
    assert_eq!(at30.num_frames(), (n - 1) / 4 + 1);
    for f in [0, 1, 100, at30.num_frames() - 1] {
        for j in 0..bvh.motion.num_joints() {
            assert!(
                at30.rotation(f, j)
                    .abs_diff_eq(bvh.motion.rotation(4 * f, j), 1e-12)
            );
            assert!(
                at30.translation(f, j)
                    .abs_diff_eq(bvh.motion.translation(4 * f, j), 1e-12)
            );
        }
    }
}

#[test]
fn resampling_interpolates_between_frames_with_slerp_and_lerp() {
    let bvh = load(&bandai1("walk", "normal"));
    let m = &bvh.motion;
    // 30 -> 20 fps: output frame 1 sits at source frame 1.5.
    let at20 = m.resample(20.0);
    assert_eq!(
        at20.num_frames(),
        ((m.num_frames() - 1) as f64 * 20.0 / 30.0).floor() as usize + 1
    );
    for j in 0..m.num_joints() {
        let (a, b) = (m.rotation(1, j), m.rotation(2, j));
        let mid = at20.rotation(1, j);
        // Halfway by angle to both neighbours.
        assert!((mid.angle_between(a) - mid.angle_between(b)).abs() < 1e-9);
        assert!((a.angle_between(b) - 2.0 * mid.angle_between(a)).abs() < 1e-9);
        let t = at20.translation(1, j);
        assert!(t.abs_diff_eq((m.translation(1, j) + m.translation(2, j)) / 2.0, 1e-9));
    }
}

#[test]
fn mirror_text_command_mirrors_lines_from_stdin() {
    use std::io::Write;
    let mut child = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .arg("mirror-text")
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(b"a person waves with the left hand\nwave-left-hand\nturn counter clockwise\nRight foot forward\n")
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    assert_eq!(
        String::from_utf8(out.stdout).unwrap(),
        "a person waves with the right hand\nwave-right-hand\nturn clockwise\nLeft foot forward\n"
    );
}

#[test]
fn calibrate_mirror_command_reproduces_the_bundled_profile() {
    let out = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["calibrate-mirror", "--profile", "cmu"])
        .arg(shared_data().join("cmu/01_01.bvh"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let printed = String::from_utf8(out.stdout).unwrap();
    let bundled = std::fs::read_to_string(repo().join("schemas/skeletons/cmu.toml")).unwrap();
    let table = bundled.split("[reflections]").nth(1).unwrap().trim();
    assert_eq!(printed.split("[reflections]").nth(1).unwrap().trim(), table);
}

#[test]
fn every_command_has_help() {
    for cmd in [
        vec!["--help"],
        vec!["build", "--help"],
        vec!["mirror-text", "--help"],
        vec!["calibrate-mirror", "--help"],
        vec!["schema", "--help"],
        vec!["bench", "--help"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .args(&cmd)
            .output()
            .unwrap();
        assert!(out.status.success(), "{cmd:?}");
        let text = String::from_utf8(out.stdout).unwrap();
        assert!(
            text.len() > 100 && text.contains("Usage"),
            "{cmd:?}: {text}"
        );
    }
}

#[test]
fn a_config_error_exits_with_code_2_and_names_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("bad.toml");
    ConfigSpec::new("x")
        .output("o")
        .fps(0)
        .source(Source::new("s", "cmu", &["*.bvh"]).filename_labels("{a}", "{a}", "{a}"))
        .write(&cfg);
    let out = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["build", "--config"])
        .arg(&cfg)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("dataset.fps"), "{err}");
}

#[test]
fn derived_features_on_a_real_walk_look_like_walking() {
    use motionforge::features::{FeatureConfig, features};
    let bvh = load(&bandai1("walk", "normal"));
    let profile = ProfileSpec::bundled("bandai-namco")
        .unwrap()
        .bind(&bvh.skeleton)
        .unwrap();
    let n = bvh.skeleton.len();
    let positions: Vec<f32> =
        motionforge::motion::canonical::dataset_positions(&bvh.motion, &profile)
            .iter()
            .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect();
    let rotations: Vec<f32> = bvh
        .motion
        .rotations
        .iter()
        .flat_map(|q| [q.x as f32, q.y as f32, q.z as f32, q.w as f32])
        .collect();
    let f = features(
        &positions,
        &rotations,
        n,
        30.0,
        &profile,
        &FeatureConfig {
            rotations_6d: true,
            velocities: true,
            ..FeatureConfig::default()
        },
    );
    let future = f.future_root.unwrap();
    let frames = bvh.motion.num_frames();
    // Mid-walk, the root is about a second's walk ahead 30 frames later, and barely to the side.
    let mid = frames / 2;
    let (right, forward) = (future[mid * 9 + 6], future[mid * 9 + 7]);
    assert!(
        forward > 0.8 && forward < 2.5 && right.abs() < 0.3 * forward,
        "+30 frames: right {right}, forward {forward}"
    );
    // Each foot is planted part of the time and moving part of the time.
    let contacts = f.foot_contacts.unwrap();
    for foot in 0..4 {
        let share = (0..frames).filter(|&k| contacts[k * 4 + foot]).count() as f64 / frames as f64;
        assert!(
            share > 0.2 && share < 0.9,
            "foot {foot} in contact {share:.2} of the time"
        );
    }
    // 6D rotations are the first two columns of rotation matrices: unit and orthogonal.
    let r6 = f.rotations_6d.unwrap();
    for c in r6.chunks_exact(6).take(500) {
        let (a, b) = (
            glam::Vec3::new(c[0], c[1], c[2]),
            glam::Vec3::new(c[3], c[4], c[5]),
        );
        assert!(
            (a.length() - 1.0).abs() < 1e-4
                && (b.length() - 1.0).abs() < 1e-4
                && a.dot(b).abs() < 1e-4
        );
    }
}
