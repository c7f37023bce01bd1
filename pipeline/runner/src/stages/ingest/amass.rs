//! AMASS `.npz` sequences (`[sources.amass]`): the poses put on the skeleton of the user's own
//! body model (found by family and gender), at the file's rate or HumanML3D's stride.

use super::{
    CaptureFormat, CaptureInput, EFFECTIVE_RATE_NOTE, IngestOutput, NAME, accepted,
    implausible_fps, reject,
};
use crate::config::AmassConfig;
use crate::source::CaptureFile;
use motionforge_core::base::{Fingerprint, RejectReason};
use motionforge_sources::annotate::span::{Note, NoteKind};

impl CaptureFormat for AmassConfig {
    fn fingerprint(&self, print: Fingerprint) -> Fingerprint {
        // The body models are part of the input: a changed model changes every joint.
        print.json("amass", self).text(
            "body models",
            &motionforge_sources::amass::models_digest(&self.body_model_dir),
        )
    }

    /// Body shapes and MoSh's first stage sit beside AMASS sequences.
    fn skipped(&self, file: &CaptureFile) -> Option<Note> {
        motionforge_sources::amass::is_not_a_motion(&file.file_name()).then(|| {
            Note::new(
                NoteKind::AmassNotAMotion,
                format!(
                    "`{}`: a body shape or MoSh stage-i file, not a motion: skipped",
                    file.display
                ),
            )
        })
    }

    fn read(&self, input: &CaptureInput<'_>) -> IngestOutput {
        read_amass(input, self)
    }
}

/// Ingest of an AMASS `.npz`: the sequence read, its body model found (by family and gender) and
/// the poses put on the model's skeleton, at the file's rate or HumanML3D's stride.
fn read_amass(input: &CaptureInput<'_>, config: &AmassConfig) -> IngestOutput {
    use motionforge_sources::amass::{
        FrameRateMode, HUMANML3D_FPS, humanml3d_stride, model_gender, model_path,
    };
    let file = input.file;
    let refuse = |reason: RejectReason, message: String, frame: Option<u64>| IngestOutput {
        capture: None,
        rejects: vec![reject(NAME, file, reason, message, None, frame)],
    };
    // Noted at the source (`source::annotation_notes`), never read as motions.
    if config.skipped(file).is_some() {
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
