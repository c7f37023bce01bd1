//! A text read against the lexicon (steps 1 and 2 of the module doc): lower-case tokens in
//! clauses, verbs lemmatised, the longest lexicon phrase at each position, words whose sense
//! depends on their neighbours reinterpreted, and the side words before a phrase.

use super::table::{Kind, Side, T, WordSet, lexicon, strong};

/// The lemma of a word for matching actions: irregular forms, then suffix stripping until a known
/// action word comes out; other words stay as they are.
pub(super) fn lemma(word: &str) -> String {
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
pub(super) struct Token {
    pub(super) raw: String,
    pub(super) lemma: String,
    pub(super) clause: usize,
}

pub(super) fn tokenize(text: &str) -> Vec<Token> {
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
pub(super) struct Hit {
    /// First token.
    pub(super) start: usize,
    /// One past the last token.
    pub(super) end: usize,
    pub(super) kind: Kind,
    pub(super) phrase: String,
}

pub(super) fn find_hits(tokens: &[Token]) -> Vec<Hit> {
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
pub(super) fn side_before(tokens: &[Token], start: usize, skip: &WordSet) -> Option<Side> {
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
pub(super) fn word_before_phrase(tokens: &[Token], start: usize) -> Option<usize> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lemmas() {
        assert_eq!(lemma("waving"), "wave");
        assert_eq!(lemma("running"), "run");
        assert_eq!(lemma("walks"), "walk");
        assert_eq!(lemma("stepped"), "step");
        assert_eq!(lemma("ran"), "run");
        assert_eq!(lemma("hands"), "hands");
    }
}
