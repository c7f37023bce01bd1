//! Caption mirroring: a motion mirrored left/right must have its caption mirrored too, or the
//! training pair teaches the model the wrong side.
//!
//! Words handled (whole words only, any of lower, UPPER or Title case):
//!
//! * sides: `left`/`right`, `lefts`/`rights` (as in "turn lefts"), `leftward`/`rightward`,
//!   `leftwards`/`rightwards`, `leftmost`/`rightmost`;
//! * rotation: `clockwise` becomes `counterclockwise`; `counterclockwise`, `counter clockwise`,
//!   `counter-clockwise`, `anticlockwise`, `anti clockwise`, `anti-clockwise` (and `clock-wise`
//!   spellings) all become `clockwise`.
//!
//! A word is delimited by anything that is not a letter or digit, so hyphens and underscores are
//! boundaries (`left-handed`, `turn_left`) while `bright`, `upright`, `leftover`, `righteous`,
//! `copyright` and `lefthand` are left alone.
//!
//! Typos in real captions (`schemas/side-words.toml`, compiled in):
//!
//! * misspelled side words (`rigth`, `lfet`, `leftwords`...) mirror to the correct spelling;
//! * the rotation family takes misspelled prefixes and spellings (`conterclockwise`,
//!   `counter clokwise`);
//! * a side word glued to the word before it (`degreeleftwards`, `turnleft`) is mirrored in place
//!   (`degreerightwards`) when that word has two letters or more and the whole word is not an
//!   English word that merely ends in a side word (`upright`, `alright`, `copyright`, `bright`:
//!   the file's `keep` list, every such word of WordNet 3.0). A side word glued to the word after
//!   it (`leftover`, `lefthand`) and a rotation word glued to anything are left alone: the first
//!   reads as a longer word, and `conterclockwise` shows that a glued "prefix" may be a misspelled
//!   `counter`, whose mirror would then be wrong.
//!
//! `right angle` is geometry, not a side, when it reads `a right angle`, `right angles` or
//! `right-angled`; those stay as they are. A bare `right angle` is kept as a side because real
//! labels pair it with `left angle` ("rotate right angle" / "rotate left angle"). Other non-side
//! senses (`all right`, `right away`) are not recognised: they do not occur in motion captions we
//! have seen and guessing them would break genuine sides ("turn right away from the wall").
//!
//! Mirroring twice returns the input for side words written in lower, UPPER or Title case. The
//! rotation family and misspellings are exempt: their many spellings collapse to the correct one
//! (`rigth` -> `left` -> `right`, `anticlockwise` -> `clockwise` -> `counterclockwise`).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::ops::Range;
use std::sync::LazyLock;

use regex::{Captures, Regex};

/// A body or direction side named in a caption.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Side {
    /// "left", "leftward", ...
    Left,
    /// "right", "rightward", ...
    Right,
}

impl Side {
    /// The side a left/right mirror turns this one into.
    pub fn mirrored(self) -> Side {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
}

/// A rotation sense named in a caption.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Rotation {
    /// "clockwise", "cw", ...
    Clockwise,
    /// "counterclockwise", "anticlockwise", "ccw", ...
    Counterclockwise,
}

impl Rotation {
    /// The sense a left/right mirror turns this one into.
    pub fn mirrored(self) -> Rotation {
        match self {
            Rotation::Clockwise => Rotation::Counterclockwise,
            Rotation::Counterclockwise => Rotation::Clockwise,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Meaning {
    Side(Side),
    Rotation(Rotation),
}

/// Canonical spelling (lowercase, separators removed), its mirror, and what it means. One table
/// serves `mirror_text`, `mirror_side_word`, `side_words` and `rotation_words`, so they cannot
/// disagree about which words count.
const WORDS: &[(&str, &str, Meaning)] = &[
    ("left", "right", Meaning::Side(Side::Left)),
    ("right", "left", Meaning::Side(Side::Right)),
    ("lefts", "rights", Meaning::Side(Side::Left)),
    ("rights", "lefts", Meaning::Side(Side::Right)),
    ("leftward", "rightward", Meaning::Side(Side::Left)),
    ("rightward", "leftward", Meaning::Side(Side::Right)),
    ("leftwards", "rightwards", Meaning::Side(Side::Left)),
    ("rightwards", "leftwards", Meaning::Side(Side::Right)),
    ("leftmost", "rightmost", Meaning::Side(Side::Left)),
    ("rightmost", "leftmost", Meaning::Side(Side::Right)),
    (
        "clockwise",
        "counterclockwise",
        Meaning::Rotation(Rotation::Clockwise),
    ),
    (
        "counterclockwise",
        "clockwise",
        Meaning::Rotation(Rotation::Counterclockwise),
    ),
    (
        "anticlockwise",
        "clockwise",
        Meaning::Rotation(Rotation::Counterclockwise),
    ),
];

/// Candidate words. The regex crate has no look-around and its `\b` counts `_` as a word
/// character, so the boundary after a word is matched explicitly here and the boundary before it
/// is checked in [`tokens`]. Matching the trailing boundary inside the regex also lets the engine
/// fall back to a shorter alternative ("right anglesX" is still the side word "right").
/// Letters are ASCII case-insensitive only: Unicode folding would let `K` (Kelvin sign) or `ſ`
/// stand in for letters and then miss the table.
static CANDIDATE: LazyLock<Regex> = LazyLock::new(|| {
    let spellings = &*SPELLINGS;
    let join = |items: Vec<String>| items.join("|");
    let clockwise = join(
        spellings
            .rotation
            .clockwise
            .iter()
            .map(|s| clockwise_pattern(s))
            .collect(),
    );
    let counter = join(
        spellings
            .rotation
            .counter
            .iter()
            .map(|s| regex::escape(s))
            .collect(),
    );
    let sides = join(spellings.sides.iter().map(|s| regex::escape(s)).collect());
    Regex::new(&format!(
        r"(?x)
        (?:
            (?P<keep>(?i-u:
                a [\ \t_-]+ right [\ \t_-]+ angle
              | right [\ \t_-]+ angle [sd]
            ))
          | (?P<word>(?i-u:
                (?:{counter}) [\ \t_-]* (?:{clockwise})
              | (?:{clockwise})
              | (?:{sides})
            ))
        )
        (?: [^\p{{Alphabetic}}\p{{N}}] | \z )
        "
    ))
    .expect("the side-word regex is built from literals and the bundled spellings")
});

/// A recognised span of the input: either a word to mirror, or a phrase that contains a side word
/// but must stay as it is.
struct Token {
    span: Range<usize>,
    /// `None` for kept phrases such as "a right angle".
    entry: Option<(&'static str, Meaning)>,
}

fn is_word_char(c: char) -> bool {
    c.is_alphanumeric()
}

fn canonical(word: &str) -> String {
    word.chars()
        .filter(|c| !matches!(c, ' ' | '\t' | '_' | '-'))
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

/// The typo data of `schemas/side-words.toml`, as written.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct TypoFile {
    misspellings: BTreeMap<String, String>,
    rotation: RotationSpellings,
    glued: Glued,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RotationSpellings {
    counter: Vec<String>,
    clockwise: Vec<String>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Glued {
    keep: Vec<String>,
}

/// Every spelling the mirror reads, canonical (lowercase, no separators), with its meaning.
struct Spellings {
    /// Spelling -> (mirror, meaning).
    table: HashMap<String, (&'static str, Meaning)>,
    /// Side-word spellings, longest first: the regex alternatives.
    sides: Vec<String>,
    rotation: RotationSpellings,
    /// English words that end in a side word (`upright`).
    keep: HashSet<String>,
}

const TYPOS_TOML: &str = include_str!("../../../schemas/side-words.toml");

/// The bundled typo data is part of the source, like the regex below: a unit test loads it, so a
/// failure here is a build defect, never an input's.
static SPELLINGS: LazyLock<Spellings> = LazyLock::new(|| {
    let file: TypoFile = toml::from_str(TYPOS_TOML)
        .expect("schemas/side-words.toml is valid (a unit test loads it)");
    let mut table: HashMap<String, (&'static str, Meaning)> = WORDS
        .iter()
        .map(|&(spelling, mirror, meaning)| (spelling.to_string(), (mirror, meaning)))
        .collect();
    let mut sides: Vec<String> = WORDS
        .iter()
        .filter(|(_, _, m)| matches!(m, Meaning::Side(_)))
        .map(|(spelling, _, _)| spelling.to_string())
        .collect();
    for (typo, correct) in file.misspellings {
        if let Some(&entry) = table.get(&correct) {
            table.insert(typo.clone(), entry);
            sides.push(typo);
        }
    }
    let counterclockwise = ("clockwise", Meaning::Rotation(Rotation::Counterclockwise));
    for cw in &file.rotation.clockwise {
        table.insert(
            cw.clone(),
            ("counterclockwise", Meaning::Rotation(Rotation::Clockwise)),
        );
        for counter in &file.rotation.counter {
            table.insert(format!("{counter}{cw}"), counterclockwise);
        }
    }
    // Longest first, so `leftwards` is tried before `left` and the trailing boundary decides.
    sides.sort_by(|a, b| b.len().cmp(&a.len()).then_with(|| a.cmp(b)));
    Spellings {
        table,
        sides,
        rotation: file.rotation,
        keep: file.glued.keep.into_iter().collect(),
    }
});

fn lookup(word: &str) -> Option<(&'static str, Meaning)> {
    SPELLINGS.table.get(&canonical(word)).copied()
}

/// A clockwise spelling as a regex: `clock` may be split from `wise` by a separator.
fn clockwise_pattern(spelling: &str) -> String {
    match spelling.strip_prefix("clock") {
        Some(rest) if rest.starts_with('w') => format!(r"clock[\ \t_-]?{}", regex::escape(rest)),
        _ => regex::escape(spelling),
    }
}

/// Whether a side word at `start` glued to the word before it (`degreeleftwards`) is one: the
/// word before has two ASCII letters or more and ends in one, and the whole word is not an
/// English word that merely ends in a side word (`upright`, `alright`), nor its plural.
fn glued_side(text: &str, start: usize, end: usize) -> bool {
    let before = &text[..start];
    let prefix_start = before
        .char_indices()
        .rev()
        .take_while(|&(_, c)| is_word_char(c))
        .last()
        .map_or(start, |(i, _)| i);
    let prefix = &text[prefix_start..start];
    let letters = prefix.chars().filter(char::is_ascii_alphabetic).count();
    let ends_in_letter = prefix
        .chars()
        .next_back()
        .is_some_and(|c| c.is_ascii_alphabetic());
    if !prefix.is_ascii() || letters < 2 || !ends_in_letter {
        return false;
    }
    let whole = text[prefix_start..end].to_ascii_lowercase();
    let singular = whole.strip_suffix('s').unwrap_or(&whole);
    !SPELLINGS.keep.contains(&whole) && !SPELLINGS.keep.contains(singular)
}

fn token_from(caps: &Captures<'_>) -> Option<Token> {
    if let Some(keep) = caps.name("keep") {
        return Some(Token {
            span: keep.range(),
            entry: None,
        });
    }
    let word = caps.name("word")?;
    // Every spelling the regex accepts is in the table; a miss would only drop one word.
    let entry = lookup(word.as_str())?;
    Some(Token {
        span: word.range(),
        entry: Some(entry),
    })
}

/// Recognised words and kept phrases of `text`, left to right, not overlapping.
fn tokens(text: &str) -> Vec<Token> {
    let mut out = Vec::new();
    let mut pos = 0;
    while let Some(caps) = CANDIDATE.captures_at(text, pos) {
        let Some(token) = token_from(&caps) else {
            // Unreachable while the regex and the table agree; skip the candidate rather than
            // stop, so one odd spelling cannot hide the words after it.
            pos = caps.get(0).map_or(text.len(), |m| m.end());
            continue;
        };
        let preceded_by_word_char = text[..token.span.start]
            .chars()
            .next_back()
            .is_some_and(is_word_char);
        let glued = matches!(token.entry, Some((_, Meaning::Side(_))))
            && glued_side(text, token.span.start, token.span.end);
        if preceded_by_word_char && !glued {
            // Inside a longer word ("bright"): a real word can only start later, but possibly
            // within this candidate ("xa right angle"), so rescan from the next character.
            let step = text[token.span.start..]
                .chars()
                .next()
                .map_or(1, char::len_utf8);
            pos = token.span.start + step;
            continue;
        }
        // Resume at the end of the word, not of the match: the consumed boundary character
        // cannot start a word, but it must not hide anything either.
        pos = token.span.end;
        out.push(token);
    }
    out
}

/// Spells `word` in the case style of `template`: all caps, leading capital, or lowercase.
fn match_case(template: &str, word: &str) -> String {
    let mut letters = template.chars().filter(|c| c.is_ascii_alphabetic());
    let first_upper = letters
        .clone()
        .next()
        .is_some_and(|c| c.is_ascii_uppercase());
    let all_upper = first_upper && letters.all(|c| c.is_ascii_uppercase());
    if all_upper {
        return word.to_ascii_uppercase();
    }
    if first_upper {
        let mut chars = word.chars();
        return match chars.next() {
            Some(first) => first.to_ascii_uppercase().to_string() + chars.as_str(),
            None => String::new(),
        };
    }
    word.to_string()
}

/// Mirrors a caption left/right in one pass, so "left ... right" becomes "right ... left".
///
/// ```
/// use motionforge_language::text::mirror_text;
/// assert_eq!(mirror_text("Wave-left-hand, then turn_right"), "Wave-right-hand, then turn_left");
/// assert_eq!(mirror_text("walk counter clockwise"), "walk clockwise");
/// ```
pub fn mirror_text(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 8);
    let mut last = 0;
    for token in tokens(text) {
        let Some((mirror, _)) = token.entry else {
            continue;
        };
        out.push_str(&text[last..token.span.start]);
        out.push_str(&match_case(&text[token.span.clone()], mirror));
        last = token.span.end;
    }
    out.push_str(&text[last..]);
    out
}

/// The mirror of a single side or rotation word, in lowercase, or `None` when `word` is not one
/// (e.g. a hand field that says "both"). Case-insensitive; surrounding text is not allowed.
///
/// ```
/// use motionforge_language::text::mirror_side_word;
/// let hand = "both";
/// assert_eq!(mirror_side_word("Left"), Some("right"));
/// assert_eq!(mirror_side_word(hand).unwrap_or(hand), "both");
/// ```
pub fn mirror_side_word(word: &str) -> Option<&'static str> {
    match tokens(word).as_slice() {
        [token] if token.span == (0..word.len()) => token.entry.map(|(mirror, _)| mirror),
        _ => None,
    }
}

/// The sides a caption names, in order, so a paraphrase or a mirrored caption can be checked
/// against the original.
pub fn side_words(text: &str) -> Vec<Side> {
    tokens(text)
        .into_iter()
        .filter_map(|t| match t.entry {
            Some((_, Meaning::Side(side))) => Some(side),
            _ => None,
        })
        .collect()
}

/// The rotation senses a caption names, in order; the counterpart of [`side_words`].
pub fn rotation_words(text: &str) -> Vec<Rotation> {
    tokens(text)
        .into_iter()
        .filter_map(|t| match t.entry {
            Some((_, Meaning::Rotation(rotation))) => Some(rotation),
            _ => None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn swaps_sides_in_one_pass() {
        assert_eq!(mirror_text("step left then right"), "step right then left");
        assert_eq!(mirror_text("left right left"), "right left right");
        assert_eq!(mirror_text("left"), "right");
        assert_eq!(mirror_text(""), "");
    }

    #[test]
    fn longer_side_forms() {
        assert_eq!(
            mirror_text("drift leftward, leftwards, rightmost"),
            "drift rightward, rightwards, leftmost"
        );
        assert_eq!(mirror_text("turn lefts"), "turn rights");
    }

    #[test]
    fn whole_words_only() {
        for text in [
            "bright",
            "upright",
            "leftover",
            "righteous",
            "copyright",
            "lefthand",
            "rightly",
            "left2",
            "3right",
            "clock",
            "place it on the counter",
            "anti",
            "clockwiser",
            "counterclockwisely",
            "éleft",
        ] {
            assert_eq!(mirror_text(text), text, "{text:?} must stay");
        }
    }

    #[test]
    fn hyphens_underscores_and_punctuation_are_boundaries() {
        assert_eq!(mirror_text("wave-left-hand"), "wave-right-hand");
        assert_eq!(mirror_text("turn_left"), "turn_right");
        assert_eq!(mirror_text("left-handed"), "right-handed");
        assert_eq!(mirror_text("(left),right."), "(right),left.");
        assert_eq!(mirror_text("left\nright"), "right\nleft");
        assert_eq!(mirror_text("LEFT_RIGHT"), "RIGHT_LEFT");
        assert_eq!(mirror_text("é left"), "é right");
    }

    #[test]
    fn keeps_case() {
        assert_eq!(mirror_text("Left"), "Right");
        assert_eq!(mirror_text("LEFT"), "RIGHT");
        assert_eq!(mirror_text("Right"), "Left");
        assert_eq!(mirror_text("Counterclockwise"), "Clockwise");
        assert_eq!(mirror_text("Counter-Clockwise"), "Clockwise");
        assert_eq!(mirror_text("CLOCKWISE"), "COUNTERCLOCKWISE");
        assert_eq!(mirror_text("Clockwise"), "Counterclockwise");
        assert_eq!(mirror_text("ANTI CLOCKWISE"), "CLOCKWISE");
    }

    #[test]
    fn rotation_family() {
        for text in [
            "counterclockwise",
            "counter-clockwise",
            "counter clockwise",
            "counter_clockwise",
            "anticlockwise",
            "anti-clockwise",
            "anti clockwise",
            "counter-clock-wise",
        ] {
            assert_eq!(
                mirror_text(&format!("spin {text} fast")),
                "spin clockwise fast"
            );
        }
        assert_eq!(mirror_text("clockwise"), "counterclockwise");
        assert_eq!(mirror_text("clock-wise"), "counterclockwise");
        assert_eq!(
            mirror_text("clockwise then counterclockwise"),
            "counterclockwise then clockwise"
        );
        // "counter" on its own is a kitchen counter.
        assert_eq!(
            mirror_text("counter, clockwise"),
            "counter, counterclockwise"
        );
    }

    #[test]
    fn right_angle_geometry_is_kept() {
        assert_eq!(
            mirror_text("turn left at a right angle"),
            "turn right at a right angle"
        );
        assert_eq!(mirror_text("bend at right angles"), "bend at right angles");
        assert_eq!(mirror_text("a right-angled turn"), "a right-angled turn");
        assert_eq!(mirror_text("rotate right angle"), "rotate left angle");
        // Not a phrase after all: fall back to the side word.
        assert_eq!(mirror_text("right anglesX"), "left anglesX");
        assert_eq!(mirror_text("xa right angle"), "xa left angle");
        assert!(side_words("turn left at a right angle") == [Side::Left]);
    }

    #[test]
    fn the_bundled_typo_data_loads() {
        let spellings = &*SPELLINGS;
        assert_eq!(lookup("rigth"), Some(("left", Meaning::Side(Side::Right))));
        assert_eq!(
            lookup("conter-clockwise"),
            Some(("clockwise", Meaning::Rotation(Rotation::Counterclockwise)))
        );
        assert!(spellings.sides.iter().any(|s| s == "lfet"));
        assert!(spellings.keep.contains("upright"));
        // Every misspelling names a known word.
        let file: TypoFile = toml::from_str(TYPOS_TOML).unwrap();
        for (typo, correct) in &file.misspellings {
            assert!(WORDS.iter().any(|w| w.0 == correct), "{typo} = {correct}");
        }
    }

    #[test]
    fn misspelled_side_and_rotation_words() {
        assert_eq!(mirror_text("turn rigth"), "turn left");
        assert_eq!(mirror_text("raise lfet hand"), "raise right hand");
        assert_eq!(mirror_text("Rihgt"), "Left");
        assert_eq!(mirror_text("drift leftwords"), "drift rightwards");
        assert_eq!(mirror_text("walk conterclockwise"), "walk clockwise");
        assert_eq!(mirror_text("counter clokwise"), "clockwise");
        assert_eq!(mirror_text("anti-clockwize"), "clockwise");
        assert_eq!(mirror_text("clock wise"), "counterclockwise");
        assert_eq!(
            rotation_words("conterclockwise"),
            [Rotation::Counterclockwise]
        );
        assert_eq!(side_words("rigth then lfet"), [Side::Right, Side::Left]);
    }

    #[test]
    fn side_words_glued_to_the_word_before() {
        assert_eq!(
            mirror_text("turn 90 degreeleftwards"),
            "turn 90 degreerightwards"
        );
        assert_eq!(mirror_text("turnLeft"), "turnRight");
        assert_eq!(
            mirror_text("stepright, 90degreeleft"),
            "stepleft, 90degreeright"
        );
        assert_eq!(side_words("degreeleftwards"), [Side::Left]);
        assert_eq!(mirror_text(&mirror_text("go toright")), "go toright");
        for text in [
            "uprights",
            "Alright",
            "copyrights",
            "OUTRIGHT",
            "playwright",
            "bright",
            "xleft",
            "3right",
            "leftover",
            "lefthand",
            "conterclockwisely",
            "turnclockwise",
        ] {
            assert_eq!(mirror_text(text), text, "{text:?} must stay");
        }
    }

    #[test]
    fn mirrors_twice_back() {
        for text in [
            "left-right LEFT Right rightwards leftmost",
            "turn_left at a right angle",
        ] {
            assert_eq!(mirror_text(&mirror_text(text)), text);
        }
    }

    #[test]
    fn single_words() {
        assert_eq!(mirror_side_word("left"), Some("right"));
        assert_eq!(mirror_side_word("RIGHT"), Some("left"));
        assert_eq!(mirror_side_word("anti-clockwise"), Some("clockwise"));
        assert_eq!(mirror_side_word("clockwise"), Some("counterclockwise"));
        for word in [
            "both",
            "",
            "left hand",
            " left",
            "bright",
            "a right angle",
            "le-ft",
        ] {
            assert_eq!(mirror_side_word(word), None, "{word:?}");
        }
    }

    #[test]
    fn lists_sides_and_rotations_in_order() {
        assert_eq!(
            side_words("right foot over left, then leftwards; upright"),
            [Side::Right, Side::Left, Side::Left]
        );
        assert_eq!(side_words("stand still"), []);
        assert_eq!(
            rotation_words("anti clockwise, then clockwise"),
            [Rotation::Counterclockwise, Rotation::Clockwise]
        );
        assert_eq!(Side::Left.mirrored(), Side::Right);
        assert_eq!(Rotation::Clockwise.mirrored(), Rotation::Counterclockwise);
    }
}
