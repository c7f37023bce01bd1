//! The report's gallery: one stick-figure filmstrip per motion type, drawn from the shards by
//! `dataset::preview`, so a reader sees what each type's clips look like.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{ClipRow, FigureProblem, ReportError};
use motionforge_format::dataset::{self, preview};

/// Poses per filmstrip.
const STRIP_FRAMES: usize = 6;
/// Pixels of one pose.
const SIZE: u32 = 200;

fn gallery_err(problem: impl Into<FigureProblem>) -> ReportError {
    ReportError::Figure {
        figure: "gallery".into(),
        problem: Box::new(problem.into()),
    }
}

/// Writes `gallery/<type>.png` for every motion type of `rows` (its representative: the first
/// original, real clip of that type by clip id) and returns the files and the Markdown section
/// for `report.md` (empty when no clip has a motion type).
pub(crate) fn write_gallery(
    dataset: &Path,
    rows: &[ClipRow],
    out_dir: &Path,
) -> Result<(Vec<PathBuf>, String), ReportError> {
    let mut chosen: BTreeMap<&str, &str> = BTreeMap::new();
    for row in rows
        .iter()
        .filter(|r| !r.mirrored && r.source_kind != "synthetic")
    {
        if let Some(t) = row.motion_type.as_deref() {
            let slot = chosen.entry(t).or_insert(row.clip_id.as_str());
            if row.clip_id.as_str() < *slot {
                *slot = row.clip_id.as_str();
            }
        }
    }
    if chosen.is_empty() {
        return Ok((Vec::new(), String::new()));
    }
    let clips = dataset::list_clips(dataset).map_err(gallery_err)?;
    let skeletons = dataset::read_skeletons(dataset).map_err(gallery_err)?;
    let dir = out_dir.join("gallery");
    std::fs::create_dir_all(&dir).map_err(|source| ReportError::Io {
        path: dir.clone(),
        source,
    })?;
    let options = preview::PreviewOptions {
        size: SIZE,
        strip_frames: STRIP_FRAMES,
        animate: false,
        ..preview::PreviewOptions::default()
    };
    let mut files = Vec::new();
    let mut md = String::from(
        "\n## Gallery\n\nOne clip per motion type (the first original by clip id), six poses \
         evenly spaced over the clip, drawn from the shards in its canonical frame by a fixed \
         camera in front of the character. Left arm blue, left leg teal, right arm red, right \
         leg orange; the cross is the pelvis goal (`motionforge preview` draws any clip).\n",
    );
    for (motion_type, clip_id) in chosen {
        let frames = dataset::read_clip_in(dataset, &clips, clip_id).map_err(gallery_err)?;
        let skeleton = skeletons.get(&frames.info.skeleton).ok_or_else(|| {
            gallery_err(FigureProblem::NoSkeleton {
                skeleton: frames.info.skeleton.clone(),
                clip_id: clip_id.to_string(),
            })
        })?;
        let panel = preview::Panel {
            frames: &frames,
            skeleton,
        };
        let drawn = preview::render(&[panel], &options).map_err(gallery_err)?;
        let name = format!("{}.png", preview::file_stem(&motion_type.replace(' ', "-")));
        let path = dir.join(&name);
        motionforge_core::base::write_atomic(&path, &drawn.png().map_err(gallery_err)?)?;
        md.push_str(&format!(
            "\n### {}\n\n![{} filmstrip](gallery/{name})\n\n`{}`: {}\n",
            super::tables::markdown_escape(motion_type),
            super::tables::markdown_escape(motion_type),
            clip_id,
            super::tables::markdown_escape(&frames.info.text)
        ));
        files.push(path);
    }
    Ok((files, md))
}
