//! The actor's state during a session (posture, place, what each hand holds) and the
//! requirements and effects of an instruction on it.

use serde::{Deserialize, Serialize};

use super::scene::{Hold, Scene};
use motionforge_sources::annotate::span::Hand;

/// The actor's body posture.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Posture {
    /// On the feet.
    Standing,
    /// Seated (on a place such as a sofa).
    Sitting,
    /// Lying (on a place such as a sofa or bed).
    Lying,
    /// On the knees.
    Kneeling,
    /// Squatting.
    Squatting,
    /// Bent forward.
    Bending,
}

impl Posture {
    /// Name as written in scene files.
    pub fn as_str(self) -> &'static str {
        match self {
            Posture::Standing => "standing",
            Posture::Sitting => "sitting",
            Posture::Lying => "lying",
            Posture::Kneeling => "kneeling",
            Posture::Squatting => "squatting",
            Posture::Bending => "bending",
        }
    }
}

/// Where a hand-held object is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Loc {
    /// Resting at a place (index into [`Scene::places`]).
    Place(usize),
    /// In a hand, or held with both.
    Held(Hand),
}

/// The actor's state: posture, place and where each object some interaction can move is.
///
/// Objects no interaction takes never move: their places are kept once, in
/// [`Scene::object_start`], not in every state, so a state's size does not grow with them.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct State {
    /// Body posture.
    pub posture: Posture,
    /// The place the actor is at, `None` in the open room.
    pub at: Option<usize>,
    /// Where each object of [`Scene::movable`] is, in the same order.
    pub objects: Vec<Loc>,
}

impl State {
    /// Where an object of [`Scene::objects`] is: its entry in the state if some interaction can
    /// move it, else the place it starts at.
    pub fn loc(&self, scene: &Scene, object: usize) -> Option<Loc> {
        match scene.slot(object) {
            Some(slot) => self.objects.get(slot).copied(),
            None => scene.object_start.get(object).map(|&p| Loc::Place(p)),
        }
    }

    /// The position in [`State::objects`] of the object in a hand (`Hand::Both` asks for an
    /// object held with both).
    fn held_slot(&self, side: Hand) -> Option<usize> {
        self.objects.iter().position(|l| match (l, side) {
            (Loc::Held(Hand::Both), _) => true,
            (Loc::Held(h), s) => *h == s,
            _ => false,
        })
    }

    /// The object (an index into [`Scene::objects`]) in a hand (`Hand::Both` asks for an object
    /// held with both).
    pub fn in_hand(&self, scene: &Scene, side: Hand) -> Option<usize> {
        self.held_slot(side)
            .and_then(|slot| scene.movable.get(slot).copied())
    }

    /// True if the hand holds nothing.
    pub fn free(&self, side: Hand) -> bool {
        self.held_slot(side).is_none()
    }

    /// What the hands hold, for people: `left: cup, right: empty`.
    pub fn hands_text(&self, scene: &Scene) -> String {
        let name = |o: Option<usize>| o.map_or("empty", |o| scene.objects[o].as_str());
        let both = self
            .objects
            .iter()
            .position(|l| *l == Loc::Held(Hand::Both))
            .and_then(|slot| scene.movable.get(slot).copied());
        match both {
            Some(o) => format!("both: {}", scene.objects[o]),
            None => format!(
                "left: {}, right: {}",
                name(self.in_hand(scene, Hand::Left)),
                name(self.in_hand(scene, Hand::Right))
            ),
        }
    }

    /// The whole state, for people.
    pub fn text(&self, scene: &Scene) -> String {
        let place = match self.at {
            Some(p) => format!("at the {}", scene.places[p]),
            None => "in the open room".to_string(),
        };
        format!(
            "{} {place}, {}",
            self.posture.as_str(),
            self.hands_text(scene)
        )
    }
}

/// One condition an instruction (or the end of a session) needs.
#[derive(Debug, Clone, PartialEq)]
pub enum Requirement {
    /// The posture is one of these.
    Posture(Vec<Posture>),
    /// The actor is at one of these places (`None`: the open room).
    At(Vec<Option<usize>>),
    /// The actor is at none of these places.
    NotAt(Vec<Option<usize>>),
    /// Both hands hold nothing.
    EmptyHands,
    /// This hand holds nothing (both hands for `Hand::Both`).
    HandFree(Hand),
    /// The object rests at the place the actor is at.
    ObjectHere(usize),
    /// The object is in this hand (held with both for `Hand::Both`).
    InHand(usize, Hand),
    /// The object is held, in any hand.
    Held(usize),
    /// The object is held and the other hand is free (a two-handed use of a held object).
    HeldOtherFree(usize),
    /// The actor is at a place (to put something down on it).
    AtSomePlace,
}

impl Requirement {
    /// The requirements the hands and the object add: a free hand to take into, the object
    /// where it must be.
    pub fn for_hands(
        hand: Option<Hand>,
        hold: Option<Hold>,
        object: Option<usize>,
    ) -> Vec<Requirement> {
        match (hold, object, hand) {
            (None, _, Some(h)) => vec![Requirement::HandFree(h)],
            (None, _, None) => vec![],
            (Some(Hold::Take), Some(o), Some(h)) => {
                vec![Requirement::ObjectHere(o), Requirement::HandFree(h)]
            }
            (Some(Hold::Keep), Some(o), Some(Hand::Both)) => vec![Requirement::HeldOtherFree(o)],
            (Some(Hold::Keep | Hold::Release), Some(o), Some(h)) => {
                let mut v = vec![Requirement::InHand(o, h)];
                if hold == Some(Hold::Release) {
                    v.insert(0, Requirement::AtSomePlace);
                }
                v
            }
            (Some(Hold::Keep), Some(o), None) => vec![Requirement::Held(o)],
            // Validation refuses take/release without hands and hold without objects.
            _ => vec![],
        }
    }

    /// Whether the state meets it (`scene` places the objects the state does not carry).
    pub fn holds(&self, scene: &Scene, s: &State) -> bool {
        match self {
            Requirement::Posture(list) => list.contains(&s.posture),
            Requirement::At(list) => list.contains(&s.at),
            Requirement::NotAt(list) => !list.contains(&s.at),
            Requirement::EmptyHands => s.free(Hand::Left) && s.free(Hand::Right),
            Requirement::HandFree(Hand::Both) => s.free(Hand::Left) && s.free(Hand::Right),
            Requirement::HandFree(h) => s.free(*h),
            Requirement::ObjectHere(o) => {
                s.at.is_some_and(|p| s.loc(scene, *o) == Some(Loc::Place(p)))
            }
            Requirement::InHand(o, h) => s.loc(scene, *o) == Some(Loc::Held(*h)),
            Requirement::Held(o) => matches!(s.loc(scene, *o), Some(Loc::Held(_))),
            Requirement::HeldOtherFree(o) => match s.loc(scene, *o) {
                Some(Loc::Held(Hand::Both)) => true,
                Some(Loc::Held(Hand::Left)) => s.free(Hand::Right),
                Some(Loc::Held(Hand::Right)) => s.free(Hand::Left),
                _ => false,
            },
            Requirement::AtSomePlace => s.at.is_some(),
        }
    }

    /// The requirement in words, with the scene's names: `posture standing or sitting`.
    pub fn text(&self, scene: &Scene) -> String {
        let places = |list: &[Option<usize>]| {
            list.iter()
                .map(|p| format!("`{}`", scene.place_name(*p)))
                .collect::<Vec<_>>()
                .join(" or ")
        };
        let object = |o: &usize| format!("`{}`", scene.objects[*o]);
        match self {
            Requirement::Posture(list) => format!(
                "posture {}",
                list.iter()
                    .map(|p| p.as_str())
                    .collect::<Vec<_>>()
                    .join(" or ")
            ),
            Requirement::At(list) => format!("being at {}", places(list)),
            Requirement::NotAt(list) => format!("not being at {}", places(list)),
            Requirement::EmptyHands => "empty hands".into(),
            Requirement::HandFree(Hand::Both) => "both hands free".into(),
            Requirement::HandFree(h) => format!("the {} hand free", h.as_str()),
            Requirement::ObjectHere(o) => format!("{} at the actor's place", object(o)),
            Requirement::InHand(o, Hand::Both) => format!("{} held with both hands", object(o)),
            Requirement::InHand(o, h) => format!("{} in the {} hand", object(o), h.as_str()),
            Requirement::Held(o) => format!("{} in a hand", object(o)),
            Requirement::HeldOtherFree(o) => {
                format!("{} in one hand and the other hand free", object(o))
            }
            Requirement::AtSomePlace => "being at a place to put the object on".into(),
        }
    }
}

/// What an instruction changes.
#[derive(Debug, Clone, PartialEq)]
pub struct Effect {
    /// The posture it leaves.
    pub posture: Option<Posture>,
    /// The place it leaves the actor at (`Some(None)`: the open room).
    pub at: Option<Option<usize>>,
    /// The object it takes or puts down, with the hand(s).
    pub hold: Option<(Hold, usize, Hand)>,
}

impl Effect {
    /// The state after the instruction (its requirements already hold). Only objects of
    /// [`Scene::movable`] are taken or put down: an object no interaction takes is never in a
    /// hand to put down.
    pub fn apply(&self, scene: &Scene, s: &State) -> State {
        let mut next = s.clone();
        let moved = match self.hold {
            Some((Hold::Take, o, h)) => Some((o, Loc::Held(h))),
            Some((Hold::Release, o, _)) => s.at.map(|p| (o, Loc::Place(p))),
            _ => None,
        };
        if let Some((o, to)) = moved
            && let Some(loc) = scene.slot(o).and_then(|slot| next.objects.get_mut(slot))
        {
            *loc = to;
        }
        if let Some(p) = self.posture {
            next.posture = p;
        }
        if let Some(at) = self.at {
            next.at = at;
        }
        next
    }
}
