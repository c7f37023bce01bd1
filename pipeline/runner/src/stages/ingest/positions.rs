//! Joint-position arrays (`.npy`, `[sources.positions]`): read, checked against the layout and
//! turned into a motion on the clip's own bone lengths by inverse kinematics.

use super::{
    CaptureFormat, CaptureInput, IngestOutput, NAME, REPORTED_LENGTH_CHANGE, accepted,
    implausible_fps, reject,
};
use crate::config::PositionsConfig;
use motionforge_core::base::{Fingerprint, RejectReason};
use motionforge_core::motion::ik::{PositionLayout, motion_from_positions};
use motionforge_core::motion::npy::read_joint_positions;
use motionforge_sources::annotate::span::{Note, NoteKind};

impl CaptureFormat for PositionsConfig {
    fn fingerprint(&self, print: Fingerprint) -> Fingerprint {
        print.json("positions", self)
    }

    fn read(&self, input: &CaptureInput<'_>) -> IngestOutput {
        read_positions(input, self)
    }
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
fn read_positions(input: &CaptureInput<'_>, config: &PositionsConfig) -> IngestOutput {
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
