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

/// The canonical frame of a clip from its first frame (dataset-axes positions, one frame).
/// Facing is perpendicular to the left-to-right hip line across the up axis; shoulders are used
/// when the hips are missing or stacked vertically. `None` when neither gives a direction.
pub fn canonical_frame(first_frame: &[DVec3], profile: &Profile) -> Option<CanonicalFrame> {
    let pelvis = *first_frame.get(profile.root)?;
    let lateral = [
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
        let d = *first_frame.get(r)? - *first_frame.get(l)?;
        let h = DVec3::new(d.x, d.y, 0.0);
        (h.length() > 1e-6).then(|| h.normalize())
    })?;
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
