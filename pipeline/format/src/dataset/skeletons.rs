//! `skeletons.json` read back, and a row's frames turned into a [`Motion`] on its own skeleton.
//!
//! Fields this reader does not know are ignored, so a writer may add some (a mirrored skeleton of
//! an asymmetric capture, for one) without breaking it.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use glam::{DQuat, DVec3};
use serde::Deserialize;

use super::{ClipFrames, DatasetError};
use motionforge_core::motion::profile::dataset_axes;
use motionforge_core::motion::{Channel, Joint, Motion, SignedAxis, Skeleton};

/// Every skeleton of a dataset, by skeleton id (the `skeleton` column).
pub type Skeletons = BTreeMap<String, SkeletonEntry>;

/// One entry of `skeletons.json`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct SkeletonEntry {
    /// The profile name.
    pub profile: String,
    /// The root-motion joint's name.
    pub root: String,
    /// The capture axes the profile declares.
    pub capture_axes: CaptureAxes,
    /// File units to metres.
    pub unit_scale: f64,
    /// Joints in table order.
    pub joints: Vec<SkeletonJoint>,
}

/// `capture_axes`: which file axes are up and forward.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct CaptureAxes {
    /// Up, e.g. `+y`.
    pub up: SignedAxis,
    /// Forward, e.g. `+z`.
    pub forward: SignedAxis,
}

/// One joint of a [`SkeletonEntry`].
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct SkeletonJoint {
    /// The joint's name.
    pub name: String,
    /// The parent's index; `None` for joint 0.
    pub parent: Option<usize>,
    /// Rest offset in metres, in the parent's frame.
    pub offset_m: [f64; 3],
    /// The left/right partner's name (itself for centre joints).
    #[serde(default)]
    pub mirror: Option<String>,
    /// SINC body part, if any.
    #[serde(default)]
    pub part: Option<String>,
    /// Role (`pelvis`, `hip`, `hand`, ...).
    #[serde(default)]
    pub role: Option<String>,
    /// Rest offset in file units as read (datasets written before schema 7's skeletons lack it).
    #[serde(default)]
    pub offset: Option<[f64; 3]>,
    /// BVH channels in file order.
    #[serde(default)]
    pub channels: Option<Vec<String>>,
    /// The end site's offset in file units.
    #[serde(default)]
    pub end_site: Option<[f64; 3]>,
}

/// Reads `<dataset>/skeletons.json`.
pub fn read_skeletons(dataset: &Path) -> Result<Skeletons, DatasetError> {
    let path = dataset.join(motionforge_core::base::layout::SKELETONS_FILE);
    let text = std::fs::read_to_string(&path).map_err(|source| DatasetError::Io {
        path: path.clone(),
        source,
    })?;
    let skeletons: Skeletons =
        serde_json::from_str(&text).map_err(|e| DatasetError::Skeletons {
            path: path.clone(),
            message: format!("line {}: {e}", e.line()),
        })?;
    for (id, s) in &skeletons {
        let bad = s
            .joints
            .iter()
            .enumerate()
            .find(|(j, joint)| match joint.parent {
                None => *j != 0,
                Some(p) => p >= *j,
            });
        if s.joints.is_empty() || bad.is_some() || !(s.unit_scale.is_finite() && s.unit_scale > 0.0)
        {
            return Err(DatasetError::Skeletons {
                path,
                message: format!(
                    "skeleton `{id}`: expected joints with parents before children, joint 0 the \
                     only root, and a positive unit_scale"
                ),
            });
        }
    }
    Ok(skeletons)
}

impl SkeletonEntry {
    /// Parent index per joint.
    pub fn parents(&self) -> Vec<Option<usize>> {
        self.joints.iter().map(|j| j.parent).collect()
    }

    /// The hierarchy as the capture file had it (offsets in file units, channels, end sites), or
    /// why the entry lacks what that needs.
    pub fn skeleton(&self) -> Result<Skeleton, String> {
        let mut joints = Vec::with_capacity(self.joints.len());
        for j in &self.joints {
            let (Some(offset), Some(channels)) = (j.offset, &j.channels) else {
                return Err(format!(
                    "joint `{}` has no `offset` or `channels`: the dataset was written before \
                     skeletons.json recorded them; rebuild it, or use export-bvh --config",
                    j.name
                ));
            };
            let channels = channels
                .iter()
                .map(|c| Channel::parse(c).ok_or_else(|| format!("`{c}` is not a BVH channel")))
                .collect::<Result<Vec<_>, _>>()?;
            joints.push(Joint {
                name: j.name.clone(),
                parent: j.parent,
                offset: DVec3::from_array(offset),
                channels,
                end_site: j.end_site.map(DVec3::from_array),
            });
        }
        Ok(Skeleton { joints })
    }
}

/// The motion of a row on its own skeleton, in capture units and axes: the inverse of the
/// writer's change to the dataset frame. Rotations are the stored ones (joint 0's turned back to
/// capture axes); a joint with position channels gets its translation from the stored world
/// positions (`W_parent⁻¹ (P_j − P_parent)` over the unit scale), every other joint its rest
/// offset.
pub fn clip_motion(frames: &ClipFrames, entry: &SkeletonEntry) -> Result<Motion, String> {
    let skeleton = entry.skeleton()?;
    let n = skeleton.len();
    if n != frames.info.joints {
        return Err(format!(
            "skeleton `{}` has {n} joints, the row {}",
            frames.info.skeleton, frames.info.joints
        ));
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
