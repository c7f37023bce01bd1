//! Body-part sets (SINC's six parts): parsing LLM answers, the embedded labeller, part-velocity
//! evidence from motion, and the SINC Table 1 evaluation.
//!
//! A [`PartSet`] is the value everything here produces and compares: a set of the six
//! [`BodyPart`]s in SINC's order `[global, torso, left arm, right arm, left leg, right leg]`. Two
//! actions are compatible (can be performed at the same time, SINC's synthetic pairs) when their
//! part sets are disjoint.
//!
//! * [`answer::parse_part_answer`] reads a GPT answer to SINC's list prompt into a set, flagging
//!   anything outside the list instead of guessing;
//! * [`lexicon::label_text`] labels an action text offline from a lexicon of body-part and action
//!   words;
//! * [`velocity::motion_parts`] labels a motion from how fast each part moves;
//! * [`eval::evaluate`] scores any of them against manual labels (SINC Table 1).
//!
//! ```
//! use motionforge_core::motion::BodyPart;
//! use motionforge_language::parts::{PartSet, lexicon::label_text};
//!
//! let walk = label_text("walk forward").parts;
//! let wave = label_text("wave with the right hand").parts;
//! assert!(walk.is_disjoint(wave), "walking and waving can be combined");
//! assert!(wave.contains(BodyPart::RightArm));
//! assert_eq!(wave.mirrored(), PartSet::from_parts(&[BodyPart::LeftArm]));
//! ```

pub mod answer;
pub mod eval;
pub mod lexicon;
pub mod velocity;

use std::fmt;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use motionforge_core::motion::BodyPart;

/// Which labeller gave a clip its parts. Written in tables and reports as `embedded:lexicon`,
/// `embedded:velocity`, `llm:<model>`, `import:<file>` or `composed`; ordered as those names sort,
/// so a pair's joined sources read the same as when they were strings.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum LabelSource {
    /// A synthetic pair: the union of its sources' parts.
    Composed,
    /// The embedded labeller's lexicon, from the text.
    Lexicon,
    /// The motion's part velocities (the text had no answer).
    Velocity,
    /// Answers imported from a file (`motionforge labels import`).
    Import {
        /// The file's name.
        file: String,
    },
    /// An LLM answer.
    Llm {
        /// The model that answered.
        model: String,
    },
}

impl fmt::Display for LabelSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LabelSource::Lexicon => f.write_str("embedded:lexicon"),
            LabelSource::Velocity => f.write_str("embedded:velocity"),
            LabelSource::Llm { model } => write!(f, "llm:{model}"),
            LabelSource::Import { file } => write!(f, "import:{file}"),
            LabelSource::Composed => f.write_str("composed"),
        }
    }
}

/// The labellers of a clip's parts: one, or for a real pair of two texts, each text's (written
/// joined by `+`). A set, held as a sorted list without repeats: every clip carries one, and a
/// `BTreeSet` of one element allocates a whole node (about 370 bytes). It is encoded as the set
/// was (a sequence in order), and decoding sorts and removes repeats again.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(from = "std::collections::BTreeSet<LabelSource>")]
pub struct LabelSources(Vec<LabelSource>);

impl From<std::collections::BTreeSet<LabelSource>> for LabelSources {
    fn from(set: std::collections::BTreeSet<LabelSource>) -> LabelSources {
        LabelSources(set.into_iter().collect())
    }
}

impl FromIterator<LabelSource> for LabelSources {
    fn from_iter<I: IntoIterator<Item = LabelSource>>(sources: I) -> LabelSources {
        let mut all: Vec<LabelSource> = sources.into_iter().collect();
        all.sort();
        all.dedup();
        all.shrink_to_fit();
        LabelSources(all)
    }
}

impl LabelSources {
    /// A single source.
    pub fn one(source: LabelSource) -> LabelSources {
        LabelSources(vec![source])
    }

    /// True when `source` is the only one.
    pub fn is_only(&self, source: &LabelSource) -> bool {
        self.0.len() == 1 && self.0[0] == *source
    }
}

impl fmt::Display for LabelSources {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, s) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str("+")?;
            }
            write!(f, "{s}")?;
        }
        Ok(())
    }
}

/// A set of SINC's six body parts, stored as a bitmask (bit `i` is `BodyPart::ALL[i]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, PartialOrd, Ord)]
pub struct PartSet(u8);

/// Position of a part in SINC's vector order.
fn bit(part: BodyPart) -> u8 {
    match part {
        BodyPart::Global => 0,
        BodyPart::Torso => 1,
        BodyPart::LeftArm => 2,
        BodyPart::RightArm => 3,
        BodyPart::LeftLeg => 4,
        BodyPart::RightLeg => 5,
    }
}

/// The snake_case name of a part, as serde writes it (`left_arm`).
pub fn part_name(part: BodyPart) -> &'static str {
    match part {
        BodyPart::Global => "global",
        BodyPart::Torso => "torso",
        BodyPart::LeftArm => "left_arm",
        BodyPart::RightArm => "right_arm",
        BodyPart::LeftLeg => "left_leg",
        BodyPart::RightLeg => "right_leg",
    }
}

impl PartSet {
    /// No part.
    pub const EMPTY: PartSet = PartSet(0);
    /// All six parts.
    pub const ALL: PartSet = PartSet(0b11_1111);
    /// Both arms.
    pub const ARMS: PartSet = PartSet(0b00_1100);
    /// Both legs.
    pub const LEGS: PartSet = PartSet(0b11_0000);
    /// Global orientation and translation (the pelvis) alone.
    pub const GLOBAL: PartSet = PartSet(0b00_0001);
    /// Torso (spine, neck, head) alone.
    pub const TORSO: PartSet = PartSet(0b00_0010);

    /// A set of the given parts.
    pub fn from_parts(parts: &[BodyPart]) -> PartSet {
        parts.iter().copied().collect()
    }

    /// A set from SINC's binary vector `[global, torso, left arm, right arm, left leg, right leg]`.
    pub fn from_vec6(v: [bool; 6]) -> PartSet {
        BodyPart::ALL
            .into_iter()
            .zip(v)
            .filter(|(_, on)| *on)
            .map(|(p, _)| p)
            .collect()
    }

    /// The raw bitmask (bit `i` is `BodyPart::ALL[i]`).
    pub fn bits(self) -> u8 {
        self.0
    }

    /// Whether the set holds `part`.
    pub fn contains(self, part: BodyPart) -> bool {
        self.0 & (1 << bit(part)) != 0
    }

    /// Adds `part`; returns whether it was new.
    pub fn insert(&mut self, part: BodyPart) -> bool {
        let new = !self.contains(part);
        self.0 |= 1 << bit(part);
        new
    }

    /// Removes `part`; returns whether it was present.
    pub fn remove(&mut self, part: BodyPart) -> bool {
        let had = self.contains(part);
        self.0 &= !(1 << bit(part));
        had
    }

    /// The set with `part` added.
    pub fn with(mut self, part: BodyPart) -> PartSet {
        self.insert(part);
        self
    }

    /// Parts in either set.
    pub fn union(self, other: PartSet) -> PartSet {
        PartSet(self.0 | other.0)
    }

    /// Parts in both sets.
    pub fn intersection(self, other: PartSet) -> PartSet {
        PartSet(self.0 & other.0)
    }

    /// Parts in `self` but not in `other`.
    pub fn difference(self, other: PartSet) -> PartSet {
        PartSet(self.0 & !other.0)
    }

    /// No part in common: the two actions are compatible (SINC `get_compat_matrix`).
    pub fn is_disjoint(self, other: PartSet) -> bool {
        self.0 & other.0 == 0
    }

    /// Number of parts.
    pub fn len(self) -> usize {
        self.0.count_ones() as usize
    }

    /// Whether the set is empty.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Left and right swapped, for a motion (and caption) mirrored left/right.
    pub fn mirrored(self) -> PartSet {
        self.iter().map(BodyPart::mirrored).collect()
    }

    /// SINC's binary vector `[global, torso, left arm, right arm, left leg, right leg]`.
    pub fn to_vec6(self) -> [bool; 6] {
        BodyPart::ALL.map(|p| self.contains(p))
    }

    /// The parts in SINC's order.
    pub fn iter(self) -> impl Iterator<Item = BodyPart> {
        BodyPart::ALL.into_iter().filter(move |p| self.contains(*p))
    }
}

impl FromIterator<BodyPart> for PartSet {
    fn from_iter<I: IntoIterator<Item = BodyPart>>(iter: I) -> PartSet {
        let mut set = PartSet::EMPTY;
        for p in iter {
            set.insert(p);
        }
        set
    }
}

impl std::ops::BitOr for PartSet {
    type Output = PartSet;
    fn bitor(self, rhs: PartSet) -> PartSet {
        self.union(rhs)
    }
}

impl std::ops::BitOrAssign for PartSet {
    fn bitor_assign(&mut self, rhs: PartSet) {
        *self = self.union(rhs);
    }
}

impl std::ops::BitAnd for PartSet {
    type Output = PartSet;
    fn bitand(self, rhs: PartSet) -> PartSet {
        self.intersection(rhs)
    }
}

impl From<BodyPart> for PartSet {
    fn from(part: BodyPart) -> PartSet {
        PartSet::EMPTY.with(part)
    }
}

/// `left_arm, right_arm` in SINC's order; the empty set prints as nothing.
impl fmt::Display for PartSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, part) in self.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            f.write_str(part_name(part))?;
        }
        Ok(())
    }
}

/// Serialised as a list of part names in SINC's order: `["left_arm", "right_arm"]`.
impl Serialize for PartSet {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        // A Vec gives the length up front, which formats without field names (postcard) need.
        serializer.collect_seq(self.iter().collect::<Vec<_>>())
    }
}

/// Read from a list of part names in any order; duplicates are accepted (a set).
impl<'de> Deserialize<'de> for PartSet {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<PartSet, D::Error> {
        let parts = Vec::<BodyPart>::deserialize(deserializer)?;
        Ok(parts.into_iter().collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirrored_swaps_sides_and_keeps_centre() {
        let set = PartSet::from_parts(&[BodyPart::Global, BodyPart::LeftArm, BodyPart::RightLeg]);
        assert_eq!(
            set.mirrored(),
            PartSet::from_parts(&[BodyPart::Global, BodyPart::RightArm, BodyPart::LeftLeg])
        );
        assert_eq!(set.mirrored().mirrored(), set);
        assert_eq!(PartSet::ARMS.mirrored(), PartSet::ARMS);
        assert_eq!(PartSet::ALL.mirrored(), PartSet::ALL);
    }

    #[test]
    fn disjoint_means_compatible() {
        let walk = PartSet::LEGS.with(BodyPart::Global);
        let wave = PartSet::from(BodyPart::RightArm);
        let kick = PartSet::from(BodyPart::RightLeg);
        assert!(walk.is_disjoint(wave));
        assert!(!walk.is_disjoint(kick));
        assert!(PartSet::EMPTY.is_disjoint(PartSet::ALL));
    }

    #[test]
    fn vec6_is_sinc_order() {
        let set = PartSet::from_vec6([true, false, false, true, false, true]);
        assert_eq!(set.to_vec6(), [true, false, false, true, false, true]);
        assert_eq!(set.to_string(), "global, right_arm, right_leg");
        assert_eq!(set.len(), 3);
        assert_eq!(PartSet::EMPTY.to_string(), "");
    }

    #[test]
    fn insert_remove_and_len() {
        let mut set = PartSet::EMPTY;
        assert!(set.insert(BodyPart::Torso));
        assert!(!set.insert(BodyPart::Torso));
        assert_eq!(set.len(), 1);
        assert!(set.remove(BodyPart::Torso));
        assert!(set.is_empty());
    }

    #[test]
    fn serde_round_trip_as_names() {
        let set = PartSet::from_parts(&[BodyPart::RightLeg, BodyPart::Torso]);
        let json = serde_json::to_string(&set).unwrap();
        assert_eq!(json, r#"["torso","right_leg"]"#);
        assert_eq!(serde_json::from_str::<PartSet>(&json).unwrap(), set);
        let dup: PartSet = serde_json::from_str(r#"["torso","torso"]"#).unwrap();
        assert_eq!(dup, PartSet::TORSO);
        assert!(serde_json::from_str::<PartSet>(r#"["tail"]"#).is_err());
    }
}
