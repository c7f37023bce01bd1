//! A scene's interactions: each checked (type, weight, text and its placeholders, the places
//! and objects it names, hands and hold), then expanded into one [`Candidate`] per bound place,
//! object and hand, within [`MAX_CANDIDATES`].

use std::collections::BTreeSet;

use super::file::{HandsFile, InteractionFile, OneOrMany};
use super::problems::{Problems, Seg, k};
use super::resolve::{SceneNames, check_type, finite_positive, first_time};
use super::{Candidate, Hold, MAX_CANDIDATES};
use crate::state::{Effect, Posture, Requirement};
use motionforge_sources::annotate::span::Hand;
use motionforge_sources::annotate::taxonomy::Taxonomy;

/// A place an interaction's `requires` or `leaves` names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum AtName {
    /// A place of the scene, or the open room (`None`).
    Fixed(Option<usize>),
    /// `{place}`: each instruction's bound place.
    Bound,
}

impl AtName {
    fn bind(self, place: Option<usize>) -> Option<usize> {
        match self {
            AtName::Fixed(p) => p,
            AtName::Bound => place,
        }
    }
}

/// The places a list names, each once in file order, and the problems (each once): a name
/// that is not a place, `{place}` without a `places` list. Linear in the list's length.
fn at_names(
    list: &[String],
    at_value: &dyn Fn(&str) -> Result<Option<usize>, String>,
    has_places: bool,
    places: usize,
) -> (Vec<AtName>, Vec<String>) {
    let mut names = Vec::new();
    let mut errors = Vec::new();
    let mut seen = vec![false; places + 1];
    let mut bound_seen = false;
    let mut bad: BTreeSet<&str> = BTreeSet::new();
    for name in list {
        if name == "{place}" {
            if !has_places {
                if !bound_seen {
                    errors.push("`{place}` needs a `places` list".to_string());
                }
            } else if !bound_seen {
                names.push(AtName::Bound);
            }
            bound_seen = true;
            continue;
        }
        match at_value(name) {
            Ok(p) => {
                if first_time(&mut seen, p) {
                    names.push(AtName::Fixed(p));
                }
            }
            Err(e) => {
                if bad.insert(name) {
                    errors.push(e);
                }
            }
        }
    }
    (names, errors)
}

/// Every interaction, checked and expanded into candidates in file order; an interaction with
/// a problem adds none.
pub(super) fn resolve_interactions(
    interactions: &[InteractionFile],
    names: &SceneNames,
    taxonomy: &Taxonomy,
    problems: &mut Problems,
) -> Vec<Candidate> {
    let mut candidates = Vec::new();
    if interactions.is_empty() {
        problems.push(
            &[k("interactions")],
            "empty: expected at least one interaction".into(),
        );
    }
    for (i, inter) in interactions.iter().enumerate() {
        let before = problems.count();
        let bound = Interaction::resolve(i, inter, names, taxonomy, problems);
        if problems.count() > before {
            continue;
        }
        // Counted before expanding, so a long list cannot make the reader allocate its product.
        let expansion = bound.places.len() * bound.objects.len() * bound.hands.len();
        if candidates.len() + expansion > MAX_CANDIDATES {
            problems.push(
                &[k("interactions"), Seg::I(i)],
                format!(
                    "the scene expands into more than {MAX_CANDIDATES} instructions (places x \
                     objects x hands of every interaction); split it into smaller scenes"
                ),
            );
            break;
        }
        bound.expand_into(&mut candidates);
    }
    candidates
}

/// One interaction with its names resolved: what it expands over (each list at least one
/// entry, `None` for "not bound") and its requirements and effect before binding `{place}`.
struct Interaction<'f> {
    index: usize,
    file: &'f InteractionFile,
    text: &'f str,
    places: Vec<Option<usize>>,
    objects: Vec<Option<usize>>,
    hands: Vec<Option<Hand>>,
    hold: Option<Hold>,
    requires_at: Option<Vec<AtName>>,
    requires_not_at: Option<Vec<AtName>>,
    requires_posture: Option<Vec<Posture>>,
    leaves_at: Option<AtName>,
}

impl<'f> Interaction<'f> {
    /// Checks `interactions[index]`, recording its problems; the result is expanded only when
    /// there are none.
    fn resolve(
        index: usize,
        inter: &'f InteractionFile,
        names: &SceneNames,
        taxonomy: &Taxonomy,
        problems: &mut Problems,
    ) -> Interaction<'f> {
        let key = |field: &str| vec![k("interactions"), Seg::I(index), k(field)];
        if let Err(e) = check_type(taxonomy, &inter.motion_type) {
            problems.push(&key("type"), e);
        }
        if !finite_positive(inter.weight) {
            problems.push(
                &key("weight"),
                format!("{}: expected a number above 0", inter.weight),
            );
        }
        let text = inter.text.trim();
        if text.is_empty() || text.contains(['\n', '\r']) {
            problems.push(&key("text"), "expected one line of instruction text".into());
        }
        check_placeholders(text, inter, &key("text"), problems);
        let mut places = bind_names(index, NameList::Places, &inter.places, names, problems);
        let mut objects = bind_names(index, NameList::Objects, &inter.objects, names, problems);
        let hold = resolve_hold(inter, &key, problems);
        if places.is_empty() {
            places.push(None);
        }
        if objects.is_empty() {
            objects.push(None);
        }
        let hands: Vec<Option<Hand>> = match inter.hands {
            HandsFile::None => vec![None],
            HandsFile::Left => vec![Some(Hand::Left)],
            HandsFile::Right => vec![Some(Hand::Right)],
            HandsFile::One => vec![Some(Hand::Left), Some(Hand::Right)],
            HandsFile::Both => vec![Some(Hand::Both)],
        };
        // The places `requires` and `leaves` name, resolved once for all the interaction's
        // instructions (`{place}` is each one's bound place).
        let has_places = !inter.places.is_empty();
        let mut resolve_list = |list: &[String], field: &str| {
            let at_value = |name: &str| names.at_value(name);
            let (found, errors) = at_names(list, &at_value, has_places, names.places.len());
            for e in errors {
                problems.push(&key(field), e);
            }
            found
        };
        let requires_at = inter
            .requires
            .at
            .as_ref()
            .map(|l| resolve_list(l.as_slice(), "requires"));
        let requires_not_at = inter
            .requires
            .not_at
            .as_ref()
            .map(|l| resolve_list(l.as_slice(), "requires"));
        let leaves_at = inter
            .leaves
            .at
            .as_ref()
            .and_then(|a| resolve_list(std::slice::from_ref(a), "leaves").pop());
        Interaction {
            index,
            file: inter,
            text,
            places,
            objects,
            hands,
            hold,
            requires_at,
            requires_not_at,
            requires_posture: inter.requires.posture.as_ref().map(OneOrMany::distinct),
            leaves_at,
        }
    }

    /// One candidate per bound place, object and hand, in that order.
    fn expand_into(&self, candidates: &mut Vec<Candidate>) {
        for &place in &self.places {
            for &object in &self.objects {
                for &hand in &self.hands {
                    candidates.push(self.candidate(place, object, hand));
                }
            }
        }
    }

    fn candidate(
        &self,
        place: Option<usize>,
        object: Option<usize>,
        hand: Option<Hand>,
    ) -> Candidate {
        let inter = self.file;
        let hold = self.hold;
        let bind = |names: &[AtName]| -> Vec<Option<usize>> {
            names.iter().map(|n| n.bind(place)).collect()
        };
        let mut requires = Vec::new();
        if let Some(p) = &self.requires_posture {
            requires.push(Requirement::Posture(p.clone()));
        }
        if let Some(at) = &self.requires_at {
            requires.push(Requirement::At(bind(at)));
        }
        if let Some(not_at) = &self.requires_not_at {
            requires.push(Requirement::NotAt(bind(not_at)));
        }
        if inter.requires.empty_hands {
            requires.push(Requirement::EmptyHands);
        }
        requires.extend(Requirement::for_hands(hand, hold, object));
        Candidate {
            interaction: self.index,
            motion_type: inter.motion_type.clone(),
            template: self.text.to_string(),
            place,
            object,
            hand,
            hold,
            requires,
            effect: Effect {
                posture: inter.leaves.posture,
                at: self.leaves_at.map(|n| n.bind(place)),
                hold: hold
                    .zip(object)
                    .zip(hand)
                    .map(|((h, o), hand)| (h, o, hand)),
            },
            weight: inter.weight,
        }
    }
}

/// Each `{...}` of an instruction text must be a known placeholder with something to fill it.
fn check_placeholders(text: &str, inter: &InteractionFile, key: &[Seg], problems: &mut Problems) {
    let mut rest = text;
    while let Some(open) = rest.find('{') {
        let after = &rest[open + 1..];
        let Some(close) = after.find('}') else {
            problems.push(key, format!("`{text}`: a `{{` is never closed"));
            break;
        };
        let name = &after[..close];
        let filled = match name {
            "place" => !inter.places.is_empty(),
            "object" => !inter.objects.is_empty(),
            "hand" => inter.hands != HandsFile::None,
            _ => {
                problems.push(
                    key,
                    format!("`{{{name}}}`: expected `{{place}}`, `{{object}}` or `{{hand}}`"),
                );
                true
            }
        };
        if !filled {
            let needs = match name {
                "place" => "a `places` list",
                "object" => "an `objects` list",
                _ => "`hands` other than `none`",
            };
            problems.push(
                key,
                format!("`{{{name}}}` needs {needs} on the interaction"),
            );
        }
        rest = &after[close + 1..];
    }
}

/// Which of the scene's lists an interaction's names are looked up in.
#[derive(Clone, Copy)]
enum NameList {
    Places,
    Objects,
}

/// The interaction's `places` or `objects` (`list`, from the file), each a name of the scene.
fn bind_names(
    index: usize,
    which: NameList,
    list: &[String],
    names: &SceneNames,
    problems: &mut Problems,
) -> Vec<Option<usize>> {
    let (field, what, listed) = match which {
        NameList::Places => ("places", "a place", &names.places_listed),
        NameList::Objects => ("objects", "an object", &names.objects_listed),
    };
    let mut bound = Vec::new();
    for (j, name) in list.iter().enumerate() {
        let found = match which {
            NameList::Places => names.place_index(name),
            NameList::Objects => names.object_index(name),
        };
        match found {
            Some(x) => bound.push(Some(x)),
            None => problems.push(
                &[k("interactions"), Seg::I(index), k(field), Seg::I(j)],
                format!("`{name}` is not {what} of the scene ({field}: {listed})"),
            ),
        }
    }
    bound
}

/// What the interaction does with its objects (`keep` by default when it has some); taking or
/// putting down needs a hand.
fn resolve_hold(
    inter: &InteractionFile,
    key: &dyn Fn(&str) -> Vec<Seg>,
    problems: &mut Problems,
) -> Option<Hold> {
    let hold = match (inter.hold, inter.objects.is_empty()) {
        (Some(_), true) => {
            problems.push(
                &key("hold"),
                "`hold` needs an `objects` list on the interaction".into(),
            );
            None
        }
        (None, true) => None,
        (h, false) => Some(h.unwrap_or(Hold::Keep)),
    };
    if matches!(hold, Some(Hold::Take | Hold::Release)) && inter.hands == HandsFile::None {
        problems.push(
            &key("hands"),
            "`none`: taking or putting down an object needs `left`, `right`, `one` or `both`"
                .into(),
        );
    }
    hold
}
