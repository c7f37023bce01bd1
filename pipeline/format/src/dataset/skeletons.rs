//! A row's frames turned into a [`Motion`] on its own skeleton, from its `skeletons.json` entry
//! (the file's type is [`crate::io::skeletons`], re-exported here).

use std::sync::Arc;

use glam::{DQuat, DVec3};

use super::ClipFrames;
pub use crate::io::skeletons::{
    CaptureAxes, NoBvhLayout, SkeletonEntry, SkeletonJoint, Skeletons, SkeletonsError,
    read_skeletons,
};
use motionforge_core::motion::profile::dataset_axes;
use motionforge_core::motion::{Motion, Skeleton};

/// Why a row cannot be put on its skeleton.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClipMotionError {
    /// The entry lacks the file-unit offsets or channels.
    #[error(transparent)]
    NoBvhLayout(#[from] NoBvhLayout),
    /// The skeleton and the row count different joints.
    #[error("skeleton `{skeleton}` has {skeleton_joints} joints, the row {row_joints}")]
    JointCount {
        /// The skeleton id.
        skeleton: String,
        /// Joints of the skeleton.
        skeleton_joints: usize,
        /// Joints of the row (`num_joints`).
        row_joints: usize,
    },
}

/// The motion of a row on its own skeleton, in capture units and axes: the inverse of the
/// writer's change to the dataset frame. Rotations are the stored ones (joint 0's turned back to
/// capture axes); a joint with position channels gets its translation from the stored world
/// positions (`W_parent⁻¹ (P_j − P_parent)` over the unit scale), every other joint its rest
/// offset.
pub fn clip_motion(frames: &ClipFrames, entry: &SkeletonEntry) -> Result<Motion, ClipMotionError> {
    let skeleton = entry.skeleton()?;
    let n = skeleton.len();
    if n != frames.info.joints {
        return Err(ClipMotionError::JointCount {
            skeleton: frames.info.skeleton.clone(),
            skeleton_joints: n,
            row_joints: frames.info.joints,
        });
    }
    let to_capture = dataset_axes(entry.capture_axes.up, entry.capture_axes.forward).inverse();
    Ok(motion_from_rows(
        skeleton,
        to_capture,
        entry.unit_scale,
        frames.info.fps,
        &frames.positions,
        &frames.rotations,
    ))
}

/// [`clip_motion`] from a row's arrays: `positions` (`frames × joints × 3`, dataset frame,
/// metres) and `rotations` (`frames × joints × 4`) on `skeleton`, whose capture axes are
/// `to_capture` from the dataset frame and whose file units are `scale` metres. Frames run as far
/// as both arrays hold whole frames.
pub fn motion_from_rows(
    skeleton: Skeleton,
    to_capture: DQuat,
    scale: f64,
    fps: f64,
    positions: &[f32],
    rotations: &[f32],
) -> Motion {
    let n = skeleton.len();
    let count = if n == 0 {
        0
    } else {
        (positions.len() / (n * 3)).min(rotations.len() / (n * 4))
    };
    let stored_rotations = rotations;
    let mut rotations = Vec::with_capacity(count * n);
    let mut translations = Vec::with_capacity(count * n);
    let mut world = vec![DQuat::IDENTITY; n];
    for f in 0..count {
        let p = &positions[f * n * 3..(f + 1) * n * 3];
        let at = |j: usize| {
            DVec3::new(
                f64::from(p[j * 3]),
                f64::from(p[j * 3 + 1]),
                f64::from(p[j * 3 + 2]),
            )
        };
        for (j, joint) in skeleton.joints.iter().enumerate() {
            let q = &stored_rotations[(f * n + j) * 4..(f * n + j) * 4 + 4];
            let stored = DQuat::from_xyzw(
                f64::from(q[0]),
                f64::from(q[1]),
                f64::from(q[2]),
                f64::from(q[3]),
            )
            .normalize();
            let (local, translation) = match joint.parent {
                None => (to_capture * stored, to_capture * at(j) / scale),
                Some(parent) => {
                    let t = if joint.has_position_channels() {
                        world[parent].inverse() * (at(j) - at(parent)) / scale
                    } else {
                        joint.offset
                    };
                    (stored, t)
                }
            };
            world[j] = match joint.parent {
                None => stored,
                Some(parent) => world[parent] * stored,
            };
            rotations.push(local);
            translations.push(translation);
        }
    }
    Motion {
        skeleton: Arc::new(skeleton),
        fps,
        rotations,
        translations,
    }
}
