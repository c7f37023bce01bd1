//! HumanML3D's motion representation: the 263 numbers per frame that text-to-motion, T2M-GPT,
//! MoMask, MDM and their evaluators read, computed from 22 SMPL body-joint positions exactly as
//! HumanML3D's `motion_representation.ipynb` (`process_file`) computes them, and the positions
//! recovered from them as its `recover_from_ric` does.
//!
//! Positions are y-up, in metres, at 20 frames per second, on SMPL's first 22 joints in SMPL's
//! order ([`JOINTS`]). A motion of `T` frames gives `T - 1` rows:
//!
//! | columns | what |
//! |---|---|
//! | 0 | root rotation velocity about y (the sine of half the heading change, through `arcsin`) |
//! | 1-2 | root linear velocity on the ground plane, in the next frame's heading |
//! | 3 | root height |
//! | 4-66 | joints 1-21 relative to the root on the ground plane, in the frame's heading |
//! | 67-192 | joints 1-21 rotations, 6D (the first two columns of the rotation matrix) |
//! | 193-258 | joints 0-21 velocities, in the frame's heading |
//! | 259-262 | foot contacts: left ankle, left foot, right ankle, right foot |
//!
//! Where the reference code's behaviour is surprising, it is reproduced, because pretrained
//! evaluators were trained on it; `docs/humanml3d.md` lists each quirk. Where it divides by
//! zero (a bone of zero length, a bone pointing exactly against its rest direction), this module
//! returns an error or a defined rotation instead of NaN.

use glam::{DMat3, DQuat, DVec3};

mod recover;

pub use recover::{positions_from_vectors, recover_from_ric};

/// Joints of the body HumanML3D uses (SMPL's first 22).
pub const NUM_JOINTS: usize = 22;
/// Numbers per row of the representation.
pub const DIM: usize = 4 + (NUM_JOINTS - 1) * 3 + (NUM_JOINTS - 1) * 6 + NUM_JOINTS * 3 + 4;
/// The frame rate HumanML3D's arrays are at.
pub const FPS: f64 = 20.0;

/// SMPL's body joints, in order.
pub const JOINTS: [&str; NUM_JOINTS] = [
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
];

/// The kinematic chains (`t2m_kinematic_chain`): each starts at the pelvis or spine3.
pub const CHAINS: [&[usize]; 5] = [
    &[0, 2, 5, 8, 11],
    &[0, 1, 4, 7, 10],
    &[0, 3, 6, 9, 12, 15],
    &[9, 14, 17, 19, 21],
    &[9, 13, 16, 18, 20],
];

/// Each joint's parent (`None` for the pelvis).
pub const PARENTS: [Option<usize>; NUM_JOINTS] = [
    None,
    Some(0),
    Some(0),
    Some(0),
    Some(1),
    Some(2),
    Some(3),
    Some(4),
    Some(5),
    Some(6),
    Some(7),
    Some(8),
    Some(9),
    Some(9),
    Some(9),
    Some(12),
    Some(13),
    Some(14),
    Some(16),
    Some(17),
    Some(18),
    Some(19),
];

/// Each joint's rest direction from its parent (`t2m_raw_offsets`): the direction rotations are
/// measured from.
pub const REST_DIRECTIONS: [[f64; 3]; NUM_JOINTS] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [-1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.0, 0.0, 1.0],
    [0.0, 1.0, 0.0],
    [1.0, 0.0, 0.0],
    [-1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
];

/// Bone lengths every clip is retargeted to (metres, as float32 like the reference): frame 0 of
/// HumanML3D clip 000021 (`t2m_tgt_skel_id`). `tests/humanml3d.rs` recomputes them from that
/// file.
pub const REFERENCE_LENGTHS: [f64; NUM_JOINTS] = [
    0.0,
    0.10307393223047256,
    0.10988342016935349,
    0.13156823813915253,
    0.3936232626438141,
    0.3901881277561188,
    0.14319021999835968,
    0.4324330985546112,
    0.42564353346824646,
    0.05736473575234413,
    0.14338184893131256,
    0.14941902458667755,
    0.21936005353927612,
    0.13748674094676971,
    0.14338286221027374,
    0.1030392199754715,
    0.13161404430866241,
    0.12298443913459778,
    0.25683990120887756,
    0.26309171319007874,
    0.26601195335388184,
    0.2698764503002167,
];

/// Left ankle and foot.
const FEET_LEFT: [usize; 2] = [7, 10];
/// Right ankle and foot.
const FEET_RIGHT: [usize; 2] = [8, 11];
/// The joints whose length sets the retargeting scale (right knee and right ankle bones).
const LEG_BONES: [usize; 2] = [5, 8];
/// Squared displacement per frame (m²) under which a foot is in contact.
pub const CONTACT_THRESHOLD: f64 = 0.002;
/// Standard deviation (frames) of the Gaussian that smooths the facing direction.
const FACING_SIGMA: f64 = 20.0;

/// Why a motion has no HumanML3D representation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Hml3dError {
    /// Rows are frame-to-frame differences: one frame gives none.
    #[error("{frames} frame(s): the representation needs at least 2")]
    TooShort {
        /// Frames given.
        frames: usize,
    },
    /// The array is not frames × 22 joints.
    #[error("{values} positions are not a whole number of {NUM_JOINTS}-joint frames")]
    Shape {
        /// Positions given.
        values: usize,
    },
    /// A position is NaN or infinite.
    #[error("frame {frame}, joint {joint} (`{name}`): position is not finite", name = JOINTS[*joint])]
    NotFinite {
        /// The frame.
        frame: usize,
        /// The joint.
        joint: usize,
    },
    /// A joint sits on its parent, so its bone has no direction.
    #[error(
        "frame {frame}: joint {joint} (`{name}`) coincides with its parent; a bone needs a direction",
        name = JOINTS[*joint]
    )]
    ZeroBone {
        /// The frame.
        frame: usize,
        /// The joint.
        joint: usize,
    },
    /// Hips and shoulders give no horizontal left-right direction, so the body has no facing.
    #[error("frame {frame}: hips and shoulders give no facing direction")]
    NoFacing {
        /// The frame.
        frame: usize,
    },
}

/// The rotation taking `from` to `to` (HumanML3D's `qbetween`: the shortest arc). For opposite
/// directions, where the reference divides zero by zero, a half turn about an axis
/// perpendicular to `from` (y when possible).
pub(crate) fn between(from: DVec3, to: DVec3) -> DQuat {
    let axis = from.cross(to);
    let w = (from.length_squared() * to.length_squared()).sqrt() + from.dot(to);
    let q = DQuat::from_xyzw(axis.x, axis.y, axis.z, w);
    let norm = q.length();
    if norm > 1e-12 * (from.length() * to.length()).max(f64::MIN_POSITIVE) {
        return q / norm;
    }
    let mut perpendicular = from.cross(DVec3::Y);
    if perpendicular.length_squared() < 1e-24 {
        perpendicular = from.cross(DVec3::X);
    }
    let p = perpendicular.normalize();
    DQuat::from_xyzw(p.x, p.y, p.z, 0.0)
}

/// The (unnormalised) horizontal left-to-right direction of a frame from hips and shoulders.
fn across(frame: &[DVec3], right_hip: usize, left_hip: usize) -> DVec3 {
    (frame[right_hip] - frame[left_hip]) + (frame[17] - frame[16])
}

/// Facing: up × across, the body's forward on the ground plane.
fn facing(across: DVec3) -> DVec3 {
    DVec3::new(across.z, 0.0, -across.x)
}

/// `scipy.ndimage.gaussian_filter1d(values, sigma, mode='nearest')` with its default truncation
/// at four standard deviations.
fn gaussian_smooth(values: &[DVec3], sigma: f64) -> Vec<DVec3> {
    let radius = (4.0 * sigma + 0.5) as isize;
    let mut weights: Vec<f64> = (-radius..=radius)
        .map(|x| (-0.5 / (sigma * sigma) * (x * x) as f64).exp())
        .collect();
    let total: f64 = weights.iter().sum();
    for w in &mut weights {
        *w /= total;
    }
    let last = values.len() as isize - 1;
    (0..values.len() as isize)
        .map(|t| {
            (-radius..=radius)
                .zip(&weights)
                .map(|(k, w)| values[(t + k).clamp(0, last) as usize] * *w)
                .fold(DVec3::ZERO, |a, b| a + b)
        })
        .collect()
}

/// HumanML3D's representation of a motion given as `frames × 22` joint positions (y-up, metres,
/// 20 fps, SMPL order): `frames - 1` rows of [`DIM`] numbers, row-major.
pub fn vectors(positions: &[DVec3]) -> Result<Vec<f32>, Hml3dError> {
    if !positions.len().is_multiple_of(NUM_JOINTS) {
        return Err(Hml3dError::Shape {
            values: positions.len(),
        });
    }
    let frames = positions.len() / NUM_JOINTS;
    if frames < 2 {
        return Err(Hml3dError::TooShort { frames });
    }
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        return Err(Hml3dError::NotFinite {
            frame: i / NUM_JOINTS,
            joint: i % NUM_JOINTS,
        });
    }
    let p = retarget(positions, frames)?;
    let global = on_floor_facing_z(p)?;
    let root = root_rotations(&global, frames)?;
    let local = local_rotations(&global, &root, frames)?;
    let mut out = Vec::with_capacity((frames - 1) * DIM);
    for t in 0..frames - 1 {
        push_row(&mut out, &global, &root, &local, t);
    }
    Ok(out)
}

/// The unit direction of joint `j`'s bone at frame `t` of `p` (`frames × 22`).
fn bone_direction(p: &[DVec3], t: usize, j: usize) -> Result<DVec3, Hml3dError> {
    let parent = PARENTS[j].unwrap_or(0);
    (p[t * NUM_JOINTS + j] - p[t * NUM_JOINTS + parent])
        .try_normalize()
        .ok_or(Hml3dError::ZeroBone { frame: t, joint: j })
}

/// Retarget to the reference bone lengths: each bone keeps its direction, the root its path
/// scaled by the ratio of leg lengths (what the reference's IK followed by FK amounts to).
fn retarget(positions: &[DVec3], frames: usize) -> Result<Vec<DVec3>, Hml3dError> {
    let first = &positions[..NUM_JOINTS];
    let leg = |lengths: &dyn Fn(usize) -> f64| LEG_BONES.iter().map(|&j| lengths(j)).sum::<f64>();
    let source_leg = leg(&|j| {
        // The reference keeps offsets in float32.
        f64::from((first[j] - first[PARENTS[j].unwrap_or(0)]).length() as f32)
    });
    let target_leg = leg(&|j| REFERENCE_LENGTHS[j]);
    let scale = target_leg / source_leg;
    let mut p = vec![DVec3::ZERO; positions.len()];
    for t in 0..frames {
        p[t * NUM_JOINTS] = positions[t * NUM_JOINTS] * scale;
        for chain in CHAINS {
            for link in chain.windows(2) {
                let (parent, child) = (link[0], link[1]);
                let d = bone_direction(positions, t, child)?;
                p[t * NUM_JOINTS + child] =
                    p[t * NUM_JOINTS + parent] + d * REFERENCE_LENGTHS[child];
            }
        }
    }
    Ok(p)
}

/// On the floor, the first frame's root over the origin, facing +z; from here the reference
/// holds positions in float32, so they are rounded to it.
fn on_floor_facing_z(mut p: Vec<DVec3>) -> Result<Vec<DVec3>, Hml3dError> {
    let floor = p.iter().map(|v| v.y).fold(f64::INFINITY, f64::min);
    let origin = DVec3::new(p[0].x, 0.0, p[0].z);
    for v in &mut p {
        v.y -= floor;
        *v -= origin;
    }
    let forward0 = across(&p[..NUM_JOINTS], 2, 1)
        .try_normalize()
        .and_then(|a| facing(a).try_normalize())
        .ok_or(Hml3dError::NoFacing { frame: 0 })?;
    let face = between(forward0, DVec3::Z);
    Ok(p.iter()
        .map(|v| {
            let r = face * *v;
            DVec3::new(
                f64::from(r.x as f32),
                f64::from(r.y as f32),
                f64::from(r.z as f32),
            )
        })
        .collect())
}

/// Root rotation per frame from the smoothed facing. The reference's IK unpacks its face
/// joints in another order than `process_file` does, so its left-right direction is the
/// shoulders' minus the hips' (reproduced: evaluators were trained on it); the first frame's
/// root rotation is the identity.
fn root_rotations(global: &[DVec3], frames: usize) -> Result<Vec<DQuat>, Hml3dError> {
    let facings: Vec<DVec3> = (0..frames)
        .map(|t| {
            across(&global[t * NUM_JOINTS..(t + 1) * NUM_JOINTS], 1, 2)
                .try_normalize()
                .map(facing)
                .ok_or(Hml3dError::NoFacing { frame: t })
        })
        .collect::<Result<_, _>>()?;
    let smoothed = gaussian_smooth(&facings, FACING_SIGMA);
    let mut root = Vec::with_capacity(frames);
    for (t, f) in smoothed.iter().enumerate() {
        if t == 0 {
            root.push(DQuat::IDENTITY);
            continue;
        }
        let f = f.try_normalize().ok_or(Hml3dError::NoFacing { frame: t })?;
        root.push(between(f, DVec3::Z));
    }
    Ok(root)
}

/// Local rotations along each chain, each chain starting from the root rotation (also for
/// the arms, which start at spine3: the reference does not carry the spine's rotation).
fn local_rotations(
    global: &[DVec3],
    root: &[DQuat],
    frames: usize,
) -> Result<Vec<DQuat>, Hml3dError> {
    let mut local = vec![DQuat::IDENTITY; global.len()];
    for t in 0..frames {
        local[t * NUM_JOINTS] = root[t];
        for chain in CHAINS {
            let mut r = root[t];
            for link in chain.windows(2) {
                let child = link[1];
                let v = bone_direction(global, t, child)?;
                let swing = between(DVec3::from_array(REST_DIRECTIONS[child]), v);
                let l = r.conjugate() * swing;
                local[t * NUM_JOINTS + child] = l;
                r *= l;
            }
        }
    }
    Ok(local)
}

/// Appends frame `t`'s [`DIM`] numbers (it needs frame `t + 1` too): root velocities and
/// height, joint positions, rotations and velocities, foot contacts.
fn push_row(out: &mut Vec<f32>, global: &[DVec3], root: &[DQuat], local: &[DQuat], t: usize) {
    let at = |t: usize, j: usize| global[t * NUM_JOINTS + j];
    let heading = root[t];
    // Root: rotation velocity, linear velocity (in the next frame's heading), height.
    let turn = root[t + 1] * root[t].conjugate();
    let step = root[t + 1] * (at(t + 1, 0) - at(t, 0));
    out.extend([
        turn.y.clamp(-1.0, 1.0).asin() as f32,
        step.x as f32,
        step.z as f32,
        at(t, 0).y as f32,
    ]);
    // Joints relative to the root on the ground plane, in this frame's heading.
    let base = DVec3::new(at(t, 0).x, 0.0, at(t, 0).z);
    for j in 1..NUM_JOINTS {
        let v = heading * (at(t, j) - base);
        out.extend([v.x as f32, v.y as f32, v.z as f32]);
    }
    for j in 1..NUM_JOINTS {
        let m = DMat3::from_quat(local[t * NUM_JOINTS + j]);
        out.extend([
            m.x_axis.x as f32,
            m.x_axis.y as f32,
            m.x_axis.z as f32,
            m.y_axis.x as f32,
            m.y_axis.y as f32,
            m.y_axis.z as f32,
        ]);
    }
    for j in 0..NUM_JOINTS {
        let v = heading * (at(t + 1, j) - at(t, j));
        out.extend([v.x as f32, v.y as f32, v.z as f32]);
    }
    out.extend(FEET_LEFT.map(|j| foot_contact(global, t, j)));
    out.extend(FEET_RIGHT.map(|j| foot_contact(global, t, j)));
}

/// Foot contact of joint `j` between frames `t` and `t + 1`, compared in float32 like the
/// reference so borderline frames agree.
fn foot_contact(global: &[DVec3], t: usize, j: usize) -> f32 {
    let at = |t: usize| global[t * NUM_JOINTS + j];
    let (a, b) = (at(t).as_vec3(), at(t + 1).as_vec3());
    let d = b - a;
    let squared = d.x * d.x + d.y * d.y + d.z * d.z;
    if squared < CONTACT_THRESHOLD as f32 {
        1.0
    } else {
        0.0
    }
}
