//! The embedded part labeller: an action text to SINC's six parts from a lexicon, offline,
//! instant and deterministic. It stands in for the GPT-3 query of SINC section 3.1.
//!
//! # How a text is read
//!
//! 1. **Tokens.** Lowercase words (letters and digits; apostrophes vanish so `arm's` is `arms`).
//!    Verbs are lemmatised against the lexicon (`waving` -> `wave`, `ran` -> `run`); body-part nouns
//!    keep their number (`hand` and `hands` differ). Clauses break at punctuation and at `and`,
//!    `then`, `while`, `before`, `after`, `during`, `when`, `or`, `but`.
//! 2. **Entries.** At each position the longest lexicon phrase wins (`stand up` over `stand`).
//!    An entry is a body-part noun, an action, an object noun or a face feature.
//! 3. **Body-part nouns** (`left hand`, `knees`, `head`, `waist`...). A side word just before the
//!    noun (over `the`, `upper`, `both`, ... ) gives the side; plural or `both` means both sides;
//!    a singular limb with no side (`wave hand`, `one leg`) also means both sides, because the text
//!    does not say which and GPT-3's answers on BABEL's texts do the same. A noun after a location
//!    preposition (`to the head`, `hands on hips`, `in front of chest`) or as the object of a
//!    contact verb (`scratch head`, `hold left leg`) is a *target*: it does not move, the hand that
//!    reaches it does. A particle after a verb is not a place (`lift up left leg`, `shake off
//!    right foot`: the leg is the verb's object and moves), and a held limb posed by a particle
//!    moves itself (`hold left leg up`). Two exceptions, both from how bodies work: a hand, arm, wrist, elbow or
//!    finger is involved even as a target (`touch left hand with right hand` moves both arms to
//!    meet), and a leg after `on` with no hand before it is a support (`stand on left leg`,
//!    `hop on one foot`). A noun followed by `level`, `height`, `width`, ... is a measure
//!    (`waist level`) and ignored. Face features (`face`, `mouth`, `chin`, `ear`...) are never
//!    parts: they are what a hand touches.
//! 4. **Actions** have a strength:
//!    * *strong* actions always add their parts (`walk`: global + both legs; `look`: torso);
//!    * *limb* actions (`wave`, `punch`, `kick`, `throw`, contact verbs such as `grab`) name a limb
//!      but not which one: a moving limb noun in the same clause says which (`wave right hand`,
//!      `kick with left foot`, `tap foot`), else a side word next to the verb (`right front kick`,
//!      `punch left`), else `with the left`, else the side of what an arm action touches
//!      (`scratch right ear`: right arm; a shoulder is reached by the other hand), else both;
//!    * *generic* verbs (`raise`, `lift`, `move`, `bend`, `turn`, `stretch`...) take their parts
//!      from the nouns of their clause and fall back to a default only when the clause has none
//!      (`bend` alone: global + torso; `bend knees`: both legs; `turn left`: global + torso + both
//!      legs; `turn head`: torso; `push`: both arms + torso, `push with right arm`: right arm);
//!    * an action word right after a preposition (`in`, `on`, `at`, `from`, `across`...) is a
//!      noun (`walk in circles`, `walk in hook pattern`, `walk across a plank`), unless it names a
//!      posture held there (`stand in fighting pose`);
//!    * *weak* words (`stand`, `pose`, `exercise`, `talk`) count only when nothing else in the
//!      whole text does.
//! 5. **Objects** (`object`, `phone`, `ball`, `cup`...) mean the hands in a clause with no action
//!    and no body part, and turn a whole-body generic verb into a hand action (`move item`); not
//!    after a location preposition (`sit on chair`).
//! 6. The text's parts are the union over clauses. A text where nothing fires is *unknown*
//!    ([`TextLabel::known`] is `false`) and gets [`UNKNOWN_DEFAULT`], both arms: the most common
//!    answer of GPT-3 on BABEL's 6,518 texts, and the majority on the two parts (the arms) that
//!    GPT-3 marks for more than half of them.
//!
//! Conventions chosen (and where they come from): parts are the ones the action needs, not the
//! ones that may come along (walking swings the arms; SINC's annotators mark such parts
//! "sometimes", which does not count); global (the pelvis: root translation and orientation) comes
//! with every action that moves or turns the whole body or lowers the hips (walk, jump, turn
//! around, sit, kneel, bow, lean); torso comes with looking, nodding, bending, leaning, bowing and
//! twisting, not with arm actions. Defaults were checked against GPT-3's answers on BABEL's texts
//! (training data); the manual gold labels were not used to build the lexicon (see
//! `docs/part-labels.md`).
//!
//! This file holds the labeller's answer and [`label_text`]. The lexicon's word tables, read from
//! `schemas/lexicon.toml` and checked once, are in `table.rs`; reading a text into tokens,
//! lemmas and lexicon hits (steps 1 and 2) in `lookup.rs`; the roles of part nouns and each
//! clause's parts (steps 3 to 6) in `clause.rs`.

mod clause;
mod lookup;
mod table;

use self::clause::{ClauseWords, Labelling, noun_roles};
use self::lookup::{find_hits, tokenize};
pub use self::table::{LexiconError, MeaningProblem, check_lexicon};
use super::PartSet;

/// What an unknown text gets: both arms (see the module doc).
pub const UNKNOWN_DEFAULT: PartSet = PartSet::ARMS;

/// The embedded labeller's answer for one text.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TextLabel {
    /// The parts involved.
    pub parts: PartSet,
    /// The lexicon entries that contributed, in text order (`walk`, `left hand`, ...).
    pub matched: Vec<String>,
    /// `false` when no entry fired and `parts` is [`UNKNOWN_DEFAULT`].
    pub known: bool,
}

/// Labels an action text with SINC's six parts (see the module doc for the rules).
///
/// ```
/// use motionforge_language::parts::lexicon::label_text;
///
/// assert_eq!(label_text("walk forward").parts.to_string(), "global, left_leg, right_leg");
/// assert_eq!(label_text("wave with left hand").parts.to_string(), "left_arm");
/// assert_eq!(label_text("right front kick").parts.to_string(), "right_leg");
/// assert_eq!(label_text("scratch head").parts.to_string(), "left_arm, right_arm");
/// assert_eq!(label_text("look to the right").parts.to_string(), "torso");
/// let unknown = label_text("xyzzy");
/// assert!(!unknown.known);
/// ```
pub fn label_text(text: &str) -> TextLabel {
    let tokens = tokenize(text);
    let hits = find_hits(&tokens);
    let clauses = tokens.last().map(|t| t.clause + 1).unwrap_or(0);
    let roles = noun_roles(&tokens, &hits, clauses);
    let mut label = Labelling::default();
    for clause in 0..clauses {
        let in_clause: Vec<usize> = (0..hits.len())
            .filter(|&k| tokens[hits[k].start].clause == clause)
            .collect();
        let words = ClauseWords {
            tokens: &tokens,
            hits: &hits,
            roles: &roles,
            in_clause: &in_clause,
        };
        words.label(clause, &mut label);
    }
    label.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parts(text: &str) -> String {
        label_text(text).parts.to_string()
    }

    #[test]
    fn locomotion_and_direction_words() {
        assert_eq!(parts("walk to the left"), "global, left_leg, right_leg");
        assert_eq!(parts("Running"), "global, left_leg, right_leg");
        assert_eq!(parts("turn around"), "global, torso, left_leg, right_leg");
    }

    #[test]
    fn sides_bind_to_nouns_and_limb_actions() {
        assert_eq!(parts("raise right hand"), "right_arm");
        assert_eq!(parts("wave"), "left_arm, right_arm");
        assert_eq!(parts("kick right"), "right_leg");
        assert_eq!(parts("kick to the right"), "left_leg, right_leg");
        assert_eq!(parts("hop on left foot"), "global, left_leg");
        assert_eq!(parts("throw with the left"), "left_arm");
        assert_eq!(parts("left and right hands up"), "left_arm, right_arm");
    }

    #[test]
    fn targets_do_not_move() {
        assert_eq!(parts("hands on hips"), "left_arm, right_arm");
        assert_eq!(parts("touch left knee with right hand"), "right_arm");
        assert_eq!(parts("raise right hand to mouth"), "right_arm");
        assert_eq!(parts("look over right shoulder"), "torso");
        assert_eq!(parts("bend at the waist"), "global, torso");
        assert_eq!(parts("stand on left leg"), "left_leg");
        assert_eq!(parts("place object at waist level"), "left_arm, right_arm");
    }

    /// The failure classes found on BABEL's texts (docs/part-labels.md), each on real texts.
    #[test]
    fn failure_classes() {
        // A limb as the object of a hand verb moves itself; it is not the hand doing it.
        assert_eq!(parts("lift up right foot"), "right_leg");
        assert_eq!(parts("shake off left leg"), "left_leg");
        assert_eq!(parts("hold right leg up"), "right_leg");
        assert_eq!(parts("reach for right foot"), "right_arm");
        assert_eq!(parts("stand while hold leg"), "left_arm, right_arm");
        // A noun in a locative phrase is not the action.
        assert_eq!(
            parts("walk forward in hook pattern"),
            "global, left_leg, right_leg"
        );
        assert_eq!(parts("walk across a plank"), "global, left_leg, right_leg");
        assert_eq!(
            parts("stand in fighting pose"),
            "global, torso, left_arm, right_arm, left_leg, right_leg"
        );
        // Whole-body verbs whose trunk involvement is implicit.
        assert_eq!(parts("spin around"), "global, torso, left_leg, right_leg");
        assert_eq!(
            parts("walk 90 degrees left"),
            "global, torso, left_leg, right_leg"
        );
        assert_eq!(parts("stagger back"), "global, torso, left_leg, right_leg");
        assert_eq!(parts("push object forward"), "torso, left_arm, right_arm");
        assert_eq!(parts("push with right arm"), "right_arm");
        assert_eq!(parts("rotate arms inward"), "left_arm, right_arm");
    }

    #[test]
    fn clauses_combine() {
        assert_eq!(
            parts("walk forward while waving right hand"),
            "global, right_arm, left_leg, right_leg"
        );
        assert_eq!(parts("turn head left"), "torso");
    }

    #[test]
    fn unknown_gets_the_default_and_a_flag() {
        let l = label_text("");
        assert!(!l.known);
        assert_eq!(l.parts, UNKNOWN_DEFAULT);
        assert!(l.matched.is_empty());
        assert!(label_text("stand").known);
    }
}
