//! The capture-session planner (LINGO's Motion Planner, appendix B.1.3, Figure A1): for a scene,
//! the sequence of instructions an actor performs, drawn from a Markov chain over the scene's
//! interactions that honours their requirements (posture, place, hands, held objects) and ends in
//! a valid state, with transition weights that favour the motion types a built dataset lacks.
//!
//! Its output is what the build reads back after the session: an event log
//! ([`motionforge_sources::annotate::event_log`]) whose instructions become clips, plus an operator sheet.
//! A tool over a scene file and a built dataset: it uses the report's readers and the event-log
//! format, no stage and no runner. `docs/planner.md` documents the rule and the figures.
//!
//! ```
//! use std::path::Path;
//! use motionforge_planner::{DatasetCounts, Scene, plan};
//!
//! let scene = Scene::load(Path::new("../../schemas/scenes/living-room.toml"))?;
//! let session = plan(&scene, &DatasetCounts::default(), 7)?;
//! assert!(!session.steps.is_empty());
//! assert_eq!(session, plan(&scene, &DatasetCounts::default(), 7)?);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Step 6 of a clip's way, looking forward: the dataset's counts per motion type decide which
//! instructions the next capture session favours, whose event log makes the next clips.

mod balance;
mod chain;
mod render;
mod scene;
mod state;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use balance::{DatasetCounts, factors, kl_to_target};
pub use chain::MAX_STATES;
pub use render::{EVENT_LOG_COLUMNS, event_log_csv, operator_sheet};
pub use scene::{
    Candidate, Hold, Limit, MAX_CANDIDATES, MAX_MOVABLE, MAX_OBJECTS, MAX_PLACES, MAX_SCENE_BYTES,
    NO_PLACE, Scene, SceneError, SceneProblem,
};
pub use state::{Effect, Loc, Posture, Requirement, State};

use motionforge_sources::annotate::span::Hand;

/// Why no session can be planned for a scene.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// No valid sequence exists: the requirement that cannot be met.
    #[error("no valid session: {requirement}")]
    Unplannable {
        /// The requirement, in words, with the scene's names.
        requirement: String,
    },
    /// The end state is reachable, but not within the session's limit.
    #[error("{}", over_budget_message(*needed, *limit))]
    OverBudget {
        /// Least cost from the start back to a valid end state.
        needed: u64,
        /// The limit, in the same unit (instructions or milliseconds).
        budget: u64,
        /// The limit as written.
        limit: Limit,
    },
    /// The scene reaches more states than the planner enumerates.
    #[error(
        "the scene reaches more than {states} states (places x postures x object positions); \
         split it into smaller scenes"
    )]
    TooLarge {
        /// The bound: [`MAX_STATES`], fewer for a scene whose instructions' requirements are
        /// long to check in every state (`docs/planner.md`).
        states: usize,
    },
}

fn over_budget_message(needed: u64, limit: Limit) -> String {
    match limit {
        Limit::Instructions(n) => format!(
            "no valid session: reaching the end state from the start takes at least {needed} \
             instructions, more than limits.instructions = {n}"
        ),
        Limit::Millis(ms) => format!(
            "no valid session: reaching the end state from the start takes at least {:.1} s by \
             the duration estimates, more than limits.minutes = {}",
            needed as f64 / 1000.0,
            ms as f64 / 60_000.0
        ),
    }
}

/// One planned instruction.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Index into [`Scene::candidates`].
    pub candidate: usize,
    /// The instruction text, placeholders filled.
    pub text: String,
    /// Its motion type.
    pub motion_type: String,
    /// The hand or hands it uses.
    pub hand: Option<Hand>,
    /// The object it involves (held object, else its place).
    pub object: Option<String>,
    /// What it does with its object (a grasp or release to mark).
    pub hold: Option<Hold>,
    /// Estimated seconds.
    pub seconds: f64,
    /// The state before it.
    pub before: State,
    /// The state after it.
    pub after: State,
}

/// A planned capture session.
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    /// The scene's name.
    pub scene: String,
    /// The seed it was drawn with.
    pub seed: u64,
    /// The instructions, in order.
    pub steps: Vec<Step>,
    /// Instructions per motion type in this session.
    pub session_counts: BTreeMap<String, u64>,
    /// The dataset's clips per motion type the balance started from (empty without a dataset).
    pub dataset_counts: BTreeMap<String, u64>,
    /// The target share per motion type.
    pub target: BTreeMap<String, f64>,
    /// Interactions no reachable state allows, with why.
    pub unreachable: Vec<String>,
}

impl Session {
    /// Estimated seconds of the whole session.
    pub fn seconds(&self) -> f64 {
        self.steps.iter().map(|s| s.seconds).sum()
    }

    /// Dataset plus session, per motion type.
    pub fn combined_counts(&self) -> BTreeMap<String, u64> {
        let mut all = self.dataset_counts.clone();
        for (t, n) in &self.session_counts {
            *all.entry(t.clone()).or_default() += n;
        }
        all
    }

    /// KL divergence (nats) of the dataset's distribution over the target's types from the
    /// target, before (`None` without counts) and after the session.
    pub fn kl(&self) -> (Option<f64>, Option<f64>) {
        (
            kl_to_target(&self.dataset_counts, &self.target),
            kl_to_target(&self.combined_counts(), &self.target),
        )
    }
}

/// Plans a session for `scene`, steering toward the scene's target from `counts` (empty counts:
/// the session balances only itself). The same scene, counts and seed give the same session.
pub fn plan(scene: &Scene, counts: &DatasetCounts, seed: u64) -> Result<Session, PlanError> {
    let graph = chain::Graph::explore(scene)?;
    chain::walk(scene, &graph, counts, seed)
}

/// The files [`write_session`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WrittenSession {
    /// The event log (`<capture>.csv`).
    pub event_log: PathBuf,
    /// The operator sheet (`<capture>.md`).
    pub sheet: PathBuf,
}

/// Writes the session's event log (`<capture>.csv`, read by the `event_log` annotation format
/// under the capture key `capture`) and operator sheet (`<capture>.md`) into `dir`, atomically.
pub fn write_session(
    session: &Session,
    scene: &Scene,
    dir: &Path,
    capture: &str,
) -> Result<WrittenSession, motionforge_core::base::WorkspaceError> {
    let event_log = dir.join(format!("{capture}.csv"));
    let sheet = dir.join(format!("{capture}.md"));
    if !dir.as_os_str().is_empty() {
        std::fs::create_dir_all(dir).map_err(motionforge_core::base::io_err(dir))?;
    }
    motionforge_core::base::write_atomic(&event_log, event_log_csv(session).as_bytes())?;
    motionforge_core::base::write_atomic(
        &sheet,
        operator_sheet(session, scene, capture).as_bytes(),
    )?;
    Ok(WrittenSession { event_log, sheet })
}
