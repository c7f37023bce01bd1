//! `skeletons.json`: every skeleton of a dataset by id, as one typed value that the writer
//! serialises and every reader (`export-bvh`, `preview`, the exports, the gallery, the service)
//! deserialises.
//!
//! Fields a reader does not know are ignored, so a writer may add some without breaking older
//! readers; fields added after the first datasets were written (`offset`, `channels`, ...) are
//! optional.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use glam::DVec3;

use motionforge_core::motion::{BodyPart, Channel, Joint, Role, SignedAxis, Skeleton};

// Fields are declared in alphabetical order: the file's keys have always been sorted, and a
// struct serialises in declaration order.

/// Every skeleton of a dataset, by skeleton id (the `skeleton` column).
pub type Skeletons = BTreeMap<String, SkeletonEntry>;

/// One entry of `skeletons.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkeletonEntry {
    /// The capture axes the profile declares.
    pub capture_axes: CaptureAxes,
    /// Joints in table order.
    pub joints: Vec<SkeletonJoint>,
    /// For a mirrored clip's own skeleton: the id of the skeleton it reflects.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mirror_of: Option<String>,
    /// The profile name.
    pub profile: String,
    /// The root-motion joint's name.
    pub root: String,
    /// File units to metres.
    pub unit_scale: f64,
}

/// `capture_axes`: which file axes are up and forward.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CaptureAxes {
    /// Forward, e.g. `+z`.
    pub forward: SignedAxis,
    /// Up, e.g. `+y`.
    pub up: SignedAxis,
}

/// One joint of a [`SkeletonEntry`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkeletonJoint {
    /// BVH channels in file order (datasets written before schema 7's skeletons lack them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub channels: Option<Vec<Channel>>,
    /// The end site's offset in file units (written as `null` for joints without one).
    #[serde(default)]
    pub end_site: Option<[f64; 3]>,
    /// The left/right partner's name (itself for centre joints).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mirror: Option<String>,
    /// The joint's name.
    pub name: String,
    /// Rest offset in file units as read (datasets written before schema 7's skeletons lack it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset: Option<[f64; 3]>,
    /// Rest offset in metres, in the parent's frame.
    pub offset_m: [f64; 3],
    /// The parent's index; `None` for joint 0.
    pub parent: Option<usize>,
    /// SINC body part, if any (written as `null` for joints of none).
    #[serde(default)]
    pub part: Option<BodyPart>,
    /// Role (`pelvis`, `hip`, `hand`, ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub role: Option<Role>,
}

impl SkeletonEntry {
    /// Parent index per joint.
    pub fn parents(&self) -> Vec<Option<usize>> {
        self.joints.iter().map(|j| j.parent).collect()
    }

    /// The hierarchy as the capture file had it (offsets in file units, channels, end sites).
    pub fn skeleton(&self) -> Result<Skeleton, NoBvhLayout> {
        let mut joints = Vec::with_capacity(self.joints.len());
        for j in &self.joints {
            let (Some(offset), Some(channels)) = (j.offset, &j.channels) else {
                return Err(NoBvhLayout {
                    joint: j.name.clone(),
                });
            };
            joints.push(Joint {
                name: j.name.clone(),
                parent: j.parent,
                offset: DVec3::from_array(offset),
                channels: channels.clone(),
                end_site: j.end_site.map(DVec3::from_array),
            });
        }
        Ok(Skeleton { joints })
    }
}

/// A [`SkeletonEntry`] without what a BVH of it needs: written before `skeletons.json` recorded
/// file-unit offsets and channels.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "joint `{joint}` has no `offset` or `channels`: the dataset was written before \
     skeletons.json recorded them; rebuild it, or use export-bvh --config"
)]
pub struct NoBvhLayout {
    /// The first joint that lacks them.
    pub joint: String,
}

/// Why `skeletons.json` cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum SkeletonsError {
    /// The file cannot be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The file is not JSON of skeletons (the parser's message gives the line and column).
    #[error("{}: not a motionforge skeletons.json: {source}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: serde_json::Error,
    },
    /// A skeleton has no joints.
    #[error("{}: skeleton `{skeleton}` has no joints", path.display())]
    NoJoints {
        /// The file.
        path: PathBuf,
        /// The skeleton id.
        skeleton: String,
    },
    /// A joint's parent does not come before it, or a joint other than joint 0 has none.
    #[error(
        "{}: skeleton `{skeleton}`: joint {joint} (`{name}`) has parent {parent:?}; expected \
         parents before children and joint 0 the only root",
        path.display()
    )]
    JointOrder {
        /// The file.
        path: PathBuf,
        /// The skeleton id.
        skeleton: String,
        /// The joint's index.
        joint: usize,
        /// The joint's name.
        name: String,
        /// Its parent index.
        parent: Option<usize>,
    },
    /// `unit_scale` is not a positive number.
    #[error(
        "{}: skeleton `{skeleton}`: unit_scale is {unit_scale}, expected a positive number",
        path.display()
    )]
    UnitScale {
        /// The file.
        path: PathBuf,
        /// The skeleton id.
        skeleton: String,
        /// The value found.
        unit_scale: f64,
    },
}

/// Reads `<dataset>/skeletons.json` and checks every skeleton's hierarchy and unit scale.
pub fn read_skeletons(dataset: &Path) -> Result<Skeletons, SkeletonsError> {
    let path = dataset.join(motionforge_core::base::layout::SKELETONS_FILE);
    let bytes = std::fs::read(&path).map_err(|source| SkeletonsError::Io {
        path: path.clone(),
        source,
    })?;
    let skeletons: Skeletons =
        serde_json::from_slice(&bytes).map_err(|source| SkeletonsError::Json {
            path: path.clone(),
            source,
        })?;
    for (id, s) in &skeletons {
        check_entry(&path, id, s)?;
    }
    Ok(skeletons)
}

fn check_entry(path: &Path, id: &str, s: &SkeletonEntry) -> Result<(), SkeletonsError> {
    if s.joints.is_empty() {
        return Err(SkeletonsError::NoJoints {
            path: path.to_path_buf(),
            skeleton: id.to_string(),
        });
    }
    let misplaced = s
        .joints
        .iter()
        .enumerate()
        .find(|(j, joint)| match joint.parent {
            None => *j != 0,
            Some(p) => p >= *j,
        });
    if let Some((j, joint)) = misplaced {
        return Err(SkeletonsError::JointOrder {
            path: path.to_path_buf(),
            skeleton: id.to_string(),
            joint: j,
            name: joint.name.clone(),
            parent: joint.parent,
        });
    }
    if !(s.unit_scale.is_finite() && s.unit_scale > 0.0) {
        return Err(SkeletonsError::UnitScale {
            path: path.to_path_buf(),
            skeleton: id.to_string(),
            unit_scale: s.unit_scale,
        });
    }
    Ok(())
}

/// The text of `skeletons.json` as written: pretty JSON, keys sorted. The same text goes into
/// every shard's key-value metadata (`motionforge.skeletons`).
pub fn skeletons_json(skeletons: &Skeletons) -> String {
    // Nothing in the type can fail to serialise (string keys, plain values).
    serde_json::to_string_pretty(skeletons).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_entry_round_trips_and_unknown_fields_are_ignored() {
        let text = r#"{"s": {"capture_axes": {"forward": "+z", "up": "+y"},
            "joints": [{"channels": ["Xposition", "Zrotation"], "end_site": null,
                        "mirror": "Hips", "name": "Hips", "offset": [0.0, 1.0, 0.0],
                        "offset_m": [0.0, 0.01, 0.0], "parent": null, "part": "global",
                        "role": "pelvis", "later": 1}],
            "profile": "cmu", "root": "Hips", "unit_scale": 0.01, "extra": true}}"#;
        let skeletons: Skeletons = serde_json::from_str(text).unwrap();
        let entry = &skeletons["s"];
        assert_eq!(entry.joints[0].part, Some(BodyPart::Global));
        assert_eq!(entry.joints[0].role, Some(Role::Pelvis));
        assert_eq!(
            entry.joints[0].channels,
            Some(vec![Channel::Xposition, Channel::Zrotation])
        );
        let again: Skeletons = serde_json::from_str(&skeletons_json(&skeletons)).unwrap();
        assert_eq!(again, skeletons);
    }

    #[test]
    fn a_joint_before_its_parent_is_refused_by_name() {
        let dir = std::env::temp_dir().join(format!("mf-skeletons-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let text = r#"{"s": {"capture_axes": {"forward": "+z", "up": "+y"},
            "joints": [{"name": "a", "offset_m": [0, 0, 0], "parent": null},
                       {"name": "b", "offset_m": [0, 0, 0], "parent": 1}],
            "profile": "p", "root": "a", "unit_scale": 1.0}}"#;
        std::fs::write(dir.join("skeletons.json"), text).unwrap();
        let e = read_skeletons(&dir).unwrap_err();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(
            matches!(&e, SkeletonsError::JointOrder { joint: 1, name, .. } if name == "b"),
            "{e}"
        );
    }
}
