//! Captions in HumanML3D's text-file form (`caption#word/POS ...#start#end`).
//!
//! HumanML3D's `text_process.py` runs spaCy 2.3.4's `en_core_web_sm` over each caption (hyphens
//! removed first), keeps the alphabetic tokens, replaces nouns and verbs by their lemma (except
//! the word `left`) and writes `word/UPOS` pairs. The evaluators of text-to-motion, T2M-GPT and
//! MoMask read those pairs back (GloVe vector of the word, one-hot class of the tag), so a
//! caption line made here has to carry the words and tags spaCy would have given.
//!
//! This module does it without Python: the tags come from spaCy `en_core_web_sm`'s own tagger
//! network, run by `humanml3d::spacy_tagger` on weights exported from the model
//! (`schemas/caption-tagger-spacy.bin`, written by `tools/export-caption-tagger.py`), its Penn
//! Treebank tags turned into coarse tags by spaCy 2.3.4's table ([`pos234`]); lemmas come from a
//! lemmatiser over data files compiled into the crate (`schemas/caption-tagger.toml`, WordNet 3.0
//! for open-class words and irregular forms). The earlier rule-based tagger stays available as
//! [`rule_tokens`] for comparison. `docs/humanml3d-captions.md` describes the method, the data's
//! provenance and how often the result agrees with spaCy on real captions.

use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::str::FromStr;
use std::sync::{Mutex, OnceLock};

use serde::Deserialize;

mod spacy_tagger;
mod tokenize;

pub use self::spacy_tagger::SpacyModelError;
use self::spacy_tagger::{SpacyTagger, SpacyToken};
use self::tokenize::{Piece, split_words};

const RULES_TOML: &str = include_str!("../../../../schemas/caption-tagger.toml");
const LEXICON_TSV: &str = include_str!("../../../../schemas/pos-lexicon.tsv");
const EXCEPTIONS_TSV: &str = include_str!("../../../../schemas/pos-exceptions.tsv");

/// A Universal POS tag as spaCy assigns them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Upos {
    /// Adjective.
    Adj,
    /// Adposition (preposition, verb particle).
    Adp,
    /// Adverb.
    Adv,
    /// Auxiliary verb.
    Aux,
    /// Coordinating conjunction.
    Cconj,
    /// Determiner (possessive determiners included, as in spaCy 2.3.4).
    Det,
    /// Interjection.
    Intj,
    /// Noun.
    Noun,
    /// Numeral.
    Num,
    /// Particle (infinitival `to`, `not`).
    Part,
    /// Pronoun.
    Pron,
    /// Proper noun.
    Propn,
    /// Punctuation.
    Punct,
    /// Subordinating conjunction.
    Sconj,
    /// Symbol.
    Sym,
    /// Verb (modals included, as in spaCy 2.3.4).
    Verb,
    /// Other.
    X,
    /// Whitespace.
    Space,
}

const ALL_UPOS: [Upos; 18] = [
    Upos::Adj,
    Upos::Adp,
    Upos::Adv,
    Upos::Aux,
    Upos::Cconj,
    Upos::Det,
    Upos::Intj,
    Upos::Noun,
    Upos::Num,
    Upos::Part,
    Upos::Pron,
    Upos::Propn,
    Upos::Punct,
    Upos::Sconj,
    Upos::Sym,
    Upos::Verb,
    Upos::X,
    Upos::Space,
];

impl Upos {
    /// The tag as spaCy spells it (`NOUN`, `VERB`, ...).
    pub fn as_str(self) -> &'static str {
        match self {
            Upos::Adj => "ADJ",
            Upos::Adp => "ADP",
            Upos::Adv => "ADV",
            Upos::Aux => "AUX",
            Upos::Cconj => "CCONJ",
            Upos::Det => "DET",
            Upos::Intj => "INTJ",
            Upos::Noun => "NOUN",
            Upos::Num => "NUM",
            Upos::Part => "PART",
            Upos::Pron => "PRON",
            Upos::Propn => "PROPN",
            Upos::Punct => "PUNCT",
            Upos::Sconj => "SCONJ",
            Upos::Sym => "SYM",
            Upos::Verb => "VERB",
            Upos::X => "X",
            Upos::Space => "SPACE",
        }
    }
}

impl fmt::Display for Upos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Upos {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        ALL_UPOS
            .into_iter()
            .find(|t| t.as_str() == s)
            .ok_or_else(|| format!("`{s}` is not a Universal POS tag"))
    }
}

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

/// Why the rule tagger's bundled files do not load.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TaggerDataError {
    /// The rules file does not parse or has unknown keys.
    #[error("schemas/caption-tagger.toml: {0}")]
    Rules(#[source] toml::de::Error),
    /// An entry names a tag that is not a Universal POS tag.
    #[error("schemas/caption-tagger.toml {entry}: `{tag}` is not a Universal POS tag")]
    UnknownTag {
        /// The entry (`[closed] the`, `[lemma.rules]`...).
        entry: String,
        /// The tag.
        tag: String,
    },
    /// An entry gives no tag.
    #[error("schemas/caption-tagger.toml {entry}: no tag")]
    NoTag {
        /// The entry.
        entry: String,
    },
    /// A lemma rule is for a closed-class tag.
    #[error("schemas/caption-tagger.toml [lemma.rules]: {tag} is not open-class")]
    NotOpenClass {
        /// The tag as written.
        tag: String,
    },
    /// A line of the word lexicon is not a word with four counts.
    #[error("schemas/pos-lexicon.tsv line {line}: {problem}: {text:?}")]
    Lexicon {
        /// 1-based line.
        line: usize,
        /// What is wrong with it.
        problem: LexiconLine,
        /// The line.
        text: String,
    },
    /// A line of the exceptions is not `form<TAB>NOUN|VERB|ADJ<TAB>lemma`.
    #[error(
        "schemas/pos-exceptions.tsv line {line}: not `form<TAB>NOUN|VERB|ADJ<TAB>lemma`: {text:?}"
    )]
    Exception {
        /// 1-based line.
        line: usize,
        /// The line.
        text: String,
    },
}

/// What is wrong with a line of `schemas/pos-lexicon.tsv`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LexiconLine {
    /// The first column is empty.
    #[error("no word")]
    NoWord,
    /// The line ends before the four counts.
    #[error("fewer than five columns")]
    Short,
    /// A count is neither a number nor `-`.
    #[error("a count is not a number or '-'")]
    Count,
    /// More columns, or no count given.
    #[error("not a word with four counts, one at least given")]
    Shape,
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

/// A Penn Treebank tag as spaCy 2.3.4 turns it into a coarse tag: its morphology rules for
/// particular words first (`spacy/lang/en/morph_rules.py`), then its tag map
/// (`spacy/lang/en/tag_map.py`). Possessives come out DET, modals VERB, as in HumanML3D's files.
pub fn pos234(penn: &str, word: &str) -> Upos {
    use Upos::*;
    // morph_rules.py lists each word lower-case and title-case; nothing else matches.
    let lower = word.to_lowercase();
    let mut rest = lower.chars();
    let title: String = rest
        .next()
        .map(|f| f.to_uppercase().chain(rest).collect())
        .unwrap_or_default();
    if word == lower || word == title {
        let w = lower.as_str();
        let rule = match penn {
            "IN" if [
                "that", "if", "as", "because", "while", "since", "like", "so", "than", "whether",
                "although", "though", "unless", "once", "cause", "upon", "till", "whereas",
                "whilst", "except", "despite", "wether", "but", "becuse", "whie", "it", "w/out",
                "albeit", "save", "besides", "becouse", "coz", "til", "ask", "i'd", "out", "near",
                "seince", "tho", "sice", "will",
            ]
            .contains(&w) =>
            {
                Some(Sconj)
            }
            "NN" if [
                "something",
                "anyone",
                "anything",
                "nothing",
                "someone",
                "everything",
                "everyone",
                "everybody",
                "nobody",
                "somebody",
                "anybody",
                "any1",
            ]
            .contains(&w) =>
            {
                Some(Pron)
            }
            "RB" if ["not", "n't", "nt", "n\u{2019}t"].contains(&w) => Some(Part),
            "VB" if ["be", "have", "do", "get", "of", "am", "are", "'ve"].contains(&w) => Some(Aux),
            "VBN" if w == "been" => Some(Aux),
            "VBG" if w == "being" => Some(Aux),
            "VBZ" if ["am", "are", "is", "'re", "'s", "has", "does"].contains(&w) => Some(Aux),
            "VBP"
                if [
                    "are", "'re", "am", "do", "have", "'m", "'ve", "'s", "is", "'d",
                ]
                .contains(&w) =>
            {
                Some(Aux)
            }
            "VBD" if ["was", "were", "did", "had", "'d"].contains(&w) => Some(Aux),
            _ => None,
        };
        if let Some(t) = rule {
            return t;
        }
    }
    match penn {
        "." | "," | "-LRB-" | "-RRB-" | "``" | "\"\"" | "''" | ":" | "HYPH" | "NFP" => Punct,
        "$" | "#" | "SYM" => Sym,
        "AFX" | "JJ" | "JJR" | "JJS" => Adj,
        "CC" => Cconj,
        "CD" => Num,
        "DT" | "PDT" | "PRP$" | "WDT" | "WP$" => Det,
        "EX" | "PRP" | "WP" => Pron,
        "IN" | "RP" => Adp,
        "MD" | "VB" | "VBD" | "VBG" | "VBN" | "VBP" | "VBZ" | "BES" | "HVS" => Verb,
        "NN" | "NNS" => Noun,
        "NNP" | "NNPS" => Propn,
        "POS" | "TO" => Part,
        "RB" | "RBR" | "RBS" | "WRB" => Adv,
        "UH" => Intj,
        "SP" | "_SP" => Space,
        _ => X,
    }
}

/// [`tokens`] as the rule-based tagger that preceded the perceptron tags them (context rules
/// over the lexicon's readings; `docs/humanml3d-captions.md`), kept to compare the two.
pub fn rule_tokens(caption: &str) -> Result<Vec<Token>, CaptionError> {
    check_length(caption)?;
    let tagger = tagger()?;
    let pieces = split_words(&caption.replace('-', ""));
    let analysed: Vec<Word> = pieces.iter().map(|p| tagger.analyse(&p.text)).collect();
    let tags = tagger.tag(&analysed);
    // No Penn tags: a word is a base form where its reading for its tag is the lemma itself.
    let base: Vec<bool> = analysed
        .iter()
        .zip(&tags)
        .map(|(w, tag)| w.form(*tag) == Some(Form::Base))
        .collect();
    finish(caption, &analysed, tags, &base, tagger)
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

/// The open-class parts of speech, in the lexicon's column order.
const OPEN: [Upos; 4] = [Upos::Noun, Upos::Verb, Upos::Adj, Upos::Adv];

/// How a verb or noun reading is inflected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Form {
    /// The lemma itself.
    Base,
    /// A plural noun or third-person verb in -s.
    S,
    /// A past form (-ed or irregular).
    Past,
    /// A present participle (-ing).
    Ing,
}

/// One way to read a word as an open-class part of speech.
#[derive(Debug, Clone)]
struct Reading {
    form: Form,
    /// SemCor count of the lemma for this part of speech, plus one so a known lemma weighs more
    /// than none.
    weight: f64,
}

/// A caption token and what the lexicon says it can be.
#[derive(Debug, Clone)]
struct Word {
    text: String,
    lower: String,
    alpha: bool,
    /// Closed-class tags, default first; empty for open-class words.
    closed: Vec<Upos>,
    /// Readings as noun, verb, adjective, adverb.
    open: [Option<Reading>; 4],
}

impl Word {
    fn reading(&self, tag: Upos) -> Option<&Reading> {
        OPEN.iter()
            .position(|&t| t == tag)
            .and_then(|i| self.open[i].as_ref())
    }

    fn can(&self, tag: Upos) -> bool {
        self.closed.contains(&tag) || self.reading(tag).is_some()
    }

    fn weight(&self, tag: Upos) -> f64 {
        self.reading(tag).map_or(0.0, |r| r.weight)
    }

    fn form(&self, tag: Upos) -> Option<Form> {
        self.reading(tag).map(|r| r.form)
    }

    /// The open reading the lexicon favours, as a fallback.
    fn likeliest(&self) -> Option<Upos> {
        OPEN.into_iter()
            .filter(|&t| self.reading(t).is_some())
            .max_by(|&a, &b| self.weight(a).total_cmp(&self.weight(b)))
    }

    /// Starts a noun phrase: a determiner, number, pronoun or an open-class noun or adjective.
    fn starts_noun_phrase(&self) -> bool {
        if self.closed.is_empty() {
            self.can(Upos::Noun) || self.can(Upos::Adj)
        } else {
            matches!(self.closed[0], Upos::Det | Upos::Num | Upos::Pron)
        }
    }

    /// Can head a noun phrase after an adjective: an open-class word with a noun reading.
    fn nominal(&self) -> bool {
        self.closed.is_empty() && self.can(Upos::Noun)
    }

    /// The word as HumanML3D writes it for this tag: nouns and verbs by their lemma, but `left`,
    /// and lower-cased as it is when its Penn tag is a base form (`base`).
    fn output(&self, tag: Upos, base: bool, tagger: &Tagger) -> String {
        if !matches!(tag, Upos::Noun | Upos::Verb) || self.text == "left" {
            return self.text.clone();
        }
        if base {
            return self.lower.clone();
        }
        if let Some(lemma) = tagger.lemma_exceptions.get(&self.lower) {
            return lemma.clone();
        }
        tagger.rule_lemma(&self.lower, tag)
    }
}

/// The rules file's layout.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RulesFile {
    closed: BTreeMap<String, String>,
    lemma: LemmaRules,
    guess: BTreeMap<String, String>,
    context: Context,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LemmaRules {
    exceptions: BTreeMap<String, String>,
    rules: BTreeMap<String, Vec<[String; 2]>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Context {
    noun_over_verb_at_start: f64,
    sides: Vec<String>,
}

/// The loaded, checked tagger data.
struct Tagger {
    closed: HashMap<String, Vec<Upos>>,
    /// SemCor count (or None: not a lemma) per open-class part of speech.
    lexicon: HashMap<String, [Option<u32>; 4]>,
    /// Irregular form -> (part of speech, lemma).
    irregular: HashMap<String, Vec<(Upos, String)>>,
    lemma_exceptions: HashMap<String, String>,
    /// Suffix rules per open-class part of speech (adverbs have none).
    suffixes: [Vec<(String, String)>; 4],
    /// Ending -> tag for unknown words, longest ending first.
    guess: Vec<(String, Upos)>,
    context: Context,
}

fn tagger() -> Result<&'static Tagger, CaptionError> {
    static TAGGER: OnceLock<Result<Tagger, TaggerDataError>> = OnceLock::new();
    TAGGER
        .get_or_init(|| Tagger::load(RULES_TOML, LEXICON_TSV, EXCEPTIONS_TSV))
        .as_ref()
        .map_err(CaptionError::Rules)
}

fn open_index(tag: Upos) -> Option<usize> {
    OPEN.iter().position(|&t| t == tag)
}

impl Tagger {
    fn load(rules: &str, lexicon: &str, exceptions: &str) -> Result<Tagger, TaggerDataError> {
        let file: RulesFile = toml::from_str(rules).map_err(TaggerDataError::Rules)?;
        let tags = |s: &str, entry: &str| -> Result<Vec<Upos>, TaggerDataError> {
            let v: Vec<Upos> = s
                .split_whitespace()
                .map(|tag| {
                    Upos::from_str(tag).map_err(|_| TaggerDataError::UnknownTag {
                        entry: entry.to_string(),
                        tag: tag.to_string(),
                    })
                })
                .collect::<Result<_, _>>()?;
            if v.is_empty() {
                return Err(TaggerDataError::NoTag {
                    entry: entry.to_string(),
                });
            }
            Ok(v)
        };
        let mut closed = HashMap::new();
        for (word, spec) in &file.closed {
            closed.insert(word.clone(), tags(spec, &format!("[closed] {word}"))?);
        }
        let mut suffixes: [Vec<(String, String)>; 4] = Default::default();
        for (pos, list) in &file.lemma.rules {
            let tag = tags(pos, "[lemma.rules]")?[0];
            let i = open_index(tag)
                .ok_or_else(|| TaggerDataError::NotOpenClass { tag: pos.clone() })?;
            suffixes[i] = list.iter().map(|[a, b]| (a.clone(), b.clone())).collect();
        }
        let mut guess = Vec::new();
        for (ending, tag) in &file.guess {
            guess.push((ending.clone(), tags(tag, &format!("[guess] {ending}"))?[0]));
        }
        guess.sort_by_key(|(ending, _)| std::cmp::Reverse(ending.len()));
        let lexicon = parse_lexicon(lexicon)?;
        let irregular = parse_exceptions(exceptions)?;
        Ok(Tagger {
            closed,
            lexicon,
            irregular,
            lemma_exceptions: file.lemma.exceptions.into_iter().collect(),
            suffixes,
            guess,
            context: file.context,
        })
    }

    /// The readings WordNet allows a word: as a lemma itself, as an irregular form, or through a
    /// suffix rule whose result is a lemma of that part of speech (WordNet's morphy).
    fn analyse(&self, text: &str) -> Word {
        let lower = text.to_lowercase();
        let alpha = !text.is_empty() && text.chars().all(char::is_alphabetic);
        let closed = self.closed.get(&lower).cloned().unwrap_or_default();
        let mut open: [Option<Reading>; 4] = Default::default();
        if alpha
            && closed
                .iter()
                .all(|t| !matches!(t, Upos::Det | Upos::Pron | Upos::Aux))
        {
            for (i, &tag) in OPEN.iter().enumerate() {
                open[i] = self.reading(&lower, i, tag);
            }
        }
        if alpha && closed.is_empty() && open.iter().all(Option::is_none) {
            let tag = self
                .guess
                .iter()
                .find(|(ending, _)| lower.len() > ending.len() && lower.ends_with(ending.as_str()))
                .map_or(Upos::Noun, |(_, t)| *t);
            if let Some(i) = open_index(tag) {
                open[i] = Some(Reading {
                    form: inflection(&lower, tag),
                    weight: 0.5,
                });
            }
        }
        Word {
            text: text.to_string(),
            lower,
            alpha,
            closed,
            open,
        }
    }

    fn count(&self, word: &str, i: usize) -> Option<u32> {
        self.lexicon.get(word).and_then(|c| c[i])
    }

    fn reading(&self, word: &str, i: usize, tag: Upos) -> Option<Reading> {
        let base = self.count(word, i);
        let irregular = self
            .irregular
            .get(word)
            .and_then(|v| v.iter().find(|(t, _)| *t == tag))
            .map(|(_, lemma)| lemma.clone());
        let derived = irregular.or_else(|| {
            self.suffixes[i]
                .iter()
                .filter(|(end, _)| word.ends_with(end.as_str()))
                .map(|(end, new)| format!("{}{new}", &word[..word.len() - end.len()]))
                .find(|form| !form.is_empty() && self.count(form, i).is_some())
        });
        match (derived, base) {
            (Some(lemma), _) => {
                let weight = f64::from(self.count(&lemma, i).unwrap_or(0)) + 1.0;
                Some(Reading {
                    form: inflection(word, tag),
                    weight,
                })
            }
            (None, Some(n)) => Some(Reading {
                form: Form::Base,
                weight: f64::from(n) + 1.0,
            }),
            (None, None) => None,
        }
    }

    /// spaCy's lemma of an inflected noun or verb (`rule_lemmatize`): its irregular form's lemma,
    /// else of the suffix rules' results that are lemmas the one of the last rule (spaCy puts each
    /// before those found earlier: `swinging` is `swing`, not the verb `swinge` of the rule tried
    /// first), else the first rule's result (`binoculars` is `binocular`, though WordNet lists
    /// the plural as a noun too), else the word.
    fn rule_lemma(&self, word: &str, tag: Upos) -> String {
        let Some(i) = open_index(tag) else {
            return word.to_string();
        };
        if let Some((_, lemma)) = self
            .irregular
            .get(word)
            .and_then(|v| v.iter().find(|(t, _)| *t == tag))
        {
            return lemma.clone();
        }
        let forms: Vec<String> = self.suffixes[i]
            .iter()
            .filter(|(end, _)| word.ends_with(end.as_str()))
            .map(|(end, new)| format!("{}{new}", &word[..word.len() - end.len()]))
            .filter(|form| !form.is_empty())
            .collect();
        forms
            .iter()
            .rev()
            .find(|form| self.count(form, i).is_some())
            .or(forms.first())
            .cloned()
            .unwrap_or_else(|| word.to_string())
    }

    /// Tags a caption's tokens left to right; each decision sees the tags already given and the
    /// readings of the next word.
    fn tag(&self, words: &[Word]) -> Vec<Upos> {
        let mut tags: Vec<Upos> = Vec::with_capacity(words.len());
        for (i, w) in words.iter().enumerate() {
            let prev = i.checked_sub(1).map(|j| tags[j]);
            let before_conj = i
                .checked_sub(2)
                .filter(|_| prev == Some(Upos::Cconj))
                .map(|j| tags[j]);
            let plural_before = i.checked_sub(1).is_some_and(|j| {
                prev == Some(Upos::Noun) && words[j].form(Upos::Noun) == Some(Form::S)
            });
            tags.push(self.decide(w, prev, plural_before, before_conj, words.get(i + 1)));
        }
        tags
    }

    /// One token's tag: the rules docs/humanml3d-captions.md lists, first match wins.
    fn decide(
        &self,
        w: &Word,
        prev: Option<Upos>,
        plural_before: bool,
        before_conj: Option<Upos>,
        next: Option<&Word>,
    ) -> Upos {
        if !w.alpha {
            return if w
                .text
                .chars()
                .all(|c| c.is_ascii_digit() || c == '.' || c == ',')
            {
                Upos::Num
            } else {
                Upos::Punct
            };
        }
        let around = Around {
            prev,
            plural_before,
            before_conj,
            next,
        };
        if self.context.sides.contains(&w.lower) {
            return side_tag(w, &around);
        }
        if let Some(t) = self.closed_tag(w, next) {
            return t;
        }
        self.open_tag(w, &around)
    }

    /// A word of a closed class ("to", "her", "his", the closed lists), else `None`.
    fn closed_tag(&self, w: &Word, next: Option<&Word>) -> Option<Upos> {
        let next_np = next.is_some_and(Word::starts_noun_phrase);
        match w.lower.as_str() {
            "to" => {
                // spaCy reads a bare word that can be a verb after "to" as an infinitive.
                let verb_next = next.is_some_and(|n| {
                    n.closed.is_empty()
                        && n.form(Upos::Verb) == Some(Form::Base)
                        && !self.context.sides.contains(&n.lower)
                });
                return Some(if verb_next { Upos::Part } else { Upos::Adp });
            }
            "her" | "his" => return Some(if next_np { Upos::Det } else { Upos::Pron }),
            _ => {}
        }
        let &first = w.closed.first()?;
        Some(if w.closed.contains(&Upos::Adp) && next_np {
            Upos::Adp
        } else {
            first
        })
    }

    /// A word of the open classes: its only reading, else the rules by its neighbours.
    fn open_tag(&self, w: &Word, around: &Around) -> Upos {
        use Upos::{Adj, Adv, Det, Noun, Num, Verb};
        let (prev, next) = (around.prev, around.next);
        let candidates: Vec<Upos> = OPEN.into_iter().filter(|&t| w.can(t)).collect();
        if let [only] = candidates[..] {
            return only;
        }
        // Coordination: "walk and turn", "arms and legs".
        if let Some(t) = around
            .before_conj
            .filter(|&t| w.can(t) && matches!(t, Noun | Verb | Adj))
        {
            return t;
        }
        let next_np = next.is_some_and(Word::starts_noun_phrase);
        let next_nominal = next.is_some_and(Word::nominal);
        let (noun, verb, adj) = (w.weight(Noun), w.weight(Verb), w.weight(Adj));
        let verb_form = w.form(Verb);
        // An adjective before its noun, when the adjective is the word's usual reading.
        let attributive = w.can(Adj) && next_nominal && adj >= noun.max(verb).max(w.weight(Adv));
        // Adverbs of direction and manner ("forward", "back", "straight") outside noun phrases.
        if w.likeliest() == Some(Adv) && !matches!(prev, Some(Det | Adj | Num)) {
            return Adv;
        }
        // An imperative action label or clause starts with its verb: "kick ball", "then walk".
        let clause_start = matches!(prev, None | Some(Upos::Cconj | Upos::Sconj | Upos::Punct));
        if clause_start && matches!(verb_form, Some(Form::Base | Form::Ing)) && !attributive {
            let ratio = self.context.noun_over_verb_at_start;
            if noun <= ratio * verb || next_np && !next_nominal {
                return Verb;
            }
        }
        if let Some(t) = tag_after_previous(w, around, attributive) {
            return t;
        }
        if attributive {
            return Adj;
        }
        w.likeliest().unwrap_or(Noun)
    }
}

/// What a token's tag decision sees around it: the tags already given and the next word.
struct Around<'w> {
    /// The previous token's tag.
    prev: Option<Upos>,
    /// The previous token is a plural noun.
    plural_before: bool,
    /// The tag before a coordinating conjunction just before.
    before_conj: Option<Upos>,
    next: Option<&'w Word>,
}

/// A side word ("left", "right", ...): a past participle after a function word or ending the
/// caption after a verb is an adjective, else a verb; otherwise an adjective before a noun, a
/// noun after a determiner or adposition, an adverb elsewhere.
fn side_tag(w: &Word, around: &Around) -> Upos {
    use Upos::{Adj, Adp, Adv, Det, Noun, Num, Verb};
    let (prev, next) = (around.prev, around.next);
    if w.form(Verb) == Some(Form::Past) {
        let after_function_word = matches!(prev, Some(Adp | Det | Adj | Num));
        let ends_after_verb = prev == Some(Verb) && next.is_none();
        return if after_function_word || ends_after_verb {
            Adj
        } else {
            Verb
        };
    }
    if next.is_some_and(Word::nominal) {
        Adj
    } else if matches!(prev, Some(Det | Adp)) {
        Noun
    } else {
        Adv
    }
}

/// The rules by the previous tag, for an open-class word that is `attributive` (an adjective
/// before its noun) or not; `None` where they do not decide.
fn tag_after_previous(w: &Word, around: &Around, attributive: bool) -> Option<Upos> {
    use Upos::{Adj, Adp, Adv, Det, Noun, Num, Part, Verb};
    let prev = around.prev;
    let next_nominal = around.next.is_some_and(Word::nominal);
    let (noun, verb) = (w.weight(Noun), w.weight(Verb));
    let verb_form = w.form(Verb);
    match prev {
        // Inside a noun phrase: an adjective before its noun, else the noun.
        Some(Det | Num | Adj | Adp) => {
            if attributive || (w.can(Adj) && next_nominal && !w.can(Noun)) {
                return Some(Adj);
            }
            if prev == Some(Adp) && verb_form == Some(Form::Ing) {
                return Some(Verb);
            }
            if w.can(Noun) {
                return Some(Noun);
            }
        }
        // After a verb: its object, or an adverb of manner or direction.
        Some(Verb | Upos::Aux) => {
            if prev == Some(Upos::Aux) && verb_form.is_some() {
                return Some(Verb);
            }
            if attributive {
                return Some(Adj);
            }
            // The object noun, unless the word is rather an adjective or adverb ("hold still").
            let best = [Noun, Adj, Adv].into_iter().filter(|&t| w.can(t));
            if let Some(t) = best.max_by(|&a, &b| w.weight(a).total_cmp(&w.weight(b))) {
                return Some(t);
            }
        }
        // After a noun or pronoun: its finite verb ("a man kicks", "he walks"), or the head
        // of a compound ("arm swing").
        Some(Noun | Upos::Pron | Upos::Propn) => match verb_form {
            Some(Form::S) if verb >= noun || prev == Some(Upos::Pron) => return Some(Verb),
            Some(Form::Base) if around.plural_before || prev == Some(Upos::Pron) => {
                return Some(Verb);
            }
            Some(Form::Past | Form::Ing) => return Some(Verb),
            _ if w.can(Noun) => return Some(Noun),
            _ => {}
        },
        Some(Part) if verb_form.is_some() => return Some(Verb),
        _ => {}
    }
    None
}

/// The inflection a word's ending shows for a part of speech.
fn inflection(word: &str, tag: Upos) -> Form {
    match tag {
        Upos::Verb if word.ends_with("ing") => Form::Ing,
        Upos::Verb if word.ends_with("ed") => Form::Past,
        Upos::Verb | Upos::Noun if word.ends_with('s') && !word.ends_with("ss") => Form::S,
        Upos::Verb => Form::Past,
        _ => Form::Base,
    }
}

fn parse_lexicon(text: &str) -> Result<HashMap<String, [Option<u32>; 4]>, TaggerDataError> {
    let mut map = HashMap::with_capacity(80_000);
    for (n, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.is_empty() {
            continue;
        }
        let bad = |problem: LexiconLine| TaggerDataError::Lexicon {
            line: n + 1,
            problem,
            text: line.to_string(),
        };
        let mut cells = line.split('\t');
        let word = cells
            .next()
            .filter(|w| !w.is_empty())
            .ok_or_else(|| bad(LexiconLine::NoWord))?;
        let mut counts = [None; 4];
        for c in &mut counts {
            let cell = cells.next().ok_or_else(|| bad(LexiconLine::Short))?;
            *c = match cell {
                "-" => None,
                n => Some(n.parse::<u32>().map_err(|_| bad(LexiconLine::Count))?),
            };
        }
        if cells.next().is_some() || counts.iter().all(Option::is_none) {
            return Err(bad(LexiconLine::Shape));
        }
        map.insert(word.to_string(), counts);
    }
    Ok(map)
}

fn parse_exceptions(text: &str) -> Result<HashMap<String, Vec<(Upos, String)>>, TaggerDataError> {
    let mut map: HashMap<String, Vec<(Upos, String)>> = HashMap::new();
    for (n, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.is_empty() {
            continue;
        }
        let bad = || TaggerDataError::Exception {
            line: n + 1,
            text: line.to_string(),
        };
        let [form, tag, lemma] = line.split('\t').collect::<Vec<_>>()[..] else {
            return Err(bad());
        };
        let tag = Upos::from_str(tag)
            .ok()
            .filter(|t| open_index(*t).is_some())
            .ok_or_else(bad)?;
        map.entry(form.to_string())
            .or_default()
            .push((tag, lemma.to_string()));
    }
    Ok(map)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bundled_data_loads() {
        let t = tagger().map_err(|e| e.to_string()).unwrap();
        assert!(t.lexicon.len() > 50_000);
        assert!(t.irregular.contains_key("feet"));
    }

    #[test]
    fn invalid_data_is_refused_with_its_line() {
        let err = Tagger::load(RULES_TOML, "walk\t1\tx\t-\t-\n", EXCEPTIONS_TSV)
            .err()
            .unwrap();
        assert!(
            matches!(
                err,
                TaggerDataError::Lexicon {
                    line: 1,
                    problem: LexiconLine::Count,
                    ..
                }
            ),
            "{err:?}"
        );
        assert!(err.to_string().contains("pos-lexicon.tsv line 1"), "{err}");
        let err = Tagger::load(RULES_TOML, LEXICON_TSV, "feet\tNOUN\n")
            .err()
            .unwrap();
        assert!(
            err.to_string().contains("pos-exceptions.tsv line 1"),
            "{err}"
        );
        let err = Tagger::load(
            "[closed]\nthe = \"DETERMINER\"\n",
            LEXICON_TSV,
            EXCEPTIONS_TSV,
        )
        .err()
        .unwrap();
        assert!(matches!(err, TaggerDataError::Rules(_)), "{err:?}");
        assert!(err.to_string().contains("caption-tagger.toml"), "{err}");
    }

    #[test]
    fn penn_tags_map_as_spacy_2_3_4_maps_them() {
        assert_eq!(pos234("PRP$", "his"), Upos::Det);
        assert_eq!(pos234("MD", "can"), Upos::Verb);
        assert_eq!(pos234("VBZ", "is"), Upos::Aux);
        assert_eq!(pos234("VBZ", "Is"), Upos::Aux);
        assert_eq!(pos234("VBZ", "IS"), Upos::Verb);
        assert_eq!(pos234("IN", "while"), Upos::Sconj);
        assert_eq!(pos234("NN", "someone"), Upos::Pron);
        assert_eq!(pos234("RB", "n't"), Upos::Part);
        assert_eq!(pos234("RP", "up"), Upos::Adp);
        assert_eq!(pos234("no such tag", "walk"), Upos::X);
    }

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
