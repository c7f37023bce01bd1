//! Skeleton profiles: what each joint is (role, side, body part), how the capture's axes and units
//! map to the dataset's, and the per-joint reflections that mirror local rotations.
//!
//! Profiles are data (`schemas/skeletons/*.toml`); five are bundled: Bandai Namco, CMU (cgspeed
//! BVH), the SMPL 22-joint order, and the SMPL-H and SMPL-X body models of AMASS captures.

use std::collections::BTreeMap;
use std::fmt;

use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

use super::skeleton::Skeleton;

/// A world or joint axis with a sign, as written in profiles: `+x`, `-z`, ...
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct SignedAxis {
    /// 0, 1, 2 for x, y, z.
    pub axis: usize,
    /// `true` for the negative direction.
    pub negative: bool,
}

impl SignedAxis {
    /// The unit vector.
    pub fn vector(self) -> DVec3 {
        let mut v = DVec3::ZERO;
        v[self.axis] = if self.negative { -1.0 } else { 1.0 };
        v
    }
}

/// The rotation taking capture axes (`up`, `forward`) to dataset axes: x right, y forward, z up
/// (right-handed).
pub fn dataset_axes(up: SignedAxis, forward: SignedAxis) -> DQuat {
    let (up, forward) = (up.vector(), forward.vector());
    let right = forward.cross(up);
    // Rows are the capture-frame directions that become x, y, z.
    DQuat::from_mat3(&DMat3::from_cols(right, forward, up).transpose())
}

impl TryFrom<String> for SignedAxis {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        let t = s.trim().to_ascii_lowercase();
        let (negative, rest) = match t.strip_prefix('-') {
            Some(r) => (true, r),
            None => (false, t.strip_prefix('+').unwrap_or(&t)),
        };
        let axis = match rest {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => {
                return Err(format!(
                    "`{s}` is not an axis (expected one of +x, -x, +y, -y, +z, -z)"
                ));
            }
        };
        Ok(SignedAxis { axis, negative })
    }
}

impl From<SignedAxis> for String {
    fn from(a: SignedAxis) -> String {
        a.to_string()
    }
}

impl fmt::Display for SignedAxis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}{}",
            if self.negative { '-' } else { '+' },
            ['x', 'y', 'z'][self.axis]
        )
    }
}

/// A reflection that flips an odd number of axes (determinant -1): the `B_j` of the mirroring rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "lowercase")]
pub enum Reflection {
    /// Flip x: `diag(-1, 1, 1)`.
    X,
    /// Flip y: `diag(1, -1, 1)`.
    Y,
    /// Flip z: `diag(1, 1, -1)`.
    Z,
    /// Flip all three: `-I`.
    Xyz,
}

impl Reflection {
    /// All four candidates, in tie-break order.
    pub const ALL: [Reflection; 4] = [Reflection::X, Reflection::Y, Reflection::Z, Reflection::Xyz];

    /// The reflection that flips one axis.
    pub fn across(axis: usize) -> Reflection {
        match axis {
            0 => Reflection::X,
            1 => Reflection::Y,
            _ => Reflection::Z,
        }
    }

    /// Applies the reflection to a vector.
    pub fn apply(self, v: DVec3) -> DVec3 {
        match self {
            Reflection::X => DVec3::new(-v.x, v.y, v.z),
            Reflection::Y => DVec3::new(v.x, -v.y, v.z),
            Reflection::Z => DVec3::new(v.x, v.y, -v.z),
            Reflection::Xyz => -v,
        }
    }

    /// The rotation `-B` (determinant +1) as a quaternion. Since `B = -(-B)`, the sign cancels in
    /// `B_p R B_j⁻¹`, which is therefore `q(-B_p) · R · q(-B_j)⁻¹` in quaternions.
    pub fn negated_rotation(self) -> DQuat {
        match self {
            Reflection::X => DQuat::from_xyzw(1.0, 0.0, 0.0, 0.0),
            Reflection::Y => DQuat::from_xyzw(0.0, 1.0, 0.0, 0.0),
            Reflection::Z => DQuat::from_xyzw(0.0, 0.0, 1.0, 0.0),
            Reflection::Xyz => DQuat::IDENTITY,
        }
    }
}

/// The six body parts of SINC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BodyPart {
    /// Root rotation and translation.
    Global,
    /// Spine, neck and head.
    Torso,
    /// Left collar to left hand.
    LeftArm,
    /// Right collar to right hand.
    RightArm,
    /// Left hip to left toes.
    LeftLeg,
    /// Right hip to right toes.
    RightLeg,
}

impl BodyPart {
    /// All parts in SINC's vector order `[global, torso, left arm, right arm, left leg, right leg]`.
    pub const ALL: [BodyPart; 6] = [
        BodyPart::Global,
        BodyPart::Torso,
        BodyPart::LeftArm,
        BodyPart::RightArm,
        BodyPart::LeftLeg,
        BodyPart::RightLeg,
    ];

    /// The same part on the other side.
    pub fn mirrored(self) -> BodyPart {
        match self {
            BodyPart::LeftArm => BodyPart::RightArm,
            BodyPart::RightArm => BodyPart::LeftArm,
            BodyPart::LeftLeg => BodyPart::RightLeg,
            BodyPart::RightLeg => BodyPart::LeftLeg,
            other => other,
        }
    }
}

/// What a joint is anatomically; used for feet, hands and facing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// A static or auxiliary root above the pelvis.
    Root,
    /// The pelvis: the root-motion joint.
    Pelvis,
    /// A spine joint.
    Spine,
    /// Neck.
    Neck,
    /// Head.
    Head,
    /// Collar bone (clavicle).
    Collar,
    /// Shoulder / upper arm.
    Shoulder,
    /// Elbow / forearm.
    Elbow,
    /// Wrist / hand.
    Hand,
    /// Finger or thumb.
    Finger,
    /// Hip / thigh.
    Hip,
    /// Knee / shin.
    Knee,
    /// Ankle / foot.
    Ankle,
    /// Toes.
    Toe,
    /// Anything else.
    Other,
}

/// A profile as written in TOML.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProfileSpec {
    /// Profile name (`bandai-namco`, `cmu`, `smpl-22`).
    pub name: String,
    /// One line on what skeleton this is.
    #[serde(default)]
    pub description: String,
    /// The capture's up axis.
    pub up: SignedAxis,
    /// The capture's forward axis (the way the character faces at rest or at the start of takes).
    pub forward: SignedAxis,
    /// File units to metres.
    pub unit_scale: f64,
    /// The root-motion joint (pelvis); its world position is the clip's root trajectory.
    pub root: String,
    /// Joint names in order, for skeletons that come without a hierarchy (joint-position arrays).
    #[serde(default)]
    pub joints: Vec<String>,
    /// Parent of each joint in `joints` (-1 for the root).
    #[serde(default)]
    pub parents: Vec<i64>,
    /// Joints whose translation channels carry motion (mirrored like the root); other joints keep
    /// their own translation values, so a mirrored motion stays on the original skeleton.
    #[serde(default)]
    pub motion_joints: Vec<String>,
    /// Left/right pairs that name detection misses or gets wrong.
    #[serde(default)]
    pub pairs: BTreeMap<String, String>,
    /// Joints of each body part.
    pub parts: BTreeMap<BodyPart, Vec<String>>,
    /// Role of each named joint; unnamed joints are `other`.
    #[serde(default)]
    pub roles: BTreeMap<String, Role>,
    /// Per-joint reflection `B_j` for mirroring local rotations (calibrated; see `docs/mirroring.md`).
    #[serde(default)]
    pub reflections: BTreeMap<String, Reflection>,
    /// Where SMPL's 22 body joints are on this skeleton, by SMPL joint name (`pelvis`,
    /// `left_hip`, ...): what the HumanML3D export places them by (`docs/humanml3d.md`).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub smpl22: BTreeMap<String, SmplJoint>,
}

/// Where one SMPL body joint is on another skeleton.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum SmplJoint {
    /// At a joint of the skeleton.
    Joint(String),
    /// On the line between two joints, `at` of the way from the first (for rigs with fewer
    /// spine joints than SMPL).
    Between {
        /// The two joints.
        between: [String; 2],
        /// 0 at the first, 1 at the second.
        at: f64,
    },
}

/// SMPL's 22 body joints placed on a skeleton: for each, two joint indices and the weight of the
/// second (0 for a joint of the skeleton itself).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmplPlacement(pub [(usize, usize, f64); 22]);

impl SmplPlacement {
    /// SMPL's body joints of one frame of `frame` (positions of the skeleton's joints).
    pub fn place(&self, frame: &[DVec3]) -> [DVec3; 22] {
        self.0.map(|(a, b, t)| frame[a].lerp(frame[b], t))
    }
}

/// Errors binding a profile to a skeleton.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProfileError {
    /// The profile TOML does not parse.
    #[error("profile `{name}`: {source}")]
    Parse {
        /// Profile name or file.
        name: String,
        /// The parser's error.
        source: toml::de::Error,
    },
    /// No bundled profile of that name.
    #[error(
        "no bundled skeleton profile `{0}` (bundled: bandai-namco, cmu, smpl-22, smplh-52, smplx-55)"
    )]
    Unknown(String),
    /// The profile names a joint the skeleton lacks.
    #[error(
        "profile `{profile}` names joint `{joint}` in {field}, which the skeleton does not have"
    )]
    MissingJoint {
        /// Profile name.
        profile: String,
        /// Joint name.
        joint: String,
        /// Which profile field names it.
        field: &'static str,
    },
    /// Left/right pairs that do not form a mirror-symmetric hierarchy.
    #[error("profile `{profile}`: left/right pairs are not symmetric: {fault}")]
    Asymmetric {
        /// Profile name.
        profile: String,
        /// What is inconsistent.
        fault: SymmetryFault,
    },
    /// Up and forward are the same axis.
    #[error("profile `{0}`: up and forward axes must differ")]
    Axes(String),
    /// The profile does not say where SMPL's body joints are.
    #[error(
        "profile `{profile}` has no `[smpl22]` entry for SMPL joint `{joint}`; add one naming a joint of the skeleton or `{{ between = [a, b], at = t }}` (docs/humanml3d.md)"
    )]
    NoSmplJoint {
        /// Profile name.
        profile: String,
        /// The SMPL joint.
        joint: String,
    },
    /// An `[smpl22]` entry is not usable.
    #[error("profile `{profile}`: `[smpl22]` entry `{joint}`: {fault}")]
    BadSmplJoint {
        /// Profile name.
        profile: String,
        /// The SMPL joint (or the unknown key).
        joint: String,
        /// What is wrong.
        fault: SmplJointFault,
    },
}

/// How left/right pairs fail to describe a mirror-symmetric hierarchy (joints by name).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SymmetryFault {
    /// `joint` pairs with `partner`, whose own partner is another joint.
    #[error("`{joint}` pairs with `{partner}` but not back")]
    NotMutual {
        /// The joint.
        joint: String,
        /// Its partner.
        partner: String,
    },
    /// The parent of `partner` is not the partner of the parent of `joint`.
    #[error("the parent of `{partner}` does not mirror the parent of `{joint}`")]
    ParentNotMirrored {
        /// The joint.
        joint: String,
        /// Its partner.
        partner: String,
    },
}

/// What is wrong with one `[smpl22]` entry.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SmplJointFault {
    /// The key is not an SMPL body joint.
    #[error("not one of SMPL's 22 body joints")]
    NotSmpl,
    /// The entry names a joint the skeleton lacks.
    #[error("the skeleton has no joint `{name}`")]
    NoSuchJoint {
        /// The joint as named.
        name: String,
    },
    /// `at` is outside 0..=1.
    #[error("`at` is {at}; expected 0 to 1")]
    AtOutOfRange {
        /// The value given.
        at: f64,
    },
}

const BUNDLED: [(&str, &str); 5] = [
    (
        "bandai-namco",
        include_str!("../../../../schemas/skeletons/bandai-namco.toml"),
    ),
    (
        "cmu",
        include_str!("../../../../schemas/skeletons/cmu.toml"),
    ),
    (
        "smpl-22",
        include_str!("../../../../schemas/skeletons/smpl-22.toml"),
    ),
    (
        "smplh-52",
        include_str!("../../../../schemas/skeletons/smplh-52.toml"),
    ),
    (
        "smplx-55",
        include_str!("../../../../schemas/skeletons/smplx-55.toml"),
    ),
];

impl ProfileSpec {
    /// Parses a profile from TOML text.
    pub fn from_toml(name: &str, text: &str) -> Result<ProfileSpec, ProfileError> {
        toml::from_str(text).map_err(|source| ProfileError::Parse {
            name: name.to_string(),
            source,
        })
    }

    /// Where SMPL's 22 body joints (in SMPL order, `smpl_names`) are on a skeleton whose joints
    /// are `joint_names`.
    pub fn smpl_placement(
        &self,
        smpl_names: &[&str; 22],
        joint_names: &[&str],
    ) -> Result<SmplPlacement, ProfileError> {
        let bad = |joint: &str, fault: SmplJointFault| ProfileError::BadSmplJoint {
            profile: self.name.clone(),
            joint: joint.to_string(),
            fault,
        };
        if let Some(unknown) = self
            .smpl22
            .keys()
            .find(|k| !smpl_names.contains(&k.as_str()))
        {
            return Err(bad(unknown, SmplJointFault::NotSmpl));
        }
        let index = |smpl: &str, name: &str| {
            joint_names.iter().position(|j| *j == name).ok_or_else(|| {
                bad(
                    smpl,
                    SmplJointFault::NoSuchJoint {
                        name: name.to_string(),
                    },
                )
            })
        };
        let mut out = [(0usize, 0usize, 0.0f64); 22];
        for (slot, smpl) in out.iter_mut().zip(smpl_names) {
            *slot = match self.smpl22.get(*smpl) {
                None => {
                    return Err(ProfileError::NoSmplJoint {
                        profile: self.name.clone(),
                        joint: smpl.to_string(),
                    });
                }
                Some(SmplJoint::Joint(name)) => {
                    let i = index(smpl, name)?;
                    (i, i, 0.0)
                }
                Some(SmplJoint::Between { between, at }) => {
                    if !(0.0..=1.0).contains(at) {
                        return Err(bad(smpl, SmplJointFault::AtOutOfRange { at: *at }));
                    }
                    (index(smpl, &between[0])?, index(smpl, &between[1])?, *at)
                }
            };
        }
        Ok(SmplPlacement(out))
    }

    /// One of the bundled profiles by name.
    pub fn bundled(name: &str) -> Result<ProfileSpec, ProfileError> {
        let (_, text) = BUNDLED
            .iter()
            .find(|(n, _)| *n == name)
            .ok_or_else(|| ProfileError::Unknown(name.to_string()))?;
        ProfileSpec::from_toml(name, text)
    }

    /// Names of the bundled profiles.
    pub fn bundled_names() -> impl Iterator<Item = &'static str> {
        BUNDLED.iter().map(|(n, _)| *n)
    }

    /// The skeleton described by `joints`/`parents`, for sources without their own hierarchy.
    pub fn skeleton(&self) -> Option<Skeleton> {
        if self.joints.is_empty() || self.joints.len() != self.parents.len() {
            return None;
        }
        let joints = self
            .joints
            .iter()
            .zip(&self.parents)
            .map(|(name, &p)| super::skeleton::Joint {
                name: name.clone(),
                parent: usize::try_from(p).ok(),
                offset: DVec3::ZERO,
                channels: Vec::new(),
                end_site: None,
            })
            .collect();
        Some(Skeleton { joints })
    }

    /// Binds the profile to a concrete skeleton: resolves names to indices, detects left/right
    /// pairs, and checks that the pairs describe a mirror-symmetric hierarchy.
    pub fn bind(&self, skeleton: &Skeleton) -> Result<Profile, ProfileError> {
        if self.up.axis == self.forward.axis {
            return Err(ProfileError::Axes(self.name.clone()));
        }
        let find = |joint: &str, field: &'static str| {
            skeleton
                .index_of(joint)
                .ok_or_else(|| ProfileError::MissingJoint {
                    profile: self.name.clone(),
                    joint: joint.to_string(),
                    field,
                })
        };
        let root = find(&self.root, "root")?;
        let names: Vec<&str> = skeleton.names().collect();
        let mut swap = detect_pairs(&names);
        for (a, b) in &self.pairs {
            let (ia, ib) = (find(a, "pairs")?, find(b, "pairs")?);
            swap[ia] = ib;
            swap[ib] = ia;
        }
        for j in 0..swap.len() {
            let s = swap[j];
            if swap[s] != j {
                return Err(self.asymmetric(SymmetryFault::NotMutual {
                    joint: names[j].to_string(),
                    partner: names[s].to_string(),
                }));
            }
            let parent_of_swap = skeleton.joints[s].parent;
            let swap_of_parent = skeleton.joints[j].parent.map(|p| swap[p]);
            if parent_of_swap != swap_of_parent {
                return Err(self.asymmetric(SymmetryFault::ParentNotMirrored {
                    joint: names[j].to_string(),
                    partner: names[s].to_string(),
                }));
            }
        }
        let mut part_of = vec![None; skeleton.len()];
        for (part, joints) in &self.parts {
            for name in joints {
                part_of[find(name, "parts")?] = Some(*part);
            }
        }
        let mut roles = vec![Role::Other; skeleton.len()];
        for (name, role) in &self.roles {
            roles[find(name, "roles")?] = *role;
        }
        let mut motion_joints = vec![false; skeleton.len()];
        motion_joints[0] = true;
        for name in &self.motion_joints {
            motion_joints[find(name, "motion_joints")?] = true;
        }
        let mut reflections = vec![None; skeleton.len()];
        for (name, r) in &self.reflections {
            reflections[find(name, "reflections")?] = Some(*r);
        }
        let lateral = self.forward.vector().cross(self.up.vector());
        let right_axis = (0..3)
            .max_by(|&a, &b| lateral[a].abs().total_cmp(&lateral[b].abs()))
            .unwrap_or(0);
        Ok(Profile {
            name: self.name.clone(),
            up: self.up,
            forward: self.forward,
            unit_scale: self.unit_scale,
            root,
            swap,
            part_of,
            roles,
            motion_joints,
            reflections,
            world_reflection: Reflection::across(right_axis),
        })
    }

    fn asymmetric(&self, fault: SymmetryFault) -> ProfileError {
        ProfileError::Asymmetric {
            profile: self.name.clone(),
            fault,
        }
    }
}

/// Profiles already bound, by profile and skeleton. A dataset's captures share a few skeletons
/// (three among Bandai Namco's 2,902), and binding (pair detection by joint name) costs far more
/// than comparing two skeletons; the build binds once per stored motion it reads.
#[derive(Debug, Default)]
pub struct BoundProfiles {
    seen: std::sync::Mutex<Vec<Bound>>,
}

/// A profile, a skeleton and what binding them gave.
type Bound = (ProfileSpec, Skeleton, Result<Profile, ProfileError>);

/// Skeletons remembered at most; past that, binding is done each time rather than memory grown.
const BOUND_PROFILES_KEPT: usize = 64;

impl BoundProfiles {
    /// `spec.bind(skeleton)`, remembered.
    pub fn bind(&self, spec: &ProfileSpec, skeleton: &Skeleton) -> Result<Profile, ProfileError> {
        if let Ok(seen) = self.seen.lock()
            && let Some((_, _, bound)) = seen
                .iter()
                .find(|(s, k, _)| s.name == spec.name && k == skeleton && s == spec)
        {
            return bound.clone();
        }
        let bound = spec.bind(skeleton);
        if let Ok(mut seen) = self.seen.lock()
            && seen.len() < BOUND_PROFILES_KEPT
        {
            seen.push((spec.clone(), skeleton.clone(), bound.clone()));
        }
        bound
    }
}

/// A profile bound to one skeleton: everything by joint index.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// Profile name.
    pub name: String,
    /// Capture up axis.
    pub up: SignedAxis,
    /// Capture forward axis.
    pub forward: SignedAxis,
    /// File units to metres.
    pub unit_scale: f64,
    /// Root-motion joint index.
    pub root: usize,
    /// Mirror partner of each joint (itself for centre joints).
    pub swap: Vec<usize>,
    /// Body part of each joint.
    pub part_of: Vec<Option<BodyPart>>,
    /// Role of each joint.
    pub roles: Vec<Role>,
    /// Joints whose translation channels carry motion.
    pub motion_joints: Vec<bool>,
    /// Calibrated reflection per joint, where the profile has one.
    pub reflections: Vec<Option<Reflection>>,
    /// The world reflection `M` across the character's sagittal plane.
    pub world_reflection: Reflection,
}

impl Profile {
    /// The rotation taking capture axes to dataset axes: x right, y forward, z up (right-handed).
    pub fn to_dataset_axes(&self) -> DQuat {
        dataset_axes(self.up, self.forward)
    }

    /// Joint indices with the given role.
    pub fn joints_with_role(&self, role: Role) -> impl Iterator<Item = usize> + '_ {
        self.roles
            .iter()
            .enumerate()
            .filter(move |(_, r)| **r == role)
            .map(|(i, _)| i)
    }

    /// Joint indices of a body part.
    pub fn joints_of(&self, part: BodyPart) -> impl Iterator<Item = usize> + '_ {
        self.part_of
            .iter()
            .enumerate()
            .filter(move |(_, p)| **p == Some(part))
            .map(|(i, _)| i)
    }
}

/// Detects left/right partners from joint names: `_L`/`_R`, `.L`/`.R` suffixes, `Left`/`Right`
/// anywhere, `L`/`R` prefixes before a capital or `_`, and `left_`/`right_`. Joints without a
/// partner map to themselves.
pub fn detect_pairs(names: &[&str]) -> Vec<usize> {
    let index: BTreeMap<&str, usize> = names.iter().enumerate().map(|(i, n)| (*n, i)).collect();
    names
        .iter()
        .enumerate()
        .map(|(i, name)| {
            side_swapped_names(name)
                .into_iter()
                .find_map(|cand| index.get(cand.as_str()).copied().filter(|&k| k != i))
                .unwrap_or(i)
        })
        .collect()
}

fn side_swapped_names(name: &str) -> Vec<String> {
    let mut out = Vec::new();
    // Keep a namespace such as `mixamorig:` out of the prefix rules.
    let (ns, base) = match name.rfind(':') {
        Some(k) => (&name[..=k], &name[k + 1..]),
        None => ("", name),
    };
    for (l, r) in [
        ("_L", "_R"),
        (".L", ".R"),
        ("_l", "_r"),
        (".l", ".r"),
        ("-L", "-R"),
    ] {
        if let Some(stem) = base.strip_suffix(l) {
            out.push(format!("{ns}{stem}{r}"));
        }
        if let Some(stem) = base.strip_suffix(r) {
            out.push(format!("{ns}{stem}{l}"));
        }
        for (a, b) in [(l, r), (r, l)] {
            let infix = format!("{a}_");
            if let Some(k) = base.find(&infix) {
                out.push(format!(
                    "{ns}{}{b}_{}",
                    &base[..k],
                    &base[k + infix.len()..]
                ));
            }
        }
    }
    for (l, r) in [("Left", "Right"), ("left", "right"), ("LEFT", "RIGHT")] {
        if base.contains(l) {
            out.push(format!("{ns}{}", base.replacen(l, r, 1)));
        }
        if base.contains(r) {
            out.push(format!("{ns}{}", base.replacen(r, l, 1)));
        }
    }
    let mut chars = base.chars();
    if let (Some(first), Some(second)) = (chars.next(), chars.next())
        && (second.is_ascii_uppercase() || second == '_')
    {
        let rest = &base[1..];
        match first {
            'L' => out.push(format!("{ns}R{rest}")),
            'R' => out.push(format!("{ns}L{rest}")),
            'l' => out.push(format!("{ns}r{rest}")),
            'r' => out.push(format!("{ns}l{rest}")),
            _ => {}
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_from_every_naming_convention() {
        let names = [
            "Hips",
            "Shoulder_L",
            "Shoulder_R",
            "LeftUpLeg",
            "RightUpLeg",
            "LHipJoint",
            "RHipJoint",
            "left_knee",
            "right_knee",
            "hand.L",
            "hand.R",
            "mixamorig:LeftArm",
            "mixamorig:RightArm",
            "Lowerback",
        ];
        let swap = detect_pairs(&names);
        let partner = |n: &str| names[swap[names.iter().position(|x| *x == n).unwrap()]];
        assert_eq!(partner("Shoulder_L"), "Shoulder_R");
        assert_eq!(partner("RightUpLeg"), "LeftUpLeg");
        assert_eq!(partner("LHipJoint"), "RHipJoint");
        assert_eq!(partner("left_knee"), "right_knee");
        assert_eq!(partner("hand.R"), "hand.L");
        assert_eq!(partner("mixamorig:LeftArm"), "mixamorig:RightArm");
        assert_eq!(partner("Hips"), "Hips");
        // `Lowerback` starts with `L` but not before a capital: a centre joint.
        assert_eq!(partner("Lowerback"), "Lowerback");
    }

    #[test]
    fn bundled_profiles_parse() {
        for name in ProfileSpec::bundled_names() {
            let spec = ProfileSpec::bundled(name).unwrap();
            assert_eq!(spec.name, name);
            assert_eq!(spec.parts.len(), 6, "{name} must list all six body parts");
        }
    }

    #[test]
    fn dataset_axes_map_y_up_z_forward_to_z_up_y_forward() {
        let spec = ProfileSpec::bundled("smpl-22").unwrap();
        let profile = spec.bind(&spec.skeleton().unwrap()).unwrap();
        let q = profile.to_dataset_axes();
        assert!(
            (q * DVec3::Y - DVec3::Z).length() < 1e-12,
            "capture up becomes z"
        );
        assert!(
            (q * DVec3::Z - DVec3::Y).length() < 1e-12,
            "capture forward becomes y"
        );
        assert!(
            (q * DVec3::NEG_X - DVec3::X).length() < 1e-12,
            "the character's right becomes x"
        );
        assert_eq!(profile.world_reflection, Reflection::X);
    }

    /// The texts of the symmetry and `[smpl22]` faults: they must not change.
    #[test]
    fn every_fault_reads_as_it_always_has() {
        let spec = ProfileSpec::bundled("smpl-22").unwrap();
        let skeleton = spec.skeleton().unwrap();
        let paired = |a: &str, b: &str| {
            let mut spec = spec.clone();
            spec.pairs.insert(a.into(), b.into());
            spec.bind(&skeleton).unwrap_err()
        };
        let err = paired("right_hip", "left_knee");
        assert!(
            matches!(
                err,
                ProfileError::Asymmetric {
                    fault: SymmetryFault::NotMutual { .. },
                    ..
                }
            ),
            "{err}"
        );
        assert_eq!(
            err.to_string(),
            "profile `smpl-22`: left/right pairs are not symmetric: `left_hip` pairs with `right_hip` but not back"
        );
        let err = paired("left_hip", "right_knee");
        assert!(
            matches!(
                err,
                ProfileError::Asymmetric {
                    fault: SymmetryFault::ParentNotMirrored { .. },
                    ..
                }
            ),
            "{err}"
        );
        assert_eq!(
            err.to_string(),
            "profile `smpl-22`: left/right pairs are not symmetric: the parent of `right_knee` does not mirror the parent of `left_hip`"
        );
        let names: Vec<&str> = skeleton.names().collect();
        let smpl = &crate::humanml3d::JOINTS;
        let placed = |key: &str, joint: SmplJoint| {
            let mut spec = spec.clone();
            spec.smpl22.insert(key.into(), joint);
            spec.smpl_placement(smpl, &names).unwrap_err()
        };
        let err = placed("tail", SmplJoint::Joint("pelvis".into()));
        assert_eq!(
            err.to_string(),
            "profile `smpl-22`: `[smpl22]` entry `tail`: not one of SMPL's 22 body joints"
        );
        let err = placed("pelvis", SmplJoint::Joint("hips".into()));
        assert_eq!(
            err.to_string(),
            "profile `smpl-22`: `[smpl22]` entry `pelvis`: the skeleton has no joint `hips`"
        );
        let between = SmplJoint::Between {
            between: ["pelvis".into(), "spine1".into()],
            at: 1.5,
        };
        let err = placed("pelvis", between);
        assert!(
            matches!(
                err,
                ProfileError::BadSmplJoint {
                    fault: SmplJointFault::AtOutOfRange { at: 1.5 },
                    ..
                }
            ),
            "{err}"
        );
        assert_eq!(
            err.to_string(),
            "profile `smpl-22`: `[smpl22]` entry `pelvis`: `at` is 1.5; expected 0 to 1"
        );
    }
}
