//! AMASS captures (issue 32): `.npz` files of SMPL-H / SMPL-X pose parameters read with a body
//! model, checked against an independent NumPy implementation of the reference maths (smplx's
//! `lbs` joints, in float32 as smplx computes), and built end to end through the binary.
//!
//! AMASS files and SMPL body models cannot be redistributed, so the tests write their own with
//! NumPy (`GENERATE`): body models with the real key names and shapes (SMPL-H: 6,890 vertices,
//! 52 joints and its kinematic tree; SMPL-X: 10,475 vertices, 55 joints), seeded random values of
//! realistic size (vertices within a few centimetres of their joint, `J_regressor` rows
//! normalised, shape directions of a centimetre per unit), and AMASS-layout sequences.
//!
//! The poses are real motion: the raw SMPL-H joints of HumanML3D clip 000021 (an AMASS capture,
//! `../shared/data/humanml3d/joints/000021.npy`) turned into local rotations of the 22 body joints
//! by the project's own inverse kinematics (`motion::ik`), with the model's rest joints taken from
//! that fit's skeleton, and the root turned from y up to AMASS's z up. The shared data has no
//! finger, jaw or eye motion: those joints take half the rotation of a body joint in the same
//! frame (so they move with the capture's timing), which exercises every joint of the chain.
use crate::common;
use common::project::{ConfigSpec, Source};

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::{DQuat, DVec3};
use motionforge::amass::{self, Family};
use motionforge::motion::ProfileSpec;
use motionforge::motion::ik::{PositionLayout, motion_from_positions};
use motionforge::motion::npy::read_joint_positions;

/// The NumPy side: body models, AMASS sequences, and the reference joints, from a JSON spec.
const GENERATE: &str = r#"
import json, sys, numpy as np
spec = json.load(open(sys.argv[1]))
BODY = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19]
def hand(wrist, first):
    out = []
    for finger in range(5):
        base = first + 3 * finger
        out += [wrist, base, base + 1]
    return out
PARENTS = {
    'smplh': BODY + hand(20, 22) + hand(21, 37),
    'smplx': BODY + [15, 15, 15] + hand(20, 25) + hand(21, 40),
}
VERTICES = {'smplh': 6890, 'smplx': 10475}
FACES = {'smplh': 13776, 'smplx': 20908}
BETAS = {'smplh': 16, 'smplx': 20}

def make_model(m):
    fam = m['family']
    rng = np.random.default_rng(m['seed'])
    rest = np.fromfile(m['rest'], dtype='<f8').reshape(-1, 3)
    J, V = len(PARENTS[fam]), VERTICES[fam]
    assert rest.shape[0] == J
    owner = np.arange(V) % J
    # Each vertex a few centimetres from its joint; each joint the weighted mean of its vertices.
    v_template = rest[owner] + rng.normal(0.0, 0.03, (V, 3))
    regressor = np.zeros((J, V))
    for j in range(J):
        w = rng.uniform(0.1, 1.0, (owner == j).sum())
        regressor[j, owner == j] = w / w.sum()
    B = BETAS[fam]
    shapedirs = rng.normal(0.0, 0.01, (J, 3, B))[owner] + rng.normal(0.0, 0.002, (V, 3, B))
    weights = np.zeros((V, J)); weights[np.arange(V), owner] = 1.0
    if fam == 'smplh':
        root = 4294967295
        kintree = np.array([[root] + PARENTS[fam][1:], list(range(J))], dtype=np.int64)
        dtype = np.float64
    else:
        kintree = np.array([PARENTS[fam], list(range(J))], dtype=np.int32)
        dtype = np.float32
    arrays = dict(
        v_template=v_template.astype(dtype),
        shapedirs=shapedirs.astype(dtype),
        posedirs=np.zeros((V, 3, (J - 1) * 9), dtype=np.float32),
        J_regressor=regressor.astype(dtype),
        kintree_table=kintree,
        weights=weights.astype(dtype),
        f=rng.integers(0, V, (FACES[fam], 3)).astype(np.uint32),
    )
    for key in m.get('drop', []):
        del arrays[key]
    np.savez_compressed(m['path'], **arrays)

def make_sequence(s):
    fam = s['family']
    width = 156 if fam == 'smplh' else 165
    poses = np.fromfile(s['poses'], dtype='<f8').reshape(-1, width)
    trans = np.fromfile(s['trans'], dtype='<f8').reshape(-1, 3)
    arrays = dict(poses=poses, trans=trans, betas=np.array(s['betas'], dtype=np.float64))
    g = s['gender']
    arrays['gender'] = np.array(g.encode()) if s.get('gender_bytes') else np.array(g)
    if fam == 'smplh':
        arrays['mocap_framerate'] = np.array(s['fps'])
        arrays['dmpls'] = np.zeros((len(poses), 8))
    else:
        arrays['mocap_frame_rate'] = np.array(s['fps'])
        arrays['surface_model_type'] = np.array('smplx')
        arrays['num_betas'] = np.array(len(s['betas']))
        arrays['root_orient'] = poses[:, :3]
        arrays['pose_body'] = poses[:, 3:66]
        arrays['pose_jaw'] = poses[:, 66:69]
        arrays['pose_eye'] = poses[:, 69:75]
        arrays['pose_hand'] = poses[:, 75:]
    for key in s.get('drop', []):
        del arrays[key]
    for key, value in s.get('replace', {}).items():
        arrays[key] = np.array(value)
    if s.get('nan_at'):
        f, i = s['nan_at']
        arrays['poses'] = arrays['poses'].copy()
        arrays['poses'][f, i] = np.nan
    np.savez(s['path'], **arrays)
    if s.get('truncate'):
        data = open(s['path'], 'rb').read()
        open(s['path'], 'wb').write(data[: len(data) // 2])

# The reference: smplx's lbs (blend_shapes, vertices2joints, batch_rodrigues,
# batch_rigid_transform) for the joints, in float32, plus trans; frames as HumanML3D takes them.
def batch_rodrigues(rot_vecs):
    angle = np.linalg.norm(rot_vecs + 1e-8, axis=1, keepdims=True)
    rot_dir = rot_vecs / angle
    cos = np.cos(angle)[:, :, None]
    sin = np.sin(angle)[:, :, None]
    rx, ry, rz = np.split(rot_dir, 3, axis=1)
    zeros = np.zeros_like(rx)
    K = np.concatenate([zeros, -rz, ry, rz, zeros, -rx, -ry, rx, zeros], axis=1).reshape(-1, 3, 3)
    ident = np.eye(3, dtype=rot_vecs.dtype)[None]
    return (ident + sin * K + (1 - cos) * np.matmul(K, K)).astype(np.float32)

def joints_of(seq, model, nb, humanml3d):
    """(frames, joints, 3) float32 joints and the frames' stride and effective rate."""
    f32 = np.float32
    betas = seq['betas'][:nb].astype(f32)
    v_shaped = model['v_template'].astype(f32) + np.einsum('l,mkl->mk', betas, model['shapedirs'][:, :, :nb].astype(f32))
    J = np.einsum('ik,ji->jk', v_shaped, model['J_regressor'].astype(f32))
    parents = model['kintree_table'][0].astype(np.int64)
    fps = float(seq['mocap_framerate'] if 'mocap_framerate' in seq.files else seq['mocap_frame_rate'])
    step = int(fps / 20) if humanml3d else 1
    frames = list(range(0, seq['poses'].shape[0], step))
    poses = seq['poses'][frames].astype(f32)
    trans = seq['trans'][frames].astype(f32)
    n = J.shape[0]
    rot = batch_rodrigues(poses.reshape(-1, 3)).reshape(len(frames), n, 3, 3)
    rel = J.copy()
    rel[1:] -= J[parents[1:]]
    out = np.zeros((len(frames), n, 3), dtype=f32)
    for t in range(len(frames)):
        chain = [None] * n
        for j in range(n):
            m = np.eye(4, dtype=f32)
            m[:3, :3] = rot[t, j]
            m[:3, 3] = rel[j]
            chain[j] = m if j == 0 else np.matmul(chain[parents[j]], m)
            out[t, j] = chain[j][:3, 3]
    out += trans[:, None, :]
    return out, step, fps / step

def reference(r):
    seq = np.load(r['sequence'])
    out, step, effective = joints_of(seq, np.load(r['model']), r['num_betas'], r['humanml3d'])
    np.save(r['out'], out)
    print(json.dumps({'out': r['out'], 'frames': len(out), 'stride': step, 'effective': effective}))

# HumanML3D's raw_pose_processing: amass_to_pose (its gender test, 10 betas, the stride), the
# y/z swap, then the segment step (dataset head trims at 20 fps, the slice, x negated) and
# swap_left_right for the mirror; the 22 body joints kept, as the export writes them.
def swap_left_right(data):
    data = data.copy()
    data[..., 0] *= -1
    right_chain = [2, 5, 8, 11, 14, 17, 19, 21]
    left_chain = [1, 4, 7, 10, 13, 16, 18, 20]
    tmp = data[:, right_chain]
    data[:, right_chain] = data[:, left_chain]
    data[:, left_chain] = tmp
    return data

def notebook(r):
    bdata = np.load(r['sequence'], allow_pickle=True)
    gender = 'male' if bdata['gender'] == 'male' else 'female'
    model = np.load(f"{r['models']}/smplh/{gender}/model.npz")
    joints, _, _ = joints_of(bdata, model, 10, True)
    trans_matrix = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    data = np.dot(joints, trans_matrix)
    fps = 20
    path = r['source_path']
    if 'Eyes_Japan_Dataset' in path:
        data = data[3 * fps:]
    if 'MPI_HDM05' in path:
        data = data[3 * fps:]
    if 'TotalCapture' in path:
        data = data[1 * fps:]
    if 'MPI_Limits' in path:
        data = data[1 * fps:]
    if 'Transitions_mocap' in path:
        data = data[int(0.5 * fps):]
    data = data[r['start']:r['end']]
    data[..., 0] *= -1
    np.save(r['out'], data[:, :22].astype(np.float32))
    np.save(r['out_m'], swap_left_right(data)[:, :22].astype(np.float32))
    print(json.dumps({'out': r['out'], 'gender': gender, 'frames': len(data)}))

for m in spec.get('models', []):
    make_model(m)
for s in spec.get('sequences', []):
    make_sequence(s)
for r in spec.get('references', []):
    reference(r)
for r in spec.get('notebook', []):
    notebook(r)
"#;

/// The real motion: clip 000021's body joints, fitted by the project's IK.
struct RealMotion {
    /// Rest position of each body joint (the fit's skeleton, root placed as SMPL's).
    rest: Vec<DVec3>,
    /// Local rotations per frame of the 22 body joints, root turned to z up.
    rotations: Vec<[DQuat; 22]>,
    /// Root positions per frame, z up.
    root: Vec<DVec3>,
}

/// [`real_motion`] resampled to `fps` by the project's own resampling (slerp of rotations).
fn real_motion_at(fps: f64) -> RealMotion {
    real_motion_resampled(Some(fps))
}

fn real_motion() -> RealMotion {
    real_motion_resampled(None)
}

fn real_motion_resampled(fps: Option<f64>) -> RealMotion {
    let path = common::shared_data().join("humanml3d/joints/000021.npy");
    let bytes = std::fs::read(&path).unwrap();
    let array = read_joint_positions(&bytes).unwrap();
    let body: Vec<DVec3> = array
        .positions
        .chunks_exact(array.joints)
        .flat_map(|f| f[..22].iter().copied())
        .collect();
    let spec = ProfileSpec::bundled("smpl-22").unwrap();
    let layout = PositionLayout::from_profile(&spec).unwrap();
    let (motion, _) = motion_from_positions(&layout, &body, 20.0, 0.05).unwrap();
    let motion = match fps {
        Some(fps) => motion.resample(fps),
        None => motion,
    };
    let mut rest = vec![DVec3::new(0.001, -0.35, 0.012); 22];
    for (j, joint) in motion.skeleton.joints.iter().enumerate() {
        if let Some(p) = joint.parent {
            rest[j] = rest[p] + joint.offset;
        }
    }
    let up = DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2);
    let frames = motion.num_frames();
    let rotations = (0..frames)
        .map(|f| {
            std::array::from_fn(|j| {
                let r = motion.rotation(f, j);
                if j == 0 { up * r } else { r }
            })
        })
        .collect();
    let root = (0..frames).map(|f| up * motion.translation(f, 0)).collect();
    RealMotion {
        rest,
        rotations,
        root,
    }
}

fn axis_angle(q: DQuat) -> DVec3 {
    let q = if q.w < 0.0 { -q } else { q };
    let (axis, angle) = q.to_axis_angle();
    axis * angle
}

/// Rest joints of a family: the fitted body, then jaw and eyes by the head and fingers along
/// each forearm (3 segments of 3 cm, fingers 2 cm apart).
fn family_rest(real: &RealMotion, family: Family) -> Vec<DVec3> {
    let mut rest = real.rest.clone();
    if family == Family::SmplX {
        let head = rest[15];
        rest.push(head + DVec3::new(0.0, -0.05, 0.05));
        rest.push(head + DVec3::new(0.03, 0.03, 0.08));
        rest.push(head + DVec3::new(-0.03, 0.03, 0.08));
    }
    // Spread across the forearm, mirror images of each other (x is the body's side axis).
    for (wrist, elbow, side) in [(20, 18, 1.0), (21, 19, -1.0)] {
        let along = (rest[wrist] - rest[elbow]).normalize();
        let across = side * along.cross(DVec3::Y).normalize_or(DVec3::Z);
        for finger in 0..5 {
            let mut at = rest[wrist] + across * (0.02 * (finger as f64 - 2.0));
            for _ in 0..3 {
                at += along * 0.03;
                rest.push(at);
            }
        }
    }
    assert_eq!(rest.len(), family.joints());
    rest
}

/// Axis-angle poses (frames × joints × 3) and translations of the real motion on a family.
fn family_poses(real: &RealMotion, family: Family, rest: &[DVec3]) -> (Vec<f64>, Vec<f64>) {
    let n = family.joints();
    let mut poses = Vec::new();
    let mut trans = Vec::new();
    for (f, rotations) in real.rotations.iter().enumerate() {
        for j in 0..n {
            let r = if j < 22 {
                rotations[j]
            } else {
                // Half of a body joint's rotation (skipping the root), by joint index.
                DQuat::IDENTITY.slerp(rotations[1 + (j * 7) % 21], 0.5)
            };
            poses.extend(axis_angle(r).to_array());
        }
        trans.extend((real.root[f] - rest[0]).to_array());
    }
    (poses, trans)
}

fn write_f64(path: &Path, values: &[f64]) {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(path, bytes).unwrap();
}

/// A scratch folder with the real motion's rest joints and poses for both families.
struct Scratch {
    dir: tempfile::TempDir,
}

impl Scratch {
    fn new() -> Scratch {
        let dir = tempfile::tempdir().unwrap();
        let real = real_motion();
        for family in [Family::SmplH, Family::SmplX] {
            let rest = family_rest(&real, family);
            let flat: Vec<f64> = rest.iter().flat_map(|v| v.to_array()).collect();
            let name = family.folder();
            write_f64(&dir.path().join(format!("{name}-rest.bin")), &flat);
            let (poses, trans) = family_poses(&real, family, &rest);
            write_f64(&dir.path().join(format!("{name}-poses.bin")), &poses);
            write_f64(&dir.path().join(format!("{name}-trans.bin")), &trans);
        }
        Scratch { dir }
    }

    /// Writes the real motion at `fps` as SMPL-H poses and translations; their file names.
    fn smplh_at(&self, fps: f64) -> (PathBuf, PathBuf) {
        let real = real_motion_at(fps);
        let rest = family_rest(&real, Family::SmplH);
        let (poses, trans) = family_poses(&real, Family::SmplH, &rest);
        let names = (
            self.path(&format!("smplh-poses-{fps}.bin")),
            self.path(&format!("smplh-trans-{fps}.bin")),
        );
        write_f64(&names.0, &poses);
        write_f64(&names.1, &trans);
        names
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// A model spec: family, gender folder under `models/`, seed, keys to leave out.
    fn model(&self, family: Family, gender: &str, seed: u64, drop: &[&str]) -> serde_json::Value {
        let path = self
            .path("models")
            .join(family.folder())
            .join(gender)
            .join("model.npz");
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        serde_json::json!({
            "path": path, "family": family.folder(), "seed": seed, "drop": drop,
            "rest": self.path(&format!("{}-rest.bin", family.folder())),
        })
    }

    /// A sequence spec (more keys can be added to the object).
    fn sequence(
        &self,
        name: &str,
        family: Family,
        gender: &str,
        betas: &[f64],
        fps: f64,
    ) -> serde_json::Value {
        let f = family.folder();
        serde_json::json!({
            "path": self.path(name), "family": f, "gender": gender, "betas": betas, "fps": fps,
            "poses": self.path(&format!("{f}-poses.bin")),
            "trans": self.path(&format!("{f}-trans.bin")),
        })
    }

    /// Runs the generator; its printed lines (one JSON object per reference).
    fn generate(&self, spec: serde_json::Value) -> Vec<serde_json::Value> {
        let path = self.path("spec.json");
        std::fs::write(&path, spec.to_string()).unwrap();
        common::run_python(GENERATE, &[&path])
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    }
}

/// Sixteen realistic non-zero shape coefficients.
const BETAS: [f64; 16] = [
    1.2, -0.8, 0.5, 1.9, -1.1, 0.3, -0.4, 0.9, -1.6, 0.7, 0.2, -0.3, 0.6, -0.9, 1.1, -0.2,
];

/// Largest distance between the library's joints (the motion's forward kinematics) and the
/// reference's, over every frame and joint.
fn max_error(motion: &motionforge::motion::Motion, reference: &Path) -> (f64, usize) {
    let array = read_joint_positions(&std::fs::read(reference).unwrap()).unwrap();
    let world = motion.forward_kinematics();
    assert_eq!(array.frames, motion.num_frames(), "{}", reference.display());
    assert_eq!(array.joints, motion.num_joints(), "{}", reference.display());
    let worst = world
        .positions
        .iter()
        .zip(&array.positions)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);
    (worst, array.frames)
}

#[test]
fn joints_equal_the_numpy_reference_for_both_families_genders_and_shapes() {
    let s = Scratch::new();
    let zero = [0.0; 16];
    // (file, family, stated gender, as bytes, betas)
    let cases = [
        ("h_male_zero.npz", Family::SmplH, "male", false, &zero),
        ("h_female_betas.npz", Family::SmplH, "female", true, &BETAS),
        ("x_male_betas.npz", Family::SmplX, "male", true, &BETAS),
        ("x_female_zero.npz", Family::SmplX, "female", false, &zero),
    ];
    let mut models = Vec::new();
    for (i, family) in [Family::SmplH, Family::SmplX].into_iter().enumerate() {
        for (k, gender) in ["male", "female"].into_iter().enumerate() {
            models.push(s.model(family, gender, 10 * i as u64 + k as u64 + 1, &[]));
        }
    }
    let mut sequences = Vec::new();
    let mut references = Vec::new();
    for (name, family, gender, bytes, betas) in cases {
        let mut seq = s.sequence(name, family, gender, betas, 120.0);
        seq["gender_bytes"] = bytes.into();
        sequences.push(seq);
        let model = amass::model_path(&s.path("models"), family, gender);
        references.push(serde_json::json!({
            "sequence": s.path(name), "model": model, "num_betas": 10, "humanml3d": false,
            "out": s.path(&format!("{name}.ref.npy")),
        }));
    }
    s.generate(serde_json::json!({
        "models": models, "sequences": sequences, "references": references,
    }));
    let mut previous: Option<Vec<DVec3>> = None;
    for (name, family, gender, bytes, betas) in cases {
        let data = std::fs::read(s.path(name)).unwrap();
        let seq = amass::read_sequence(name, &data, true).unwrap();
        assert_eq!(seq.family, family, "{name}");
        assert_eq!(seq.fps, Some(120.0), "{name}");
        let stated = seq.gender.clone().unwrap();
        assert_eq!(
            (stated.value.as_str(), stated.bytes),
            (gender, bytes),
            "{name}"
        );
        let chosen = amass::model_gender(amass::GenderChoice::File, Some(&stated), false).unwrap();
        assert_eq!(chosen, gender);
        let model =
            amass::load_model(&amass::model_path(&s.path("models"), family, chosen), 10).unwrap();
        let motion = amass::to_motion(&seq, &model, 1, 120.0).unwrap();
        let (worst, frames) = max_error(&motion, &s.path(&format!("{name}.ref.npy")));
        assert_eq!(frames, 180, "{name}");
        eprintln!("{name}: largest difference from the reference {worst:e} m");
        assert!(
            worst < 1e-5,
            "{name}: joints differ from the reference by {worst:e} m"
        );
        // The shapes and models really differ, so agreeing is not agreeing on nothing.
        let first: Vec<DVec3> = motion.forward_kinematics().frame(0).to_vec();
        if let Some(prev) = &previous
            && prev.len() == first.len()
        {
            let apart = prev
                .iter()
                .zip(&first)
                .map(|(a, b)| a.distance(*b))
                .fold(0.0, f64::max);
            assert!(
                apart > 1e-3,
                "{name}: same joints as the case before ({apart:e})"
            );
        }
        previous = Some(first);
        assert!(betas.len() >= 10);
    }
}

#[test]
fn the_humanml3d_frame_rate_mode_takes_every_int_fps_over_20th_frame_from_frame_0() {
    let s = Scratch::new();
    let rates = [120.0, 250.0, 59.99999, 100.0];
    let model = amass::model_path(&s.path("models"), Family::SmplH, "male");
    let mut sequences = Vec::new();
    let mut references = Vec::new();
    for fps in rates {
        let name = format!("rate_{fps}_poses.npz");
        sequences.push(s.sequence(&name, Family::SmplH, "male", &BETAS, fps));
        references.push(serde_json::json!({
            "sequence": s.path(&name), "model": model, "num_betas": 10, "humanml3d": true,
            "out": s.path(&format!("{name}.ref.npy")),
        }));
    }
    let printed = s.generate(serde_json::json!({
        "models": [s.model(Family::SmplH, "male", 7, &[])],
        "sequences": sequences, "references": references,
    }));
    let model = amass::load_model(&model, 10).unwrap();
    let mut effective_rates = Vec::new();
    for (fps, reference) in rates.into_iter().zip(&printed) {
        let name = format!("rate_{fps}_poses.npz");
        let seq =
            amass::read_sequence(&name, &std::fs::read(s.path(&name)).unwrap(), true).unwrap();
        let (stride, effective) = amass::humanml3d_stride(seq.fps.unwrap());
        assert_eq!(
            stride as u64,
            reference["stride"].as_u64().unwrap(),
            "{fps}"
        );
        assert!((effective - reference["effective"].as_f64().unwrap()).abs() < 1e-9);
        let motion = amass::to_motion(&seq, &model, stride, amass::HUMANML3D_FPS).unwrap();
        assert_eq!(motion.fps, 20.0);
        let (worst, frames) = max_error(&motion, &s.path(&format!("{name}.ref.npy")));
        assert_eq!(
            frames as u64,
            reference["frames"].as_u64().unwrap(),
            "{fps}"
        );
        assert!(worst < 1e-5, "{fps} fps: {worst:e} m");
        effective_rates.push((frames, (effective * 1e4).round() / 1e4));
    }
    // HumanML3D's published rates: 180 frames at 120 fps every 6th, 250 every 12th (20.83 fps),
    // 59.99999 every 2nd (30 fps), 100 every 5th.
    assert_eq!(
        effective_rates,
        [(30, 20.0), (15, 20.8333), (90, 30.0), (36, 20.0)]
    );
}

/// A config of one AMASS source over `captures` (globs), with `extra` keys and values in its
/// `[sources.amass]`.
fn amass_config(dir: &Path, captures: &[&str], extra: &[(&str, &str)]) -> PathBuf {
    let source = Source::new("amass", "smplh-52", captures)
        .licence("test data written by the test")
        .filename_labels("{action}_{take}", "{action}", "a person does a {action}")
        .amass("models");
    let source = extra.iter().fold(source, |source, (key, value)| {
        source.set(&format!("amass.{key}"), *value)
    });
    ConfigSpec::new("amass-test")
        .set("dataset.fps", 20.0)
        .seed(7)
        .set("synthetic.exhaustive", true)
        .source(source)
        .write(dir.join("amass.toml"))
}

fn motionforge() -> Command {
    Command::new(env!("CARGO_BIN_EXE_motionforge"))
}

#[test]
fn an_amass_build_goes_end_to_end_and_refuses_bad_files_by_name() {
    let s = Scratch::new();
    let mut sequences = vec![
        s.sequence("walk_001_poses.npz", Family::SmplH, "male", &BETAS, 120.0),
        s.sequence(
            "jump_001_poses.npz",
            Family::SmplH,
            "female",
            &[0.0; 16],
            250.0,
        ),
        s.sequence(
            "wave_001_poses.npz",
            Family::SmplH,
            "female",
            &BETAS,
            59.99999,
        ),
        s.sequence("shape.npz", Family::SmplH, "male", &BETAS, 120.0),
    ];
    let mut bad = |name: &str, key: &str, value: serde_json::Value| {
        let mut seq = s.sequence(name, Family::SmplH, "male", &BETAS, 120.0);
        seq[key] = value;
        sequences.push(seq);
    };
    bad("cut_001_poses.npz", "truncate", true.into());
    bad("nan_001_poses.npz", "nan_at", serde_json::json!([40, 17]));
    bad(
        "narrow_001_poses.npz",
        "replace",
        serde_json::json!({"poses": vec![vec![0.0; 100]; 3]}),
    );
    bad(
        "norate_001_poses.npz",
        "drop",
        serde_json::json!(["mocap_framerate"]),
    );
    bad("neutral_001_poses.npz", "gender", "neutral".into());
    // An SMPL-X file in a source of SMPL-H's profile.
    sequences.push(s.sequence("smplx_001_poses.npz", Family::SmplX, "male", &BETAS, 120.0));
    s.generate(serde_json::json!({
        "models": [
            s.model(Family::SmplH, "male", 3, &[]),
            s.model(Family::SmplH, "female", 4, &[]),
        ],
        "sequences": sequences,
    }));
    let config = amass_config(s.dir.path(), &["*.npz"], &[("frame_rate", "humanml3d")]);
    common::run_ok(
        motionforge()
            .args(["build", "--quiet", "--config"])
            .arg(&config),
    );
    let dataset = s.path("out/amass-test");

    // Every bad file is refused by name, naming what is wrong; the good ones made clips.
    let rejects = std::fs::read_to_string(dataset.join("rejects.jsonl")).unwrap();
    let rejects: Vec<serde_json::Value> = rejects
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let reject_of = |file: &str| {
        rejects
            .iter()
            .find(|r| r["file"] == file)
            .unwrap_or_else(|| panic!("no reject for {file}: {rejects:?}"))
    };
    for (file, words) in [
        ("cut_001_poses.npz", &["zip"][..]),
        ("nan_001_poses.npz", &["`poses`", "frame 40", "NaN"]),
        ("narrow_001_poses.npz", &["`poses`", "100 values per frame"]),
        ("norate_001_poses.npz", &["mocap_framerate"]),
        (
            "neutral_001_poses.npz",
            &["neutral", "smplh/neutral/model.npz"],
        ),
    ] {
        let r = reject_of(file);
        assert_eq!(r["reason"], "amass", "{r}");
        for w in words {
            assert!(
                r["message"].as_str().unwrap().contains(w),
                "{file}: {w}: {r}"
            );
        }
    }
    let r = reject_of("smplx_001_poses.npz");
    assert_eq!(r["reason"], "profile", "{r}");
    assert!(r["message"].as_str().unwrap().contains("smplx-55"), "{r}");
    assert_eq!(rejects.len(), 6, "{rejects:?}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dataset.join("build-report.json")).unwrap())
            .unwrap();
    let notes = &report["notes_by_kind"];
    // 250 fps (20.83) and 59.99999 fps (30) differ from 20 fps; 120 fps does not.
    assert_eq!(notes["amass_effective_rate"], 2, "{notes}");
    assert_eq!(notes["amass_not_a_motion"], 1, "{notes}");

    let listed = common::run_ok(motionforge().args(["clips", "--json"]).arg(&dataset));
    let rows: serde_json::Value = serde_json::from_slice(&listed.stdout).unwrap();
    let rows = rows.as_array().unwrap();
    let listed = serde_json::to_string(rows).unwrap();
    // Clips are named by the capture key, the stem without AMASS's `_poses`.
    for take in ["walk_001", "jump_001", "wave_001"] {
        assert!(listed.contains(take), "{take} made no clip: {listed}");
    }
    // Rows, not files, are counted at their real rate: each off-rate capture's clip and mirror,
    // and every synthetic pair with such a clip among its sources.
    let id_of = |row: &serde_json::Value| row["clip_id"].as_str().unwrap().to_string();
    let real_at = |take: &str| {
        rows.iter()
            .filter(|r| !id_of(r).starts_with("synthetic/") && id_of(r).contains(take))
            .count()
    };
    let pairs_off_rate = rows
        .iter()
        .filter(|r| id_of(r).starts_with("synthetic/"))
        .filter(|r| id_of(r).contains("jump_001") || id_of(r).contains("wave_001"))
        .count();
    assert!(
        pairs_off_rate > 0,
        "the test needs pairs of off-rate clips: {listed}"
    );
    let by_rate = &report["clips_by_effective_rate"];
    let counted = |rate: &str| by_rate[rate].as_u64().unwrap_or(0) as usize;
    assert!(counted("20.83") >= real_at("jump_001"), "{by_rate}");
    assert!(counted("30.00") >= real_at("wave_001"), "{by_rate}");
    assert_eq!(real_at("jump_001"), 2, "{listed}");
    assert_eq!(
        counted("20.83") + counted("30.00"),
        real_at("jump_001") + real_at("wave_001") + pairs_off_rate,
        "{by_rate}"
    );
    assert_eq!(by_rate.as_object().unwrap().len(), 2, "{by_rate}");

    // The rows export to HumanML3D's layout, and a clip back to BVH on the model's skeleton.
    let hml = s.path("hml");
    common::run_ok(
        motionforge()
            .args(["export", "humanml3d", "--quiet", "--dataset"])
            .arg(&dataset)
            .arg("--out")
            .arg(&hml),
    );
    let joints: Vec<PathBuf> = std::fs::read_dir(hml.join("joints"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(
        joints.len(),
        rows.len(),
        "a joints file per row: {joints:?}"
    );
    let mirrored = joints
        .iter()
        .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with('M'))
        .count();
    assert_eq!(mirrored, 3, "the three captures' mirrors: {joints:?}");
    let clip_id = rows
        .iter()
        .find_map(|v| v["clip_id"].as_str().map(String::from))
        .expect("a clip id");
    let bvh = s.path("clip.bvh");
    common::run_ok(
        motionforge()
            .args(["export-bvh", "--clip", &clip_id, "--output"])
            .arg(&bvh)
            .arg(&dataset),
    );
    let text = std::fs::read_to_string(&bvh).unwrap();
    assert!(
        text.contains("JOINT left_thumb3"),
        "{}",
        &text[..400.min(text.len())]
    );
    let previews = s.path("previews");
    common::run_ok(
        motionforge()
            .args(["preview", "--quiet", "--clip", &clip_id, "--output"])
            .arg(&previews)
            .arg(&dataset),
    );
    let drawn = std::fs::read_dir(&previews).unwrap().count();
    assert_eq!(drawn, 2, "a GIF and a PNG for the clip");
}

#[test]
fn a_body_model_missing_a_key_or_a_gender_is_a_config_error_naming_the_path() {
    let s = Scratch::new();
    s.generate(serde_json::json!({
        "models": [s.model(Family::SmplH, "male", 3, &["J_regressor"])],
        "sequences": [s.sequence("walk_001_poses.npz", Family::SmplH, "male", &BETAS, 120.0)],
    }));
    let config = amass_config(s.dir.path(), &["*.npz"], &[]);
    let out = motionforge()
        .args(["config", "check", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("sources[0].amass.body_model"), "{err}");
    assert!(err.contains("smplh/male/model.npz"), "{err}");
    assert!(err.contains("no array `J_regressor`"), "{err}");

    let config = amass_config(s.dir.path(), &["*.npz"], &[("gender", "neutral")]);
    let out = motionforge()
        .args(["config", "check", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("neutral model"), "{err}");
}

/// Largest distance between the forward kinematics of `mirrored` and the reflection of
/// `original`'s joints (each joint at its partner's reflected place).
fn mirror_error(
    plan: &motionforge::motion::MirrorPlan,
    original: &motionforge::motion::Motion,
    mirrored: &motionforge::motion::Motion,
) -> f64 {
    let reflected = plan.reflect_positions(&original.forward_kinematics().positions);
    mirrored
        .forward_kinematics()
        .positions
        .iter()
        .zip(&reflected)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max)
}

#[test]
fn smpl_reflections_mirror_the_body_and_hands_on_the_models_own_skeleton() {
    use motionforge::motion::{MirrorPlan, OffsetPolicy, Reflection};
    let s = Scratch::new();
    for family in [Family::SmplH, Family::SmplX] {
        let name = format!("{}_mirror.npz", family.folder());
        s.generate(serde_json::json!({
            "models": [s.model(family, "male", 5, &[])],
            // Zero betas: the generated shape directions are random, not left/right symmetric
            // as SMPL's are.
            "sequences": [s.sequence(&name, family, "male", &[0.0; 16], 60.0)],
        }));
        let seq =
            amass::read_sequence(&name, &std::fs::read(s.path(&name)).unwrap(), true).unwrap();
        let model =
            amass::load_model(&amass::model_path(&s.path("models"), family, "male"), 10).unwrap();
        let motion = amass::to_motion(&seq, &model, 1, 60.0).unwrap();
        let profile = ProfileSpec::bundled(family.profile())
            .unwrap()
            .bind(&motion.skeleton)
            .unwrap();
        let plan = MirrorPlan::from_profile(&motion.skeleton, &profile).unwrap();
        // On the mirrored skeleton the copy is the exact reflection.
        let exact = mirror_error(&plan, &motion, &plan.mirror(&motion, OffsetPolicy::Mirror));
        assert!(exact < 1e-9, "{family:?}: {exact:e}");
        // On the original skeleton it is off only by the body's left/right asymmetry (the
        // capture's bone lengths, a few centimetres), fingers included: each joint's rest frame is the model's own axes,
        // so SMPL's reflection across x mirrors every local rotation.
        let kept = mirror_error(&plan, &motion, &plan.mirror(&motion, OffsetPolicy::Keep));
        // Any other reflection turns limbs the wrong way.
        let wrong = MirrorPlan::with_reflections(
            &motion.skeleton,
            &profile,
            vec![Reflection::Z; motion.num_joints()],
        );
        let off = mirror_error(&wrong, &motion, &wrong.mirror(&motion, OffsetPolicy::Keep));
        eprintln!("{family:?}: kept skeleton {kept:.4} m, wrong reflections {off:.4} m");
        assert!(kept < 0.05, "{family:?}: mirrored joints off by {kept} m");
        assert!(off > 4.0 * kept, "{family:?}: {off} vs {kept}");
    }
}

/// `bench --amass` reads a folder of AMASS files (recursively, leaving out `shape.npz`) beside
/// the BVH files of `--data`, and with `--build` builds it. Timings are not asserted: that every
/// file and frame is counted and every figure is there.
#[test]
fn bench_amass_reads_and_builds_a_folder_of_amass_files() {
    let s = Scratch::new();
    std::fs::create_dir_all(s.path("npz/sub")).unwrap();
    let sequences = vec![
        s.sequence("npz/walk_poses.npz", Family::SmplH, "male", &BETAS, 120.0),
        s.sequence(
            "npz/sub/jump_poses.npz",
            Family::SmplH,
            "female",
            &BETAS,
            60.0,
        ),
        s.sequence("npz/sub/shape.npz", Family::SmplH, "male", &BETAS, 120.0),
    ];
    s.generate(serde_json::json!({
        "models": [
            s.model(Family::SmplH, "male", 3, &[]),
            s.model(Family::SmplH, "female", 4, &[]),
        ],
        "sequences": sequences,
    }));
    let frames = std::fs::read(s.path("smplh-trans.bin")).unwrap().len() / (3 * 8);
    let out = common::run_ok(
        motionforge()
            .args(["bench", "--repeat", "1", "--build", "--amass"])
            .arg(s.path("npz"))
            .arg("--body-model")
            .arg(s.path("models"))
            .arg("--data")
            .arg(common::repo().join("fixtures/bandai-namco-1/data"))
            .current_dir(s.dir.path()),
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(
        stdout.starts_with(&format!("AMASS: 2 files, {} frames", 2 * frames)),
        "{stdout}"
    );
    assert!(stdout.contains("1 smplh female, 1 smplh male"), "{stdout}");
    let bvh_files = std::fs::read_dir(common::repo().join("fixtures/bandai-namco-1/data"))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "bvh")
        })
        .count();
    assert!(
        stdout.contains(&format!("BVH:   {bvh_files} files")),
        "{stdout}"
    );
    assert!(stdout.contains("build: 4 rows from 2 files"), "{stdout}");
    for prefix in ["read + joints", "read + fk", "(AMASS is"] {
        let rest = stdout
            .lines()
            .find_map(|l| l.split_once(prefix).map(|(_, rest)| rest))
            .unwrap_or_else(|| panic!("no `{prefix}` in {stdout}"));
        let number: f64 = rest
            .trim_start()
            .split(|c: char| !(c.is_ascii_digit() || c == '.'))
            .next()
            .unwrap()
            .parse()
            .unwrap_or_else(|e| panic!("`{prefix}`: {e}: {stdout}"));
        assert!(number > 0.0, "{prefix}: {stdout}");
    }
    for stage in ["ingest", "write", "report"] {
        assert!(
            stdout.lines().any(|l| l.trim_start().starts_with(stage)),
            "no `{stage}` in {stdout}"
        );
    }
}

/// Reading an AMASS file and computing its joints, timed on one thread: a 2,000-frame SMPL-H
/// sequence (the real motion, repeated) read from its bytes, put on the body model's skeleton
/// and through forward kinematics, best of five. The body model is read once, outside the
/// timing, as a build reads it. Run in release:
/// `cargo test --release --test builds amass::reading -- --ignored --nocapture`
/// (`docs/performance.md`). With `MOTIONFORGE_AMASS_KEEP=<folder>` the body model folder and the
/// sequence are copied there: `scripts/amass-bench-data.sh` does that for `bench --amass`.
#[test]
#[ignore = "a measurement: run in release"]
fn reading_and_forward_kinematics_frames_per_second() {
    let s = Scratch::new();
    let n = Family::SmplH.joints();
    let poses: Vec<u8> = std::fs::read(s.path("smplh-poses.bin")).unwrap();
    let trans: Vec<u8> = std::fs::read(s.path("smplh-trans.bin")).unwrap();
    let frames = 2000;
    let repeat = |bytes: &[u8], width: usize| -> Vec<u8> {
        bytes
            .chunks_exact(width)
            .cycle()
            .take(frames)
            .flatten()
            .copied()
            .collect()
    };
    std::fs::write(s.path("long-poses.bin"), repeat(&poses, n * 3 * 8)).unwrap();
    std::fs::write(s.path("long-trans.bin"), repeat(&trans, 3 * 8)).unwrap();
    let mut seq = s.sequence("long_poses.npz", Family::SmplH, "male", &BETAS, 120.0);
    seq["poses"] = s
        .path("long-poses.bin")
        .to_string_lossy()
        .into_owned()
        .into();
    seq["trans"] = s
        .path("long-trans.bin")
        .to_string_lossy()
        .into_owned()
        .into();
    s.generate(serde_json::json!({
        "models": [s.model(Family::SmplH, "male", 5, &[])],
        "sequences": [seq],
    }));
    let bytes = std::fs::read(s.path("long_poses.npz")).unwrap();
    let model = amass::load_model(
        &amass::model_path(&s.path("models"), Family::SmplH, "male"),
        10,
    )
    .unwrap();
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let start = std::time::Instant::now();
        let seq = amass::read_sequence("long_poses.npz", &bytes, true).unwrap();
        let motion = amass::to_motion(&seq, &model, 1, 120.0).unwrap();
        let world = motion.forward_kinematics();
        assert_eq!(world.num_frames(), frames);
        best = best.min(start.elapsed().as_secs_f64());
    }
    println!(
        "{frames} frames, {} MB: read + joints {:.0} frames/s on one thread ({:.1} ms)",
        bytes.len() / 1_000_000,
        frames as f64 / best,
        best * 1e3
    );
    if let Some(keep) = std::env::var_os("MOTIONFORGE_AMASS_KEEP") {
        let keep = PathBuf::from(keep);
        common::copy_dir(&s.path("models"), &keep.join("models"));
        std::fs::copy(s.path("long_poses.npz"), keep.join("long_poses.npz")).unwrap();
    }
}

/// Reads a `.npy` of joint positions as (frames, joints, positions).
fn joints_file(path: &Path) -> motionforge::motion::npy::JointArray {
    read_joint_positions(&std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())))
        .unwrap()
}

fn largest_difference(
    a: &motionforge::motion::npy::JointArray,
    b: &motionforge::motion::npy::JointArray,
) -> f64 {
    assert_eq!((a.frames, a.joints), (b.frames, b.joints));
    a.positions
        .iter()
        .zip(&b.positions)
        .map(|(x, y)| x.distance(*y))
        .fold(0.0, f64::max)
}

#[test]
fn humanml3d_index_rows_cut_from_amass_files_export_the_notebooks_joints_and_mirrors() {
    let s = Scratch::new();
    // Real rows of HumanML3D's index: a 100 fps KIT capture, two datasets with head trims and a
    // CMU capture; each pointed at an AMASS file written here at its dataset's rate.
    let index = std::fs::read_to_string(common::shared_data().join("humanml3d/index.csv")).unwrap();
    let wanted = [
        ("000000.npy", 100.0, "male", false),
        ("004938.npy", 120.0, "female", false),
        ("000708.npy", 120.0, "male", true),
        ("000043.npy", 120.0, "male", true),
    ];
    let mut rows = Vec::new();
    for (name, fps, gender, bytes) in wanted {
        let line = index
            .lines()
            .find(|l| l.ends_with(&format!(",{name}")))
            .unwrap_or_else(|| panic!("no row {name}"));
        let fields: Vec<&str> = line.split(',').collect();
        rows.push((
            line.to_string(),
            fields[0].to_string(),
            fields[1].parse::<i64>().unwrap(),
            fields[2].parse::<i64>().unwrap(),
            name,
            fps,
            gender,
            bytes,
        ));
    }
    let mut sequences = Vec::new();
    let mut notebook = Vec::new();
    for (_, source_path, start, end, name, fps, gender, bytes) in &rows {
        let relative = source_path
            .strip_prefix("./pose_data/")
            .unwrap()
            .replace(".npy", ".npz");
        let path = s.path("amass").join(&relative);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let (poses, trans) = s.smplh_at(*fps);
        let mut seq = s.sequence("unused", Family::SmplH, gender, &BETAS, *fps);
        seq["path"] = path.to_string_lossy().into_owned().into();
        seq["poses"] = poses.to_string_lossy().into_owned().into();
        seq["trans"] = trans.to_string_lossy().into_owned().into();
        seq["gender_bytes"] = (*bytes).into();
        sequences.push(seq);
        notebook.push(serde_json::json!({
            "sequence": path, "models": s.path("models"), "source_path": source_path,
            "start": start, "end": end,
            "out": s.path(&format!("ref-{name}")), "out_m": s.path(&format!("ref-M{name}")),
        }));
    }
    let printed = s.generate(serde_json::json!({
        "models": [
            s.model(Family::SmplH, "male", 3, &[]),
            s.model(Family::SmplH, "female", 4, &[]),
        ],
        "sequences": sequences,
        "notebook": notebook,
    }));
    // HumanML3D's quirk: the bytes `male` files got the female model.
    let genders: Vec<&str> = printed
        .iter()
        .map(|p| p["gender"].as_str().unwrap())
        .collect();
    assert_eq!(genders, ["male", "female", "female", "female"]);
    let mut csv = String::from("source_path,start_frame,end_frame,new_name\n");
    for (line, ..) in &rows {
        csv.push_str(line);
        csv.push('\n');
    }
    std::fs::write(s.path("index.csv"), csv).unwrap();
    let config = ConfigSpec::new("hml")
        .fps(20)
        .synthetic(false)
        .source(
            Source::new("amass", "smplh-52", &["amass/**/*_poses.npz"])
                .frame_index_labels("index.csv", 20)
                .set("labels.humanml3d_cuts", true)
                .set("labels.default_text", "a person moves")
                .amass("models")
                .set("amass.frame_rate", "humanml3d")
                .set("amass.humanml3d_gender", true),
        )
        .write(s.path("hml.toml"));
    common::run_ok(
        motionforge()
            .args(["build", "--quiet", "--config"])
            .arg(&config),
    );
    let dataset = s.path("out/hml");
    let rejects = std::fs::read_to_string(dataset.join("rejects.jsonl")).unwrap_or_default();
    assert!(rejects.trim().is_empty(), "{rejects}");
    let hml = s.path("export");
    common::run_ok(
        motionforge()
            .args(["export", "humanml3d", "--quiet", "--dataset"])
            .arg(&dataset)
            .arg("--out")
            .arg(&hml),
    );
    // names.csv: which exported name is which clip.
    let names = std::fs::read_to_string(hml.join("names.csv")).unwrap();
    for (_, source_path, _, _, name, ..) in &rows {
        let key = source_path
            .rsplit('/')
            .next()
            .unwrap()
            .trim_end_matches(".npy")
            .trim_end_matches("_poses");
        let exported = names
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect::<Vec<_>>())
            .find(|f| f[1].contains(key) && f[4] == "false")
            .unwrap_or_else(|| panic!("no exported clip of {key}: {names}"));
        let ours = joints_file(&hml.join("joints").join(format!("{}.npy", exported[0])));
        let theirs = joints_file(&s.path(&format!("ref-{name}")));
        let worst = largest_difference(&ours, &theirs);
        eprintln!(
            "{name} ({key}): {} frames, largest difference {worst:e} m",
            ours.frames
        );
        assert!(
            worst < 1e-5,
            "{name}: joints/ differs from the notebook's by {worst:e} m"
        );
        let ours = joints_file(&hml.join("joints").join(format!("M{}.npy", exported[0])));
        let theirs = joints_file(&s.path(&format!("ref-M{name}")));
        let worst = largest_difference(&ours, &theirs);
        assert!(
            worst < 1e-5,
            "M{name}: differs from swap_left_right by {worst:e} m"
        );
    }
}

/// Also: a second source, HumanML3D's index rows for the same two captures, over the same files
/// in the same config: one dataset with the clips of both, each named by its source.
#[test]
fn babel_feat_p_paths_find_amass_files_and_a_wrong_duration_is_reported() {
    let s = Scratch::new();
    // The real BABEL records: 141_05 (3.83 s, CMU at 60 fps) and 86_08 (76.73 s). The files
    // written here: 141_05 with 230 frames at 60 fps (3.83 s), 86_08 with the 9 s real motion,
    // far from its record's duration.
    let (poses60, trans60) = s.smplh_at(60.0);
    let width = Family::SmplH.joints() * 3 * 8;
    let cut = |path: &Path, frame_bytes: usize| {
        let bytes = std::fs::read(path).unwrap();
        std::fs::write(path, &bytes[..230 * frame_bytes]).unwrap();
    };
    cut(&poses60, width);
    cut(&trans60, 3 * 8);
    let mut short = s.sequence("unused", Family::SmplH, "male", &BETAS, 60.0);
    let dir = s.path("amass/CMU/CMU/141");
    std::fs::create_dir_all(&dir).unwrap();
    short["path"] = dir
        .join("141_05_poses.npz")
        .to_string_lossy()
        .into_owned()
        .into();
    short["poses"] = poses60.to_string_lossy().into_owned().into();
    short["trans"] = trans60.to_string_lossy().into_owned().into();
    let mut long = s.sequence("unused", Family::SmplH, "female", &BETAS, 120.0);
    let (poses120, trans120) = s.smplh_at(120.0);
    let dir = s.path("amass/CMU/CMU/86");
    std::fs::create_dir_all(&dir).unwrap();
    long["path"] = dir
        .join("86_08_poses.npz")
        .to_string_lossy()
        .into_owned()
        .into();
    long["poses"] = poses120.to_string_lossy().into_owned().into();
    long["trans"] = trans120.to_string_lossy().into_owned().into();
    s.generate(serde_json::json!({
        "models": [
            s.model(Family::SmplH, "male", 3, &[]),
            s.model(Family::SmplH, "female", 4, &[]),
        ],
        "sequences": [short, long],
    }));
    let babel = common::shared_data().join("babel/babel_records_from_notebook_outputs.json");
    let captures = ["amass/**/*_poses.npz"];
    let config = ConfigSpec::new("babel")
        .synthetic(false)
        .source(
            Source::new("babel", "smplh-52", &captures)
                .babel_labels(&babel.to_string_lossy())
                .amass("models"),
        )
        .source(
            Source::new("humanml3d", "smplh-52", &captures)
                .frame_index_labels("index.csv", 20)
                .set("labels.default_text", "a person moves")
                .amass("models"),
        )
        .write(s.path("babel.toml"));
    // HumanML3D's real rows of the two captures.
    let index = std::fs::read_to_string(common::shared_data().join("humanml3d/index.csv")).unwrap();
    let mut rows = String::from("source_path,start_frame,end_frame,new_name\n");
    for line in index
        .lines()
        .filter(|l| l.contains("/141_05_poses") || l.contains("/86_08_poses"))
    {
        rows.push_str(line);
        rows.push('\n');
    }
    std::fs::write(s.path("index.csv"), rows).unwrap();
    common::run_ok(
        motionforge()
            .args(["build", "--quiet", "--config"])
            .arg(&config),
    );
    let dataset = s.path("out/babel");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dataset.join("build-report.json")).unwrap())
            .unwrap();
    let notes = report["notes"].as_array().unwrap();
    let mismatches: Vec<&str> = notes
        .iter()
        .filter(|n| n["kind"] == "duration_mismatch")
        .map(|n| n["message"].as_str().unwrap())
        .collect();
    assert_eq!(mismatches.len(), 1, "{mismatches:?}");
    assert!(
        mismatches[0].contains("86_08_poses.npz"),
        "{}",
        mismatches[0]
    );
    assert!(mismatches[0].contains("76.73"), "{}", mismatches[0]);
    // No record is left without its capture, and 141_05's labels became clips.
    assert!(
        !notes
            .iter()
            .any(|n| n["kind"] == "annotation_without_capture"),
        "{notes:?}"
    );
    let listed = common::run_ok(motionforge().args(["clips", "--json"]).arg(&dataset));
    let rows: serde_json::Value = serde_json::from_slice(&listed.stdout).unwrap();
    let texts: Vec<String> = rows
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["clip_id"].as_str().unwrap().contains("141_05"))
        .map(|r| r["text"].as_str().unwrap().to_string())
        .collect();
    for label in ["hopping left", "hopping right"] {
        assert!(texts.iter().any(|t| t == label), "{label}: {texts:?}");
    }
    // Both sources' clips of the same capture, each clip id starting with its source.
    let of_141_05 = |source: &str| {
        rows.as_array()
            .unwrap()
            .iter()
            .filter(|r| {
                let id = r["clip_id"].as_str().unwrap();
                id.starts_with(&format!("{source}/")) && id.contains("141_05")
            })
            .count()
    };
    assert!(of_141_05("babel") >= 2, "{rows:#}");
    assert!(of_141_05("humanml3d") >= 1, "{rows:#}");
    // One capture, one split, whichever source its text came from.
    let splits: std::collections::BTreeSet<&str> = rows
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["clip_id"].as_str().unwrap().contains("141_05"))
        .map(|r| r["split"].as_str().unwrap())
        .collect();
    assert_eq!(splits.len(), 1, "{splits:?}");
    let rejects = std::fs::read_to_string(dataset.join("rejects.jsonl")).unwrap_or_default();
    assert!(rejects.trim().is_empty(), "{rejects}");
}
