//! The checks that turn a parsed scene file into a [`Scene`]: places and objects, the start and
//! end states, the session's limit and durations, the balance target and the objects that move;
//! every problem is recorded with its key. Interactions are resolved in `interaction.rs`.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::Path;

use super::file::{BalanceFile, EndFile, EndHands, LimitsFile, OneOrMany, SceneFile, StartFile};
use super::interaction::resolve_interactions;
use super::problems::{Problems, Seg, k, listing};
use super::{Candidate, Hold, Limit, MAX_MOVABLE, NO_PLACE, Scene};
use crate::state::{Loc, Posture, Requirement, State};
use motionforge_sources::annotate::taxonomy::{Taxonomy, normalize_label};

/// True the first time `place` (an index into `places`, `None` the open room) is seen, marking it
/// in `seen` (one flag per place, then the open room).
pub(super) fn first_time(seen: &mut [bool], place: Option<usize>) -> bool {
    let i = place.unwrap_or(seen.len().saturating_sub(1));
    match seen.get_mut(i) {
        Some(flag) if !*flag => {
            *flag = true;
            true
        }
        _ => false,
    }
}

/// A type name of the taxonomy, or the problem with a suggestion.
pub(super) fn check_type(taxonomy: &Taxonomy, name: &str) -> Result<(), String> {
    if taxonomy.get(name).is_some() {
        return Ok(());
    }
    let normal = normalize_label(name);
    let hint = if taxonomy.get(&normal).is_some() {
        format!(" (write it as `{normal}`)")
    } else {
        let close: Vec<&str> = taxonomy
            .types()
            .map(|t| t.name.as_str())
            .filter(|t| {
                let first = normal.split(' ').next().unwrap_or_default();
                !first.is_empty() && t.split(' ').any(|w| w == first)
            })
            .collect();
        if close.is_empty() {
            String::new()
        } else {
            format!(" (similar: {})", close.join(", "))
        }
    };
    Err(format!(
        "`{name}` is not a motion type of schemas/motion_types.toml{hint}"
    ))
}

pub(super) fn finite_positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

/// Turns the parsed file into a scene, recording every problem; the scene returned is only
/// used when there are none.
pub(super) fn resolve(
    file: SceneFile,
    path: &Path,
    taxonomy: &Taxonomy,
    problems: &mut Problems,
) -> Scene {
    let name = file.name.clone().unwrap_or_else(|| {
        path.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into())
    });
    let names = SceneNames::resolve(&file.places, &file.objects, problems);
    let start_at = resolve_start_at(&file.start, &names, problems);
    let start_posture = file.start.posture.unwrap_or(Posture::Standing);
    let end = resolve_end(
        file.end.unwrap_or_default(),
        start_posture,
        &names,
        problems,
    );
    let limit = resolve_limit(&file.limits, problems);
    let default_secs = file.limits.default_seconds;
    check_seconds(&file.limits, taxonomy, problems);
    let candidates = resolve_interactions(&file.interactions, &names, taxonomy, problems);
    let strength = file.balance.strength;
    let target = resolve_balance(&file.balance, &candidates, taxonomy, problems);
    let movable = movable_objects(&candidates, problems);
    let SceneNames {
        places,
        objects,
        object_start,
        ..
    } = names;
    let start = State {
        posture: start_posture,
        at: start_at,
        objects: movable
            .iter()
            .filter_map(|&o| object_start.get(o).map(|&p| Loc::Place(p)))
            .collect(),
    };
    Scene {
        name,
        places,
        objects,
        object_start,
        movable,
        start,
        end,
        limit,
        seconds: file.limits.seconds,
        default_seconds: default_secs,
        strength,
        target,
        candidates,
    }
}

/// The scene's places and objects as the checks look them up. Places are found by name in a
/// map and objects by binary search: a scene's lists are checked in time linear in their
/// lengths.
pub(super) struct SceneNames {
    /// Distinct places, in file order.
    pub(super) places: Vec<String>,
    place_ids: HashMap<String, usize>,
    /// The places joined for messages.
    pub(super) places_listed: String,
    /// Objects, sorted (read from a sorted map).
    pub(super) objects: Vec<String>,
    /// The place each object of `objects` starts at.
    pub(super) object_start: Vec<usize>,
    /// The objects joined for messages.
    pub(super) objects_listed: String,
}

impl SceneNames {
    /// Places and objects: distinct, non-empty, not the reserved word; every object starts at a
    /// place.
    fn resolve(
        place_list: &[String],
        object_list: &BTreeMap<String, String>,
        problems: &mut Problems,
    ) -> SceneNames {
        let mut places: Vec<String> = Vec::new();
        let mut place_ids: HashMap<String, usize> = HashMap::new();
        for (i, p) in place_list.iter().enumerate() {
            let p = p.trim();
            if p.is_empty() || p == NO_PLACE || p.contains(['{', '}', '\n']) {
                problems.push(
                    &[k("places"), Seg::I(i)],
                    format!(
                        "`{p}`: expected a place name (not empty, not `{NO_PLACE}`, no braces)"
                    ),
                );
            } else if place_ids.contains_key(p) {
                problems.push(&[k("places"), Seg::I(i)], format!("`{p}` is listed twice"));
            } else {
                place_ids.insert(p.to_string(), places.len());
                places.push(p.to_string());
            }
        }
        let places_listed = listing(&places);
        let mut names = SceneNames {
            places,
            place_ids,
            places_listed,
            objects: Vec::new(),
            object_start: Vec::new(),
            objects_listed: String::new(),
        };
        for (object, at) in object_list {
            let key = [k("objects"), k(object)];
            if object.trim().is_empty()
                || object.contains(['{', '}', '\n'])
                || names.place_ids.contains_key(object.as_str())
            {
                problems.push(
                    &key,
                    format!(
                        "`{object}`: expected an object name (not empty, no braces, not a place)"
                    ),
                );
                continue;
            }
            match names.place_index(at) {
                Some(p) => {
                    names.objects.push(object.clone());
                    names.object_start.push(p);
                }
                None => problems.push(
                    &key,
                    format!(
                        "`{at}`: an object starts at one of the places ({})",
                        names.places_listed
                    ),
                ),
            }
        }
        names.objects_listed = listing(&names.objects);
        names
    }

    pub(super) fn place_index(&self, name: &str) -> Option<usize> {
        self.place_ids.get(name).copied()
    }

    pub(super) fn object_index(&self, name: &str) -> Option<usize> {
        self.objects.binary_search_by(|o| o.as_str().cmp(name)).ok()
    }

    /// An `at` value: `none` is the open room; anything else must be a listed place.
    pub(super) fn at_value(&self, name: &str) -> Result<Option<usize>, String> {
        if name == NO_PLACE {
            return Ok(None);
        }
        self.place_index(name).map(Some).ok_or_else(|| {
            format!(
                "`{name}` is not a place of the scene (places: {}; or `{NO_PLACE}`)",
                self.places_listed
            )
        })
    }
}

/// The actor's start place (`start.at`), the open room where unset or wrong.
fn resolve_start_at(
    start: &StartFile,
    names: &SceneNames,
    problems: &mut Problems,
) -> Option<usize> {
    match start.at.as_deref() {
        None => None,
        Some(a) => match names.at_value(a) {
            Ok(p) => p,
            Err(e) => {
                problems.push(&[k("start"), k("at")], e);
                None
            }
        },
    }
}

/// What a valid final state must meet: a posture (the start's, by default), a place where
/// `end.at` names some, and empty hands unless `end.hands = "any"`.
fn resolve_end(
    end_file: EndFile,
    start_posture: Posture,
    names: &SceneNames,
    problems: &mut Problems,
) -> Vec<Requirement> {
    let mut end = Vec::new();
    end.push(Requirement::Posture(
        end_file
            .posture
            .as_ref()
            .map(OneOrMany::distinct)
            .unwrap_or_else(|| vec![start_posture]),
    ));
    // A list of places holds each once (`["sofa", "sofa"]` is `["sofa"]`): a requirement is
    // at most the places long, however long the file's list.
    let mut seen = vec![false; names.places.len() + 1];
    if let Some(at) = &end_file.at {
        let mut list = Vec::new();
        for (i, a) in at.as_slice().iter().enumerate() {
            match names.at_value(a) {
                Ok(p) => {
                    if first_time(&mut seen, p) {
                        list.push(p);
                    }
                }
                Err(e) => problems.push(&[k("end"), k("at"), Seg::I(i)], e),
            }
        }
        end.push(Requirement::At(list));
    }
    if end_file.hands == EndHands::Empty {
        end.push(Requirement::EmptyHands);
    }
    end
}

/// The session's limit: exactly one of `instructions` and `minutes`, in range.
fn resolve_limit(limits: &LimitsFile, problems: &mut Problems) -> Limit {
    match (limits.instructions, limits.minutes) {
        (Some(n), None) if (1..=10_000).contains(&n) => Limit::Instructions(n),
        (Some(n), None) => {
            problems.push(
                &[k("limits"), k("instructions")],
                format!("{n}: expected 1 to 10000 instructions"),
            );
            Limit::Instructions(1)
        }
        (None, Some(m)) if finite_positive(m) && m <= 240.0 => {
            Limit::Millis((m * 60_000.0).round() as u64)
        }
        (None, Some(m)) => {
            problems.push(
                &[k("limits"), k("minutes")],
                format!("{m}: expected a number of minutes above 0, at most 240"),
            );
            Limit::Instructions(1)
        }
        (Some(_), Some(_)) => {
            problems.push(
                &[k("limits")],
                "both `instructions` and `minutes`: give one of them".into(),
            );
            Limit::Instructions(1)
        }
        (None, None) => {
            problems.push(
                &[k("limits")],
                "neither `instructions` nor `minutes`: give one of them".into(),
            );
            Limit::Instructions(1)
        }
    }
}

/// `limits.default_seconds` and every `limits.seconds` entry: a known type, a duration in range.
fn check_seconds(limits: &LimitsFile, taxonomy: &Taxonomy, problems: &mut Problems) {
    let default_secs = limits.default_seconds;
    if !(finite_positive(default_secs) && default_secs <= 3600.0) {
        problems.push(
            &[k("limits"), k("default_seconds")],
            format!("{default_secs}: expected seconds above 0, at most 3600"),
        );
    }
    for (t, s) in &limits.seconds {
        let key = [k("limits"), k("seconds"), k(t)];
        if let Err(e) = check_type(taxonomy, t) {
            problems.push(&key, e);
        }
        if !(finite_positive(*s) && *s <= 3600.0) {
            problems.push(&key, format!("{s}: expected seconds above 0, at most 3600"));
        }
    }
}

/// The balance target's shares, normalised to sum to 1; by default uniform over the scene's
/// types. Checks `balance.strength` too.
fn resolve_balance(
    balance: &BalanceFile,
    candidates: &[Candidate],
    taxonomy: &Taxonomy,
    problems: &mut Problems,
) -> BTreeMap<String, f64> {
    let strength = balance.strength;
    if !(strength.is_finite() && (0.0..=10.0).contains(&strength)) {
        problems.push(
            &[k("balance"), k("strength")],
            format!("{strength}: expected a number from 0 to 10"),
        );
    }
    let scene_types: BTreeSet<&str> = candidates.iter().map(|c| c.motion_type.as_str()).collect();
    let mut target = BTreeMap::new();
    if balance.target.is_empty() {
        for t in &scene_types {
            target.insert(t.to_string(), 1.0);
        }
    } else {
        for (t, w) in &balance.target {
            let key = [k("balance"), k("target"), k(t)];
            if let Err(e) = check_type(taxonomy, t) {
                problems.push(&key, e);
            } else if !scene_types.contains(t.as_str()) {
                problems.push(
                    &key,
                    format!("no interaction of the scene has type `{t}`: a session cannot add it"),
                );
            }
            if !finite_positive(*w) {
                problems.push(&key, format!("{w}: expected a share above 0"));
            }
            target.insert(t.clone(), *w);
        }
    }
    let total: f64 = target.values().sum();
    if total > 0.0 && total.is_finite() {
        for v in target.values_mut() {
            *v /= total;
        }
    }
    target
}

/// The objects some instruction takes, ascending: the only ones that ever move (an object is
/// put down only from a hand), so the states carry where those are, and nothing of the others.
fn movable_objects(candidates: &[Candidate], problems: &mut Problems) -> Vec<usize> {
    let mut movable: Vec<usize> = candidates
        .iter()
        .filter(|c| c.hold == Some(Hold::Take))
        .filter_map(|c| c.object)
        .collect();
    movable.sort_unstable();
    movable.dedup();
    if movable.len() > MAX_MOVABLE {
        problems.push(
            &[k("objects")],
            format!(
                "{} objects are taken by interactions (`hold = \"take\"`), more than the \
                 {MAX_MOVABLE} a scene may move; split it into smaller scenes",
                movable.len()
            ),
        );
    }
    movable
}
