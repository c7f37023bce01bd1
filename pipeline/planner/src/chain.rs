//! The Markov chain: every state reachable from the start, the cheapest way from each back to a
//! valid end state, and the walk that only takes instructions from which the end stays within
//! the remaining budget.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap, HashMap};
use std::rc::Rc;

use super::balance::{DatasetCounts, factors};
use super::scene::{Limit, Scene};
use super::state::{Requirement, State};
use super::{PlanError, Session, Step};

/// The most states a scene may reach; beyond it the scene is refused as too large to plan.
pub const MAX_STATES: usize = 200_000;

/// The most transitions (state, instruction) the graph may hold.
const MAX_EDGES: usize = 4_000_000;

/// The most requirement checks exploring may cost: every state checks every instruction's
/// requirements, a list of postures or places costing its length, any other requirement one
/// (a hand or object check looks at no more than `MAX_MOVABLE` positions). A scene whose
/// instructions cost `w` per state may reach at most this over `w` states: fewer than
/// [`MAX_STATES`] only past 2,000 per state (the living room costs 88), so the time exploring
/// takes is bounded before any state is built.
const MAX_CHECKS: u64 = 400_000_000;

/// The shortest duration estimate, in milliseconds: the segment stage's default shortest clip
/// (`min_seconds`, 0.5 s). It also bounds a `minutes` session to 28,800 instructions.
const MIN_MILLIS: u64 = 500;

/// The reachable state graph of a scene.
pub(super) struct Graph {
    /// States, the start first (shared with the index that finds them while exploring: one
    /// copy of each).
    pub states: Vec<Rc<State>>,
    /// Per state: (candidate, next state) for every candidate whose requirements hold.
    pub edges: Vec<Vec<(usize, usize)>>,
}

impl Graph {
    /// Every state reachable from the scene's start (breadth first, candidates in file order).
    pub(crate) fn explore(scene: &Scene) -> Result<Graph, PlanError> {
        let max_states = max_states(scene);
        let start = Rc::new(scene.start.clone());
        let mut states = vec![Rc::clone(&start)];
        let mut index: HashMap<Rc<State>, usize> = HashMap::from([(start, 0)]);
        let mut edges: Vec<Vec<(usize, usize)>> = Vec::new();
        let mut total = 0usize;
        let mut i = 0;
        while i < states.len() {
            let mut out = Vec::new();
            for (c, cand) in scene.candidates.iter().enumerate() {
                if !cand.requires.iter().all(|r| r.holds(scene, &states[i])) {
                    continue;
                }
                let next = cand.effect.apply(scene, &states[i]);
                let j = match index.get(&next) {
                    Some(&j) => j,
                    None => {
                        if states.len() >= max_states {
                            return Err(PlanError::TooLarge { states: max_states });
                        }
                        let next = Rc::new(next);
                        states.push(Rc::clone(&next));
                        index.insert(next, states.len() - 1);
                        states.len() - 1
                    }
                };
                out.push((c, j));
            }
            total += out.len();
            if total > MAX_EDGES {
                return Err(PlanError::TooLarge {
                    states: states.len(),
                });
            }
            edges.push(out);
            i += 1;
        }
        Ok(Graph { states, edges })
    }

    /// The least cost from each state to a valid end state (`None`: unreachable), by Dijkstra on
    /// the reversed graph from every end state.
    pub(crate) fn cost_to_end(&self, scene: &Scene, cost: &[u64]) -> Vec<Option<u64>> {
        let n = self.states.len();
        let mut reverse: Vec<Vec<(usize, u64)>> = vec![Vec::new(); n];
        for (from, out) in self.edges.iter().enumerate() {
            for &(c, to) in out {
                reverse[to].push((from, cost[c]));
            }
        }
        let mut dist: Vec<Option<u64>> = vec![None; n];
        let mut heap = BinaryHeap::new();
        for (s, state) in self.states.iter().enumerate() {
            if is_end(scene, state) {
                dist[s] = Some(0);
                heap.push(Reverse((0u64, s)));
            }
        }
        while let Some(Reverse((d, s))) = heap.pop() {
            if dist[s].is_some_and(|best| d > best) {
                continue;
            }
            for &(from, c) in &reverse[s] {
                let nd = d.saturating_add(c);
                if dist[from].is_none_or(|best| nd < best) {
                    dist[from] = Some(nd);
                    heap.push(Reverse((nd, from)));
                }
            }
        }
        dist
    }
}

/// The most states exploring `scene` may build: [`MAX_STATES`], fewer for a scene whose
/// requirement checks cost more than [`MAX_CHECKS`] over it per state. Known before any state is
/// built, as is each state's size (the scene's movable objects, at most `MAX_MOVABLE`).
fn max_states(scene: &Scene) -> usize {
    let allowed = MAX_CHECKS / checks_per_state(scene).max(1);
    usize::try_from(allowed).map_or(MAX_STATES, |n| n.clamp(1, MAX_STATES))
}

/// What checking every instruction's requirements in one state costs, in [`MAX_CHECKS`] units.
fn checks_per_state(scene: &Scene) -> u64 {
    scene
        .candidates
        .iter()
        .map(|c| {
            c.requires
                .iter()
                .map(|r| match r {
                    Requirement::Posture(l) => l.len().max(1) as u64,
                    Requirement::At(l) | Requirement::NotAt(l) => l.len().max(1) as u64,
                    _ => 1,
                })
                .sum::<u64>()
                .max(1)
        })
        .sum()
}

/// Whether a state meets every end requirement.
pub(super) fn is_end(scene: &Scene, state: &State) -> bool {
    scene.end.iter().all(|r| r.holds(scene, state))
}

/// The first of `requirements` that no state of `states` meets, else `None` (each is met
/// somewhere, though maybe never all together).
pub(super) fn never_met<'r>(
    scene: &Scene,
    requirements: &'r [Requirement],
    states: &[Rc<State>],
) -> Option<&'r Requirement> {
    requirements
        .iter()
        .find(|r| !states.iter().any(|s| r.holds(scene, s)))
}

/// Estimated seconds of each motion type: the dataset's median, else the scene's
/// `limits.seconds`, else `limits.default_seconds`.
pub(super) fn seconds_of(scene: &Scene, counts: &DatasetCounts, motion_type: &str) -> f64 {
    counts
        .median_seconds
        .get(motion_type)
        .or_else(|| scene.seconds.get(motion_type))
        .copied()
        .unwrap_or(scene.default_seconds)
}

/// Walks the chain. At each step the allowed instructions are those whose requirements hold and
/// from whose result the end is reachable within what remains of the budget (the previous
/// instruction again only when nothing else is allowed). A motion type among theirs is drawn
/// with probability proportional to its balance factor times the mean scene weight of its
/// allowed instructions, then one of them in proportion to its weight.
pub(super) fn walk(
    scene: &Scene,
    graph: &Graph,
    counts: &DatasetCounts,
    seed: u64,
) -> Result<Session, PlanError> {
    let millis: Vec<u64> = scene
        .candidates
        .iter()
        .map(|c| {
            ((seconds_of(scene, counts, &c.motion_type) * 1000.0).round() as u64).max(MIN_MILLIS)
        })
        .collect();
    let (cost, budget): (Vec<u64>, u64) = match scene.limit {
        Limit::Instructions(n) => (vec![1; scene.candidates.len()], u64::from(n)),
        Limit::Millis(ms) => (millis.clone(), ms),
    };
    let to_end = graph.cost_to_end(scene, &cost);
    match to_end[0] {
        None => return Err(unreachable_end(scene, graph)),
        Some(needed) if needed > budget => {
            return Err(PlanError::OverBudget {
                needed,
                budget,
                limit: scene.limit,
            });
        }
        Some(_) => {}
    }

    let mut rng = fastrand::Rng::with_seed(seed);
    let mut session_counts: BTreeMap<String, u64> = BTreeMap::new();
    let mut running = counts.clips.clone();
    let mut state = 0usize;
    let mut used = 0u64;
    let mut previous: Option<usize> = None;
    let mut steps = Vec::new();
    loop {
        let allowed: Vec<(usize, usize)> = graph.edges[state]
            .iter()
            .copied()
            .filter(|&(c, next)| to_end[next].is_some_and(|d| used + cost[c] + d <= budget))
            .collect();
        if allowed.is_empty() {
            break;
        }
        let fresh: Vec<(usize, usize)> = allowed
            .iter()
            .copied()
            .filter(|&(c, _)| Some(c) != previous)
            .collect();
        let pool = if fresh.is_empty() { allowed } else { fresh };
        // First the motion type, then the instruction of that type: a type does not gain
        // weight by expanding into many instructions (four `pick up`s: two objects, two hands).
        let balance = factors(&scene.target, &running, scene.strength);
        // A type outside the target is a connector (walking to the table to drink): never
        // preferred over a target type, so it gets the smallest target factor.
        let outside = balance.values().copied().fold(f64::INFINITY, f64::min);
        let outside = if outside.is_finite() { outside } else { 1.0 };
        let mut by_type: BTreeMap<&str, Vec<usize>> = BTreeMap::new();
        for (k, &(c, _)) in pool.iter().enumerate() {
            by_type
                .entry(scene.candidates[c].motion_type.as_str())
                .or_default()
                .push(k);
        }
        let type_weights: Vec<f64> = by_type
            .iter()
            .map(|(t, ks)| {
                let mean = ks
                    .iter()
                    .map(|&k| scene.candidates[pool[k].0].weight)
                    .sum::<f64>()
                    / ks.len() as f64;
                mean * balance.get(*t).copied().unwrap_or(outside)
            })
            .collect();
        let members = by_type
            .into_values()
            .nth(draw(&mut rng, &type_weights))
            .unwrap_or_default();
        let member_weights: Vec<f64> = members
            .iter()
            .map(|&k| scene.candidates[pool[k].0].weight)
            .collect();
        let Some(&pick) = members.get(draw(&mut rng, &member_weights)) else {
            break;
        };
        let (c, next) = pool[pick];
        let cand = &scene.candidates[c];
        *session_counts.entry(cand.motion_type.clone()).or_default() += 1;
        *running.entry(cand.motion_type.clone()).or_default() += 1;
        used += cost[c];
        steps.push(Step {
            candidate: c,
            text: cand.text(scene),
            motion_type: cand.motion_type.clone(),
            hand: cand.hand,
            object: cand.object_name(scene).map(str::to_string),
            hold: cand.hold,
            seconds: millis[c] as f64 / 1000.0,
            before: State::clone(&graph.states[state]),
            after: State::clone(&graph.states[next]),
        });
        previous = Some(c);
        state = next;
    }
    if steps.is_empty() {
        return Err(no_first_step(scene, graph));
    }
    Ok(Session {
        scene: scene.name.clone(),
        seed,
        steps,
        session_counts,
        dataset_counts: counts.clips.clone(),
        target: scene.target.clone(),
        unreachable: never_possible(scene, graph),
    })
}

/// An index drawn with probability proportional to `weights` (all finite and positive).
fn draw(rng: &mut fastrand::Rng, weights: &[f64]) -> usize {
    let total: f64 = weights.iter().sum();
    let mut x = rng.f64() * total;
    for (k, w) in weights.iter().enumerate() {
        if x < *w {
            return k;
        }
        x -= w;
    }
    weights.len().saturating_sub(1)
}

/// The error for a scene whose end no reachable state meets, naming the requirement.
fn unreachable_end(scene: &Scene, graph: &Graph) -> PlanError {
    let requirement = match never_met(scene, &scene.end, &graph.states) {
        Some(r) => format!(
            "the end state needs {}, which no sequence from the start ({}) reaches",
            r.text(scene),
            scene.start.text(scene)
        ),
        None => format!(
            "the end state needs {} together, which no sequence from the start ({}) reaches",
            scene
                .end
                .iter()
                .map(|r| r.text(scene))
                .collect::<Vec<_>>()
                .join(" and "),
            scene.start.text(scene)
        ),
    };
    PlanError::Unplannable { requirement }
}

/// The error for a scene where no first instruction fits: each interaction's first unmet
/// requirement at the start.
fn no_first_step(scene: &Scene, graph: &Graph) -> PlanError {
    let start = &graph.states[0];
    let mut reasons: Vec<String> = Vec::new();
    for cand in &scene.candidates {
        let why = match cand.requires.iter().find(|r| !r.holds(scene, start)) {
            Some(r) => format!("needs {}", r.text(scene)),
            None => "leaves a state from which the end is out of budget".to_string(),
        };
        let line = format!(
            "interactions[{}] `{}` {why}",
            cand.interaction, cand.template
        );
        if !reasons.contains(&line) {
            reasons.push(line);
        }
    }
    PlanError::Unplannable {
        requirement: format!(
            "no instruction can start from {}: {}",
            start.text(scene),
            reasons.join("; ")
        ),
    }
}

/// Interactions that no reachable state allows, with the requirement never met.
fn never_possible(scene: &Scene, graph: &Graph) -> Vec<String> {
    let mut used = vec![false; scene.candidates.len()];
    for out in &graph.edges {
        for &(c, _) in out {
            used[c] = true;
        }
    }
    let mut notes: Vec<String> = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for (c, cand) in scene.candidates.iter().enumerate() {
        if used[c] {
            continue;
        }
        let why = match never_met(scene, &cand.requires, &graph.states) {
            Some(r) => format!("needs {}, which no reachable state has", r.text(scene)),
            None => "its requirements never hold together".to_string(),
        };
        let text = format!(
            "interactions[{}] `{}` is never possible: {why}",
            cand.interaction,
            cand.text(scene)
        );
        if seen.insert(text.clone()) {
            notes.push(text);
        }
    }
    notes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_living_room_explores_up_to_the_full_state_limit() {
        let scene = Scene::load(std::path::Path::new(
            "../../schemas/scenes/living-room.toml",
        ))
        .unwrap();
        assert!(checks_per_state(&scene) < MAX_CHECKS / MAX_STATES as u64);
        assert_eq!(max_states(&scene), MAX_STATES);
    }
}
