//! The embedded part labeller: an action text to SINC's six parts from a lexicon, offline,
//! instant and deterministic. It stands in for the GPT-3 query of SINC section 3.1.
//!
//! # How a text is read
//!
//! 1. **Tokens.** Lowercase words (letters and digits; apostrophes vanish so `arm's` is `arms`).
//!    Verbs are lemmatised against the lexicon (`waving` -> `wave`, `ran` -> `run`); body-part nouns
//!    keep their number (`hand` and `hands` differ). Clauses break at punctuation and at `and`,
//!    `then`, `while`, `before`, `after`, `during`, `when`, `or`, `but`.
//! 2. **Entries.** At each position the longest lexicon phrase wins (`stand up` over `stand`).
//!    An entry is a body-part noun, an action, an object noun or a face feature.
//! 3. **Body-part nouns** (`left hand`, `knees`, `head`, `waist`...). A side word just before the
//!    noun (over `the`, `upper`, `both`, ... ) gives the side; plural or `both` means both sides;
//!    a singular limb with no side (`wave hand`, `one leg`) also means both sides, because the text
//!    does not say which and GPT-3's answers on BABEL's texts do the same. A noun after a location
//!    preposition (`to the head`, `hands on hips`, `in front of chest`) or as the object of a
//!    contact verb (`scratch head`, `hold left leg`) is a *target*: it does not move, the hand that
//!    reaches it does. A particle after a verb is not a place (`lift up left leg`, `shake off
//!    right foot`: the leg is the verb's object and moves), and a held limb posed by a particle
//!    moves itself (`hold left leg up`). Two exceptions, both from how bodies work: a hand, arm, wrist, elbow or
//!    finger is involved even as a target (`touch left hand with right hand` moves both arms to
//!    meet), and a leg after `on` with no hand before it is a support (`stand on left leg`,
//!    `hop on one foot`). A noun followed by `level`, `height`, `width`, ... is a measure
//!    (`waist level`) and ignored. Face features (`face`, `mouth`, `chin`, `ear`...) are never
//!    parts: they are what a hand touches.
//! 4. **Actions** have a strength:
//!    * *strong* actions always add their parts (`walk`: global + both legs; `look`: torso);
//!    * *limb* actions (`wave`, `punch`, `kick`, `throw`, contact verbs such as `grab`) name a limb
//!      but not which one: a moving limb noun in the same clause says which (`wave right hand`,
//!      `kick with left foot`, `tap foot`), else a side word next to the verb (`right front kick`,
//!      `punch left`), else `with the left`, else the side of what an arm action touches
//!      (`scratch right ear`: right arm; a shoulder is reached by the other hand), else both;
//!    * *generic* verbs (`raise`, `lift`, `move`, `bend`, `turn`, `stretch`...) take their parts
//!      from the nouns of their clause and fall back to a default only when the clause has none
//!      (`bend` alone: global + torso; `bend knees`: both legs; `turn left`: global + torso + both
//!      legs; `turn head`: torso; `push`: both arms + torso, `push with right arm`: right arm);
//!    * an action word right after a preposition (`in`, `on`, `at`, `from`, `across`...) is a
//!      noun (`walk in circles`, `walk in hook pattern`, `walk across a plank`), unless it names a
//!      posture held there (`stand in fighting pose`);
//!    * *weak* words (`stand`, `pose`, `exercise`, `talk`) count only when nothing else in the
//!      whole text does.
//! 5. **Objects** (`object`, `phone`, `ball`, `cup`...) mean the hands in a clause with no action
//!    and no body part, and turn a whole-body generic verb into a hand action (`move item`); not
//!    after a location preposition (`sit on chair`).
//! 6. The text's parts are the union over clauses. A text where nothing fires is *unknown*
//!    ([`TextLabel::known`] is `false`) and gets [`UNKNOWN_DEFAULT`], both arms: the most common
//!    answer of GPT-3 on BABEL's 6,518 texts, and the majority on the two parts (the arms) that
//!    GPT-3 marks for more than half of them.
//!
//! Conventions chosen (and where they come from): parts are the ones the action needs, not the
//! ones that may come along (walking swings the arms; SINC's annotators mark such parts
//! "sometimes", which does not count); global (the pelvis: root translation and orientation) comes
//! with every action that moves or turns the whole body or lowers the hips (walk, jump, turn
//! around, sit, kneel, bow, lean); torso comes with looking, nodding, bending, leaning, bowing and
//! twisting, not with arm actions. Defaults were checked against GPT-3's answers on BABEL's texts
//! (training data); the manual gold labels were not used to build the lexicon (see
//! `docs/part-labels.md`).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::LazyLock;

use serde::Deserialize;

use super::PartSet;
use motionforge_core::motion::BodyPart;

/// What an unknown text gets: both arms (see the module doc).
pub const UNKNOWN_DEFAULT: PartSet = PartSet::ARMS;

/// The embedded labeller's answer for one text.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TextLabel {
    /// The parts involved.
    pub parts: PartSet,
    /// The lexicon entries that contributed, in text order (`walk`, `left hand`, ...).
    pub matched: Vec<String>,
    /// `false` when no entry fired and `parts` is [`UNKNOWN_DEFAULT`].
    pub known: bool,
}

const G: u8 = 1;
const T: u8 = 2;
const LA: u8 = 4;
const RA: u8 = 8;
const LL: u8 = 16;
const RL: u8 = 32;
const ARMS: u8 = LA | RA;
const LEGS: u8 = LL | RL;
const ALL: u8 = 63;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Limb {
    Arm,
    Leg,
}

impl Limb {
    fn parts(self, side: Side) -> PartSet {
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
enum Side {
    Left,
    Right,
    Both,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Strength {
    /// Always adds its parts.
    Strong,
    /// Adds its default only when its clause names no moving body part.
    Generic,
    /// Counts only when nothing else in the text does.
    Weak,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
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

const fn strong(extra: u8) -> Kind {
    Kind::Act {
        strength: Strength::Strong,
        limb: None,
        extra,
        contact: false,
    }
}

/// The bundled lexicon (`schemas/lexicon.toml`).
const LEXICON_TOML: &str = include_str!("../../../../schemas/lexicon.toml");

/// A set of words from the lexicon file.
type WordSet = HashSet<&'static str>;

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
    #[error("schemas/lexicon.toml: phrase `{phrase}`: {message}")]
    Meaning {
        /// The phrase.
        phrase: String,
        /// What is wrong.
        message: String,
    },
}

struct Lexicon {
    /// First word of a phrase -> (words, kind), longest first.
    by_first: HashMap<&'static str, Vec<(Vec<&'static str>, Kind)>>,
    /// Every word that appears in an action phrase: the targets of lemmatisation.
    verbs: WordSet,
    /// One-word body-part and feature nouns.
    nouns: WordSet,
    /// Words that join clauses; parts of one clause do not decide for another.
    clause: WordSet,
    /// Prepositions after which a part is a place, not a mover.
    location: WordSet,
    /// Words allowed between a side (or preposition) and its noun.
    modifiers: WordSet,
    /// Words allowed between a side and a limb action (`right front kick`).
    act_modifiers: WordSet,
    /// Nouns followed by these are measures (`waist level`).
    measures: WordSet,
    /// Things handled with the hands.
    objects: WordSet,
    /// Direction words (`face left`).
    directions: WordSet,
    /// Adverb particles of phrasal verbs (`lift up`, `shake off`); also what poses a held limb
    /// (`hold left leg up`).
    particles: WordSet,
    /// Prepositions after which an action word is a noun (`in a circle`, `across a plank`).
    noun_after: WordSet,
    /// Nouns that make an action word before them a posture held (`in fighting pose`).
    postures: WordSet,
    /// Irregular forms and their lemma.
    irregular: HashMap<&'static str, &'static str>,
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
fn parse_meaning(meaning: &str) -> Result<Kind, String> {
    let words: Vec<&str> = meaning.split_whitespace().collect();
    let limb = |limb, plural, self_moving| Kind::Limb {
        limb,
        plural,
        self_moving,
    };
    let parts_of = |rest: &[&str]| -> Result<u8, String> {
        rest.iter().try_fold(0u8, |acc, w| {
            parts_mask(w)
                .map(|m| acc | m)
                .ok_or_else(|| format!("`{w}` is not a part (global, torso, arms, legs, all)"))
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
                other => {
                    return Err(format!(
                        "`{other}` is not a meaning (arm, arms, shoulder, shoulders, leg, legs, feature, trunk, strong, generic, weak)"
                    ));
                }
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
        [] => Err("empty meaning".into()),
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
        let kind = parse_meaning(&meaning).map_err(|message| LexiconError::Meaning {
            phrase: phrase.clone(),
            message,
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
fn lexicon() -> &'static Lexicon {
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

/// The lemma of a word for matching actions: irregular forms, then suffix stripping until a known
/// action word comes out; other words stay as they are.
fn lemma(word: &str) -> String {
    if let Some(l) = lexicon().irregular.get(word) {
        return (*l).to_string();
    }
    let lex = lexicon();
    // Nouns keep their number (`hands` is not `hand`), and known verbs are their own lemma.
    if lex.verbs.contains(word) || lex.nouns.contains(word) {
        return word.to_string();
    }
    let mut candidates: Vec<String> = Vec::new();
    for (suffix, add) in [
        ("ing", ""),
        ("ing", "e"),
        ("ies", "y"),
        ("ied", "y"),
        ("es", ""),
        ("s", ""),
        ("ed", ""),
        ("ed", "e"),
        ("d", ""),
    ] {
        if let Some(stem) = word.strip_suffix(suffix)
            && stem.len() >= 2
        {
            candidates.push(format!("{stem}{add}"));
            // running -> run, stepped -> step: a doubled final consonant.
            let b = stem.as_bytes();
            if add.is_empty() && b.len() >= 3 && b[b.len() - 1] == b[b.len() - 2] {
                candidates.push(stem[..stem.len() - 1].to_string());
            }
        }
    }
    candidates
        .into_iter()
        .find(|c| lex.verbs.contains(c.as_str()))
        .unwrap_or_else(|| word.to_string())
}

#[derive(Debug, Clone)]
struct Token {
    raw: String,
    lemma: String,
    clause: usize,
}

fn tokenize(text: &str) -> Vec<Token> {
    let mut tokens = Vec::new();
    let mut clause = 0;
    let mut word = String::new();
    for c in text.chars().flat_map(char::to_lowercase) {
        if c.is_alphanumeric() {
            word.push(c);
        } else if c == '\'' || c == '’' {
            // `arm's` -> `arms`
        } else {
            push_word(&mut word, &mut tokens, &mut clause);
            if matches!(c, ',' | ';' | '.' | '!' | '?' | '(' | ')' | '/' | ':') {
                clause += 1;
            }
        }
    }
    push_word(&mut word, &mut tokens, &mut clause);
    tokens
}

fn push_word(word: &mut String, tokens: &mut Vec<Token>, clause: &mut usize) {
    if word.is_empty() {
        return;
    }
    let raw = std::mem::take(word);
    if lexicon().clause.contains(raw.as_str()) {
        *clause += 1;
    }
    // Irregular forms may expand to two words (`tpose` -> `t pose`).
    let l = lemma(&raw);
    let mut parts = l.split(' ');
    let first = parts.next().unwrap_or_default().to_string();
    tokens.push(Token {
        raw: raw.clone(),
        lemma: first,
        clause: *clause,
    });
    for extra in parts {
        tokens.push(Token {
            raw: extra.to_string(),
            lemma: extra.to_string(),
            clause: *clause,
        });
    }
}

/// One lexicon hit.
#[derive(Debug, Clone)]
struct Hit {
    /// First token.
    start: usize,
    /// One past the last token.
    end: usize,
    kind: Kind,
    phrase: String,
}

fn find_hits(tokens: &[Token]) -> Vec<Hit> {
    let lex = lexicon();
    let mut hits = Vec::new();
    let mut i = 0;
    while i < tokens.len() {
        let mut best: Option<(usize, Kind, String)> = None;
        for key in [tokens[i].raw.as_str(), tokens[i].lemma.as_str()] {
            let Some(list) = lex.by_first.get(key) else {
                continue;
            };
            for (words, kind) in list {
                let n = words.len();
                if i + n > tokens.len() || best.as_ref().is_some_and(|(m, _, _)| *m >= n) {
                    continue;
                }
                let fits = words.iter().enumerate().all(|(k, w)| {
                    let t = &tokens[i + k];
                    t.raw == *w || t.lemma == *w
                });
                // A phrase may not straddle clauses (`walk and turn` is two).
                let same_clause = tokens[i..i + n]
                    .iter()
                    .all(|t| t.clause == tokens[i].clause);
                if fits && same_clause {
                    best = Some((n, *kind, words.join(" ")));
                }
            }
        }
        if let Some((n, kind, phrase)) = best {
            hits.push(Hit {
                start: i,
                end: i + n,
                kind,
                phrase,
            });
            i += n;
        } else {
            if lex.objects.contains(tokens[i].raw.as_str()) {
                hits.push(Hit {
                    start: i,
                    end: i + 1,
                    kind: Kind::Object,
                    phrase: tokens[i].raw.clone(),
                });
            }
            i += 1;
        }
    }
    reinterpret(tokens, &mut hits);
    hits
}

/// Words whose sense depends on their neighbours.
fn reinterpret(tokens: &[Token], hits: &mut Vec<Hit>) {
    let raw = |i: usize| tokens.get(i).map(|t| t.raw.as_str()).unwrap_or("");
    for hit in hits.iter_mut() {
        let prev = if hit.start > 0 {
            raw(hit.start - 1)
        } else {
            ""
        };
        let next = raw(hit.end);
        match hit.phrase.as_str() {
            // `face left`, `face to the wall`, `about face`: turning to face is the torso (SINC's
            // own few-shot example "face to the left" -> torso, neck).
            "face"
                if (lexicon().directions.contains(next)
                    && !lexicon().directions.contains(prev))
                    || prev == "about" =>
            {
                hit.kind = strong(T);
            }
            // `watch` the noun (wrist watch, check watch, look at watch) is an object.
            "watch"
                if matches!(
                    prev,
                    "wrist" | "at" | "check" | "checks" | "the" | "a" | "his" | "her" | "on"
                ) || next == "on" =>
            {
                hit.kind = Kind::Object;
            }
            _ => {}
        }
    }
    let mut keep = vec![true; hits.len()];
    for k in 0..hits.len() {
        let hit = &hits[k];
        // `in circles`, `in place`, `walk in hook pattern`, `across a plank`, `on the fight`: an
        // action word after a preposition is a noun (a place, a path's shape, a thing), not the
        // action.
        if matches!(hit.kind, Kind::Act { .. }) {
            let mut j = hit.start;
            while j > 0 && matches!(raw(j - 1), "a" | "an" | "the" | "small" | "big" | "large") {
                j -= 1;
            }
            let posture = [raw(hit.end - 1), raw(hit.end)]
                .iter()
                .any(|w| lexicon().postures.contains(w));
            if j > 0 && lexicon().noun_after.contains(raw(j - 1)) && !posture {
                keep[k] = false;
            }
        }
        // `take a step`, `take two steps`: the step is the action, not taking.
        if hit.phrase == "take"
            && hits[k + 1..].iter().any(|h| {
                h.phrase == "step"
                    && h.start <= hit.end + 3
                    && tokens[h.start].clause == tokens[hit.start].clause
            })
        {
            keep[k] = false;
        }
    }
    let mut k = 0;
    hits.retain(|_| {
        k += 1;
        keep[k - 1]
    });
}

/// Side named by the words just before `start` (over `skip` words), if any. `left and right
/// hands` looks past the conjunction, which otherwise ends a clause.
fn side_before(tokens: &[Token], start: usize, skip: &WordSet) -> Option<Side> {
    let mut left = false;
    let mut right = false;
    let mut both = false;
    let mut clause = tokens.get(start).map(|t| t.clause);
    let mut j = start;
    while j > 0 {
        j -= 1;
        let w = tokens[j].raw.as_str();
        if matches!(w, "and" | "or") {
            let side_before_it = j > 0 && matches!(tokens[j - 1].raw.as_str(), "left" | "right");
            if (left || right) && side_before_it {
                clause = Some(tokens[j - 1].clause);
                continue;
            }
            break;
        }
        if Some(tokens[j].clause) != clause {
            break;
        }
        match w {
            "left" => left = true,
            "right" => right = true,
            "both" | "two" | "each" | "either" | "one" | "other" | "opposite" | "single" => {
                both = true
            }
            _ if skip.contains(&w) => {}
            _ => break,
        }
    }
    match (left, right, both) {
        (true, true, _) => Some(Side::Both),
        (true, false, false) => Some(Side::Left),
        (false, true, false) => Some(Side::Right),
        (_, _, true) => Some(Side::Both),
        _ => None,
    }
}

/// Index of the first token before the noun phrase that ends at `start` (skipping modifiers
/// and sides), or `None` at the start of the text.
fn word_before_phrase(tokens: &[Token], start: usize) -> Option<usize> {
    let mut j = start;
    while j > 0 {
        j -= 1;
        let w = tokens[j].raw.as_str();
        if !lexicon().modifiers.contains(w) {
            return Some(j);
        }
    }
    None
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Moving,
    Target,
    Ignored,
}

/// Labels an action text with SINC's six parts (see the module doc for the rules).
///
/// ```
/// use motionforge_language::parts::lexicon::label_text;
///
/// assert_eq!(label_text("walk forward").parts.to_string(), "global, left_leg, right_leg");
/// assert_eq!(label_text("wave with left hand").parts.to_string(), "left_arm");
/// assert_eq!(label_text("right front kick").parts.to_string(), "right_leg");
/// assert_eq!(label_text("scratch head").parts.to_string(), "left_arm, right_arm");
/// assert_eq!(label_text("look to the right").parts.to_string(), "torso");
/// let unknown = label_text("xyzzy");
/// assert!(!unknown.known);
/// ```
pub fn label_text(text: &str) -> TextLabel {
    let tokens = tokenize(text);
    let hits = find_hits(&tokens);
    let clauses = tokens.last().map(|t| t.clause + 1).unwrap_or(0);
    let roles = noun_roles(&tokens, &hits, clauses);
    let mut label = Labelling::default();
    for clause in 0..clauses {
        let in_clause: Vec<usize> = (0..hits.len())
            .filter(|&k| tokens[hits[k].start].clause == clause)
            .collect();
        let words = ClauseWords {
            tokens: &tokens,
            hits: &hits,
            roles: &roles,
            in_clause: &in_clause,
        };
        words.label(clause, &mut label);
    }
    label.finish()
}

/// The role of each hit: a part noun moves or is a target (touched, pointed at); every other hit
/// is ignored here.
fn noun_roles(tokens: &[Token], hits: &[Hit], clauses: usize) -> Vec<Role> {
    let mut roles = vec![Role::Ignored; hits.len()];
    let mut previous_part_is_arm = vec![false; clauses];
    for (k, hit) in hits.iter().enumerate() {
        let clause = tokens[hit.start].clause;
        let is_noun = matches!(hit.kind, Kind::Limb { .. } | Kind::Trunk { .. });
        if !is_noun {
            continue;
        }
        let next = tokens.get(hit.end).map(|t| t.raw.as_str()).unwrap_or("");
        if lexicon().measures.contains(next) {
            roles[k] = Role::Ignored;
            continue;
        }
        let target = is_target(tokens, hits, hit, next, previous_part_is_arm[clause]);
        roles[k] = match hit.kind {
            Kind::Limb {
                self_moving: true, ..
            } => Role::Moving,
            _ if target => Role::Target,
            _ => Role::Moving,
        };
        if let Kind::Limb { limb, .. } = hit.kind {
            previous_part_is_arm[clause] = limb == Limb::Arm;
        }
    }
    roles
}

/// Whether a part noun is touched or pointed at rather than moved: the object of a contact
/// verb, or after a location word, but not a leg stood on (`on the left leg`) unless an arm
/// came just before in the clause.
fn is_target(tokens: &[Token], hits: &[Hit], hit: &Hit, next: &str, after_arm: bool) -> bool {
    let clause = tokens[hit.start].clause;
    let before = word_before_phrase(tokens, hit.start)
        .filter(|&j| tokens[j].clause == clause)
        .map(|j| (tokens[j].raw.as_str(), j));
    // The verb this noun is the object of: the action just before it, or before a particle
    // (`lift up left leg`, `shake off right foot`), which then is not a place.
    let verb = before.and_then(|(w, j)| {
        hits.iter().find(|h| {
            matches!(h.kind, Kind::Act { .. })
                && (h.end == j + 1 || (h.end == j && lexicon().particles.contains(w)))
        })
    });
    // `hold left leg up`: a limb held in a pose moves itself; `hold left leg` is touched.
    let posed = lexicon().particles.contains(next);
    let after_contact = !posed
        && verb.is_some_and(|h| {
            matches!(h.kind, Kind::Act { contact: true, .. })
                && before.is_some_and(|(_, j)| h.end == j + 1)
        });
    let after_location =
        verb.is_none() && before.is_some_and(|(w, _)| lexicon().location.contains(w));
    let support = before.is_some_and(|(w, _)| w == "on" || w == "onto")
        && matches!(
            hit.kind,
            Kind::Limb {
                limb: Limb::Leg,
                ..
            }
        )
        && !after_arm;
    (after_contact || after_location) && !support
}

/// The parts a text's clauses add up to, with the phrases that gave them; weak actions' parts
/// are kept apart and used only for a text with nothing else.
#[derive(Default)]
struct Labelling {
    parts: PartSet,
    matched: Vec<String>,
    weak: PartSet,
    weak_matched: Vec<String>,
}

impl Labelling {
    fn add(&mut self, set: PartSet, name: &str) {
        add(set, name, &mut self.matched, &mut self.parts);
    }

    fn finish(self) -> TextLabel {
        let Labelling {
            mut parts,
            mut matched,
            weak,
            weak_matched,
        } = self;
        if parts.is_empty() && !weak.is_empty() {
            parts = weak;
            matched = weak_matched;
        }
        let known = !parts.is_empty();
        TextLabel {
            parts: if known { parts } else { UNKNOWN_DEFAULT },
            matched,
            known,
        }
    }
}

/// What moved in a clause so far: its actions' limbs depend on it.
#[derive(Default, Clone, Copy)]
struct Moving {
    /// A limb noun moves (`raise left arm`).
    limb: bool,
    /// Any part noun moves.
    any: bool,
}

/// One clause of a text: its tokens and hits, with the hits' roles, and which hits are in it.
struct ClauseWords<'a> {
    tokens: &'a [Token],
    hits: &'a [Hit],
    roles: &'a [Role],
    /// Indices into `hits` of the clause's hits.
    in_clause: &'a [usize],
}

impl ClauseWords<'_> {
    /// Adds the clause's parts: its moving part nouns, then its actions, then a handled object
    /// when nothing else acted.
    fn label(&self, clause: usize, label: &mut Labelling) {
        let sides = Sides {
            instrument: self.instrument_side(clause),
            target: self.target_side(),
        };
        let moving = self.add_moving_nouns(label);
        let object = self.handled_object();
        let acted = self.add_actions(label, moving, object, sides);
        if !acted
            && !moving.any
            && let Some(k) = object
        {
            let set = Limb::Arm.parts(sides.instrument.unwrap_or(Side::Both));
            label.add(set, &self.hits[k].phrase);
        }
    }

    /// `scratch right ear`, `touch left shoulder`: with no hand named, the target's side says
    /// which hand; the same side, except for a shoulder, which the other hand reaches.
    fn target_side(&self) -> Option<Side> {
        let tokens = self.tokens;
        let mut target_side: Option<Side> = None;
        for &k in self.in_clause {
            let hit = &self.hits[k];
            let shoulder = match hit.kind {
                Kind::Feature => false,
                Kind::Limb {
                    self_moving: false,
                    limb: Limb::Arm,
                    ..
                } if self.roles[k] == Role::Target => true,
                Kind::Limb { .. } | Kind::Trunk { .. } if self.roles[k] == Role::Target => false,
                _ => continue,
            };
            let side = side_before(tokens, hit.start, &lexicon().modifiers).or_else(|| {
                // `right side of face`
                let j = word_before_phrase(tokens, hit.start)?;
                (j >= 1 && tokens[j].raw == "of" && tokens[j - 1].raw == "side")
                    .then(|| side_before(tokens, j - 1, &lexicon().modifiers))
                    .flatten()
            });
            let side = match (side, shoulder) {
                (Some(Side::Left), true) => Side::Right,
                (Some(Side::Right), true) => Side::Left,
                (Some(s), _) => s,
                (None, _) => continue,
            };
            target_side = match target_side {
                Some(t) if t != side => Some(Side::Both),
                _ => Some(side),
            };
        }
        target_side
    }

    /// "with the left" / "use the right": an instrument side for the clause's limb action (the
    /// last one the clause names; not one followed by a noun, which takes the side).
    fn instrument_side(&self, clause: usize) -> Option<Side> {
        let tokens = self.tokens;
        let mut instrument_side: Option<Side> = None;
        for (i, t) in tokens.iter().enumerate() {
            if t.clause != clause || !matches!(t.raw.as_str(), "with" | "use" | "using") {
                continue;
            }
            let mut j = i + 1;
            while j < tokens.len() && matches!(tokens[j].raw.as_str(), "the" | "his" | "her") {
                j += 1;
            }
            let side_word = tokens.get(j).map(|t| t.raw.as_str());
            let then_noun = self.hits.iter().any(|h| h.start == j + 1);
            if !then_noun {
                instrument_side = match side_word {
                    Some("left") => Some(Side::Left),
                    Some("right") => Some(Side::Right),
                    Some("both") => Some(Side::Both),
                    _ => instrument_side,
                };
            }
        }
        instrument_side
    }

    /// Adds the clause's moving part nouns, each with its side.
    fn add_moving_nouns(&self, label: &mut Labelling) -> Moving {
        let tokens = self.tokens;
        let mut moving = Moving::default();
        for &k in self.in_clause {
            let hit = &self.hits[k];
            if self.roles[k] != Role::Moving {
                continue;
            }
            match hit.kind {
                Kind::Limb { limb, plural, .. } => {
                    let side = if plural {
                        Side::Both
                    } else {
                        side_before(tokens, hit.start, &lexicon().modifiers).unwrap_or(Side::Both)
                    };
                    let name = side_name(side, plural, &hit.phrase);
                    label.add(limb.parts(side), &name);
                    moving.limb = true;
                    moving.any = true;
                }
                Kind::Trunk { parts: p, hip } => {
                    let mut set = PartSet(p);
                    let mut name = hit.phrase.clone();
                    if hip && let Some(side) = side_before(tokens, hit.start, &lexicon().modifiers)
                    {
                        set |= Limb::Leg.parts(side);
                        name = side_name(side, false, &hit.phrase);
                    }
                    label.add(set, &name);
                    moving.any = true;
                }
                _ => {}
            }
        }
        moving
    }

    /// An object handled in the clause (`move item`, `roll the ball`), not a place: a generic
    /// verb then means the hands, not its whole-body default.
    fn handled_object(&self) -> Option<usize> {
        self.in_clause.iter().copied().find(|&k| {
            self.hits[k].kind == Kind::Object
                && word_before_phrase(self.tokens, self.hits[k].start)
                    .is_none_or(|j| !lexicon().location.contains(self.tokens[j].raw.as_str()))
        })
    }

    /// Adds the clause's actions by strength; true when a strong or generic one acted.
    fn add_actions(
        &self,
        label: &mut Labelling,
        moving: Moving,
        object: Option<usize>,
        sides: Sides,
    ) -> bool {
        let mut acted = false;
        for &k in self.in_clause {
            let hit = &self.hits[k];
            let Kind::Act {
                strength,
                limb,
                extra,
                ..
            } = hit.kind
            else {
                continue;
            };
            let limb_parts =
                |absorbed: bool| self.action_limb_parts(hit, limb, extra, absorbed, sides);
            match strength {
                Strength::Strong => {
                    let set = PartSet(extra) | limb_parts(moving.limb);
                    label.add(set, &hit.phrase);
                    acted = true;
                }
                Strength::Generic => {
                    if !moving.any && object.is_some() && limb.is_none() {
                        let side = sides.instrument.unwrap_or(Side::Both);
                        label.add(Limb::Arm.parts(side), &hit.phrase);
                    } else if !moving.any {
                        let set = PartSet(extra) | limb_parts(false);
                        label.add(set, &hit.phrase);
                    }
                    acted = true;
                }
                Strength::Weak => {
                    label.weak |= PartSet(extra) | limb_parts(moving.limb);
                    if !label.weak_matched.contains(&hit.phrase) {
                        label.weak_matched.push(hit.phrase.clone());
                    }
                }
            }
        }
        acted
    }

    /// The limb parts of an action on a limb, on its side; none when a moving limb noun of the
    /// clause already took them (`absorbed`) or the action names no limb.
    fn action_limb_parts(
        &self,
        hit: &Hit,
        limb: Option<Limb>,
        extra: u8,
        absorbed: bool,
        sides: Sides,
    ) -> PartSet {
        match limb {
            Some(l) if !absorbed => {
                // A side after a locomotion-like limb action (`hop right`) is a direction, after
                // a pure limb action (`kick right`) the limb.
                let after = if extra == 0 {
                    side_after(self.tokens, self.hits, hit.end)
                } else {
                    None
                };
                let side = side_before(self.tokens, hit.start, &lexicon().act_modifiers)
                    .or(after)
                    .or(sides.instrument)
                    .or(if l == Limb::Arm { sides.target } else { None })
                    .unwrap_or(Side::Both);
                l.parts(side)
            }
            _ => PartSet::EMPTY,
        }
    }
}

/// The sides a clause gives its limb actions that name none themselves.
#[derive(Clone, Copy)]
struct Sides {
    /// From "with the left", "use the right".
    instrument: Option<Side>,
    /// From a touched part's side (`scratch right ear`).
    target: Option<Side>,
}

/// A side word right after a limb action that ends its clause or precedes no noun: `kick right`,
/// `punch left`, but not `kick to the right` or `wave right hand` (the noun takes it).
fn side_after(tokens: &[Token], hits: &[Hit], end: usize) -> Option<Side> {
    let t = tokens.get(end)?;
    let side = match t.raw.as_str() {
        "left" => Side::Left,
        "right" => Side::Right,
        _ => return None,
    };
    let next_is_noun = hits
        .iter()
        .any(|h| h.start == end + 1 && !matches!(h.kind, Kind::Act { .. }));
    let next_same_clause = tokens.get(end + 1).is_some_and(|n| n.clause == t.clause);
    let next = tokens.get(end + 1).map(|n| n.raw.as_str()).unwrap_or("");
    if next_is_noun || (next_same_clause && matches!(next, "side" | "of")) {
        return None;
    }
    Some(side)
}

fn add(set: PartSet, name: &str, matched: &mut Vec<String>, parts: &mut PartSet) {
    *parts |= set;
    if !matched.iter().any(|m| m == name) {
        matched.push(name.to_string());
    }
}

fn side_name(side: Side, plural: bool, phrase: &str) -> String {
    match (side, plural) {
        (_, true) => phrase.to_string(),
        (Side::Left, false) => format!("left {phrase}"),
        (Side::Right, false) => format!("right {phrase}"),
        (Side::Both, false) => phrase.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parts(text: &str) -> String {
        label_text(text).parts.to_string()
    }

    #[test]
    fn lemmas() {
        assert_eq!(lemma("waving"), "wave");
        assert_eq!(lemma("running"), "run");
        assert_eq!(lemma("walks"), "walk");
        assert_eq!(lemma("stepped"), "step");
        assert_eq!(lemma("ran"), "run");
        assert_eq!(lemma("hands"), "hands");
    }

    #[test]
    fn locomotion_and_direction_words() {
        assert_eq!(parts("walk to the left"), "global, left_leg, right_leg");
        assert_eq!(parts("Running"), "global, left_leg, right_leg");
        assert_eq!(parts("turn around"), "global, torso, left_leg, right_leg");
    }

    #[test]
    fn sides_bind_to_nouns_and_limb_actions() {
        assert_eq!(parts("raise right hand"), "right_arm");
        assert_eq!(parts("wave"), "left_arm, right_arm");
        assert_eq!(parts("kick right"), "right_leg");
        assert_eq!(parts("kick to the right"), "left_leg, right_leg");
        assert_eq!(parts("hop on left foot"), "global, left_leg");
        assert_eq!(parts("throw with the left"), "left_arm");
        assert_eq!(parts("left and right hands up"), "left_arm, right_arm");
    }

    #[test]
    fn targets_do_not_move() {
        assert_eq!(parts("hands on hips"), "left_arm, right_arm");
        assert_eq!(parts("touch left knee with right hand"), "right_arm");
        assert_eq!(parts("raise right hand to mouth"), "right_arm");
        assert_eq!(parts("look over right shoulder"), "torso");
        assert_eq!(parts("bend at the waist"), "global, torso");
        assert_eq!(parts("stand on left leg"), "left_leg");
        assert_eq!(parts("place object at waist level"), "left_arm, right_arm");
    }

    /// The failure classes found on BABEL's texts (docs/part-labels.md), each on real texts.
    #[test]
    fn failure_classes() {
        // A limb as the object of a hand verb moves itself; it is not the hand doing it.
        assert_eq!(parts("lift up right foot"), "right_leg");
        assert_eq!(parts("shake off left leg"), "left_leg");
        assert_eq!(parts("hold right leg up"), "right_leg");
        assert_eq!(parts("reach for right foot"), "right_arm");
        assert_eq!(parts("stand while hold leg"), "left_arm, right_arm");
        // A noun in a locative phrase is not the action.
        assert_eq!(
            parts("walk forward in hook pattern"),
            "global, left_leg, right_leg"
        );
        assert_eq!(parts("walk across a plank"), "global, left_leg, right_leg");
        assert_eq!(
            parts("stand in fighting pose"),
            "global, torso, left_arm, right_arm, left_leg, right_leg"
        );
        // Whole-body verbs whose trunk involvement is implicit.
        assert_eq!(parts("spin around"), "global, torso, left_leg, right_leg");
        assert_eq!(
            parts("walk 90 degrees left"),
            "global, torso, left_leg, right_leg"
        );
        assert_eq!(parts("stagger back"), "global, torso, left_leg, right_leg");
        assert_eq!(parts("push object forward"), "torso, left_arm, right_arm");
        assert_eq!(parts("push with right arm"), "right_arm");
        assert_eq!(parts("rotate arms inward"), "left_arm, right_arm");
    }

    #[test]
    fn clauses_combine() {
        assert_eq!(
            parts("walk forward while waving right hand"),
            "global, right_arm, left_leg, right_leg"
        );
        assert_eq!(parts("turn head left"), "torso");
    }

    #[test]
    fn unknown_gets_the_default_and_a_flag() {
        let l = label_text("");
        assert!(!l.known);
        assert_eq!(l.parts, UNKNOWN_DEFAULT);
        assert!(l.matched.is_empty());
        assert!(label_text("stand").known);
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
            Err(LexiconError::Meaning { phrase, message }) => {
                assert_eq!(phrase, "walk");
                assert!(message.contains("`elbows` is not a part"), "{message}");
            }
            other => panic!("{:?}", other.err()),
        }
        let unknown = format!("{LEXICON_TOML}\n[extra]\nx = 1\n");
        assert!(matches!(
            load_lexicon(&unknown),
            Err(LexiconError::Parse(_))
        ));
    }
}
