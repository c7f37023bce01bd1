//! Per-clip plausibility metrics on world joint positions (CODA 3.1 and appendices B, E): foot
//! skating, ground penetration, self-penetration between body-part chains, and lean.
//!
//! Everything is computed from dataset-axes positions (x right, y forward, z up, metres; see
//! [`crate::motion::canonical::dataset_positions`]), so real captures and synthetic composites are
//! judged alike. Thresholds and the measured real distributions are in `docs/plausibility.md`.

use serde::{Deserialize, Serialize};

use glam::DVec3;

use crate::motion::{BodyPart, Profile, Role};

/// Height above a foot joint's floor level (metres) below which it may be in ground contact.
pub const CONTACT_HEIGHT: f64 = 0.03;
/// Quantile of a foot role's heights over the clip taken as its floor level.
pub const FLOOR_QUANTILE: f64 = 0.02;
/// Vertical speed (m/s) below which a low foot joint counts as in contact; landing and lifting
/// feet move vertically and are not planted yet.
pub const CONTACT_VERTICAL_SPEED: f64 = 0.3;
/// Rate (frames per second) velocities are measured at, whatever the clip's rate: finite
/// differences over 1/30 s keep capture jitter at 120 fps from reading as skating.
pub const VELOCITY_RATE: f64 = 30.0;
/// Padding (metres) added to each chain's joint bounding box: a generous limb radius, so boxes
/// that do not overlap are at least twice this apart and need no bone-to-bone test.
pub const LIMB_RADIUS: f64 = 0.1;
/// Joints within this height (metres) of a frame's lowest body joint form its base of support:
/// the feet when standing, knees and hands when kneeling.
pub const SUPPORT_BAND: f64 = 0.1;
/// Smallest height (metres) of the centre of mass above the base of support for lean to be
/// measured; lower, the body lies or sits on the floor and the angle is meaningless.
pub const MIN_LEVER: f64 = 0.25;
/// Lean is averaged over windows of this many seconds before taking the maximum.
pub const LEAN_WINDOW: f64 = 0.5;

/// Plausibility metrics of one clip. Distances in metres, speeds in m/s, angles in degrees.
///
/// Non-finite input positions make every metric NaN, so such a clip fails every threshold.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct Plausibility {
    /// Mean horizontal speed of the supporting foot while a foot is planted (m/s); 0 when no foot
    /// is ever planted. Per frame step the slowest planted foot is the support.
    pub foot_skate: f64,
    /// Largest horizontal speed of the supporting foot (m/s). Single steps at touch-down are
    /// noisy, so this is reported, not thresholded.
    pub foot_skate_max: f64,
    /// The foot (left or right leg) that contributes most of the skating (largest sum of its
    /// speeds as the support); `None` when no foot is ever planted.
    pub foot_skate_foot: Option<BodyPart>,
    /// Share of measured frame steps with at least one planted foot, in `[0, 1]`.
    pub contact_fraction: f64,
    /// Depth (metres, `>= 0`) of the lowest body joint below the floor `z = 0`; 0 if none is below.
    pub ground_penetration: f64,
    /// Frame of the deepest joint (0 when nothing is below the floor).
    pub ground_penetration_frame: usize,
    /// Minimum bone-to-bone distance (metres) between a limb chain (arm or leg) and the spine
    /// chain over all frames: a limb bone this close to the spine is inside the torso. Capped at
    /// `2 * LIMB_RADIUS` (the value when no limb box ever overlaps the spine's).
    pub self_distance: f64,
    /// Frame of [`Plausibility::self_distance`].
    pub self_distance_frame: usize,
    /// The limb that comes closest to the spine; `None` when no limb box overlapped the spine's.
    pub self_distance_part: Option<BodyPart>,
    /// Minimum bone-to-bone distance (metres) between two limb chains (arm-arm, leg-leg,
    /// arm-leg). Reported, not thresholded: hands together and crossed feet bring real captures'
    /// bones within millimetres (see `docs/plausibility.md`). Capped like `self_distance`.
    pub limb_distance: f64,
    /// Frame of [`Plausibility::limb_distance`].
    pub limb_distance_frame: usize,
    /// The two limbs that come closest; `None` when no pair of boxes overlapped.
    pub limb_distance_parts: Option<(BodyPart, BodyPart)>,
    /// Largest sustained lean (degrees): the angle between the vertical and the line from the base
    /// of support to the centre of mass, averaged over [`LEAN_WINDOW`] seconds, maximum over the
    /// clip.
    pub lean: f64,
    /// Mean per-frame lean (degrees) over the frames where it is measured.
    pub lean_mean: f64,
    /// Centre frame of the window with the largest lean.
    pub lean_frame: usize,
}

/// Limits a plausible clip stays within. The defaults are chosen from the real captures' measured
/// distributions; see `docs/plausibility.md`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Thresholds {
    /// Largest allowed [`Plausibility::foot_skate`] (m/s).
    pub max_foot_skate: f64,
    /// Largest allowed [`Plausibility::ground_penetration`] (m).
    pub max_ground_penetration: f64,
    /// Smallest allowed [`Plausibility::self_distance`] (m).
    pub min_self_distance: f64,
    /// Largest allowed [`Plausibility::lean`] (degrees).
    pub max_lean: f64,
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            max_foot_skate: 0.4,
            max_ground_penetration: 0.03,
            min_self_distance: 0.03,
            max_lean: 25.0,
        }
    }
}

/// A plausibility check a clip can fail, named as the build report counts it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Check {
    /// [`Plausibility::foot_skate`] above [`Thresholds::max_foot_skate`].
    FootSkating,
    /// [`Plausibility::ground_penetration`] above [`Thresholds::max_ground_penetration`].
    GroundPenetration,
    /// [`Plausibility::self_distance`] below [`Thresholds::min_self_distance`].
    SelfPenetration,
    /// [`Plausibility::lean`] above [`Thresholds::max_lean`].
    Lean,
}

impl Check {
    /// Every check, in the order they are made.
    pub const ALL: &'static [Check] = &[
        Check::FootSkating,
        Check::GroundPenetration,
        Check::SelfPenetration,
        Check::Lean,
    ];

    /// The check's name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Check::FootSkating => "foot_skating",
            Check::GroundPenetration => "ground_penetration",
            Check::SelfPenetration => "self_penetration",
            Check::Lean => "lean",
        }
    }
}

impl std::fmt::Display for Check {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Plausibility {
    /// The checks the clip fails against `t`, in the order of [`Check::ALL`]. Empty for a
    /// plausible clip. A metric that is NaN fails.
    pub fn failed_checks(&self, t: &Thresholds) -> Vec<Check> {
        let mut out = Vec::new();
        if !at_most(self.foot_skate, t.max_foot_skate) {
            out.push(Check::FootSkating);
        }
        if !at_most(self.ground_penetration, t.max_ground_penetration) {
            out.push(Check::GroundPenetration);
        }
        if !at_most(t.min_self_distance, self.self_distance) {
            out.push(Check::SelfPenetration);
        }
        if !at_most(self.lean, t.max_lean) {
            out.push(Check::Lean);
        }
        out
    }

    /// The names of the checks the clip fails `t`, in a fixed order: `foot_skating`,
    /// `ground_penetration`, `self_penetration`, `lean`. Empty for a plausible clip. A metric
    /// that is NaN fails.
    pub fn failures(&self, t: &Thresholds) -> Vec<&'static str> {
        self.failed_checks(t).into_iter().map(Check::name).collect()
    }
}

/// `a <= b`, false when either is NaN (so a NaN metric fails rather than passes).
fn at_most(a: f64, b: f64) -> bool {
    a <= b
}

/// Plausibility metrics of a clip from its world positions in dataset axes (z up, metres),
/// frame-major with `joints` joints per frame, sampled at `fps`.
///
/// Joints are identified through `profile` (roles and body parts); joints the profile does not
/// describe are ignored. A trailing partial frame is ignored. Missing pieces contribute nothing:
/// without feet there is no skating, without chains no self-distance (the cap is reported), and a
/// non-positive or non-finite `fps` gives no skating and an unsmoothed lean.
pub fn plausibility(
    positions: &[DVec3],
    joints: usize,
    fps: f64,
    profile: &Profile,
) -> Plausibility {
    let cap = 2.0 * LIMB_RADIUS;
    let mut out = Plausibility {
        self_distance: cap,
        limb_distance: cap,
        ..Plausibility::default()
    };
    let frames = positions.len().checked_div(joints).unwrap_or(0);
    let clip = Clip {
        positions: &positions[..frames * joints],
        joints,
        frames,
    };
    if !clip.positions.iter().all(|p| p.is_finite()) {
        return Plausibility {
            foot_skate: f64::NAN,
            foot_skate_max: f64::NAN,
            contact_fraction: f64::NAN,
            ground_penetration: f64::NAN,
            self_distance: f64::NAN,
            limb_distance: f64::NAN,
            lean: f64::NAN,
            lean_mean: f64::NAN,
            ..out
        };
    }
    if frames == 0 {
        return out;
    }
    let body = body_joints(profile, joints);
    skating(&clip, fps, profile, &mut out);
    penetration(&clip, &body, &mut out);
    self_distance(&clip, profile, &mut out);
    lean(&clip, &body, fps, &mut out);
    out
}

/// Positions of a whole number of frames.
struct Clip<'a> {
    positions: &'a [DVec3],
    joints: usize,
    frames: usize,
}

impl Clip<'_> {
    fn at(&self, f: usize, j: usize) -> DVec3 {
        self.positions[f * self.joints + j]
    }

    fn frame(&self, f: usize) -> &[DVec3] {
        &self.positions[f * self.joints..(f + 1) * self.joints]
    }

    /// Distance between two bones (joint index pairs) in frame `f`.
    fn bone_distance(&self, f: usize, (p0, p1): (usize, usize), (q0, q1): (usize, usize)) -> f64 {
        segment_distance(
            self.at(f, p0),
            self.at(f, p1),
            self.at(f, q0),
            self.at(f, q1),
        )
    }
}

/// Joints that are part of the body: all but static auxiliary roots (Bandai's `joint_Root` stays
/// at the origin while the actor walks away).
fn body_joints(profile: &Profile, joints: usize) -> Vec<usize> {
    (0..joints)
        .filter(|&j| profile.roles.get(j).is_some_and(|r| *r != Role::Root))
        .collect()
}

/// Joints of `part` with `role`, within the clip's joint count.
fn joints_where(profile: &Profile, joints: usize, part: BodyPart, role: Role) -> Vec<usize> {
    profile
        .joints_with_role(role)
        .filter(|&j| j < joints && profile.part_of.get(j) == Some(&Some(part)))
        .collect()
}

/// The `q` quantile of `values` (sorted in place), `None` when empty.
fn quantile(values: &mut [f64], q: f64) -> Option<f64> {
    values.sort_by(f64::total_cmp);
    let k = ((values.len().checked_sub(1)? as f64) * q).round() as usize;
    values.get(k).copied()
}

const FEET: [BodyPart; 2] = [BodyPart::LeftLeg, BodyPart::RightLeg];
const FOOT_ROLES: [Role; 2] = [Role::Ankle, Role::Toe];

fn skating(clip: &Clip, fps: f64, profile: &Profile, out: &mut Plausibility) {
    if !(fps.is_finite() && fps > 0.0) {
        return;
    }
    // Floor level per role, shared by both feet: an ankle rests higher than a toe, and a foot held
    // up for the whole clip must not define its own floor. A low quantile rather than the minimum
    // keeps a glitched frame from lifting every contact out of reach.
    let mut feet: [Vec<(usize, f64)>; 2] = [Vec::new(), Vec::new()];
    for role in FOOT_ROLES {
        let per_side: Vec<Vec<usize>> = FEET
            .iter()
            .map(|&side| joints_where(profile, clip.joints, side, role))
            .collect();
        let mut heights: Vec<f64> = per_side
            .iter()
            .flatten()
            .flat_map(|&j| (0..clip.frames).map(move |f| clip.at(f, j).z))
            .collect();
        if let Some(level) = quantile(&mut heights, FLOOR_QUANTILE) {
            for (foot, joints) in feet.iter_mut().zip(per_side) {
                foot.extend(joints.into_iter().map(|j| (j, level)));
            }
        }
    }
    let step = ((fps / VELOCITY_RATE).round() as usize).max(1);
    let dt = step as f64 / fps;
    let (mut sum, mut by_foot, mut steps, mut planted) = (0.0, [0.0; 2], 0usize, 0usize);
    for f in 0..clip.frames.saturating_sub(step) {
        steps += 1;
        let support = feet
            .iter()
            .enumerate()
            .filter_map(|(side, foot)| Some((side, foot_speed(clip, foot, f, step, dt)?)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((side, v)) = support {
            planted += 1;
            sum += v;
            by_foot[side] += v;
            out.foot_skate_max = out.foot_skate_max.max(v);
        }
    }
    if planted > 0 {
        out.foot_skate = sum / planted as f64;
        out.foot_skate_foot = Some(if by_foot[1] > by_foot[0] {
            FEET[1]
        } else {
            FEET[0]
        });
    }
    if steps > 0 {
        out.contact_fraction = planted as f64 / steps as f64;
    }
}

/// Horizontal speed of a planted foot over frames `f..f + step`, `None` when it is not planted.
///
/// Planted means every joint of the foot (ankle and toe) is within [`CONTACT_HEIGHT`] of its floor
/// level and moves vertically slower than [`CONTACT_VERTICAL_SPEED`]: a heel sweeping in to land
/// and a swing toe skimming the floor come within a centimetre of it, but never both at once. The
/// foot's speed is its slower joint's, so a foot pivoting on its heel or toe stays still.
fn foot_speed(clip: &Clip, foot: &[(usize, f64)], f: usize, step: usize, dt: f64) -> Option<f64> {
    let mut speed: Option<f64> = None;
    for &(j, level) in foot {
        let (a, b) = (clip.at(f, j), clip.at(f + step, j));
        let low = a.z.max(b.z) - level < CONTACT_HEIGHT;
        let still = ((b.z - a.z) / dt).abs() < CONTACT_VERTICAL_SPEED;
        if !(low && still) {
            return None;
        }
        let v = (b - a).truncate().length() / dt;
        speed = Some(speed.map_or(v, |s| s.min(v)));
    }
    speed
}

fn penetration(clip: &Clip, body: &[usize], out: &mut Plausibility) {
    for f in 0..clip.frames {
        for &j in body {
            let depth = -clip.at(f, j).z;
            if depth > out.ground_penetration {
                out.ground_penetration = depth;
                out.ground_penetration_frame = f;
            }
        }
    }
}

/// A body-part chain: joints from the attachment to the tip.
struct Chain {
    part: BodyPart,
    joints: Vec<usize>,
}

impl Chain {
    fn is_spine(&self) -> bool {
        self.part == BodyPart::Torso
    }
}

/// The five chains of CODA's penetration test, from roles: spine pelvis to head, arms collar to
/// hand (fingers branch off the hand and are left out), legs hip to toe. Joints are ordered by
/// role along the chain, then by index (parents precede children in every supported skeleton).
fn chains(profile: &Profile, joints: usize) -> Vec<Chain> {
    let ordered = |part: BodyPart, roles: &[Role]| -> Vec<usize> {
        roles
            .iter()
            .flat_map(|&r| joints_where(profile, joints, part, r))
            .collect()
    };
    let mut spine: Vec<usize> = profile
        .joints_with_role(Role::Pelvis)
        .filter(|&j| j < joints)
        .take(1)
        .collect();
    spine.extend(ordered(
        BodyPart::Torso,
        &[Role::Spine, Role::Neck, Role::Head],
    ));
    let arm = [Role::Collar, Role::Shoulder, Role::Elbow, Role::Hand];
    let leg = [Role::Hip, Role::Knee, Role::Ankle, Role::Toe];
    let mut out = vec![Chain {
        part: BodyPart::Torso,
        joints: spine,
    }];
    for (part, roles) in [
        (BodyPart::LeftArm, &arm),
        (BodyPart::RightArm, &arm),
        (BodyPart::LeftLeg, &leg),
        (BodyPart::RightLeg, &leg),
    ] {
        out.push(Chain {
            part,
            joints: ordered(part, roles),
        });
    }
    out.retain(|c| c.joints.len() >= 2);
    out
}

/// Two chains (by index) and the bones of theirs to compare (by index into the bone list).
type ChainPair = (usize, usize, Vec<(usize, usize)>);

/// Two bones to compare, as joint index pairs.
type BonePair = ((usize, usize), (usize, usize));

/// Bone pairs of two chains that are not close by construction. A limb's first bone (clavicle,
/// thigh) is anchored on or beside the spine (CMU's clavicles start exactly on a spine joint,
/// Bandai's thighs 10 cm from the pelvis) and beside its partner's first bone, so it is compared
/// with neither the spine nor another limb's first bone. Bones sharing a joint are skipped too.
fn bone_pairs(a: &Chain, b: &Chain) -> Vec<BonePair> {
    let bones = |c: &Chain| -> Vec<(bool, (usize, usize))> {
        c.joints
            .windows(2)
            .enumerate()
            .map(|(i, w)| (i == 0 && !c.is_spine(), (w[0], w[1])))
            .collect()
    };
    let mut out = Vec::new();
    for (a_root, x) in bones(a) {
        for &(b_root, y) in &bones(b) {
            let anchored = (a_root && (b_root || b.is_spine())) || (b_root && a.is_spine());
            let shared = [x.0, x.1].iter().any(|j| *j == y.0 || *j == y.1);
            if !anchored && !shared {
                out.push((x, y));
            }
        }
    }
    out
}

/// A chain's joint bounding box in frame `f`, padded by [`LIMB_RADIUS`].
fn padded_box(clip: &Clip, chain: &Chain, f: usize) -> (DVec3, DVec3) {
    let (lo, hi) = chain.joints.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &j| (lo.min(clip.at(f, j)), hi.max(clip.at(f, j))),
    );
    (lo - LIMB_RADIUS, hi + LIMB_RADIUS)
}

fn self_distance(clip: &Clip, profile: &Profile, out: &mut Plausibility) {
    let chains = chains(profile, clip.joints);
    // Every bone once; pairs name bones by index, so each frame measures a bone once.
    let mut bones: Vec<(usize, usize)> = Vec::new();
    let mut bone_index = |bone: (usize, usize)| match bones.iter().position(|b| *b == bone) {
        Some(i) => i,
        None => {
            bones.push(bone);
            bones.len() - 1
        }
    };
    // Chain pairs (by index) and their bone pairs (by bone index).
    let mut pairs: Vec<ChainPair> = Vec::new();
    for a in 0..chains.len() {
        for b in a + 1..chains.len() {
            let indexed: Vec<(usize, usize)> = bone_pairs(&chains[a], &chains[b])
                .into_iter()
                .map(|(x, y)| (bone_index(x), bone_index(y)))
                .collect();
            if !indexed.is_empty() {
                pairs.push((a, b, indexed));
            }
        }
    }
    let mut self_best: Option<(f64, usize, BodyPart)> = None;
    let mut limb_best: Option<(f64, usize, (BodyPart, BodyPart))> = None;
    let mut spheres: Vec<(DVec3, f64)> = vec![(DVec3::ZERO, 0.0); bones.len()];
    for f in 0..clip.frames {
        let boxes: Vec<(DVec3, DVec3)> = chains.iter().map(|c| padded_box(clip, c, f)).collect();
        for (sphere, &(j0, j1)) in spheres.iter_mut().zip(&bones) {
            let (p0, p1) = (clip.at(f, j0), clip.at(f, j1));
            *sphere = ((p0 + p1) * 0.5, (p1 - p0).length() * 0.5);
        }
        for (a, b, pair_bones) in pairs.iter() {
            let ((a_lo, a_hi), (b_lo, b_hi)) = (boxes[*a], boxes[*b]);
            // Broad phase (CODA): only chains whose padded boxes overlap get the bone test; boxes
            // apart are more than 2 * LIMB_RADIUS apart, the reported cap.
            if a_lo.cmpgt(b_hi).any() || b_lo.cmpgt(a_hi).any() {
                continue;
            }
            let (ca, cb) = (&chains[*a], &chains[*b]);
            let spine = ca.is_spine() || cb.is_spine();
            // Only a distance below the best so far changes the result, so a bone pair whose
            // bounding spheres are further apart than that is not measured. The margin keeps
            // rounding in the bound from skipping a pair the exact test would have taken.
            let best = if spine {
                self_best.map(|(d, _, _)| d)
            } else {
                limb_best.map(|(d, _, _)| d)
            };
            let d = pair_bones
                .iter()
                .filter(|&&(x, y)| {
                    let Some(best) = best else { return true };
                    let ((cx, rx), (cy, ry)) = (spheres[x], spheres[y]);
                    let reach = best * (1.0 + 1e-9) + 1e-12 + rx + ry;
                    cx.distance_squared(cy) <= reach * reach
                })
                .map(|&(x, y)| clip.bone_distance(f, bones[x], bones[y]))
                .fold(f64::INFINITY, f64::min);
            if spine {
                let limb = if ca.is_spine() { cb.part } else { ca.part };
                if self_best.is_none_or(|(best, _, _)| d < best) {
                    self_best = Some((d, f, limb));
                }
            } else if limb_best.is_none_or(|(best, _, _)| d < best) {
                limb_best = Some((d, f, (ca.part, cb.part)));
            }
        }
    }
    // Distances past the cap are only computed when boxes happen to overlap; clamping keeps the
    // value comparable between clips.
    let cap = 2.0 * LIMB_RADIUS;
    if let Some((d, f, part)) = self_best {
        out.self_distance = d.min(cap);
        out.self_distance_frame = f;
        out.self_distance_part = Some(part);
    }
    if let Some((d, f, parts)) = limb_best {
        out.limb_distance = d.min(cap);
        out.limb_distance_frame = f;
        out.limb_distance_parts = Some(parts);
    }
}

/// Distance between segments `p0 p1` and `q0 q1` (closest points by clamped parameters, after
/// Ericson, Real-Time Collision Detection 5.1.9); degenerate segments are points.
pub fn segment_distance(p0: DVec3, p1: DVec3, q0: DVec3, q1: DVec3) -> f64 {
    const EPS: f64 = 1e-12;
    let d1 = p1 - p0;
    let d2 = q1 - q0;
    let r = p0 - q0;
    let a = d1.length_squared();
    let e = d2.length_squared();
    let f = d2.dot(r);
    let (s, t) = if a <= EPS && e <= EPS {
        (0.0, 0.0)
    } else if a <= EPS {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(r);
        if e <= EPS {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            // Parallel segments (denom 0): any s works; start from 0 and let t and the re-clamp
            // below find the closest pair.
            let mut s = if denom > EPS {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    ((p0 + d1 * s) - (q0 + d2 * t)).length()
}

/// Per-frame lean (degrees): the angle between the vertical and the line from the base of
/// support to the centre of mass (the mean of the body joints, every joint weighing 1 as in CODA).
/// The base of support is the mean of the body joints within [`SUPPORT_BAND`] of the frame's
/// lowest one. `None` for frames whose centre of mass is less than [`MIN_LEVER`] above the base
/// (the body lies or sits on the floor; balance is not at stake).
pub fn lean_per_frame(positions: &[DVec3], joints: usize, profile: &Profile) -> Vec<Option<f64>> {
    let frames = positions.len().checked_div(joints).unwrap_or(0);
    let body = body_joints(profile, joints);
    (0..frames)
        .map(|f| frame_lean(&positions[f * joints..(f + 1) * joints], &body))
        .collect()
}

fn frame_lean(frame: &[DVec3], body: &[usize]) -> Option<f64> {
    let mean = |points: &mut dyn Iterator<Item = DVec3>| {
        let (sum, n) = points.fold((DVec3::ZERO, 0usize), |(s, n), p| (s + p, n + 1));
        (n > 0).then(|| sum / n as f64)
    };
    let com = mean(&mut body.iter().map(|&j| frame[j]))?;
    let lowest = body
        .iter()
        .map(|&j| frame[j].z)
        .fold(f64::INFINITY, f64::min);
    let base = mean(
        &mut body
            .iter()
            .map(|&j| frame[j])
            .filter(|p| p.z < lowest + SUPPORT_BAND),
    )?;
    let lever = com - base;
    (lever.z >= MIN_LEVER).then(|| lever.truncate().length().atan2(lever.z).to_degrees())
}

fn lean(clip: &Clip, body: &[usize], fps: f64, out: &mut Plausibility) {
    let per_frame: Vec<Option<f64>> = (0..clip.frames)
        .map(|f| frame_lean(clip.frame(f), body))
        .collect();
    let (sum, n) = per_frame
        .iter()
        .flatten()
        .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 {
        return;
    }
    out.lean_mean = sum / n as f64;
    // The artefact is a sustained lean; single frames of a sprint start or a stumble lean further.
    let half = if fps.is_finite() && fps > 0.0 {
        (LEAN_WINDOW * fps / 2.0).round() as usize
    } else {
        0
    };
    // Prefix sums of the measured values and of their count, so each window costs O(1).
    let mut prefix = vec![(0.0, 0usize); per_frame.len() + 1];
    for (f, v) in per_frame.iter().enumerate() {
        let (s, n) = prefix[f];
        prefix[f + 1] = match v {
            Some(v) => (s + v, n + 1),
            None => (s, n),
        };
    }
    for f in 0..per_frame.len() {
        let (lo, hi) = (f.saturating_sub(half), (f + half + 1).min(per_frame.len()));
        let (sum, n) = (prefix[hi].0 - prefix[lo].0, prefix[hi].1 - prefix[lo].1);
        if n > 0 && sum / n as f64 > out.lean {
            out.lean = sum / n as f64;
            out.lean_frame = f;
        }
    }
}

/// Net heading change (degrees) past which a motion counts as turning the other way than its text
/// says; Bandai Namco 2's walk-turns turn 90 to 180 degrees.
pub const CONTRADICTING_TURN_DEG: f64 = 45.0;
/// Displacement (metres) along the first frame's facing past which a motion counts as walking
/// the other way than its text says.
pub const CONTRADICTING_TRAVEL: f64 = 0.5;
/// A hand the text names contradicts the motion when it travels (relative to the pelvis) less
/// than this share of the other hand's path.
pub const CONTRADICTING_HAND_SHARE: f64 = 0.5;
/// Least path (metres, relative to the pelvis) of the other hand for a hand claim to be judged:
/// below it neither hand does anything to compare.
pub const MIN_HAND_PATH: f64 = 0.3;

/// A side.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    /// The character's left.
    Left,
    /// The character's right.
    Right,
}

impl Side {
    fn word(self) -> &'static str {
        match self {
            Side::Left => "left",
            Side::Right => "right",
        }
    }
}

/// What a text says a motion does, in terms the motion can be measured against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Claims {
    /// "turn left", "walk-turn-right", "turns to the left".
    pub turn: Option<Side>,
    /// Walking or stepping forward (`Some(true)`) or back (`Some(false)`).
    pub forward: Option<bool>,
    /// "left hand", "wave-right-hand" (only one side named).
    pub hand: Option<Side>,
}

/// The claims of `text`, read from its words (letters and digits; `-` and `_` separate words, so
/// file-name labels such as `walk-turn-left` read as text).
pub fn claims(text: &str) -> Claims {
    let lower = text.to_ascii_lowercase();
    let words: Vec<&str> = lower
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .collect();
    let side = |w: &str| match w {
        "left" | "leftward" | "leftwards" => Some(Side::Left),
        "right" | "rightward" | "rightwards" => Some(Side::Right),
        _ => None,
    };
    let mut out = Claims::default();
    let mut turns: Vec<Side> = Vec::new();
    let mut hands: Vec<Side> = Vec::new();
    for (i, w) in words.iter().enumerate() {
        let after = &words[i + 1..words.len().min(i + 4)];
        if matches!(*w, "turn" | "turns" | "turning" | "turned")
            && let Some(s) = after.iter().find_map(|a| side(a))
        {
            turns.push(s);
        }
        if let Some(s) = side(w)
            && words
                .get(i + 1)
                .is_some_and(|n| matches!(*n, "hand" | "hands"))
        {
            hands.push(s);
        }
        if matches!(
            *w,
            "walk" | "walks" | "walking" | "step" | "steps" | "stepping"
        ) {
            match words.get(i + 1).copied() {
                Some("back" | "backward" | "backwards") => out.forward = Some(false),
                Some("forward" | "forwards") => out.forward = Some(true),
                _ => {}
            }
        }
    }
    let one = |sides: &[Side]| match sides {
        [first, rest @ ..] if rest.iter().all(|s| s == first) => Some(*first),
        _ => None,
    };
    out.turn = one(&turns);
    out.hand = one(&hands);
    out
}

/// The largest left turn and the largest right turn (degrees, both `>= 0`) anywhere in a motion:
/// the largest rise and the largest fall of its heading, averaged over 0.5 s so the hips' swing
/// with every step does not count. `None` without a facing direction.
fn largest_turns(
    positions: &[DVec3],
    joints: usize,
    fps: f64,
    profile: &Profile,
) -> Option<(f64, f64)> {
    let track = crate::motion::canonical::heading_track(positions, joints, profile)?;
    let n = track.len();
    let half = if fps.is_finite() && fps > 0.0 {
        (0.25 * fps).round() as usize
    } else {
        0
    };
    let mut sums = vec![0.0; n + 1];
    for (f, h) in track.iter().enumerate() {
        sums[f + 1] = sums[f] + h;
    }
    let (mut low, mut high) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut left, mut right) = (0.0f64, 0.0f64);
    for f in 0..n {
        let (lo, hi) = (f.saturating_sub(half), (f + half + 1).min(n));
        let h = ((sums[hi] - sums[lo]) / (hi - lo) as f64).to_degrees();
        low = low.min(h);
        high = high.max(h);
        left = left.max(h - low);
        right = right.max(high - h);
    }
    Some((left, right))
}

/// A clip whose text says one thing and whose motion measurably does another. The label is never
/// changed: the build lists these, and drops them only when asked.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Contradiction {
    /// The clip.
    pub clip_id: String,
    /// What the text says: `turn left`, `walk back`, `right hand`, ...
    pub claim: String,
    /// What the motion does, in words: `turns right`, `walks forward`, `moves the left hand`.
    pub motion: String,
    /// The measurement: degrees of net turn (left positive), metres along the first frame's
    /// facing, or the named hand's path over the other's.
    pub measured: f64,
}

/// The contradictions between `text` and a motion (dataset-axes positions, frame-major, `joints`
/// per frame, at `fps`): a turn the other way by more than [`CONTRADICTING_TURN_DEG`], a walk the
/// other way by more than [`CONTRADICTING_TRAVEL`], a named hand that moves less than
/// [`CONTRADICTING_HAND_SHARE`] of the other. Claims the motion cannot be measured for are not
/// judged.
pub fn contradictions(
    clip_id: &str,
    text: &str,
    positions: &[DVec3],
    joints: usize,
    fps: f64,
    profile: &Profile,
) -> Vec<Contradiction> {
    use crate::motion::canonical::{canonical_frame, hand_joint, net_turn};
    let said = claims(text);
    let mut out = Vec::new();
    let frames = positions.len().checked_div(joints).unwrap_or(0);
    if frames < 2 || !positions.iter().all(|p| p.is_finite()) {
        return out;
    }
    let note = |claim: String, motion: String, measured: f64| Contradiction {
        clip_id: clip_id.to_string(),
        claim,
        motion,
        measured,
    };
    if let Some(side) = said.turn
        && let Some(turn) = net_turn(positions, joints, fps, 0.5, profile).map(f64::to_degrees)
        && let Some((left, right)) = largest_turns(positions, joints, fps, profile)
    {
        // The other way overall, and never the way the text says: a walk that turns right and
        // then, at the end of the take, turns round to the left is not a contradiction.
        let wrong = match side {
            Side::Left => turn <= -CONTRADICTING_TURN_DEG && left < CONTRADICTING_TURN_DEG,
            Side::Right => turn >= CONTRADICTING_TURN_DEG && right < CONTRADICTING_TURN_DEG,
        };
        if wrong {
            let did = if turn > 0.0 { "left" } else { "right" };
            out.push(note(
                format!("turn {}", side.word()),
                format!("turns {did} {:.0} degrees", turn.abs()),
                turn,
            ));
        }
    }
    if let Some(forward) = said.forward
        && let Some(frame) = canonical_frame(&positions[..joints], profile)
        && let Some(last) = positions.get((frames - 1) * joints + profile.root)
    {
        let along = frame.apply(*last).y;
        let wrong = if forward {
            along <= -CONTRADICTING_TRAVEL
        } else {
            along >= CONTRADICTING_TRAVEL
        };
        if wrong {
            let did = if along > 0.0 { "forward" } else { "back" };
            out.push(note(
                format!("walk {}", if forward { "forward" } else { "back" }),
                format!("walks {did} {:.2} m", along.abs()),
                along,
            ));
        }
    }
    if let Some(side) = said.hand {
        let (named, other) = match side {
            Side::Left => (BodyPart::LeftArm, BodyPart::RightArm),
            Side::Right => (BodyPart::RightArm, BodyPart::LeftArm),
        };
        let path = |part: BodyPart| -> Option<f64> {
            let hand = hand_joint(profile, part)?;
            let at = |f: usize| positions[f * joints + hand] - positions[f * joints + profile.root];
            Some((1..frames).map(|f| (at(f) - at(f - 1)).length()).sum())
        };
        if let (Some(named_path), Some(other_path)) = (path(named), path(other))
            && other_path >= MIN_HAND_PATH
            && named_path < CONTRADICTING_HAND_SHARE * other_path
        {
            let did = if side == Side::Left { "right" } else { "left" };
            out.push(note(
                format!("{} hand", side.word()),
                format!(
                    "moves the {did} hand ({:.2} m against {:.2} m)",
                    other_path, named_path
                ),
                named_path / other_path,
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use rayon::prelude::*;

    use super::*;
    use crate::motion::canonical::dataset_positions;
    use crate::motion::{ProfileSpec, read_bvh};

    /// The distances as measured before bone pairs were skipped by their bounding spheres: every
    /// bone pair of every chain pair whose boxes overlap.
    fn every_pair(clip: &Clip, profile: &Profile) -> [Option<(f64, usize)>; 2] {
        let chains = chains(profile, clip.joints);
        let [mut spine_best, mut limb_best]: [Option<(f64, usize)>; 2] = [None, None];
        for f in 0..clip.frames {
            for a in 0..chains.len() {
                for b in a + 1..chains.len() {
                    let bones = bone_pairs(&chains[a], &chains[b]);
                    let ((a_lo, a_hi), (b_lo, b_hi)) = (
                        padded_box(clip, &chains[a], f),
                        padded_box(clip, &chains[b], f),
                    );
                    if bones.is_empty() || a_lo.cmpgt(b_hi).any() || b_lo.cmpgt(a_hi).any() {
                        continue;
                    }
                    let d = bones
                        .iter()
                        .map(|&(x, y)| clip.bone_distance(f, x, y))
                        .fold(f64::INFINITY, f64::min);
                    let best = if chains[a].is_spine() || chains[b].is_spine() {
                        &mut spine_best
                    } else {
                        &mut limb_best
                    };
                    if best.is_none_or(|(x, _)| d < x) {
                        *best = Some((d, f));
                    }
                }
            }
        }
        [spine_best, limb_best]
    }

    #[test]
    fn skipping_far_bone_pairs_measures_what_every_pair_measures_on_real_captures() {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut files: Vec<(PathBuf, &str)> = vec![(root.join("fixtures/cmu/01_01.bvh"), "cmu")];
        for dir in [
            root.join("fixtures/bandai-namco-1/data"),
            root.join("../shared/data/bandai-namco-2-subset/data"),
        ] {
            let listing = std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{dir:?}: {e}"));
            for entry in listing {
                let path = entry.unwrap().path();
                if path.extension().is_some_and(|e| e == "bvh") {
                    files.push((path, "bandai-namco"));
                }
            }
        }
        assert!(files.len() > 60, "{} captures", files.len());
        files.par_iter().for_each(|(path, profile)| {
            let bvh = read_bvh(&std::fs::read_to_string(path).unwrap()).unwrap();
            let motion = &bvh.motion;
            let profile = ProfileSpec::bundled(profile)
                .unwrap()
                .bind(&motion.skeleton)
                .unwrap();
            let positions = dataset_positions(motion, &profile);
            let joints = motion.num_joints();
            let clip = Clip {
                positions: &positions,
                joints,
                frames: positions.len() / joints,
            };
            let mut pruned = Plausibility::default();
            self_distance(&clip, &profile, &mut pruned);
            let [spine, limb] = every_pair(&clip, &profile);
            let (spine, limb) = (spine.unwrap(), limb.unwrap());
            assert_eq!(
                (pruned.self_distance, pruned.self_distance_frame),
                (spine.0.min(2.0 * LIMB_RADIUS), spine.1),
                "{path:?}"
            );
            assert_eq!(
                (pruned.limb_distance, pruned.limb_distance_frame),
                (limb.0.min(2.0 * LIMB_RADIUS), limb.1),
                "{path:?}"
            );
        });
    }
}
