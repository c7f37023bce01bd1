//! Dataset axes and the canonical frame of a clip (LINGO A.4, B.2.2): origin at the first frame's
//! pelvis on the ground, rotated so the character faces +y; x to the character's right, z up,
//! metres. Goals are expressed in it.

use glam::{DQuat, DVec3};

use super::motion::Motion;
use super::profile::{BodyPart, Profile, Role};

/// World positions of every joint at every frame in dataset axes (x right, y forward, z up) and
/// metres, frame-major.
pub fn dataset_positions(motion: &Motion, profile: &Profile) -> Vec<DVec3> {
    let axes = profile.to_dataset_axes();
    let scale = profile.unit_scale;
    motion
        .forward_kinematics()
        .positions
        .into_iter()
        .map(|p| axes * (p * scale))
        .collect()
}

/// A clip's first-frame canonical frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CanonicalFrame {
    /// The first frame's pelvis, dropped to the ground plane (z = 0).
    pub origin: DVec3,
    /// Rotation about z taking the character's initial facing to +y.
    pub rotation: DQuat,
}

impl CanonicalFrame {
    /// A dataset-axes position in this frame.
    pub fn apply(&self, p: DVec3) -> DVec3 {
        self.rotation * (p - self.origin)
    }
}

/// The left and right joints of a role, by body part (hips by default, shoulders as fallback).
fn side_pair(
    profile: &Profile,
    role: Role,
    left: BodyPart,
    right: BodyPart,
) -> Option<(usize, usize)> {
    let find = |part: BodyPart| {
        profile
            .joints_with_role(role)
            .find(|&j| profile.part_of[j] == Some(part))
    };
    Some((find(left)?, find(right)?))
}

/// The character's heading in one frame (dataset-axes positions): the angle (radians,
/// counterclockwise seen from above, so a left turn increases it) of its forward direction
/// from +x, forward being perpendicular to the left-to-right hip line (shoulders as fallback).
/// `None` when neither gives a direction.
pub fn heading(frame: &[DVec3], profile: &Profile) -> Option<f64> {
    let lateral = lateral(frame, profile)?;
    Some(lateral.x.atan2(-lateral.y))
}

/// The heading ([`heading`]) of every frame of frame-major positions, unwrapped so that turns
/// add up past a half turn; `None` when a frame has no facing direction.
pub fn heading_track(positions: &[DVec3], joints: usize, profile: &Profile) -> Option<Vec<f64>> {
    let mut out: Vec<f64> = Vec::new();
    for frame in positions.chunks_exact(joints.max(1)) {
        let h = heading(frame, profile)?;
        let next = match out.last() {
            Some(&last) => {
                last + (h - last + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI
            }
            None => h,
        };
        out.push(next);
    }
    Some(out)
}

/// Net heading change of a motion (radians, left turns positive): the mean unwrapped heading of
/// its last `ends` seconds less that of its first (a quarter of the motion when shorter), so the
/// hips' swing with every step averages out. `None` without a facing direction or frames.
pub fn net_turn(
    positions: &[DVec3],
    joints: usize,
    fps: f64,
    ends: f64,
    profile: &Profile,
) -> Option<f64> {
    let track = heading_track(positions, joints, profile)?;
    let n = track.len();
    if n == 0 {
        return None;
    }
    let k = if fps.is_finite() && fps > 0.0 && ends.is_finite() && ends > 0.0 {
        ((ends * fps).round() as usize).min(n / 4).max(1)
    } else {
        1
    };
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    Some(mean(&track[n - k..]) - mean(&track[..k]))
}

/// The horizontal left-to-right direction of a frame (hips, then shoulders, then collars).
fn lateral(frame: &[DVec3], profile: &Profile) -> Option<DVec3> {
    [
        side_pair(profile, Role::Hip, BodyPart::LeftLeg, BodyPart::RightLeg),
        side_pair(
            profile,
            Role::Shoulder,
            BodyPart::LeftArm,
            BodyPart::RightArm,
        ),
        side_pair(profile, Role::Collar, BodyPart::LeftArm, BodyPart::RightArm),
    ]
    .into_iter()
    .flatten()
    .find_map(|(l, r)| {
        let d = *frame.get(r)? - *frame.get(l)?;
        let h = DVec3::new(d.x, d.y, 0.0);
        (h.length() > 1e-6).then(|| h.normalize())
    })
}

/// The canonical frame of a clip from its first frame (dataset-axes positions, one frame).
/// Facing is perpendicular to the left-to-right hip line across the up axis; shoulders are used
/// when the hips are missing or stacked vertically. `None` when neither gives a direction.
pub fn canonical_frame(first_frame: &[DVec3], profile: &Profile) -> Option<CanonicalFrame> {
    let pelvis = *first_frame.get(profile.root)?;
    let lateral = lateral(first_frame, profile)?;
    // forward = up × right
    let forward = DVec3::new(-lateral.y, lateral.x, 0.0);
    let angle = std::f64::consts::FRAC_PI_2 - forward.y.atan2(forward.x);
    Some(CanonicalFrame {
        origin: DVec3::new(pelvis.x, pelvis.y, 0.0),
        rotation: DQuat::from_rotation_z(angle),
    })
}

/// The hand joint on a side, if the profile has one.
pub fn hand_joint(profile: &Profile, part: BodyPart) -> Option<usize> {
    profile
        .joints_with_role(Role::Hand)
        .find(|&j| profile.part_of[j] == Some(part))
}
