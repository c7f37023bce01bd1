//! Joint positions to a motion: inverse kinematics for captures that store where the joints are
//! (HumanML3D's joint arrays) rather than how they turn, so mirroring, segmentation,
//! composition, features and BVH export work on them like on any capture.
//!
//! The skeleton gets the clip's own bone lengths (the mean over frames) and a rest pose facing
//! forward. Each joint with one child turns by the swing that takes its child's rest direction to
//! where the child is (no twist, as HumanML3D derives its rotations); a joint with several
//! children (the pelvis, the upper spine) turns by the body frame its children span, so rigid
//! groups (hips and spine, neck and collars) are reproduced exactly. Leaves keep their parent's
//! rotation. Forward kinematics of the result gives back the input positions up to the change of
//! bone lengths over time, which [`Fit`] reports.

use std::sync::Arc;

use glam::{DMat3, DQuat, DVec3};

use super::profile::{BodyPart, ProfileSpec, detect_pairs};
use super::{Channel, Joint, Motion, Skeleton};

/// The joints of a position array: names, parents (parents before children) and, for each joint,
/// which side it is on, for rest directions that mirror left onto right.
#[derive(Debug, Clone, PartialEq)]
pub struct PositionLayout {
    /// Joint names.
    pub names: Vec<String>,
    /// Parent of each joint (`None` for the root, which must be joint 0).
    pub parents: Vec<Option<usize>>,
    /// Each joint's left/right partner (itself for joints on the midline).
    pub partners: Vec<usize>,
    /// Each joint's side: `Some(true)` left, `Some(false)` right, `None` midline.
    pub left: Vec<Option<bool>>,
    /// The capture's up and forward directions (unit, perpendicular).
    pub up: DVec3,
    /// The capture's forward direction.
    pub forward: DVec3,
}

impl PositionLayout {
    /// The layout a positions-only profile describes (`joints`, `parents`, axes, parts and
    /// pairs); `None` when it lists no joints or its parents do not match them.
    pub fn from_profile(spec: &ProfileSpec) -> Option<PositionLayout> {
        let n = spec.joints.len();
        if n == 0 || spec.parents.len() != n {
            return None;
        }
        let parents = spec
            .parents
            .iter()
            .map(|&p| usize::try_from(p).ok().filter(|&p| p < n))
            .collect();
        let names: Vec<&str> = spec.joints.iter().map(String::as_str).collect();
        let mut partners = detect_pairs(&names);
        for (a, b) in &spec.pairs {
            if let (Some(i), Some(k)) = (
                names.iter().position(|x| x == a),
                names.iter().position(|x| x == b),
            ) {
                partners[i] = k;
                partners[k] = i;
            }
        }
        let side = |name: &str| {
            let in_part = |part: BodyPart| {
                spec.parts
                    .get(&part)
                    .is_some_and(|joints| joints.iter().any(|j| j == name))
            };
            if in_part(BodyPart::LeftArm) || in_part(BodyPart::LeftLeg) {
                Some(true)
            } else if in_part(BodyPart::RightArm) || in_part(BodyPart::RightLeg) {
                Some(false)
            } else {
                None
            }
        };
        Some(PositionLayout {
            left: names.iter().map(|n| side(n)).collect(),
            names: spec.joints.clone(),
            parents,
            partners,
            up: spec.up.vector(),
            forward: spec.forward.vector(),
        })
    }
}

/// How well forward kinematics of the motion reproduces the positions.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Fit {
    /// Largest distance between an input position and the motion's (file units).
    pub max_residual: f64,
    /// Where it is: frame and joint.
    pub worst: (usize, usize),
    /// Largest relative change of a bone's length from its mean over the clip.
    pub max_length_change: f64,
}

/// Why positions have no motion.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IkError {
    /// The array does not hold whole frames of the layout.
    #[error("{values} positions are not whole frames of {joints} joints")]
    Shape {
        /// Positions given.
        values: usize,
        /// Joints per frame.
        joints: usize,
    },
    /// The layout is not a tree rooted at joint 0 with parents before children.
    #[error("joint {joint} (`{name}`): its parent must come before it and only joint 0 is a root")]
    Hierarchy {
        /// The joint.
        joint: usize,
        /// Its name.
        name: String,
    },
    /// A joint coincides with its parent, so its bone has no direction.
    #[error("frame {frame}: joint `{name}` coincides with its parent; a bone needs a length")]
    ZeroBone {
        /// The frame.
        frame: usize,
        /// The joint.
        name: String,
    },
    /// A bone's length changes more than the tolerance allows: the array is not one body.
    #[error(
        "frame {frame}: bone to `{name}` is {length:.4} long against {mean:.4} on average ({change:.1}% off; at most {tolerance:.1}% allowed)",
        change = 100.0 * (length - mean).abs() / mean,
        tolerance = 100.0 * tolerance
    )]
    BoneLength {
        /// The frame.
        frame: usize,
        /// The joint at the bone's end.
        name: String,
        /// Its length there.
        length: f64,
        /// Its mean length.
        mean: f64,
        /// The allowed relative change.
        tolerance: f64,
    },
}

impl IkError {
    /// The frame of the bad bone, when the fault is in one.
    pub fn frame(&self) -> Option<usize> {
        match self {
            IkError::BoneLength { frame, .. } | IkError::ZeroBone { frame, .. } => Some(*frame),
            _ => None,
        }
    }
}

/// Reflection across the midline plane (the plane of up and forward).
fn mirror(v: DVec3, lateral: DVec3) -> DVec3 {
    v - 2.0 * v.dot(lateral) * lateral
}

/// The shortest rotation taking unit `from` to unit `to`.
fn swing(from: DVec3, to: DVec3) -> DQuat {
    let d = from.dot(to);
    if d < -1.0 + 1e-12 {
        // Opposite: a half turn about any perpendicular axis.
        let mut axis = from.cross(DVec3::X);
        if axis.length_squared() < 1e-12 {
            axis = from.cross(DVec3::Y);
        }
        return DQuat::from_axis_angle(axis.normalize(), std::f64::consts::PI);
    }
    DQuat::from_rotation_arc(from, to)
}

/// The rotation taking the rest frame (`rest`: columns left, up, forward in capture axes) to the
/// frame a sideways (leftward) and an upward vector span.
fn body_frame(rest: &DMat3, sideways: DVec3, upward: DVec3) -> Option<DQuat> {
    let x = sideways.try_normalize()?;
    let y = (upward - upward.dot(x) * x).try_normalize()?;
    let spanned = DMat3::from_cols(x, y, x.cross(y));
    Some(DQuat::from_mat3(&(spanned * rest.transpose())))
}

/// The motion whose forward kinematics places the joints of `layout` at `positions` (`frames ×
/// joints`, frame-major) at `fps`, and how well it does. `tolerance` is the largest relative
/// change of a bone's length from its mean that is accepted.
pub fn motion_from_positions(
    layout: &PositionLayout,
    positions: &[DVec3],
    fps: f64,
    tolerance: f64,
) -> Result<(Motion, Fit), IkError> {
    let clip = Positions::new(layout, positions)?;
    let mut fit = Fit::default();
    let lengths = clip.bone_lengths(tolerance, &mut fit)?;
    let (world, offsets) = clip.world_rotations(&lengths);
    let (rotations, translations) = clip.local_channels(&world, &offsets);
    let motion = Motion {
        skeleton: skeleton_of(layout, &offsets),
        fps,
        rotations,
        translations,
    };
    let n = clip.n;
    let pose = motion.forward_kinematics();
    for (i, (a, b)) in pose.positions.iter().zip(positions).enumerate() {
        let d = a.distance(*b);
        if d > fit.max_residual {
            fit.max_residual = d;
            fit.worst = (i / n, i % n);
        }
    }
    Ok((motion, fit))
}

/// A checked position array with its layout: whole frames of a tree rooted at joint 0.
struct Positions<'a> {
    layout: &'a PositionLayout,
    positions: &'a [DVec3],
    /// Joints per frame.
    n: usize,
    frames: usize,
    /// Each joint's children, in joint order.
    children: Vec<Vec<usize>>,
    /// The capture's lateral (leftward) axis.
    lateral: DVec3,
    /// The rest frame: columns lateral, up and forward (the capture's own axes, facing forward).
    rest: DMat3,
}

impl<'a> Positions<'a> {
    fn new(layout: &'a PositionLayout, positions: &'a [DVec3]) -> Result<Self, IkError> {
        let n = layout.names.len();
        if n == 0 || !positions.len().is_multiple_of(n) || positions.is_empty() {
            return Err(IkError::Shape {
                values: positions.len(),
                joints: n,
            });
        }
        for (j, parent) in layout.parents.iter().enumerate() {
            let ok = match parent {
                None => j == 0,
                Some(p) => *p < j,
            };
            if !ok {
                return Err(IkError::Hierarchy {
                    joint: j,
                    name: layout.names[j].clone(),
                });
            }
        }
        let lateral = layout.up.cross(layout.forward).normalize();
        Ok(Positions {
            layout,
            positions,
            n,
            frames: positions.len() / n,
            children: (0..n)
                .map(|j| (0..n).filter(|&c| layout.parents[c] == Some(j)).collect())
                .collect(),
            lateral,
            rest: DMat3::from_cols(lateral, layout.up, layout.forward),
        })
    }

    fn at(&self, t: usize, j: usize) -> DVec3 {
        self.positions[t * self.n + j]
    }

    /// The bone ending at joint `j` at frame `t` (the root's position for the root).
    fn bone(&self, t: usize, j: usize) -> DVec3 {
        self.at(t, j) - self.layout.parents[j].map_or(DVec3::ZERO, |p| self.at(t, p))
    }

    /// Bone lengths: each bone's mean, and every frame checked against it.
    fn bone_lengths(&self, tolerance: f64, fit: &mut Fit) -> Result<Vec<f64>, IkError> {
        let (frames, layout) = (self.frames, self.layout);
        let mut lengths = vec![0.0; self.n];
        for (j, mean) in lengths.iter_mut().enumerate().skip(1) {
            for t in 0..frames {
                let l = self.bone(t, j).length();
                if l.is_nan() || l <= 1e-9 {
                    return Err(IkError::ZeroBone {
                        frame: t,
                        name: layout.names[j].clone(),
                    });
                }
                *mean += l / frames as f64;
            }
            for t in 0..frames {
                let l = self.bone(t, j).length();
                let change = (l - *mean).abs() / *mean;
                // NaN (an overflowing length or mean) fails the check too.
                if change.is_nan() || change > tolerance {
                    return Err(IkError::BoneLength {
                        frame: t,
                        name: layout.names[j].clone(),
                        length: l,
                        mean: *mean,
                        tolerance,
                    });
                }
                fit.max_length_change = fit.max_length_change.max(change);
            }
        }
        Ok(lengths)
    }

    /// World rotation of every joint at every frame, and rest offsets in the rest frame, joint
    /// by joint from the root (a joint's turn starts from its parent's).
    fn world_rotations(&self, lengths: &[f64]) -> (Vec<DQuat>, Vec<DVec3>) {
        let mut world = vec![DQuat::IDENTITY; self.positions.len()];
        let mut offsets = vec![DVec3::ZERO; self.n];
        for j in 0..self.n {
            let kids = &self.children[j];
            if kids.len() >= 2 {
                self.turn_rigid_group(j, &mut world, &mut offsets);
            } else if let [c] = kids.as_slice() {
                self.swing_to_child(j, *c, lengths[*c], &mut world, &mut offsets);
            } else {
                for t in 0..self.frames {
                    world[t * self.n + j] = world_of(&world, self.n, self.layout.parents[j], t);
                }
            }
        }
        (world, offsets)
    }

    /// A joint with several children turns as a rigid group: by the frame its children span
    /// (left-right and up when a pair and a midline child are there, else the first two
    /// children). Its children's offsets are their mean bones in that frame.
    fn turn_rigid_group(&self, j: usize, world: &mut [DQuat], offsets: &mut [DVec3]) {
        let (layout, n) = (self.layout, self.n);
        let kids = &self.children[j];
        let pair = kids.iter().find_map(|&a| {
            let b = layout.partners[a];
            (b != a && kids.contains(&b) && layout.left[a] == Some(true)).then_some((a, b))
        });
        let up_child = kids
            .iter()
            .copied()
            .find(|&c| layout.left[c].is_none())
            .unwrap_or(kids[0]);
        let spans = |t: usize| match pair {
            Some((l, r)) => (self.bone(t, l) - self.bone(t, r), self.bone(t, up_child)),
            None => (self.bone(t, kids[0]), self.bone(t, kids[1])),
        };
        let mut sum = vec![DVec3::ZERO; kids.len()];
        for t in 0..self.frames {
            let (side, up) = spans(t);
            let frame = body_frame(&self.rest, side, up)
                // Degenerate spans: keep the parent's orientation for this frame.
                .unwrap_or_else(|| world_of(world, n, layout.parents[j], t));
            world[t * n + j] = frame;
            for (s, &c) in sum.iter_mut().zip(kids) {
                *s += frame.inverse() * self.bone(t, c);
            }
        }
        for (s, &c) in sum.iter().zip(kids) {
            offsets[c] = *s / self.frames as f64;
        }
    }

    /// A joint with one child `c` turns by the swing taking the child's rest direction to where
    /// the child is.
    fn swing_to_child(
        &self,
        j: usize,
        c: usize,
        length: f64,
        world: &mut [DQuat],
        offsets: &mut [DVec3],
    ) {
        let (layout, n) = (self.layout, self.n);
        let d = self.rest_direction(c, world);
        offsets[c] = d * length;
        for t in 0..self.frames {
            let pw = world_of(world, n, layout.parents[j], t);
            let s = swing(pw * d, self.bone(t, c).normalize());
            world[t * n + j] = s * pw;
        }
    }

    /// Rest direction of a single child `c`: the mean direction in the parent's frame, made a
    /// mirror image of the partner's so mirrored motions stay on the skeleton; the swing is
    /// exact for any.
    fn rest_direction(&self, c: usize, world: &[DQuat]) -> DVec3 {
        let (layout, positions, frames, lateral) =
            (self.layout, self.positions, self.frames, self.lateral);
        let own = mean_direction(layout, positions, world, c, frames);
        match layout.left[c] {
            None => {
                let flat = mirror(own, lateral) + own;
                flat.try_normalize().unwrap_or(own)
            }
            Some(_) if layout.partners[c] != c && layout.partners[c] < self.n => {
                // The partner's bone hangs from the partner of this joint, computed from the
                // same kind of frame: average the two, mirrored.
                let other = layout.partners[c];
                if layout.parents[other].is_some_and(|op| self.children[op].len() == 1) {
                    let theirs = mean_direction(layout, positions, world, other, frames);
                    (own + mirror(theirs, lateral))
                        .try_normalize()
                        .unwrap_or(own)
                } else {
                    own
                }
            }
            Some(_) => own,
        }
    }

    /// Each joint's rotation relative to its parent, frame-major; the root also moves (its
    /// position), the other joints keep their rest offsets.
    fn local_channels(&self, world: &[DQuat], offsets: &[DVec3]) -> (Vec<DQuat>, Vec<DVec3>) {
        let n = self.n;
        let mut rotations = Vec::with_capacity(self.positions.len());
        let mut translations = Vec::with_capacity(self.positions.len());
        for t in 0..self.frames {
            for j in 0..n {
                let w = world[t * n + j];
                match self.layout.parents[j] {
                    None => {
                        rotations.push(w);
                        translations.push(self.at(t, j));
                    }
                    Some(p) => {
                        rotations.push(world[t * n + p].inverse() * w);
                        translations.push(offsets[j]);
                    }
                }
            }
        }
        (rotations, translations)
    }
}

/// The skeleton of the layout with the solved rest offsets: the root with position and
/// rotation channels, every other joint with rotations.
fn skeleton_of(layout: &PositionLayout, offsets: &[DVec3]) -> Arc<Skeleton> {
    Arc::new(Skeleton {
        joints: (0..layout.names.len())
            .map(|j| Joint {
                name: layout.names[j].clone(),
                parent: layout.parents[j],
                offset: offsets[j],
                channels: if j == 0 {
                    vec![
                        Channel::Xposition,
                        Channel::Yposition,
                        Channel::Zposition,
                        Channel::Zrotation,
                        Channel::Xrotation,
                        Channel::Yrotation,
                    ]
                } else {
                    vec![Channel::Zrotation, Channel::Xrotation, Channel::Yrotation]
                },
                end_site: None,
            })
            .collect(),
    })
}

/// World rotation of `joint` (the identity for none) at frame `t`.
fn world_of(world: &[DQuat], n: usize, joint: Option<usize>, t: usize) -> DQuat {
    joint.map_or(DQuat::IDENTITY, |p| world[t * n + p])
}

/// The mean direction of bone `joint` in the world frame of its grandparent (the frame its
/// parent's swing starts from): the rest direction of a single child.
fn mean_direction(
    layout: &PositionLayout,
    positions: &[DVec3],
    world: &[DQuat],
    joint: usize,
    frames: usize,
) -> DVec3 {
    let n = layout.names.len();
    let Some(p) = layout.parents[joint] else {
        return layout.up;
    };
    let mut sum = DVec3::ZERO;
    for t in 0..frames {
        let frame = layout.parents[p].map_or(DQuat::IDENTITY, |g| world[t * n + g]);
        let b = positions[t * n + joint] - positions[t * n + p];
        sum += frame.inverse() * b.normalize();
    }
    sum.try_normalize().unwrap_or(layout.up)
}
