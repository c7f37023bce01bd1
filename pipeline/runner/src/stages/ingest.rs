//! `ingest`: one capture file in, the parsed capture out (at its own frame rate).

use serde::{Deserialize, Serialize};

use crate::config::{AmassConfig, PositionsConfig};
use crate::source::CaptureFile;
use crate::stage::{CachedStage, CaptureStage, Versioned};
use motionforge_core::base::{Reject, RejectReason, Stamp};
use motionforge_core::motion::bvh::FPS_RANGE;
use motionforge_core::motion::ik::{PositionLayout, motion_from_positions};
use motionforge_core::motion::npy::read_joint_positions;
use motionforge_core::motion::{Motion, ProfileSpec, read_bvh};
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
    /// For joint-position arrays: how to read them (`None`: the file is BVH).
    pub positions: Option<&'a PositionsConfig>,
    /// For AMASS `.npz` files: the body model and how to read them.
    pub amass: Option<&'a AmassConfig>,
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
    // Only sources of joint positions and AMASS files name theirs, so BVH captures keep their
    // fingerprints.
    let print = match input.positions {
        Some(p) => print.json("positions", p),
        None => print,
    };
    match input.amass {
        // The body models are part of the input: a changed model changes every joint.
        Some(a) => print
            .json("amass", a)
            .text(
                "body models",
                &motionforge_sources::amass::models_digest(&a.body_model_dir),
            )
            .stamp(),
        None => print.stamp(),
    }
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
    let file = input.file;
    let refuse = |r: Reject| IngestOutput {
        capture: None,
        rejects: vec![r],
    };
    if let Some(positions) = input.positions {
        return run_positions(input, positions);
    }
    if let Some(amass) = input.amass {
        return run_amass(input, amass);
    }
    let text = match std::str::from_utf8(input.bytes) {
        Ok(t) => t,
        Err(e) => {
            let line = input.bytes[..e.valid_up_to()]
                .iter()
                .filter(|b| **b == b'\n')
                .count() as u64
                + 1;
            let message = format!("not UTF-8 text (byte {})", e.valid_up_to());
            return refuse(reject(
                NAME,
                file,
                RejectReason::Encoding,
                message,
                Some(line),
                None,
            ));
        }
    };
    let bvh = match read_bvh(text) {
        Ok(b) => b,
        Err(e) => {
            let frame = e.frame.map(|f| f as u64);
            return refuse(reject(
                NAME,
                file,
                RejectReason::Bvh,
                e.kind.to_string(),
                Some(e.line as u64),
                frame,
            ));
        }
    };
    if let Err(e) = input.profile.bind(&bvh.skeleton) {
        return refuse(reject(
            NAME,
            file,
            RejectReason::Profile,
            e.to_string(),
            None,
            None,
        ));
    }
    if bvh.motion.num_frames() == 0 {
        return refuse(reject(
            NAME,
            file,
            RejectReason::Empty,
            "capture has no frames".into(),
            None,
            None,
        ));
    }
    if let Some(fps) = input.fps_override
        && !FPS_RANGE.contains(&fps)
    {
        let message = format!(
            "frame-rate override {fps} (sources.fps_override or fps_table) is outside the plausible range {} to {} fps",
            FPS_RANGE.start(),
            FPS_RANGE.end()
        );
        return refuse(reject(NAME, file, RejectReason::Fps, message, None, None));
    }
    let fps = input.fps_override.unwrap_or(bvh.header_fps);
    let mut motion = bvh.motion;
    motion.fps = fps;
    accepted(input, fps, None, motion, Vec::new())
}

/// The joint-position array of one frame in the layout's first 22 joints, in HumanML3D's axes
/// (x left, y up, z forward) and metres: `negate_x` first, then the units, then the rotation
/// taking the arrays' up and forward to +y and +z.
pub fn body_positions(
    positions: &[glam::DVec3],
    joints: usize,
    config: &PositionsConfig,
) -> Vec<glam::DVec3> {
    let up = config.up.vector();
    let forward = config.forward.vector();
    let lateral = up.cross(forward);
    positions
        .chunks_exact(joints.max(1))
        .flat_map(|frame| frame.iter().take(22))
        .map(|&p| {
            let mut v = p;
            if config.negate_x {
                v.x = -v.x;
            }
            v *= config.units;
            glam::DVec3::new(v.dot(lateral), v.dot(up), v.dot(forward))
        })
        .collect()
}

/// Ingest of a joint-position array: read, checked against the layout, turned into a motion on
/// the clip's own bone lengths by inverse kinematics (`motion::ik`).
fn run_positions(input: &CaptureInput<'_>, config: &PositionsConfig) -> IngestOutput {
    let file = input.file;
    let refuse = |reason: RejectReason, message: String, frame: Option<u64>| IngestOutput {
        capture: None,
        rejects: vec![reject(NAME, file, reason, message, None, frame)],
    };
    let array = match read_joint_positions(input.bytes) {
        Ok(a) => a,
        Err(e) => {
            let frame = e.frame().map(|f| f as u64);
            return refuse(RejectReason::Positions, e.to_string(), frame);
        }
    };
    let want = config.layout.joints();
    if array.joints != want {
        return refuse(
            RejectReason::Positions,
            format!(
                "{} joints per frame; layout `{}` stores {want}",
                array.joints,
                config.layout.as_str()
            ),
            None,
        );
    }
    if array.frames == 0 {
        return refuse(RejectReason::Empty, "capture has no frames".into(), None);
    }
    let fps = input.fps_override.unwrap_or(config.fps);
    if let Some(message) = implausible_fps(fps) {
        return refuse(RejectReason::Fps, message, None);
    }
    let Some(layout) = PositionLayout::from_profile(input.profile) else {
        let message = format!(
            "profile `{}` lists no joints and parents, so it cannot hold joint positions (use `smpl-22`)",
            input.profile.name
        );
        return refuse(RejectReason::Profile, message, None);
    };
    if layout.names.len() != 22 {
        let message = format!(
            "profile `{}` has {} joints; joint-position layouts give the 22 SMPL body joints (use `smpl-22`)",
            input.profile.name,
            layout.names.len()
        );
        return refuse(RejectReason::Profile, message, None);
    }
    let body = body_positions(&array.positions, array.joints, config);
    let (motion, fit) = match motion_from_positions(&layout, &body, fps, config.bone_tolerance) {
        Ok(m) => m,
        Err(e) => {
            let frame = e.frame().map(|f| f as u64);
            return refuse(RejectReason::Positions, e.to_string(), frame);
        }
    };
    if let Err(e) = input.profile.bind(&motion.skeleton) {
        return refuse(RejectReason::Profile, e.to_string(), None);
    }
    let mut notes = Vec::new();
    if fit.max_length_change > REPORTED_LENGTH_CHANGE {
        let (frame, joint) = fit.worst;
        notes.push(Note::new(
            NoteKind::IkResidual,
            format!(
                "`{}`: bone lengths vary up to {:.3}% from their means, so forward kinematics \
                 reproduces the positions to {:.2e} m (worst: frame {frame}, joint `{}`)",
                file.display,
                100.0 * fit.max_length_change,
                fit.max_residual,
                layout.names.get(joint).map_or("?", String::as_str),
            ),
        ));
    }
    accepted(input, fps, None, motion, notes)
}

/// Ingest of an AMASS `.npz`: the sequence read, its body model found (by family and gender) and
/// the poses put on the model's skeleton, at the file's rate or HumanML3D's stride.
fn run_amass(input: &CaptureInput<'_>, config: &AmassConfig) -> IngestOutput {
    use motionforge_sources::amass::{
        FrameRateMode, HUMANML3D_FPS, humanml3d_stride, model_gender, model_path,
    };
    let file = input.file;
    let refuse = |reason: RejectReason, message: String, frame: Option<u64>| IngestOutput {
        capture: None,
        rejects: vec![reject(NAME, file, reason, message, None, frame)],
    };
    // Noted at the source (`source::annotation_notes`), never read as motions.
    if motionforge_sources::amass::is_not_a_motion(&file.file_name()) {
        return IngestOutput::default();
    }
    let sequence = match motionforge_sources::amass::read_sequence(
        &file.display,
        input.bytes,
        input.fps_override.is_none(),
    ) {
        Ok(s) => s,
        Err(e) => {
            let frame = match &e.kind {
                motionforge_sources::amass::AmassErrorKind::Value { frame, .. } => {
                    Some(*frame as u64)
                }
                _ => None,
            };
            return refuse(RejectReason::Amass, e.kind.to_string(), frame);
        }
    };
    let profile = input.profile.name.as_str();
    let wanted = sequence.family.profile();
    if ["smplh-52", "smplx-55"].contains(&profile) && profile != wanted {
        let message = format!(
            "{} file (`poses` {} wide) in a source whose profile is `{profile}`: put it in a source with profile `{wanted}`",
            if wanted == "smplh-52" {
                "an SMPL-H"
            } else {
                "an SMPL-X"
            },
            3 * sequence.family.joints()
        );
        return refuse(RejectReason::Profile, message, None);
    }
    let Some(fps) = input.fps_override.or(sequence.fps) else {
        return refuse(
            RejectReason::Amass,
            motionforge_sources::amass::AmassErrorKind::NoFrameRate.to_string(),
            None,
        );
    };
    if let Some(message) = implausible_fps(fps) {
        return refuse(RejectReason::Fps, message, None);
    }
    let gender = match model_gender(
        config.gender,
        sequence.gender.as_ref(),
        config.humanml3d_gender,
    ) {
        Ok(g) => g,
        Err(message) => return refuse(RejectReason::Amass, message, None),
    };
    let path = model_path(&config.body_model_dir, sequence.family, gender);
    if !path.is_file() {
        let message = format!(
            "needs the {gender} {} body model, but {} does not exist (set sources.amass.gender to use another)",
            sequence.family.folder(),
            path.display()
        );
        return refuse(RejectReason::Amass, message, None);
    }
    let model = match motionforge_sources::amass::load_model(&path, config.num_betas) {
        Ok(m) => m,
        Err(e) => return refuse(RejectReason::Amass, e.to_string(), None),
    };
    let mut notes = Vec::new();
    let (stride, label_fps, effective_fps) = match config.frame_rate {
        FrameRateMode::Resample => (1, fps, None),
        FrameRateMode::Humanml3d => {
            let (stride, effective) = humanml3d_stride(fps);
            let off_rate = (effective - HUMANML3D_FPS).abs() > 1e-6;
            if off_rate {
                notes.push(Note::new(
                    EFFECTIVE_RATE_NOTE,
                    format!(
                        "`{}`: {fps} fps taken every {stride} frames is {effective:.4} fps, labelled {HUMANML3D_FPS} fps as HumanML3D does",
                        file.display
                    ),
                ));
            }
            (stride, HUMANML3D_FPS, off_rate.then_some(effective))
        }
    };
    let motion = match motionforge_sources::amass::to_motion(&sequence, &model, stride, label_fps) {
        Ok(m) => m,
        Err(e) => return refuse(RejectReason::Amass, e.to_string(), None),
    };
    if motion.num_frames() == 0 {
        return refuse(RejectReason::Empty, "capture has no frames".into(), None);
    }
    if let Err(e) = input.profile.bind(&motion.skeleton) {
        return refuse(RejectReason::Profile, e.to_string(), None);
    }
    accepted(input, label_fps, effective_fps, motion, notes)
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
