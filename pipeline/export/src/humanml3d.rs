//! `motionforge export humanml3d`: a built dataset as a HumanML3D folder, the layout that
//! text-to-motion, T2M-GPT, MoMask, MDM and their evaluators read:
//!
//! ```text
//! new_joint_vecs/<name>.npy   (T-1, 263) float32: humanml3d::vectors
//! new_joints/<name>.npy       (T-1, 22, 3) float32: positions recovered from the vectors
//! joints/<name>.npy           (T, 22, 3) float32: the 20 fps, y-up positions the vectors came from
//! texts/<name>.txt            caption#word/POS ...#start#end, one line per caption
//! Mean.npy, Std.npy           (263,) float32, HumanML3D's per-group averaged std
//! train.txt val.txt test.txt all.txt   names per split (mirrored clips `M<name>`)
//! names.csv                   name, clip_id, split, source_kind, mirrored
//! export.json                 what was exported, skipped and why, and what the loaders filter
//! ```
//!
//! Each clip's skeleton is mapped to SMPL's 22 body joints by its profile's `[smpl22]` table,
//! turned to HumanML3D's axes (y up), resampled to 20 fps and converted as HumanML3D does.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;

use motionforge_core::base::guard::{Kept, check_replaceable, is_plain_name};
use motionforge_core::humanml3d::{self as hml3d, DIM, NUM_JOINTS};
use motionforge_core::motion::profile::SmplPlacement;
use motionforge_core::motion::{Motion, ProfileSpec};
use motionforge_format::dataset::{self, DatasetError, OpenShard, ShardBatch};
use motionforge_format::io::schema::Column;
use motionforge_format::io::skeletons::{SkeletonsError, read_skeletons};
use motionforge_sources::clip::Split;

/// Rows the HumanML3D loaders keep: `Text2MotionDatasetV2` drops motions shorter than 40 rows or
/// 200 rows and longer.
pub const LOADER_ROWS: std::ops::Range<usize> = 40..200;

/// Rows decoded at once: the frames of this many clips are held while they are converted.
const BATCH_ROWS: usize = 64;

/// How to export.
#[derive(Debug, Clone, Default)]
pub struct ExportOptions {
    /// Replace an existing output folder.
    pub force: bool,
    /// Profiles of skeletons that are not bundled (a dataset built with a profile file).
    pub profiles: Vec<ProfileSpec>,
}

/// A clip that was not exported, and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Skipped {
    /// The clip.
    pub clip_id: String,
    /// Why.
    pub reason: String,
}

/// What an export wrote.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct ExportSummary {
    /// Rows of the dataset.
    pub clips: usize,
    /// Clips written.
    pub exported: usize,
    /// Rows of 263 numbers written over all clips.
    pub rows: usize,
    /// Exported clips per split.
    pub splits: BTreeMap<String, usize>,
    /// Clips not exported, with the reason.
    pub skipped: Vec<Skipped>,
    /// Captions not written (a malformed line makes the loaders drop the whole clip), by clip.
    pub captions_refused: Vec<Skipped>,
    /// Exported clips the HumanML3D loaders will drop for their length (outside 40 to 199 rows):
    /// names.
    pub filtered_by_loaders: Vec<String>,
}

/// Why an export stopped.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// A file cannot be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A shard's frames column cannot be decoded.
    #[error("{}: {problem}", path.display())]
    Frames {
        /// The shard.
        path: PathBuf,
        /// What the column holds instead (in the message, not a cause: the message is whole).
        problem: motionforge_format::io::parquet::FrameColumnError,
    },
    /// A shard holds more rows on the second read (its frames) than on the first (its entries):
    /// it changed during the export.
    #[error("{}: more rows on the second read than on the first", path.display())]
    ShardChanged {
        /// The shard.
        path: PathBuf,
    },
    /// The folder is not a built dataset.
    #[error("{}: no clip table (data/*.parquet); build the dataset first", path.display())]
    NotADataset {
        /// The folder.
        path: PathBuf,
    },
    /// The output folder exists.
    #[error("{} exists; pass --force to replace it", path.display())]
    Exists {
        /// The folder.
        path: PathBuf,
    },
    /// The output folder exists and is not an export, so `--force` will not remove it.
    #[error(
        "{} exists and is not a finished HumanML3D export (no {EXPORT_MARKER}); it is not replaced, even with --force: remove it yourself or choose another --out",
        path.display()
    )]
    NotAnExport {
        /// The folder.
        path: PathBuf,
    },
    /// `skeletons.json` cannot be read.
    #[error(transparent)]
    Skeletons(#[from] SkeletonsError),
    /// A shard cannot be read.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The output folder is, holds or lies inside a folder the export must keep.
    #[error(transparent)]
    Refused(#[from] motionforge_core::base::guard::Refused),
}

/// The export's folder inside the dataset when no `--out` is given: the one place inside the
/// dataset folder it writes.
pub const DEFAULT_DIR: &str = "humanml3d";

/// Written last into an export: a folder without it is not a finished export (an interrupted run
/// never leaves one, and `--force` replaces only folders that have it).
pub const EXPORT_MARKER: &str = "export.json";

/// Split lists HumanML3D's loaders open (T2M-GPT's evaluation fails on a missing `val.txt`).
const STANDARD_LISTS: [&str; 3] = ["train", "val", "test"];

/// Split names the export cannot use as list files: `all.txt` is its own list.
const RESERVED_LISTS: [&str; 1] = ["all"];

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> ExportError + '_ {
    move |source| ExportError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// One row of the table, without its frames.
#[derive(Debug, Clone)]
struct Entry {
    clip_id: String,
    split: Split,
    mirrored: bool,
    source_kind: String,
    /// Caption, every text and the paraphrases, each once, in that order.
    captions: Vec<String>,
    /// The shard it is in.
    shard: usize,
}

/// Tags every distinct caption before the clips are written, a batch of them at a time on all
/// cores: the tagger is about twice as cheap on many captions at once
/// (`caption::remember_all`), and the clips then find their captions' tags remembered.
fn tag_captions(entries: &[Entry]) {
    const CAPTIONS_PER_BATCH: usize = 256;
    let distinct: std::collections::BTreeSet<&str> = entries
        .iter()
        .flat_map(|e| e.captions.iter().map(String::as_str))
        .collect();
    let distinct: Vec<&str> = distinct.into_iter().collect();
    distinct.par_chunks(CAPTIONS_PER_BATCH).for_each(|batch| {
        // Unreadable tagger data is refused, with its error, when the first clip is written.
        let _ = motionforge_language::caption::remember_all(batch);
    });
}

/// Exports the dataset in `dataset` (a build's `<output>/<name>` folder) into `out`.
pub fn export_humanml3d(
    dataset: &Path,
    out: &Path,
    options: &ExportOptions,
) -> Result<ExportSummary, ExportError> {
    check_out(dataset, out, options)?;
    let shards = clip_tables(dataset)?;
    let placements = placements(dataset, options)?;
    let mut entries = Vec::new();
    for (i, shard) in shards.iter().enumerate() {
        read_entries(shard, i, &mut entries)?;
    }
    let names = assign_names(&entries);
    tag_captions(&entries);

    // Everything goes to a staging folder beside `out`, renamed into place at the end: an
    // interrupted export leaves no folder that looks complete.
    let staging = staging_path(out);
    if staging.exists() {
        fs::remove_dir_all(&staging).map_err(io_err(&staging))?;
    }
    for dir in ["new_joint_vecs", "new_joints", "joints", "texts"] {
        let path = staging.join(dir);
        fs::create_dir_all(&path).map_err(io_err(&path))?;
    }
    let export = ClipExport {
        staging: &staging,
        placements: &placements,
        names: &names,
    };
    let mut tally = Tally {
        summary: ExportSummary {
            clips: entries.len(),
            ..ExportSummary::default()
        },
        moments: Moments::default(),
        exported: Vec::new(),
    };
    for (i, shard) in shards.iter().enumerate() {
        let rows: Vec<&Entry> = entries.iter().filter(|e| e.shard == i).collect();
        export.shard(shard, &rows, &mut tally)?;
    }
    tally.finish(&staging, out)
}

/// `out` may be written: not the dataset or the working folder, and either absent or (with
/// `--force`) an earlier export. An interrupted replacement is restored first.
fn check_out(dataset: &Path, out: &Path, options: &ExportOptions) -> Result<(), ExportError> {
    let kept = Kept::working_folder().and(dataset, "the dataset folder it exports", &[DEFAULT_DIR]);
    check_replaceable(out, &kept, "pass another --out")?;
    motionforge_core::base::restore_replaced(out).map_err(|e| ExportError::Io {
        path: out.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    })?;
    if out.exists() {
        if !options.force {
            return Err(ExportError::Exists {
                path: out.to_path_buf(),
            });
        }
        if !is_export(out) {
            return Err(ExportError::NotAnExport {
                path: out.to_path_buf(),
            });
        }
    }
    Ok(())
}

/// The dataset's shards, opened; at least one.
fn clip_tables(dataset: &Path) -> Result<Vec<OpenShard>, ExportError> {
    dataset::open_shards(dataset).map_err(|e| match e {
        DatasetError::NotADataset { .. } => ExportError::NotADataset {
            path: dataset.to_path_buf(),
        },
        e => ExportError::Dataset(e),
    })
}

/// What every clip's export reads: where it writes, the skeletons' SMPL placements and the
/// clips' HumanML3D names.
struct ClipExport<'a> {
    staging: &'a Path,
    placements: &'a BTreeMap<String, Result<SmplPlacement, String>>,
    names: &'a BTreeMap<String, String>,
}

impl ClipExport<'_> {
    /// Exports the clips of one shard (`rows`, its entries in row order). A row group at a
    /// time: converted and written on all cores, then counted in row order (so Mean and Std do
    /// not depend on scheduling). While a group is converted, the next one is read and decoded
    /// beside it, so the shard's reading does not leave the cores waiting.
    fn shard<'e>(
        &self,
        shard: &OpenShard,
        rows: &[&'e Entry],
        tally: &mut Tally<'e>,
    ) -> Result<(), ExportError> {
        let mut groups = read_frames(shard)?;
        let mut next = 0;
        let mut ready = groups.next();
        while let Some(frames) = ready.take() {
            let frames = frames?;
            let group =
                rows.get(next..next + frames.len())
                    .ok_or_else(|| ExportError::ShardChanged {
                        path: shard.path().to_path_buf(),
                    })?;
            next += frames.len();
            let (done, following) = rayon::join(
                || {
                    group
                        .par_iter()
                        .zip(&frames)
                        .map(|(entry, frames)| self.clip(entry, frames))
                        .collect::<Vec<Result<Result<Done, Skipped>, ExportError>>>()
                },
                || groups.next(),
            );
            for (entry, done) in group.iter().zip(done) {
                match done? {
                    Ok(done) => tally.add(entry, done),
                    Err(skipped) => tally.summary.skipped.push(skipped),
                }
            }
            ready = following;
        }
        Ok(())
    }

    /// Converts and writes one clip, or says why it is skipped.
    fn clip(&self, entry: &Entry, frames: &Frames) -> Result<Result<Done, Skipped>, ExportError> {
        if let Err(why) = usable_split(&entry.split) {
            return Ok(Err(Skipped {
                clip_id: entry.clip_id.clone(),
                reason: why,
            }));
        }
        let converted = match convert(entry, frames, self.placements) {
            Ok(c) => c,
            Err(skipped) => return Ok(Err(skipped)),
        };
        let (text, refused) = caption_lines(entry);
        if text.is_empty() {
            // An empty texts file makes every loader drop the clip without a word.
            let why: Vec<String> = refused.into_iter().map(|r| r.reason).collect();
            return Ok(Err(Skipped {
                clip_id: entry.clip_id.clone(),
                reason: format!("no caption could be written: {}", why.join("; ")),
            }));
        }
        let name = self.names.get(&entry.clip_id).cloned().unwrap_or_default();
        write_clip(self.staging, &name, &converted)?;
        let path = self.staging.join("texts").join(format!("{name}.txt"));
        fs::write(&path, text).map_err(io_err(&path))?;
        Ok(Ok(Done {
            refused,
            name,
            moments: Moments::of(&converted.vectors),
        }))
    }
}

/// What the export has written so far: the summary, the vectors' moments and the exported
/// clips by name.
struct Tally<'e> {
    summary: ExportSummary,
    moments: Moments,
    exported: Vec<(String, &'e Entry)>,
}

impl<'e> Tally<'e> {
    fn add(&mut self, entry: &'e Entry, done: Done) {
        self.summary.rows += done.moments.rows;
        self.summary.captions_refused.extend(done.refused);
        if !LOADER_ROWS.contains(&done.moments.rows) {
            self.summary.filtered_by_loaders.push(done.name.clone());
        }
        self.moments.merge(&done.moments);
        self.exported.push((done.name, entry));
    }

    /// Writes the split lists, Mean and Std and the marker into `staging`, then swaps it in as
    /// `out`.
    fn finish(self, staging: &Path, out: &Path) -> Result<ExportSummary, ExportError> {
        let Tally {
            mut summary,
            moments,
            mut exported,
        } = self;
        exported.sort_by(|a, b| name_order(&a.0).cmp(&name_order(&b.0)));
        summary.exported = exported.len();
        summary
            .filtered_by_loaders
            .sort_by(|a, b| name_order(a).cmp(&name_order(b)));
        write_lists(staging, &exported, &mut summary)?;
        if let Some((mean, std)) = moments.mean_std() {
            write_npy(&staging.join("Mean.npy"), &[DIM], &mean)?;
            write_npy(&staging.join("Std.npy"), &[DIM], &std)?;
        }
        let json = serde_json::to_vec_pretty(&summary).unwrap_or_default();
        // The marker last, then one swap: `out` is always the old export or the new one.
        let path = staging.join(EXPORT_MARKER);
        fs::write(&path, json).map_err(io_err(&path))?;
        motionforge_core::base::replace_dir(staging, out).map_err(|e| ExportError::Io {
            path: out.to_path_buf(),
            source: std::io::Error::other(e.to_string()),
        })?;
        Ok(summary)
    }
}

/// True when `dir` is a finished export (it has the marker) or an empty folder.
pub fn is_export(dir: &Path) -> bool {
    dir.join(EXPORT_MARKER).is_file()
        || fs::read_dir(dir).is_ok_and(|mut entries| entries.next().is_none())
}

fn staging_path(out: &Path) -> PathBuf {
    motionforge_core::base::sibling(out, "partial")
}

/// HumanML3D's order of names: originals by number, then mirrors by number.
fn name_order(name: &str) -> (bool, &str) {
    (name.starts_with('M'), name)
}

/// Six-digit names: originals (and synthetic pairs) by clip id, each mirror `M` + its
/// original's name (a mirror whose original is not in the table gets a number of its own).
fn assign_names(entries: &[Entry]) -> BTreeMap<String, String> {
    let mut originals: Vec<&str> = entries
        .iter()
        .filter(|e| !e.mirrored)
        .map(|e| e.clip_id.as_str())
        .collect();
    originals.sort_unstable();
    let width = 6.max(originals.len().to_string().len());
    let mut names: BTreeMap<String, String> = originals
        .iter()
        .enumerate()
        .map(|(i, id)| (id.to_string(), format!("{i:0width$}")))
        .collect();
    let mut next = originals.len();
    let mut mirrors: Vec<&str> = entries
        .iter()
        .filter(|e| e.mirrored)
        .map(|e| e.clip_id.as_str())
        .collect();
    mirrors.sort_unstable();
    for id in mirrors {
        let of = id.strip_suffix(":m").and_then(|o| names.get(o)).cloned();
        let name = match of {
            Some(n) => format!("M{n}"),
            None => {
                next += 1;
                format!("M{:0width$}", next - 1)
            }
        };
        names.insert(id.to_string(), name);
    }
    names
}

/// Every skeleton id of `skeletons.json` with where SMPL's joints are on it, or why not.
fn placements(
    dataset: &Path,
    options: &ExportOptions,
) -> Result<BTreeMap<String, Result<SmplPlacement, String>>, ExportError> {
    let skeletons = read_skeletons(dataset)?;
    let mut out = BTreeMap::new();
    for (id, skeleton) in skeletons {
        let names: Vec<&str> = skeleton.joints.iter().map(|j| j.name.as_str()).collect();
        let spec = options
            .profiles
            .iter()
            .find(|p| p.name == skeleton.profile)
            .cloned()
            .map(Ok)
            .unwrap_or_else(|| ProfileSpec::bundled(&skeleton.profile));
        let placement = spec
            .and_then(|spec| spec.smpl_placement(&hml3d::JOINTS, &names))
            .map_err(|e| e.to_string());
        out.insert(id, placement);
    }
    Ok(out)
}

/// The shard's rows with only `columns` (each required) decoded, [`BATCH_ROWS`] at a time.
fn batches(
    shard: &OpenShard,
    columns: &[Column],
) -> Result<impl Iterator<Item = Result<ShardBatch, ExportError>> + use<>, ExportError> {
    let batches = shard
        .read(columns)
        .require(columns)
        .batch_rows(BATCH_ROWS)
        .batches()?;
    Ok(batches.map(|b| b.map_err(ExportError::from)))
}

fn read_entries(shard: &OpenShard, index: usize, out: &mut Vec<Entry>) -> Result<(), ExportError> {
    let columns = [
        Column::ClipId,
        Column::Split,
        Column::Mirrored,
        Column::SourceKind,
        Column::Text,
        Column::Texts,
        Column::Paraphrases,
    ];
    for batch in batches(shard, &columns)? {
        let batch = batch?;
        let (texts, paraphrases) = (
            batch.string_lists(Column::Texts)?,
            batch.string_lists(Column::Paraphrases)?,
        );
        let (ids, splits, kinds) = (
            batch.strings(Column::ClipId)?,
            batch.strings(Column::Split)?,
            batch.strings(Column::SourceKind)?,
        );
        let text = batch.strings(Column::Text)?;
        let mirrored = batch.bools(Column::Mirrored)?;
        for i in 0..batch.num_rows() {
            let mut captions = vec![text[i].clone().unwrap_or_default()];
            for v in texts[i].iter().chain(&paraphrases[i]) {
                if !captions.iter().any(|c| c == v) {
                    captions.push(v.clone());
                }
            }
            out.push(Entry {
                captions,
                clip_id: ids[i].clone().unwrap_or_default(),
                split: Split::new(splits[i].as_deref().unwrap_or_default()),
                mirrored: mirrored[i].unwrap_or(false),
                source_kind: kinds[i].clone().unwrap_or_default(),
                shard: index,
            });
        }
    }
    Ok(())
}

/// A clip written: its name, its column sums and the captions that could not be written.
struct Done {
    refused: Vec<Skipped>,
    name: String,
    moments: Moments,
}

/// One row's frames as the shard holds them.
struct Frames {
    skeleton: String,
    fps: f64,
    frames: usize,
    joints: usize,
    /// The positions, or why the row's column could not be read.
    positions: Result<Vec<f32>, String>,
}

/// The frames of every row of a shard, a batch of rows at a time.
fn read_frames(
    shard: &OpenShard,
) -> Result<impl Iterator<Item = Result<Vec<Frames>, ExportError>> + use<>, ExportError> {
    let columns = [
        Column::Skeleton,
        Column::Fps,
        Column::NumFrames,
        Column::NumJoints,
        Column::JointPositions,
    ];
    Ok(batches(shard, &columns)?.map(|batch| frames_of(&batch?)))
}

fn frames_of(batch: &ShardBatch) -> Result<Vec<Frames>, ExportError> {
    let skeleton = batch.strings(Column::Skeleton)?;
    let fps = batch.floats(Column::Fps)?;
    let count = |column: Column| -> Result<Vec<usize>, ExportError> {
        Ok(batch
            .ints(column)?
            .into_iter()
            .map(|v| v.and_then(|v| usize::try_from(v).ok()).unwrap_or(0))
            .collect())
    };
    let (frames, joints) = (count(Column::NumFrames)?, count(Column::NumJoints)?);
    let positions = batch.column(Column::JointPositions)?;
    let mut out = Vec::with_capacity(batch.num_rows());
    for i in 0..batch.num_rows() {
        let (n, j) = (frames[i], joints[i]);
        // A row whose frames do not match its counts is skipped with the reason (the export goes
        // on); a column of another layout fails the shard.
        let values = match motionforge_format::io::parquet::frame_values(
            positions,
            Column::JointPositions,
            i,
            n,
            j,
        ) {
            Ok(Some(v)) => Ok(v),
            Ok(None) => Err("joint_positions is null".to_string()),
            Err(e @ motionforge_format::io::parquet::FrameColumnError::Shape { .. }) => {
                Err(e.to_string())
            }
            Err(problem) => {
                return Err(ExportError::Frames {
                    path: batch.path().to_path_buf(),
                    problem,
                });
            }
        };
        out.push(Frames {
            skeleton: skeleton[i].clone().unwrap_or_default(),
            fps: fps[i].unwrap_or(f64::NAN),
            frames: n,
            joints: j,
            positions: values,
        });
    }
    Ok(out)
}

/// One clip in HumanML3D's form.
struct Converted {
    /// `T × 22` positions: 20 fps, y up, metres, SMPL order.
    joints: Vec<DVec3>,
    /// `(T - 1) × 263`.
    vectors: Vec<f32>,
}

fn convert(
    entry: &Entry,
    frames: &Frames,
    placements: &BTreeMap<String, Result<SmplPlacement, String>>,
) -> Result<Converted, Skipped> {
    let skip = |reason: String| Skipped {
        clip_id: entry.clip_id.clone(),
        reason,
    };
    let placement = match placements.get(&frames.skeleton) {
        Some(Ok(p)) => p,
        Some(Err(why)) => return Err(skip(why.clone())),
        None => {
            return Err(skip(format!(
                "skeleton `{}` is not in skeletons.json",
                frames.skeleton
            )));
        }
    };
    let positions = frames.positions.as_ref().map_err(|why| skip(why.clone()))?;
    if frames.joints == 0 || frames.frames.checked_mul(frames.joints * 3) != Some(positions.len()) {
        return Err(skip(format!(
            "joint_positions holds {} values, not num_frames × num_joints × 3 = {} × {} × 3",
            positions.len(),
            frames.frames,
            frames.joints
        )));
    }
    // Dataset frame (x right, y forward, z up) to HumanML3D's (y up; x = -right, z = forward):
    // a rotation, so left stays left.
    let smpl: Vec<DVec3> = positions
        .chunks_exact(frames.joints * 3)
        .flat_map(|frame| {
            let frame: Vec<DVec3> = frame
                .chunks_exact(3)
                .map(|p| DVec3::new(-f64::from(p[0]), f64::from(p[2]), f64::from(p[1])))
                .collect();
            placement.place(&frame)
        })
        .collect();
    let joints = resample(&smpl, frames.fps);
    let vectors = hml3d::vectors(&joints).map_err(|e| skip(e.to_string()))?;
    Ok(Converted { joints, vectors })
}

/// Positions at 20 fps by linear interpolation between the frames around each time (the frame
/// count as `Motion::resample` gives it). Bones are set to the reference lengths afterwards, so
/// interpolating positions loses nothing the representation keeps.
fn resample(positions: &[DVec3], fps: f64) -> Vec<DVec3> {
    let frames = positions.len() / NUM_JOINTS;
    if frames == 0 || !(fps.is_finite() && fps > 0.0) || (fps - hml3d::FPS).abs() < 1e-9 {
        return positions.to_vec();
    }
    let out = Motion::resampled_frames(frames, fps, hml3d::FPS);
    let mut v = Vec::with_capacity(out.min(frames.saturating_mul(4)) * NUM_JOINTS);
    for (lo, hi, t) in Motion::resample_points(frames, fps, hml3d::FPS) {
        for j in 0..NUM_JOINTS {
            v.push(positions[lo * NUM_JOINTS + j].lerp(positions[hi * NUM_JOINTS + j], t));
        }
    }
    v
}

fn write_npy(path: &Path, shape: &[usize], values: &[f32]) -> Result<(), ExportError> {
    // The bytes npyz writes, made in one pass (npyz writes a value at a time).
    let bytes = motionforge_format::io::normalization::npy_f32(values, shape);
    fs::write(path, bytes).map_err(io_err(path))
}

fn flat(positions: &[DVec3]) -> Vec<f32> {
    positions
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect()
}

fn write_clip(dir: &Path, name: &str, clip: &Converted) -> Result<(), ExportError> {
    let rows = clip.vectors.len() / DIM;
    let file = format!("{name}.npy");
    write_npy(
        &dir.join("new_joint_vecs").join(&file),
        &[rows, DIM],
        &clip.vectors,
    )?;
    let recovered = hml3d::recover_from_ric(&clip.vectors);
    write_npy(
        &dir.join("new_joints").join(&file),
        &[rows, NUM_JOINTS, 3],
        &flat(&recovered),
    )?;
    write_npy(
        &dir.join("joints").join(&file),
        &[clip.joints.len() / NUM_JOINTS, NUM_JOINTS, 3],
        &flat(&clip.joints),
    )
}

/// The lines of `texts/<name>.txt`: one HumanML3D caption line per caption of the clip (the
/// whole clip: `0.0#0.0`); the captions that cannot be tagged, with why.
fn caption_lines(entry: &Entry) -> (String, Vec<Skipped>) {
    let mut text = String::new();
    let mut refused = Vec::new();
    for caption in &entry.captions {
        match motionforge_language::caption::caption_line(caption, 0.0, 0.0) {
            Ok(line) => {
                text.push_str(&line);
                text.push('\n');
            }
            Err(e) => refused.push(Skipped {
                clip_id: entry.clip_id.clone(),
                reason: e.to_string(),
            }),
        }
    }
    (text, refused)
}

/// Whether a split's list file can be written: its name becomes `<out>/<split>.txt`, so a name
/// from a shard (someone else's dataset, a shard written by hand) must stay a plain file name.
fn usable_split(split: &Split) -> Result<(), String> {
    let name = list_name(split);
    if !is_plain_name(name) || name.starts_with('.') {
        return Err(format!(
            "split {name:?} is not a plain file name, so it cannot name a list file"
        ));
    }
    if RESERVED_LISTS.contains(&name) {
        return Err(format!(
            "split {name:?} would overwrite the export's own {name}.txt"
        ));
    }
    Ok(())
}

/// Split lists, `all.txt` and `names.csv`.
/// A split's name in HumanML3D's folder: its loaders open `val.txt`, where the dataset says
/// `validation` (Hugging Face's name).
fn list_name(split: &Split) -> &str {
    match split.as_str() {
        "validation" => "val",
        name => name,
    }
}

fn write_lists(
    dir: &Path,
    exported: &[(String, &Entry)],
    summary: &mut ExportSummary,
) -> Result<(), ExportError> {
    let mut by_split: BTreeMap<&Split, String> = BTreeMap::new();
    let mut all = String::new();
    let mut csv = String::from("name,clip_id,split,source_kind,mirrored\n");
    for (name, entry) in exported {
        let list = by_split.entry(&entry.split).or_default();
        list.push_str(name);
        list.push('\n');
        all.push_str(name);
        all.push('\n');
        csv.push_str(&format!(
            "{name},{},{},{},{}\n",
            csv_field(&entry.clip_id),
            csv_field(list_name(&entry.split)),
            entry.source_kind,
            entry.mirrored
        ));
        *summary
            .splits
            .entry(list_name(&entry.split).to_string())
            .or_insert(0) += 1;
    }
    // Every loader opens train, val and test: an empty split still gets its (empty) list.
    let mut lists: BTreeMap<&str, String> = STANDARD_LISTS
        .iter()
        .map(|&name| (name, String::new()))
        .collect();
    for (split, names) in by_split {
        lists.insert(list_name(split), names);
    }
    for (name, names) in lists {
        let path = dir.join(format!("{name}.txt"));
        fs::write(&path, names).map_err(io_err(&path))?;
    }
    for (file, text) in [("all.txt", all), ("names.csv", csv)] {
        let path = dir.join(file);
        fs::write(&path, text).map_err(io_err(&path))?;
    }
    Ok(())
}

fn csv_field(value: &str) -> String {
    if value.contains([',', '"', '\n']) {
        format!("\"{}\"", value.replace('"', "\"\""))
    } else {
        value.to_string()
    }
}

/// Column sums for `Mean.npy` and `Std.npy`, over every exported row as HumanML3D does.
#[derive(Default)]
struct Moments {
    rows: usize,
    sum: Vec<f64>,
    squares: Vec<f64>,
}

impl Moments {
    /// The sums of one clip's rows.
    fn of(vectors: &[f32]) -> Moments {
        let mut m = Moments {
            rows: 0,
            sum: vec![0.0; DIM],
            squares: vec![0.0; DIM],
        };
        for row in vectors.chunks_exact(DIM) {
            for (k, v) in row.iter().enumerate() {
                let v = f64::from(*v);
                m.sum[k] += v;
                m.squares[k] += v * v;
            }
            m.rows += 1;
        }
        m
    }

    fn merge(&mut self, other: &Moments) {
        if self.sum.is_empty() {
            self.sum = vec![0.0; DIM];
            self.squares = vec![0.0; DIM];
        }
        for (a, b) in self.sum.iter_mut().zip(&other.sum) {
            *a += b;
        }
        for (a, b) in self.squares.iter_mut().zip(&other.squares) {
            *a += b;
        }
        self.rows += other.rows;
    }

    /// The mean of every column and HumanML3D's std: each group's (rotation velocity, linear
    /// velocity, height, positions, rotations, velocities, contacts) standard deviations
    /// averaged and that average used for every column of the group.
    fn mean_std(&self) -> Option<(Vec<f32>, Vec<f32>)> {
        if self.rows == 0 {
            return None;
        }
        let n = self.rows as f64;
        let mean: Vec<f64> = self.sum.iter().map(|s| s / n).collect();
        let std: Vec<f64> = self
            .squares
            .iter()
            .zip(&mean)
            .map(|(q, m)| (q / n - m * m).max(0.0).sqrt())
            .collect();
        let j = NUM_JOINTS;
        let groups = [
            0..1,
            1..3,
            3..4,
            4..4 + (j - 1) * 3,
            4 + (j - 1) * 3..4 + (j - 1) * 9,
            4 + (j - 1) * 9..4 + (j - 1) * 9 + j * 3,
            4 + (j - 1) * 9 + j * 3..DIM,
        ];
        let mut averaged = std.clone();
        for g in groups {
            let avg = std[g.clone()].iter().sum::<f64>() / g.len() as f64;
            averaged[g].fill(avg);
        }
        Some((
            mean.iter().map(|v| *v as f32).collect(),
            averaged.iter().map(|v| *v as f32).collect(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(id: &str, mirrored: bool) -> Entry {
        Entry {
            clip_id: id.into(),
            split: Split::train(),
            mirrored,
            source_kind: "real_single".into(),
            captions: Vec::new(),
            shard: 0,
        }
    }

    #[test]
    fn mirrors_take_their_originals_names() {
        let names = assign_names(&[
            entry("b", false),
            entry("a:m", true),
            entry("a", false),
            entry("c:m", true),
        ]);
        assert_eq!(names["a"], "000000");
        assert_eq!(names["b"], "000001");
        assert_eq!(names["a:m"], "M000000");
        // No original `c` in the table: a number of its own.
        assert_eq!(names["c:m"], "M000002");
    }

    #[test]
    fn std_is_averaged_per_group() {
        let mut m = Moments::default();
        let mut a = vec![0.0f32; DIM];
        let mut b = vec![0.0f32; DIM];
        // Column 1 varies by 2 and column 2 by 0: their group's std is the average, 0.5.
        a[1] = 1.0;
        b[1] = -1.0;
        m.merge(&Moments::of(&a));
        m.merge(&Moments::of(&b));
        let (mean, std) = m.mean_std().unwrap();
        assert_eq!(mean[1], 0.0);
        assert_eq!((std[1], std[2]), (0.5, 0.5));
        assert_eq!(std[0], 0.0);
    }
}
