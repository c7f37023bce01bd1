//! SINC's post-processing of an LLM answer to the body-part list prompt (`text_list_to_bp` in
//! `sinc/tools/frank.py`), without its debugger-on-surprise: anything that is neither on the list
//! nor a known synonym is reported, never guessed.
//!
//! The prompt (SINC appendix B, third variant) asks the model to choose from
//! `left arm, right arm, left leg, right leg, torso, neck, buttocks, waist`; the answer is one part
//! per line after `Answer:`.
//!
//! Normalisation, in order: lowercase; drop a leading `answer` (with or without `:`); split into
//! items on newlines, commas, semicolons and the word `and`; remove punctuation inside each item
//! (apostrophes vanish, other marks become spaces), collapse spaces, drop leading list numbers and
//! a leading `the`, `my` or `a`; drop empty items.
//!
//! Mapping (SINC's own rules first, then the synonyms this crate adds):
//!
//! | item | parts | source |
//! |---|---|---|
//! | `left arm`, `right arm`, `left leg`, `right leg`, `torso` | itself | the list |
//! | `neck` | torso | the list, SINC maps it |
//! | `waist`, `buttocks` | global | the list, SINC maps it |
//! | `shoulders` | both arms, unless an arm is listed | SINC |
//! | `left shoulder`, `right shoulder` | that arm | SINC |
//! | `global orientation`, `global` | global | SINC's first two prompt variants |
//! | `hips`, `hip`, `pelvis`, `butt` | global | added |
//! | `arms`, `hands`, `both arms`, `wrists`, `elbows` | both arms | added |
//! | `left hand`, `right wrist`, `left elbow`, ... | that arm | added |
//! | `legs`, `feet`, `knees`, `ankles` | both legs | added |
//! | `left foot`, `right knee`, `left hip`, ... | that leg | added |
//! | `head`, `chest`, `back`, `lower back`, `spine`, `abdomen`, `upper body` | torso | added |
//! | `whole body`, `full body`, `entire body`, `all of the above` | all six | added |
//!
//! Not mapped, so reported in [`ParsedAnswer::off_list`]:
//!
//! * a hand, arm, wrist, elbow, finger, foot, leg, knee or ankle **without a side** (`hand`,
//!   `wrist`): which limb is meant is a guess. SINC drops `hand` and `wrist` silently; we drop them
//!   too (no part added) but say so.
//! * face features (`right side of face`, `right eye`, `mouth`, ...): in the real answers they are
//!   what a hand touches, not what moves (`touch right eye with right hand` -> `right arm`,
//!   `right eye`). SINC drops them; so do we, flagged.
//! * refusals (`None of the above.`, `This question does not have a specific answer ...`): no part;
//!   the answer is also [`ParsedAnswer::empty`]. SINC forces five such texts ("animal behavior
//!   series", "swim on air", ...) to all six parts by name; that is a per-text override for the
//!   caller, not the parser's business.

use super::PartSet;
use motionforge_core::motion::BodyPart;

/// The eight words of SINC's third prompt, in the prompt's order.
pub const PROMPT_LIST: [&str; 8] = [
    "left arm",
    "right arm",
    "left leg",
    "buttocks",
    "waist",
    "right leg",
    "torso",
    "neck",
];

/// Items outside [`PROMPT_LIST`] that map to parts (besides `shoulders`, which depends on the rest
/// of the answer). Sided items name their side; plural items mean both sides.
pub const SYNONYMS: &[(&str, &[BodyPart])] = {
    use BodyPart::*;
    &[
        ("global orientation", &[Global]),
        ("global", &[Global]),
        ("hips", &[Global]),
        ("hip", &[Global]),
        ("pelvis", &[Global]),
        ("butt", &[Global]),
        ("left shoulder", &[LeftArm]),
        ("right shoulder", &[RightArm]),
        ("left hand", &[LeftArm]),
        ("right hand", &[RightArm]),
        ("left wrist", &[LeftArm]),
        ("right wrist", &[RightArm]),
        ("left elbow", &[LeftArm]),
        ("right elbow", &[RightArm]),
        ("left forearm", &[LeftArm]),
        ("right forearm", &[RightArm]),
        ("left upper arm", &[LeftArm]),
        ("right upper arm", &[RightArm]),
        ("left fingers", &[LeftArm]),
        ("right fingers", &[RightArm]),
        ("arms", &[LeftArm, RightArm]),
        ("both arms", &[LeftArm, RightArm]),
        ("hands", &[LeftArm, RightArm]),
        ("both hands", &[LeftArm, RightArm]),
        ("wrists", &[LeftArm, RightArm]),
        ("elbows", &[LeftArm, RightArm]),
        ("forearms", &[LeftArm, RightArm]),
        ("left foot", &[LeftLeg]),
        ("right foot", &[RightLeg]),
        ("left knee", &[LeftLeg]),
        ("right knee", &[RightLeg]),
        ("left ankle", &[LeftLeg]),
        ("right ankle", &[RightLeg]),
        ("left thigh", &[LeftLeg]),
        ("right thigh", &[RightLeg]),
        ("left hip", &[LeftLeg]),
        ("right hip", &[RightLeg]),
        ("legs", &[LeftLeg, RightLeg]),
        ("both legs", &[LeftLeg, RightLeg]),
        ("feet", &[LeftLeg, RightLeg]),
        ("both feet", &[LeftLeg, RightLeg]),
        ("knees", &[LeftLeg, RightLeg]),
        ("ankles", &[LeftLeg, RightLeg]),
        ("thighs", &[LeftLeg, RightLeg]),
        ("head", &[Torso]),
        ("chest", &[Torso]),
        ("back", &[Torso]),
        ("upper back", &[Torso]),
        ("lower back", &[Torso]),
        ("spine", &[Torso]),
        ("abdomen", &[Torso]),
        ("stomach", &[Torso]),
        ("upper body", &[Torso]),
        (
            "whole body",
            &[Global, Torso, LeftArm, RightArm, LeftLeg, RightLeg],
        ),
        (
            "full body",
            &[Global, Torso, LeftArm, RightArm, LeftLeg, RightLeg],
        ),
        (
            "entire body",
            &[Global, Torso, LeftArm, RightArm, LeftLeg, RightLeg],
        ),
        (
            "all of the above",
            &[Global, Torso, LeftArm, RightArm, LeftLeg, RightLeg],
        ),
    ]
};

/// An LLM answer read into parts.
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct ParsedAnswer {
    /// The parts named, after SINC's mapping and the synonyms.
    pub parts: PartSet,
    /// Items neither on the prompt's list nor a known synonym, normalised, in answer order. They
    /// add no part.
    pub off_list: Vec<String>,
    /// Items not on the prompt's list that a synonym mapped (`shoulders`, `right shoulder`,
    /// `hands`, ...), normalised, in answer order.
    pub synonyms: Vec<String>,
    /// No part at all came out of the answer.
    pub empty: bool,
}

impl ParsedAnswer {
    /// The answer needs a look: it has unmapped items or no part. Flagged answers are never
    /// completed by guessing.
    pub fn is_flagged(&self) -> bool {
        self.empty || !self.off_list.is_empty()
    }

    /// The answer used words outside the prompt's list, whether or not a synonym mapped them.
    pub fn has_raw_off_list(&self) -> bool {
        !self.off_list.is_empty() || !self.synonyms.is_empty()
    }
}

/// Splits an answer into normalised items (see the module doc).
pub fn answer_items(answer: &str) -> Vec<String> {
    let lower = answer.to_lowercase();
    let body = strip_answer_prefix(lower.trim());
    let mut items = Vec::new();
    for piece in body.split(['\n', '\r', ',', ';']) {
        for part in split_on_and(piece) {
            let item = clean_item(part);
            if !item.is_empty() {
                items.push(item);
            }
        }
    }
    items
}

/// Drops a leading `answer` / `answer:`; SINC deletes the word anywhere, which would also eat it
/// inside a refusal, so only the prefix goes.
fn strip_answer_prefix(s: &str) -> &str {
    match s.strip_prefix("answer") {
        Some(rest) if rest.starts_with([':', ' ', '\n', '-', '\t']) || rest.is_empty() => {
            rest.trim_start_matches(|c: char| c == ':' || c == '-' || c.is_whitespace())
        }
        _ => s,
    }
}

/// Splits on the whole word `and` (`left arm and right arm`), keeping `hand` and `band` whole.
fn split_on_and(piece: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut start = 0;
    let words: Vec<(usize, &str)> = piece
        .split_whitespace()
        .map(|w| {
            // Byte offset of the word inside `piece`: split_whitespace yields subslices of it.
            (w.as_ptr() as usize - piece.as_ptr() as usize, w)
        })
        .collect();
    for (offset, word) in words {
        let bare = word.trim_matches(|c: char| !c.is_alphanumeric());
        if bare == "and" || word == "&" {
            out.push(&piece[start..offset]);
            start = offset + word.len();
        }
    }
    out.push(&piece[start..]);
    out
}

/// Punctuation out, spaces collapsed, bullets, numbers and articles off the front.
fn clean_item(raw: &str) -> String {
    let mut s = String::with_capacity(raw.len());
    for c in raw.chars() {
        if c == '\'' || c == '’' {
            continue;
        }
        s.push(if c.is_alphanumeric() { c } else { ' ' });
    }
    let mut words: Vec<&str> = s.split_whitespace().collect();
    // "1. left arm", "- torso", "the left arm": the list marker or article carries no meaning.
    while let Some(first) = words.first() {
        if first.chars().all(|c| c.is_ascii_digit()) || matches!(*first, "the" | "my" | "a") {
            words.remove(0);
        } else {
            break;
        }
    }
    words.join(" ")
}

fn list_part(item: &str) -> Option<BodyPart> {
    match item {
        "left arm" => Some(BodyPart::LeftArm),
        "right arm" => Some(BodyPart::RightArm),
        "left leg" => Some(BodyPart::LeftLeg),
        "right leg" => Some(BodyPart::RightLeg),
        "torso" | "neck" => Some(BodyPart::Torso),
        "buttocks" | "waist" => Some(BodyPart::Global),
        _ => None,
    }
}

/// Reads an answer to SINC's list prompt. Infallible: whatever it cannot map it reports.
///
/// ```
/// use motionforge_core::motion::BodyPart;
/// use motionforge_language::parts::answer::parse_part_answer;
///
/// let a = parse_part_answer("Answer: right leg\nleft leg\nbuttocks");
/// assert_eq!(a.parts.to_string(), "global, left_leg, right_leg");
/// assert!(!a.is_flagged());
///
/// let b = parse_part_answer("Answer: right arm\nright eye");
/// assert_eq!(b.parts.to_string(), "right_arm");
/// assert_eq!(b.off_list, ["right eye"]);
///
/// let c = parse_part_answer("Answer: None of the above.");
/// assert!(c.empty && c.is_flagged());
/// ```
pub fn parse_part_answer(answer: &str) -> ParsedAnswer {
    let items = answer_items(answer);
    let arm_listed = items.iter().any(|i| {
        matches!(
            list_part(i).or_else(|| synonym(i).and_then(|p| p.first().copied())),
            Some(BodyPart::LeftArm | BodyPart::RightArm)
        )
    });
    let mut out = ParsedAnswer::default();
    for item in items {
        if let Some(part) = list_part(&item) {
            out.parts.insert(part);
        } else if item == "shoulders" || item == "both shoulders" {
            // SINC: shrugging names the shoulders; they belong to the arm chains (collar bones),
            // but an answer that already lists an arm has said which.
            if !arm_listed {
                out.parts |= PartSet::ARMS;
            }
            out.synonyms.push(item);
        } else if let Some(parts) = synonym(&item) {
            out.parts |= PartSet::from_parts(parts);
            out.synonyms.push(item);
        } else {
            out.off_list.push(item);
        }
    }
    out.empty = out.parts.is_empty();
    out
}

fn synonym(item: &str) -> Option<&'static [BodyPart]> {
    SYNONYMS.iter().find(|(s, _)| *s == item).map(|(_, p)| *p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn list_items_and_sinc_mapping() {
        let a = parse_part_answer("Answer: right leg\nleft leg\nbuttocks\nwaist\ntorso\nneck");
        assert_eq!(
            a.parts,
            PartSet::from_parts(&[
                BodyPart::Global,
                BodyPart::Torso,
                BodyPart::LeftLeg,
                BodyPart::RightLeg
            ])
        );
        assert!(a.off_list.is_empty() && a.synonyms.is_empty() && !a.empty);
    }

    #[test]
    fn commas_and_and_split_items() {
        let a = parse_part_answer("answer: Left arm, right arm and torso.");
        assert_eq!(a.parts.to_string(), "torso, left_arm, right_arm");
        let b = parse_part_answer("Left hand & right hand");
        assert_eq!(b.parts, PartSet::ARMS);
        // `hand` is not split by the `and` rule.
        assert_eq!(parse_part_answer("hands").parts, PartSet::ARMS);
    }

    #[test]
    fn shoulders_follow_sinc() {
        assert_eq!(
            parse_part_answer("Answer: shoulders\ntorso")
                .parts
                .to_string(),
            "torso, left_arm, right_arm"
        );
        assert_eq!(
            parse_part_answer("Answer: shoulders\nright arm")
                .parts
                .to_string(),
            "right_arm"
        );
        let a = parse_part_answer("Answer: left arm\nright shoulder");
        assert_eq!(a.parts, PartSet::ARMS);
        assert_eq!(a.synonyms, ["right shoulder"]);
        assert!(!a.is_flagged() && a.has_raw_off_list());
    }

    #[test]
    fn sideless_limbs_and_refusals_are_flagged() {
        let a = parse_part_answer("Answer: left arm\nhand");
        assert_eq!(a.parts.to_string(), "left_arm");
        assert_eq!(a.off_list, ["hand"]);
        let b = parse_part_answer("Answer: None, as this action is not possible.");
        assert!(b.empty);
        assert_eq!(b.off_list, ["none", "as this action is not possible"]);
        let c = parse_part_answer("");
        assert!(c.empty && c.off_list.is_empty() && c.is_flagged());
    }

    #[test]
    fn whole_body_is_everything() {
        assert_eq!(parse_part_answer("Whole body").parts, PartSet::ALL);
    }

    #[test]
    fn answer_word_only_dropped_at_the_start() {
        assert_eq!(answer_items("Answer:torso"), ["torso"]);
        assert_eq!(answer_items("answers vary"), ["answers vary"]);
    }
}
