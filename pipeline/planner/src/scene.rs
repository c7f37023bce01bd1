//! The scene file (TOML): the places the actor can be at, the hand-held objects and where they
//! start, the actor's start and end states, the interactions with their requirements and effects,
//! the session's limit and the balance target. `schemas/scene.md` documents every key.
//!
//! Reading expands each interaction into candidates (one per place, object and hand it names), so
//! the chain works on concrete instructions. Every problem is reported at once with its key.

use std::cell::OnceCell;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::Read as _;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::state::{Effect, Loc, Posture, Requirement, State};
use motionforge_core::base::toml_path::{self, SpannedToml, line_of};
use motionforge_sources::annotate::span::Hand;
use motionforge_sources::annotate::taxonomy::{Taxonomy, normalize_label};

/// The most candidates a scene may expand into: the chain enumerates states times candidates.
/// Every interaction is at least one candidate, so it bounds the interactions too.
pub const MAX_CANDIDATES: usize = 2_000;

/// The largest scene file read, in bytes (1 MiB; the living room is 5 KB). The TOML parser
/// holds up to about 120 bytes per byte of a file of long arrays of small values (measured,
/// docs/performance.md), so this bounds reading to about 150 MB at worst.
pub const MAX_SCENE_BYTES: usize = 1 << 20;

/// The most places a scene may list.
pub const MAX_PLACES: usize = 1_000;

/// The most hand-held objects a scene may list. Objects no interaction takes cost nothing per
/// state (their places are kept once), so this bounds only the reading and the messages.
pub const MAX_OBJECTS: usize = 50_000;

/// The most objects some interaction takes (`hold = "take"`): every state carries where each
/// of them is, so with [`crate::MAX_STATES`] this bounds the states' memory before any
/// is built.
pub const MAX_MOVABLE: usize = 32;

/// The most problems a rejected scene lists (a file with a million bad names gets the first
/// ones, not a million lines).
const MAX_PROBLEMS: usize = 100;

/// The most names a message lists (`objects: cup, phone`); a longer list is cut with its count.
const MAX_NAMES_SHOWN: usize = 20;

/// Why a scene file cannot be used. Every variant names the file; problems name their key.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file cannot be read.
    #[error("scene {path}: cannot read: {source}")]
    Read {
        /// The scene file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is larger than a scene file may be ([`MAX_SCENE_BYTES`]).
    #[error(
        "scene {}: more than {limit} bytes, the most a scene file may have; split it into \
         smaller scenes",
        path.display()
    )]
    TooBig {
        /// The scene file.
        path: PathBuf,
        /// The limit, in bytes.
        limit: usize,
    },
    /// The file is not TOML.
    #[error("scene {}{}: {}", path.display(), at_line(*line), error.message().trim_end())]
    Syntax {
        /// The scene file.
        path: PathBuf,
        /// 1-based line, where known.
        line: Option<usize>,
        /// The parser's error. Not a `#[source]`: the message quotes its short form, and its
        /// full form (the file's lines) would be appended by whatever prints the causes. Boxed:
        /// it is large, and errors are rare.
        error: Box<toml::de::Error>,
    },
    /// The file is TOML but not of the scene's shape.
    #[error("scene {}{}: {}{}", path.display(), at_line(*line), key.as_deref().map(|k| format!("{k}: ")).unwrap_or_default(), error.message().trim_end())]
    Shape {
        /// The scene file.
        path: PathBuf,
        /// 1-based line, where known.
        line: Option<usize>,
        /// The dotted key of the value, `None` for the whole file.
        key: Option<String>,
        /// What the reader expected there (not a `#[source]`, and boxed, as for
        /// [`SceneError::Syntax`]).
        error: Box<toml::de::Error>,
    },
    /// Values parse but are not acceptable: every problem found.
    #[error("{}", invalid_message(path, problems, *unlisted))]
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// What is wrong, in file order where lines are known (at most the first 100 found).
        problems: Vec<SceneProblem>,
        /// Problems found beyond those listed.
        unlisted: usize,
    },
    /// The bundled motion-type taxonomy did not load (a build defect, not the scene's).
    #[error(transparent)]
    Taxonomy(#[from] motionforge_sources::annotate::taxonomy::TaxonomyError),
}

/// One problem of a scene: its dotted key, its line and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SceneProblem {
    /// Dotted key with array positions: `interactions[2].type`.
    pub key: String,
    /// 1-based line of the key (or of its table), where known.
    pub line: Option<usize>,
    /// What is wrong and what is expected.
    pub message: String,
}

/// `:line`, or nothing when the line is not known.
fn at_line(line: Option<usize>) -> String {
    line.map(|l| format!(":{l}")).unwrap_or_default()
}

fn invalid_message(path: &Path, problems: &[SceneProblem], unlisted: usize) -> String {
    let at = |p: &SceneProblem| match p.line {
        Some(line) => format!("{}:{line}: {}: {}", path.display(), p.key, p.message),
        None => format!("{}: {}: {}", path.display(), p.key, p.message),
    };
    match problems {
        [one] if unlisted == 0 => format!("scene {}", at(one)),
        many => {
            let mut text = format!(
                "scene {} has {} problems:",
                path.display(),
                many.len() + unlisted
            );
            for p in many {
                text.push_str("\n  ");
                text.push_str(&at(p));
            }
            if unlisted > 0 {
                text.push_str(&format!("\n  ... and {unlisted} more"));
            }
            text
        }
    }
}

/// `names` joined with `, `, the first [`MAX_NAMES_SHOWN`] of a longer list with its count.
fn listing(names: &[String]) -> String {
    if names.len() <= MAX_NAMES_SHOWN {
        return names.join(", ");
    }
    format!(
        "{}, ... ({} in all)",
        names[..MAX_NAMES_SHOWN].join(", "),
        names.len()
    )
}

/// A value or a list of values (`posture = "standing"` or `posture = ["standing", "sitting"]`).
/// Read by hand rather than as an untagged enum, so a wrong value gets the value's own error
/// (`unknown variant `sittin`, expected one of ...`) instead of "did not match any variant".
#[derive(Debug, Clone)]
enum OneOrMany<T> {
    One(T),
    Many(Vec<T>),
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for OneOrMany<T> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> serde::de::Visitor<'de> for Visitor<T> {
            type Value = OneOrMany<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a name or a list of names")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
                use serde::de::IntoDeserializer;
                T::deserialize(v.into_deserializer()).map(OneOrMany::One)
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<Self::Value, A::Error> {
                let mut all = Vec::new();
                while let Some(x) = seq.next_element()? {
                    all.push(x);
                }
                Ok(OneOrMany::Many(all))
            }
        }
        deserializer.deserialize_any(Visitor(std::marker::PhantomData))
    }
}

impl<T> OneOrMany<T> {
    fn as_slice(&self) -> &[T] {
        match self {
            OneOrMany::One(x) => std::slice::from_ref(x),
            OneOrMany::Many(v) => v,
        }
    }
}

impl OneOrMany<Posture> {
    /// The postures, each once, in file order.
    fn distinct(&self) -> Vec<Posture> {
        let mut list: Vec<Posture> = Vec::new();
        for p in self.as_slice() {
            if !list.contains(p) {
                list.push(*p);
            }
        }
        list
    }
}

/// True the first time `place` (an index into `places`, `None` the open room) is seen, marking it
/// in `seen` (one flag per place, then the open room).
fn first_time(seen: &mut [bool], place: Option<usize>) -> bool {
    let i = place.unwrap_or(seen.len().saturating_sub(1));
    match seen.get_mut(i) {
        Some(flag) if !*flag => {
            *flag = true;
            true
        }
        _ => false,
    }
}

#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
struct StartFile {
    #[serde(default)]
    posture: Option<Posture>,
    #[serde(default)]
    at: Option<String>,
}

#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
enum EndHands {
    #[default]
    Empty,
    Any,
}

#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
struct EndFile {
    #[serde(default)]
    posture: Option<OneOrMany<Posture>>,
    #[serde(default)]
    at: Option<OneOrMany<String>>,
    #[serde(default)]
    hands: EndHands,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct LimitsFile {
    #[serde(default)]
    instructions: Option<u32>,
    #[serde(default)]
    minutes: Option<f64>,
    #[serde(default = "default_seconds")]
    default_seconds: f64,
    #[serde(default)]
    seconds: BTreeMap<String, f64>,
}

fn default_seconds() -> f64 {
    4.0
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct BalanceFile {
    #[serde(default = "default_strength")]
    strength: f64,
    #[serde(default)]
    target: BTreeMap<String, f64>,
}

impl Default for BalanceFile {
    fn default() -> Self {
        BalanceFile {
            strength: default_strength(),
            target: BTreeMap::new(),
        }
    }
}

/// Measured on the living room from the demo's counts (docs/planner.md): greedier strengths
/// balance more (mean KL after a session 0.67 at 1, 0.58 at 2, 0.50 at 4), but leave the scene's
/// weights and the seed less say; 2 is the middle.
fn default_strength() -> f64 {
    2.0
}

/// Which hands an interaction uses.
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
enum HandsFile {
    #[default]
    None,
    Left,
    Right,
    One,
    Both,
}

/// What an interaction does with its object.
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Hold {
    /// Picks the object up from the actor's place into the hand(s).
    Take,
    /// Uses an object already in the hand(s); it stays there.
    Keep,
    /// Puts the object down at the actor's place.
    Release,
}

#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
struct RequiresFile {
    #[serde(default)]
    posture: Option<OneOrMany<Posture>>,
    #[serde(default)]
    at: Option<OneOrMany<String>>,
    #[serde(default)]
    not_at: Option<OneOrMany<String>>,
    #[serde(default)]
    empty_hands: bool,
}

#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
struct LeavesFile {
    #[serde(default)]
    posture: Option<Posture>,
    #[serde(default)]
    at: Option<String>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct InteractionFile {
    #[serde(rename = "type")]
    motion_type: String,
    text: String,
    #[serde(default)]
    places: Vec<String>,
    #[serde(default)]
    objects: Vec<String>,
    #[serde(default)]
    hands: HandsFile,
    #[serde(default)]
    hold: Option<Hold>,
    #[serde(default)]
    requires: RequiresFile,
    #[serde(default)]
    leaves: LeavesFile,
    #[serde(default = "default_weight")]
    weight: f64,
}

fn default_weight() -> f64 {
    1.0
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    #[serde(default)]
    name: Option<String>,
    #[serde(default)]
    places: Vec<String>,
    #[serde(default)]
    objects: BTreeMap<String, String>,
    #[serde(default)]
    start: StartFile,
    #[serde(default)]
    end: Option<EndFile>,
    limits: LimitsFile,
    #[serde(default)]
    balance: BalanceFile,
    interactions: Vec<InteractionFile>,
}

/// How long a session may be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Limit {
    /// At most this many instructions.
    Instructions(u32),
    /// At most this many milliseconds of estimated motion.
    Millis(u64),
}

/// One concrete instruction the chain can emit: an interaction with its place, object and hand
/// bound.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// Position of its interaction in the file (`interactions[i]`).
    pub interaction: usize,
    /// Its motion type (a name of `schemas/motion_types.toml`).
    pub motion_type: String,
    /// The text template as written.
    pub template: String,
    /// The bound `{place}`, an index into [`Scene::places`].
    pub place: Option<usize>,
    /// The bound `{object}`, an index into [`Scene::objects`].
    pub object: Option<usize>,
    /// The hand or hands it uses.
    pub hand: Option<Hand>,
    /// What it does with its object.
    pub hold: Option<Hold>,
    /// Everything that must hold before it, in the order they are checked.
    pub requires: Vec<Requirement>,
    /// What it changes.
    pub effect: Effect,
    /// The scene's weight for it.
    pub weight: f64,
}

impl Candidate {
    /// The instruction text: the template with `{place}`, `{object}` and `{hand}` filled in.
    pub fn text(&self, scene: &Scene) -> String {
        let mut text = self.template.clone();
        if let Some(p) = self.place {
            text = text.replace("{place}", &scene.places[p]);
        }
        if let Some(o) = self.object {
            text = text.replace("{object}", &scene.objects[o]);
        }
        if let Some(h) = self.hand {
            text = text.replace("{hand}", h.as_str());
        }
        text
    }

    /// The object named in the event log: the held object, else the bound place.
    pub fn object_name<'s>(&self, scene: &'s Scene) -> Option<&'s str> {
        self.object
            .map(|o| scene.objects[o].as_str())
            .or_else(|| self.place.map(|p| scene.places[p].as_str()))
    }
}

/// A validated scene with its interactions expanded into candidates.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The scene's name (its `name`, else the file stem).
    pub name: String,
    /// Places the actor can be at (static scene objects), in file order.
    pub places: Vec<String>,
    /// Hand-held objects, sorted by name.
    pub objects: Vec<String>,
    /// The place (index into `places`) each object of `objects` starts at. An object no
    /// interaction takes stays there: states do not carry it.
    pub object_start: Vec<usize>,
    /// The objects (indices into `objects`, ascending) some interaction takes: the ones a state
    /// carries, in [`State::objects`], in this order.
    pub movable: Vec<usize>,
    /// The actor's state when the session starts.
    pub start: State,
    /// What a valid final state must meet.
    pub end: Vec<Requirement>,
    /// The session's length limit.
    pub limit: Limit,
    /// Estimated seconds per motion type, from the scene (`limits.seconds`).
    pub seconds: BTreeMap<String, f64>,
    /// Estimated seconds of a type the dataset and `limits.seconds` do not know.
    pub default_seconds: f64,
    /// The balance exponent (`balance.strength`).
    pub strength: f64,
    /// Target share per motion type, summing to 1: `balance.target` normalised, else uniform
    /// over the scene's types.
    pub target: BTreeMap<String, f64>,
    /// Every concrete instruction, in file order of interactions, then place, object, hand.
    pub candidates: Vec<Candidate>,
}

impl Scene {
    /// Reads and validates a scene file against the bundled motion types. A file of more than
    /// [`MAX_SCENE_BYTES`] is refused unread.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let read_error = |source| SceneError::Read {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::open(path).map_err(read_error)?;
        let mut bytes = Vec::new();
        file.take(MAX_SCENE_BYTES as u64 + 1)
            .read_to_end(&mut bytes)
            .map_err(read_error)?;
        if bytes.len() > MAX_SCENE_BYTES {
            return Err(SceneError::TooBig {
                path: path.to_path_buf(),
                limit: MAX_SCENE_BYTES,
            });
        }
        let text = String::from_utf8(bytes).map_err(|e| {
            read_error(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "stream did not contain valid UTF-8 (at byte {})",
                    e.utf8_error().valid_up_to()
                ),
            ))
        })?;
        Scene::parse(&text, path)
    }

    /// Parses and validates a scene; `path` names it in errors and gives the default name.
    pub fn parse(text: &str, path: &Path) -> Result<Scene, SceneError> {
        if text.len() > MAX_SCENE_BYTES {
            return Err(SceneError::TooBig {
                path: path.to_path_buf(),
                limit: MAX_SCENE_BYTES,
            });
        }
        let taxonomy = Taxonomy::bundled()?;
        let tree = toml::de::DeTable::parse(text).map_err(|error| SceneError::Syntax {
            path: path.to_path_buf(),
            line: error.span().map(|s| line_of(text, s.start)),
            error: Box::new(error),
        })?;
        // The tree goes into the deserializer whole (no copy kept: it is the largest thing
        // reading holds); lines are looked up in a second parse, only if there is a problem.
        let parsed: Result<SceneFile, _> =
            serde_path_to_error::deserialize(toml::Deserializer::from(tree));
        let lines = Lines::new(text);
        let file = parsed.map_err(|e| {
            let keys = segments(e.path());
            let line = e
                .inner()
                .span()
                .map(|s| lines.at(s.start))
                .or_else(|| lines.line(&steps(&keys)));
            let key = Some(e.path().to_string()).filter(|k| k != ".");
            SceneError::Shape {
                path: path.to_path_buf(),
                line,
                key,
                error: Box::new(e.into_inner()),
            }
        })?;
        let mut problems = Problems {
            lines: &lines,
            found: Vec::new(),
            unlisted: 0,
        };
        // The lists' lengths first: nothing below is sized by a list over its limit.
        let counts = [
            ("places", file.places.len(), MAX_PLACES),
            ("objects", file.objects.len(), MAX_OBJECTS),
            ("interactions", file.interactions.len(), MAX_CANDIDATES),
        ];
        let over: Vec<_> = counts.into_iter().filter(|(_, n, l)| n > l).collect();
        let scene = if over.is_empty() {
            Some(resolve(file, path, &taxonomy, &mut problems))
        } else {
            // Dropped before the problems' lines parse the text again.
            drop(file);
            for (list, n, limit) in over {
                problems.push(
                    &[k(list)],
                    format!(
                        "{n} {list}, more than the {limit} a scene may have; split it into \
                         smaller scenes"
                    ),
                );
            }
            None
        };
        match scene {
            Some(scene) if problems.count() == 0 => Ok(scene),
            _ => {
                let mut found = problems.found;
                found.sort_by_key(|p| p.line.unwrap_or(usize::MAX));
                Err(SceneError::Invalid {
                    path: path.to_path_buf(),
                    problems: found,
                    unlisted: problems.unlisted,
                })
            }
        }
    }

    /// The position in a state's [`State::objects`] of an object of `objects`, `None` for an
    /// object no interaction takes.
    pub fn slot(&self, object: usize) -> Option<usize> {
        self.movable.binary_search(&object).ok()
    }

    /// The motion types the scene's interactions have, sorted.
    pub fn types(&self) -> BTreeSet<&str> {
        self.candidates
            .iter()
            .map(|c| c.motion_type.as_str())
            .collect()
    }

    /// A place's name, or `none` for the open room.
    pub fn place_name(&self, place: Option<usize>) -> &str {
        place.map_or("none", |p| self.places[p].as_str())
    }
}

#[derive(Debug, Clone)]
enum Seg {
    K(String),
    I(usize),
}

fn segments(path: &serde_path_to_error::Path) -> Vec<Seg> {
    use serde_path_to_error::Segment;
    path.iter()
        .filter_map(|s| match s {
            Segment::Seq { index } => Some(Seg::I(*index)),
            Segment::Map { key } => Some(Seg::K(key.clone())),
            _ => None,
        })
        .collect()
}

/// `path` as the borrowed steps `base::toml_path` reads.
fn steps(path: &[Seg]) -> Vec<toml_path::Seg<'_>> {
    path.iter()
        .map(|seg| match seg {
            Seg::K(k) => toml_path::Seg::K(k),
            Seg::I(i) => toml_path::Seg::I(*i),
        })
        .collect()
}

/// The lines of a scene's text: a byte offset's line by binary search (not by counting), and a
/// key's line from a spanned tree parsed only when a problem asks for one.
struct Lines<'i> {
    text: &'i str,
    starts: Vec<usize>,
    tree: OnceCell<Option<SpannedToml<'i>>>,
}

impl<'i> Lines<'i> {
    fn new(text: &'i str) -> Lines<'i> {
        let starts = std::iter::once(0)
            .chain(memchr::memchr_iter(b'\n', text.as_bytes()).map(|i| i + 1))
            .collect();
        Lines {
            text,
            starts,
            tree: OnceCell::new(),
        }
    }

    /// 1-based line of a byte offset.
    fn at(&self, offset: usize) -> usize {
        self.starts.partition_point(|&s| s <= offset).max(1)
    }

    /// The line of the deepest part of `path` the file spells out.
    fn line(&self, path: &[toml_path::Seg<'_>]) -> Option<usize> {
        let tree = self.tree.get_or_init(|| {
            toml::de::DeTable::parse(self.text)
                .ok()
                .map(|t| SpannedToml::new(self.text, t.into_inner()))
        });
        tree.as_ref()?.find(path).1.map(|s| self.at(s.start))
    }
}

/// A place an interaction's `requires` or `leaves` names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum AtName {
    /// A place of the scene, or the open room (`None`).
    Fixed(Option<usize>),
    /// `{place}`: each instruction's bound place.
    Bound,
}

impl AtName {
    fn bind(self, place: Option<usize>) -> Option<usize> {
        match self {
            AtName::Fixed(p) => p,
            AtName::Bound => place,
        }
    }
}

/// The places a list names, each once in file order, and the problems (each once): a name
/// that is not a place, `{place}` without a `places` list. Linear in the list's length.
fn at_names(
    list: &[String],
    at_value: &dyn Fn(&str) -> Result<Option<usize>, String>,
    has_places: bool,
    places: usize,
) -> (Vec<AtName>, Vec<String>) {
    let mut names = Vec::new();
    let mut errors = Vec::new();
    let mut seen = vec![false; places + 1];
    let mut bound_seen = false;
    let mut bad: BTreeSet<&str> = BTreeSet::new();
    for name in list {
        if name == "{place}" {
            if !has_places {
                if !bound_seen {
                    errors.push("`{place}` needs a `places` list".to_string());
                }
            } else if !bound_seen {
                names.push(AtName::Bound);
            }
            bound_seen = true;
            continue;
        }
        match at_value(name) {
            Ok(p) => {
                if first_time(&mut seen, p) {
                    names.push(AtName::Fixed(p));
                }
            }
            Err(e) => {
                if bad.insert(name) {
                    errors.push(e);
                }
            }
        }
    }
    (names, errors)
}

struct Problems<'a, 'i> {
    lines: &'a Lines<'i>,
    found: Vec<SceneProblem>,
    /// Problems found after the first [`MAX_PROBLEMS`], counted, not listed.
    unlisted: usize,
}

impl Problems<'_, '_> {
    /// Problems found so far, listed or not.
    fn count(&self) -> usize {
        self.found.len() + self.unlisted
    }

    fn push(&mut self, path: &[Seg], message: String) {
        if self.found.len() >= MAX_PROBLEMS {
            self.unlisted += 1;
            return;
        }
        let path = steps(path);
        self.found.push(SceneProblem {
            key: toml_path::key_name(&path),
            line: self.lines.line(&path),
            message,
        });
    }
}

fn k(s: &str) -> Seg {
    Seg::K(s.to_string())
}

/// The reserved `at` value for "at no place" (the open room).
pub const NO_PLACE: &str = "none";

/// A type name of the taxonomy, or the problem with a suggestion.
fn check_type(taxonomy: &Taxonomy, name: &str) -> Result<(), String> {
    if taxonomy.get(name).is_some() {
        return Ok(());
    }
    let normal = normalize_label(name);
    let hint = if taxonomy.get(&normal).is_some() {
        format!(" (write it as `{normal}`)")
    } else {
        let close: Vec<&str> = taxonomy
            .types()
            .map(|t| t.name.as_str())
            .filter(|t| {
                let first = normal.split(' ').next().unwrap_or_default();
                !first.is_empty() && t.split(' ').any(|w| w == first)
            })
            .collect();
        if close.is_empty() {
            String::new()
        } else {
            format!(" (similar: {})", close.join(", "))
        }
    };
    Err(format!(
        "`{name}` is not a motion type of schemas/motion_types.toml{hint}"
    ))
}

fn finite_positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

/// Turns the parsed file into a scene, recording every problem; the scene returned is only
/// used when there are none.
fn resolve(file: SceneFile, path: &Path, taxonomy: &Taxonomy, problems: &mut Problems) -> Scene {
    let name = file.name.clone().unwrap_or_else(|| {
        path.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into())
    });
    let names = SceneNames::resolve(&file.places, &file.objects, problems);
    let start_at = resolve_start_at(&file.start, &names, problems);
    let start_posture = file.start.posture.unwrap_or(Posture::Standing);
    let end = resolve_end(
        file.end.unwrap_or_default(),
        start_posture,
        &names,
        problems,
    );
    let limit = resolve_limit(&file.limits, problems);
    let default_secs = file.limits.default_seconds;
    check_seconds(&file.limits, taxonomy, problems);
    let candidates = resolve_interactions(&file.interactions, &names, taxonomy, problems);
    let strength = file.balance.strength;
    let target = resolve_balance(&file.balance, &candidates, taxonomy, problems);
    let movable = movable_objects(&candidates, problems);
    let SceneNames {
        places,
        objects,
        object_start,
        ..
    } = names;
    let start = State {
        posture: start_posture,
        at: start_at,
        objects: movable
            .iter()
            .filter_map(|&o| object_start.get(o).map(|&p| Loc::Place(p)))
            .collect(),
    };
    Scene {
        name,
        places,
        objects,
        object_start,
        movable,
        start,
        end,
        limit,
        seconds: file.limits.seconds,
        default_seconds: default_secs,
        strength,
        target,
        candidates,
    }
}

/// The scene's places and objects as the checks look them up. Places are found by name in a
/// map and objects by binary search: a scene's lists are checked in time linear in their
/// lengths.
struct SceneNames {
    /// Distinct places, in file order.
    places: Vec<String>,
    place_ids: HashMap<String, usize>,
    /// The places joined for messages.
    places_listed: String,
    /// Objects, sorted (read from a sorted map).
    objects: Vec<String>,
    /// The place each object of `objects` starts at.
    object_start: Vec<usize>,
    /// The objects joined for messages.
    objects_listed: String,
}

impl SceneNames {
    /// Places and objects: distinct, non-empty, not the reserved word; every object starts at a
    /// place.
    fn resolve(
        place_list: &[String],
        object_list: &BTreeMap<String, String>,
        problems: &mut Problems,
    ) -> SceneNames {
        let mut places: Vec<String> = Vec::new();
        let mut place_ids: HashMap<String, usize> = HashMap::new();
        for (i, p) in place_list.iter().enumerate() {
            let p = p.trim();
            if p.is_empty() || p == NO_PLACE || p.contains(['{', '}', '\n']) {
                problems.push(
                    &[k("places"), Seg::I(i)],
                    format!(
                        "`{p}`: expected a place name (not empty, not `{NO_PLACE}`, no braces)"
                    ),
                );
            } else if place_ids.contains_key(p) {
                problems.push(&[k("places"), Seg::I(i)], format!("`{p}` is listed twice"));
            } else {
                place_ids.insert(p.to_string(), places.len());
                places.push(p.to_string());
            }
        }
        let places_listed = listing(&places);
        let mut names = SceneNames {
            places,
            place_ids,
            places_listed,
            objects: Vec::new(),
            object_start: Vec::new(),
            objects_listed: String::new(),
        };
        for (object, at) in object_list {
            let key = [k("objects"), k(object)];
            if object.trim().is_empty()
                || object.contains(['{', '}', '\n'])
                || names.place_ids.contains_key(object.as_str())
            {
                problems.push(
                    &key,
                    format!(
                        "`{object}`: expected an object name (not empty, no braces, not a place)"
                    ),
                );
                continue;
            }
            match names.place_index(at) {
                Some(p) => {
                    names.objects.push(object.clone());
                    names.object_start.push(p);
                }
                None => problems.push(
                    &key,
                    format!(
                        "`{at}`: an object starts at one of the places ({})",
                        names.places_listed
                    ),
                ),
            }
        }
        names.objects_listed = listing(&names.objects);
        names
    }

    fn place_index(&self, name: &str) -> Option<usize> {
        self.place_ids.get(name).copied()
    }

    fn object_index(&self, name: &str) -> Option<usize> {
        self.objects.binary_search_by(|o| o.as_str().cmp(name)).ok()
    }

    /// An `at` value: `none` is the open room; anything else must be a listed place.
    fn at_value(&self, name: &str) -> Result<Option<usize>, String> {
        if name == NO_PLACE {
            return Ok(None);
        }
        self.place_index(name).map(Some).ok_or_else(|| {
            format!(
                "`{name}` is not a place of the scene (places: {}; or `{NO_PLACE}`)",
                self.places_listed
            )
        })
    }
}

/// The actor's start place (`start.at`), the open room where unset or wrong.
fn resolve_start_at(
    start: &StartFile,
    names: &SceneNames,
    problems: &mut Problems,
) -> Option<usize> {
    match start.at.as_deref() {
        None => None,
        Some(a) => match names.at_value(a) {
            Ok(p) => p,
            Err(e) => {
                problems.push(&[k("start"), k("at")], e);
                None
            }
        },
    }
}

/// What a valid final state must meet: a posture (the start's, by default), a place where
/// `end.at` names some, and empty hands unless `end.hands = "any"`.
fn resolve_end(
    end_file: EndFile,
    start_posture: Posture,
    names: &SceneNames,
    problems: &mut Problems,
) -> Vec<Requirement> {
    let mut end = Vec::new();
    end.push(Requirement::Posture(
        end_file
            .posture
            .as_ref()
            .map(OneOrMany::distinct)
            .unwrap_or_else(|| vec![start_posture]),
    ));
    // A list of places holds each once (`["sofa", "sofa"]` is `["sofa"]`): a requirement is
    // at most the places long, however long the file's list.
    let mut seen = vec![false; names.places.len() + 1];
    if let Some(at) = &end_file.at {
        let mut list = Vec::new();
        for (i, a) in at.as_slice().iter().enumerate() {
            match names.at_value(a) {
                Ok(p) => {
                    if first_time(&mut seen, p) {
                        list.push(p);
                    }
                }
                Err(e) => problems.push(&[k("end"), k("at"), Seg::I(i)], e),
            }
        }
        end.push(Requirement::At(list));
    }
    if end_file.hands == EndHands::Empty {
        end.push(Requirement::EmptyHands);
    }
    end
}

/// The session's limit: exactly one of `instructions` and `minutes`, in range.
fn resolve_limit(limits: &LimitsFile, problems: &mut Problems) -> Limit {
    match (limits.instructions, limits.minutes) {
        (Some(n), None) if (1..=10_000).contains(&n) => Limit::Instructions(n),
        (Some(n), None) => {
            problems.push(
                &[k("limits"), k("instructions")],
                format!("{n}: expected 1 to 10000 instructions"),
            );
            Limit::Instructions(1)
        }
        (None, Some(m)) if finite_positive(m) && m <= 240.0 => {
            Limit::Millis((m * 60_000.0).round() as u64)
        }
        (None, Some(m)) => {
            problems.push(
                &[k("limits"), k("minutes")],
                format!("{m}: expected a number of minutes above 0, at most 240"),
            );
            Limit::Instructions(1)
        }
        (Some(_), Some(_)) => {
            problems.push(
                &[k("limits")],
                "both `instructions` and `minutes`: give one of them".into(),
            );
            Limit::Instructions(1)
        }
        (None, None) => {
            problems.push(
                &[k("limits")],
                "neither `instructions` nor `minutes`: give one of them".into(),
            );
            Limit::Instructions(1)
        }
    }
}

/// `limits.default_seconds` and every `limits.seconds` entry: a known type, a duration in range.
fn check_seconds(limits: &LimitsFile, taxonomy: &Taxonomy, problems: &mut Problems) {
    let default_secs = limits.default_seconds;
    if !(finite_positive(default_secs) && default_secs <= 3600.0) {
        problems.push(
            &[k("limits"), k("default_seconds")],
            format!("{default_secs}: expected seconds above 0, at most 3600"),
        );
    }
    for (t, s) in &limits.seconds {
        let key = [k("limits"), k("seconds"), k(t)];
        if let Err(e) = check_type(taxonomy, t) {
            problems.push(&key, e);
        }
        if !(finite_positive(*s) && *s <= 3600.0) {
            problems.push(&key, format!("{s}: expected seconds above 0, at most 3600"));
        }
    }
}

/// Every interaction, checked and expanded into candidates in file order; an interaction with
/// a problem adds none.
fn resolve_interactions(
    interactions: &[InteractionFile],
    names: &SceneNames,
    taxonomy: &Taxonomy,
    problems: &mut Problems,
) -> Vec<Candidate> {
    let mut candidates = Vec::new();
    if interactions.is_empty() {
        problems.push(
            &[k("interactions")],
            "empty: expected at least one interaction".into(),
        );
    }
    for (i, inter) in interactions.iter().enumerate() {
        let before = problems.count();
        let bound = Interaction::resolve(i, inter, names, taxonomy, problems);
        if problems.count() > before {
            continue;
        }
        // Counted before expanding, so a long list cannot make the reader allocate its product.
        let expansion = bound.places.len() * bound.objects.len() * bound.hands.len();
        if candidates.len() + expansion > MAX_CANDIDATES {
            problems.push(
                &[k("interactions"), Seg::I(i)],
                format!(
                    "the scene expands into more than {MAX_CANDIDATES} instructions (places x \
                     objects x hands of every interaction); split it into smaller scenes"
                ),
            );
            break;
        }
        bound.expand_into(&mut candidates);
    }
    candidates
}

/// One interaction with its names resolved: what it expands over (each list at least one
/// entry, `None` for "not bound") and its requirements and effect before binding `{place}`.
struct Interaction<'f> {
    index: usize,
    file: &'f InteractionFile,
    text: &'f str,
    places: Vec<Option<usize>>,
    objects: Vec<Option<usize>>,
    hands: Vec<Option<Hand>>,
    hold: Option<Hold>,
    requires_at: Option<Vec<AtName>>,
    requires_not_at: Option<Vec<AtName>>,
    requires_posture: Option<Vec<Posture>>,
    leaves_at: Option<AtName>,
}

impl<'f> Interaction<'f> {
    /// Checks `interactions[index]`, recording its problems; the result is expanded only when
    /// there are none.
    fn resolve(
        index: usize,
        inter: &'f InteractionFile,
        names: &SceneNames,
        taxonomy: &Taxonomy,
        problems: &mut Problems,
    ) -> Interaction<'f> {
        let key = |field: &str| vec![k("interactions"), Seg::I(index), k(field)];
        if let Err(e) = check_type(taxonomy, &inter.motion_type) {
            problems.push(&key("type"), e);
        }
        if !finite_positive(inter.weight) {
            problems.push(
                &key("weight"),
                format!("{}: expected a number above 0", inter.weight),
            );
        }
        let text = inter.text.trim();
        if text.is_empty() || text.contains(['\n', '\r']) {
            problems.push(&key("text"), "expected one line of instruction text".into());
        }
        check_placeholders(text, inter, &key("text"), problems);
        let mut places = bind_names(index, NameList::Places, &inter.places, names, problems);
        let mut objects = bind_names(index, NameList::Objects, &inter.objects, names, problems);
        let hold = resolve_hold(inter, &key, problems);
        if places.is_empty() {
            places.push(None);
        }
        if objects.is_empty() {
            objects.push(None);
        }
        let hands: Vec<Option<Hand>> = match inter.hands {
            HandsFile::None => vec![None],
            HandsFile::Left => vec![Some(Hand::Left)],
            HandsFile::Right => vec![Some(Hand::Right)],
            HandsFile::One => vec![Some(Hand::Left), Some(Hand::Right)],
            HandsFile::Both => vec![Some(Hand::Both)],
        };
        // The places `requires` and `leaves` name, resolved once for all the interaction's
        // instructions (`{place}` is each one's bound place).
        let has_places = !inter.places.is_empty();
        let mut resolve_list = |list: &[String], field: &str| {
            let at_value = |name: &str| names.at_value(name);
            let (found, errors) = at_names(list, &at_value, has_places, names.places.len());
            for e in errors {
                problems.push(&key(field), e);
            }
            found
        };
        let requires_at = inter
            .requires
            .at
            .as_ref()
            .map(|l| resolve_list(l.as_slice(), "requires"));
        let requires_not_at = inter
            .requires
            .not_at
            .as_ref()
            .map(|l| resolve_list(l.as_slice(), "requires"));
        let leaves_at = inter
            .leaves
            .at
            .as_ref()
            .and_then(|a| resolve_list(std::slice::from_ref(a), "leaves").pop());
        Interaction {
            index,
            file: inter,
            text,
            places,
            objects,
            hands,
            hold,
            requires_at,
            requires_not_at,
            requires_posture: inter.requires.posture.as_ref().map(OneOrMany::distinct),
            leaves_at,
        }
    }

    /// One candidate per bound place, object and hand, in that order.
    fn expand_into(&self, candidates: &mut Vec<Candidate>) {
        for &place in &self.places {
            for &object in &self.objects {
                for &hand in &self.hands {
                    candidates.push(self.candidate(place, object, hand));
                }
            }
        }
    }

    fn candidate(
        &self,
        place: Option<usize>,
        object: Option<usize>,
        hand: Option<Hand>,
    ) -> Candidate {
        let inter = self.file;
        let hold = self.hold;
        let bind = |names: &[AtName]| -> Vec<Option<usize>> {
            names.iter().map(|n| n.bind(place)).collect()
        };
        let mut requires = Vec::new();
        if let Some(p) = &self.requires_posture {
            requires.push(Requirement::Posture(p.clone()));
        }
        if let Some(at) = &self.requires_at {
            requires.push(Requirement::At(bind(at)));
        }
        if let Some(not_at) = &self.requires_not_at {
            requires.push(Requirement::NotAt(bind(not_at)));
        }
        if inter.requires.empty_hands {
            requires.push(Requirement::EmptyHands);
        }
        requires.extend(Requirement::for_hands(hand, hold, object));
        Candidate {
            interaction: self.index,
            motion_type: inter.motion_type.clone(),
            template: self.text.to_string(),
            place,
            object,
            hand,
            hold,
            requires,
            effect: Effect {
                posture: inter.leaves.posture,
                at: self.leaves_at.map(|n| n.bind(place)),
                hold: hold
                    .zip(object)
                    .zip(hand)
                    .map(|((h, o), hand)| (h, o, hand)),
            },
            weight: inter.weight,
        }
    }
}

/// Each `{...}` of an instruction text must be a known placeholder with something to fill it.
fn check_placeholders(text: &str, inter: &InteractionFile, key: &[Seg], problems: &mut Problems) {
    let mut rest = text;
    while let Some(open) = rest.find('{') {
        let after = &rest[open + 1..];
        let Some(close) = after.find('}') else {
            problems.push(key, format!("`{text}`: a `{{` is never closed"));
            break;
        };
        let name = &after[..close];
        let filled = match name {
            "place" => !inter.places.is_empty(),
            "object" => !inter.objects.is_empty(),
            "hand" => inter.hands != HandsFile::None,
            _ => {
                problems.push(
                    key,
                    format!("`{{{name}}}`: expected `{{place}}`, `{{object}}` or `{{hand}}`"),
                );
                true
            }
        };
        if !filled {
            let needs = match name {
                "place" => "a `places` list",
                "object" => "an `objects` list",
                _ => "`hands` other than `none`",
            };
            problems.push(
                key,
                format!("`{{{name}}}` needs {needs} on the interaction"),
            );
        }
        rest = &after[close + 1..];
    }
}

/// Which of the scene's lists an interaction's names are looked up in.
#[derive(Clone, Copy)]
enum NameList {
    Places,
    Objects,
}

/// The interaction's `places` or `objects` (`list`, from the file), each a name of the scene.
fn bind_names(
    index: usize,
    which: NameList,
    list: &[String],
    names: &SceneNames,
    problems: &mut Problems,
) -> Vec<Option<usize>> {
    let (field, what, listed) = match which {
        NameList::Places => ("places", "a place", &names.places_listed),
        NameList::Objects => ("objects", "an object", &names.objects_listed),
    };
    let mut bound = Vec::new();
    for (j, name) in list.iter().enumerate() {
        let found = match which {
            NameList::Places => names.place_index(name),
            NameList::Objects => names.object_index(name),
        };
        match found {
            Some(x) => bound.push(Some(x)),
            None => problems.push(
                &[k("interactions"), Seg::I(index), k(field), Seg::I(j)],
                format!("`{name}` is not {what} of the scene ({field}: {listed})"),
            ),
        }
    }
    bound
}

/// What the interaction does with its objects (`keep` by default when it has some); taking or
/// putting down needs a hand.
fn resolve_hold(
    inter: &InteractionFile,
    key: &dyn Fn(&str) -> Vec<Seg>,
    problems: &mut Problems,
) -> Option<Hold> {
    let hold = match (inter.hold, inter.objects.is_empty()) {
        (Some(_), true) => {
            problems.push(
                &key("hold"),
                "`hold` needs an `objects` list on the interaction".into(),
            );
            None
        }
        (None, true) => None,
        (h, false) => Some(h.unwrap_or(Hold::Keep)),
    };
    if matches!(hold, Some(Hold::Take | Hold::Release)) && inter.hands == HandsFile::None {
        problems.push(
            &key("hands"),
            "`none`: taking or putting down an object needs `left`, `right`, `one` or `both`"
                .into(),
        );
    }
    hold
}

/// The balance target's shares, normalised to sum to 1; by default uniform over the scene's
/// types. Checks `balance.strength` too.
fn resolve_balance(
    balance: &BalanceFile,
    candidates: &[Candidate],
    taxonomy: &Taxonomy,
    problems: &mut Problems,
) -> BTreeMap<String, f64> {
    let strength = balance.strength;
    if !(strength.is_finite() && (0.0..=10.0).contains(&strength)) {
        problems.push(
            &[k("balance"), k("strength")],
            format!("{strength}: expected a number from 0 to 10"),
        );
    }
    let scene_types: BTreeSet<&str> = candidates.iter().map(|c| c.motion_type.as_str()).collect();
    let mut target = BTreeMap::new();
    if balance.target.is_empty() {
        for t in &scene_types {
            target.insert(t.to_string(), 1.0);
        }
    } else {
        for (t, w) in &balance.target {
            let key = [k("balance"), k("target"), k(t)];
            if let Err(e) = check_type(taxonomy, t) {
                problems.push(&key, e);
            } else if !scene_types.contains(t.as_str()) {
                problems.push(
                    &key,
                    format!("no interaction of the scene has type `{t}`: a session cannot add it"),
                );
            }
            if !finite_positive(*w) {
                problems.push(&key, format!("{w}: expected a share above 0"));
            }
            target.insert(t.clone(), *w);
        }
    }
    let total: f64 = target.values().sum();
    if total > 0.0 && total.is_finite() {
        for v in target.values_mut() {
            *v /= total;
        }
    }
    target
}

/// The objects some instruction takes, ascending: the only ones that ever move (an object is
/// put down only from a hand), so the states carry where those are, and nothing of the others.
fn movable_objects(candidates: &[Candidate], problems: &mut Problems) -> Vec<usize> {
    let mut movable: Vec<usize> = candidates
        .iter()
        .filter(|c| c.hold == Some(Hold::Take))
        .filter_map(|c| c.object)
        .collect();
    movable.sort_unstable();
    movable.dedup();
    if movable.len() > MAX_MOVABLE {
        problems.push(
            &[k("objects")],
            format!(
                "{} objects are taken by interactions (`hold = \"take\"`), more than the \
                 {MAX_MOVABLE} a scene may move; split it into smaller scenes",
                movable.len()
            ),
        );
    }
    movable
}
