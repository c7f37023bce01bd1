//! Composing two motions by body part (SINC section 3.1 and appendix C), on local rotations, so
//! every column of the composite (positions by forward kinematics included) is consistent.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::motion::Motion;
use super::profile::{BodyPart, Profile};

/// The six parts as a bit set, local to composition (the dataset-level `PartSet` lives in
/// the `parts` module; motion knows nothing of labelling).
pub type PartMask = u8;

/// The bit of a part in a [`PartMask`], in SINC's order.
pub fn part_bit(part: BodyPart) -> PartMask {
    1 << BodyPart::ALL.iter().position(|p| *p == part).unwrap_or(0)
}

const LEG_BLOCK: [BodyPart; 3] = [BodyPart::Global, BodyPart::LeftLeg, BodyPart::RightLeg];

/// Where the composite's frames start in the longer motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Trim {
    /// Keep the longer motion's first frames (SINC's training setting).
    #[default]
    Start,
    /// Start at this frame of the longer motion (a seeded random offset, chosen by the caller).
    At(usize),
}

/// A composite and which parts came from which motion.
#[derive(Debug, Clone, PartialEq)]
pub struct Composite {
    /// The composed motion on the skeleton of the motion that gave the legs.
    pub motion: Motion,
    /// Parts taken from the first argument.
    pub parts_from_first: PartMask,
    /// Parts taken from the second argument.
    pub parts_from_second: PartMask,
    /// Frame of each input where the composite starts.
    pub starts: [usize; 2],
}

/// Composes `first` (doing `first_parts`) and `second` (doing `second_parts`) with SINC's five
/// steps: (1) trim the longer to the shorter; (2) order so B has fewer parts than A; (3) if B
/// involves a leg or the global orientation, both legs, the root rotation and the root
/// translation come from B, otherwise from A; (4) every other part comes from B if B does it,
/// else from A; (5) combine per joint. Joints without a part come from A. Both motions must be
/// on skeletons with the same joints at the same rate; the composite keeps the skeleton (offsets)
/// of the motion that gives the legs, so feet stay on its bones.
pub fn compose(
    first: &Motion,
    first_parts: PartMask,
    second: &Motion,
    second_parts: PartMask,
    profile: &Profile,
    trim: Trim,
) -> Composite {
    // (2) B has fewer parts; on a tie the second argument is B, so the call order decides.
    let swap = first_parts.count_ones() < second_parts.count_ones();
    let (a, b, b_parts) = if swap {
        (second, first, first_parts)
    } else {
        (first, second, second_parts)
    };
    // (1) Trim the longer to the shorter.
    let frames = a.num_frames().min(b.num_frames());
    let offset = |m: &Motion| match trim {
        Trim::Start => 0,
        Trim::At(k) => k.min(m.num_frames() - frames),
    };
    let (a_start, b_start) = (offset(a), offset(b));
    // (3) The leg block travels together: legs, root rotation and root translation.
    let leg_mask: PartMask = LEG_BLOCK.iter().map(|p| part_bit(*p)).sum();
    let legs_from_b = b_parts & leg_mask != 0;
    let n = a.num_joints();
    let from_b: Vec<bool> = (0..n)
        .map(|j| match profile.part_of.get(j).copied().flatten() {
            Some(p) if LEG_BLOCK.contains(&p) => legs_from_b,
            Some(p) => b_parts & part_bit(p) != 0,
            None => false,
        })
        .collect();
    // The composite keeps the skeleton of the leg block's owner: its translations carry the root
    // motion and its bones hold the feet where that motion planted them.
    let (base, base_start) = if legs_from_b {
        (b, b_start)
    } else {
        (a, a_start)
    };
    let mut rotations = Vec::with_capacity(frames * n);
    let mut translations = Vec::with_capacity(frames * n);
    for f in 0..frames {
        for (j, &use_b) in from_b.iter().enumerate() {
            let (src, start) = if use_b { (b, b_start) } else { (a, a_start) };
            rotations.push(src.rotation(start + f, j));
            translations.push(base.translation(base_start + f, j));
        }
    }
    let motion = Motion {
        skeleton: Arc::clone(&base.skeleton),
        fps: a.fps,
        rotations,
        translations,
    };
    let mut parts_b: PartMask = 0;
    let mut parts_a: PartMask = 0;
    for part in BodyPart::ALL {
        let bit = part_bit(part);
        let takes_b = if LEG_BLOCK.contains(&part) {
            legs_from_b
        } else {
            b_parts & bit != 0
        };
        if takes_b {
            parts_b |= bit
        } else {
            parts_a |= bit
        }
    }
    let (parts_from_first, parts_from_second, starts) = if swap {
        (parts_b, parts_a, [b_start, a_start])
    } else {
        (parts_a, parts_b, [a_start, b_start])
    };
    Composite {
        motion,
        parts_from_first,
        parts_from_second,
        starts,
    }
}
