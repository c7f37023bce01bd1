//! Part-velocity evidence: which parts a motion moves, from how fast they move (SINC section 3.1,
//! "Could we extract body part labels without GPT-3?", Table 1 first row).
//!
//! For every frame and part we take the mean speed of the part's joints, then standardise and
//! threshold:
//!
//! * **Global** is the pelvis moving in the world: the mean world speed of the root-motion joint
//!   and its children (hips and spine base), so both travelling and turning on the spot count.
//! * **Every other part** moves relative to what it hangs from: joint positions minus the position
//!   of the part's *anchor* (the parent of its topmost joint: the chest for an arm, the pelvis for
//!   a leg or the torso) before differentiating. Walking then does not make the arms or the torso
//!   "move" because the body travels. (SINC's baseline differentiates raw positions, one reason it
//!   scores 0.65.) Only the anchor's position is removed, not its orientation: in the anchor's
//!   rotating frame a bow (the pelvis tilting) made the still legs "move"; in world orientation it
//!   does not.
//! * **Standardised over frames**: the per-frame speeds of all six parts of the motion are pooled;
//!   a part's score is its mean speed minus the pooled mean, over the pooled standard deviation
//!   (the mean over frames of its z-scores). The score says how much a part moves *compared with
//!   the rest of this motion*, whatever the capture's overall pace or style.
//! * **Threshold**: a part is involved when its score is above [`SCORE_THRESHOLD`] (0: faster than
//!   the motion's average part) and its mean speed is above [`MIN_SPEED`] (0.03 m/s), so a still
//!   motion involves nothing instead of its noise. The score threshold was fixed from its meaning
//!   before any measurement. The speed floor was first set to 0.10 m/s from hand speeds; on the
//!   Bandai captures that silenced 14 slow-style takes (a timid wave moves the arm's four joints
//!   0.06 m/s on average over the take), so it was lowered to 0.03 m/s, about twice the speed of
//!   parts that stay still in those takes (legs while waving: 0.007-0.02 m/s: mocap jitter and
//!   sway). SINC picked its threshold by visual inspection; `docs/part-labels.md` lists how
//!   agreement moves with both thresholds.
//!
//! Positions come from [`dataset_positions`] (metres, dataset axes).

use glam::DVec3;

use super::PartSet;
use motionforge_core::motion::canonical::dataset_positions;
use motionforge_core::motion::{BodyPart, Motion, Profile};

/// Score above which a part counts as involved: faster than this motion's average part.
pub const SCORE_THRESHOLD: f64 = 0.0;

/// Mean speed (m/s) a part must also exceed: below it the part is at rest whatever its score
/// (about twice the jitter of still parts in real captures; see the module doc).
pub const MIN_SPEED: f64 = 0.03;

/// The velocity evidence for one motion.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PartScores {
    /// Mean speed per part over frames, metres per second, in SINC's order.
    pub speed: [f64; 6],
    /// Standardised score per part: `(speed - pooled mean) / pooled standard deviation`.
    pub score: [f64; 6],
    /// Parts whose score exceeds [`SCORE_THRESHOLD`] and speed [`MIN_SPEED`].
    pub parts: PartSet,
    /// Frames the speeds were measured over (frame pairs).
    pub frames: usize,
}

impl PartScores {
    /// The parts at other thresholds than the defaults, for studying the choice.
    pub fn parts_at(&self, score_threshold: f64, min_speed: f64) -> PartSet {
        BodyPart::ALL
            .into_iter()
            .enumerate()
            .filter(|&(i, _)| self.score[i] > score_threshold && self.speed[i] > min_speed)
            .map(|(_, p)| p)
            .collect()
    }
}

/// The parts a motion moves (see the module doc).
pub fn motion_parts(motion: &Motion, profile: &Profile) -> PartSet {
    part_scores(motion, profile).parts
}

/// Fraction of the six parts on which two sets agree (both have it or both lack it).
pub fn agreement(a: PartSet, b: PartSet) -> f64 {
    let differ = (a.bits() ^ b.bits()).count_ones() as f64;
    (6.0 - differ) / 6.0
}

/// Speeds, scores and parts of one motion. A motion of fewer than two frames, or a part with no
/// joint in the profile, has speed 0 for that part and is never involved.
pub fn part_scores(motion: &Motion, profile: &Profile) -> PartScores {
    let n = motion.num_joints();
    let frames = motion.num_frames();
    let positions = dataset_positions(motion, profile);
    let parents = motion.skeleton.parents();
    let depth = depths(&parents);

    // Joints measured per part, and the anchor they are measured against (None: world).
    let groups: Vec<(Vec<usize>, Option<usize>)> = BodyPart::ALL
        .iter()
        .map(|&part| {
            if part == BodyPart::Global {
                let root = profile.root;
                let mut joints = vec![root];
                joints.extend((0..n).filter(|&j| parents[j] == Some(root)));
                (joints, None)
            } else {
                let joints: Vec<usize> = profile.joints_of(part).collect();
                let top = joints.iter().copied().min_by_key(|&j| depth[j]);
                let anchor = top.and_then(|j| parents[j]);
                (joints, anchor)
            }
        })
        .collect();

    let steps = frames.saturating_sub(1);
    let mut per_frame: Vec<[f64; 6]> = Vec::with_capacity(steps);
    if n > 0 && positions.len() == frames * n {
        let local = |f: usize, j: usize, anchor: Option<usize>| -> DVec3 {
            let p = positions[f * n + j];
            match anchor {
                Some(a) => p - positions[f * n + a],
                None => p,
            }
        };
        for f in 0..steps {
            let mut v = [0.0; 6];
            for (p, (joints, anchor)) in groups.iter().enumerate() {
                if joints.is_empty() {
                    continue;
                }
                let sum: f64 = joints
                    .iter()
                    .map(|&j| (local(f + 1, j, *anchor) - local(f, j, *anchor)).length())
                    .sum();
                v[p] = sum / joints.len() as f64 * motion.fps;
            }
            per_frame.push(v);
        }
    }

    let mut speed = [0.0; 6];
    for v in &per_frame {
        for p in 0..6 {
            speed[p] += v[p];
        }
    }
    if !per_frame.is_empty() {
        for s in &mut speed {
            *s /= per_frame.len() as f64;
        }
    }
    let pooled: Vec<f64> = per_frame.iter().flatten().copied().collect();
    let (mean, sd) = mean_sd(&pooled);
    let score = speed.map(|s| if sd > 0.0 { (s - mean) / sd } else { 0.0 });
    let mut scores = PartScores {
        speed,
        score,
        parts: PartSet::EMPTY,
        frames: per_frame.len(),
    };
    scores.parts = scores.parts_at(SCORE_THRESHOLD, MIN_SPEED);
    scores
}

fn mean_sd(xs: &[f64]) -> (f64, f64) {
    if xs.is_empty() {
        return (0.0, 0.0);
    }
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// Depth of each joint in the hierarchy (roots 0). Parents come before children in a skeleton.
fn depths(parents: &[Option<usize>]) -> Vec<usize> {
    let mut depth = vec![0usize; parents.len()];
    for j in 0..parents.len() {
        if let Some(p) = parents[j]
            && p < j
        {
            depth[j] = depth[p] + 1;
        }
    }
    depth
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agreement_counts_matching_parts() {
        assert_eq!(agreement(PartSet::ARMS, PartSet::ARMS), 1.0);
        assert_eq!(agreement(PartSet::EMPTY, PartSet::ALL), 0.0);
        let a = PartSet::from(BodyPart::LeftArm);
        assert!((agreement(a, PartSet::ARMS) - 5.0 / 6.0).abs() < 1e-12);
    }

    use std::sync::Arc;

    use motionforge_core::motion::ProfileSpec;

    /// SMPL-22 with every joint at the origin of its parent, moving `joint` along x by
    /// `amplitude * sin` per frame (metres, 30 fps, 60 frames).
    fn smpl_motion(joint: Option<&str>, amplitude: f64) -> (Motion, Profile) {
        let spec = ProfileSpec::bundled("smpl-22").unwrap();
        let skeleton = spec.skeleton().unwrap();
        let profile = spec.bind(&skeleton).unwrap();
        let n = skeleton.len();
        let moving = joint.and_then(|name| skeleton.index_of(name));
        let frames = 60;
        let mut translations = vec![DVec3::new(0.0, 0.1, 0.0); frames * n];
        for f in 0..frames {
            if let Some(j) = moving {
                translations[f * n + j].x = amplitude * (f as f64 * 0.3).sin();
            }
        }
        let motion = Motion {
            skeleton: Arc::new(skeleton),
            fps: 30.0,
            rotations: vec![glam::DQuat::IDENTITY; frames * n],
            translations,
        };
        (motion, profile)
    }

    #[test]
    fn a_still_motion_moves_no_part() {
        let (motion, profile) = smpl_motion(None, 0.0);
        let scores = part_scores(&motion, &profile);
        assert_eq!(scores.parts, PartSet::EMPTY);
        assert_eq!(scores.speed, [0.0; 6]);
        assert_eq!(scores.frames, 59);
    }

    #[test]
    fn a_waving_wrist_is_the_right_arm() {
        let (motion, profile) = smpl_motion(Some("right_wrist"), 0.3);
        assert_eq!(
            motion_parts(&motion, &profile),
            PartSet::from(BodyPart::RightArm)
        );
    }

    #[test]
    fn travelling_without_limb_motion_is_global_only() {
        // The pelvis carries every other joint along: relative to their anchors they stay put.
        let (motion, profile) = smpl_motion(Some("pelvis"), 0.5);
        assert_eq!(motion_parts(&motion, &profile), PartSet::GLOBAL);
    }

    #[test]
    fn pooled_standardisation() {
        let (m, s) = mean_sd(&[1.0, 3.0]);
        assert_eq!((m, s), (2.0, 1.0));
        assert_eq!(mean_sd(&[]), (0.0, 0.0));
    }
}
