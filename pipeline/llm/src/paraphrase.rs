//! Checks of a paraphrase answer, line by line, before anything is used or counted as good. Each
//! line the check refuses gets one typed reason ([`ParaphraseFault`]), the first that applies in
//! this order:
//!
//! 1. **markup**: template or special tokens (`[INST]`, `[/INST]`, `[IMG]`, `<s>`, `<|eot_id|>`,
//!    `<start_of_turn>`, `<<SYS>>`), HTML-like tags, Markdown emphasis, headings or code fences;
//! 2. **url**: `http://`, `https://`, `www.` or a bare domain (`youtube.com`);
//! 3. **code**: characters prose does not use (`{ } [ ] < > = ; | \ $ ^ ~ @ _ *` and backticks) or a
//!    call such as `print(`;
//! 4. **not_english**: not a plain English sentence: a character outside ASCII letters, digits
//!    and sentence punctuation, fewer letters than twice its other characters, a word of more than
//!    30 letters, no word of two letters, or a line ending in `:` (a preamble such as
//!    `Here are 3 paraphrases:`);
//! 5. **too_short** / **too_long**: fewer than 2 words (the source's count when that is 1), or more
//!    than `max(3 × source words, source words + 12)` words or 300 characters;
//! 6. **beyond_count**: a line after the number of alternatives asked;
//! 7. **duplicate**: the source again, or an earlier line (case and spacing ignored);
//! 8. **sides** / **turning**: different left/right or clockwise words than the source (`text.rs`);
//! 9. **action**: the source's action is lost. The action is kept when the two share a content lemma
//!    (noun, verb, proper noun or interjection, lemmatised by the HumanML3D caption tagger) outside
//!    the generic words of `schemas/paraphrase.toml`, or a lemma of each is in one of its synonym
//!    groups (`bye` and `wave`, `walk` and `stroll`). A source with no such lemma has no action to
//!    lose.
//!
//! The checks are lexical: a fluent sentence about another action that shares a noun with the
//! source passes (`kick a ball` for `throw a ball`). They catch what small models were seen to
//! produce (template tokens, links, lists longer than asked, the prompt repeated), not every
//! wrong meaning.

use std::collections::{BTreeSet, HashMap, HashSet};
use std::sync::LazyLock;

use regex::Regex;
use serde::{Deserialize, Serialize};

use motionforge_language::caption::{Upos, tokens};
use motionforge_language::text::{rotation_words, side_words};

/// Why a paraphrase line is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParaphraseFault {
    /// Template or special tokens, tags, Markdown.
    Markup,
    /// A link or domain name.
    Url,
    /// Code or symbols prose does not use.
    Code,
    /// Not a plain English sentence.
    NotEnglish,
    /// Too few words for the source.
    TooShort,
    /// Too many words or characters for the source.
    TooLong,
    /// More lines than alternatives asked.
    BeyondCount,
    /// The source again, or an earlier line.
    Duplicate,
    /// Other left/right words than the source.
    Sides,
    /// Another turning direction than the source.
    Turning,
    /// The source's action is not there.
    Action,
}

impl ParaphraseFault {
    /// The reason's code in reports (`markup`, `beyond_count`, ...).
    pub fn code(self) -> &'static str {
        match self {
            ParaphraseFault::Markup => "markup",
            ParaphraseFault::Url => "url",
            ParaphraseFault::Code => "code",
            ParaphraseFault::NotEnglish => "not_english",
            ParaphraseFault::TooShort => "too_short",
            ParaphraseFault::TooLong => "too_long",
            ParaphraseFault::BeyondCount => "beyond_count",
            ParaphraseFault::Duplicate => "duplicate",
            ParaphraseFault::Sides => "sides",
            ParaphraseFault::Turning => "turning",
            ParaphraseFault::Action => "action",
        }
    }
}

impl std::fmt::Display for ParaphraseFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ParaphraseFault::Markup => "markup, a template or a special token",
            ParaphraseFault::Url => "a URL",
            ParaphraseFault::Code => "code or symbols",
            ParaphraseFault::NotEnglish => "not a plain English sentence",
            ParaphraseFault::TooShort => "too short for the source",
            ParaphraseFault::TooLong => "too long for the source",
            ParaphraseFault::BeyondCount => "more alternatives than asked",
            ParaphraseFault::Duplicate => "duplicate",
            ParaphraseFault::Sides => "changes the side words (left/right)",
            ParaphraseFault::Turning => "changes the turning direction",
            ParaphraseFault::Action => "loses the action",
        })
    }
}

/// A paraphrase answer, checked: every non-empty line (list markers removed) in answer order,
/// with the reason it is refused, if it is.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Paraphrases {
    /// The lines and their faults.
    pub lines: Vec<(String, Option<ParaphraseFault>)>,
}

impl Paraphrases {
    /// The lines that passed every check.
    pub fn accepted(&self) -> Vec<&str> {
        self.lines
            .iter()
            .filter(|(_, f)| f.is_none())
            .map(|(l, _)| l.as_str())
            .collect()
    }

    /// The refused lines and why.
    pub fn rejected(&self) -> Vec<(&str, ParaphraseFault)> {
        self.lines
            .iter()
            .filter_map(|(l, f)| f.map(|f| (l.as_str(), f)))
            .collect()
    }
}

/// Longest paraphrase in characters.
const MAX_CHARS: usize = 300;
/// Longest word in letters (English words in captions stay well below).
const MAX_WORD_LETTERS: usize = 30;

/// The word lists of `schemas/paraphrase.toml`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WordFile {
    generic: Vec<String>,
    synonyms: Vec<Vec<String>>,
}

struct Words {
    generic: HashSet<String>,
    /// Lemma -> the synonym groups it is in.
    group_of: HashMap<String, Vec<usize>>,
}

const WORDS_TOML: &str = include_str!("../../../schemas/paraphrase.toml");

static WORDS: LazyLock<Result<Words, ParaphraseWordsError>> = LazyLock::new(|| {
    let file: WordFile = toml::from_str(WORDS_TOML).map_err(ParaphraseWordsError::Toml)?;
    let mut group_of: HashMap<String, Vec<usize>> = HashMap::new();
    for (i, group) in file.synonyms.iter().enumerate() {
        for word in group {
            if word.contains(char::is_whitespace) || word.is_empty() {
                return Err(ParaphraseWordsError::NotOneWord { word: word.clone() });
            }
            group_of.entry(word.to_lowercase()).or_default().push(i);
        }
    }
    Ok(Words {
        generic: file.generic.iter().map(|w| w.to_lowercase()).collect(),
        group_of,
    })
});

/// Why the paraphrase word lists cannot be used (a build with a broken `schemas/` file).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParaphraseWordsError {
    /// The file is not the expected TOML.
    #[error("schemas/paraphrase.toml: {0}")]
    Toml(#[source] toml::de::Error),
    /// A synonym is blank or more than one word.
    #[error("schemas/paraphrase.toml: synonym `{word}` must be one lowercase word")]
    NotOneWord {
        /// The synonym as written.
        word: String,
    },
}

/// Loads the word lists once; the build calls it before the stage so a broken file stops it.
pub fn check_words() -> Result<(), ParaphraseWordsError> {
    WORDS.as_ref().map(|_| ()).map_err(Clone::clone)
}

static MARKUP: LazyLock<Regex> = LazyLock::new(|| {
    Regex::new(
        r"(?ix)
          \[/?[a-z_]{2,}\]            # [INST] [/INST] [IMG]
        | <\|[^|]*\|>                 # <|eot_id|> <|im_start|>
        | </?[a-z_][a-z0-9_:-]*[^>]*> # <s> </s> <start_of_turn> <b>
        | <<\s*/?\s*sys\s*>>          # <<SYS>>
        | \*\*|__                     # Markdown emphasis
        | ^\s*\#                      # Markdown heading
        | ```                         # code fence
        ",
    )
    .unwrap_or_else(|e| unreachable!("constant regex: {e}"))
});

static URL: LazyLock<Regex> = LazyLock::new(|| {
    Regex::new(r"(?i)https?://|\bwww\.|\b[a-z0-9-]+\.(com|org|net|io|edu|gov|ly|be|co|html?)\b")
        .unwrap_or_else(|e| unreachable!("constant regex: {e}"))
});

static CALL: LazyLock<Regex> = LazyLock::new(|| {
    Regex::new(r"\b[A-Za-z_][A-Za-z0-9_.]*\(")
        .unwrap_or_else(|e| unreachable!("constant regex: {e}"))
});

fn strip_list_marker(line: &str) -> &str {
    let t = line.trim();
    let t = t.trim_start_matches(|c: char| c.is_ascii_digit());
    let t = t.strip_prefix(['.', ')', ':']).unwrap_or(t);
    let t = t.trim_start_matches(['-', '*', '•', ' ']);
    t.trim().trim_matches(['"', '\u{201c}', '\u{201d}']).trim()
}

/// Case- and spacing-blind form for duplicate checks.
fn key(s: &str) -> String {
    s.to_lowercase()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

fn word_count(s: &str) -> usize {
    s.split_whitespace()
        .filter(|w| w.chars().any(|c| c.is_alphanumeric()))
        .count()
}

/// The form checks (1 to 4 of the module doc) of one line.
fn form_fault(line: &str) -> Option<ParaphraseFault> {
    if MARKUP.is_match(line) {
        return Some(ParaphraseFault::Markup);
    }
    if URL.is_match(line) {
        return Some(ParaphraseFault::Url);
    }
    if line.contains([
        '{', '}', '[', ']', '<', '>', '=', ';', '|', '\\', '$', '^', '~', '@', '_', '*', '`',
    ]) || CALL.is_match(line)
    {
        return Some(ParaphraseFault::Code);
    }
    let letters = line.chars().filter(|c| c.is_ascii_alphabetic()).count();
    let others = line
        .chars()
        .filter(|c| !c.is_whitespace() && !c.is_ascii_alphabetic())
        .count();
    let plain = line.chars().all(|c| {
        c.is_ascii_alphanumeric()
            || c.is_whitespace()
            || ".,!?'\"-:()/&%+\u{2019}\u{2018}\u{201c}\u{201d}".contains(c)
    });
    let longest = line
        .split(|c: char| !c.is_ascii_alphabetic())
        .map(str::len)
        .max()
        .unwrap_or(0);
    if !plain || letters < 2 * others || longest > MAX_WORD_LETTERS {
        return Some(ParaphraseFault::NotEnglish);
    }
    if longest < 2 || line.trim_end().ends_with(':') {
        return Some(ParaphraseFault::NotEnglish);
    }
    None
}

/// The lemmas of `text` that name its action: nouns, verbs, proper nouns and interjections,
/// generic words removed.
fn action_lemmas(text: &str, words: &Words) -> BTreeSet<String> {
    tokens(text)
        .map(|tokens| {
            tokens
                .into_iter()
                .filter(|t| matches!(t.tag, Upos::Noun | Upos::Verb | Upos::Propn | Upos::Intj))
                .map(|t| t.word.to_lowercase())
                .filter(|w| !words.generic.contains(w))
                .collect()
        })
        .unwrap_or_default()
}

/// True when `line` keeps the action of `source` (item 9 of the module doc).
fn keeps_action(source: &BTreeSet<String>, line: &str, words: &Words) -> bool {
    if source.is_empty() {
        return true;
    }
    // Surface words too: the tagger may tag a word of a short caption differently in each text.
    let mut found = action_lemmas(line, words);
    found.extend(
        line.split(|c: char| !c.is_ascii_alphabetic())
            .filter(|w| !w.is_empty())
            .map(str::to_lowercase),
    );
    if source.iter().any(|w| found.contains(w)) {
        return true;
    }
    let groups = |w: &String| words.group_of.get(w).cloned().unwrap_or_default();
    let source_groups: BTreeSet<usize> = source.iter().flat_map(groups).collect();
    found
        .iter()
        .flat_map(groups)
        .any(|g| source_groups.contains(&g))
}

/// Splits a paraphrase answer into lines and checks each against `original` (the module doc):
/// at most `asked` lines are considered, and each is accepted or refused with one reason.
pub fn check_paraphrases(original: &str, answer: &str, asked: usize) -> Paraphrases {
    let mut out = Paraphrases::default();
    let Ok(words) = WORDS.as_ref() else {
        // check_words() stops a build before this; without word lists nothing can be accepted.
        return out;
    };
    let source_words = word_count(original).max(1);
    let min_words = source_words.min(2);
    let max_words = (3 * source_words).max(source_words + 12);
    let source_action = action_lemmas(original, words);
    let mut seen = vec![key(original)];
    let (sides, turns) = (
        sorted(side_words(original)),
        sorted(rotation_words(original)),
    );
    let mut candidates = 0;
    for line in answer.lines() {
        let text = strip_list_marker(line);
        if text.is_empty() {
            continue;
        }
        let fault = if let Some(f) = form_fault(text) {
            Some(f)
        } else if word_count(text) < min_words {
            Some(ParaphraseFault::TooShort)
        } else if word_count(text) > max_words || text.chars().count() > MAX_CHARS {
            Some(ParaphraseFault::TooLong)
        } else {
            candidates += 1;
            if candidates > asked {
                Some(ParaphraseFault::BeyondCount)
            } else if seen.contains(&key(text)) {
                Some(ParaphraseFault::Duplicate)
            } else if sorted(side_words(text)) != sides {
                Some(ParaphraseFault::Sides)
            } else if sorted(rotation_words(text)) != turns {
                Some(ParaphraseFault::Turning)
            } else if !keeps_action(&source_action, text, words) {
                Some(ParaphraseFault::Action)
            } else {
                None
            }
        };
        if fault.is_none() {
            seen.push(key(text));
        }
        out.lines.push((text.to_string(), fault));
    }
    out
}

fn sorted<T: Ord>(mut v: Vec<T>) -> Vec<T> {
    v.sort();
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reasons(p: &Paraphrases) -> Vec<&'static str> {
        p.rejected().iter().map(|(_, f)| f.code()).collect()
    }

    #[test]
    fn word_lists_load() {
        check_words().unwrap();
    }

    #[test]
    fn sides_duplicates_and_actions() {
        let p = check_paraphrases(
            "wave with the left hand",
            "1. Wave using the left hand.\n2. wave with the right hand\n- raise the left hand and wave it\n3. Wave using the left hand.\n\nwave\nwave with the left hand",
            10,
        );
        assert_eq!(
            p.accepted(),
            vec![
                "Wave using the left hand.",
                "raise the left hand and wave it"
            ]
        );
        assert_eq!(
            reasons(&p),
            vec!["sides", "duplicate", "too_short", "duplicate"]
        );
    }

    #[test]
    fn junk_seen_from_a_small_model_is_refused() {
        let p = check_paraphrases(
            "a person does a walk",
            "[/INST]\n[IMG]http://www.youtube.com/watch?v=abc[/IMG]\nSee www.example.com for more\nprint(\"walk\")\nHere are 3 paraphrases:\nSomeone walks forward.\nA person strolls along.\nThe person sits on a chair.\nA person takes a walk.\nA man walks slowly.",
            3,
        );
        assert_eq!(
            p.accepted(),
            vec!["Someone walks forward.", "A person strolls along."]
        );
        assert_eq!(
            reasons(&p),
            vec![
                "markup",
                "markup",
                "url",
                "code",
                "not_english",
                "action",
                "beyond_count",
                "beyond_count"
            ],
            "{p:?}"
        );
    }

    #[test]
    fn synonyms_and_lemmas_keep_the_action() {
        let p = check_paraphrases(
            "a person does a bye",
            "A person waves goodbye.\nSomeone says bye with a hand.\nA person jumps.",
            3,
        );
        assert_eq!(p.accepted().len(), 2, "{p:?}");
        assert_eq!(reasons(&p), vec!["action"]);
        let long = "a person walks ".repeat(10);
        let p = check_paraphrases(
            "walk",
            &format!("{long}\nwalking\nZzzzzzzzzzzzzzzzzzzzzzzzzzzzzzzzzzz walks"),
            3,
        );
        assert_eq!(reasons(&p), vec!["too_long", "not_english"], "{p:?}");
        assert_eq!(p.accepted(), vec!["walking"]);
    }

    #[test]
    fn foreign_text_is_not_english() {
        let p = check_paraphrases("a person walks", "Una persona camina rápido.\n人が歩く", 3);
        assert_eq!(reasons(&p), vec!["not_english", "not_english"]);
    }
}
