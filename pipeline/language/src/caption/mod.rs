//! Captions in HumanML3D's text-file form (`caption#word/POS ...#start#end`).
//!
//! HumanML3D's `text_process.py` runs spaCy 2.3.4's `en_core_web_sm` over each caption (hyphens
//! removed first), keeps the alphabetic tokens, replaces nouns and verbs by their lemma (except
//! the word `left`) and writes `word/UPOS` pairs. The evaluators of text-to-motion, T2M-GPT and
//! MoMask read those pairs back (GloVe vector of the word, one-hot class of the tag), so a
//! caption line made here has to carry the words and tags spaCy would have given.
//!
//! This module does it without Python: the tags come from spaCy `en_core_web_sm`'s own tagger
//! network, run by `spacy_tagger.rs` on weights exported from the model
//! (`schemas/caption-tagger-spacy.bin`, written by `tools/export-caption-tagger.py`), its Penn
//! Treebank tags turned into coarse tags by spaCy 2.3.4's table ([`pos234`]); lemmas come from a
//! lemmatiser over data files compiled into the crate (`schemas/caption-tagger.toml`, WordNet 3.0
//! for open-class words and irregular forms). The earlier rule-based tagger stays available as
//! [`rule_tokens`] for comparison. `docs/humanml3d-captions.md` describes the method, the data's
//! provenance and how often the result agrees with spaCy on real captions.
//!
//! This file holds the captions' public face: [`tokens`] (with the results it remembers),
//! [`caption_line`] and the errors. The coarse tags and spaCy's table are in `upos.rs`, the
//! tokenisation in `tokenize.rs`, the network in `spacy_tagger.rs`, and the lexicon's readings,
//! the lemmatiser and the rule-based tagger in `rules.rs`.

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

mod rules;
mod spacy_tagger;
mod tokenize;
mod upos;

pub use self::rules::{LexiconLine, TaggerDataError, rule_tokens};
use self::rules::{Tagger, Word, tagger};
pub use self::spacy_tagger::SpacyModelError;
use self::spacy_tagger::{SpacyTagger, SpacyToken};
use self::tokenize::{Piece, split_words};
pub use self::upos::{Upos, pos234};

/// One word of a caption as HumanML3D writes it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Token {
    /// The word, already lemmatised where HumanML3D lemmatises (nouns and verbs but `left`).
    pub word: String,
    /// Its part of speech.
    pub tag: Upos,
}

/// Why a caption cannot become a HumanML3D caption line.
#[derive(Debug, Clone, thiserror::Error)]
pub enum CaptionError {
    /// `#` separates the line's four fields; readers would drop the clip.
    #[error(
        "caption {caption:?} contains '#', which separates the fields of a HumanML3D caption line"
    )]
    Hash {
        /// The caption.
        caption: String,
    },
    /// A caption file holds one caption per line.
    #[error(
        "caption {caption:?} contains a line break; a HumanML3D caption file has one caption per line"
    )]
    LineBreak {
        /// The caption.
        caption: String,
    },
    /// Nothing would be left between the first two `#`.
    #[error(
        "caption {caption:?} has no alphabetic word, so its HumanML3D token list would be empty"
    )]
    NoWords {
        /// The caption.
        caption: String,
    },
    /// Start and end are seconds into the motion: finite, non-negative, end not before start.
    #[error(
        "caption {caption:?}: times {start}..{end} are not finite non-negative seconds with start <= end"
    )]
    Times {
        /// The caption.
        caption: String,
        /// Start, seconds.
        start: f64,
        /// End, seconds.
        end: f64,
    },
    /// Longer than [`MAX_CAPTION_CHARS`]: not a caption (the message quotes its start only).
    #[error(
        "caption {start:?}... has {chars} characters; a caption has at most {MAX_CAPTION_CHARS}"
    )]
    TooLong {
        /// Its first characters.
        start: String,
        /// Its length in characters.
        chars: usize,
    },
    /// The bundled tagger rules or word lists did not load (a build with broken `schemas/`
    /// files). The error is the one the load left, read once for the whole run.
    #[error("caption tagger data: {0}")]
    Rules(#[source] &'static TaggerDataError),
    /// The bundled spaCy tagger model did not load (as for [`CaptionError::Rules`]).
    #[error("caption tagger data: {0}")]
    Model(#[source] &'static SpacyModelError),
}

/// The longest caption, in characters, that is read or tagged. Real captions are a sentence or
/// two (the longest of KIT-ML's 12,164 has 221 characters, of BABEL's labels 119); the tagger's
/// work and memory grow with a caption's length, so a longer text is refused where it is read
/// (`docs/formats.md`, "Caption files") and by [`tokens`] and [`caption_line`].
pub const MAX_CAPTION_CHARS: usize = 4_000;

/// The length in characters of `text` when it is longer than [`MAX_CAPTION_CHARS`].
pub fn over_length(text: &str) -> Option<usize> {
    // Bytes bound characters: most texts need no count.
    if text.len() <= MAX_CAPTION_CHARS || text.chars().nth(MAX_CAPTION_CHARS).is_none() {
        return None;
    }
    Some(text.chars().count())
}

/// [`CaptionError::TooLong`] when `caption` is longer than [`MAX_CAPTION_CHARS`].
fn check_length(caption: &str) -> Result<(), CaptionError> {
    match over_length(caption) {
        None => Ok(()),
        Some(chars) => Err(CaptionError::TooLong {
            start: caption.chars().take(40).collect(),
            chars,
        }),
    }
}

/// The caption's words and tags as HumanML3D's `process_text` gives them: tags from spaCy's
/// tagger network mapped as spaCy 2.3.4 maps them, lemmas from the lexicon.
/// A caption longer than [`MAX_CAPTION_CHARS`] is refused ([`CaptionError::TooLong`]).
pub fn tokens(caption: &str) -> Result<Vec<Token>, CaptionError> {
    check_length(caption)?;
    if let Some(hit) = remembered(caption) {
        return Ok(hit);
    }
    let out = tag_captions(&[caption])?.pop().unwrap_or_else(|| {
        Err(CaptionError::NoWords {
            caption: caption.to_string(),
        })
    })?;
    remember(caption, &out);
    Ok(out)
}

/// Tags the captions [`tokens`] does not remember yet, all together, and remembers them (as far
/// as its memory bound allows), so later calls of [`tokens`] and [`caption_line`] find them.
/// Together is about twice as cheap as one at a time: the network's weights are packed for
/// its matrix products once for all (`docs/performance.md`, "Captions tagged in batches").
/// Captions that cannot be tagged are left for [`tokens`] to refuse with its error.
pub fn remember_all(captions: &[&str]) -> Result<(), CaptionError> {
    let mut seen = std::collections::HashSet::new();
    let todo: Vec<&str> = captions
        .iter()
        .copied()
        .filter(|c| over_length(c).is_none() && seen.insert(*c) && remembered(c).is_none())
        .collect();
    for (caption, out) in todo.iter().zip(tag_captions(&todo)?) {
        if let Ok(out) = out {
            remember(caption, &out);
        }
    }
    Ok(())
}

/// The results [`tokens`] keeps. The network costs about 0.3 ms a caption; datasets repeat
/// captions (every take of an action from its file name, a caption and its paraphrases'
/// sources), so results are kept.
fn memo() -> &'static Mutex<Memo> {
    static SEEN: OnceLock<Mutex<Memo>> = OnceLock::new();
    SEEN.get_or_init(Mutex::default)
}

fn remembered(caption: &str) -> Option<Vec<Token>> {
    memo()
        .lock()
        .ok()
        .and_then(|m| m.captions.get(caption).cloned())
}

fn remember(caption: &str, out: &[Token]) {
    let size = caption.len()
        + out
            .iter()
            .map(|t| std::mem::size_of::<Token>() + t.word.len())
            .sum::<usize>();
    if let Ok(mut m) = memo().lock()
        && m.captions.len() < MEMO_CAPTIONS
        && m.bytes + size <= MEMO_BYTES
        && !m.captions.contains_key(caption)
    {
        m.bytes += size;
        m.captions.insert(caption.to_string(), out.to_vec());
    }
}

/// The captions [`tokens`] remembers, and about how many bytes they hold.
#[derive(Default)]
struct Memo {
    captions: HashMap<String, Vec<Token>>,
    bytes: usize,
}

/// How many captions [`tokens`] remembers (a few MB for captions of a sentence or two)...
const MEMO_CAPTIONS: usize = 1 << 16;
/// ...and how many bytes of captions and tokens at most, however long the captions are.
const MEMO_BYTES: usize = 64 << 20;

/// Each caption's tokens, the network run over all of them together.
fn tag_captions(captions: &[&str]) -> Result<Vec<Result<Vec<Token>, CaptionError>>, CaptionError> {
    let tagger = tagger()?;
    let net = spacy()?;
    let pieces: Vec<Vec<Piece>> = captions
        .iter()
        .map(|c| split_words(&c.replace('-', "")))
        .collect();
    let inputs: Vec<Vec<SpacyToken>> = pieces.iter().map(|p| spacy_input(p, net)).collect();
    let texts: Vec<&[SpacyToken]> = inputs.iter().map(Vec::as_slice).collect();
    let penn = net.tag_many(&texts);
    Ok(captions
        .iter()
        .zip(&pieces)
        .zip(penn)
        .map(|((caption, pieces), penn)| {
            let analysed: Vec<Word> = pieces.iter().map(|p| tagger.analyse(&p.text)).collect();
            let tags = penn
                .iter()
                .zip(pieces)
                .map(|(penn, p)| pos234(penn, &p.text))
                .collect();
            let base: Vec<bool> = penn.iter().map(|t| is_base_form(t)).collect();
            finish(caption, &analysed, tags, &base, tagger)
        })
        .collect())
}

/// True for the Penn tags whose words spaCy's English lemmatiser leaves as they are (lower-cased):
/// a singular noun (NN: `Number=Sing`), a bare verb (VB: `VerbForm=Inf`) and a present verb
/// that is not third person (VBP), its `is_base_form`. Its suffix rules would otherwise turn
/// `taes` into `tae` and `series` into `serie`.
fn is_base_form(penn: &str) -> bool {
    matches!(penn, "NN" | "VB" | "VBP")
}

/// The pieces as the network reads them, with the norms of the tokenizer exceptions they come from.
fn spacy_input<'a>(pieces: &'a [Piece], net: &'a SpacyTagger) -> Vec<SpacyToken<'a>> {
    pieces
        .iter()
        .map(|p| SpacyToken {
            text: &p.text,
            norm: net
                .special_norms(&p.chunk)
                .filter(|n| n.len() == p.parts)
                .and_then(|n| n.get(p.part))
                .map(String::as_str),
            space_after: p.space_after,
            is_space: p.text.chars().all(char::is_whitespace),
        })
        .collect()
}

/// Every token of the caption (hyphens removed, as for [`tokens`]) with the six attributes
/// spaCy's tagger reads (NORM, PREFIX, SUFFIX, SHAPE, SPACY, IS_SPACE, as `Doc.to_array` gives
/// them): what the tests compare with spaCy's own, so the inputs are checked, not just the tags.
pub fn spacy_attributes(caption: &str) -> Result<Vec<(String, [u64; 6])>, CaptionError> {
    check_length(caption)?;
    let net = spacy()?;
    let pieces = split_words(&caption.replace('-', ""));
    Ok(spacy_input(&pieces, net)
        .iter()
        .map(|t| (t.text.to_string(), net.attributes(t)))
        .collect())
}

fn spacy() -> Result<&'static SpacyTagger, CaptionError> {
    static MODEL: OnceLock<Result<SpacyTagger, SpacyModelError>> = OnceLock::new();
    MODEL
        .get_or_init(SpacyTagger::bundled)
        .as_ref()
        .map_err(CaptionError::Model)
}

/// The alphabetic tokens with their tags, nouns and verbs lemmatised (but those whose Penn tag
/// is a base form, `base`).
fn finish(
    caption: &str,
    analysed: &[Word],
    tags: Vec<Upos>,
    base: &[bool],
    tagger: &Tagger,
) -> Result<Vec<Token>, CaptionError> {
    let out: Vec<Token> = analysed
        .iter()
        .zip(tags)
        .zip(base)
        .filter(|((w, _), _)| w.alpha)
        .map(|((w, tag), &base)| Token {
            word: w.output(tag, base, tagger),
            tag,
        })
        .collect();
    if out.is_empty() {
        return Err(CaptionError::NoWords {
            caption: caption.to_string(),
        });
    }
    Ok(out)
}

/// `caption#w/TAG w/TAG ...#start#end` (no newline), with `start` and `end` in seconds written as
/// Python's `'%s' % float` writes them.
pub fn caption_line(caption: &str, start: f64, end: f64) -> Result<String, CaptionError> {
    // First: the other errors quote the whole caption.
    check_length(caption)?;
    if caption.contains('#') {
        return Err(CaptionError::Hash {
            caption: caption.to_string(),
        });
    }
    // Python's text files split lines on all of these, so any would break the one-line record.
    if caption.contains([
        '\n', '\r', '\u{b}', '\u{c}', '\u{1c}', '\u{1d}', '\u{1e}', '\u{85}', '\u{2028}',
        '\u{2029}',
    ]) {
        return Err(CaptionError::LineBreak {
            caption: caption.to_string(),
        });
    }
    if !(start.is_finite() && end.is_finite() && start >= 0.0 && end >= start) {
        return Err(CaptionError::Times {
            caption: caption.to_string(),
            start,
            end,
        });
    }
    let pairs: Vec<String> = tokens(caption)?
        .iter()
        .map(|t| format!("{}/{}", t.word, t.tag))
        .collect();
    Ok(format!(
        "{caption}#{}#{}#{}",
        pairs.join(" "),
        python_float(start),
        python_float(end)
    ))
}

/// A float as Python's `repr` writes it: the shortest digits that round-trip, positional from
/// 1e-4 up to 1e16 (always with a fractional part), scientific with a two-digit exponent outside.
pub fn python_float(x: f64) -> String {
    if !x.is_finite() {
        return if x.is_nan() {
            "nan".into()
        } else if x > 0.0 {
            "inf".into()
        } else {
            "-inf".into()
        };
    }
    if x == 0.0 {
        return if x.is_sign_negative() {
            "-0.0".into()
        } else {
            "0.0".into()
        };
    }
    // `{:e}` gives Rust's shortest round-trip digits, the same digits Python's repr chooses.
    let sci = format!("{x:e}");
    let (mantissa, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let (sign, mantissa) = mantissa
        .strip_prefix('-')
        .map_or(("", mantissa), |m| ("-", m));
    let digits: String = mantissa.chars().filter(char::is_ascii_digit).collect();
    if (-4..16).contains(&exp) {
        let point = exp + 1;
        let body = if point <= 0 {
            format!("0.{}{digits}", "0".repeat((-point) as usize))
        } else if point as usize >= digits.len() {
            format!("{digits}{}.0", "0".repeat(point as usize - digits.len()))
        } else {
            format!(
                "{}.{}",
                &digits[..point as usize],
                &digits[point as usize..]
            )
        };
        format!("{sign}{body}")
    } else {
        let sign_e = if exp < 0 { '-' } else { '+' };
        format!("{sign}{mantissa}e{sign_e}{:02}", exp.abs())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_carry_spacing_and_the_exception_they_come_from() {
        let p = split_words("he  doesn't\tstop, a,b ");
        let texts: Vec<&str> = p.iter().map(|p| p.text.as_str()).collect();
        assert_eq!(
            texts,
            ["he", " ", "does", "n't", "\t", "stop", ",", "a", ",", "b"]
        );
        let spaced: Vec<bool> = p.iter().map(|p| p.space_after).collect();
        assert_eq!(
            spaced,
            [
                true, false, false, false, false, false, true, false, false, true
            ]
        );
        assert_eq!(
            (p[3].chunk.as_str(), p[3].part, p[3].parts),
            ("doesn't", 1, 2)
        );
    }
}
