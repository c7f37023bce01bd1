//! The core of motionforge: base types and motion maths, with no files of a build, no stages and no
//! configuration.
//!
//! * [`base`]: fingerprints, atomic writes, rejects and drops, the dataset layout, locks.
//! * [`motion`]: [`motion::Skeleton`] and [`motion::Motion`] (local rotations and translations per
//!   frame), the BVH reader and writer, joint-position arrays, profiles, forward and inverse
//!   kinematics, mirroring and composition by body part.
//! * [`humanml3d`]: HumanML3D's 263-number representation and its inverse.
//! * [`features`] and [`quality`]: per-clip derived features and plausibility metrics.
//! * [`progress`]: the progress events stages report.
//!
//! # A clip's way through this crate
//!
//! Step 1 of a clip's way from capture to row (`docs/architecture.md`): the capture's bytes become a
//! [`motion::Skeleton`] and a [`motion::Motion`] here ([`motion::read_bvh`], or [`motion::npy`] and
//! inverse kinematics for joint arrays), and the clip's frames come back here at the end, when its
//! row is made: forward kinematics, [`features`] and [`quality`] measure them.

pub mod base;
pub mod features;
pub mod humanml3d;
pub mod motion;
pub mod progress;
pub mod quality;
