//! HumanML3D's representation against HumanML3D's own files (`../shared/data/humanml3d`): the
//! reference skeleton, the shipped pair 012314 (`new_joint_vecs` and `new_joints`), the raw
//! 52-joint array of clip 000021 and MoMask's example 000612.

use crate::common;

use std::path::PathBuf;

use glam::DVec3;
use motionforge::humanml3d::{
    DIM, NUM_JOINTS, PARENTS, REFERENCE_LENGTHS, positions_from_vectors, recover_from_ric, vectors,
};
use motionforge::motion::ProfileSpec;
use motionforge::motion::ik::{PositionLayout, motion_from_positions};
use motionforge::motion::npy::{JointArray, NpyError, read_joint_positions};

fn hml3d(path: &str) -> PathBuf {
    common::shared_data().join("humanml3d").join(path)
}

fn joints(path: &str) -> JointArray {
    let bytes = std::fs::read(hml3d(path)).unwrap();
    read_joint_positions(&bytes).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// A `.npy` of shape (rows, 263), float32 or float64, as flat f32 values.
fn vector_file(path: &str) -> Vec<f32> {
    let bytes = std::fs::read(hml3d(path)).unwrap();
    let file = npyz::NpyFile::new(&bytes[..]).unwrap();
    assert_eq!(file.shape()[1], DIM as u64, "{path}");
    match file.dtype().num_bytes() {
        Some(4) => file.into_vec::<f32>().unwrap(),
        _ => file
            .into_vec::<f64>()
            .unwrap()
            .into_iter()
            .map(|v| v as f32)
            .collect(),
    }
}

/// The body joints (the first 22) of every frame.
fn body(array: &JointArray) -> Vec<DVec3> {
    array
        .positions
        .chunks_exact(array.joints)
        .flat_map(|f| f[..NUM_JOINTS].iter().copied())
        .collect()
}

/// Largest absolute difference, and where (row, column).
fn worst(a: &[f32], b: &[f32], width: usize) -> (f64, usize, usize) {
    assert_eq!(a.len(), b.len());
    let mut out = (0.0, 0, 0);
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        let d = f64::from((x - y).abs());
        if d > out.0 {
            out = (d, i / width, i % width);
        }
    }
    out
}

#[test]
fn reference_lengths_are_frame_zero_of_clip_000021() {
    let raw = joints("joints/000021.npy");
    assert_eq!((raw.frames, raw.joints), (180, 52));
    for (j, parent) in PARENTS.iter().enumerate() {
        let Some(parent) = parent else { continue };
        let length = (raw.positions[j] - raw.positions[*parent]).length();
        assert!(
            (length - REFERENCE_LENGTHS[j]).abs() < 1e-7,
            "joint {j}: {length} in the file, {} in the code",
            REFERENCE_LENGTHS[j]
        );
    }
}

#[test]
fn positions_recovered_from_the_shipped_vectors_match_the_shipped_new_joints() {
    let vecs = vector_file("HumanML3D/new_joint_vecs/012314.npy");
    let shipped = joints("HumanML3D/new_joints/012314.npy");
    let rows = vecs.len() / DIM;
    assert_eq!(shipped.frames, rows, "new_joints has one position per row");
    let recovered = recover_from_ric(&vecs);
    let ours: Vec<f32> = recovered
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let theirs: Vec<f32> = shipped
        .positions
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let (d, row, col) = worst(&ours, &theirs, NUM_JOINTS * 3);
    println!("recovery: worst {d:e} at frame {row}, value {col}");
    assert!(d < 1e-5, "{d} at frame {row}, value {col}");
}

#[test]
fn vectors_computed_from_positions_match_the_shipped_vectors() {
    // HumanML3D ships 012314's vectors (rows = frames - 1) and positions recovered from them,
    // which stop one frame short; the last frame is recovered from the last row's velocities,
    // so the vectors are recomputed from every frame they were made from.
    let shipped = vector_file("HumanML3D/new_joint_vecs/012314.npy");
    let positions = positions_from_vectors(&shipped);
    assert_eq!(positions.len() / NUM_JOINTS, shipped.len() / DIM + 1);
    let ours = vectors(&positions).unwrap();
    let (d, row, col) = worst(&ours, &shipped, DIM);
    println!("012314: worst {d:e} at row {row}, column {col}");
    assert!(d < 1e-4, "{d} at row {row}, column {col}");
}

#[test]
fn the_raw_52_joint_array_of_clip_000021_gives_its_vectors() {
    let raw = joints("joints/000021.npy");
    let positions = body(&raw);
    let v = vectors(&positions).unwrap();
    assert_eq!(v.len(), (raw.frames - 1) * DIM);
    assert!(v.iter().all(|x| x.is_finite()));
    // The reference skeleton is already at the reference lengths: its own positions come back
    // (on the floor, facing +z, first root over the origin), bone for bone.
    let back = positions_from_vectors(&v);
    for (t, frame) in back.chunks_exact(NUM_JOINTS).enumerate() {
        for (j, parent) in PARENTS.iter().enumerate() {
            let Some(parent) = parent else { continue };
            let length = (frame[j] - frame[*parent]).length();
            assert!(
                (length - REFERENCE_LENGTHS[j]).abs() < 1e-5,
                "frame {t}, joint {j}: {length}"
            );
        }
    }
}

#[test]
fn momask_example_000612_turns_past_180_degrees_and_keeps_the_reference_quirk() {
    let shipped = vector_file("momask-example/000612.npy");
    // Row 142 is where the smoothed heading crosses 180 degrees: the reference takes `arcsin` of
    // a rotation whose quaternion flipped hemisphere, so the row's rotation velocity has the
    // wrong sign (its neighbours turn the other way).
    let glitch = 142 * DIM;
    assert!(
        shipped[glitch] * shipped[glitch - DIM] < 0.0
            && shipped[glitch] * shipped[glitch + DIM] < 0.0
    );
    // Positions from the true turn (the sign undone); the vectors made from them must carry the
    // glitch again, as the evaluators saw it.
    let mut true_turn = shipped.clone();
    true_turn[glitch] = -true_turn[glitch];
    let positions = positions_from_vectors(&true_turn);
    let ours = vectors(&positions).unwrap();
    let (d, row, col) = worst(&ours, &shipped, DIM);
    println!("000612: worst {d:e} at row {row}, column {col}");
    assert!(d < 1e-4, "{d} at row {row}, column {col}");
}

#[test]
fn damaged_arrays_are_refused_with_what_was_expected() {
    let bytes = std::fs::read(hml3d("joints/000021.npy")).unwrap();
    // Cut inside the values: the header's shape promises more than the file holds.
    let cut = &bytes[..bytes.len() / 2];
    assert!(matches!(
        read_joint_positions(cut),
        Err(NpyError::Truncated { .. })
    ));
    assert!(matches!(
        read_joint_positions(b"not numpy"),
        Err(NpyError::Header(_))
    ));
    // A NaN in frame 3, joint 5.
    let header = bytes.len() - 180 * 52 * 3 * 8;
    let mut poisoned = bytes.clone();
    let at = header + ((3 * 52 + 5) * 3) * 8;
    poisoned[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    let err = read_joint_positions(&poisoned).unwrap_err();
    assert!(
        matches!(err, NpyError::NotFinite { frame: 3, joint: 5 }),
        "{err:?}"
    );
    assert!(err.to_string().contains("frame 3, joint 5"));
}

/// Inverse kinematics of a HumanML3D array on the `smpl-22` profile, and how close forward
/// kinematics of the result comes back.
fn ik_of(positions: &[DVec3]) -> (motionforge::motion::Motion, motionforge::motion::ik::Fit) {
    let spec = ProfileSpec::bundled("smpl-22").unwrap();
    let layout = PositionLayout::from_profile(&spec).unwrap();
    motion_from_positions(&layout, positions, 20.0, 0.05).unwrap()
}

#[test]
fn joint_arrays_become_motions_whose_forward_kinematics_gives_them_back() {
    for file in ["joints/000021.npy", "HumanML3D/new_joints/012314.npy"] {
        let array = joints(file);
        let positions = body(&array);
        let (motion, fit) = ik_of(&positions);
        println!("{file}: {fit:?}");
        assert_eq!(motion.num_frames(), array.frames);
        assert!(fit.max_residual < 1e-4, "{file}: {fit:?}");
        assert!(fit.max_length_change < 1e-3, "{file}: {fit:?}");
        // The rotations are not a relabelling of positions: a bone's rest offset has the clip's
        // own mean length.
        let skeleton = &motion.skeleton;
        let knee = skeleton.index_of("left_knee").unwrap();
        let hip = skeleton.index_of("left_hip").unwrap();
        let length = (positions[knee] - positions[hip]).length();
        assert!((skeleton.joints[knee].offset.length() - length).abs() < 1e-3);
    }
}

#[test]
fn a_joint_array_whose_bones_stretch_is_refused_naming_the_frame_and_bone() {
    let mut positions = body(&joints("joints/000021.npy"));
    // Frame 50: the left wrist 10 cm further from the elbow than anywhere else.
    let (elbow, wrist) = (18, 20);
    let d = positions[50 * NUM_JOINTS + wrist] - positions[50 * NUM_JOINTS + elbow];
    positions[50 * NUM_JOINTS + wrist] += d.normalize() * 0.1;
    let spec = ProfileSpec::bundled("smpl-22").unwrap();
    let layout = PositionLayout::from_profile(&spec).unwrap();
    let err = motion_from_positions(&layout, &positions, 20.0, 0.05).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("frame 50") && text.contains("left_wrist"),
        "{text}"
    );
}

#[test]
fn a_motion_from_joint_positions_mirrors_onto_the_reflected_positions() {
    use motionforge::motion::{MirrorPlan, OffsetPolicy};
    let positions = body(&joints("joints/000021.npy"));
    let (motion, _) = ik_of(&positions);
    let spec = ProfileSpec::bundled("smpl-22").unwrap();
    let profile = spec.bind(&motion.skeleton).unwrap();
    let plan = MirrorPlan::from_profile(&motion.skeleton, &profile).unwrap();
    // The mirror image: x negated (the midline plane of a y-up, z-forward capture), left and
    // right joints swapped.
    let worst = |policy: OffsetPolicy| -> f64 {
        let mirrored = plan.mirror(&motion, policy).forward_kinematics();
        let mut worst: f64 = 0.0;
        for (t, frame) in positions.chunks_exact(NUM_JOINTS).enumerate() {
            for j in 0..NUM_JOINTS {
                let p = frame[profile.swap[j]];
                let expected = DVec3::new(-p.x, p.y, p.z);
                worst = worst.max(mirrored.positions[t * NUM_JOINTS + j].distance(expected));
            }
        }
        worst
    };
    // On the mirrored skeleton the rotations mirror exactly.
    let exact = worst(OffsetPolicy::Mirror);
    // On the clip's own skeleton (what a dataset keeps) the difference is the body's own
    // asymmetry: SMPL's left and right hips, collars and limbs differ by millimetres, and the
    // hands end up within a few centimetres of the mirror image.
    let kept = worst(OffsetPolicy::Keep);
    println!("mirror: {exact:e} m on the mirrored skeleton, {kept:e} m on the clip's own");
    assert!(exact < 1e-4, "{exact}");
    assert!(kept < 0.04, "{kept}");
}
