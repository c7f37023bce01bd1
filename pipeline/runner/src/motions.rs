//! Motions stay on disk while the build holds the rest of every clip: a clip's frames are read back
//! from the chunks the segment stage spilled only when a stage needs them, so memory grows with the
//! number of clips, not with their frames. Mirrors and synthetic pairs are not stored: they are made
//! again from their sources when read, which costs less than writing and reading them.

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};

use super::{BuildError, Workspace, WorkspaceError, sha256_hex};
use motionforge_core::motion::compose::{Trim, compose};
use motionforge_core::motion::{BoundProfiles, MirrorPlan, Motion, OffsetPolicy, ProfileSpec};
use motionforge_sources::clip::{Clip, LoadedClip};

/// Stage-cache folder of segmented clips' motions, in chunks.
pub(super) const SEGMENT_CHUNKS: &str = "segment-motions";
/// Stage-cache folders where earlier versions stored mirrored and synthetic frames: emptied.
pub(super) const RETIRED_CHUNKS: [&str; 2] = ["mirror-motions", "synthetic"];
/// Motions per chunk file.
pub(super) const CHUNK: usize = 32;
/// Decoded entries kept: a capture's originals and mirrors, and the chunk being written.
const RECENT: usize = 4;

/// Where a clip's frames are: stored in a stage-cache chunk, or made when read from frames that
/// are (a mirror is a cheap function of its original, a synthetic pair of its two sources, so
/// storing them would only multiply the cache).
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub(super) enum MotionRef {
    /// Frames stored in a chunk of the stage cache.
    Stored {
        /// Stage-cache folder of the chunk (`segment-motions`). Shared: every clip's reference,
        /// its mirror's and its composites' name the same one.
        stage: Arc<str>,
        /// The entry's fingerprint, shared like `stage` (encoded as the string it is).
        fingerprint: Arc<str>,
        /// The clip's index among the entry's motions.
        index: u32,
        /// Frames of the motion (the held clip has none).
        frames: u32,
    },
    /// The left/right mirror of another motion, on the same skeleton.
    Mirrored(Box<MotionRef>),
    /// Two motions stitched by body part (`motion::compose`).
    Composed {
        /// The first motion and the parts it does.
        first: Box<MotionRef>,
        /// Parts of `first` (`motion::compose::PartMask`).
        first_parts: u8,
        /// The second motion.
        second: Box<MotionRef>,
        /// Parts of `second`.
        second_parts: u8,
        /// Where the composite starts in the longer motion (`None`: at its start).
        start: Option<u32>,
        /// Frames of the composite.
        frames: u32,
    },
}

impl MotionRef {
    /// Frames of the motion.
    pub(super) fn frames(&self) -> u32 {
        match self {
            MotionRef::Stored { frames, .. } | MotionRef::Composed { frames, .. } => *frames,
            MotionRef::Mirrored(of) => of.frames(),
        }
    }

    /// The stored chunks (stage folder, fingerprint) the motion is made from.
    pub(super) fn chunks(&self) -> Vec<(&str, &str)> {
        match self {
            MotionRef::Stored {
                stage, fingerprint, ..
            } => vec![(&**stage, &**fingerprint)],
            MotionRef::Mirrored(of) => of.chunks(),
            MotionRef::Composed { first, second, .. } => {
                let mut all = first.chunks();
                all.extend(second.chunks());
                all
            }
        }
    }
}

/// Every held clip's motion location, by clip id and capture path.
pub(super) type MotionIndex = BTreeMap<ClipKey, MotionRef>;

/// A clip's key in a [`MotionIndex`]: its id and its capture's path, ordered, compared and
/// encoded as the pair of strings. The path is the clip's shared capture reference, not a copy:
/// the index holds every clip of the table.
#[derive(Debug, Clone)]
pub(super) struct ClipKey {
    clip_id: String,
    capture: Arc<motionforge_sources::clip::CaptureRef>,
}

impl ClipKey {
    fn parts(&self) -> (&str, &str) {
        (&self.clip_id, &self.capture.path)
    }
}

impl PartialEq for ClipKey {
    fn eq(&self, other: &Self) -> bool {
        self.parts() == other.parts()
    }
}

impl Eq for ClipKey {}

impl PartialOrd for ClipKey {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for ClipKey {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.parts().cmp(&other.parts())
    }
}

impl Serialize for ClipKey {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        self.parts().serialize(serializer)
    }
}

/// The key of a clip in a [`MotionIndex`].
pub(super) fn key(clip: &Clip) -> ClipKey {
    ClipKey {
        clip_id: clip.clip_id.clone(),
        capture: Arc::clone(&clip.capture),
    }
}

/// Reads motions back from the stage cache, keeping the last few entries decoded, and makes the
/// mirrors and composites the cache does not store.
pub(super) struct MotionSource {
    workspace: Workspace,
    /// Skeleton profiles by name: mirrors and composites need the bound profile.
    specs: Vec<ProfileSpec>,
    bound: Arc<BoundProfiles>,
    /// Bone offsets of mirrors (`[mirror] offsets`).
    offsets: OffsetPolicy,
    recent: Mutex<VecDeque<(String, Arc<Vec<Motion>>)>>,
}

impl MotionSource {
    /// Motions of `workspace`'s cache, on skeletons of the profiles `specs`.
    pub(super) fn new(
        workspace: &Workspace,
        specs: &[ProfileSpec],
        bound: &Arc<BoundProfiles>,
        offsets: OffsetPolicy,
    ) -> MotionSource {
        MotionSource {
            workspace: workspace.clone(),
            specs: specs.to_vec(),
            bound: Arc::clone(bound),
            offsets,
            recent: Mutex::new(VecDeque::new()),
        }
    }

    /// A source over the same cache with its own memory of recent entries, for another thread.
    pub(super) fn sibling(&self) -> MotionSource {
        MotionSource::new(&self.workspace, &self.specs, &self.bound, self.offsets)
    }

    /// The motion `at` points to, on a skeleton of profile `profile`.
    pub(super) fn motion(&self, at: &MotionRef, profile: &str) -> Result<Motion, BuildError> {
        match at {
            MotionRef::Stored { .. } => self.stored(at),
            MotionRef::Mirrored(of) => {
                let original = self.motion(of, profile)?;
                let bound = self.bind(&original, profile)?;
                let plan = MirrorPlan::from_profile(&original.skeleton, &bound)
                    .map_err(BuildError::Remirror)?;
                Ok(plan.mirror(&original, self.offsets))
            }
            MotionRef::Composed {
                first,
                first_parts,
                second,
                second_parts,
                start,
                ..
            } => {
                let a = self.motion(first, profile)?;
                let b = self.motion(second, profile)?;
                let bound = self.bind(&a, profile)?;
                let trim = start.map_or(Trim::Start, |s| Trim::At(s as usize));
                Ok(compose(&a, *first_parts, &b, *second_parts, &bound, trim).motion)
            }
        }
    }

    fn bind(
        &self,
        motion: &Motion,
        profile: &str,
    ) -> Result<motionforge_core::motion::Profile, BuildError> {
        let spec = self
            .specs
            .iter()
            .find(|s| s.name == profile)
            .ok_or_else(|| BuildError::NoProfile {
                profile: profile.to_string(),
            })?;
        self.bound
            .bind(spec, &motion.skeleton)
            .map_err(|error| BuildError::Rebind {
                profile: profile.to_string(),
                error: Box::new(error),
            })
    }

    fn stored(&self, at: &MotionRef) -> Result<Motion, BuildError> {
        let MotionRef::Stored {
            stage,
            fingerprint,
            index,
            ..
        } = at
        else {
            return Err(missing(at, "not a stored motion"));
        };
        let id = format!("{stage}/{fingerprint}");
        let found = self
            .recent
            .lock()
            .ok()
            .and_then(|r| r.iter().find(|(k, _)| *k == id).map(|(_, m)| Arc::clone(m)));
        let entry = match found {
            Some(m) => m,
            None => {
                let motions = Arc::new(self.read(at, stage, fingerprint)?);
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
            .get(*index as usize)
            .cloned()
            .ok_or_else(|| missing(at, "the entry has fewer clips"))
    }

    /// The frames of a held `clip`.
    pub(super) fn motion_of(&self, clip: &Clip, index: &MotionIndex) -> Result<Motion, BuildError> {
        let at = index.get(&key(clip)).ok_or_else(|| BuildError::NoMotion {
            clip: clip.clip_id.clone(),
        })?;
        self.motion(at, &clip.profile)
    }

    /// `clip` with its frames read back.
    pub(super) fn load(&self, clip: &Clip, index: &MotionIndex) -> Result<LoadedClip, BuildError> {
        Ok(LoadedClip {
            clip: clip.clone(),
            motion: self.motion_of(clip, index)?,
        })
    }

    fn read(
        &self,
        at: &MotionRef,
        stage: &str,
        fingerprint: &str,
    ) -> Result<Vec<Motion>, BuildError> {
        let packed = match stage {
            SEGMENT_CHUNKS => self.workspace.load::<Vec<PackedMotion>>(stage, fingerprint),
            _ => None,
        };
        let packed = packed.ok_or_else(|| missing(at, "the cache entry is gone or unreadable"))?;
        packed
            .into_iter()
            .map(PackedMotion::unpack)
            .collect::<Option<Vec<Motion>>>()
            .ok_or_else(|| missing(at, "the cache entry is inconsistent"))
    }
}

fn missing(at: &MotionRef, why: &str) -> BuildError {
    let (stage, fingerprint) = at.chunks().first().copied().unwrap_or(("?", "?"));
    BuildError::Workspace(WorkspaceError::Io {
        path: format!(".motionforge/cache/{stage} (entry {fingerprint})").into(),
        source: std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!("{why}; run the build again with --force"),
        ),
    })
}

/// A joint's local translation over a motion: most joints keep their offset in every frame, so
/// it is stored once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
enum Track {
    /// The same translation in every frame.
    Fixed([f64; 3]),
    /// One translation per frame.
    Moving(Vec<[f64; 3]>),
}

/// A motion as a cache chunk stores it: the same numbers as [`Motion`] (so outputs made from the
/// cache are bit-identical to outputs made from the parse), without repeating constant
/// translations in every frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct PackedMotion {
    skeleton: Arc<motionforge_core::motion::Skeleton>,
    fps: f64,
    frames: u32,
    /// Frame-major local rotations (x, y, z, w).
    rotations: Vec<[f64; 4]>,
    /// One track per joint.
    tracks: Vec<Track>,
}

impl PackedMotion {
    fn pack(motion: &Motion) -> PackedMotion {
        let joints = motion.num_joints();
        let frames = motion.num_frames();
        let tracks = (0..joints)
            .map(|j| {
                let mut values = (0..frames).map(|f| motion.translations[f * joints + j]);
                let first = values.next().unwrap_or_default();
                if values.all(|t| t.to_array() == first.to_array()) {
                    Track::Fixed(first.to_array())
                } else {
                    Track::Moving(
                        (0..frames)
                            .map(|f| motion.translations[f * joints + j].to_array())
                            .collect(),
                    )
                }
            })
            .collect();
        PackedMotion {
            skeleton: Arc::clone(&motion.skeleton),
            fps: motion.fps,
            frames: frames as u32,
            rotations: motion.rotations.iter().map(|q| q.to_array()).collect(),
            tracks,
        }
    }

    /// The motion, or `None` when the arrays do not fit together (a damaged entry).
    fn unpack(self) -> Option<Motion> {
        let joints = self.skeleton.joints.len();
        let frames = self.frames as usize;
        if self.tracks.len() != joints || self.rotations.len() != frames.checked_mul(joints)? {
            return None;
        }
        let mut translations = vec![glam::DVec3::ZERO; frames * joints];
        for (j, track) in self.tracks.iter().enumerate() {
            match track {
                Track::Fixed(t) => {
                    for f in 0..frames {
                        translations[f * joints + j] = glam::DVec3::from_array(*t);
                    }
                }
                Track::Moving(ts) => {
                    if ts.len() != frames {
                        return None;
                    }
                    for (f, t) in ts.iter().enumerate() {
                        translations[f * joints + j] = glam::DVec3::from_array(*t);
                    }
                }
            }
        }
        Some(Motion {
            skeleton: self.skeleton,
            fps: self.fps,
            rotations: self
                .rotations
                .into_iter()
                .map(glam::DQuat::from_array)
                .collect(),
            translations,
        })
    }
}

/// Moves segmented clips' frames to disk as they are made, in chunks of at most [`CHUNK`] named by
/// their content, so a stage holds one chunk of frames however many clips it makes. (The names
/// reach the table fingerprint in the manifest: they say what the frames are, not where.)
pub(super) struct MotionSpill<'w> {
    workspace: &'w Workspace,
    pending: Vec<PackedMotion>,
    refs: Vec<MotionRef>,
    /// The folder name every reference shares.
    stage: Arc<str>,
}

impl<'w> MotionSpill<'w> {
    /// Spills into the `segment-motions` folder of `workspace`'s cache.
    pub(super) fn new(workspace: &'w Workspace) -> Self {
        MotionSpill {
            workspace,
            pending: Vec::new(),
            refs: Vec::new(),
            stage: SEGMENT_CHUNKS.into(),
        }
    }

    /// Takes a clip's frames; they are stored with the chunk.
    pub(super) fn push(&mut self, motion: Motion) -> Result<(), BuildError> {
        self.refs.push(MotionRef::Stored {
            stage: Arc::clone(&self.stage),
            // Named when its chunk is stored (`flush`).
            fingerprint: Arc::from(""),
            index: self.pending.len() as u32,
            frames: motion.num_frames() as u32,
        });
        self.pending.push(PackedMotion::pack(&motion));
        if self.pending.len() == CHUNK {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), BuildError> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let bytes =
            postcard::to_stdvec(&self.pending).map_err(|source| WorkspaceError::Encode {
                what: format!("{SEGMENT_CHUNKS} chunk"),
                source,
            })?;
        let name: Arc<str> = sha256_hex(&bytes).into();
        self.workspace.store_bytes(SEGMENT_CHUNKS, &name, &bytes)?;
        let start = self.refs.len() - self.pending.len();
        for r in &mut self.refs[start..] {
            if let MotionRef::Stored { fingerprint, .. } = r {
                *fingerprint = Arc::clone(&name);
            }
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
