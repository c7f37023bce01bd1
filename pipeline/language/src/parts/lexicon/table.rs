//! The lexicon's word tables: the meanings a phrase can have (body-part nouns, actions and their
//! strength, objects, face features) in the grammar of `schemas/lexicon.toml`, the word lists
//! that steer the reading, and the file loaded and checked once for the whole run.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::LazyLock;

use serde::Deserialize;

use super::PartSet;
use motionforge_core::motion::BodyPart;

const G: u8 = 1;
pub(super) const T: u8 = 2;
const LA: u8 = 4;
const RA: u8 = 8;
const LL: u8 = 16;
const RL: u8 = 32;
const ARMS: u8 = LA | RA;
const LEGS: u8 = LL | RL;
const ALL: u8 = 63;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Limb {
    Arm,
    Leg,
}

impl Limb {
    pub(super) fn parts(self, side: Side) -> PartSet {
        let (l, r) = match self {
            Limb::Arm => (BodyPart::LeftArm, BodyPart::RightArm),
            Limb::Leg => (BodyPart::LeftLeg, BodyPart::RightLeg),
        };
        match side {
            Side::Left => PartSet::from(l),
            Side::Right => PartSet::from(r),
            Side::Both => PartSet::from_parts(&[l, r]),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Side {
    Left,
    Right,
    Both,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Strength {
    /// Always adds its parts.
    Strong,
    /// Adds its default only when its clause names no moving body part.
    Generic,
    /// Counts only when nothing else in the text does.
    Weak,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    /// A limb noun: `hand` (plural false) or `hands` (plural true).
    Limb {
        limb: Limb,
        plural: bool,
        /// Involved even when a hand reaches it (hands and arms); shoulders and legs are not.
        self_moving: bool,
    },
    /// A torso/global noun with fixed parts; `hip` adds the leg of its side when it has one.
    Trunk { parts: u8, hip: bool },
    /// An action.
    Act {
        strength: Strength,
        limb: Option<Limb>,
        extra: u8,
        /// A verb whose direct object is touched, not moved (`scratch head`).
        contact: bool,
    },
    /// An object a hand would handle.
    Object,
    /// A face feature: never a part.
    Feature,
}

pub(super) const fn strong(extra: u8) -> Kind {
    Kind::Act {
        strength: Strength::Strong,
        limb: None,
        extra,
        contact: false,
    }
}

/// The bundled lexicon (`schemas/lexicon.toml`).
const LEXICON_TOML: &str = include_str!("../../../../../schemas/lexicon.toml");

/// A set of words from the lexicon file.
pub(super) type WordSet = HashSet<&'static str>;

/// The lexicon file as written.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LexiconFile {
    phrases: BTreeMap<String, String>,
    words: WordLists,
    irregular: BTreeMap<String, String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WordLists {
    clause: Vec<String>,
    location: Vec<String>,
    modifiers: Vec<String>,
    act_modifiers: Vec<String>,
    measures: Vec<String>,
    objects: Vec<String>,
    directions: Vec<String>,
    particles: Vec<String>,
    noun_after: Vec<String>,
    postures: Vec<String>,
}

/// Why the lexicon file cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LexiconError {
    /// The file does not parse or has unknown keys.
    #[error("schemas/lexicon.toml: {0}")]
    Parse(#[source] toml::de::Error),
    /// A phrase's meaning is not in the file's grammar.
    #[error("schemas/lexicon.toml: phrase `{phrase}`: {problem}")]
    Meaning {
        /// The phrase.
        phrase: String,
        /// What is wrong with its meaning.
        problem: MeaningProblem,
    },
}

/// What is wrong with a phrase's meaning in `schemas/lexicon.toml`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MeaningProblem {
    /// The meaning has no word.
    #[error("empty meaning")]
    Empty,
    /// The first word is not one of the grammar's meanings.
    #[error(
        "`{0}` is not a meaning (arm, arms, shoulder, shoulders, leg, legs, feature, trunk, strong, generic, weak)"
    )]
    NotAMeaning(String),
    /// A word where the grammar expects a part is not one.
    #[error("`{0}` is not a part (global, torso, arms, legs, all)")]
    NotAPart(String),
}

pub(super) struct Lexicon {
    /// First word of a phrase -> (words, kind), longest first.
    pub(super) by_first: HashMap<&'static str, Vec<(Vec<&'static str>, Kind)>>,
    /// Every word that appears in an action phrase: the targets of lemmatisation.
    pub(super) verbs: WordSet,
    /// One-word body-part and feature nouns.
    pub(super) nouns: WordSet,
    /// Words that join clauses; parts of one clause do not decide for another.
    pub(super) clause: WordSet,
    /// Prepositions after which a part is a place, not a mover.
    pub(super) location: WordSet,
    /// Words allowed between a side (or preposition) and its noun.
    pub(super) modifiers: WordSet,
    /// Words allowed between a side and a limb action (`right front kick`).
    pub(super) act_modifiers: WordSet,
    /// Nouns followed by these are measures (`waist level`).
    pub(super) measures: WordSet,
    /// Things handled with the hands.
    pub(super) objects: WordSet,
    /// Direction words (`face left`).
    pub(super) directions: WordSet,
    /// Adverb particles of phrasal verbs (`lift up`, `shake off`); also what poses a held limb
    /// (`hold left leg up`).
    pub(super) particles: WordSet,
    /// Prepositions after which an action word is a noun (`in a circle`, `across a plank`).
    pub(super) noun_after: WordSet,
    /// Nouns that make an action word before them a posture held (`in fighting pose`).
    pub(super) postures: WordSet,
    /// Irregular forms and their lemma.
    pub(super) irregular: HashMap<&'static str, &'static str>,
}

/// Parts named in a meaning (`global torso`, `arms`, `all`).
fn parts_mask(word: &str) -> Option<u8> {
    Some(match word {
        "global" => G,
        "torso" => T,
        "arms" => ARMS,
        "legs" => LEGS,
        "all" => ALL,
        _ => return None,
    })
}

/// A phrase's meaning, from the grammar described at the top of `schemas/lexicon.toml`.
fn parse_meaning(meaning: &str) -> Result<Kind, MeaningProblem> {
    let words: Vec<&str> = meaning.split_whitespace().collect();
    let limb = |limb, plural, self_moving| Kind::Limb {
        limb,
        plural,
        self_moving,
    };
    let parts_of = |rest: &[&str]| -> Result<u8, MeaningProblem> {
        rest.iter().try_fold(0u8, |acc, w| {
            parts_mask(w)
                .map(|m| acc | m)
                .ok_or_else(|| MeaningProblem::NotAPart(w.to_string()))
        })
    };
    match words.as_slice() {
        ["arm"] => Ok(limb(Limb::Arm, false, true)),
        ["arms"] => Ok(limb(Limb::Arm, true, true)),
        ["shoulder"] => Ok(limb(Limb::Arm, false, false)),
        ["shoulders"] => Ok(limb(Limb::Arm, true, false)),
        ["leg"] => Ok(limb(Limb::Leg, false, false)),
        ["legs"] => Ok(limb(Limb::Leg, true, false)),
        ["feature"] => Ok(Kind::Feature),
        ["trunk", rest @ ..] => {
            let hip = rest.last() == Some(&"hip");
            let rest = if hip { &rest[..rest.len() - 1] } else { rest };
            Ok(Kind::Trunk {
                parts: parts_of(rest)?,
                hip,
            })
        }
        [strength, rest @ ..] => {
            let strength = match *strength {
                "strong" => Strength::Strong,
                "generic" => Strength::Generic,
                "weak" => Strength::Weak,
                other => return Err(MeaningProblem::NotAMeaning(other.to_string())),
            };
            let (limb, rest) = match rest.first() {
                Some(&"arm") => (Some(Limb::Arm), &rest[1..]),
                Some(&"leg") => (Some(Limb::Leg), &rest[1..]),
                _ => (None, rest),
            };
            let (contact, rest) = match rest.first() {
                Some(&"contact") => (true, &rest[1..]),
                _ => (false, rest),
            };
            Ok(Kind::Act {
                strength,
                limb,
                extra: parts_of(rest)?,
                contact,
            })
        }
        [] => Err(MeaningProblem::Empty),
    }
}

fn word_set(words: Vec<String>) -> WordSet {
    words
        .into_iter()
        .map(motionforge_core::base::leak)
        .collect()
}

fn load_lexicon(text: &str) -> Result<Lexicon, LexiconError> {
    let file: LexiconFile = toml::from_str(text).map_err(LexiconError::Parse)?;
    let mut by_first: HashMap<&'static str, Vec<(Vec<&'static str>, Kind)>> = HashMap::new();
    let mut verbs = HashSet::new();
    let mut nouns = HashSet::new();
    for (phrase, meaning) in file.phrases {
        let kind = parse_meaning(&meaning).map_err(|problem| LexiconError::Meaning {
            phrase: phrase.clone(),
            problem,
        })?;
        let phrase = motionforge_core::base::leak(phrase);
        let words: Vec<&'static str> = phrase.split(' ').collect();
        if matches!(kind, Kind::Act { .. }) {
            verbs.extend(words.iter().copied());
        } else if words.len() == 1 {
            nouns.insert(phrase);
        }
        if let Some(first) = words.first() {
            by_first.entry(first).or_default().push((words, kind));
        }
    }
    for list in by_first.values_mut() {
        // Longest first; the phrases come sorted, so equal lengths keep a fixed order.
        list.sort_by_key(|(w, _)| std::cmp::Reverse(w.len()));
    }
    let w = file.words;
    Ok(Lexicon {
        by_first,
        verbs,
        nouns,
        clause: word_set(w.clause),
        location: word_set(w.location),
        modifiers: word_set(w.modifiers),
        act_modifiers: word_set(w.act_modifiers),
        measures: word_set(w.measures),
        objects: word_set(w.objects),
        directions: word_set(w.directions),
        particles: word_set(w.particles),
        noun_after: word_set(w.noun_after),
        postures: word_set(w.postures),
        irregular: file
            .irregular
            .into_iter()
            .map(|(k, v)| {
                (
                    motionforge_core::base::leak(k),
                    motionforge_core::base::leak(v),
                )
            })
            .collect(),
    })
}

static LEX: LazyLock<Result<Lexicon, LexiconError>> = LazyLock::new(|| load_lexicon(LEXICON_TOML));

/// The bundled lexicon, loaded and validated once; `Err` says what is wrong with the file. The
/// build checks it before labelling ([`check_lexicon`]).
pub(super) fn lexicon() -> &'static Lexicon {
    static EMPTY: LazyLock<Lexicon> = LazyLock::new(|| Lexicon {
        by_first: HashMap::new(),
        verbs: HashSet::new(),
        nouns: HashSet::new(),
        clause: HashSet::new(),
        location: HashSet::new(),
        modifiers: HashSet::new(),
        act_modifiers: HashSet::new(),
        measures: HashSet::new(),
        objects: HashSet::new(),
        directions: HashSet::new(),
        particles: HashSet::new(),
        noun_after: HashSet::new(),
        postures: HashSet::new(),
        irregular: HashMap::new(),
    });
    match &*LEX {
        Ok(lexicon) => lexicon,
        Err(_) => &EMPTY,
    }
}

/// Loads and validates the bundled lexicon (`schemas/lexicon.toml`): every phrase's meaning in
/// the file's grammar, every word list present.
pub fn check_lexicon() -> Result<(), LexiconError> {
    match &*LEX {
        Ok(_) => Ok(()),
        Err(e) => Err(e.clone()),
    }
}

#[cfg(test)]
mod lexicon_file_tests {
    use super::*;

    #[test]
    fn the_bundled_lexicon_loads_and_covers_every_list() {
        assert_eq!(check_lexicon(), Ok(()));
        let lex = lexicon();
        assert!(lex.by_first.values().map(Vec::len).sum::<usize>() > 500);
        for (name, set) in [
            ("clause", &lex.clause),
            ("location", &lex.location),
            ("modifiers", &lex.modifiers),
            ("act_modifiers", &lex.act_modifiers),
            ("measures", &lex.measures),
            ("objects", &lex.objects),
            ("directions", &lex.directions),
        ] {
            assert!(!set.is_empty(), "{name}");
        }
        assert_eq!(lex.irregular.get("ran"), Some(&"run"));
    }

    #[test]
    fn meanings_follow_the_grammar_and_errors_name_the_phrase() {
        assert_eq!(
            parse_meaning("strong arm contact"),
            Ok(Kind::Act {
                strength: Strength::Strong,
                limb: Some(Limb::Arm),
                extra: 0,
                contact: true
            })
        );
        assert_eq!(
            parse_meaning("trunk global hip"),
            Ok(Kind::Trunk {
                parts: G,
                hip: true
            })
        );
        assert_eq!(
            parse_meaning("weak torso arms"),
            Ok(Kind::Act {
                strength: Strength::Weak,
                limb: None,
                extra: T | ARMS,
                contact: false
            })
        );
        let bad = LEXICON_TOML.replacen("\"walk\" = ", "\"walk\" = \"strong elbows\" # ", 1);
        match load_lexicon(&bad) {
            Err(err) => {
                assert_eq!(
                    err,
                    LexiconError::Meaning {
                        phrase: "walk".into(),
                        problem: MeaningProblem::NotAPart("elbows".into()),
                    }
                );
                assert_eq!(
                    err.to_string(),
                    "schemas/lexicon.toml: phrase `walk`: `elbows` is not a part (global, torso, \
                     arms, legs, all)"
                );
            }
            Ok(_) => panic!("a meaning with `elbows` loaded"),
        }
        assert_eq!(parse_meaning(" "), Err(MeaningProblem::Empty));
        assert_eq!(MeaningProblem::Empty.to_string(), "empty meaning");
        let run = parse_meaning("run legs").err();
        assert_eq!(run, Some(MeaningProblem::NotAMeaning("run".into())));
        assert_eq!(
            run.map(|p| p.to_string()).unwrap_or_default(),
            "`run` is not a meaning (arm, arms, shoulder, shoulders, leg, legs, feature, trunk, \
             strong, generic, weak)"
        );
        let unknown = format!("{LEXICON_TOML}\n[extra]\nx = 1\n");
        assert!(matches!(
            load_lexicon(&unknown),
            Err(LexiconError::Parse(_))
        ));
    }
}
