//! Motion types: a [`Taxonomy`] of named types in groups (after LINGO's Table A1, bundled as
//! `schemas/motion_types.toml`), and a [`TypeMap`] that maps a dataset's free-text labels onto it.
//!
//! A [`MotionType`] carries the flags later stages need: `locomotion` (reset the frame counter,
//! horizontal pelvis goal), `hand_goal` (the hand position at the grasp/release frame is a goal),
//! `scene_dependent` (the motion needs the scene) and `mirror` (the type a left/right mirror turns
//! it into). `schemas/motion-types.md` explains every group, type and flag.
//!
//! A dataset's labels reach a type in three steps, and only these: the label *is* a type name
//! (after [`normalize_label`]), an alias names it exactly, or the first matching rule (a regex)
//! names it. Anything else is unmapped and reported as such; nothing is guessed.
//!
//! ```
//! use motionforge_sources::annotate::taxonomy::{Taxonomy, TypeMap, TypeMapConfig, TypeRule};
//!
//! let config = TypeMapConfig {
//!     rules: vec![TypeRule { pattern: r"^turn (to (the )?)?left$".into(), r#type: "turn left".into() }],
//!     ..TypeMapConfig::default()
//! };
//! let map = TypeMap::new(Taxonomy::bundled()?, &config)?;
//! assert_eq!(map.map("Turn to the left").map(|t| t.name.as_str()), Some("turn left"));
//! assert_eq!(map.taxonomy().mirror_of("turn left"), Some("turn right"));
//! assert!(map.map("turn around").is_none());
//! # Ok::<(), motionforge_sources::annotate::taxonomy::TaxonomyError>(())
//! ```

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use regex::{Regex, RegexBuilder};
use serde::{Deserialize, Serialize};

/// The bundled taxonomy's text (`schemas/motion_types.toml`).
pub const BUNDLED_TOML: &str = include_str!("../../../../schemas/motion_types.toml");

/// The name errors in the bundled taxonomy are reported under.
pub const BUNDLED_FILE: &str = "schemas/motion_types.toml";

/// Where types added by [`Taxonomy::with_extra`] are reported to come from.
pub const EXTRA_ORIGIN: &str = "extra types";

/// Why a taxonomy or a label map cannot be used. Every variant names the offending entry.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TaxonomyError {
    /// A taxonomy file could not be read.
    #[error("{file}: cannot read: {message}")]
    Read {
        /// The file.
        file: String,
        /// The I/O error's text (kept as text: the error is cloned, and `std::io::Error` is not
        /// `Clone`).
        message: String,
    },
    /// A taxonomy file is not valid TOML or has the wrong shape.
    #[error("{file}: not a valid taxonomy: {message}")]
    Parse {
        /// The file.
        file: String,
        /// The TOML parser's message (kept as text: it quotes the offending line).
        message: String,
    },
    /// A type or group name is empty, or a type name is not in normal form.
    #[error("{file}: {what} name `{name}` is not valid: {fault}")]
    InvalidName {
        /// The file.
        file: String,
        /// `type` or `group`.
        what: &'static str,
        /// The name as written.
        name: String,
        /// What is wrong with it.
        fault: NameFault,
    },
    /// Two groups share a name.
    #[error("{file}: group `{name}` is defined twice")]
    DuplicateGroup {
        /// The file.
        file: String,
        /// The repeated name.
        name: String,
    },
    /// Two types share a name.
    #[error("{file}: type `{name}` is defined twice")]
    DuplicateType {
        /// The file.
        file: String,
        /// The repeated name.
        name: String,
    },
    /// A type names a group that does not exist.
    #[error("{file}: type `{type_name}` is in group `{group}`, which is not defined")]
    UnknownGroup {
        /// The file.
        file: String,
        /// The type.
        type_name: String,
        /// The missing group.
        group: String,
    },
    /// A type's mirror does not exist, is the type itself, or does not mirror back.
    #[error("{file}: type `{type_name}` mirrors to `{mirror}`: {fault}")]
    BadMirror {
        /// The file.
        file: String,
        /// The type.
        type_name: String,
        /// Its `mirror` value.
        mirror: String,
        /// What is wrong.
        fault: MirrorFault,
    },
    /// An alias is empty, repeated, shadowed by a type name, or names a type that does not exist.
    #[error("alias `{alias}` -> `{target}`: {fault}")]
    BadAlias {
        /// The alias as written.
        alias: String,
        /// The type it names.
        target: String,
        /// What is wrong.
        fault: AliasFault,
    },
    /// A rule's regex does not compile, or it names a type that does not exist.
    #[error("rule {index} (`{pattern}` -> `{target}`): {fault}")]
    BadRule {
        /// The rule's position in `rules` (0-based).
        index: usize,
        /// The regex as written.
        pattern: String,
        /// The type it names.
        target: String,
        /// What is wrong.
        fault: RuleFault,
    },
}

/// What is wrong with a type or group name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameFault {
    /// Empty or blank.
    #[error("it is empty")]
    Empty,
    /// Not in normal form (lowercase words, single spaces).
    #[error("write it as `{normal}` (lowercase words, single spaces)")]
    NotNormal {
        /// The name in normal form.
        normal: String,
    },
}

/// What is wrong with a type's `mirror`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MirrorFault {
    /// The type names itself.
    #[error("a type cannot mirror to itself; leave `mirror` out")]
    ToItself,
    /// No type has the mirror's name.
    #[error("no type has that name")]
    NoSuchType,
    /// The mirror type does not mirror back. The names are boxed `str`s to keep
    /// [`TaxonomyError`] as small as it was: build errors carry it by value.
    #[error("not mutual: `{other}` mirrors to {}", mirrored_name(.other_mirror.as_deref()))]
    NotMutual {
        /// The mirror type.
        other: Box<str>,
        /// Its own `mirror`, if any.
        other_mirror: Option<Box<str>>,
    },
}

/// A type's mirror as messages name it: `` `name` `` or `nothing`.
fn mirrored_name(mirror: Option<&str>) -> String {
    mirror.map_or("nothing".to_string(), |m| format!("`{m}`"))
}

/// What is wrong with an alias.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AliasFault {
    /// The alias normalizes to nothing.
    #[error("the alias is empty")]
    Empty,
    /// No type has the target's name.
    #[error("no type has that name")]
    NoSuchType,
    /// The alias is another type's name.
    #[error("`{label}` is itself a type name, which always wins over an alias")]
    TypeName {
        /// The alias, normalized.
        label: String,
    },
    /// Two aliases normalize to the same label.
    #[error("same label as alias `{other}` once normalized to `{label}`")]
    SameLabel {
        /// The other alias as written.
        other: String,
        /// The label both normalize to.
        label: String,
    },
}

/// What is wrong with a rule.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RuleFault {
    /// No type has the rule's target name.
    #[error("no type has that name")]
    NoSuchType,
    /// The pattern does not compile.
    #[error("not a valid regex: {0}")]
    Regex(
        /// The regex crate's message (kept as text: it spans lines and points into the pattern).
        String,
    ),
}

/// One motion type.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct MotionType {
    /// Name: lowercase words separated by single spaces (`walk front left`).
    pub name: String,
    /// The group's name.
    pub group: String,
    /// Locomotion: the frame counter is reset to zero and the clip has a horizontal pelvis goal
    /// (LINGO A.3, A.4, B.2.2).
    #[serde(default)]
    pub locomotion: bool,
    /// Reaching/grasp type: the hand position at the grasp or release frame is the clip's hand
    /// goal (LINGO A.4, B.1.5).
    #[serde(default)]
    pub hand_goal: bool,
    /// The motion needs the scene to be generated or judged (LINGO A.2).
    #[serde(default)]
    pub scene_dependent: bool,
    /// The type a left/right mirror of the motion becomes (`turn left` -> `turn right`); `None`
    /// when mirroring keeps the type.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mirror: Option<String>,
    /// One-line description.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
}

/// A group of motion types (one block of LINGO's Table A1).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct MotionGroup {
    /// Name (`locomotion`, `pick up / put down`, ...).
    pub name: String,
    /// The table's description of the group.
    #[serde(default)]
    pub description: String,
}

/// A `[[types]]` entry of a taxonomy file: a [`MotionType`] plus the objects the table names.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TypeEntry {
    name: String,
    group: String,
    #[serde(default)]
    locomotion: bool,
    #[serde(default)]
    hand_goal: bool,
    #[serde(default)]
    scene_dependent: bool,
    #[serde(default)]
    mirror: Option<String>,
    #[serde(default)]
    description: String,
    #[serde(default)]
    objects: Vec<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TaxonomyFile {
    #[serde(default)]
    groups: Vec<MotionGroup>,
    #[serde(default)]
    types: Vec<TypeEntry>,
}

/// A validated set of motion groups and types: names are unique and in normal form, every type's
/// group exists, and mirrors exist and are mutual.
#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct Taxonomy {
    groups: Vec<MotionGroup>,
    types: Vec<MotionType>,
    /// Objects the source table names for a type (`play` -> game, guitar), by type name.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    objects: BTreeMap<String, Vec<String>>,
    #[serde(skip)]
    index: HashMap<String, usize>,
}

/// A label in the form names are compared in: trimmed, lowercase, `-` and `_` read as spaces,
/// runs of whitespace collapsed to one space.
pub fn normalize_label(label: &str) -> String {
    label
        .to_lowercase()
        .replace(['-', '_'], " ")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

impl Taxonomy {
    /// The bundled taxonomy (`schemas/motion_types.toml`, LINGO's Table A1).
    pub fn bundled() -> Result<Taxonomy, TaxonomyError> {
        Taxonomy::from_toml(BUNDLED_TOML, BUNDLED_FILE)
    }

    /// Reads a taxonomy file.
    pub fn from_file(path: &Path) -> Result<Taxonomy, TaxonomyError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| TaxonomyError::Read {
            file: file.clone(),
            message: e.to_string(),
        })?;
        Taxonomy::from_toml(&text, &file)
    }

    /// Parses and validates a taxonomy (`[[groups]]` and `[[types]]` tables); `file` names the
    /// source in errors.
    pub fn from_toml(text: &str, file: &str) -> Result<Taxonomy, TaxonomyError> {
        let parsed: TaxonomyFile = toml::from_str(text).map_err(|e| TaxonomyError::Parse {
            file: file.to_string(),
            message: e.to_string(),
        })?;
        let mut objects = BTreeMap::new();
        let mut types = Vec::with_capacity(parsed.types.len());
        for entry in parsed.types {
            if !entry.objects.is_empty() {
                objects.insert(entry.name.clone(), entry.objects);
            }
            types.push(MotionType {
                name: entry.name,
                group: entry.group,
                locomotion: entry.locomotion,
                hand_goal: entry.hand_goal,
                scene_dependent: entry.scene_dependent,
                mirror: entry.mirror,
                description: entry.description,
            });
        }
        Taxonomy::validated(parsed.groups, types, objects, file)
    }

    /// Adds dataset-specific types (e.g. `side step left` in `locomotion`). They obey the same
    /// rules as the file's types: a name already taken, an unknown group or a one-sided mirror is
    /// an error (reported under [`EXTRA_ORIGIN`]). A mirror pair must be added together.
    pub fn with_extra(self, extra: Vec<MotionType>) -> Result<Taxonomy, TaxonomyError> {
        if extra.is_empty() {
            return Ok(self);
        }
        let Taxonomy {
            groups,
            mut types,
            objects,
            ..
        } = self;
        types.extend(extra);
        Taxonomy::validated(groups, types, objects, EXTRA_ORIGIN)
    }

    fn validated(
        groups: Vec<MotionGroup>,
        types: Vec<MotionType>,
        objects: BTreeMap<String, Vec<String>>,
        file: &str,
    ) -> Result<Taxonomy, TaxonomyError> {
        let invalid =
            |what: &'static str, name: &str, fault: NameFault| TaxonomyError::InvalidName {
                file: file.to_string(),
                what,
                name: name.to_string(),
                fault,
            };
        let mut group_names = HashMap::new();
        for group in &groups {
            if group.name.trim().is_empty() {
                return Err(invalid("group", &group.name, NameFault::Empty));
            }
            if group_names.insert(group.name.as_str(), ()).is_some() {
                return Err(TaxonomyError::DuplicateGroup {
                    file: file.to_string(),
                    name: group.name.clone(),
                });
            }
        }
        let mut index = HashMap::with_capacity(types.len());
        for (i, ty) in types.iter().enumerate() {
            let normal = normalize_label(&ty.name);
            if normal.is_empty() {
                return Err(invalid("type", &ty.name, NameFault::Empty));
            }
            if normal != ty.name {
                return Err(invalid("type", &ty.name, NameFault::NotNormal { normal }));
            }
            if index.insert(normal, i).is_some() {
                return Err(TaxonomyError::DuplicateType {
                    file: file.to_string(),
                    name: ty.name.clone(),
                });
            }
            if !group_names.contains_key(ty.group.as_str()) {
                return Err(TaxonomyError::UnknownGroup {
                    file: file.to_string(),
                    type_name: ty.name.clone(),
                    group: ty.group.clone(),
                });
            }
        }
        for ty in &types {
            let Some(mirror) = &ty.mirror else { continue };
            let bad = |fault: MirrorFault| TaxonomyError::BadMirror {
                file: file.to_string(),
                type_name: ty.name.clone(),
                mirror: mirror.clone(),
                fault,
            };
            if *mirror == ty.name {
                return Err(bad(MirrorFault::ToItself));
            }
            let Some(other) = index.get(mirror.as_str()).and_then(|&j| types.get(j)) else {
                return Err(bad(MirrorFault::NoSuchType));
            };
            if other.mirror.as_deref() != Some(ty.name.as_str()) {
                return Err(bad(MirrorFault::NotMutual {
                    other: other.name.as_str().into(),
                    other_mirror: other.mirror.as_deref().map(Box::from),
                }));
            }
        }
        Ok(Taxonomy {
            groups,
            types,
            objects,
            index,
        })
    }

    /// The type with this name (compared after [`normalize_label`]).
    pub fn get(&self, name: &str) -> Option<&MotionType> {
        self.index
            .get(normalize_label(name).as_str())
            .and_then(|&i| self.types.get(i))
    }

    /// All types, in file order (extra types last).
    pub fn types(&self) -> impl Iterator<Item = &MotionType> {
        self.types.iter()
    }

    /// All groups, in file order.
    pub fn groups(&self) -> impl Iterator<Item = &MotionGroup> {
        self.groups.iter()
    }

    /// The group with this exact name.
    pub fn group(&self, name: &str) -> Option<&MotionGroup> {
        self.groups.iter().find(|g| g.name == name)
    }

    /// The types of one group, in file order.
    pub fn types_in<'a>(&'a self, group: &'a str) -> impl Iterator<Item = &'a MotionType> + 'a {
        self.types.iter().filter(move |t| t.group == group)
    }

    /// Objects the source table names for a type (`play` -> game, guitar); empty when none.
    pub fn objects(&self, name: &str) -> &[String] {
        self.get(name)
            .and_then(|t| self.objects.get(&t.name))
            .map_or(&[], Vec::as_slice)
    }

    /// The name of the type a left/right mirror turns `name` into: its `mirror`, or its own name
    /// when it has no side. `None` for an unknown name.
    pub fn mirror_of(&self, name: &str) -> Option<&str> {
        self.get(name)
            .map(|t| t.mirror.as_deref().unwrap_or(t.name.as_str()))
    }
}

/// One rule of a [`TypeMapConfig`]: labels matching `pattern` map to `type`.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct TypeRule {
    /// A regex, matched case-insensitively against the normalized label (see
    /// [`normalize_label`]); anchor it (`^...$`) unless a prefix is really enough.
    pub pattern: String,
    /// The type's name.
    #[serde(rename = "type")]
    pub r#type: String,
}

/// The config's mapping from dataset labels to types.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct TypeMapConfig {
    /// A taxonomy file replacing the bundled one (relative paths are resolved against the config
    /// file's folder by [`TypeMapConfig::load_taxonomy`]).
    #[serde(default)]
    pub taxonomy: Option<PathBuf>,
    /// Dataset-specific types added to the taxonomy.
    #[serde(default)]
    pub extra: Vec<MotionType>,
    /// Exact labels (compared after [`normalize_label`]) and the type each one is.
    #[serde(default)]
    pub aliases: BTreeMap<String, String>,
    /// Regex rules, tried in order after names and aliases; the first match wins.
    #[serde(default)]
    pub rules: Vec<TypeRule>,
}

impl TypeMapConfig {
    /// The taxonomy this config starts from: the file `taxonomy` names (relative to `base_dir`
    /// when given), else the bundled one. Extra types are added by [`TypeMap::new`].
    pub fn load_taxonomy(&self, base_dir: Option<&Path>) -> Result<Taxonomy, TaxonomyError> {
        match &self.taxonomy {
            None => Taxonomy::bundled(),
            Some(path) => match base_dir {
                Some(base) if path.is_relative() => Taxonomy::from_file(&base.join(path)),
                _ => Taxonomy::from_file(path),
            },
        }
    }
}

/// How [`TypeMap`] reached a type.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[serde(rename_all = "snake_case")]
pub enum MatchKind {
    /// The label is the type's name.
    Name,
    /// An alias names the type.
    Alias,
    /// The rule at this position in `rules` matched.
    Rule(usize),
}

/// Labels sorted into mapped (by type name) and unmapped; nothing is merged or dropped.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Eq, Default)]
pub struct LabelReport {
    /// Type name -> the labels that mapped to it, in input order.
    pub mapped: BTreeMap<String, Vec<String>>,
    /// Labels no name, alias or rule maps, in input order.
    pub unmapped: Vec<String>,
}

impl LabelReport {
    /// How many labels were mapped.
    pub fn mapped_count(&self) -> usize {
        self.mapped.values().map(Vec::len).sum()
    }
}

#[derive(Clone, Debug)]
struct CompiledRule {
    regex: Regex,
    target: usize,
}

/// Maps a dataset's labels to motion types: names, then aliases, then rules.
#[derive(Clone, Debug)]
pub struct TypeMap {
    taxonomy: Taxonomy,
    aliases: HashMap<String, usize>,
    rules: Vec<CompiledRule>,
}

/// Upper bound on a compiled rule, so a config cannot ask for a huge automaton.
const RULE_SIZE_LIMIT: usize = 1 << 20;

impl TypeMap {
    /// Checks that every alias and rule names an existing type and every rule compiles; errors
    /// name the alias or rule and the bad value.
    ///
    /// `config.extra` types the taxonomy does not have yet are added (see
    /// [`Taxonomy::with_extra`]); ones already there with the identical definition (the caller
    /// applied `with_extra` itself) are accepted, a different definition under the same name is a
    /// [`TaxonomyError::DuplicateType`].
    pub fn new(taxonomy: Taxonomy, config: &TypeMapConfig) -> Result<TypeMap, TaxonomyError> {
        let missing: Vec<MotionType> = config
            .extra
            .iter()
            .filter(|e| taxonomy.get(&e.name) != Some(*e))
            .cloned()
            .collect();
        let taxonomy = taxonomy.with_extra(missing)?;
        let mut aliases: HashMap<String, usize> = HashMap::new();
        let mut spelled: HashMap<String, &str> = HashMap::new();
        for (alias, target) in &config.aliases {
            let bad = |fault: AliasFault| TaxonomyError::BadAlias {
                alias: alias.clone(),
                target: target.clone(),
                fault,
            };
            let key = normalize_label(alias);
            if key.is_empty() {
                return Err(bad(AliasFault::Empty));
            }
            let Some(&t) = taxonomy.index.get(normalize_label(target).as_str()) else {
                return Err(bad(AliasFault::NoSuchType));
            };
            if let Some(&own) = taxonomy.index.get(key.as_str())
                && own != t
            {
                return Err(bad(AliasFault::TypeName { label: key }));
            }
            if let Some(other) = spelled.insert(key.clone(), alias) {
                return Err(bad(AliasFault::SameLabel {
                    other: other.to_string(),
                    label: key,
                }));
            }
            aliases.insert(key, t);
        }
        let mut rules = Vec::with_capacity(config.rules.len());
        for (index, rule) in config.rules.iter().enumerate() {
            let bad = |fault: RuleFault| TaxonomyError::BadRule {
                index,
                pattern: rule.pattern.clone(),
                target: rule.r#type.clone(),
                fault,
            };
            let Some(&target) = taxonomy.index.get(normalize_label(&rule.r#type).as_str()) else {
                return Err(bad(RuleFault::NoSuchType));
            };
            let regex = RegexBuilder::new(&rule.pattern)
                .case_insensitive(true)
                .size_limit(RULE_SIZE_LIMIT)
                .build()
                .map_err(|e| bad(RuleFault::Regex(e.to_string())))?;
            rules.push(CompiledRule { regex, target });
        }
        Ok(TypeMap {
            taxonomy,
            aliases,
            rules,
        })
    }

    /// Maps a label: exact type name (case-insensitive, trimmed, `-`/`_` as spaces) -> alias ->
    /// first matching rule; `None` when unmapped. Never guesses beyond that.
    pub fn map(&self, label: &str) -> Option<&MotionType> {
        self.map_with_kind(label).map(|(t, _)| t)
    }

    /// Like [`TypeMap::map`], also saying whether a name, an alias or which rule decided.
    pub fn map_with_kind(&self, label: &str) -> Option<(&MotionType, MatchKind)> {
        let key = normalize_label(label);
        if key.is_empty() {
            return None;
        }
        let (index, kind) = if let Some(&i) = self.taxonomy.index.get(key.as_str()) {
            (i, MatchKind::Name)
        } else if let Some(&i) = self.aliases.get(key.as_str()) {
            (i, MatchKind::Alias)
        } else {
            let (n, rule) = self
                .rules
                .iter()
                .enumerate()
                .find(|(_, r)| r.regex.is_match(&key))?;
            (rule.target, MatchKind::Rule(n))
        };
        self.taxonomy.types.get(index).map(|t| (t, kind))
    }

    /// Maps every label and sorts them into mapped (by type) and unmapped.
    pub fn report<'a>(&self, labels: impl IntoIterator<Item = &'a str>) -> LabelReport {
        let mut report = LabelReport::default();
        for label in labels {
            match self.map(label) {
                Some(t) => report
                    .mapped
                    .entry(t.name.clone())
                    .or_default()
                    .push(label.to_string()),
                None => report.unmapped.push(label.to_string()),
            }
        }
        report
    }

    /// The taxonomy labels are mapped onto (including the config's extra types).
    pub fn taxonomy(&self) -> &Taxonomy {
        &self.taxonomy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = r#"
[[groups]]
name = "turning"
description = "Change the orientation of the body."

[[groups]]
name = "locomotion"

[[types]]
name = "turn left"
group = "turning"
mirror = "turn right"

[[types]]
name = "turn right"
group = "turning"
mirror = "turn left"

[[types]]
name = "walk forward"
group = "locomotion"
locomotion = true
objects = ["floor"]
"#;

    fn small() -> Taxonomy {
        match Taxonomy::from_toml(SMALL, "small.toml") {
            Ok(t) => t,
            Err(e) => panic!("{e}"),
        }
    }

    fn ty(name: &str, group: &str, mirror: Option<&str>) -> MotionType {
        MotionType {
            name: name.into(),
            group: group.into(),
            locomotion: false,
            hand_goal: false,
            scene_dependent: false,
            mirror: mirror.map(str::to_string),
            description: String::new(),
        }
    }

    #[test]
    fn normalizes_labels() {
        assert_eq!(normalize_label("  Walk_Front-LEFT \t"), "walk front left");
        assert_eq!(normalize_label("a  -  b"), "a b");
        assert_eq!(normalize_label(" _- "), "");
    }

    #[test]
    fn parses_flags_with_defaults() {
        let t = small();
        let walk = t.get("walk forward").expect("present");
        assert!(walk.locomotion && !walk.hand_goal && !walk.scene_dependent);
        assert_eq!(walk.mirror, None);
        assert_eq!(t.objects("Walk_Forward"), ["floor".to_string()]);
        assert!(t.objects("turn left").is_empty());
        assert_eq!(t.mirror_of("turn left"), Some("turn right"));
        assert_eq!(t.mirror_of("walk forward"), Some("walk forward"));
        assert_eq!(t.mirror_of("fly"), None);
        assert_eq!(t.types_in("turning").count(), 2);
        assert_eq!(
            t.group("turning").map(|g| g.description.as_str()),
            Some("Change the orientation of the body.")
        );
    }

    #[test]
    fn motion_type_deserializes_with_defaults() {
        let t: MotionType =
            toml::from_str("name = \"side step left\"\ngroup = \"locomotion\"").expect("valid");
        assert_eq!(t, ty("side step left", "locomotion", None));
        let bad: Result<MotionType, _> =
            toml::from_str("name = \"x\"\ngroup = \"y\"\nlocomtion = true");
        assert!(bad.is_err(), "a misspelt flag must not be ignored");
    }

    #[test]
    fn rejects_invalid_files() {
        let cases = [
            (
                SMALL.replace("\"turn right\"\ngroup", "\"turn left\"\ngroup"),
                "turn left",
            ),
            (
                SMALL.replace("group = \"locomotion\"\nloc", "group = \"walking\"\nloc"),
                "walking",
            ),
            (SMALL.replace("mirror = \"turn left\"", ""), "turn right"),
            (
                SMALL.replace("mirror = \"turn right\"", "mirror = \"turn up\""),
                "turn up",
            ),
            (
                SMALL.replace("\"walk forward\"", "\"Walk Forward\""),
                "Walk Forward",
            ),
            (
                SMALL.replace("name = \"locomotion\"", "name = \"turning\""),
                "turning",
            ),
            (format!("{SMALL}\nwhat = 1"), "what"),
        ];
        for (text, needle) in cases {
            match Taxonomy::from_toml(&text, "bad.toml") {
                Ok(_) => panic!("accepted a taxonomy that should name `{needle}`"),
                Err(e) => {
                    let msg = e.to_string();
                    assert!(msg.contains(needle) && msg.contains("bad.toml"), "{msg}");
                }
            }
        }
    }

    #[test]
    fn extra_types_follow_the_same_rules() {
        let t = small()
            .with_extra(vec![
                ty("side step left", "locomotion", Some("side step right")),
                ty("side step right", "locomotion", Some("side step left")),
            ])
            .expect("valid extras");
        assert_eq!(t.mirror_of("side step right"), Some("side step left"));
        let one_sided =
            small().with_extra(vec![ty("side step left", "locomotion", Some("turn left"))]);
        assert!(matches!(one_sided, Err(TaxonomyError::BadMirror { .. })));
        let dup = small().with_extra(vec![ty("turn left", "turning", None)]);
        assert!(
            matches!(dup, Err(TaxonomyError::DuplicateType { ref file, .. }) if file == EXTRA_ORIGIN)
        );
    }

    #[test]
    fn maps_by_name_then_alias_then_first_rule() {
        let config = TypeMapConfig {
            aliases: BTreeMap::from([("Rotate Left".into(), "turn left".into())]),
            rules: vec![
                TypeRule {
                    pattern: "^turn".into(),
                    r#type: "turn right".into(),
                },
                TypeRule {
                    pattern: "left$".into(),
                    r#type: "turn left".into(),
                },
            ],
            ..TypeMapConfig::default()
        };
        let map = TypeMap::new(small(), &config).expect("valid");
        let kind = |l: &str| map.map_with_kind(l).map(|(t, k)| (t.name.clone(), k));
        assert_eq!(
            kind("TURN_LEFT"),
            Some(("turn left".into(), MatchKind::Name))
        );
        assert_eq!(
            kind("rotate-left"),
            Some(("turn left".into(), MatchKind::Alias))
        );
        assert_eq!(
            kind("turn around left"),
            Some(("turn right".into(), MatchKind::Rule(0)))
        );
        assert_eq!(
            kind("Step LEFT"),
            Some(("turn left".into(), MatchKind::Rule(1)))
        );
        assert_eq!(kind("jump"), None);
        assert_eq!(kind("   "), None);
        let report = map.report(["turn left", "jump", "hop", "rotate left"]);
        assert_eq!(report.mapped_count(), 2);
        assert_eq!(report.unmapped, ["jump", "hop"]);
        assert_eq!(report.mapped["turn left"], ["turn left", "rotate left"]);
    }

    #[test]
    fn rejects_bad_aliases_and_rules() {
        let alias = |k: &str, v: &str| TypeMapConfig {
            aliases: BTreeMap::from([(k.into(), v.into())]),
            ..TypeMapConfig::default()
        };
        let err = TypeMap::new(small(), &alias("spin", "spin left")).expect_err("unknown");
        assert!(err.to_string().contains("`spin`") && err.to_string().contains("spin left"));
        let err = TypeMap::new(small(), &alias("turn left", "turn right")).expect_err("shadowed");
        assert!(matches!(err, TaxonomyError::BadAlias { .. }));
        assert!(TypeMap::new(small(), &alias("turn left", "turn left")).is_ok());
        let two = TypeMapConfig {
            aliases: BTreeMap::from([
                ("Spin".into(), "turn left".into()),
                ("spin".into(), "turn right".into()),
            ]),
            ..TypeMapConfig::default()
        };
        assert!(matches!(
            TypeMap::new(small(), &two),
            Err(TaxonomyError::BadAlias { .. })
        ));
        let rule = |p: &str, t: &str| TypeMapConfig {
            rules: vec![TypeRule {
                pattern: p.into(),
                r#type: t.into(),
            }],
            ..TypeMapConfig::default()
        };
        let err = TypeMap::new(small(), &rule("^(turn", "turn left")).expect_err("regex");
        assert!(
            matches!(err, TaxonomyError::BadRule { index: 0, ref pattern, .. } if pattern == "^(turn")
        );
        let err = TypeMap::new(small(), &rule("^turn", "spin")).expect_err("target");
        assert!(err.to_string().contains("spin"));
    }

    #[test]
    fn config_reads_from_toml() {
        let text = r#"
[[extra]]
name = "side step left"
group = "locomotion"
locomotion = true

[aliases]
"walk forwards" = "walk forward"

[[rules]]
pattern = "^turn (to (the )?)?left$"
type = "turn left"
"#;
        let config: TypeMapConfig = toml::from_str(text).expect("valid config");
        let applied = small()
            .with_extra(config.extra.clone())
            .expect("valid extras");
        assert!(
            TypeMap::new(applied, &config).is_ok(),
            "extras applied twice are accepted"
        );
        let mut changed = config.clone();
        changed.extra[0].locomotion = false;
        let applied = small()
            .with_extra(config.extra.clone())
            .expect("valid extras");
        assert!(matches!(
            TypeMap::new(applied, &changed),
            Err(TaxonomyError::DuplicateType { .. })
        ));
        assert_eq!(config.rules[0].r#type, "turn left");
        let map = TypeMap::new(small(), &config).expect("valid");
        assert!(map.map("side-step left").is_some_and(|t| t.locomotion));
        assert_eq!(
            map.map("turn to the left").map(|t| t.name.as_str()),
            Some("turn left")
        );
        let typo: Result<TypeMapConfig, _> = toml::from_str("[[rule]]\npattern = \"x\"");
        assert!(typo.is_err());
    }

    #[test]
    fn bundled_taxonomy_is_valid() {
        let t = Taxonomy::bundled().expect("bundled taxonomy");
        assert!(t.get("walk forward").is_some_and(|t| t.locomotion));
    }

    /// The texts of the name, mirror, alias and rule faults: they must not change.
    #[test]
    fn every_fault_reads_as_it_always_has() {
        let text = |r: Result<Taxonomy, TaxonomyError>| r.map(|_| ()).unwrap_err().to_string();
        let extra = |t: MotionType| text(small().with_extra(vec![t]));
        let blank_group = SMALL.replace("name = \"locomotion\"", "name = \" \"");
        assert_eq!(
            text(Taxonomy::from_toml(&blank_group, "bad.toml")),
            "bad.toml: group name ` ` is not valid: it is empty"
        );
        let cases = [
            (
                ty(" ", "locomotion", None),
                "extra types: type name ` ` is not valid: it is empty",
            ),
            (
                ty("Side  Step", "locomotion", None),
                "extra types: type name `Side  Step` is not valid: write it as `side step` (lowercase words, single spaces)",
            ),
            (
                ty("spin", "turning", Some("spin")),
                "extra types: type `spin` mirrors to `spin`: a type cannot mirror to itself; leave `mirror` out",
            ),
            (
                ty("spin", "turning", Some("spun")),
                "extra types: type `spin` mirrors to `spun`: no type has that name",
            ),
            (
                ty("spin", "turning", Some("walk forward")),
                "extra types: type `spin` mirrors to `walk forward`: not mutual: `walk forward` mirrors to nothing",
            ),
            (
                ty("spin", "turning", Some("turn left")),
                "extra types: type `spin` mirrors to `turn left`: not mutual: `turn left` mirrors to `turn right`",
            ),
        ];
        for (t, want) in cases {
            assert_eq!(extra(t), want);
        }
        let map = |config: TypeMapConfig| TypeMap::new(small(), &config).map(|_| ()).unwrap_err();
        let alias = |pairs: &[(&str, &str)]| TypeMapConfig {
            aliases: pairs
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
            ..TypeMapConfig::default()
        };
        let cases = [
            (
                alias(&[(" _ ", "turn left")]),
                "alias ` _ ` -> `turn left`: the alias is empty",
            ),
            (
                alias(&[("spin", "spin left")]),
                "alias `spin` -> `spin left`: no type has that name",
            ),
            (
                alias(&[("Turn-Left", "turn right")]),
                "alias `Turn-Left` -> `turn right`: `turn left` is itself a type name, which always wins over an alias",
            ),
            (
                alias(&[("Spin", "turn left"), ("spin", "turn right")]),
                "alias `spin` -> `turn right`: same label as alias `Spin` once normalized to `spin`",
            ),
        ];
        for (config, want) in cases {
            let err = map(config);
            assert_eq!(err.to_string(), want);
            assert!(matches!(err, TaxonomyError::BadAlias { .. }), "{err}");
        }
        let rule = |p: &str, t: &str| TypeMapConfig {
            rules: vec![TypeRule {
                pattern: p.into(),
                r#type: t.into(),
            }],
            ..TypeMapConfig::default()
        };
        assert_eq!(
            map(rule("^turn", "spin")).to_string(),
            "rule 0 (`^turn` -> `spin`): no type has that name"
        );
        let err = map(rule("^(turn", "turn left")).to_string();
        assert!(
            err.starts_with(
                "rule 0 (`^(turn` -> `turn left`): not a valid regex: regex parse error:"
            ),
            "{err}"
        );
    }
}
