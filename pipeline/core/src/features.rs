//! Derived per-frame features written beside the motion columns, each switchable in the config:
//! 6D rotations (TEMOS/SINC), joint velocities, foot contacts (HumanML3D's velocity test), and
//! future root positions and headings at +10/+20/+30 frames (LAMA's motion-matching features).

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

use crate::motion::{BodyPart, Profile, Role};

/// Which derived columns to write.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FeatureConfig {
    /// `rotations_6d`: the first two columns of each local rotation matrix.
    pub rotations_6d: bool,
    /// `joint_velocities`: per-joint velocity in m/s (dataset axes).
    pub velocities: bool,
    /// `foot_contacts`: left ankle, left toe, right ankle, right toe in contact.
    pub foot_contacts: bool,
    /// `future_root`: root position and heading at +10/+20/+30 frames, in the current frame's
    /// heading frame.
    pub future_root: bool,
    /// A foot joint is in contact when slower than this (m/s). Default 0.894 m/s: HumanML3D's
    /// squared displacement of 0.002 m² per frame at 20 fps.
    pub contact_speed: f64,
}

impl Default for FeatureConfig {
    fn default() -> Self {
        FeatureConfig {
            rotations_6d: false,
            velocities: false,
            foot_contacts: true,
            future_root: true,
            contact_speed: 0.002f64.sqrt() * 20.0,
        }
    }
}

/// Frames ahead for the future root features.
pub const FUTURE_FRAMES: [usize; 3] = [10, 20, 30];

/// Derived features of one clip, each `None` when switched off.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Features {
    /// `frames × joints × 6`.
    pub rotations_6d: Option<Vec<f32>>,
    /// `frames × joints × 3`, m/s.
    pub velocities: Option<Vec<f32>>,
    /// `frames × 4`.
    pub foot_contacts: Option<Vec<bool>>,
    /// `frames × 3 × 3`: for +10/+20/+30 frames, (x right, y forward) metres and heading change
    /// in radians (counter-clockwise positive), relative to the current frame.
    pub future_root: Option<Vec<f32>>,
}

fn heading(positions: &[[f32; 3]], n: usize, f: usize, hips: Option<(usize, usize)>) -> f64 {
    let Some((l, r)) = hips else { return 0.0 };
    let (pl, pr) = (positions[f * n + l], positions[f * n + r]);
    // Angle of the left-to-right hip line in the ground plane: 0 when the character's right is
    // +x (facing +y), increasing counter-clockwise seen from above.
    let (rx, ry) = ((pr[0] - pl[0]) as f64, (pr[1] - pl[1]) as f64);
    ry.atan2(rx)
}

/// Computes the switched-on features from dataset-frame positions (metres, z up) and local
/// rotations (x, y, z, w).
pub fn features(
    positions: &[f32],
    rotations: &[f32],
    joints: usize,
    fps: f64,
    profile: &Profile,
    config: &FeatureConfig,
) -> Features {
    let frames = if joints == 0 {
        0
    } else {
        positions.len() / (joints * 3)
    };
    let pos: Vec<[f32; 3]> = positions
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let mut out = Features::default();
    if config.rotations_6d {
        let mut v = Vec::with_capacity(frames * joints * 6);
        for q in rotations.chunks_exact(4) {
            let m = glam::DMat3::from_quat(DQuat::from_xyzw(
                q[0] as f64,
                q[1] as f64,
                q[2] as f64,
                q[3] as f64,
            ));
            v.extend(
                [
                    m.x_axis.x, m.x_axis.y, m.x_axis.z, m.y_axis.x, m.y_axis.y, m.y_axis.z,
                ]
                .map(|x| x as f32),
            );
        }
        out.rotations_6d = Some(v);
    }
    // Velocity at frame f: (p[f+1] - p[f]) · fps; the last frame repeats the one before.
    let velocity = |f: usize, j: usize| -> DVec3 {
        if frames < 2 {
            return DVec3::ZERO;
        }
        let f = f.min(frames - 2);
        let a = pos[f * joints + j];
        let b = pos[(f + 1) * joints + j];
        DVec3::new(
            (b[0] - a[0]) as f64,
            (b[1] - a[1]) as f64,
            (b[2] - a[2]) as f64,
        ) * fps
    };
    if config.velocities {
        let mut v = Vec::with_capacity(frames * joints * 3);
        for f in 0..frames {
            for j in 0..joints {
                let d = velocity(f, j);
                v.extend([d.x as f32, d.y as f32, d.z as f32]);
            }
        }
        out.velocities = Some(v);
    }
    let side = |role: Role, part: BodyPart| {
        profile
            .joints_with_role(role)
            .find(|&j| profile.part_of[j] == Some(part))
    };
    if config.foot_contacts {
        let feet = [
            side(Role::Ankle, BodyPart::LeftLeg),
            side(Role::Toe, BodyPart::LeftLeg),
            side(Role::Ankle, BodyPart::RightLeg),
            side(Role::Toe, BodyPart::RightLeg),
        ];
        let mut v = Vec::with_capacity(frames * 4);
        for f in 0..frames {
            for foot in feet {
                v.push(foot.is_some_and(|j| velocity(f, j).length() < config.contact_speed));
            }
        }
        out.foot_contacts = Some(v);
    }
    if config.future_root {
        let hips = side(Role::Hip, BodyPart::LeftLeg).zip(side(Role::Hip, BodyPart::RightLeg));
        let root = profile.root;
        let mut v = Vec::with_capacity(frames * 9);
        for f in 0..frames {
            let h = heading(&pos, joints, f, hips);
            let here = pos[f * joints + root];
            for k in FUTURE_FRAMES {
                let g = (f + k).min(frames - 1);
                let there = pos[g * joints + root];
                let (dx, dy) = ((there[0] - here[0]) as f64, (there[1] - here[1]) as f64);
                // Into the current heading frame: forward is +y, right is +x.
                let (s, c) = (h.sin(), h.cos());
                let right = dx * c + dy * s;
                let forward = -dx * s + dy * c;
                let mut turn = heading(&pos, joints, g, hips) - h;
                turn = (turn + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                v.extend([right as f32, forward as f32, turn as f32]);
            }
        }
        out.future_root = Some(v);
    }
    out
}
