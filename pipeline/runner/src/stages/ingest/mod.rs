//! `ingest`: one capture file in, the parsed capture out (at its own frame rate).
//!
//! Each kind of capture file is a [`CaptureFormat`] in a file of its own (`bvh.rs`,
//! `positions.rs`, `amass.rs`); [`format_of`] is the one place a source's config picks its format,
//! so a new kind of capture is its file, its config section and one line there.

mod amass;
mod bvh;
mod positions;

pub use bvh::Bvh;
pub use positions::body_positions;

use serde::{Deserialize, Serialize};

use crate::config::SourceConfig;
use crate::source::CaptureFile;
use crate::stage::{CachedStage, CaptureStage, Versioned};
use motionforge_core::base::{Fingerprint, Reject, RejectReason, Stamp};
use motionforge_core::motion::bvh::FPS_RANGE;
use motionforge_core::motion::{Motion, ProfileSpec};
use motionforge_sources::annotate::span::{Note, NoteKind};
use motionforge_sources::clip::{Capture, CaptureRef};

/// Stage name.
pub const NAME: &str = "ingest";
/// Bump when the stage's output for the same input changes (5: a capture records its effective
/// frame rate).
pub const VERSION: u32 = 5;

/// The stage as the runner caches it: one record per capture file.
pub(crate) struct Ingest;

impl Versioned for Ingest {
    const STAGE: crate::Stage = crate::Stage::Ingest;
    const VERSION: u32 = VERSION;
}

impl CachedStage for Ingest {
    type Output = IngestRecord;

    fn take_rejects(output: &mut IngestRecord) -> Vec<Reject> {
        std::mem::take(&mut output.rejects)
    }
}

impl CaptureStage for Ingest {}

/// Kind of the note that an AMASS file's frames, taken at HumanML3D's stride, are at another
/// rate than the 20 fps they are labelled with (counted in the build report's `notes_by_kind`).
pub const EFFECTIVE_RATE_NOTE: NoteKind = NoteKind::AmassEffectiveRate;

/// Bone-length change (relative to the bone's mean) from which a capture's IK fit is reported:
/// below it the bones are constant to the arrays' float precision.
pub const REPORTED_LENGTH_CHANGE: f64 = 1e-4;

/// What the stage reads for one capture.
#[derive(Debug)]
pub struct CaptureInput<'a> {
    /// The file.
    pub file: &'a CaptureFile,
    /// Its bytes.
    pub bytes: &'a [u8],
    /// SHA-256 of `bytes` (hex), computed once by the caller: hashing is a visible share of a
    /// build's time.
    pub sha256: &'a str,
    /// Source name.
    pub source: &'a str,
    /// Its source's profile.
    pub profile: &'a ProfileSpec,
    /// Frame-rate override for this file (BVH headers can be wrong).
    pub fps_override: Option<f64>,
    /// How the file is read ([`format_of`] its source).
    pub format: &'a dyn CaptureFormat,
}

/// A kind of capture file: what its reading depends on, which files of a source's globs hold a
/// motion, and how one is read.
pub trait CaptureFormat: std::fmt::Debug + Sync {
    /// Adds the format's settings to a capture's fingerprint (BVH adds none, so its captures
    /// keep their fingerprints).
    fn fingerprint(&self, print: Fingerprint) -> Fingerprint {
        print
    }

    /// For a file that sits among the captures but holds no motion, the note that it is skipped
    /// (it is not read).
    fn skipped(&self, _file: &CaptureFile) -> Option<Note> {
        None
    }

    /// Reads one capture: the capture, or why it is refused.
    fn read(&self, input: &CaptureInput<'_>) -> IngestOutput;
}

/// The format of `source`'s capture files, from its config: the one place a kind of capture is
/// registered.
pub fn format_of(source: &SourceConfig) -> &dyn CaptureFormat {
    if let Some(positions) = &source.positions {
        return positions;
    }
    if let Some(amass) = &source.amass {
        return amass;
    }
    &Bvh
}

/// The stage's output for one capture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct IngestOutput {
    /// The capture, unless it was refused.
    pub capture: Option<Capture>,
    /// Why it was refused.
    pub rejects: Vec<Reject>,
}

/// What the stage keeps for one capture: the capture described without its frames. Parsing the
/// file again costs less than storing its frames, so when a later stage must run again it re-reads
/// the file, whose content the fingerprint pins.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct IngestRecord {
    /// The capture's description, unless it was refused.
    pub capture: Option<CaptureHeader>,
    /// Why it was refused.
    pub rejects: Vec<Reject>,
}

/// A read capture without its frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaptureHeader {
    /// The file and its digest.
    pub capture: CaptureRef,
    /// File stem: the key annotations find the capture by.
    pub stem: String,
    /// Skeleton profile name.
    pub profile: String,
    /// The hierarchy.
    pub skeleton: std::sync::Arc<motionforge_core::motion::Skeleton>,
    /// Frames at the capture's rate.
    pub frames: u64,
}

impl IngestOutput {
    /// The record the stage cache keeps.
    pub fn record(&self) -> IngestRecord {
        IngestRecord {
            capture: self.capture.as_ref().map(|c| CaptureHeader {
                capture: c.capture.clone(),
                stem: c.stem.clone(),
                profile: c.profile.clone(),
                skeleton: std::sync::Arc::clone(&c.motion.skeleton),
                frames: c.motion.num_frames() as u64,
            }),
            rejects: self.rejects.clone(),
        }
    }
}

/// The fingerprint of one capture's ingest: everything the output depends on. The bytes are not
/// read: `input.sha256` stands for them, so the fingerprint is known without reading the file.
pub fn fingerprint(input: &CaptureInput<'_>) -> Stamp {
    let print = Ingest::fingerprint()
        .text("source name", input.source)
        .text("file path", &input.file.display)
        .text("file content", input.sha256)
        .json("skeleton profile", input.profile)
        .json("fps override", &input.fps_override);
    input.format.fingerprint(print).stamp()
}

/// A refusal of `file` by `stage`.
pub fn reject(
    stage: &str,
    file: &CaptureFile,
    reason: RejectReason,
    message: String,
    line: Option<u64>,
    frame: Option<u64>,
) -> Reject {
    Reject {
        stage: stage.to_string(),
        file: file.display.clone(),
        line,
        frame,
        reason,
        message,
    }
}

/// Runs the stage on one capture.
pub fn run(input: &CaptureInput<'_>) -> IngestOutput {
    input.format.read(input)
}

/// A capture read: its motion at `fps` (really at `effective_fps` when that is given), with what
/// the reader noted.
fn accepted(
    input: &CaptureInput<'_>,
    fps: f64,
    effective_fps: Option<f64>,
    motion: Motion,
    notes: Vec<Note>,
) -> IngestOutput {
    let file = input.file;
    IngestOutput {
        capture: Some(Capture {
            capture: CaptureRef {
                source: input.source.to_string(),
                path: file.display.clone(),
                sha256: input.sha256.to_string(),
                fps,
                effective_fps,
            },
            stem: file.stem(),
            profile: input.profile.name.clone(),
            motion,
            notes,
        }),
        rejects: Vec::new(),
    }
}

/// Why `fps` cannot be a capture's frame rate, when it is outside [`FPS_RANGE`].
fn implausible_fps(fps: f64) -> Option<String> {
    (!FPS_RANGE.contains(&fps)).then(|| {
        format!(
            "frame rate {fps} is outside the plausible range {} to {} fps",
            FPS_RANGE.start(),
            FPS_RANGE.end()
        )
    })
}
