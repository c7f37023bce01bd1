//! The joint hierarchy of a capture: names, parents, rest offsets and the BVH channel layout.

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

use crate::base::hex;

/// One BVH channel: a translation or a rotation about one axis of the joint's parent frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Channel {
    /// Translation along x.
    Xposition,
    /// Translation along y.
    Yposition,
    /// Translation along z.
    Zposition,
    /// Rotation about x, in degrees in the file.
    Xrotation,
    /// Rotation about y, in degrees in the file.
    Yrotation,
    /// Rotation about z, in degrees in the file.
    Zrotation,
}

impl Channel {
    /// Parses a channel name as BVH writes it (case-insensitive, as exporters vary).
    pub fn parse(name: &str) -> Option<Channel> {
        let lower = name.to_ascii_lowercase();
        Some(match lower.as_str() {
            "xposition" => Channel::Xposition,
            "yposition" => Channel::Yposition,
            "zposition" => Channel::Zposition,
            "xrotation" => Channel::Xrotation,
            "yrotation" => Channel::Yrotation,
            "zrotation" => Channel::Zrotation,
            _ => return None,
        })
    }

    /// The name BVH uses for this channel.
    pub fn name(self) -> &'static str {
        match self {
            Channel::Xposition => "Xposition",
            Channel::Yposition => "Yposition",
            Channel::Zposition => "Zposition",
            Channel::Xrotation => "Xrotation",
            Channel::Yrotation => "Yrotation",
            Channel::Zrotation => "Zrotation",
        }
    }

    /// True for the three position channels.
    pub fn is_position(self) -> bool {
        matches!(
            self,
            Channel::Xposition | Channel::Yposition | Channel::Zposition
        )
    }

    /// Axis index 0, 1, 2 for x, y, z.
    pub fn axis(self) -> usize {
        match self {
            Channel::Xposition | Channel::Xrotation => 0,
            Channel::Yposition | Channel::Yrotation => 1,
            Channel::Zposition | Channel::Zrotation => 2,
        }
    }

    /// The unit rotation about this channel's axis by `radians`.
    pub(crate) fn rotation(self, radians: f64) -> DQuat {
        match self.axis() {
            0 => DQuat::from_rotation_x(radians),
            1 => DQuat::from_rotation_y(radians),
            _ => DQuat::from_rotation_z(radians),
        }
    }
}

/// A joint of a [`Skeleton`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Joint {
    /// Name as written in the source file.
    pub name: String,
    /// Index of the parent joint; `None` for the root.
    pub parent: Option<usize>,
    /// Rest offset from the parent, in the source file's units.
    pub offset: DVec3,
    /// Channels in file order.
    pub channels: Vec<Channel>,
    /// Offset of the `End Site` below this joint, if the file has one.
    pub end_site: Option<DVec3>,
}

impl Joint {
    /// True when the joint has at least one position channel.
    pub fn has_position_channels(&self) -> bool {
        self.channels.iter().any(|c| c.is_position())
    }
}

/// A joint hierarchy. Joints are stored parents-first (depth-first file order), so a single forward
/// pass over the joints visits every parent before its children.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Skeleton {
    /// Joints, parents before children.
    pub joints: Vec<Joint>,
}

impl Skeleton {
    /// Number of joints (end sites excluded).
    pub fn len(&self) -> usize {
        self.joints.len()
    }

    /// True when the skeleton has no joint.
    pub fn is_empty(&self) -> bool {
        self.joints.is_empty()
    }

    /// Index of the joint with this exact name.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Joint names in order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.joints.iter().map(|j| j.name.as_str())
    }

    /// Parent index per joint.
    pub fn parents(&self) -> Vec<Option<usize>> {
        self.joints.iter().map(|j| j.parent).collect()
    }

    /// Children of joint `j`, in order.
    pub fn children(&self, j: usize) -> impl Iterator<Item = usize> + '_ {
        self.joints
            .iter()
            .enumerate()
            .filter(move |(_, joint)| joint.parent == Some(j))
            .map(|(i, _)| i)
    }

    /// Total number of channels per frame.
    pub fn channel_count(&self) -> usize {
        self.joints.iter().map(|j| j.channels.len()).sum()
    }

    /// A short, stable digest of names, parents, offsets and channels, used to tell skeletons apart.
    pub fn digest(&self) -> String {
        use sha2::{Digest, Sha256};
        let mut hasher = Sha256::new();
        for joint in &self.joints {
            hasher.update(joint.name.as_bytes());
            hasher.update([0]);
            hasher.update(
                joint
                    .parent
                    .map(|p| p as u64 + 1)
                    .unwrap_or(0)
                    .to_le_bytes(),
            );
            for v in joint.offset.to_array() {
                hasher.update(v.to_le_bytes());
            }
            for c in &joint.channels {
                hasher.update(c.name().as_bytes());
            }
        }
        hex(&hasher.finalize()[..8])
    }
}

/// One shared copy of each distinct skeleton. Clips read back from the stage cache each carry
/// their own copy (about 3 KB for Bandai Namco's), while a dataset has a handful of skeletons
/// (three in Bandai Namco 2's 2,902 captures); sharing them keeps held clips small.
#[derive(Debug, Default)]
pub struct SkeletonPool {
    seen: std::sync::Mutex<Vec<std::sync::Arc<Skeleton>>>,
}

/// Distinct skeletons kept at most; past that, a skeleton is left unshared rather than compared
/// with ever more.
const POOL_KEPT: usize = 256;

impl SkeletonPool {
    /// Points `skeleton` at the pool's copy of an equal skeleton, adding it when it is new.
    pub fn share(&self, skeleton: &mut std::sync::Arc<Skeleton>) {
        let Ok(mut seen) = self.seen.lock() else {
            return;
        };
        match seen
            .iter()
            .find(|s| std::sync::Arc::ptr_eq(s, skeleton) || ***s == **skeleton)
        {
            Some(shared) => *skeleton = std::sync::Arc::clone(shared),
            None if seen.len() < POOL_KEPT => seen.push(std::sync::Arc::clone(skeleton)),
            None => {}
        }
    }
}
