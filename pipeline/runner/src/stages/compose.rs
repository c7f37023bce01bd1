//! `compose`: synthetic simultaneous pairs (SINC 3.1, appendix C). Compatible labelled single
//! clips (disjoint part sets, same skeleton profile, same split, different captures) are stitched by
//! body part; every composite is checked for plausibility before it reaches the dataset. (Real
//! clips get the same metrics when their rows are written, so the two distributions can be
//! compared.)

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use motionforge_core::base::{Named, Tally};
use motionforge_core::motion::canonical::dataset_positions;
use motionforge_core::motion::compose::{Trim, action_kept, action_window, compose, contributions};
use motionforge_core::motion::{BodyPart, Motion, Profile};
use motionforge_core::quality::{Check, Plausibility, plausibility};
use motionforge_language::compose_text::compose_variants;
use motionforge_language::parts::PartSet;
use motionforge_sources::clip::{Clip, SourceKind, Split};

/// Stage name.
pub const NAME: &str = "compose";
/// Bump when the stage's output for the same input changes.
pub const VERSION: u32 = 7;

pub use crate::config::SyntheticConfig;

/// Counts for the build report: candidates, compatible pairs, composed, dropped by reason.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ComposeReport {
    /// Labelled single clips that may be composed.
    pub candidates: usize,
    /// Unordered candidate pairs that are compatible (disjoint parts, same profile and split,
    /// different captures).
    pub compatible: usize,
    /// Pairs drawn by the sampler.
    pub sampled: usize,
    /// Composites kept.
    pub composed: usize,
    /// Pairs dropped, each under one reason: the LLM veto, `action_cut` (the crop keeps less of
    /// the longer clip's action than `min_action_kept`) or the first plausibility check it fails.
    pub dropped: Tally<PairDrop>,
}

/// Why a sampled pair became no composite: the keys of [`ComposeReport::dropped`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PairDrop {
    /// The LLM pair check said the two actions cannot be done at once.
    LlmIncompatible,
    /// The crop keeps less of the longer clip's action than `min_action_kept`.
    ActionCut,
    /// The composite fails this plausibility check (the first it fails).
    Implausible(Check),
}

impl Named for PairDrop {
    const ALL: &'static [PairDrop] = &[
        PairDrop::LlmIncompatible,
        PairDrop::ActionCut,
        PairDrop::Implausible(Check::FootSkating),
        PairDrop::Implausible(Check::GroundPenetration),
        PairDrop::Implausible(Check::SelfPenetration),
        PairDrop::Implausible(Check::Lean),
    ];

    fn name(self) -> &'static str {
        match self {
            PairDrop::LlmIncompatible => "llm_incompatible",
            PairDrop::ActionCut => "action_cut",
            PairDrop::Implausible(check) => check.name(),
        }
    }
}

impl std::fmt::Display for PairDrop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The stage's output.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ComposeOutput {
    /// The synthetic clips.
    pub clips: Vec<Clip>,
    /// Counts.
    pub report: ComposeReport,
}

/// A deterministic generator (SplitMix64) seeded per decision, so a clip's draw does not depend on
/// which other clips exist or how work was scheduled.
struct Rng(u64);

impl Rng {
    fn new(seed: u64, key: &str) -> Rng {
        let mut h: u64 = seed ^ 0x9e37_79b9_7f4a_7c15;
        for b in key.bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
        Rng(h)
    }

    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn mask(parts: PartSet) -> u8 {
    parts
        .iter()
        .map(motionforge_core::motion::compose::part_bit)
        .sum()
}

fn part_set(mask: u8) -> PartSet {
    BodyPart::ALL
        .into_iter()
        .filter(|p| mask & motionforge_core::motion::compose::part_bit(*p) != 0)
        .collect()
}

/// The pairs the sampler draws, in order, and the candidate/compatible counts. Deterministic in
/// `seed`; `split_of` names each clip's split (pairs never cross splits).
pub fn sample<'c>(
    clips: &[&'c Clip],
    config: &SyntheticConfig,
    seed: u64,
    split_of: impl Fn(&Clip) -> Split,
) -> (Vec<(&'c Clip, &'c Clip)>, ComposeReport) {
    let mut report = ComposeReport::default();
    if !config.enabled {
        return (Vec::new(), report);
    }
    let mut candidates: Vec<&'c Clip> = clips
        .iter()
        .copied()
        .filter(|c| c.kind == SourceKind::RealSingle && c.parts.is_some_and(|p| !p.is_empty()))
        .collect();
    candidates.sort_by(|a, b| a.clip_id.cmp(&b.clip_id));
    report.candidates = candidates.len();
    // Pairs never cross a profile or split: each candidate is only checked against the others
    // of its group (members in ascending order, so every partner list is ascending as well).
    let mut group_ids: BTreeMap<(String, Split), usize> = BTreeMap::new();
    let mut members: Vec<Vec<usize>> = Vec::new();
    let mut group_of: Vec<usize> = Vec::with_capacity(candidates.len());
    for (i, c) in candidates.iter().enumerate() {
        let next = group_ids.len();
        let g = *group_ids
            .entry((c.profile.clone(), split_of(c)))
            .or_insert(next);
        if g == members.len() {
            members.push(Vec::new());
        }
        members[g].push(i);
        group_of.push(g);
    }
    // Captures and parts as small integers: the checks below run for every pair of a group.
    let mut capture_ids: BTreeMap<&str, usize> = BTreeMap::new();
    let capture_of: Vec<usize> = candidates
        .iter()
        .map(|c| {
            let next = capture_ids.len();
            *capture_ids.entry(c.capture.path.as_str()).or_insert(next)
        })
        .collect();
    let parts_of: Vec<u8> = candidates
        .iter()
        .map(|c| c.parts.map_or(0, |p| p.bits()))
        .collect();
    let compatible =
        |i: usize, j: usize| capture_of[i] != capture_of[j] && parts_of[i] & parts_of[j] == 0;
    report.compatible = count_compatible(&members, &capture_of, &parts_of);
    let n = candidates.len();
    let mut count = vec![0usize; n];
    let cap = config.max_per_clip.unwrap_or(usize::MAX);
    let mut pairs: Vec<(usize, usize)> = Vec::new();
    // Partners are never listed for every candidate at once: those lists grew with the square of
    // the dataset (2 GB at 4x Bandai Namco 2). The exhaustive mode tests each pair of a group;
    // the draw counts a candidate's open partners instead of scanning for them (`draw_pairs`).
    if config.exhaustive {
        for i in 0..n {
            for &j in members[group_of[i]].iter().filter(|&&j| j > i) {
                if compatible(i, j) && count[i] < cap && count[j] < cap {
                    count[i] += 1;
                    count[j] += 1;
                    pairs.push((i, j));
                }
            }
        }
    } else {
        pairs = draw_pairs(
            &members,
            &group_of,
            &capture_of,
            &parts_of,
            cap,
            config.probability,
            |i| Rng::new(seed, &candidates[i].clip_id),
        );
    }
    report.sampled = pairs.len();
    (
        pairs
            .into_iter()
            .map(|(i, j)| (candidates[i], candidates[j]))
            .collect(),
        report,
    )
}

/// 0/1 flags over positions `0..n` in a Fenwick tree: how many are set up to a position, and
/// where the k-th set one is, in O(log n).
struct Flags {
    /// 1-based partial sums.
    tree: Vec<u32>,
}

impl Flags {
    fn new(flags: impl ExactSizeIterator<Item = bool>) -> Flags {
        let n = flags.len();
        let mut tree = vec![0u32; n + 1];
        for (i, set) in flags.enumerate() {
            tree[i + 1] += u32::from(set);
            let up = (i + 1) + ((i + 1) & (i + 1).wrapping_neg());
            if up <= n {
                tree[up] += tree[i + 1];
            }
        }
        Flags { tree }
    }

    /// Clears the flag at `pos` (which is set).
    fn clear(&mut self, pos: usize) {
        let mut i = pos + 1;
        while i < self.tree.len() {
            self.tree[i] -= 1;
            i += i & i.wrapping_neg();
        }
    }

    /// Flags set at positions `0..=pos`.
    fn prefix(&self, pos: usize) -> usize {
        let mut i = pos + 1;
        let mut sum = 0usize;
        while i > 0 {
            sum += self.tree[i] as usize;
            i -= i & i.wrapping_neg();
        }
        sum
    }

    /// Flags set.
    fn total(&self) -> usize {
        self.tree
            .len()
            .checked_sub(2)
            .map_or(0, |last| self.prefix(last))
    }

    /// Position of the set flag with `k` set flags before it (`k < total()`).
    fn kth(&self, k: usize) -> usize {
        let n = self.tree.len() - 1;
        let mut pos = 0usize;
        let mut remaining = k + 1;
        let mut step = if n == 0 { 0 } else { 1 << n.ilog2() };
        while step > 0 {
            let next = pos + step;
            if next <= n && (self.tree[next] as usize) < remaining {
                pos = next;
                remaining -= self.tree[next] as usize;
            }
            step >>= 1;
        }
        pos
    }
}

/// The sampler's draw: candidates in order, each (with probability `probability`, while it has
/// fewer than `cap` pairs) takes one partner uniformly among the open ones of its group: other
/// captures, disjoint parts, fewer than `cap` pairs, and not a candidate that already chose it.
/// Each member set of disjoint parts is counted by a Fenwick tree over the group, so a draw costs
/// O(log n) instead of a scan of the group (which made sampling grow with the square of the
/// dataset: 8.2 s of a 10x Bandai Namco 2 build). Same pairs as scanning, in the same order.
fn draw_pairs(
    members: &[Vec<usize>],
    group_of: &[usize],
    capture_of: &[usize],
    parts_of: &[u8],
    cap: usize,
    probability: f64,
    mut rng_of: impl FnMut(usize) -> Rng,
) -> Vec<(usize, usize)> {
    let n = group_of.len();
    let mut pos_of = vec![0usize; n];
    for group in members {
        for (p, &i) in group.iter().enumerate() {
            pos_of[i] = p;
        }
    }
    // Per group: its members' distinct part sets, each with the flags of the members that a
    // member with that set may pair with (disjoint parts, fewer than `cap` pairs).
    struct Group {
        sets: Vec<u8>,
        flags: Vec<Flags>,
        by_capture: BTreeMap<usize, Vec<usize>>,
    }
    let mut groups: Vec<Group> = members
        .iter()
        .map(|group| {
            let mut sets: Vec<u8> = group.iter().map(|&i| parts_of[i]).collect();
            sets.sort_unstable();
            sets.dedup();
            let flags = sets
                .iter()
                .map(|&set| Flags::new(group.iter().map(|&j| parts_of[j] & set == 0 && cap > 0)))
                .collect();
            let mut by_capture: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
            for &j in group {
                by_capture.entry(capture_of[j]).or_default().push(j);
            }
            Group {
                sets,
                flags,
                by_capture,
            }
        })
        .collect();
    let mut count = vec![0usize; n];
    // The candidates that chose each one on their turn.
    let mut chosen_by: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut pairs = Vec::new();
    for i in 0..n {
        let mut rng = rng_of(i);
        if rng.unit() >= probability || count[i] >= cap {
            continue;
        }
        let g = group_of[i];
        let group = &groups[g];
        let Ok(set) = group.sets.binary_search(&parts_of[i]) else {
            continue;
        };
        let flags = &group.flags[set];
        // Counted by the flags but not open to `i`: its own capture's members (itself too, had
        // it no parts) and the candidates that chose it.
        let mut closed: Vec<usize> = group
            .by_capture
            .get(&capture_of[i])
            .into_iter()
            .flatten()
            .chain(&chosen_by[i])
            .copied()
            .filter(|&j| parts_of[j] & parts_of[i] == 0 && count[j] < cap)
            .map(|j| pos_of[j])
            .collect();
        closed.sort_unstable();
        closed.dedup();
        let open = flags.total() - closed.len();
        if open == 0 {
            continue;
        }
        // The open member with `k` open ones before it: past each closed one ranked before it.
        let k = rng.below(open);
        let mut rank = k;
        for &p in &closed {
            if flags.prefix(p) - 1 <= rank {
                rank += 1;
            } else {
                break;
            }
        }
        let j = members[g][flags.kth(rank)];
        chosen_by[j].push(i);
        pairs.push((i, j));
        for x in [i, j] {
            count[x] += 1;
            if count[x] == cap {
                let group = &mut groups[g];
                for (set, flags) in group.sets.iter().zip(group.flags.iter_mut()) {
                    if parts_of[x] & set == 0 {
                        flags.clear(pos_of[x]);
                    }
                }
            }
        }
    }
    pairs
}

/// Compatible pairs (different captures, disjoint parts) within each group, counted from how many
/// members have each part set instead of by testing every pair.
fn count_compatible(members: &[Vec<usize>], capture_of: &[usize], parts_of: &[u8]) -> usize {
    let mut total = 0usize;
    for group in members {
        let mut by_parts = [0usize; 64];
        let mut by_capture: BTreeMap<usize, Vec<u8>> = BTreeMap::new();
        for &i in group {
            by_parts[usize::from(parts_of[i] & 63)] += 1;
            by_capture
                .entry(capture_of[i])
                .or_default()
                .push(parts_of[i]);
        }
        // Ordered pairs of disjoint part sets, halved (a set is disjoint from itself only when
        // empty, and candidates have parts).
        let mut ordered = 0usize;
        for (a, &na) in by_parts.iter().enumerate() {
            for (b, &nb) in by_parts.iter().enumerate() {
                if a & b == 0 && a != b {
                    ordered += na * nb;
                }
            }
        }
        // Less the disjoint pairs within one capture, which are never compatible.
        let mut same_capture = 0usize;
        for parts in by_capture.values() {
            for (k, a) in parts.iter().enumerate() {
                same_capture += parts[k + 1..].iter().filter(|&&b| a & b == 0).count();
            }
        }
        total += ordered / 2 - same_capture;
    }
    total
}

/// The distinct text pairs (normalised, in draw order within a pair) of the pairs the sampler
/// draws: what the optional LLM pair check asks about before anything is composed.
pub fn texts_to_check(
    clips: &[&Clip],
    config: &SyntheticConfig,
    seed: u64,
) -> Vec<(String, String)> {
    use crate::stages::label::normalize_text;
    let (pairs, _) = sample(clips, config, seed, |c| c.split.clone());
    let texts: std::collections::BTreeSet<(String, String)> = pairs
        .iter()
        .map(|(a, b)| (normalize_text(&a.text), normalize_text(&b.text)))
        .collect();
    texts.into_iter().collect()
}

/// Pairs composed in parallel before they are kept in order.
const PAIR_BATCH: usize = 64;

/// A sampled pair after composition, before it is checked and kept.
// Unboxed: a batch's pairs are held in one vector, as large as when every pair is composed.
#[allow(clippy::large_enum_variant)]
enum Made {
    /// The crop keeps less of the cropped clip's action than `min_action_kept` (`action_cut`).
    ActionCut,
    /// Composed and measured.
    Composed(Composed),
}

/// A composed pair and its plausibility metrics.
struct Composed {
    /// The pair's generator, after the draw of the offset (the text draw continues it).
    rng: Rng,
    trim: Trim,
    /// Share of the cropped clip's action the composite keeps.
    kept: f64,
    composite: motionforge_core::motion::compose::Composite,
    metrics: Plausibility,
}

/// How a synthetic clip's frames were made, enough to make them again: the build keeps this
/// instead of the frames.
#[derive(Debug, Clone, Copy)]
pub struct Recipe<'c> {
    /// The first source clip.
    pub first: &'c Clip,
    /// The parts it does.
    pub first_parts: motionforge_core::motion::compose::PartMask,
    /// The second source clip.
    pub second: &'c Clip,
    /// The parts it does.
    pub second_parts: motionforge_core::motion::compose::PartMask,
    /// Where the composite starts in the longer motion.
    pub trim: Trim,
    /// Frames of the composite.
    pub frames: usize,
}

/// Runs the stage: the sampled pairs composed, measured for plausibility, and kept or dropped by
/// reason (real clips are measured when their rows are made, from the same positions). `veto`
/// refuses a pair before composition (the LLM check); `profile_of` binds a clip's skeleton profile; `motion_of` gives a clip's
/// frames (the clips may be held without them, one motion is read at a time); `keep` sees each
/// composed clip, with how its frames were made, before it joins the output (the build keeps the
/// recipe instead of the frames).
#[allow(clippy::too_many_arguments)]
pub fn run<E: Send>(
    clips: &[&Clip],
    config: &SyntheticConfig,
    seed: u64,
    split_of: impl Fn(&Clip) -> Split,
    profile_of: impl Fn(&Clip) -> Option<Profile>,
    motion_of: impl Fn(&Clip) -> Result<Motion, E> + Sync,
    veto: impl Fn(&Clip, &Clip) -> bool,
    mut keep: impl FnMut(&mut Clip, Recipe<'_>) -> Result<(), E>,
) -> Result<ComposeOutput, E> {
    use rayon::prelude::*;
    let mut out = ComposeOutput::default();
    // Bound once per skeleton, before the parallel work reads them.
    let mut profiles: BTreeMap<String, Option<Profile>> = BTreeMap::new();
    for c in clips {
        profiles
            .entry(c.skeleton_id())
            .or_insert_with(|| profile_of(c));
    }
    let bound =
        |c: &Clip| -> Option<&Profile> { profiles.get(&c.skeleton_id()).and_then(Option::as_ref) };
    let (pairs, report) = sample(clips, config, seed, split_of);
    out.report = report;
    // At most one composite per pair: grown by doubling, the list (a few hundred bytes per clip
    // before its strings) kept up to half its capacity unused while the stage's entry is stored.
    out.clips.reserve_exact(pairs.len());
    // Composed and measured in parallel a batch at a time (memory stays a batch of composites),
    // then kept in sampling order.
    for batch in pairs.chunks(PAIR_BATCH) {
        let vetoes: Vec<bool> = batch.iter().map(|(a, b)| veto(a, b)).collect();
        let made: Vec<Option<Made>> = batch
            .par_iter()
            .zip(&vetoes)
            .map(|((a, b), &vetoed)| {
                if vetoed {
                    return Ok(None);
                }
                let Some(profile) = bound(a) else {
                    return Ok(None);
                };
                make_pair(a, b, profile, seed, config, &motion_of).map(Some)
            })
            .collect::<Result<_, E>>()?;
        for ((&(a, b), vetoed), made) in batch.iter().zip(vetoes).zip(made) {
            if vetoed {
                out.report.dropped.add(PairDrop::LlmIncompatible);
                continue;
            }
            let made = match made {
                None => continue,
                Some(Made::ActionCut) => {
                    out.report.dropped.add(PairDrop::ActionCut);
                    continue;
                }
                Some(Made::Composed(made)) => made,
            };
            let failures = made.metrics.failed_checks(&config.thresholds);
            // Counted once, under the first check it fails, so composed + dropped = sampled.
            if let Some(&first) = failures.first() {
                out.report.dropped.add(PairDrop::Implausible(first));
                continue;
            }
            let (mut clip, recipe) = made.into_clip(a, b);
            keep(&mut clip, recipe)?;
            out.clips.push(clip);
            out.report.composed += 1;
        }
    }
    Ok(out)
}

/// One pair composed on `profile` and measured for plausibility: the longer clip cropped (at a
/// seeded offset, to its action's window, or from its start), and left uncomposed when the crop
/// keeps too little of its action.
fn make_pair<E>(
    a: &Clip,
    b: &Clip,
    profile: &Profile,
    seed: u64,
    config: &SyntheticConfig,
    motion_of: &impl Fn(&Clip) -> Result<Motion, E>,
) -> Result<Made, E> {
    let mut rng = Rng::new(seed, &format!("{}+{}", a.clip_id, b.clip_id));
    let (motion_a, motion_b) = (motion_of(a)?, motion_of(b)?);
    let (pa, pb) = (a.parts.unwrap_or_default(), b.parts.unwrap_or_default());
    // The longer clip is cropped; its action is what its own label says it does,
    // among the parts it gives the composite.
    let (from_a, from_b) = contributions(mask(pa), mask(pb));
    let frames = motion_a.num_frames().min(motion_b.num_frames());
    let (longer, action) = if motion_a.num_frames() >= motion_b.num_frames() {
        (&motion_a, from_a & mask(pa))
    } else {
        (&motion_b, from_b & mask(pb))
    };
    let (trim, kept) = if config.random_offset {
        let spare = motion_a.num_frames().abs_diff(motion_b.num_frames());
        let k = rng.below(spare + 1);
        (Trim::At(k), action_kept(longer, action, profile, k, frames))
    } else if config.keep_action {
        let w = action_window(longer, action, profile, frames);
        (Trim::At(w.start), w.kept)
    } else {
        (Trim::Start, action_kept(longer, action, profile, 0, frames))
    };
    if kept < config.min_action_kept {
        return Ok(Made::ActionCut);
    }
    let composite = compose(&motion_a, mask(pa), &motion_b, mask(pb), profile, trim);
    let positions = dataset_positions(&composite.motion, profile);
    let metrics = plausibility(
        &positions,
        composite.motion.num_joints(),
        composite.motion.fps,
        profile,
    );
    Ok(Made::Composed(Composed {
        rng,
        trim,
        kept,
        composite,
        metrics,
    }))
}

impl Composed {
    /// The synthetic clip of a kept pair (`a` first), its text drawn from the composed variants,
    /// and how its frames were made.
    fn into_clip<'c>(self, a: &'c Clip, b: &'c Clip) -> (Clip, Recipe<'c>) {
        let Composed {
            mut rng,
            trim,
            kept,
            composite,
            metrics,
        } = self;
        let (pa, pb) = (a.parts.unwrap_or_default(), b.parts.unwrap_or_default());
        let variants = compose_variants(&a.text, &b.text);
        let chosen = variants
            .get(rng.below(variants.len()))
            .map(|v| v.text.clone())
            .unwrap_or_default();
        let legs_from_a = composite.parts_from_first
            & motionforge_core::motion::compose::part_bit(BodyPart::Global)
            != 0;
        let base = if legs_from_a { a } else { b };
        let clip = Clip {
            clip_id: format!("synthetic/{}+{}", a.clip_id, b.clip_id),
            kind: SourceKind::Synthetic,
            capture: base.capture.clone(),
            frame_range: base.frame_range,
            mirrored: false,
            split: a.split.clone(),
            action: format!("{} + {}", a.action, b.action),
            text: chosen,
            texts: variants.into_iter().map(|v| v.text).collect(),
            labels: a.labels.iter().chain(&b.labels).cloned().collect(),
            annotation: "synthetic".into(),
            annotation_origin: format!("{} + {}", a.annotation_origin, b.annotation_origin),
            attributes: motionforge_sources::clip::Attributes::from([
                ("start_a".to_string(), composite.starts[0].to_string()),
                ("start_b".to_string(), composite.starts[1].to_string()),
                ("action_kept".to_string(), format!("{kept:.3}")),
            ]),
            profile: a.profile.clone(),
            motion_type: None,
            hand: None,
            object: None,
            goal_pelvis: None,
            goal_hand: None,
            parts: Some(pa | pb),
            label_source: Some(motionforge_language::parts::LabelSources::one(
                motionforge_language::parts::LabelSource::Composed,
            )),
            paraphrases: Vec::new(),
            composed_from: vec![a.clip_id.clone(), b.clip_id.clone()],
            composed_parts: vec![
                part_set(composite.parts_from_first),
                part_set(composite.parts_from_second),
            ],
            plausibility: Some(Box::new(metrics)),
            skeleton: std::sync::Arc::clone(&composite.motion.skeleton),
        };
        let recipe = Recipe {
            first: a,
            first_parts: mask(pa),
            second: b,
            second_parts: mask(pb),
            trim,
            frames: composite.motion.num_frames(),
        };
        (clip, recipe)
    }
}

#[cfg(test)]
mod tests {
    use super::{ComposeReport, PairDrop, Rng, draw_pairs};
    use motionforge_core::base::Named;
    use motionforge_core::quality::Check;
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    /// The report as the stage cache held it when drops were counted under strings.
    #[derive(serde::Serialize)]
    struct StringKeyedReport {
        candidates: usize,
        compatible: usize,
        sampled: usize,
        composed: usize,
        dropped: BTreeMap<String, usize>,
    }

    #[test]
    fn drops_keep_their_names_and_a_report_cached_with_string_keys_still_decodes() {
        let names: Vec<&str> = PairDrop::ALL.iter().map(|d| d.name()).collect();
        assert_eq!(
            names,
            [
                "llm_incompatible",
                "action_cut",
                "foot_skating",
                "ground_penetration",
                "self_penetration",
                "lean"
            ]
        );
        let old = StringKeyedReport {
            candidates: 9,
            compatible: 7,
            sampled: 6,
            composed: 1,
            dropped: names.iter().map(|n| (n.to_string(), n.len())).collect(),
        };
        let report: ComposeReport =
            postcard::from_bytes(&postcard::to_stdvec(&old).unwrap()).unwrap();
        assert_eq!(
            report.dropped.get(&PairDrop::Implausible(Check::Lean)),
            Some(&4)
        );
        assert_eq!(report.dropped.get(&PairDrop::LlmIncompatible), Some(&16));
        assert_eq!(
            postcard::to_stdvec(&report).unwrap(),
            postcard::to_stdvec(&old).unwrap()
        );
        assert_eq!(
            serde_json::to_string(&report).unwrap(),
            serde_json::to_string(&old).unwrap()
        );
    }

    /// The draw as it was first written, scanning the whole group for each candidate: the oracle
    /// [`draw_pairs`] is tested against.
    fn draw_pairs_by_scanning(
        members: &[Vec<usize>],
        group_of: &[usize],
        capture_of: &[usize],
        parts_of: &[u8],
        cap: usize,
        probability: f64,
        mut rng_of: impl FnMut(usize) -> Rng,
    ) -> Vec<(usize, usize)> {
        let n = group_of.len();
        let compatible =
            |i: usize, j: usize| capture_of[i] != capture_of[j] && parts_of[i] & parts_of[j] == 0;
        let mut count = vec![0usize; n];
        let mut pairs = Vec::new();
        // The partner each candidate chose on its turn: the pair {i, j} is taken when an
        // earlier candidate j chose i (a candidate chooses once, on its own turn).
        let mut chose: Vec<Option<usize>> = vec![None; n];
        for i in 0..n {
            let mut rng = rng_of(i);
            if rng.unit() >= probability || count[i] >= cap {
                continue;
            }
            let open: Vec<usize> = members[group_of[i]]
                .iter()
                .copied()
                .filter(|&j| {
                    j != i && compatible(i, j) && count[j] < cap && !(j < i && chose[j] == Some(i))
                })
                .collect();
            if open.is_empty() {
                continue;
            }
            let j = open[rng.below(open.len())];
            chose[i] = Some(j);
            count[i] += 1;
            count[j] += 1;
            pairs.push((i, j));
        }
        pairs
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        /// The Fenwick draw takes the same partners, in the same order, as scanning the group.
        #[test]
        fn the_draw_equals_scanning_the_group(
            seed in any::<u64>(),
            members in proptest::collection::vec((0usize..3, 0usize..12, 0u8..64), 0..80),
            cap in prop_oneof![Just(0usize), Just(1), Just(2), Just(3), Just(usize::MAX)],
            probability in prop_oneof![Just(0.3f64), Just(0.8), Just(1.0)],
        ) {
            let group_of: Vec<usize> = members.iter().map(|m| m.0).collect();
            let capture_of: Vec<usize> = members.iter().map(|m| m.1).collect();
            let parts_of: Vec<u8> = members.iter().map(|m| m.2).collect();
            let mut groups: Vec<Vec<usize>> = vec![Vec::new(); 3];
            for (i, &g) in group_of.iter().enumerate() {
                groups[g].push(i);
            }
            let rng = |i: usize| Rng::new(seed, &format!("clip {i}"));
            let fast = draw_pairs(&groups, &group_of, &capture_of, &parts_of, cap, probability, rng);
            let scanned = draw_pairs_by_scanning(
                &groups, &group_of, &capture_of, &parts_of, cap, probability, rng,
            );
            prop_assert_eq!(fast, scanned);
        }
    }

    use super::count_compatible;

    #[test]
    fn compatible_pairs_counted_by_part_sets_equal_every_pair_tested() {
        // A small deterministic generator: groups of varied sizes, several clips per capture.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = |m: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % m
        };
        for _ in 0..50 {
            let n = next(60) as usize + 1;
            let capture_of: Vec<usize> = (0..n).map(|_| next(12) as usize).collect();
            let parts_of: Vec<u8> = (0..n).map(|_| next(63) as u8 + 1).collect();
            let split = next(n as u64) as usize;
            let members = vec![(0..split).collect::<Vec<_>>(), (split..n).collect()];
            let brute: usize = members
                .iter()
                .map(|g| {
                    let mut k = 0;
                    for (x, &i) in g.iter().enumerate() {
                        for &j in &g[x + 1..] {
                            if capture_of[i] != capture_of[j] && parts_of[i] & parts_of[j] == 0 {
                                k += 1;
                            }
                        }
                    }
                    k
                })
                .sum();
            assert_eq!(count_compatible(&members, &capture_of, &parts_of), brute);
        }
    }
}
