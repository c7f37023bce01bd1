//! `Clip`: a labelled stretch of motion with its provenance, the unit every stage passes on. A
//! clip is metadata only; its frames are a [`Motion`] of their own, held beside it
//! ([`LoadedClip`]) by the work that needs them and otherwise kept in the stage cache, so a clip
//! without frames cannot be mistaken for a clip of no frames.

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::annotate::span::Hand;
use motionforge_core::motion::{Motion, Skeleton};
use motionforge_language::parts::PartSet;

/// Where a clip came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SourceKind {
    /// One real action.
    RealSingle,
    /// Two real actions performed at once (overlapping annotations).
    RealPair,
    /// Two clips stitched by body part.
    Synthetic,
}

impl SourceKind {
    /// The name written in datasets and reports.
    pub const fn as_str(self) -> &'static str {
        match self {
            SourceKind::RealSingle => "real_single",
            SourceKind::RealPair => "real_pair",
            SourceKind::Synthetic => "synthetic",
        }
    }
}

impl SourceKind {
    /// Every kind, in the order tables and reports list them.
    pub const ALL: [SourceKind; 3] = [
        SourceKind::RealSingle,
        SourceKind::RealPair,
        SourceKind::Synthetic,
    ];

    /// The kind a table's `source_kind` value names.
    pub fn parse(name: &str) -> Option<SourceKind> {
        SourceKind::ALL.into_iter().find(|k| k.as_str() == name)
    }
}

impl motionforge_core::base::Named for SourceKind {
    const ALL: &'static [SourceKind] = &SourceKind::ALL;

    fn name(self) -> &'static str {
        self.as_str()
    }
}

impl std::fmt::Display for SourceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The split a clip belongs to: `train`, `validation`, `test` (Hugging Face's names, the
/// defaults) or any other name `[splits]` configures.
/// Names are the user's, so this is a name with the rules that read it in one place: the order
/// splits are listed and written in, and which one is the training split.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Split(String);

impl Split {
    /// The training split's name.
    pub const TRAIN: &'static str = "train";

    /// The split called `name`.
    pub fn new(name: impl Into<String>) -> Split {
        Split(name.into())
    }

    /// The training split.
    pub fn train() -> Split {
        Split(Split::TRAIN.into())
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Where a split named `name` comes in listings: train, then validation (val, dev), then
    /// test, then any other name.
    pub fn rank(name: &str) -> u8 {
        match name {
            Split::TRAIN => 0,
            "val" | "validation" | "dev" => 1,
            "test" => 2,
            _ => 3,
        }
    }
}

impl Ord for Split {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (Split::rank(&self.0), &self.0).cmp(&(Split::rank(&other.0), &other.0))
    }
}

impl PartialOrd for Split {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl std::fmt::Display for Split {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl PartialEq<str> for Split {
    fn eq(&self, other: &str) -> bool {
        self.0 == other
    }
}

impl PartialEq<&str> for Split {
    fn eq(&self, other: &&str) -> bool {
        self.0 == *other
    }
}

/// The capture file a clip was cut from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaptureRef {
    /// Source name from the config.
    pub source: String,
    /// Path as found by the capture glob (relative to the config folder when under it).
    pub path: String,
    /// SHA-256 of the file's bytes, hex.
    pub sha256: String,
    /// Frame rate used for the file (header or override).
    pub fps: f64,
    /// The rate the frames really have when it is not `fps`: an AMASS file taken at HumanML3D's
    /// stride keeps every `int(rate / 20)`-th frame and labels it 20 fps, whatever rate that gives.
    /// Every clip cut from the file, its mirror and the synthetic pairs made of it are counted by it
    /// in the build report.
    pub effective_fps: Option<f64>,
}

/// A parsed capture at its own frame rate, before segmentation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Capture {
    /// The file and its digest.
    pub capture: CaptureRef,
    /// File stem: the key annotations find the capture by.
    pub stem: String,
    /// Skeleton profile name.
    pub profile: String,
    /// The whole motion at the capture's rate (`capture.fps`).
    pub motion: Motion,
    /// What reading it noticed without refusing it (the IK fit of joint positions whose bone
    /// lengths are not constant); the segment stage reports them with its own notes.
    #[serde(default)]
    pub notes: Vec<crate::annotate::span::Note>,
}

/// A clip: a stretch of motion at the dataset frame rate on its capture's skeleton, its texts and
/// provenance. The frames are not part of it (see [`LoadedClip`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Clip {
    /// Stable identifier: `<source>/<capture stem>:<start>-<end>` (capture frames), `:pair` for a
    /// real pair, `:m` appended for a mirror, `synthetic/<a>+<b>` for a synthetic pair.
    pub clip_id: String,
    /// Real single, real pair or synthetic.
    pub kind: SourceKind,
    /// The capture, shared by the clips cut from it and their mirrors.
    pub capture: Arc<CaptureRef>,
    /// Half-open frame range `[start, end)` in the capture's own frames.
    pub frame_range: (u64, u64),
    /// True for the mirrored copy.
    pub mirrored: bool,
    /// The split of the source capture (`train`, `val`, `test`, ...).
    pub split: Split,
    /// Action label.
    pub action: String,
    /// Caption.
    pub text: String,
    /// Every text of the clip: one for a single action, both for a real pair.
    pub texts: Vec<String>,
    /// Processed labels (BABEL `proc_label`, event-log motion type, ...), one per action.
    pub labels: Vec<String>,
    /// Annotation format (`filename`, `babel`, `event_log`, `frame_index`).
    pub annotation: String,
    /// Annotation file and record the clip was cut by.
    pub annotation_origin: String,
    /// Motion type from the taxonomy, for single actions whose label maps to one.
    pub motion_type: Option<String>,
    /// Hand used, when the annotation says.
    pub hand: Option<Hand>,
    /// Object involved, when the annotation says.
    pub object: Option<String>,
    /// Locomotion goal: pelvis at the last frame, (x, y) in the first-frame canonical frame, metres.
    pub goal_pelvis: Option<[f64; 2]>,
    /// Reaching goal: the hand at the grasp (or last) frame, (x, y, z) canonical, metres.
    pub goal_hand: Option<[f64; 3]>,
    /// Body parts involved (SINC's six), when labelled.
    pub parts: Option<PartSet>,
    /// Which labeller produced `parts` (`embedded:lexicon`, `embedded:velocity`, `llm:<model>`,
    /// `import:<file>`).
    pub label_source: Option<motionforge_language::parts::LabelSources>,
    /// Alternative descriptions of `text` (LLM, side words checked).
    pub paraphrases: Vec<String>,
    /// For a synthetic pair: the two source clips.
    pub composed_from: Vec<String>,
    /// For a synthetic pair: the parts taken from each source clip, in `composed_from` order.
    pub composed_parts: Vec<PartSet>,
    /// Plausibility metrics (foot skating, ground and self penetration, lean). Boxed: only
    /// synthetic pairs carry them (a real clip's are measured with its row), and inline they
    /// would make every clip of the table about a hundred bytes larger.
    pub plausibility: Option<Box<motionforge_core::quality::Plausibility>>,
    /// Extra fields from the annotation (file-name groups, sidecar keys).
    pub attributes: Attributes,
    /// Skeleton profile name.
    pub profile: String,
    /// The skeleton the clip's motion is on (the capture's).
    pub skeleton: Arc<Skeleton>,
}

/// A clip's extra fields (file-name groups, sidecar keys, a synthetic pair's offsets): a map
/// from key to value, held as a list sorted by key and shared by the copies of a clip (its
/// mirror), since every clip carries one and a `BTreeMap` of a few entries allocates a whole node
/// (about 540 bytes) besides its strings. Encoded as the map it is.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Attributes(Arc<[(String, String)]>);

impl Attributes {
    /// The value of `key`.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.0
            .binary_search_by(|(k, _)| k.as_str().cmp(key))
            .ok()
            .map(|i| self.0[i].1.as_str())
    }

    /// Every key and value, by key.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = (&str, &str)> {
        self.0.iter().map(|(k, v)| (k.as_str(), v.as_str()))
    }
}

impl From<BTreeMap<String, String>> for Attributes {
    fn from(map: BTreeMap<String, String>) -> Attributes {
        Attributes(map.into_iter().collect())
    }
}

impl<const N: usize> From<[(String, String); N]> for Attributes {
    fn from(entries: [(String, String); N]) -> Attributes {
        Attributes::from(BTreeMap::from(entries))
    }
}

impl Serialize for Attributes {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_map(self.0.iter().map(|(k, v)| (k, v)))
    }
}

impl<'de> Deserialize<'de> for Attributes {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Attributes, D::Error> {
        BTreeMap::<String, String>::deserialize(deserializer).map(Attributes::from)
    }
}

/// A clip with its frames: its motion resampled to the dataset rate, in the capture's units and
/// axes, on `clip.skeleton`.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedClip {
    /// The clip.
    pub clip: Clip,
    /// Its frames.
    pub motion: Motion,
}

impl Clip {
    /// The clip's skeleton as the table names it: profile and a digest of the hierarchy and
    /// offsets, since captures of one profile can come from differently sized actors.
    pub fn skeleton_id(&self) -> String {
        skeleton_name(&self.profile, &self.skeleton)
    }
}

/// The `skeleton` column's value for a skeleton of profile `profile`.
pub fn skeleton_name(profile: &str, skeleton: &Skeleton) -> String {
    format!("{profile}:{}", skeleton.digest())
}

/// Skeletons kept once each for many clips stored together (a cache entry, a compressed block):
/// each clip's `skeleton` is swapped for an empty placeholder before the clips are encoded and
/// given back after they are decoded, so a few distinct skeletons are not repeated in every
/// clip's bytes (about 3 KB each for Bandai Namco's) and decoded clips share them.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SkeletonTable {
    skeletons: Vec<Arc<Skeleton>>,
    /// Per clip taken, the index of its skeleton.
    of: Vec<u32>,
}

impl SkeletonTable {
    /// Takes the skeleton of each of `clips`, in order, leaving an empty one in its place.
    pub fn take_all(clips: &mut [Clip]) -> SkeletonTable {
        let mut table = SkeletonTable::default();
        let empty = Arc::new(Skeleton { joints: Vec::new() });
        for clip in clips {
            table.take(clip, &empty);
        }
        table
    }

    /// Takes `clip`'s skeleton, leaving `empty` in its place.
    pub fn take(&mut self, clip: &mut Clip, empty: &Arc<Skeleton>) {
        let skeleton = std::mem::replace(&mut clip.skeleton, Arc::clone(empty));
        let found = self
            .skeletons
            .iter()
            .position(|s| Arc::ptr_eq(s, &skeleton) || **s == *skeleton);
        let index = match found {
            Some(i) => i,
            None => {
                self.skeletons.push(skeleton);
                self.skeletons.len() - 1
            }
        } as u32;
        self.of.push(index);
    }

    /// The skeleton of the `n`-th clip taken.
    pub fn skeleton_of(&self, n: usize) -> Option<&Arc<Skeleton>> {
        let index = *self.of.get(n)?;
        self.skeletons.get(index as usize)
    }

    /// Distinct skeletons held.
    pub fn distinct(&self) -> usize {
        self.skeletons.len()
    }

    /// Gives `clips` (the ones taken by [`SkeletonTable::take_all`], in the same order) their
    /// skeletons back; `false` when the counts do not match (a damaged entry), clips unchanged.
    pub fn give_all(&self, clips: &mut [Clip]) -> bool {
        if clips.len() != self.of.len()
            || self.of.iter().any(|&i| i as usize >= self.skeletons.len())
        {
            return false;
        }
        for (n, clip) in clips.iter_mut().enumerate() {
            if let Some(skeleton) = self.skeleton_of(n) {
                clip.skeleton = Arc::clone(skeleton);
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motionforge_language::parts::{LabelSource, LabelSources};
    use std::collections::BTreeSet;

    /// `held` and `replaced` give the same postcard (cache, fingerprints) and JSON bytes.
    fn assert_encodes_as<A: Serialize, B: Serialize>(held: &A, replaced: &B) {
        assert_eq!(
            postcard::to_stdvec(held).unwrap(),
            postcard::to_stdvec(replaced).unwrap()
        );
        assert_eq!(
            serde_json::to_string(held).unwrap(),
            serde_json::to_string(replaced).unwrap()
        );
    }

    /// Attributes and label sources are held as sorted lists but must encode exactly as the map
    /// and set they replaced: cache fingerprints, the table fingerprint and JSON readers see them.
    #[test]
    fn compact_attributes_and_label_sources_encode_as_the_map_and_set_they_replace() {
        let map = BTreeMap::from([
            ("take".to_string(), "001".to_string()),
            ("content".to_string(), "raise-up-both-hands".to_string()),
            ("sidecar.style".to_string(), "0".to_string()),
        ]);
        let attributes = Attributes::from(map.clone());
        assert_encodes_as(&attributes, &map);
        let back: Attributes = postcard::from_bytes(&postcard::to_stdvec(&map).unwrap()).unwrap();
        assert_eq!(back, attributes);
        assert_eq!(attributes.get("take"), Some("001"));
        assert_eq!(attributes.get("style"), None);
        assert_eq!(
            attributes.iter().map(|(k, _)| k).collect::<Vec<_>>(),
            map.keys().map(String::as_str).collect::<Vec<_>>()
        );

        let set = BTreeSet::from([
            LabelSource::Velocity,
            LabelSource::Llm {
                model: "gpt-3".into(),
            },
            LabelSource::Lexicon,
        ]);
        // Given out of order and with a repeat, held as the set would be.
        let sources: LabelSources = [
            LabelSource::Velocity,
            LabelSource::Lexicon,
            LabelSource::Llm {
                model: "gpt-3".into(),
            },
            LabelSource::Lexicon,
        ]
        .into_iter()
        .collect();
        assert_encodes_as(&sources, &set);
        let back: LabelSources =
            serde_json::from_str(&serde_json::to_string(&set).unwrap()).unwrap();
        assert_eq!(back, sources);
        assert_eq!(
            sources.to_string(),
            "embedded:lexicon+embedded:velocity+llm:gpt-3"
        );
    }
}
