//! The tagger data compiled into the crate and what is read from it: each word's readings from
//! the lexicon (`schemas/pos-lexicon.tsv`, WordNet's irregular forms), the lemmatiser HumanML3D's
//! nouns and verbs go through, and the rule-based tagger that preceded spaCy's network
//! ([`rule_tokens`], context rules from `schemas/caption-tagger.toml`), kept for comparison.

use std::collections::{BTreeMap, HashMap};
use std::str::FromStr;
use std::sync::OnceLock;

use serde::Deserialize;

use super::tokenize::split_words;
use super::{CaptionError, Token, Upos, check_length, finish};

const RULES_TOML: &str = include_str!("../../../../schemas/caption-tagger.toml");
const LEXICON_TSV: &str = include_str!("../../../../schemas/pos-lexicon.tsv");
const EXCEPTIONS_TSV: &str = include_str!("../../../../schemas/pos-exceptions.tsv");

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

/// [`tokens`](super::tokens) as the rule-based tagger that preceded the perceptron tags them
/// (context rules over the lexicon's readings; `docs/humanml3d-captions.md`), kept to compare the
/// two.
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
pub(super) struct Word {
    text: String,
    lower: String,
    pub(super) alpha: bool,
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
    pub(super) fn output(&self, tag: Upos, base: bool, tagger: &Tagger) -> String {
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
pub(super) struct Tagger {
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

pub(super) fn tagger() -> Result<&'static Tagger, CaptionError> {
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
    pub(super) fn analyse(&self, text: &str) -> Word {
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
}
