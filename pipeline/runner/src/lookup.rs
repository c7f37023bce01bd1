//! Clips as a build would write them, frames included, read without writing a dataset:
//! `export-bvh` from a config and `bench --write-frames` take them this way.

use super::steps::run_stages;
use super::{BuildError, BuildOptions};
use crate::config::Config;
use motionforge_core::motion::Profile;
use motionforge_sources::clip::LoadedClip;

/// Every clip a build would write (synthetic pairs included), from cached stage outputs where
/// they are fresh; nothing is written except cache entries. `export-bvh` reads clips this way.
pub fn collect_clips(
    config: &Config,
    options: &BuildOptions,
) -> Result<Vec<LoadedClip>, BuildError> {
    let staged = run_stages(config, options)?;
    let motions = staged.shared.motions();
    let gathered = &staged.gathered;
    gathered
        .clips
        .iter()
        .map(|c| motions.load(c, &gathered.index))
        .collect()
}

/// A clip with its frames and its profile bound to its skeleton.
pub type ProfiledClip = (LoadedClip, Profile);

/// The clip `clip_id` as a build would write it, frames included (see [`collect_clips`]), with
/// its profile bound to its skeleton (what the write stage turns its frames into rows with), and
/// the ids of every clip (to suggest one when `clip_id` is not there). Only that clip's frames
/// are read.
pub fn find_clip(
    config: &Config,
    options: &BuildOptions,
    clip_id: &str,
) -> Result<(Option<ProfiledClip>, Vec<String>), BuildError> {
    let staged = run_stages(config, options)?;
    let motions = staged.shared.motions();
    let gathered = &staged.gathered;
    let found = match gathered.clips.iter().find(|c| c.clip_id == clip_id) {
        None => None,
        Some(c) => {
            let spec = staged
                .shared
                .specs
                .iter()
                .find(|s| s.name == c.profile)
                .ok_or_else(|| BuildError::ClipProfile {
                    clip: clip_id.to_string(),
                    profile: c.profile.clone(),
                })?;
            let profile = staged.shared.bound.bind(spec, &c.skeleton).map_err(|e| {
                BuildError::ClipProfileFit {
                    clip: clip_id.to_string(),
                    profile: c.profile.clone(),
                    error: Box::new(e),
                }
            })?;
            Some((motions.load(c, &gathered.index)?, profile))
        }
    };
    let ids = gathered.clips.iter().map(|c| c.clip_id.clone()).collect();
    Ok((found, ids))
}

/// A clip's motion as the dataset stores it: its row's f32 rotations and positions
/// (`io::parquet::dataset_motion`) read back on its own skeleton as `export-bvh <dataset>` reads
/// them from the shards (`dataset::skeletons::motion_from_rows`), so a clip exported from the
/// config and from the shards is the same file.
pub fn stored_motion(clip: &LoadedClip, profile: &Profile) -> motionforge_core::motion::Motion {
    let stored = motionforge_format::io::parquet::dataset_motion(&clip.motion, profile);
    motionforge_format::dataset::skeletons::motion_from_rows(
        (*clip.motion.skeleton).clone(),
        profile.to_dataset_axes().inverse(),
        profile.unit_scale,
        clip.motion.fps,
        &stored.positions,
        &stored.rotations,
    )
}
