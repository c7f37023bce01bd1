//! BVH captures: the hierarchy and motion of a `.bvh` file, its frame rate from the header unless
//! overridden.

use super::{CaptureFormat, CaptureInput, IngestOutput, NAME, accepted, reject};
use motionforge_core::base::{Reject, RejectReason};
use motionforge_core::motion::bvh::FPS_RANGE;
use motionforge_core::motion::read_bvh;

/// BVH files: the format of a source with neither `[sources.positions]` nor `[sources.amass]`.
#[derive(Debug, Clone, Copy, Default)]
pub struct Bvh;

impl CaptureFormat for Bvh {
    fn read(&self, input: &CaptureInput<'_>) -> IngestOutput {
        let file = input.file;
        let refuse = |r: Reject| IngestOutput {
            capture: None,
            rejects: vec![r],
        };
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
}
