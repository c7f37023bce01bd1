//! The coarse part-of-speech tags HumanML3D's files carry ([`Upos`], Universal POS as spaCy
//! spells them) and spaCy 2.3.4's table from a Penn Treebank tag to one ([`pos234`]).

use std::fmt;
use std::str::FromStr;

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

#[cfg(test)]
mod tests {
    use super::*;

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
}
