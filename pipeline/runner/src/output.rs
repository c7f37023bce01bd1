//! The write stage: the clip table and its companions, written atomically, skipped when the last
//! build wrote the same.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::companions::{Companions, card};
use super::held::{HeldClips, Summary};
use super::motions::{MotionIndex, MotionRef, MotionSource, key};
use super::{
    BuildError, CARD_FILE, DATA_DIR, MANIFEST_FILE, NORMALIZATION_DIR, PLANS_FILE, REJECTS_FILE,
    Reject, SKELETONS_FILE, Workspace, sha256_hex, workspace, write_atomic, write_atomic_with,
};
use motionforge_core::base::HashingWriter;
use motionforge_core::motion::Profile;
use motionforge_format::io::normalization::NormalizationStats;
use motionforge_format::io::parquet::{
    ROWS_PER_GROUP, Row, ShardWriter, TableError, rows_to_batch,
};
use motionforge_sources::clip::{Clip, Split};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// What the last write recorded: its inputs' fingerprint, each shard's content fingerprint, and
/// the outputs' checksums with their stat data.
#[derive(Debug, Default, Serialize, Deserialize)]
struct State {
    table_fingerprint: String,
    shards: BTreeMap<String, String>,
    outputs: BTreeMap<String, String>,
    /// Each output's length and modification time (ns) when recorded.
    #[serde(default)]
    stamps: BTreeMap<String, (u64, u128)>,
}

/// Inside the workspace: what the last write recorded.
const STATE_FILE: &str = "state.json";

/// A file's length and modification time in nanoseconds.
fn stat_stamp(path: &Path) -> Option<(u64, u128)> {
    super::digests::stat_data(&std::fs::metadata(path).ok()?)
}

/// The last write's record, and when it was written (the state file's modification time).
struct Recorded {
    state: State,
    at: Option<u128>,
}

impl Recorded {
    fn load(workspace: &Workspace) -> Option<Recorded> {
        let path = workspace.root().join(STATE_FILE);
        let state = std::fs::read(&path)
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())?;
        Some(Recorded {
            state,
            at: stat_stamp(&path).map(|(_, at)| at),
        })
    }

    /// Whether the output `name` still holds the bytes recorded. Stat data is trusted as the
    /// capture digests trust it (`docs/decisions.md`): unchanged length and modification time,
    /// the file last modified before the record was written (git's rule for racily clean
    /// files); otherwise the file is read and hashed.
    fn unchanged(&self, output: &Path, name: &str) -> bool {
        let Some(sha) = self.state.outputs.get(name) else {
            return false;
        };
        let path = output.join(name);
        let stamp = stat_stamp(&path);
        if let (Some(now), Some(then), Some(at)) = (stamp, self.state.stamps.get(name), self.at)
            && now == *then
            && now.1 < at
        {
            return true;
        }
        std::fs::read(&path).is_ok_and(|b| &sha256_hex(&b) == sha)
    }

    fn outputs_match(&self, output: &Path) -> bool {
        !self.state.outputs.is_empty()
            && self
                .state
                .outputs
                .keys()
                .all(|name| self.unchanged(output, name))
    }
}

/// What the write stage writes.
pub(super) struct Table<'a> {
    pub(super) plans: &'a BTreeMap<String, Vec<motionforge_llm::plans::PlanStep>>,
    pub(super) profiles: &'a BTreeMap<String, Profile>,
    pub(super) skeletons: &'a motionforge_format::io::skeletons::Skeletons,
    pub(super) rejects: &'a [Reject],
    /// Reads them back.
    pub(super) motions: &'a MotionSource,
}

/// The table's rows before they are written: the clips in row order and where their frames are.
pub(super) struct Rows {
    /// The clips, sorted by id.
    pub(super) clips: Vec<Clip>,
    /// Where each one's frames are.
    pub(super) index: MotionIndex,
}

/// One planned shard: its file and the clips (indices into the sorted clip list) it holds.
struct ShardPlan {
    split: Split,
    file: String,
    clips: Vec<usize>,
}

/// Rough uncompressed size of a clip's row: the per-joint arrays dominate (positions 3, rotations
/// 4, 6D rotations 6, velocities 3 floats per joint and frame; root, contacts and future root per
/// frame), whether or not every feature column is switched on.
fn row_bytes(clip: Summary) -> u64 {
    let frames = u64::from(clip.frames);
    let joints = u64::from(clip.joints);
    frames * joints * (3 + 4 + 6 + 3) * 4 + frames * (3 + 9) * 4 + frames * 4 + 2048
}

/// Shards per split, in split order, each filled up to `target` bytes (at least one clip).
fn plan_shards(clips: &HeldClips, target: u64) -> Vec<ShardPlan> {
    let splits = crate::stages::split::split_order(clips.summaries().map(|(s, _)| s.clone()));
    let mut plans = Vec::new();
    for split in splits {
        let mut groups: Vec<Vec<usize>> = vec![Vec::new()];
        let mut size = 0u64;
        for (i, (_, c)) in clips
            .summaries()
            .enumerate()
            .filter(|(_, (s, _))| **s == split)
        {
            let b = row_bytes(c);
            if size + b > target && groups.last().is_some_and(|g| !g.is_empty()) {
                groups.push(Vec::new());
                size = 0;
            }
            size += b;
            if let Some(g) = groups.last_mut() {
                g.push(i);
            }
        }
        let n = groups.len();
        for (index, group) in groups.into_iter().enumerate() {
            plans.push(ShardPlan {
                file: format!("{DATA_DIR}/{split}-{index:05}-of-{n:05}.parquet"),
                split: split.clone(),
                clips: group,
            });
        }
    }
    plans
}

/// Reads back `split` and `source_path` of every written shard and refuses a capture found in
/// two splits: the guarantee is checked on what was written, not assumed.
fn check_splits(
    plans: &[ShardPlan],
    path_of: impl Fn(&ShardPlan) -> std::path::PathBuf,
) -> Result<(), BuildError> {
    use motionforge_format::dataset::OpenShard;
    use motionforge_format::io::schema::Column;
    let mut seen: BTreeMap<String, std::collections::BTreeSet<String>> = BTreeMap::new();
    for plan in plans {
        let shard = OpenShard::open(&path_of(plan))?;
        for batch in shard.read(&[Column::Split, Column::SourcePath]).batches()? {
            let batch = batch?;
            let (splits, paths) = (
                batch.strings(Column::Split)?,
                batch.strings(Column::SourcePath)?,
            );
            for (split, path) in splits.into_iter().zip(paths) {
                if let (Some(split), Some(path)) = (split, path) {
                    seen.entry(path).or_default().insert(split);
                }
            }
        }
    }
    if let Some((capture, splits)) = seen.into_iter().find(|(_, s)| s.len() > 1) {
        return Err(BuildError::SplitLeak {
            capture,
            splits: splits.into_iter().collect(),
        });
    }
    Ok(())
}

/// Whether the written outputs are those of a table with `fingerprint`, untouched since; else why
/// not.
pub(super) fn written(
    output: &Path,
    workspace: &Workspace,
    fingerprint: &str,
) -> Result<(), crate::plan::StaleReason> {
    use crate::plan::StaleReason;
    let Some(recorded) = Recorded::load(workspace) else {
        return Err(StaleReason::NeverWritten);
    };
    if !recorded.outputs_match(output) {
        return Err(StaleReason::OutputsChanged);
    }
    if recorded.state.table_fingerprint != fingerprint {
        return Err(StaleReason::RowsChanged);
    }
    Ok(())
}

/// Inside the workspace: where a write stages the new dataset's files before switching.
const STAGING_DIR: &str = "staging";

/// Moves a fully written dataset from `staging` into `output`, by renames only (no new bytes, so
/// no disk-space failure part-way). The old manifest goes first and the new one comes last:
/// while the switch runs, the folder has no manifest, which readers are told means "not a
/// finished dataset" (docs/reference.md, "Disk full, unwritable folders"); before and after, the
/// manifest describes exactly the shards in `data/`.
fn switch(
    output: &Path,
    staging: &Path,
    plans: &[ShardPlan],
    has_normalization: bool,
) -> Result<(), BuildError> {
    let rename = |from: &Path, to: &Path| -> Result<(), BuildError> {
        std::fs::rename(from, to).map_err(|e| {
            BuildError::Workspace(workspace::io_err(to)(std::io::Error::new(
                e.kind(),
                format!("cannot move the new file into place: {e}"),
            )))
        })
    };
    let manifest = output.join(MANIFEST_FILE);
    if manifest.exists() {
        std::fs::remove_file(&manifest).map_err(workspace::io_err(&manifest))?;
    }
    let data = output.join(DATA_DIR);
    std::fs::create_dir_all(&data).map_err(workspace::io_err(&data))?;
    for plan in plans {
        let staged = staging.join(&plan.file);
        if staged.is_file() {
            rename(&staged, &output.join(&plan.file))?;
        }
    }
    // Shards of an earlier layout (other split names or counts) would look like part of the set.
    let planned: std::collections::BTreeSet<&str> = plans.iter().map(|p| p.file.as_str()).collect();
    if let Ok(entries) = std::fs::read_dir(&data) {
        for entry in entries.flatten() {
            let name = format!("{DATA_DIR}/{}", entry.file_name().to_string_lossy());
            if name.ends_with(".parquet") && !planned.contains(name.as_str()) {
                std::fs::remove_file(entry.path()).map_err(workspace::io_err(&entry.path()))?;
            }
        }
    }
    let normalization = output.join(NORMALIZATION_DIR);
    if normalization.exists() {
        std::fs::remove_dir_all(&normalization).map_err(workspace::io_err(&normalization))?;
    }
    if has_normalization {
        rename(&staging.join(NORMALIZATION_DIR), &normalization)?;
    }
    for name in [
        SKELETONS_FILE,
        REJECTS_FILE,
        PLANS_FILE,
        CARD_FILE,
        MANIFEST_FILE,
    ] {
        rename(&staging.join(name), &output.join(name))?;
    }
    let _ = std::fs::remove_dir_all(staging);
    Ok(())
}

/// What one shard needs to be written or checked.
struct ShardJob<'a> {
    table: &'a Table<'a>,
    /// The rows' clips, in row order, each with where its frames are.
    clips: &'a HeldClips,
    companions: &'a Companions,
    skeletons_json: &'a str,
    recorded: Option<&'a Recorded>,
    force: bool,
    output: &'a Path,
    staging: &'a Path,
    /// Whether normalisation statistics are gathered (over every split; each profile then takes
    /// the training split's, or the first split's that holds it).
    stats: bool,
    /// Shards being written now ([`groups_in_flight`]).
    active: AtomicUsize,
}

/// What writing (or keeping) one shard gave.
struct ShardDone {
    entry: motionforge_format::io::manifest::Shard,
    fingerprint: String,
    /// Statistics over the shard's rows.
    stats: Option<NormalizationStats>,
}

impl ShardJob<'_> {
    /// The shard's content fingerprint: its rows without frames, where the frames are, and what
    /// the writer adds (skeletons, schema, features).
    fn fingerprint(
        &self,
        plan: &ShardPlan,
        rows: &[(Clip, MotionRef)],
    ) -> Result<String, BuildError> {
        let held: Vec<&Clip> = rows.iter().map(|(c, _)| c).collect();
        let refs: Vec<Option<&MotionRef>> = rows.iter().map(|(_, at)| Some(at)).collect();
        let encoded = motionforge_core::base::encoded_sha256(&(&held, &refs), &plan.file)?;
        Ok(super::Fingerprint::new("shard", 1)
            .text("rows", &encoded)
            .text("skeletons", self.skeletons_json)
            .json(
                "schema version",
                &motionforge_format::io::schema::SCHEMA_VERSION,
            )
            .json("config features", &self.companions.features)
            .json("config dataset.zstd_level", &self.companions.zstd_level)
            .finish())
    }

    /// Writes the shard into the staging folder, or keeps the one in place when the last build
    /// wrote the same; gathers the normalisation statistics of its rows either way.
    fn run(&self, plan: &ShardPlan) -> Result<ShardDone, BuildError> {
        // The shard's clips, decoded once for its fingerprint and its rows.
        let rows = self.clips.get(&plan.clips)?;
        let fingerprint = self.fingerprint(plan, &rows)?;
        let kept = match self.recorded {
            Some(recorded)
                if !self.force
                    && recorded.state.shards.get(&plan.file) == Some(&fingerprint)
                    && recorded.unchanged(self.output, &plan.file) =>
            {
                let sha256 = recorded.state.outputs.get(&plan.file).cloned();
                let bytes = stat_stamp(&self.output.join(&plan.file)).map(|(len, _)| len);
                sha256.zip(bytes)
            }
            _ => None,
        };
        let mut stats = self.stats.then(NormalizationStats::default);
        let (sha256, bytes) = match kept {
            Some(kept) => {
                if let Some(stats) = &mut stats {
                    self.each_row_group(&rows, |groups| {
                        groups.iter().flatten().for_each(|r| stats.add_row(r));
                        Ok(())
                    })
                    .map_err(|e| e.into_build(self.output.join(&plan.file)))?;
                }
                kept
            }
            None => self.write(plan, &rows, stats.as_mut())?,
        };
        Ok(ShardDone {
            entry: motionforge_format::io::manifest::Shard {
                bytes: bytes as usize,
                file: plan.file.clone(),
                rows: plan.clips.len(),
                sha256,
            },
            fingerprint,
            stats,
        })
    }

    /// Writes the shard to the staging folder; returns its checksum and size.
    fn write(
        &self,
        plan: &ShardPlan,
        clips: &[(Clip, MotionRef)],
        mut stats: Option<&mut NormalizationStats>,
    ) -> Result<(String, u64), BuildError> {
        let path = self.staging.join(&plan.file);
        let mut failure = None;
        let mut written = None;
        write_atomic_with(&path, |file| {
            let file = file.try_clone()?;
            let result = (|| {
                let mut writer = ShardWriter::new(
                    HashingWriter::new(file),
                    self.skeletons_json,
                    self.companions.zstd_level,
                )?;
                self.each_row_group(clips, |groups| {
                    if let Some(stats) = stats.as_deref_mut() {
                        groups.iter().flatten().for_each(|r| stats.add_row(r));
                    }
                    // The rows' arrays are copied into the batches: let them go before encoding.
                    let batches = groups
                        .par_iter()
                        .map(|rows| rows_to_batch(rows))
                        .collect::<Result<Vec<_>, _>>()?;
                    drop(groups);
                    Ok(writer.write_batches(&batches)?)
                })?;
                let (_, sha256, bytes) = writer.finish()?.finish();
                Ok::<_, TableOrBuild>((sha256, bytes))
            })();
            match result {
                Ok(done) => {
                    written = Some(done);
                    Ok(())
                }
                Err(e) => {
                    failure = Some(e);
                    Err(std::io::Error::other("table encoding failed"))
                }
            }
        })
        .map_err(|e| match failure.take() {
            // Named by where it goes: the staging folder is an implementation detail.
            Some(failure) => failure.into_build(self.output.join(&plan.file)),
            None => BuildError::Workspace(e),
        })?;
        written.ok_or_else(|| BuildError::NothingWritten {
            file: plan.file.clone(),
        })
    }

    /// Calls `each` with the shard's rows, a few row groups at a time ([`groups_in_flight`]), in
    /// row order. A group's frames are read in storage order (neighbours on disk together) and
    /// its rows prepared on all cores, the groups of a window side by side; while `each` takes a
    /// window (the writer encodes its groups), the next window is read and prepared beside it, so
    /// a shard's reading and encoding overlap instead of taking turns.
    fn each_row_group(
        &self,
        clips: &[(Clip, MotionRef)],
        mut each: impl FnMut(Vec<Vec<Row<'_>>>) -> Result<(), TableOrBuild> + Send,
    ) -> Result<(), TableOrBuild> {
        let _active = Active::enter(&self.active);
        // Each slot of a window reads with its own recent-entry memory, so parallel shards and
        // groups do not evict each other's chunks.
        let mut motions = vec![self.table.motions.sibling()];
        let mut ready: Option<Vec<Vec<Row<'_>>>> = None;
        let mut at = 0;
        while at < clips.len() {
            let width = groups_in_flight(self.active.load(Ordering::Relaxed));
            while motions.len() < width {
                motions.push(self.table.motions.sibling());
            }
            // Windows are whole row groups from the shard's start, so the groups (and the
            // file's bytes) do not depend on the width.
            let window = &clips[at..clips.len().min(at + ROWS_PER_GROUP * width)];
            at += window.len();
            let (done, rows) = match ready.take() {
                Some(rows) => rayon::join(|| each(rows), || self.window_rows(&motions, window)),
                None => (Ok(()), self.window_rows(&motions, window)),
            };
            done?;
            ready = Some(rows?);
        }
        match ready {
            Some(rows) => each(rows),
            None => Ok(()),
        }
    }

    /// The rows of a window's row groups, side by side, each group read through its own slot
    /// of `motions`.
    fn window_rows<'c>(
        &self,
        motions: &[crate::motions::MotionSource],
        window: &'c [(Clip, MotionRef)],
    ) -> Result<Vec<Vec<Row<'c>>>, TableOrBuild> {
        window
            .par_chunks(ROWS_PER_GROUP)
            .zip(motions.par_iter())
            .map(|(group, motions)| self.group_rows(motions, group))
            .collect()
    }

    /// One row group's rows: its frames read in storage order, its rows made on all cores.
    fn group_rows<'c>(
        &self,
        motions: &crate::motions::MotionSource,
        group: &'c [(Clip, MotionRef)],
    ) -> Result<Vec<Row<'c>>, TableOrBuild> {
        let profiles = self.table.profiles;
        let held: Vec<&Clip> = group.iter().map(|(c, _)| c).collect();
        let mut order: Vec<usize> = (0..group.len()).collect();
        // By the chunk a motion is made from first: a mirror (or a composite) is read right
        // after its original, while the original's chunk is still decoded in the source's
        // memory of recent entries, instead of decoding the chunk a second time.
        order.sort_by_cached_key(|&i| (group[i].1.chunks().first().copied(), &group[i].1));
        let mut frames: Vec<Option<motionforge_core::motion::Motion>> = vec![None; group.len()];
        for i in order {
            let (clip, at) = &group[i];
            frames[i] = Some(
                motions
                    .motion(at, &clip.profile)
                    .map_err(TableOrBuild::Build)?,
            );
        }
        // The rows hold what they need of the frames, which go when this returns.
        held.par_iter()
            .zip(frames.par_iter())
            .map(|(clip, motion)| {
                let profile =
                    profiles
                        .get(&clip.profile)
                        .ok_or_else(|| TableError::MissingProfile {
                            clip: clip.clip_id.clone(),
                            profile: clip.profile.clone(),
                        })?;
                let motion = motion.as_ref().ok_or_else(|| BuildError::NoFrames {
                    clip: clip.clip_id.clone(),
                });
                let motion = motion.map_err(TableOrBuild::Build)?;
                Ok(Row::new(clip, motion, profile, &self.companions.features))
            })
            .collect::<Result<Vec<Row<'c>>, TableOrBuild>>()
    }
}

/// How many row groups of a shard are read, prepared and encoded side by side while `active`
/// shards are being written: the pool's threads shared among them, two threads a group (a
/// group's columns keep about 2.3 cores busy: three frame arrays hold 95% of its bytes), at
/// least one and at most eight. One on 2 cores, as before; when the largest shard is the last
/// one left on 16 cores, eight, so it does not bound the stage alone. The groups in flight, and
/// the memory they hold (rows, batch, encoded chunks), then grow with the threads, not with
/// threads times shards.
fn groups_in_flight(active: usize) -> usize {
    (rayon::current_num_threads() / (2 * active.max(1))).clamp(1, 8)
}

/// Counts a shard as being written while it lives.
struct Active<'a>(&'a AtomicUsize);

impl<'a> Active<'a> {
    fn enter(count: &'a AtomicUsize) -> Active<'a> {
        count.fetch_add(1, Ordering::Relaxed);
        Active(count)
    }
}

impl Drop for Active<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

/// A shard failed in the table encoder or in the build around it.
enum TableOrBuild {
    Table(TableError),
    Build(BuildError),
}

impl TableOrBuild {
    /// The build error, a table error named by the file it was for.
    fn into_build(self, path: std::path::PathBuf) -> BuildError {
        match self {
            TableOrBuild::Table(source) => BuildError::Table { path, source },
            TableOrBuild::Build(e) => e,
        }
    }
}

impl From<TableError> for TableOrBuild {
    fn from(e: TableError) -> Self {
        TableOrBuild::Table(e)
    }
}

/// The write stage: the shards (each skipped when its content is unchanged), normalisation
/// statistics, skeletons, rejects, plans, manifest and card, staged then switched into the dataset
/// folder. False when the last write recorded the same table and its outputs are intact.
pub(super) fn write_outputs(
    force: bool,
    output: &Path,
    workspace: &Workspace,
    fingerprint: &str,
    table: &Table<'_>,
    companions: &Companions,
    rows: Rows,
) -> Result<bool, BuildError> {
    let Rows { clips, index } = rows;
    let recorded = Recorded::load(workspace);
    if !force
        && let Some(recorded) = &recorded
        && recorded.state.table_fingerprint == fingerprint
        && recorded.outputs_match(output)
    {
        return Ok(false);
    }
    let skeletons_json = motionforge_format::io::skeletons::skeletons_json(table.skeletons);
    // From here on the clips are read a shard at a time: held compressed, they no longer grow
    // the build's memory with the dataset.
    let clips = HeldClips::new(clips, |c| index.get(&key(c)).cloned())?;
    drop(index);
    let plans_for_shards = plan_shards(&clips, companions.shard_bytes);
    // Normalisation statistics per split, gathered shard by shard as the rows pass; each
    // profile takes the training split's, or the first split's holding it (CMU in the demo).
    let with_stats = !plans_for_shards.is_empty();
    let staging = fresh_staging(workspace)?;
    let job = ShardJob {
        table,
        clips: &clips,
        companions,
        skeletons_json: &skeletons_json,
        recorded: recorded.as_ref(),
        force,
        output,
        staging: &staging,
        stats: with_stats,
        active: AtomicUsize::new(0),
    };
    // Shards are written on all cores; their results are taken in shard order, so the manifest,
    // the merged statistics and the error reported (the first shard's that failed) are the same
    // on every run.
    let done: Vec<Result<ShardDone, BuildError>> = plans_for_shards
        .par_iter()
        .map(|plan| job.run(plan))
        .collect();
    let done = done
        .into_iter()
        .collect::<Result<Vec<ShardDone>, BuildError>>()?;
    let mut shards = WrittenShards::of(&plans_for_shards, done);
    let staged_path = |plan: &ShardPlan| {
        let staged = staging.join(&plan.file);
        if staged.is_file() {
            staged
        } else {
            output.join(&plan.file)
        }
    };
    check_splits(&plans_for_shards, staged_path)?;
    if with_stats {
        // Split order: train first.
        let splits = std::mem::take(&mut shards.per_split)
            .into_iter()
            .map(|(split, stats)| (split.to_string(), stats))
            .collect();
        NormalizationStats::per_profile(splits).write(&staging.join(NORMALIZATION_DIR))?;
    }
    write_atomic(&staging.join(SKELETONS_FILE), skeletons_json.as_bytes())?;
    write_rejects(&staging, table.rejects)?;
    write_plan_table(&staging, output, table.plans)?;
    write_manifest_and_card(&staging, companions, &shards)?;
    add_companion_checksums(&staging, &mut shards.outputs)?;
    switch(output, &staging, &plans_for_shards, with_stats)?;
    record_state(workspace, output, fingerprint, shards)?;
    Ok(true)
}

/// An empty staging folder with its `data/` folder. Everything new is written into it first;
/// the dataset folder keeps the previous dataset, complete and valid, until the new one is fully
/// written (a full disk fails here and leaves it untouched). Then `switch` moves the new files
/// in, by renames only.
fn fresh_staging(workspace: &Workspace) -> Result<std::path::PathBuf, BuildError> {
    let staging = workspace.root().join(STAGING_DIR);
    if staging.exists() {
        std::fs::remove_dir_all(&staging).map_err(workspace::io_err(&staging))?;
    }
    let staged_data = staging.join(DATA_DIR);
    std::fs::create_dir_all(&staged_data).map_err(workspace::io_err(&staged_data))?;
    Ok(staging)
}

/// The written shards taken together, in shard order: statistics per split, manifest entries,
/// rows and bytes per split, and each output's checksum and shard's content fingerprint.
struct WrittenShards {
    per_split: BTreeMap<Split, NormalizationStats>,
    fingerprints: BTreeMap<String, String>,
    entries: BTreeMap<String, Vec<motionforge_format::io::manifest::Shard>>,
    split_rows: BTreeMap<Split, usize>,
    split_bytes: BTreeMap<Split, usize>,
    /// Checksums of the outputs by file name (the shards here; the companions are added).
    outputs: BTreeMap<String, String>,
}

impl WrittenShards {
    fn of(plans: &[ShardPlan], done: Vec<ShardDone>) -> WrittenShards {
        let mut shards = WrittenShards {
            per_split: BTreeMap::new(),
            fingerprints: BTreeMap::new(),
            entries: BTreeMap::new(),
            split_rows: BTreeMap::new(),
            split_bytes: BTreeMap::new(),
            outputs: BTreeMap::new(),
        };
        for (plan, done) in plans.iter().zip(done) {
            if let Some(stats) = done.stats {
                shards
                    .per_split
                    .entry(plan.split.clone())
                    .or_default()
                    .merge(stats);
            }
            *shards.split_rows.entry(plan.split.clone()).or_insert(0) += done.entry.rows;
            *shards.split_bytes.entry(plan.split.clone()).or_insert(0) += done.entry.bytes;
            shards
                .outputs
                .insert(plan.file.clone(), done.entry.sha256.clone());
            shards
                .entries
                .entry(plan.split.to_string())
                .or_default()
                .push(done.entry);
            shards
                .fingerprints
                .insert(plan.file.clone(), done.fingerprint);
        }
        shards
    }
}

/// `rejects.jsonl`: one JSON object a line.
fn write_rejects(staging: &Path, rejects: &[Reject]) -> Result<(), BuildError> {
    let mut lines = String::new();
    for r in rejects {
        lines.push_str(&serde_json::to_string(r).unwrap_or_default());
        lines.push('\n');
    }
    write_atomic(&staging.join(REJECTS_FILE), lines.as_bytes())?;
    Ok(())
}

/// The task-plan table; an encoding failure is named by the file it is for in the dataset.
fn write_plan_table(
    staging: &Path,
    output: &Path,
    plans: &BTreeMap<String, Vec<motionforge_llm::plans::PlanStep>>,
) -> Result<(), BuildError> {
    let plans_path = staging.join(PLANS_FILE);
    let mut plans_error = None;
    write_atomic_with(&plans_path, |file| {
        motionforge_format::io::parquet::write_plans(file.try_clone()?, plans)
            .map(|_| ())
            .map_err(|e| {
                plans_error = Some(e);
                std::io::Error::other("plan table encoding failed")
            })
    })
    .map_err(|e| match plans_error.take() {
        Some(source) => BuildError::Table {
            path: output.join(PLANS_FILE),
            source,
        },
        None => BuildError::Workspace(e),
    })
}

/// The manifest, with each split's rows and shards, and the dataset card.
fn write_manifest_and_card(
    staging: &Path,
    companions: &Companions,
    shards: &WrittenShards,
) -> Result<(), BuildError> {
    let mut manifest = companions.manifest.clone();
    manifest.splits = shards
        .split_rows
        .iter()
        .map(|(split, rows)| {
            let split_entry = motionforge_format::io::manifest::SplitShards {
                rows: *rows,
                shards: shards
                    .entries
                    .get(split.as_str())
                    .cloned()
                    .unwrap_or_default(),
            };
            (split.to_string(), split_entry)
        })
        .collect();
    write_atomic(&staging.join(MANIFEST_FILE), &manifest.to_json())?;
    let name = manifest.dataset.clone();
    write_atomic(
        &staging.join(CARD_FILE),
        card(&name, &shards.split_rows, &shards.split_bytes, companions).as_bytes(),
    )?;
    Ok(())
}

/// The checksums of the staged companion files (skeletons, rejects, plans, manifest, card).
fn add_companion_checksums(
    staging: &Path,
    outputs: &mut BTreeMap<String, String>,
) -> Result<(), BuildError> {
    for name in [
        SKELETONS_FILE,
        REJECTS_FILE,
        PLANS_FILE,
        MANIFEST_FILE,
        CARD_FILE,
    ] {
        let path = staging.join(name);
        let bytes = std::fs::read(&path).map_err(workspace::io_err(&path))?;
        outputs.insert(name.to_string(), sha256_hex(&bytes));
    }
    Ok(())
}

/// Records what this write made: the table's fingerprint, each shard's, and the outputs'
/// checksums with their stat data.
fn record_state(
    workspace: &Workspace,
    output: &Path,
    fingerprint: &str,
    shards: WrittenShards,
) -> Result<(), BuildError> {
    // Stat data of the files now in place, recorded before the state file is written, so each is
    // older than the record that vouches for it.
    let stamps = shards
        .outputs
        .keys()
        .filter_map(|name| stat_stamp(&output.join(name)).map(|s| (name.clone(), s)))
        .collect();
    let state = State {
        table_fingerprint: fingerprint.to_string(),
        shards: shards.fingerprints,
        outputs: shards.outputs,
        stamps,
    };
    write_atomic(
        &workspace.root().join(STATE_FILE),
        &serde_json::to_vec_pretty(&state).unwrap_or_default(),
    )?;
    Ok(())
}
