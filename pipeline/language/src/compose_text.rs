//! Text for synthetic simultaneous-action pairs (SINC-style spatial composition).
//!
//! SINC pairs two motions that use disjoint body parts and joins their two action texts with a
//! conjunction (`rule_based_concat`). Its gerund step appends "ing" to the second spaCy VERB token,
//! which writes "waveing" and "siting". This module builds the same five conjunctions with English
//! spelling rules instead, and treats phrases that do not start with a verb explicitly.
//!
//! # Phrase kinds
//!
//! Every input phrase is read as one of three [`PhraseKind`]s:
//!
//! * [`PhraseKind::Verbal`]: starts with a verb, possibly after a subject ("a person walks",
//!   "he is waving", "to run") and/or adverbs ("carefully walk forward"). Third-person forms are
//!   recognised ("steps forward" → lemma "step"), as is an already-gerund lead ("walking").
//! * [`PhraseKind::BodyState`]: starts with a body-part subject and says what that part does or
//!   where it is ("left arm up", "hands on hips", "right hand touch ground", "palms face up").
//! * [`PhraseKind::Nominal`]: anything else, read as the name of an action: "t pose", "slow walk",
//!   "golf swing", "push ups", "back flip", "right hand wave" (a body part followed by a verb that
//!   ends the phrase names the movement, it does not describe an ongoing one).
//!
//! # Renderings
//!
//! | kind        | base slot              | gerund slot                 | `during` slot                     |
//! |-------------|------------------------|-----------------------------|-----------------------------------|
//! | `Verbal`    | `walk forward`         | `walking forward`           | `during walking forward`          |
//! | `BodyState` | `keep left arm up`     | `keeping left arm up`       | `with left arm up throughout`     |
//! | `Nominal`   | `do t pose`            | `doing t pose`              | `during t pose`                   |
//!
//! The base slot of a verbal phrase drops a leading subject and uses the lemma of its verbs
//! ("a person walks" → "walk"). Body-state phrases get their verb in -ing form ("right hand touch
//! ground" → "keep right hand touching ground"). Articles are never added: real labels are
//! telegraphic ("kick ball", "hold object"), so "do t pose" stays in the same register, and guessing
//! "a"/"an"/none for plurals would add errors.
//!
//! # Templates
//!
//! For a first phrase `x` and a second phrase `y`:
//!
//! * [`Conjunction::While`]: `{base x} while {gerund y}`: "walk while waving".
//! * [`Conjunction::During`]: `{base x} {during y}`: "wave during walking" (SINC's form; reads as in
//!   "knee flexion during walking"). A body state has no duration of its own, so "walk during left
//!   arm up" is not English: it becomes "walk with left arm up throughout", the one template whose
//!   text does not contain its conjunction word.
//! * [`Conjunction::AtTheSameTime`]: `{base x} and {base y} at the same time`.
//! * [`Conjunction::Simultaneously`]: `simultaneously {base x} and {base y}`.
//! * [`Conjunction::AndAtTheSameTime`]: `{base x}, and at the same time {base y}`.
//!
//! When either phrase already leads with a gerund ("looking left"), the base slots of both use
//! the gerund rendering ("simultaneously looking left and waving") because an -ing form cannot
//! be turned back into its lemma reliably (is "hopping" from "hop" or "hopp"?), and mixing
//! "looking left and wave" reads worse than two gerunds.
//!
//! Input is normalised before use: surrounding whitespace and trailing sentence punctuation
//! (`.!?;:,`) are removed and runs of whitespace become one space. Words are otherwise kept as
//! written: side words (`left`, `right`) and case are never changed.

use std::collections::{BTreeMap, HashSet};
use std::fmt;
use std::sync::LazyLock;

use motionforge_core::base::leak;
use serde::{Deserialize, Deserializer, Serialize};

/// How two simultaneous actions are joined into one text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Conjunction {
    /// `{a} while {b-ing}`.
    While,
    /// `{a} during {b-ing}` (see the module docs for body states).
    During,
    /// `{a} and {b} at the same time`.
    AtTheSameTime,
    /// `simultaneously {a} and {b}`.
    Simultaneously,
    /// `{a}, and at the same time {b}`.
    AndAtTheSameTime,
}

impl Conjunction {
    /// Every conjunction, in the order [`compose_variants`] emits them.
    pub const ALL: [Conjunction; 5] = [
        Conjunction::While,
        Conjunction::During,
        Conjunction::AtTheSameTime,
        Conjunction::Simultaneously,
        Conjunction::AndAtTheSameTime,
    ];

    /// The snake_case name, identical to the serde representation.
    pub fn as_str(self) -> &'static str {
        match self {
            Conjunction::While => "while",
            Conjunction::During => "during",
            Conjunction::AtTheSameTime => "at_the_same_time",
            Conjunction::Simultaneously => "simultaneously",
            Conjunction::AndAtTheSameTime => "and_at_the_same_time",
        }
    }
}

impl fmt::Display for Conjunction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One composed text for a pair of actions.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ComposedText {
    /// The joined text.
    pub text: String,
    /// The conjunction (template) used.
    pub conjunction: Conjunction,
    /// `false`: the first input phrase comes first in the text; `true`: the second one does.
    pub swapped: bool,
}

/// How a phrase is read grammatically (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PhraseKind {
    /// Led by a verb ("walk forward", "a person waves", "carefully step back", "walking").
    Verbal,
    /// A body part with a position or an ongoing action ("left arm up", "hands touch knees").
    BodyState,
    /// The name of an action ("t pose", "slow walk", "golf swing", "right hand wave").
    Nominal,
}

/// Reads how `phrase` is built: verb-led, body-state or action name.
pub fn phrase_kind(phrase: &str) -> PhraseKind {
    analyze(phrase).kind
}

/// Every composed text for `a` and `b`: the five conjunctions in [`Conjunction::ALL`] order, each
/// first with `a` first (`swapped: false`) and then with `b` first (`swapped: true`), so always 10
/// entries.
pub fn compose_variants(a: &str, b: &str) -> Vec<ComposedText> {
    let (first, second) = (analyze(a), analyze(b));
    let mut out = Vec::with_capacity(Conjunction::ALL.len() * 2);
    for conjunction in Conjunction::ALL {
        for swapped in [false, true] {
            out.push(build(&first, &second, conjunction, swapped));
        }
    }
    out
}

/// One of the [`compose_variants`] texts, picked by `seed`.
///
/// Deterministic: the same seed and texts always give the same pick. The texts take part in the
/// pick (not only the seed) so that a caller passing one run-wide seed for every pair still gets
/// conjunctions and orders spread over the pairs.
pub fn compose(a: &str, b: &str, seed: u64) -> ComposedText {
    let variants = Conjunction::ALL.len() * 2;
    // FNV-1a over both texts: stable across Rust versions and platforms, unlike std's hasher.
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for byte in a.bytes().chain([0xff]).chain(b.bytes()) {
        hash ^= u64::from(byte);
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    let index = (splitmix64(seed ^ hash) % variants as u64) as usize;
    let conjunction = Conjunction::ALL[(index / 2) % Conjunction::ALL.len()];
    build(&analyze(a), &analyze(b), conjunction, index % 2 == 1)
}

/// The gerund form of an action phrase.
///
/// * Verbal phrases: the lead verb becomes its -ing form, and so does every verb coordinated
///   with it by `and`, `or`, `then` or a comma ("pick up something and drop it" → "picking up
///   something and dropping it"). A leading subject and auxiliary are dropped ("a person walks
///   forward" → "walking forward", "he is waving" → "waving"); leading adverbs stay ("carefully
///   walking forward"). Phrases already led by a gerund ("walking") are kept.
/// * Body states: the verb after the body part becomes -ing ("right hand touch ground" →
///   "right hand touching ground"); pure positions ("left arm up") are kept.
/// * Action names ("t pose", "slow walk", "forward jump", "push ups") are returned unchanged: they
///   have no verb to inflect, and composition puts "doing" in front instead.
///
/// Two data-specific repairs of BABEL spellings: "low" before a body part means "lower" ("low left
/// hand" → "lowering left hand"; "low jump" stays an action name), and "bent" before "down" or
/// "and" means "bend" ("bent down and sit" → "bending down and sitting"; "bent knees" stays a
/// state).
pub fn gerund_phrase(phrase: &str) -> String {
    analyze(phrase).render(Form::Gerund)
}

/// The -ing form of one verb, with English (US) spelling rules.
///
/// * silent `e` is dropped (make → making), but not after `e`, `o` or `y` (see → seeing,
///   tiptoe → tiptoeing, dye → dyeing); be → being;
/// * `ie` becomes `ying` (lie → lying, tie → tying, die → dying);
/// * `ic` becomes `icking` (panic → panicking, picnic → picnicking);
/// * a final consonant after a single vowel is doubled in one-syllable words (run → running,
///   sit → sitting, quit → quitting) and in a list of stressed-final words (begin, admit, occur,
///   unzip, sidestep, ...), never after a vowel team (kneel → kneeling, cook → cooking), never
///   for `w`, `x`, `y` (row → rowing, box → boxing, play → playing) and not for unstressed
///   finals (visit → visiting, open → opening, travel → traveling: US spelling);
/// * a word that is already a gerund is returned as is (walking → walking), while base verbs
///   ending in -ing are inflected (bring → bringing, swing → swinging).
///
/// Only the first whitespace-separated word is inflected; in a hyphenated word the last part is
/// (re-enter → re-entering). Words without letters are returned unchanged. Case is kept for
/// lower, Title and UPPER case words.
pub fn gerund(verb: &str) -> String {
    let verb = verb.trim();
    if let Some((head, rest)) = verb.split_once(char::is_whitespace) {
        return format!("{} {}", gerund(head), rest.trim_start());
    }
    if let Some((head, tail)) = verb.rsplit_once('-')
        && tail.chars().any(|c| c.is_alphabetic())
    {
        return format!("{head}-{}", gerund(tail));
    }
    if !verb.chars().any(|c| c.is_alphabetic()) {
        return verb.to_owned();
    }
    recase(verb, &gerund_lower(&verb.to_lowercase()))
}

/// [`gerund`] on a lowercase word.
fn gerund_lower(word: &str) -> String {
    if word == "be" {
        return "being".to_owned();
    }
    if is_gerund_form(word) {
        return word.to_owned();
    }
    if let Some(stem) = word.strip_suffix("ie") {
        return format!("{stem}ying");
    }
    if word.ends_with("ee") || word.ends_with("oe") || word.ends_with("ye") {
        return format!("{word}ing");
    }
    // "singe"/"tinge" keep their e so they do not read as "singing"/"tinging".
    if matches!(word, "singe" | "tinge" | "swinge") {
        return format!("{word}ing");
    }
    if let Some(stem) = word.strip_suffix('e')
        && !stem.is_empty()
    {
        return format!("{stem}ing");
    }
    if word.ends_with("ic") {
        return format!("{word}king");
    }
    if should_double(word)
        && let Some(last) = word.chars().last()
    {
        return format!("{word}{last}ing");
    }
    format!("{word}ing")
}

/// Consonant doubling before -ing: one-syllable CVC words and known stressed-final words.
fn should_double(word: &str) -> bool {
    let c: Vec<char> = word.chars().collect();
    let n = c.len();
    if n < 3 || !c.iter().all(|ch| ch.is_ascii_lowercase()) {
        return false;
    }
    let last = c[n - 1];
    if is_vowel(last) || matches!(last, 'w' | 'x' | 'y') {
        return false;
    }
    if !is_vowel(c[n - 2]) {
        return false;
    }
    // The "u" of "qu" is a consonant sound: quit → quitting, squat → squatting.
    let before_is_vowel = is_vowel(c[n - 3]) && !(c[n - 3] == 'u' && n >= 4 && c[n - 4] == 'q');
    if before_is_vowel {
        return false;
    }
    syllables(&c) <= 1 || words().stressed_final.contains(&word)
}

fn is_vowel(c: char) -> bool {
    matches!(c, 'a' | 'e' | 'i' | 'o' | 'u')
}

/// Vowel groups, counting `y` after the first letter and skipping the `u` of `qu`.
fn syllables(c: &[char]) -> usize {
    let mut count = 0;
    let mut in_group = false;
    for (i, &ch) in c.iter().enumerate() {
        let vowel =
            (is_vowel(ch) && !(ch == 'u' && i > 0 && c[i - 1] == 'q')) || (ch == 'y' && i > 0);
        if vowel && !in_group {
            count += 1;
        }
        in_group = vowel;
    }
    count
}

/// Puts `new` (lowercase) into the case pattern of `original`.
fn recase(original: &str, new: &str) -> String {
    let letters: Vec<char> = original.chars().filter(|c| c.is_alphabetic()).collect();
    if letters.len() > 1 && letters.iter().all(|c| c.is_uppercase()) {
        return new.to_uppercase();
    }
    if letters.first().is_some_and(|c| c.is_uppercase()) {
        let mut chars = new.chars();
        if let Some(first) = chars.next() {
            return first.to_uppercase().chain(chars).collect();
        }
    }
    new.to_owned()
}

/// Whether a lowercase word is an -ing form rather than a base verb or a noun: the stem before
/// "ing" must hold a vowel, which rules out bring, swing, string, spring, sting, fling, cling.
fn is_gerund_form(word: &str) -> bool {
    let Some(stem) = word.strip_suffix("ing") else {
        return false;
    };
    word.len() >= 5
        && stem.chars().any(|c| is_vowel(c) || c == 'y')
        && !words().not_gerunds.contains(&word)
}

/// The bundled word lists (`schemas/compose_text.toml`).
const WORDS_TOML: &str = include_str!("../../../schemas/compose_text.toml");

/// The composer's vocabulary (`schemas/compose_text.toml`, where each list is documented), kept
/// for the life of the process.
#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Words {
    #[serde(deserialize_with = "leaked")]
    not_gerunds: Vec<&'static str>,
    #[serde(deserialize_with = "leaked")]
    stressed_final: Vec<&'static str>,
    #[serde(deserialize_with = "leaked")]
    verbs: HashSet<&'static str>,
    #[serde(deserialize_with = "leaked")]
    light_verbs: Vec<&'static str>,
    #[serde(deserialize_with = "leaked")]
    compound_heads: Vec<&'static str>,
    #[serde(deserialize_with = "leaked")]
    gait_nouns: Vec<&'static str>,
    #[serde(deserialize_with = "leaked")]
    move_nouns: Vec<&'static str>,
    #[serde(deserialize_with = "phrases")]
    nominal_phrases: Vec<Vec<&'static str>>,
    #[serde(deserialize_with = "phrases")]
    subjects: Vec<Vec<&'static str>>,
    #[serde(deserialize_with = "leaked")]
    auxiliaries: Vec<&'static str>,
    #[serde(deserialize_with = "leaked")]
    side_words: Vec<&'static str>,
    #[serde(deserialize_with = "leaked")]
    body_parts: HashSet<&'static str>,
    #[serde(deserialize_with = "leaked")]
    positions: HashSet<&'static str>,
    #[serde(deserialize_with = "leaked")]
    coordinators: Vec<&'static str>,
    #[serde(deserialize_with = "leaked")]
    plain_adverbs: Vec<&'static str>,
    #[serde(deserialize_with = "leaked")]
    not_adverbs: Vec<&'static str>,
    #[serde(deserialize_with = "particles")]
    particle_verbs: Vec<(&'static str, Vec<&'static str>)>,
}

/// A list of words of the file.
fn leaked<'de, D: Deserializer<'de>, C: FromIterator<&'static str>>(d: D) -> Result<C, D::Error> {
    Ok(Vec::<String>::deserialize(d)?
        .into_iter()
        .map(leak)
        .collect())
}

/// A list of phrases of the file, each as its words.
fn phrases<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Vec<&'static str>>, D::Error> {
    let phrases: Vec<String> = Deserialize::deserialize(d)?;
    Ok(phrases
        .into_iter()
        .map(|p| leak(p).split_whitespace().collect())
        .collect())
}

/// The particle verbs of the file: each verb with its particles.
fn particles<'de, D: Deserializer<'de>>(
    d: D,
) -> Result<Vec<(&'static str, Vec<&'static str>)>, D::Error> {
    let verbs: BTreeMap<String, Vec<String>> = Deserialize::deserialize(d)?;
    Ok(verbs
        .into_iter()
        .map(|(w, p)| (leak(w), p.into_iter().map(leak).collect()))
        .collect())
}

/// Why the composer's word file cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WordsError {
    /// The file does not parse or has unknown keys.
    #[error("schemas/compose_text.toml: {0}")]
    Toml(#[source] toml::de::Error),
    /// A list the composer cannot do without is empty.
    #[error("schemas/compose_text.toml: `verbs` must not be empty, nor any `subjects` phrase")]
    Empty,
}

fn load_words(text: &str) -> Result<Words, WordsError> {
    let words: Words = toml::from_str(text).map_err(WordsError::Toml)?;
    if words.verbs.is_empty() || words.subjects.iter().any(Vec::is_empty) {
        return Err(WordsError::Empty);
    }
    Ok(words)
}

static WORDS: LazyLock<Result<Words, WordsError>> = LazyLock::new(|| load_words(WORDS_TOML));

/// The composer's vocabulary, loaded and validated once ([`check_words`] reports a bad file).
fn words() -> &'static Words {
    static EMPTY: LazyLock<Words> = LazyLock::new(Words::default);
    match &*WORDS {
        Ok(w) => w,
        Err(_) => &EMPTY,
    }
}

/// Loads and validates the bundled word file (`schemas/compose_text.toml`).
pub fn check_words() -> Result<(), WordsError> {
    match &*WORDS {
        Ok(_) => Ok(()),
        Err(e) => Err(e.clone()),
    }
}

fn is_verb(word: &str) -> bool {
    words().verbs.contains(word)
}

/// The lemma of a third-person singular form of a known verb ("walks" → "walk",
/// "pushes" → "push", "carries" → "carry", "ties" → "tie").
fn third_person_lemma(word: &str) -> Option<String> {
    match word {
        "has" => return Some("have".to_owned()),
        "does" => return Some("do".to_owned()),
        "goes" => return Some("go".to_owned()),
        _ => {}
    }
    if word.len() < 3 || !word.ends_with('s') || word.ends_with("ss") {
        return None;
    }
    let mut candidates = Vec::new();
    if let Some(stem) = word.strip_suffix("ies") {
        candidates.push(format!("{stem}y"));
        candidates.push(format!("{stem}ie"));
    }
    if let Some(stem) = word.strip_suffix("es") {
        candidates.push(stem.to_owned());
    }
    if let Some(stem) = word.strip_suffix('s') {
        candidates.push(stem.to_owned());
    }
    candidates.into_iter().find(|c| is_verb(c))
}

fn is_adverb(word: &str) -> bool {
    words().plain_adverbs.contains(&word)
        || (word.len() >= 5
            && word.ends_with("ly")
            && !is_verb(word)
            && !words().not_adverbs.contains(&word))
}

/// What to do with a verb token when rendering.
#[derive(Debug, Clone)]
enum Slot {
    /// A verb to inflect, with its lemma.
    Lemma(String),
    /// Already an -ing form: kept in every rendering.
    Gerund,
}

/// How a token's verb is written out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Form {
    Base,
    Gerund,
}

/// One whitespace-separated word, split into punctuation around a word core.
#[derive(Debug, Clone)]
struct Token {
    prefix: String,
    core: String,
    suffix: String,
    /// Lowercase core, for matching.
    key: String,
}

impl Token {
    fn new(raw: &str) -> Token {
        let mut start = raw.len();
        let mut end = 0;
        for (i, c) in raw.char_indices() {
            if c.is_alphanumeric() {
                start = start.min(i);
                end = i + c.len_utf8();
            }
        }
        if start >= end {
            return Token {
                prefix: raw.to_owned(),
                core: String::new(),
                suffix: String::new(),
                key: String::new(),
            };
        }
        let core = &raw[start..end];
        Token {
            prefix: raw[..start].to_owned(),
            core: core.to_owned(),
            suffix: raw[end..].to_owned(),
            key: core.to_lowercase(),
        }
    }

    fn with_core(&self, core: &str) -> String {
        format!("{}{}{}", self.prefix, core, self.suffix)
    }

    fn original(&self) -> String {
        self.with_core(&self.core)
    }
}

/// A phrase read once, rendered in several forms.
#[derive(Debug, Clone)]
struct Analysis {
    kind: PhraseKind,
    tokens: Vec<Token>,
    /// First token written out (a dropped subject ends before it).
    start: usize,
    /// Verb tokens to inflect, by index.
    slots: Vec<(usize, Slot)>,
    /// The lead verb is already an -ing form.
    gerund_led: bool,
}

impl Analysis {
    fn keys(&self) -> Vec<&str> {
        self.tokens.iter().map(|t| t.key.as_str()).collect()
    }

    /// The phrase with its verb slots written in `form`.
    fn render(&self, form: Form) -> String {
        let mut words = Vec::with_capacity(self.tokens.len());
        for (i, token) in self.tokens.iter().enumerate().skip(self.start) {
            let slot = self.slots.iter().find(|(j, _)| *j == i).map(|(_, s)| s);
            let word = match (slot, form) {
                (Some(Slot::Lemma(lemma)), Form::Base) => {
                    token.with_core(&recase(&token.core, lemma))
                }
                (Some(Slot::Lemma(lemma)), Form::Gerund) => {
                    token.with_core(&recase(&token.core, &gerund_lower(lemma)))
                }
                (Some(Slot::Gerund), _) | (None, _) => token.original(),
            };
            words.push(word);
        }
        words.join(" ")
    }

    /// The phrase in a base (imperative) slot.
    fn base_slot(&self) -> String {
        match self.kind {
            PhraseKind::Verbal => self.render(Form::Base),
            PhraseKind::BodyState => join(&["keep", &self.render(Form::Gerund)]),
            PhraseKind::Nominal => join(&["do", &self.render(Form::Base)]),
        }
    }

    /// The phrase in a gerund slot.
    fn gerund_slot(&self) -> String {
        match self.kind {
            PhraseKind::Verbal => self.render(Form::Gerund),
            PhraseKind::BodyState => join(&["keeping", &self.render(Form::Gerund)]),
            PhraseKind::Nominal => join(&["doing", &self.render(Form::Base)]),
        }
    }

    /// The phrase as the tail of a `During` text.
    fn during_tail(&self) -> String {
        match self.kind {
            PhraseKind::Verbal => join(&["during", &self.render(Form::Gerund)]),
            PhraseKind::BodyState => join(&["with", &self.render(Form::Gerund), "throughout"]),
            PhraseKind::Nominal => join(&["during", &self.render(Form::Base)]),
        }
    }
}

/// Joins non-empty parts with single spaces (an empty phrase must not leave double spaces).
fn join(parts: &[&str]) -> String {
    parts
        .iter()
        .filter(|p| !p.is_empty())
        .copied()
        .collect::<Vec<_>>()
        .join(" ")
}

fn build(a: &Analysis, b: &Analysis, conjunction: Conjunction, swapped: bool) -> ComposedText {
    let (x, y) = if swapped { (b, a) } else { (a, b) };
    let gerund_register = a.gerund_led || b.gerund_led;
    let base = |p: &Analysis| {
        if gerund_register {
            p.gerund_slot()
        } else {
            p.base_slot()
        }
    };
    let text = match conjunction {
        Conjunction::While => join(&[&base(x), "while", &y.gerund_slot()]),
        Conjunction::During => join(&[&base(x), &y.during_tail()]),
        Conjunction::AtTheSameTime => join(&[&base(x), "and", &base(y), "at the same time"]),
        Conjunction::Simultaneously => join(&["simultaneously", &base(x), "and", &base(y)]),
        Conjunction::AndAtTheSameTime => {
            join(&[&format!("{},", base(x)), "and at the same time", &base(y)])
        }
    };
    ComposedText {
        text,
        conjunction,
        swapped,
    }
}

fn tokenize(phrase: &str) -> Vec<Token> {
    let trimmed = phrase.trim().trim_end_matches(|c: char| {
        matches!(c, '.' | '!' | '?' | ';' | ':' | ',') || c.is_whitespace()
    });
    trimmed.split_whitespace().map(Token::new).collect()
}

fn analyze(phrase: &str) -> Analysis {
    let tokens = tokenize(phrase);
    let nominal = Analysis {
        kind: PhraseKind::Nominal,
        tokens,
        start: 0,
        slots: Vec::new(),
        gerund_led: false,
    };
    let keys = nominal.keys();
    // A comma coordinates like "and": "walk forward, turn left".
    let commas: Vec<bool> = nominal
        .tokens
        .iter()
        .map(|t| t.suffix.contains(','))
        .collect();
    // "kick series", "hand out gesture series": BABEL's names for routines, whatever leads them.
    if keys.is_empty()
        || keys.last() == Some(&"series")
        || words()
            .nominal_phrases
            .iter()
            .any(|p| keys.len() >= p.len() && keys[..p.len()] == p[..])
    {
        return nominal;
    }
    // A subject is only dropped when a verb follows it; "person with hand up" stays as written.
    if let Some(after) = subject_end(&keys)
        && let Some((slots, gerund_led)) = verbal_from(&keys, &commas, after)
    {
        return Analysis {
            kind: PhraseKind::Verbal,
            start: after,
            slots,
            gerund_led,
            ..nominal
        };
    }
    if let Some((slots, gerund_led)) = verbal_from(&keys, &commas, 0) {
        return Analysis {
            kind: PhraseKind::Verbal,
            slots,
            gerund_led,
            ..nominal
        };
    }
    if let Some(slots) = body_state(&keys, &commas) {
        return Analysis {
            kind: PhraseKind::BodyState,
            slots,
            ..nominal
        };
    }
    nominal
}

/// Index after a leading subject and auxiliary, if the phrase starts with a subject.
fn subject_end(keys: &[&str]) -> Option<usize> {
    let subject = words()
        .subjects
        .iter()
        .filter(|s| keys.len() > s.len() && keys[..s.len()] == s[..])
        .map(|s| s.len())
        .max()?;
    let aux = keys
        .get(subject)
        .is_some_and(|k| words().auxiliaries.contains(k));
    Some(subject + usize::from(aux))
}

/// The lead verb at `i`, if the word there is one in context.
fn lead_slot(keys: &[&str], i: usize) -> Option<Slot> {
    let word = *keys.get(i)?;
    let next = keys.get(i + 1).copied();
    if is_gerund_form(word) {
        return Some(Slot::Gerund);
    }
    if let Some((_, particles)) = words().particle_verbs.iter().find(|(w, _)| *w == word) {
        return next
            .filter(|n| particles.contains(n))
            .map(|_| Slot::Lemma(word.to_owned()));
    }
    if word == "bent" {
        // "bent down and sit", "bent and walk": a misspelt "bend"; "bent knees" is a state.
        return next
            .filter(|n| matches!(*n, "down" | "and"))
            .map(|_| Slot::Lemma("bend".to_owned()));
    }
    if word == "low" {
        // BABEL's "low left hand" means "lower left hand"; "low jump" is an action name.
        return next
            .filter(|n| words().side_words.contains(n) || words().body_parts.contains(n))
            .map(|_| Slot::Lemma("lower".to_owned()));
    }
    // "face look forward": a face that looks, not the verb "face".
    if word == "face"
        && next.is_some_and(|n| is_verb(n) || is_gerund_form(n) || third_person_lemma(n).is_some())
    {
        return None;
    }
    if is_verb(word) {
        return Some(Slot::Lemma(word.to_owned()));
    }
    third_person_lemma(word).map(Slot::Lemma)
}

/// Whether the verb `lemma` at `i` is really the first half of a compound action name.
fn is_compound_name(keys: &[&str], i: usize, lemma: &str) -> bool {
    let Some(&next) = keys.get(i + 1) else {
        return false;
    };
    // "push ups", "sit ups", "pull ups".
    if next == "ups" {
        return true;
    }
    if words().light_verbs.contains(&lemma) {
        return false;
    }
    if words().compound_heads.contains(&next) || words().gait_nouns.contains(&next) {
        return true;
    }
    if keys.len() == i + 2 && words().move_nouns.contains(&next) {
        return true;
    }
    // "zip zag walk", "guide forward walk": a gait noun closing a run of modifiers.
    let last = keys.len() - 1;
    last > i + 1
        && words().gait_nouns.contains(&keys[last])
        && keys[i + 1..last]
            .iter()
            .all(|k| !words().coordinators.contains(k) && !is_function_word(k))
}

/// Prepositions and articles: a gait noun after one of them is an object ("go for a walk").
fn is_function_word(word: &str) -> bool {
    matches!(
        word,
        "a" | "an"
            | "the"
            | "to"
            | "for"
            | "in"
            | "on"
            | "at"
            | "with"
            | "into"
            | "from"
            | "like"
            | "as"
            | "while"
            | "when"
    )
}

/// Reads a verb-led phrase starting at `start` (adverbs allowed before the verb).
fn verbal_from(keys: &[&str], commas: &[bool], start: usize) -> Option<(Vec<(usize, Slot)>, bool)> {
    let mut i = start;
    while keys.get(i).is_some_and(|k| is_adverb(k)) {
        i += 1;
    }
    let slot = lead_slot(keys, i)?;
    if let Slot::Lemma(lemma) = &slot
        && is_compound_name(keys, i, lemma)
    {
        return None;
    }
    let gerund_led = matches!(slot, Slot::Gerund);
    let mut slots = vec![(i, slot)];
    slots.extend(coordinated(keys, commas, i + 1));
    Some((slots, gerund_led))
}

/// Verbs coordinated after `from` ("... and drop it", "... then stand").
fn coordinated(keys: &[&str], commas: &[bool], from: usize) -> Vec<(usize, Slot)> {
    let mut slots = Vec::new();
    for j in from..keys.len() {
        let after_comma = j > 0 && commas.get(j - 1).copied().unwrap_or(false);
        if j == 0 || !(words().coordinators.contains(&keys[j - 1]) || after_comma) {
            continue;
        }
        let mut k = j;
        while keys.get(k).is_some_and(|w| is_adverb(w)) {
            k += 1;
        }
        let Some(&word) = keys.get(k) else {
            continue;
        };
        // "face" after "and" is the body part ("cover eyes and face").
        if word == "face" || words().particle_verbs.iter().any(|(w, _)| *w == word) {
            continue;
        }
        if is_gerund_form(word) {
            slots.push((k, Slot::Gerund));
        } else if is_verb(word) {
            slots.push((k, Slot::Lemma(word.to_owned())));
        } else if let Some(lemma) = third_person_lemma(word) {
            slots.push((k, Slot::Lemma(lemma)));
        }
    }
    slots
}

/// Reads a body-state phrase: side words and body parts, then a verb or a position.
/// `None` means the phrase is an action name instead.
fn body_state(keys: &[&str], commas: &[bool]) -> Option<Vec<(usize, Slot)>> {
    if keys.first() == Some(&"bent") {
        return Some(coordinated(keys, commas, 1));
    }
    let mut j = 0;
    let mut ends_on_part = false;
    let mut saw_part = false;
    while let Some(&word) = keys.get(j) {
        // "palms face up": "face" after a body part is the verb.
        if word == "face" && ends_on_part {
            break;
        }
        if words().body_parts.contains(word) {
            saw_part = true;
            ends_on_part = true;
        } else if words().side_words.contains(&word)
            // "left and right hand", "hands and arms".
            || (word == "and"
                && j > 0
                && keys
                    .get(j + 1)
                    .is_some_and(|n| words().side_words.contains(n) || words().body_parts.contains(n)))
        {
            ends_on_part = false;
        } else {
            break;
        }
        j += 1;
    }
    if !saw_part || !ends_on_part {
        return None;
    }
    let word = *keys.get(j)?;
    if words().positions.contains(word) {
        return Some(coordinated(keys, commas, j + 1));
    }
    // After a body part these are nouns: "hand gesture", "arm motion".
    if matches!(word, "gesture" | "motion") {
        return None;
    }
    let slot = if is_gerund_form(word) {
        Slot::Gerund
    } else if is_verb(word) {
        Slot::Lemma(word.to_owned())
    } else {
        Slot::Lemma(third_person_lemma(word)?)
    };
    // A verb ending the phrase names the movement ("right hand wave", "neck stretches", "hand
    // washing"), as does a verb heading a compound ("right foot drop kick", "rowing movement").
    let compound = match &slot {
        Slot::Lemma(lemma) => is_compound_name(keys, j, lemma),
        Slot::Gerund => keys
            .get(j + 1)
            .is_some_and(|n| words().compound_heads.contains(n)),
    };
    if j + 1 == keys.len() || compound {
        return None;
    }
    let mut slots = vec![(j, slot)];
    slots.extend(coordinated(keys, commas, j + 1));
    Some(slots)
}

/// SplitMix64 finaliser: spreads nearby seeds over the whole range.
fn splitmix64(seed: u64) -> u64 {
    let mut z = seed.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn word_rules() {
        for (verb, want) in [
            ("make", "making"),
            ("see", "seeing"),
            ("be", "being"),
            ("lie", "lying"),
            ("panic", "panicking"),
            ("run", "running"),
            ("visit", "visiting"),
            ("kneel", "kneeling"),
            ("row", "rowing"),
            ("walking", "walking"),
            ("bring", "bringing"),
            ("Walk", "Walking"),
            ("RUN", "RUNNING"),
            ("re-enter", "re-entering"),
            ("", ""),
            ("45", "45"),
        ] {
            assert_eq!(gerund(verb), want, "{verb}");
        }
    }

    #[test]
    fn kinds() {
        assert_eq!(phrase_kind("walk forward"), PhraseKind::Verbal);
        assert_eq!(phrase_kind("a person walks"), PhraseKind::Verbal);
        assert_eq!(phrase_kind("left arm up"), PhraseKind::BodyState);
        assert_eq!(phrase_kind("t pose"), PhraseKind::Nominal);
        assert_eq!(phrase_kind(""), PhraseKind::Nominal);
    }

    #[test]
    fn empty_inputs_do_not_panic() {
        assert_eq!(compose_variants("", "").len(), 10);
        let c = compose("", "wave", 3);
        assert!(!c.text.contains("  "), "{c:?}");
    }

    #[test]
    fn variants_and_pick_agree() {
        let all = compose_variants("walk", "wave");
        for seed in 0..50 {
            assert!(all.contains(&compose("walk", "wave", seed)));
        }
    }
}

#[cfg(test)]
mod word_file_tests {
    use super::*;

    #[test]
    fn the_bundled_word_file_loads() {
        assert_eq!(check_words(), Ok(()));
        let w = words();
        assert!(w.verbs.len() > 500 && w.verbs.contains("walk"));
        assert!(w.subjects.iter().any(|s| s[..] == ["a", "person"]));
        assert!(
            w.particle_verbs
                .iter()
                .any(|(v, p)| *v == "back" && p.contains(&"up"))
        );
    }

    #[test]
    fn a_damaged_word_file_is_an_error_not_an_empty_vocabulary() {
        let missing = WORDS_TOML.replacen("verbs = [", "verbz = [", 1);
        assert!(load_words(&missing).is_err());
        assert!(load_words(&WORDS_TOML.replacen("\"a person\"", "\"  \"", 1)).is_err());
    }
}
