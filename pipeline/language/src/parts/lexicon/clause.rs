//! From lexicon hits to parts (steps 3 to 6 of the module doc): whether each part noun moves or
//! is a target, then each clause's moving nouns, actions by strength and handled objects, with
//! the sides they take, added up over the text.

use super::lookup::{Hit, Token, side_before, word_before_phrase};
use super::table::{Kind, Limb, Side, Strength, lexicon};
use super::{PartSet, TextLabel, UNKNOWN_DEFAULT};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Role {
    Moving,
    Target,
    Ignored,
}

/// The role of each hit: a part noun moves or is a target (touched, pointed at); every other hit
/// is ignored here.
pub(super) fn noun_roles(tokens: &[Token], hits: &[Hit], clauses: usize) -> Vec<Role> {
    let mut roles = vec![Role::Ignored; hits.len()];
    let mut previous_part_is_arm = vec![false; clauses];
    for (k, hit) in hits.iter().enumerate() {
        let clause = tokens[hit.start].clause;
        let is_noun = matches!(hit.kind, Kind::Limb { .. } | Kind::Trunk { .. });
        if !is_noun {
            continue;
        }
        let next = tokens.get(hit.end).map(|t| t.raw.as_str()).unwrap_or("");
        if lexicon().measures.contains(next) {
            roles[k] = Role::Ignored;
            continue;
        }
        let target = is_target(tokens, hits, hit, next, previous_part_is_arm[clause]);
        roles[k] = match hit.kind {
            Kind::Limb {
                self_moving: true, ..
            } => Role::Moving,
            _ if target => Role::Target,
            _ => Role::Moving,
        };
        if let Kind::Limb { limb, .. } = hit.kind {
            previous_part_is_arm[clause] = limb == Limb::Arm;
        }
    }
    roles
}

/// Whether a part noun is touched or pointed at rather than moved: the object of a contact
/// verb, or after a location word, but not a leg stood on (`on the left leg`) unless an arm
/// came just before in the clause.
fn is_target(tokens: &[Token], hits: &[Hit], hit: &Hit, next: &str, after_arm: bool) -> bool {
    let clause = tokens[hit.start].clause;
    let before = word_before_phrase(tokens, hit.start)
        .filter(|&j| tokens[j].clause == clause)
        .map(|j| (tokens[j].raw.as_str(), j));
    // The verb this noun is the object of: the action just before it, or before a particle
    // (`lift up left leg`, `shake off right foot`), which then is not a place.
    let verb = before.and_then(|(w, j)| {
        hits.iter().find(|h| {
            matches!(h.kind, Kind::Act { .. })
                && (h.end == j + 1 || (h.end == j && lexicon().particles.contains(w)))
        })
    });
    // `hold left leg up`: a limb held in a pose moves itself; `hold left leg` is touched.
    let posed = lexicon().particles.contains(next);
    let after_contact = !posed
        && verb.is_some_and(|h| {
            matches!(h.kind, Kind::Act { contact: true, .. })
                && before.is_some_and(|(_, j)| h.end == j + 1)
        });
    let after_location =
        verb.is_none() && before.is_some_and(|(w, _)| lexicon().location.contains(w));
    let support = before.is_some_and(|(w, _)| w == "on" || w == "onto")
        && matches!(
            hit.kind,
            Kind::Limb {
                limb: Limb::Leg,
                ..
            }
        )
        && !after_arm;
    (after_contact || after_location) && !support
}

/// The parts a text's clauses add up to, with the phrases that gave them; weak actions' parts
/// are kept apart and used only for a text with nothing else.
#[derive(Default)]
pub(super) struct Labelling {
    parts: PartSet,
    matched: Vec<String>,
    weak: PartSet,
    weak_matched: Vec<String>,
}

impl Labelling {
    fn add(&mut self, set: PartSet, name: &str) {
        add(set, name, &mut self.matched, &mut self.parts);
    }

    pub(super) fn finish(self) -> TextLabel {
        let Labelling {
            mut parts,
            mut matched,
            weak,
            weak_matched,
        } = self;
        if parts.is_empty() && !weak.is_empty() {
            parts = weak;
            matched = weak_matched;
        }
        let known = !parts.is_empty();
        TextLabel {
            parts: if known { parts } else { UNKNOWN_DEFAULT },
            matched,
            known,
        }
    }
}

/// What moved in a clause so far: its actions' limbs depend on it.
#[derive(Default, Clone, Copy)]
struct Moving {
    /// A limb noun moves (`raise left arm`).
    limb: bool,
    /// Any part noun moves.
    any: bool,
}

/// One clause of a text: its tokens and hits, with the hits' roles, and which hits are in it.
pub(super) struct ClauseWords<'a> {
    pub(super) tokens: &'a [Token],
    pub(super) hits: &'a [Hit],
    pub(super) roles: &'a [Role],
    /// Indices into `hits` of the clause's hits.
    pub(super) in_clause: &'a [usize],
}

impl ClauseWords<'_> {
    /// Adds the clause's parts: its moving part nouns, then its actions, then a handled object
    /// when nothing else acted.
    pub(super) fn label(&self, clause: usize, label: &mut Labelling) {
        let sides = Sides {
            instrument: self.instrument_side(clause),
            target: self.target_side(),
        };
        let moving = self.add_moving_nouns(label);
        let object = self.handled_object();
        let acted = self.add_actions(label, moving, object, sides);
        if !acted
            && !moving.any
            && let Some(k) = object
        {
            let set = Limb::Arm.parts(sides.instrument.unwrap_or(Side::Both));
            label.add(set, &self.hits[k].phrase);
        }
    }

    /// `scratch right ear`, `touch left shoulder`: with no hand named, the target's side says
    /// which hand; the same side, except for a shoulder, which the other hand reaches.
    fn target_side(&self) -> Option<Side> {
        let tokens = self.tokens;
        let mut target_side: Option<Side> = None;
        for &k in self.in_clause {
            let hit = &self.hits[k];
            let shoulder = match hit.kind {
                Kind::Feature => false,
                Kind::Limb {
                    self_moving: false,
                    limb: Limb::Arm,
                    ..
                } if self.roles[k] == Role::Target => true,
                Kind::Limb { .. } | Kind::Trunk { .. } if self.roles[k] == Role::Target => false,
                _ => continue,
            };
            let side = side_before(tokens, hit.start, &lexicon().modifiers).or_else(|| {
                // `right side of face`
                let j = word_before_phrase(tokens, hit.start)?;
                (j >= 1 && tokens[j].raw == "of" && tokens[j - 1].raw == "side")
                    .then(|| side_before(tokens, j - 1, &lexicon().modifiers))
                    .flatten()
            });
            let side = match (side, shoulder) {
                (Some(Side::Left), true) => Side::Right,
                (Some(Side::Right), true) => Side::Left,
                (Some(s), _) => s,
                (None, _) => continue,
            };
            target_side = match target_side {
                Some(t) if t != side => Some(Side::Both),
                _ => Some(side),
            };
        }
        target_side
    }

    /// "with the left" / "use the right": an instrument side for the clause's limb action (the
    /// last one the clause names; not one followed by a noun, which takes the side).
    fn instrument_side(&self, clause: usize) -> Option<Side> {
        let tokens = self.tokens;
        let mut instrument_side: Option<Side> = None;
        for (i, t) in tokens.iter().enumerate() {
            if t.clause != clause || !matches!(t.raw.as_str(), "with" | "use" | "using") {
                continue;
            }
            let mut j = i + 1;
            while j < tokens.len() && matches!(tokens[j].raw.as_str(), "the" | "his" | "her") {
                j += 1;
            }
            let side_word = tokens.get(j).map(|t| t.raw.as_str());
            let then_noun = self.hits.iter().any(|h| h.start == j + 1);
            if !then_noun {
                instrument_side = match side_word {
                    Some("left") => Some(Side::Left),
                    Some("right") => Some(Side::Right),
                    Some("both") => Some(Side::Both),
                    _ => instrument_side,
                };
            }
        }
        instrument_side
    }

    /// Adds the clause's moving part nouns, each with its side.
    fn add_moving_nouns(&self, label: &mut Labelling) -> Moving {
        let tokens = self.tokens;
        let mut moving = Moving::default();
        for &k in self.in_clause {
            let hit = &self.hits[k];
            if self.roles[k] != Role::Moving {
                continue;
            }
            match hit.kind {
                Kind::Limb { limb, plural, .. } => {
                    let side = if plural {
                        Side::Both
                    } else {
                        side_before(tokens, hit.start, &lexicon().modifiers).unwrap_or(Side::Both)
                    };
                    let name = side_name(side, plural, &hit.phrase);
                    label.add(limb.parts(side), &name);
                    moving.limb = true;
                    moving.any = true;
                }
                Kind::Trunk { parts: p, hip } => {
                    let mut set = PartSet(p);
                    let mut name = hit.phrase.clone();
                    if hip && let Some(side) = side_before(tokens, hit.start, &lexicon().modifiers)
                    {
                        set |= Limb::Leg.parts(side);
                        name = side_name(side, false, &hit.phrase);
                    }
                    label.add(set, &name);
                    moving.any = true;
                }
                _ => {}
            }
        }
        moving
    }

    /// An object handled in the clause (`move item`, `roll the ball`), not a place: a generic
    /// verb then means the hands, not its whole-body default.
    fn handled_object(&self) -> Option<usize> {
        self.in_clause.iter().copied().find(|&k| {
            self.hits[k].kind == Kind::Object
                && word_before_phrase(self.tokens, self.hits[k].start)
                    .is_none_or(|j| !lexicon().location.contains(self.tokens[j].raw.as_str()))
        })
    }

    /// Adds the clause's actions by strength; true when a strong or generic one acted.
    fn add_actions(
        &self,
        label: &mut Labelling,
        moving: Moving,
        object: Option<usize>,
        sides: Sides,
    ) -> bool {
        let mut acted = false;
        for &k in self.in_clause {
            let hit = &self.hits[k];
            let Kind::Act {
                strength,
                limb,
                extra,
                ..
            } = hit.kind
            else {
                continue;
            };
            let limb_parts =
                |absorbed: bool| self.action_limb_parts(hit, limb, extra, absorbed, sides);
            match strength {
                Strength::Strong => {
                    let set = PartSet(extra) | limb_parts(moving.limb);
                    label.add(set, &hit.phrase);
                    acted = true;
                }
                Strength::Generic => {
                    if !moving.any && object.is_some() && limb.is_none() {
                        let side = sides.instrument.unwrap_or(Side::Both);
                        label.add(Limb::Arm.parts(side), &hit.phrase);
                    } else if !moving.any {
                        let set = PartSet(extra) | limb_parts(false);
                        label.add(set, &hit.phrase);
                    }
                    acted = true;
                }
                Strength::Weak => {
                    label.weak |= PartSet(extra) | limb_parts(moving.limb);
                    if !label.weak_matched.contains(&hit.phrase) {
                        label.weak_matched.push(hit.phrase.clone());
                    }
                }
            }
        }
        acted
    }

    /// The limb parts of an action on a limb, on its side; none when a moving limb noun of the
    /// clause already took them (`absorbed`) or the action names no limb.
    fn action_limb_parts(
        &self,
        hit: &Hit,
        limb: Option<Limb>,
        extra: u8,
        absorbed: bool,
        sides: Sides,
    ) -> PartSet {
        match limb {
            Some(l) if !absorbed => {
                // A side after a locomotion-like limb action (`hop right`) is a direction, after
                // a pure limb action (`kick right`) the limb.
                let after = if extra == 0 {
                    side_after(self.tokens, self.hits, hit.end)
                } else {
                    None
                };
                let side = side_before(self.tokens, hit.start, &lexicon().act_modifiers)
                    .or(after)
                    .or(sides.instrument)
                    .or(if l == Limb::Arm { sides.target } else { None })
                    .unwrap_or(Side::Both);
                l.parts(side)
            }
            _ => PartSet::EMPTY,
        }
    }
}

/// The sides a clause gives its limb actions that name none themselves.
#[derive(Clone, Copy)]
struct Sides {
    /// From "with the left", "use the right".
    instrument: Option<Side>,
    /// From a touched part's side (`scratch right ear`).
    target: Option<Side>,
}

/// A side word right after a limb action that ends its clause or precedes no noun: `kick right`,
/// `punch left`, but not `kick to the right` or `wave right hand` (the noun takes it).
fn side_after(tokens: &[Token], hits: &[Hit], end: usize) -> Option<Side> {
    let t = tokens.get(end)?;
    let side = match t.raw.as_str() {
        "left" => Side::Left,
        "right" => Side::Right,
        _ => return None,
    };
    let next_is_noun = hits
        .iter()
        .any(|h| h.start == end + 1 && !matches!(h.kind, Kind::Act { .. }));
    let next_same_clause = tokens.get(end + 1).is_some_and(|n| n.clause == t.clause);
    let next = tokens.get(end + 1).map(|n| n.raw.as_str()).unwrap_or("");
    if next_is_noun || (next_same_clause && matches!(next, "side" | "of")) {
        return None;
    }
    Some(side)
}

fn add(set: PartSet, name: &str, matched: &mut Vec<String>, parts: &mut PartSet) {
    *parts |= set;
    if !matched.iter().any(|m| m == name) {
        matched.push(name.to_string());
    }
}

fn side_name(side: Side, plural: bool, phrase: &str) -> String {
    match (side, plural) {
        (_, true) => phrase.to_string(),
        (Side::Left, false) => format!("left {phrase}"),
        (Side::Right, false) => format!("right {phrase}"),
        (Side::Both, false) => phrase.to_string(),
    }
}
