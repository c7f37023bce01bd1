//! Motions stay on disk while the build holds the rest of every clip: a clip's frames are read back
//! from the chunks the stage that made them spilled (segment, mirror, synthetic) only when a stage
//! needs them, so memory grows with the number of clips, not with their frames.

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};

use super::{BuildError, Workspace, WorkspaceError, sha256_hex};
use crate::clip::Clip;
use crate::motion::Motion;

/// Stage-cache folder of synthetic motions, in chunks.
pub(super) const SYNTHETIC_CHUNKS: &str = "synthetic";
/// Stage-cache folder of segmented clips' motions, in chunks.
pub(super) const SEGMENT_CHUNKS: &str = "segment-motions";
/// Stage-cache folder of mirrored clips' motions, in chunks.
pub(super) const MIRROR_CHUNKS: &str = "mirror-motions";
/// Synthetic motions per chunk file.
pub(super) const CHUNK: usize = 32;
/// Decoded entries kept: a capture's originals and mirrors, and the chunk being written.
const RECENT: usize = 4;

/// Where a clip's frames are: a stage-cache entry and the clip's place in it.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub(super) struct MotionRef {
    /// Stage-cache folder of the chunk (`segment-motions`, `mirror-motions` or `synthetic`).
    pub(super) stage: String,
    /// The entry's fingerprint.
    pub(super) fingerprint: String,
    /// The clip's index among the entry's motions.
    pub(super) index: u32,
    /// Frames of the motion (the held clip has none).
    pub(super) frames: u32,
}

/// Every held clip's motion location, by clip id and capture path.
pub(super) type MotionIndex = BTreeMap<(String, String), MotionRef>;

/// The key of a clip in a [`MotionIndex`].
pub(super) fn key(clip: &Clip) -> (String, String) {
    (clip.clip_id.clone(), clip.capture.path.clone())
}

/// Reads motions back from the stage cache, keeping the last few entries decoded.
pub(super) struct MotionSource {
    workspace: Workspace,
    recent: Mutex<VecDeque<(String, Arc<Vec<Motion>>)>>,
}

impl MotionSource {
    /// Motions of `workspace`'s cache.
    pub(super) fn new(workspace: &Workspace) -> MotionSource {
        MotionSource {
            workspace: workspace.clone(),
            recent: Mutex::new(VecDeque::new()),
        }
    }

    /// The motion `at` points to.
    pub(super) fn motion(&self, at: &MotionRef) -> Result<Motion, BuildError> {
        let id = format!("{}/{}", at.stage, at.fingerprint);
        let found = self
            .recent
            .lock()
            .ok()
            .and_then(|r| r.iter().find(|(k, _)| *k == id).map(|(_, m)| Arc::clone(m)));
        let entry = match found {
            Some(m) => m,
            None => {
                let motions = Arc::new(self.read(at)?);
                if let Ok(mut recent) = self.recent.lock() {
                    if recent.len() >= RECENT {
                        recent.pop_front();
                    }
                    recent.push_back((id, Arc::clone(&motions)));
                }
                motions
            }
        };
        entry
            .get(at.index as usize)
            .cloned()
            .ok_or_else(|| missing(at, "the entry has fewer clips"))
    }

    /// The frames of a held `clip`.
    pub(super) fn motion_of(&self, clip: &Clip, index: &MotionIndex) -> Result<Motion, BuildError> {
        let at = index.get(&key(clip)).ok_or_else(|| {
            BuildError::Motion(format!("no motion recorded for clip `{}`", clip.clip_id))
        })?;
        self.motion(at)
    }

    /// `clip` with its frames read back.
    pub(super) fn hydrate(&self, clip: &Clip, index: &MotionIndex) -> Result<Clip, BuildError> {
        let mut full = clip.clone();
        full.motion = self.motion_of(clip, index)?;
        Ok(full)
    }

    fn read(&self, at: &MotionRef) -> Result<Vec<Motion>, BuildError> {
        let motions = match at.stage.as_str() {
            SEGMENT_CHUNKS | MIRROR_CHUNKS | SYNTHETIC_CHUNKS => self
                .workspace
                .load::<Vec<Motion>>(&at.stage, &at.fingerprint),
            _ => None,
        };
        motions.ok_or_else(|| missing(at, "the cache entry is gone or unreadable"))
    }
}

fn missing(at: &MotionRef, why: &str) -> BuildError {
    BuildError::Workspace(WorkspaceError::Io {
        path: format!(".motionforge/cache/{}/{}.bin", at.stage, at.fingerprint).into(),
        source: std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!("{why}; run the build again with --force"),
        ),
    })
}

/// Moves clips' frames to disk as they are made, in chunks of [`CHUNK`] named by their content,
/// so a stage holds one chunk of frames however many clips it makes.
pub(super) struct MotionSpill<'w> {
    workspace: &'w Workspace,
    /// Stage-cache folder of the chunks.
    stage: &'static str,
    pending: Vec<Motion>,
    refs: Vec<MotionRef>,
}

impl<'w> MotionSpill<'w> {
    /// Spills into the `stage` folder of `workspace`'s cache.
    pub(super) fn new(workspace: &'w Workspace, stage: &'static str) -> Self {
        MotionSpill {
            workspace,
            stage,
            pending: Vec::new(),
            refs: Vec::new(),
        }
    }

    /// Takes `clip`'s frames; they are stored with the chunk.
    pub(super) fn push(&mut self, clip: &mut Clip) -> Result<(), BuildError> {
        let held = Motion {
            skeleton: Arc::clone(&clip.motion.skeleton),
            fps: clip.motion.fps,
            rotations: Vec::new(),
            translations: Vec::new(),
        };
        let motion = std::mem::replace(&mut clip.motion, held);
        self.refs.push(MotionRef {
            stage: self.stage.to_string(),
            fingerprint: String::new(),
            index: self.pending.len() as u32,
            frames: motion.num_frames() as u32,
        });
        self.pending.push(motion);
        if self.pending.len() == CHUNK {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), BuildError> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let bytes = postcard::to_stdvec(&self.pending).map_err(|e| WorkspaceError::Encode {
            what: format!("{} chunk", self.stage),
            message: e.to_string(),
        })?;
        let fingerprint = sha256_hex(&bytes);
        self.workspace
            .store_bytes(self.stage, &fingerprint, &bytes)?;
        let start = self.refs.len() - self.pending.len();
        for r in &mut self.refs[start..] {
            r.fingerprint.clone_from(&fingerprint);
        }
        self.pending.clear();
        Ok(())
    }

    /// Stores the last chunk; where each pushed clip's frames went, in push order.
    pub(super) fn finish(mut self) -> Result<Vec<MotionRef>, BuildError> {
        self.flush()?;
        Ok(self.refs)
    }
}
