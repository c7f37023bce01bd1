//! Motion core: skeletons, BVH, forward kinematics, resampling, profiles and mirroring.
//!
//! Knows nothing of files on disk, stages or LLMs.

pub mod bvh;
pub mod ik;
pub mod mirror;
#[allow(clippy::module_inception)]
mod motion;
pub mod npy;
pub mod profile;
pub mod skeleton;

pub use bvh::{
    Bvh, BvhError, BvhErrorKind, BvhWriteError, read_bvh, write_bvh, write_bvh_with_reference,
};
pub use mirror::{MirrorPlan, OffsetPolicy, calibrate, mean_rotation};
pub use motion::{Motion, WorldPose};
pub use profile::{BodyPart, BoundProfiles, Profile, ProfileSpec, Reflection, Role, SignedAxis};
pub use skeleton::{Channel, Joint, Skeleton, SkeletonPool};
pub mod canonical;
pub mod compose;
