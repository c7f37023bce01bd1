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
    let (parts_from_first, parts_from_second) = contributions(first_parts, second_parts);
    let starts = if swap {
        [b_start, a_start]
    } else {
        [a_start, b_start]
    };
    Composite {
        motion,
        parts_from_first,
        parts_from_second,
        starts,
    }
}

/// The parts each motion gives a composite of `first` (doing `first_parts`) and `second` (doing
/// `second_parts`): steps (2) to (4) of [`compose`], as `(from first, from second)`.
pub fn contributions(first_parts: PartMask, second_parts: PartMask) -> (PartMask, PartMask) {
    let swap = first_parts.count_ones() < second_parts.count_ones();
    let b_parts = if swap { first_parts } else { second_parts };
    let leg_mask: PartMask = LEG_BLOCK.iter().map(|p| part_bit(*p)).sum();
    let legs_from_b = b_parts & leg_mask != 0;
    let (mut parts_a, mut parts_b): (PartMask, PartMask) = (0, 0);
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
    if swap {
        (parts_b, parts_a)
    } else {
        (parts_a, parts_b)
    }
}

/// Horizontal path (metres) below which a motion is not counted as travelling.
pub const MIN_TRAVEL: f64 = 0.5;
/// Net heading change (degrees) below which a motion is not counted as turning.
pub const MIN_TURN_DEG: f64 = 30.0;
/// Seconds of heading averaged at each end of a stretch to measure its turn: the hips swing from
/// side to side with every step. A short window averages a quarter of its length instead.
pub const HEADING_SMOOTHING: f64 = 0.5;
/// A frame step is active when the action's rate (root speed, or the parts' angular speed) is at
/// least this share of its mean over the motion.
pub const ACTIVE_SHARE: f64 = 0.5;

/// The window of a motion a composite keeps, and how much of the motion's action is in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActionWindow {
    /// First frame of the window.
    pub start: usize,
    /// Share of the action the window keeps, in `[0, 1]`. For a motion that turns (global part
    /// or a leg, net heading change of [`MIN_TURN_DEG`] or more): the share of the net heading
    /// change inside the window. Otherwise the share of the action's active frame steps (see
    /// [`ACTIVE_SHARE`]; the rate is the root's horizontal speed for a leg block that travels
    /// [`MIN_TRAVEL`], else the summed angular speed of the parts' joints) that the window
    /// covers, out of as many as it can hold: a steady walk or wave keeps 1 in any window.
    pub kept: f64,
}

/// What a motion does, per frame, as prefix sums (index `f`: from frame 0 to frame `f`).
enum ActionTrace {
    /// Prefix sums of the unwrapped heading (radians) and of the path (metres, which breaks
    /// ties between windows that keep the same share of the turn); `ends` is how many frames of
    /// heading are averaged at each end of a stretch.
    Turn {
        heading: Vec<f64>,
        path: Vec<f64>,
        ends: usize,
    },
    /// The action's rate summed, and its active steps counted.
    Activity { amount: Vec<f64>, active: Vec<f64> },
}

impl ActionTrace {
    /// Share of the action in frames `start..start + frames` (`frames >= 1`), and the amount
    /// windows are chosen by.
    fn measure(&self, start: usize, frames: usize) -> (f64, f64) {
        let last = start + frames - 1;
        let within = |p: &Vec<f64>| p[last] - p[start];
        let whole = |p: &Vec<f64>| p[p.len() - 1] - p[0];
        match self {
            ActionTrace::Turn {
                heading,
                path,
                ends,
            } => {
                let k = (*ends).min(frames / 4).max(1);
                let whole = turn(heading, 0, heading.len() - 1, k);
                let share = if whole.abs() < 1e-9 {
                    1.0
                } else {
                    (turn(heading, start, frames, k) / whole).clamp(0.0, 1.0)
                };
                (share, share * 1e6 + within(path))
            }
            ActionTrace::Activity { amount, active } => {
                let room = (frames - 1) as f64;
                let can = room.min(whole(active));
                let share = if can <= 0.0 {
                    1.0
                } else {
                    (within(active) / can).clamp(0.0, 1.0)
                };
                (share, within(amount))
            }
        }
    }
}

/// The window of `frames` frames of `motion` that keeps most of the action of `parts` (the parts
/// of its label it gives a composite): for a turn, the most net heading change (then the most
/// path); for other locomotion the most path; otherwise the most motion of the parts' joints.
/// The earliest of equal windows wins. A motion no longer than `frames` is kept whole.
pub fn action_window(
    motion: &Motion,
    parts: PartMask,
    profile: &Profile,
    frames: usize,
) -> ActionWindow {
    let n = motion.num_frames();
    if frames == 0 || frames >= n || parts == 0 {
        return ActionWindow {
            start: 0,
            kept: 1.0,
        };
    }
    let trace = action_trace(motion, parts, profile);
    let (kept, amount) = trace.measure(0, frames);
    let mut best = (ActionWindow { start: 0, kept }, amount);
    for start in 1..=n - frames {
        let (kept, amount) = trace.measure(start, frames);
        if amount > best.1 + 1e-9 {
            best = (ActionWindow { start, kept }, amount);
        }
    }
    best.0
}

/// Share of the action of `parts` that frames `start..start + frames` of `motion` keep (see
/// [`ActionWindow::kept`]).
pub fn action_kept(
    motion: &Motion,
    parts: PartMask,
    profile: &Profile,
    start: usize,
    frames: usize,
) -> f64 {
    let n = motion.num_frames();
    if frames == 0 || frames >= n || parts == 0 || start + frames > n {
        return 1.0;
    }
    action_trace(motion, parts, profile)
        .measure(start, frames)
        .0
}

/// Prefix sums of per-step values: element `f` is the sum over the steps before frame `f`.
fn prefix(steps: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut out = vec![0.0];
    let mut sum = 0.0;
    for v in steps {
        sum += v;
        out.push(sum);
    }
    out
}

/// Per-step rates as an activity trace: their prefix, and the prefix of the steps at least
/// [`ACTIVE_SHARE`] of the mean rate.
fn activity(rates: &[f64]) -> ActionTrace {
    let mean = rates.iter().sum::<f64>() / rates.len().max(1) as f64;
    let active = rates
        .iter()
        .map(|&r| f64::from(u8::from(mean > 0.0 && r >= ACTIVE_SHARE * mean)));
    ActionTrace::Activity {
        amount: prefix(rates.iter().copied()),
        active: prefix(active),
    }
}

/// Heading change over frames `start..start + frames`: the mean heading of its last `k` frames
/// less that of its first `k`, from `prefix`, the prefix sums of the unwrapped heading.
fn turn(prefix: &[f64], start: usize, frames: usize, k: usize) -> f64 {
    let mean = |a: usize, b: usize| (prefix[b] - prefix[a]) / (b - a) as f64;
    let end = start + frames;
    mean(end - k, end) - mean(start, start + k)
}

fn action_trace(motion: &Motion, parts: PartMask, profile: &Profile) -> ActionTrace {
    let n = motion.num_frames();
    let leg_mask: PartMask = LEG_BLOCK.iter().map(|p| part_bit(*p)).sum();
    let mut parts = parts;
    if parts & leg_mask != 0 {
        let joints = motion.num_joints();
        let positions = super::canonical::dataset_positions(motion, profile);
        let root = |f: usize| {
            positions
                .get(f * joints + profile.root)
                .copied()
                .unwrap_or_default()
        };
        let speeds: Vec<f64> = (1..n)
            .map(|f| (root(f) - root(f - 1)).truncate().length())
            .collect();
        let path = prefix(speeds.iter().copied());
        let ends = if motion.fps.is_finite() && motion.fps > 0.0 {
            ((HEADING_SMOOTHING * motion.fps).round() as usize).max(1)
        } else {
            1
        };
        if let Some(unwrapped) = super::canonical::heading_track(&positions, joints, profile) {
            let heading = prefix(unwrapped.iter().copied());
            let k = ends.min(n / 4).max(1);
            if n >= 2 && turn(&heading, 0, n, k).abs() >= MIN_TURN_DEG.to_radians() {
                return ActionTrace::Turn {
                    heading,
                    path,
                    ends,
                };
            }
        }
        if path.last().is_some_and(|p| *p >= MIN_TRAVEL) {
            return activity(&speeds);
        }
        // A leg block that neither turns nor travels (a kick) is measured by its joints' motion.
        parts |= leg_mask;
    }
    let joints: Vec<usize> = (0..motion.num_joints())
        .filter(|&j| {
            profile
                .part_of
                .get(j)
                .copied()
                .flatten()
                .is_some_and(|p| parts & part_bit(p) != 0)
        })
        .collect();
    let rates: Vec<f64> = (1..n)
        .map(|f| {
            joints
                .iter()
                .map(|&j| {
                    motion
                        .rotation(f - 1, j)
                        .angle_between(motion.rotation(f, j))
                })
                .sum::<f64>()
        })
        .collect();
    activity(&rates)
}
