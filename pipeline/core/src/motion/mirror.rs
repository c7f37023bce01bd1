//! Mirroring motions across the character's sagittal plane, with their skeletons.
//!
//! Each joint `j` has a reflection `B_j` (diagonal ±1, determinant -1) that maps the child offsets
//! of its partner `swap(j)` onto its own. Mirrored local transforms are
//! `R'_j = B_parent(j) · R_swap(j) · B_j⁻¹` and `T'_j = B_parent(j) · T_swap(j)`, with the world
//! reflection `M` in place of `B_parent` at the root. By induction the mirrored world transform of
//! `j` is `M · W_swap(j) · B_j⁻¹`, so mirrored positions are `M · P_swap(j)` exactly wherever the
//! skeleton is symmetric. Offsets leave `B_j` ambiguous for joints with one child along an axis or
//! none; [`calibrate`] resolves that from captures. `docs/mirroring.md` has the derivation.

use std::sync::Arc;

use glam::{DQuat, DVec3};

use super::motion::Motion;
use super::profile::{Profile, Reflection};
use super::skeleton::Skeleton;

/// How translations of joints that do not carry motion (bone offsets) are mirrored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OffsetPolicy {
    /// Keep each joint's own values: the mirrored motion stays on the original skeleton, and its
    /// positions are off by the skeleton's left/right asymmetry (2.2% of body height on CMU).
    Keep,
    /// Use `B_parent · T_swap`: the mirrored motion is on the mirrored skeleton
    /// ([`MirrorPlan::mirror_skeleton`]) and is the exact reflection of the original.
    #[default]
    Mirror,
}

/// Everything needed to mirror motions of one skeleton.
#[derive(Debug, Clone, PartialEq)]
pub struct MirrorPlan {
    /// Partner of each joint.
    pub swap: Vec<usize>,
    /// `B_j` per joint.
    pub reflections: Vec<Reflection>,
    /// `M`, the world reflection.
    pub world: Reflection,
    /// Joints whose translations carry motion and are mirrored like the root.
    pub motion_joints: Vec<bool>,
    parents: Vec<Option<usize>>,
}

/// Why a mirror plan cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MirrorError {
    /// The profile has no reflection for a joint and no capture was given to calibrate it.
    #[error(
        "no mirror reflection for joint `{0}`; calibrate the profile (motionforge calibrate-mirror) or set `reflections.{0}`"
    )]
    Uncalibrated(String),
    /// The profile does not match the motion's skeleton.
    #[error("profile covers {profile} joints but the skeleton has {skeleton}")]
    JointCount {
        /// Joints in the profile.
        profile: usize,
        /// Joints in the skeleton.
        skeleton: usize,
    },
}

impl MirrorPlan {
    /// A plan from a bound profile whose reflections are all set.
    pub fn from_profile(skeleton: &Skeleton, profile: &Profile) -> Result<MirrorPlan, MirrorError> {
        if profile.swap.len() != skeleton.len() {
            return Err(MirrorError::JointCount {
                profile: profile.swap.len(),
                skeleton: skeleton.len(),
            });
        }
        let reflections = profile
            .reflections
            .iter()
            .enumerate()
            .map(|(j, r)| {
                r.ok_or_else(|| MirrorError::Uncalibrated(skeleton.joints[j].name.clone()))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(MirrorPlan {
            swap: profile.swap.clone(),
            reflections,
            world: profile.world_reflection,
            motion_joints: profile.motion_joints.clone(),
            parents: skeleton.parents(),
        })
    }

    /// The plan with `reflections` in place of the profile's.
    pub fn with_reflections(
        skeleton: &Skeleton,
        profile: &Profile,
        reflections: Vec<Reflection>,
    ) -> MirrorPlan {
        MirrorPlan {
            swap: profile.swap.clone(),
            reflections,
            world: profile.world_reflection,
            motion_joints: profile.motion_joints.clone(),
            parents: skeleton.parents(),
        }
    }

    /// A plan that applies the single world reflection `M R M` to every joint: wrong for skeletons
    /// with joint orients such as Bandai Namco's; kept to show why (see the regression test).
    pub fn naive(skeleton: &Skeleton, profile: &Profile) -> MirrorPlan {
        let m = profile.world_reflection;
        MirrorPlan::with_reflections(skeleton, profile, vec![m; skeleton.len()])
    }

    fn parent_reflection(&self, j: usize) -> Reflection {
        self.parents[j]
            .map(|p| self.reflections[p])
            .unwrap_or(self.world)
    }

    /// The skeleton of a mirrored motion: every offset `B_parent · offset_swap(j)` and every end
    /// site `B_j · end_site_swap(j)`, names and channels kept. A skeleton whose left and right
    /// sides are reflections of each other comes back equal (same digest); mirroring twice gives
    /// the original back.
    pub fn mirror_skeleton(&self, skeleton: &Skeleton) -> Skeleton {
        // A coordinate equal to the joint's own keeps its own bits, so a symmetric skeleton keeps
        // its digest (which hashes the bytes of every offset, and a negated 0.0 is -0.0).
        fn settle(own: DVec3, mirrored: DVec3) -> DVec3 {
            let pick = |a: f64, b: f64| if a == b { a } else { b };
            DVec3::new(
                pick(own.x, mirrored.x),
                pick(own.y, mirrored.y),
                pick(own.z, mirrored.z),
            )
        }
        let mut out = skeleton.clone();
        for (j, joint) in out.joints.iter_mut().enumerate() {
            let s = self.swap.get(j).copied().unwrap_or(j);
            let (Some(source), Some(&b)) = (skeleton.joints.get(s), self.reflections.get(j)) else {
                continue;
            };
            joint.offset = settle(joint.offset, self.parent_reflection(j).apply(source.offset));
            joint.end_site = match (joint.end_site, source.end_site) {
                (Some(own), Some(e)) => Some(settle(own, b.apply(e))),
                (_, e) => e.map(|e| b.apply(e)),
            };
        }
        out
    }

    /// The skeleton a mirror of a motion on `skeleton` is on: the same one under
    /// [`OffsetPolicy::Keep`] or when the skeleton is symmetric, else [`MirrorPlan::mirror_skeleton`].
    pub fn skeleton_of_mirror(
        &self,
        skeleton: &Arc<Skeleton>,
        offsets: OffsetPolicy,
    ) -> Arc<Skeleton> {
        match offsets {
            OffsetPolicy::Keep => Arc::clone(skeleton),
            OffsetPolicy::Mirror => {
                let mirrored = self.mirror_skeleton(skeleton);
                if mirrored == **skeleton {
                    Arc::clone(skeleton)
                } else {
                    Arc::new(mirrored)
                }
            }
        }
    }

    /// The mirrored motion: on the mirrored skeleton under [`OffsetPolicy::Mirror`] (one shared
    /// copy when the skeleton is symmetric), on the same skeleton under [`OffsetPolicy::Keep`].
    pub fn mirror(&self, motion: &Motion, offsets: OffsetPolicy) -> Motion {
        let n = motion.num_joints();
        let frames = motion.num_frames();
        let mut rotations = Vec::with_capacity(n * frames);
        let mut translations = Vec::with_capacity(n * frames);
        let conj: Vec<DQuat> = self
            .reflections
            .iter()
            .map(|r| r.negated_rotation().conjugate())
            .collect();
        let parent: Vec<(Reflection, DQuat)> = (0..n)
            .map(|j| {
                let b = self.parent_reflection(j);
                (b, b.negated_rotation())
            })
            .collect();
        for f in 0..frames {
            let base = f * n;
            for j in 0..n {
                let s = self.swap[j];
                let (bp, cp) = parent[j];
                rotations.push(cp * motion.rotations[base + s] * conj[j]);
                let t = if self.motion_joints[j] || offsets == OffsetPolicy::Mirror {
                    bp.apply(motion.translations[base + s])
                } else {
                    motion.translations[base + j]
                };
                translations.push(t);
            }
        }
        Motion {
            skeleton: self.skeleton_of_mirror(&motion.skeleton, offsets),
            fps: motion.fps,
            rotations,
            translations,
        }
    }

    /// World positions reflected by `M` with left and right joints swapped: what the mirrored
    /// motion's forward kinematics should give.
    pub fn reflect_positions(&self, positions: &[DVec3]) -> Vec<DVec3> {
        let n = self.swap.len();
        let mut out = Vec::with_capacity(positions.len());
        for frame in positions.chunks_exact(n) {
            for j in 0..n {
                out.push(self.world.apply(frame[self.swap[j]]));
            }
        }
        out
    }
}

/// Chordal L2 mean of unit quaternions (the dominant eigenvector of `Σ q qᵀ`, Markley et al.),
/// insensitive to the sign ambiguity of quaternions.
pub fn mean_rotation(quats: impl IntoIterator<Item = DQuat>) -> DQuat {
    let mut m = [[0.0f64; 4]; 4];
    let mut seed: Option<[f64; 4]> = None;
    let mut sum = [0.0f64; 4];
    for q in quats {
        let v = [q.x, q.y, q.z, q.w];
        let reference = *seed.get_or_insert(v);
        let sign = if v.iter().zip(reference).map(|(a, b)| a * b).sum::<f64>() < 0.0 {
            -1.0
        } else {
            1.0
        };
        for a in 0..4 {
            sum[a] += sign * v[a];
            for b in 0..4 {
                m[a][b] += v[a] * v[b];
            }
        }
    }
    // Power iteration from the sign-aligned sum, which is already close to the answer.
    let mut x = sum;
    for _ in 0..64 {
        let mut y = [0.0; 4];
        for a in 0..4 {
            y[a] = (0..4).map(|b| m[a][b] * x[b]).sum();
        }
        let norm = y.iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm < 1e-300 {
            break;
        }
        x = y.map(|v| v / norm);
    }
    let q = DQuat::from_xyzw(x[0], x[1], x[2], x[3]);
    if q.length_squared() > 0.5 {
        q.normalize()
    } else {
        DQuat::IDENTITY
    }
}

/// How well `B` maps the children (and end site) of `swap(j)` onto those of `j`: the largest
/// mismatch over children, relative to the longest child offset.
fn offset_misfit(skeleton: &Skeleton, swap: &[usize], j: usize, b: Reflection) -> f64 {
    let s = swap[j];
    let mut worst: f64 = 0.0;
    let mut longest: f64 = 0.0;
    for c in skeleton.children(j) {
        let target = skeleton.joints[c].offset;
        let source = skeleton.joints[swap[c]].offset;
        worst = worst.max((b.apply(source) - target).length());
        longest = longest.max(target.length());
    }
    if let (Some(target), Some(source)) = (skeleton.joints[j].end_site, skeleton.joints[s].end_site)
    {
        worst = worst.max((b.apply(source) - target).length());
        longest = longest.max(target.length());
    }
    if longest < 1e-9 { 0.0 } else { worst / longest }
}

/// Relative offset mismatch under which a reflection counts as fitting; real skeletons are
/// symmetric to about 1% (CMU), so 5% separates fits from axis flips, which miss by 100% or more.
const FIT_TOLERANCE: f64 = 0.05;

/// Chooses `B_j` for every joint: among the reflections that fit the offsets, the one whose
/// mirrored rotations of `swap(j)` come closest (chordal mean over all frames) to the real
/// rotations of `j` in `captures`; one choice per left/right pair so mirroring twice is the
/// identity. Without captures, a tie keeps the parent's reflection. Parents are decided first,
/// since `R'_j` depends on `B_parent(j)`.
pub fn calibrate(skeleton: &Skeleton, profile: &Profile, captures: &[&Motion]) -> Vec<Reflection> {
    let n = skeleton.len();
    let swap = &profile.swap;
    let mut chosen: Vec<Option<Reflection>> = vec![None; n];
    let means: Vec<Vec<DQuat>> = captures
        .iter()
        .map(|m| {
            (0..n)
                .map(|j| mean_rotation((0..m.num_frames()).map(|f| m.rotation(f, j))))
                .collect()
        })
        .collect();
    for j in 0..n {
        if chosen[j].is_some() {
            continue;
        }
        let s = swap[j];
        let misfit = |b: Reflection| {
            offset_misfit(skeleton, swap, j, b).max(offset_misfit(skeleton, swap, s, b))
        };
        let best_fit = Reflection::ALL
            .iter()
            .map(|&b| misfit(b))
            .fold(f64::INFINITY, f64::min);
        let fitting: Vec<Reflection> = Reflection::ALL
            .into_iter()
            .filter(|&b| misfit(b) <= best_fit + FIT_TOLERANCE)
            .collect();
        let parent_b = |k: usize| {
            skeleton.joints[k]
                .parent
                .and_then(|p| chosen[p])
                .unwrap_or(profile.world_reflection)
        };
        let pick = if fitting.len() == 1 || captures.is_empty() {
            let inherited = parent_b(j);
            if fitting.contains(&inherited) {
                inherited
            } else {
                fitting[0]
            }
        } else {
            let score = |b: Reflection| -> f64 {
                let cb = b.negated_rotation().conjugate();
                let mut total = 0.0;
                for (m, mean) in captures.iter().zip(&means) {
                    for (target, source) in [(j, s), (s, j)] {
                        let cp = parent_b(target).negated_rotation();
                        let mirrored = mean_rotation(
                            (0..m.num_frames()).map(|f| cp * m.rotation(f, source) * cb),
                        );
                        total += mirrored.angle_between(mean[target]);
                    }
                }
                total
            };
            fitting
                .iter()
                .copied()
                .min_by(|a, b| score(*a).total_cmp(&score(*b)))
                .unwrap_or(Reflection::Xyz)
        };
        chosen[j] = Some(pick);
        chosen[s] = Some(pick);
    }
    chosen
        .into_iter()
        .map(|c| c.unwrap_or(Reflection::Xyz))
        .collect()
}
