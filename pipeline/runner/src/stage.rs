//! What the runner needs of a stage: its place and version ([`Versioned`]), and for a stage whose
//! outputs the stage cache keeps, their type ([`CachedStage`]).
//!
//! The runner looks a cached stage's output up by the stage's fingerprint, runs it on a miss,
//! stores the output, records the stamp for the ledger and `plan`, and (for per-capture stages,
//! [`CaptureStage`]) marks the capture's item pending, done or refused. The stage's code only
//! says how to fingerprint its input and how to compute its output; the build's loop over its
//! steps (`steps.rs`) reports each stage's run and records it in the ledger.

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::capture::Item;
use super::{Reject, Stage, Workspace, WorkspaceError};
use motionforge_core::base::{Fingerprint, Stamp};

/// A stage as its fingerprints name it: its place among the build's stages and its version.
pub(crate) trait Versioned {
    /// Its place among the build's stages.
    const STAGE: Stage;
    /// Name in the stage cache, the ledger, progress lines and reports: the stage's.
    const NAME: &'static str = Self::STAGE.name();
    /// Bump when the stage's output for the same input changes: every cached output of the
    /// stage (and of the stages fed by it) is then made again.
    const VERSION: u32;

    /// The start of every fingerprint of the stage: its name and version.
    fn fingerprint() -> Fingerprint {
        Fingerprint::new(Self::NAME, Self::VERSION)
    }
}

/// A stage whose outputs are cached, item by item.
pub(crate) trait CachedStage: Versioned {
    /// What the cache keeps for one item.
    type Output: Serialize + DeserializeOwned;

    /// The rejects an output carries, taken out of it for the build's list.
    fn take_rejects(_output: &mut Self::Output) -> Vec<Reject> {
        Vec::new()
    }
}

/// A stage run capture by capture, recorded on each capture's [`Item`].
pub(crate) trait CaptureStage: CachedStage {}

impl Workspace {
    /// The cached output of stage `S` for item `key`, or `compute`'s, stored; the flag says
    /// whether it ran. An output `usable` refuses (one naming entries of another stage that are
    /// gone) is made again. In probe mode a miss returns `None` and computes nothing.
    pub(crate) fn run_stage<S: CachedStage, E: From<WorkspaceError>>(
        &self,
        key: &str,
        stamp: &Stamp,
        usable: impl FnOnce(&S::Output) -> bool,
        compute: impl FnOnce() -> Result<S::Output, E>,
    ) -> Result<Option<(S::Output, bool)>, E> {
        self.try_item_where(S::NAME, key, stamp, usable, compute)
    }
}

impl Item {
    /// Stage `S` on this capture through the stage cache ([`Workspace::run_stage`]): the
    /// output, with its rejects moved to the item and the stage recorded as done (ran or
    /// reused); `None` in probe mode when it is not cached, the item then pending at `S`.
    pub(crate) fn run_stage<S: CaptureStage, E: From<WorkspaceError>>(
        &mut self,
        workspace: &Workspace,
        stamp: Stamp,
        usable: impl FnOnce(&S::Output) -> bool,
        compute: impl FnOnce() -> Result<S::Output, E>,
    ) -> Result<Option<S::Output>, E> {
        let Some((mut output, ran)) =
            workspace.run_stage::<S, E>(&self.key, &stamp, usable, compute)?
        else {
            self.pending = Some(S::STAGE);
            return Ok(None);
        };
        self.done.push((S::STAGE, stamp.fingerprint, ran));
        self.rejects.extend(S::take_rejects(&mut output));
        Ok(Some(output))
    }
}
