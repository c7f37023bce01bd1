//! A motion: per-frame local rotations and translations on a [`Skeleton`], and forward kinematics.

use std::sync::Arc;

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

use super::skeleton::Skeleton;

/// Local joint transforms over time. Frame-major: the value of joint `j` at frame `f` is at
/// `f * joints + j`. Translations hold, per joint, the position channels where the joint has them
/// and its rest offset otherwise, so forward kinematics needs no special case.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Motion {
    /// The hierarchy the transforms apply to.
    pub skeleton: Arc<Skeleton>,
    /// Frames per second.
    pub fps: f64,
    /// Local rotation of every joint at every frame (relative to the parent frame).
    pub rotations: Vec<DQuat>,
    /// Local translation of every joint at every frame, in the skeleton's file units.
    pub translations: Vec<DVec3>,
}

/// World-space joint transforms computed by [`Motion::forward_kinematics`].
#[derive(Debug, Clone, PartialEq)]
pub struct WorldPose {
    /// Number of joints per frame.
    pub joints: usize,
    /// World position of every joint at every frame (frame-major), in file units.
    pub positions: Vec<DVec3>,
    /// World rotation of every joint at every frame (frame-major).
    pub rotations: Vec<DQuat>,
}

impl WorldPose {
    /// Number of frames.
    pub fn num_frames(&self) -> usize {
        self.positions.len().checked_div(self.joints).unwrap_or(0)
    }

    /// Position of joint `j` at frame `f`.
    pub fn position(&self, f: usize, j: usize) -> DVec3 {
        self.positions[f * self.joints + j]
    }

    /// All joint positions of frame `f`.
    pub fn frame(&self, f: usize) -> &[DVec3] {
        &self.positions[f * self.joints..(f + 1) * self.joints]
    }
}

impl Motion {
    /// Number of joints.
    pub fn num_joints(&self) -> usize {
        self.skeleton.len()
    }

    /// Number of frames.
    pub fn num_frames(&self) -> usize {
        self.rotations
            .len()
            .checked_div(self.num_joints())
            .unwrap_or(0)
    }

    /// Duration in seconds (frame count over rate).
    pub fn duration(&self) -> f64 {
        self.num_frames() as f64 / self.fps
    }

    /// Local rotation of joint `j` at frame `f`.
    pub fn rotation(&self, f: usize, j: usize) -> DQuat {
        self.rotations[f * self.num_joints() + j]
    }

    /// Local translation of joint `j` at frame `f`.
    pub fn translation(&self, f: usize, j: usize) -> DVec3 {
        self.translations[f * self.num_joints() + j]
    }

    /// World positions and rotations of every joint at every frame.
    pub fn forward_kinematics(&self) -> WorldPose {
        let n = self.num_joints();
        let frames = self.num_frames();
        let mut positions = vec![DVec3::ZERO; frames * n];
        let mut rotations = vec![DQuat::IDENTITY; frames * n];
        let parents: Vec<Option<usize>> = self.skeleton.parents();
        for f in 0..frames {
            let base = f * n;
            for (j, parent) in parents.iter().enumerate() {
                let local_r = self.rotations[base + j];
                let local_t = self.translations[base + j];
                match parent {
                    Some(p) => {
                        let pr = rotations[base + p];
                        positions[base + j] = positions[base + p] + pr * local_t;
                        rotations[base + j] = pr * local_r;
                    }
                    None => {
                        positions[base + j] = local_t;
                        rotations[base + j] = local_r;
                    }
                }
            }
        }
        WorldPose {
            joints: n,
            positions,
            rotations,
        }
    }

    /// Frames `start..end` as a new motion (clamped to the motion's length).
    pub fn slice(&self, start: usize, end: usize) -> Motion {
        let n = self.num_joints();
        let end = end.min(self.num_frames());
        let start = start.min(end);
        Motion {
            skeleton: Arc::clone(&self.skeleton),
            fps: self.fps,
            rotations: self.rotations[start * n..end * n].to_vec(),
            translations: self.translations[start * n..end * n].to_vec(),
        }
    }

    /// How many frames [`Motion::resample`] gives for `frames` frames at `from` fps resampled
    /// to `to` fps (saturating, so an absurd rate gives a huge count, never a wrapped one); for
    /// checking a clip's length before any frame is made.
    pub fn resampled_frames(frames: usize, from: f64, to: f64) -> usize {
        if frames == 0 || !(to.is_finite() && to > 0.0) || (to - from).abs() < 1e-9 {
            return frames;
        }
        let last_time = (frames - 1) as f64 / from;
        // A small epsilon keeps exact multiples (120 -> 30 fps) from losing their last frame.
        ((last_time * to + 1e-9).floor() as usize).saturating_add(1)
    }

    /// For each frame of a motion of `frames` frames at `from` fps resampled to `to` fps: the two
    /// source frames around its time and the weight of the second.
    pub fn resample_points(
        frames: usize,
        from: f64,
        to: f64,
    ) -> impl Iterator<Item = (usize, usize, f64)> {
        let last = frames.saturating_sub(1);
        (0..Motion::resampled_frames(frames, from, to)).map(move |i| {
            let src = i as f64 * from / to;
            let lo = (src.floor() as usize).min(last);
            let hi = (lo + 1).min(last);
            (lo, hi, (src - lo as f64).clamp(0.0, 1.0))
        })
    }

    /// The motion resampled to `fps`: rotations by slerp, translations by linear interpolation,
    /// between the two source frames around each target time. The last target frame is the last one
    /// whose time falls inside the source, so no frame is invented past the end.
    pub fn resample(&self, fps: f64) -> Motion {
        let n = self.num_joints();
        let frames = self.num_frames();
        let valid = fps.is_finite() && fps > 0.0;
        if frames == 0 || !valid || (fps - self.fps).abs() < 1e-9 {
            return Motion {
                fps: if valid { fps } else { self.fps },
                ..self.clone()
            };
        }
        let out_frames = Motion::resampled_frames(frames, self.fps, fps);
        // The length is checked by callers before resampling; the capacity is only a hint, and
        // capped so that a wrong rate can never reserve more than the source holds many times.
        let hint = out_frames.min(frames.saturating_mul(16)).saturating_mul(n);
        let mut rotations = Vec::with_capacity(hint);
        let mut translations = Vec::with_capacity(hint);
        for (lo, hi, t) in Motion::resample_points(frames, self.fps, fps) {
            for j in 0..n {
                let (a, b) = (self.rotations[lo * n + j], self.rotations[hi * n + j]);
                let (ta, tb) = (self.translations[lo * n + j], self.translations[hi * n + j]);
                if t < 1e-12 {
                    rotations.push(a);
                    translations.push(ta);
                } else {
                    rotations.push(a.slerp(b, t));
                    translations.push(ta.lerp(tb, t));
                }
            }
        }
        Motion {
            skeleton: Arc::clone(&self.skeleton),
            fps,
            rotations,
            translations,
        }
    }
}
