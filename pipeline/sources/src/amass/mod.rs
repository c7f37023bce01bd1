//! AMASS captures: `.npz` files of SMPL-H or SMPL-X pose parameters, turned into motions on the
//! body model's own skeleton with the user's body model (`docs/amass.md`).
//!
//! Joint positions follow the reference (smplx's `lbs`, as HumanML3D runs it): rest joints
//! `J = J_regressor · (v_template + shapedirs[..., :num_betas] · betas[:num_betas])`, axis-angle
//! to rotations as `batch_rodrigues` (angle `‖r + 1e-8‖`), the chain of `kintree_table[0]`, plus
//! `trans`. The motion holds exactly that chain: each joint's rest offset is `J_j − J_parent`
//! (the root's `J_0 + trans`, per frame), its local rotation the pose's, so the motion's forward
//! kinematics gives the reference's joints. No vertex is skinned: joints do not need it.
//!
//! Uses only [`motionforge_core::base`] and [`motionforge_core::motion`].

pub mod model;
pub mod npz;
pub mod sequence;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

pub use model::{BodyModel, Family, ModelError, ModelFault};
use motionforge_core::motion::{Channel, Joint, Motion, Skeleton};
pub use sequence::{
    AmassError, AmassErrorKind, FileGender, Sequence, ShapeFault, humanml3d_stride,
    is_not_a_motion, read_sequence,
};

/// Which body model a file gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum GenderChoice {
    /// The file's `gender` (str or bytes).
    #[default]
    File,
    /// The male model for every file.
    Male,
    /// The female model for every file.
    Female,
    /// The neutral model for every file.
    Neutral,
}

/// How an AMASS file's frame rate meets the dataset's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum FrameRateMode {
    /// Resample by time to the dataset rate, as every capture is.
    #[default]
    Resample,
    /// HumanML3D's pose_data step: every `int(fps / 20)`-th frame from frame 0, taken as 20 fps
    /// whatever the rate that gives (250 fps files: 20.83 fps; 59.99999 fps files: 30 fps).
    Humanml3d,
}

/// The rate HumanML3D's frames are taken at, whatever the stride gives.
pub const HUMANML3D_FPS: f64 = 20.0;

/// The gender folder (`male`, `female`, `neutral`) a file's model comes from. With
/// `humanml3d_quirk`, HumanML3D's choice: `bdata['gender'] == 'male'` is false for a bytes value,
/// so only a str `male` gets the male model and every other file the female one.
pub fn model_gender(
    choice: GenderChoice,
    stated: Option<&FileGender>,
    humanml3d_quirk: bool,
) -> Result<&'static str, String> {
    match choice {
        GenderChoice::Male => return Ok("male"),
        GenderChoice::Female => return Ok("female"),
        GenderChoice::Neutral => return Ok("neutral"),
        GenderChoice::File => {}
    }
    if humanml3d_quirk {
        return Ok(match stated {
            Some(g) if !g.bytes && g.value == "male" => "male",
            _ => "female",
        });
    }
    let Some(g) = stated else {
        return Err(
            "no `gender` in the file; set sources.amass.gender to the model to use".to_string(),
        );
    };
    match g.value.to_ascii_lowercase().as_str() {
        "male" => Ok("male"),
        "female" => Ok("female"),
        "neutral" => Ok("neutral"),
        other => Err(format!(
            "`gender` is {other:?}; expected male, female or neutral (or set sources.amass.gender)"
        )),
    }
}

/// The model file of a family and gender in a body model folder laid out as AMASS documents it.
pub fn model_path(folder: &Path, family: Family, gender: &str) -> PathBuf {
    folder.join(family.folder()).join(gender).join("model.npz")
}

/// Every model file a body model folder has, in a fixed order.
pub fn model_files(folder: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for family in [Family::SmplH, Family::SmplX] {
        for gender in ["female", "male", "neutral"] {
            let path = model_path(folder, family, gender);
            if path.is_file() {
                out.push(path);
            }
        }
    }
    out
}

/// What identifies a file's content without reading it: path, length and modification time.
type FileKey = (PathBuf, u64, Option<std::time::SystemTime>);

fn file_key(path: &Path) -> Option<FileKey> {
    let meta = std::fs::metadata(path).ok()?;
    Some((path.to_path_buf(), meta.len(), meta.modified().ok()))
}

/// Models are read once per process: a build reads thousands of files on a few models.
type Loaded = Result<Arc<BodyModel>, ModelError>;

fn loaded() -> &'static Mutex<HashMap<(FileKey, usize), Loaded>> {
    static LOADED: OnceLock<Mutex<HashMap<(FileKey, usize), Loaded>>> = OnceLock::new();
    LOADED.get_or_init(Default::default)
}

/// The model at `path` with `num_betas` shape coefficients, read once per process (and again
/// when the file changes).
pub fn load_model(path: &Path, num_betas: usize) -> Loaded {
    let Some(key) = file_key(path) else {
        return Err(ModelError::NotFound {
            path: path.to_path_buf(),
        });
    };
    let key = (key, num_betas);
    if let Ok(map) = loaded().lock()
        && let Some(found) = map.get(&key)
    {
        return found.clone();
    }
    let model = BodyModel::load(path, num_betas).map(Arc::new);
    if let Ok(mut map) = loaded().lock() {
        // A handful of models exist; a bound keeps a long-running service from growing.
        if map.len() >= 64 {
            map.clear();
        }
        map.insert(key, model.clone());
    }
    model
}

/// A digest of every model file in a body model folder (their paths below it and contents),
/// hashed once per process per file version: what a capture's ingest depends on besides its bytes.
pub fn models_digest(folder: &Path) -> String {
    static DIGESTS: OnceLock<Mutex<HashMap<FileKey, String>>> = OnceLock::new();
    let digests = DIGESTS.get_or_init(Default::default);
    use sha2::{Digest, Sha256};
    let mut all = Sha256::new();
    for path in model_files(folder) {
        let relative = path.strip_prefix(folder).unwrap_or(&path);
        all.update(relative.to_string_lossy().as_bytes());
        all.update([0]);
        let Some(key) = file_key(&path) else {
            continue;
        };
        let known = digests.lock().ok().and_then(|m| m.get(&key).cloned());
        let sha = match known {
            Some(sha) => sha,
            None => {
                let sha = match std::fs::read(&path) {
                    Ok(bytes) => motionforge_core::base::sha256_hex(&bytes),
                    Err(e) => format!("unreadable: {e}"),
                };
                if let Ok(mut m) = digests.lock() {
                    m.insert(key, sha.clone());
                }
                sha
            }
        };
        all.update(sha.as_bytes());
    }
    motionforge_core::base::hex(&all.finalize()[..16])
}

/// Why a sequence and a model do not make a motion.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// The model's joint count is not the family's.
    #[error(
        "body model {path} has {found} joints (`kintree_table`) but {family} poses need {expected}"
    )]
    Joints {
        /// The model file.
        path: PathBuf,
        /// The family, for people.
        family: &'static str,
        /// Joints in the model.
        found: usize,
        /// Joints the poses hold.
        expected: usize,
    },
    /// Fewer shape coefficients than `num_betas`.
    #[error("`betas` holds {found} values; num_betas = {needed} needs at least that many")]
    Betas {
        /// Values stored.
        found: usize,
        /// `num_betas`.
        needed: usize,
    },
}

/// The rotation of one axis-angle vector as smplx's `batch_rodrigues` makes it: the angle is
/// `‖r + 1e-8‖` (so a zero vector is the identity) about the direction of `r`.
pub fn rodrigues(r: DVec3) -> DQuat {
    let angle = (r + DVec3::splat(1e-8)).length();
    let (sin, cos) = (0.5 * angle).sin_cos();
    // `r / angle` is the reference's axis; its length differs from 1 by 1e-8 at most, and the
    // quaternion is normalised.
    let axis = r / angle;
    DQuat::from_xyzw(axis.x * sin, axis.y * sin, axis.z * sin, cos).normalize()
}

/// The skeleton of a body model for shape `betas`: the family's joint names, `kintree_table`'s
/// parents, rest offsets `J_j − J_parent` in metres (the root's `J_0`).
pub fn skeleton(family: Family, model: &BodyModel, rest: &[DVec3]) -> Skeleton {
    let names = family.names();
    let joints = model
        .parents
        .iter()
        .enumerate()
        .map(|(j, parent)| {
            let rotation = vec![Channel::Zrotation, Channel::Yrotation, Channel::Xrotation];
            let (offset, channels) = match parent {
                None => (
                    rest[j],
                    [Channel::Xposition, Channel::Yposition, Channel::Zposition]
                        .into_iter()
                        .chain(rotation)
                        .collect(),
                ),
                Some(p) => (rest[j] - rest[*p], rotation),
            };
            Joint {
                name: names
                    .get(j)
                    .map_or_else(|| format!("joint{j}"), |n| n.to_string()),
                parent: *parent,
                offset,
                channels,
                end_site: None,
            }
        })
        .collect();
    Skeleton { joints }
}

/// The motion of `sequence` on `model`'s skeleton: frames `0, stride, 2·stride, …` labelled at
/// `fps`. Its forward kinematics gives the reference's joint positions.
pub fn to_motion(
    sequence: &Sequence,
    model: &BodyModel,
    stride: usize,
    fps: f64,
) -> Result<Motion, FitError> {
    let family = sequence.family;
    let n = family.joints();
    if model.joints() != n {
        return Err(FitError::Joints {
            path: model.path.clone(),
            family: match family {
                Family::SmplH => "SMPL-H",
                Family::SmplX => "SMPL-X",
            },
            found: model.joints(),
            expected: n,
        });
    }
    if sequence.betas.len() < model.num_betas {
        return Err(FitError::Betas {
            found: sequence.betas.len(),
            needed: model.num_betas,
        });
    }
    let rest = model.rest_joints(&sequence.betas);
    let skeleton = Arc::new(skeleton(family, model, &rest));
    let stride = stride.max(1);
    let kept = sequence.frames.div_ceil(stride);
    let mut rotations = Vec::with_capacity(kept * n);
    let mut translations = Vec::with_capacity(kept * n);
    for f in (0..sequence.frames).step_by(stride) {
        let pose = &sequence.poses[f * 3 * n..(f + 1) * 3 * n];
        for (j, joint) in skeleton.joints.iter().enumerate() {
            rotations.push(rodrigues(DVec3::from_slice(&pose[3 * j..3 * j + 3])));
            translations.push(match joint.parent {
                None => rest[j] + sequence.trans[f],
                Some(_) => joint.offset,
            });
        }
    }
    Ok(Motion {
        skeleton,
        fps,
        rotations,
        translations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stated(value: &str, bytes: bool) -> FileGender {
        FileGender {
            value: value.into(),
            bytes,
        }
    }

    #[test]
    fn the_file_gender_is_read_from_str_and_bytes_alike_unless_the_quirk_is_asked_for() {
        let file = GenderChoice::File;
        assert_eq!(
            model_gender(file, Some(&stated("male", true)), false),
            Ok("male")
        );
        assert_eq!(
            model_gender(file, Some(&stated("female", false)), false),
            Ok("female")
        );
        assert!(
            model_gender(file, None, false)
                .unwrap_err()
                .contains("no `gender`")
        );
        assert!(model_gender(file, Some(&stated("m", false)), false).is_err());
        // HumanML3D: `bdata['gender'] == 'male'` is false for bytes, so female.
        assert_eq!(
            model_gender(file, Some(&stated("male", true)), true),
            Ok("female")
        );
        assert_eq!(
            model_gender(file, Some(&stated("male", false)), true),
            Ok("male")
        );
        assert_eq!(
            model_gender(file, Some(&stated("neutral", false)), true),
            Ok("female")
        );
        assert_eq!(model_gender(file, None, true), Ok("female"));
        // A gender set in the config wins over both.
        let bytes_male = stated("male", true);
        assert_eq!(
            model_gender(GenderChoice::Neutral, Some(&bytes_male), true),
            Ok("neutral")
        );
    }

    #[test]
    fn rodrigues_is_the_rotation_by_the_vectors_length_and_zero_is_the_identity() {
        assert!(rodrigues(DVec3::ZERO).angle_between(DQuat::IDENTITY) < 1e-7);
        let r = DVec3::new(0.3, -1.2, 2.0);
        let expected = DQuat::from_axis_angle(r.normalize(), r.length());
        assert!(rodrigues(r).angle_between(expected) < 1e-7);
    }

    #[test]
    fn humanml3d_strides_match_the_notebook() {
        assert_eq!(humanml3d_stride(120.0), (6, 20.0));
        assert_eq!(humanml3d_stride(100.0).0, 5);
        let (stride, rate) = humanml3d_stride(250.0);
        assert_eq!(stride, 12);
        assert!((rate - 20.833333).abs() < 1e-6);
        let (stride, rate) = humanml3d_stride(59.99999);
        assert_eq!(stride, 2);
        assert!((rate - 29.999995).abs() < 1e-9);
        assert_eq!(humanml3d_stride(15.0), (1, 15.0));
    }
}
