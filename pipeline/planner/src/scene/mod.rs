//! The scene file (TOML): the places the actor can be at, the hand-held objects and where they
//! start, the actor's start and end states, the interactions with their requirements and effects,
//! the session's limit and the balance target. `schemas/scene.md` documents every key.
//!
//! Reading expands each interaction into candidates (one per place, object and hand it names), so
//! the chain works on concrete instructions. Every problem is reported at once with its key.
//!
//! This file holds the validated [`Scene`] with its [`Candidate`]s, the limits a scene is read
//! within, and reading (parse, then resolve). The file's shape as written is in `file.rs`, the
//! checks that turn it into a scene in `resolve.rs` (names, start, end, limits, balance) and
//! `interaction.rs` (each interaction bound and expanded), and the errors with each problem's key
//! and line in `problems.rs`.

mod file;
mod interaction;
mod problems;
mod resolve;

use std::collections::{BTreeMap, BTreeSet};
use std::io::Read as _;
use std::path::Path;

use serde::Deserialize;

use self::file::SceneFile;
use self::problems::{Lines, Problems, k, segments, steps};
pub use self::problems::{SceneError, SceneProblem};
use self::resolve::resolve;
use super::state::{Effect, Requirement, State};
use motionforge_core::base::toml_path::line_of;
use motionforge_sources::annotate::span::Hand;
use motionforge_sources::annotate::taxonomy::Taxonomy;

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

/// The reserved `at` value for "at no place" (the open room).
pub const NO_PLACE: &str = "none";
