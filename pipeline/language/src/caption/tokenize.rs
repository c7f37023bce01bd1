//! spaCy's tokenisation of a caption, as `en_core_web_sm` splits it before tagging: words, the
//! clitics its exceptions split off (`doesn't` -> `does` `n't`), units after numbers (`5km` ->
//! `5` `km`), and the whitespace after each piece, one of the tagger's inputs.

/// One token of spaCy's tokenisation of a caption.
pub(super) struct Piece {
    pub(super) text: String,
    /// Whitespace follows it (spaCy's `whitespace_`, one of the tagger's inputs).
    pub(super) space_after: bool,
    /// The string spaCy's tokenizer exceptions would match (`doesn't` for `does` and `n't`),
    /// with this token's place among the `parts` it splits into.
    pub(super) chunk: String,
    pub(super) part: usize,
    pub(super) parts: usize,
}

impl Piece {
    fn whole(text: &str) -> Piece {
        Piece {
            text: text.to_string(),
            space_after: false,
            chunk: text.to_string(),
            part: 0,
            parts: 1,
        }
    }
}

/// spaCy's English tokenizer as far as it matters for these captions: whitespace splits,
/// punctuation comes off both ends, `,` `/` `:` `<` `>` `=` between letters split off as their
/// own tokens, and clitics ("n't", "'s", "'re", ...) come off the end.
pub(super) fn split_words(sentence: &str) -> Vec<Piece> {
    let mut out: Vec<Piece> = Vec::new();
    // Text and whitespace alternate; one space after a token is its `space_after`, any other
    // whitespace becomes a whitespace token of its own, as spaCy's tokenizer does.
    let mut rest = sentence;
    while !rest.is_empty() {
        let ws = rest.len() - rest.trim_start().len();
        if ws > 0 {
            let mut run = &rest[..ws];
            if !out.is_empty() && run.starts_with(' ') {
                if let Some(last) = out.last_mut() {
                    last.space_after = true;
                }
                run = &run[1..];
            }
            if !run.is_empty() {
                out.push(Piece::whole(run));
            }
            rest = &rest[ws..];
            continue;
        }
        let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
        let chunk = &rest[..end];
        rest = &rest[end..];
        let core = chunk.trim_matches(|c: char| !c.is_alphanumeric() && c != '\'');
        let lead = &chunk[..chunk.find(core).unwrap_or(0)];
        // A single letter keeps its period ("t.") as one token, as spaCy's exceptions do.
        let tail_start = lead.len() + core.len();
        let keeps_period = core.chars().count() == 1
            && chunk[tail_start..].starts_with('.')
            && core.chars().all(char::is_alphabetic);
        if !lead.is_empty() {
            out.push(Piece::whole(lead));
        }
        let first = out.len();
        let mut pieces = Vec::new();
        let mut from = 0;
        for (at, sep) in core.match_indices([',', '/', ':', '<', '>', '=']) {
            pieces.push(&core[from..at]);
            pieces.push(sep);
            from = at + sep.len();
        }
        pieces.push(&core[from..]);
        let mut last_was_word = false;
        for piece in pieces {
            if piece.len() == 1 && ",/:<>=".contains(piece) {
                if last_was_word {
                    out.push(Piece::whole(piece));
                }
                last_was_word = false;
                continue;
            }
            let piece = piece.trim_matches('\'');
            if piece.is_empty() {
                continue;
            }
            last_was_word = true;
            if let Some(cut) = unit_after_number(piece) {
                out.push(Piece::whole(&piece[..cut]));
                out.push(Piece::whole(&piece[cut..]));
                continue;
            }
            let (base, clitic) = split_clitic(piece);
            let base = if keeps_period {
                format!("{base}.")
            } else {
                base.to_string()
            };
            let chunk_text = if keeps_period {
                base.clone()
            } else {
                piece.to_string()
            };
            let parts = usize::from(!base.is_empty()) + usize::from(clitic.is_some());
            for (part, text) in [Some(base.as_str()).filter(|b| !b.is_empty()), clitic]
                .into_iter()
                .flatten()
                .enumerate()
            {
                out.push(Piece {
                    text: text.to_string(),
                    space_after: false,
                    chunk: chunk_text.clone(),
                    part,
                    parts,
                });
            }
        }
        // A separator with no word after it was not between letters: spaCy leaves it attached.
        if out.len() > first
            && out
                .last()
                .is_some_and(|p| p.text.len() == 1 && ",/:<>=".contains(&p.text))
        {
            out.pop();
        }
        if tail_start < chunk.len() && !keeps_period {
            out.push(Piece::whole(&chunk[tail_start..]));
        }
    }
    out
}

/// The units spaCy's tokenizer splits off a number they follow (`50cm` -> `50` `cm`), those of
/// its list (`spacy/lang/char_classes.py`) written in Latin letters; `m/s` and `km/h` are split at
/// their `/` first.
const UNITS: [&str; 45] = [
    "km", "km²", "km³", "m", "m²", "m³", "dm", "dm²", "dm³", "cm", "cm²", "cm³", "mm", "mm²",
    "mm³", "ha", "µm", "nm", "yd", "in", "ft", "kg", "g", "mg", "µg", "t", "lb", "oz", "kmh",
    "mph", "hPa", "Pa", "mbar", "mb", "MB", "kb", "KB", "gb", "GB", "tb", "TB", "T", "G", "M", "K",
];

/// Where a unit glued to a number starts in `word` (`50cm`: 2), as spaCy's suffix rule
/// `(?<=[0-9])(?:km|...)` splits it: the unit ends the word and a digit comes right before it.
fn unit_after_number(word: &str) -> Option<usize> {
    UNITS
        .iter()
        .filter_map(|unit| {
            let cut = word.len().checked_sub(unit.len())?;
            (word.ends_with(unit) && word[..cut].ends_with(|c: char| c.is_ascii_digit()))
                .then_some(cut)
        })
        .min()
}

/// Splits a trailing clitic off: "doesn't" -> ("does", "n't"), "person's" -> ("person", "'s").
fn split_clitic(word: &str) -> (&str, Option<&str>) {
    let lower = word.to_lowercase();
    if lower.len() == word.len() {
        if lower.ends_with("n't") && word.len() > 3 {
            let cut = word.len() - 3;
            return (&word[..cut], Some(&word[cut..]));
        }
        for clitic in ["'s", "'re", "'ve", "'ll", "'d", "'m"] {
            if lower.ends_with(clitic) && word.len() > clitic.len() {
                let cut = word.len() - clitic.len();
                return (&word[..cut], Some(&word[cut..]));
            }
        }
    }
    (word, None)
}
