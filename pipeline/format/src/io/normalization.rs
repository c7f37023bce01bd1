//! Normalisation statistics over the training split (HumanML3D's `Mean.npy` / `Std.npy`): mean and
//! standard deviation per joint and dimension of each motion feature, per skeleton profile, as
//! `.npy` files and one Parquet table.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::{ArrayRef, Float32Array, Int32Array, RecordBatch, StringArray};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ArrowWriter;

use super::parquet::{Row, TableError};
use motionforge_core::base::{WorkspaceError, write_atomic, write_atomic_with};

/// Why normalisation statistics could not be written.
#[derive(Debug, thiserror::Error)]
pub enum NormalizationError {
    /// A file could not be written.
    #[error(transparent)]
    Write(#[from] WorkspaceError),
    /// The statistics table could not be encoded.
    #[error("{path}: {source}")]
    Table {
        /// The table path.
        path: PathBuf,
        /// The error.
        source: Box<TableError>,
    },
    /// A statistic is NaN or infinite (never written; inputs are bounded at ingest, so this is a
    /// bug to report).
    #[error(
        "normalisation statistics of `{feature}` for profile `{profile}` are not finite; not written"
    )]
    NonFinite {
        /// The skeleton profile.
        profile: String,
        /// The feature.
        feature: String,
    },
}
use motionforge_core::features::FeatureConfig;
use motionforge_core::motion::Profile;
use motionforge_sources::clip::LoadedClip;

/// Running sums for one feature: per element (joint × dimension).
struct Moments {
    dims: usize,
    count: u64,
    sum: Vec<f64>,
    sq: Vec<f64>,
}

impl Moments {
    fn new(len: usize, dims: usize) -> Moments {
        Moments {
            dims,
            count: 0,
            sum: vec![0.0; len],
            sq: vec![0.0; len],
        }
    }

    fn add(&mut self, frame: &[f32]) {
        self.count += 1;
        for (k, v) in frame.iter().enumerate() {
            let v = f64::from(*v);
            self.sum[k] += v;
            self.sq[k] += v * v;
        }
    }

    /// Mean and standard deviation (population), the deviation floored at 1e-8 so dividing by it
    /// never blows up a constant channel, and which elements are constant (see [`CONSTANT_STD`]).
    fn finish(&self) -> (Vec<f32>, Vec<f32>, Vec<bool>) {
        let n = self.count.max(1) as f64;
        let mean: Vec<f64> = self.sum.iter().map(|s| s / n).collect();
        let raw: Vec<f64> = self
            .sq
            .iter()
            .zip(&mean)
            .map(|(q, m)| (q / n - m * m).max(0.0).sqrt())
            .collect();
        let std = raw.iter().map(|d| d.max(1e-8) as f32).collect();
        let constant = raw.iter().map(|d| *d < CONSTANT_STD).collect();
        (mean.into_iter().map(|m| m as f32).collect(), std, constant)
    }
}

/// A `.npy` (format 1.0) of little-endian f32 with the given shape.
pub fn npy_f32(values: &[f32], shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape_text}, }}");
    // Magic (6) + version (2) + length (2) + header + newline, padded to a multiple of 64.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + values.len() * 4);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    // Sized once and filled in place: a loop the compiler turns into a copy.
    let start = out.len();
    out.resize(start + values.len() * 4, 0);
    for (bytes, v) in out[start..].chunks_exact_mut(4).zip(values) {
        bytes.copy_from_slice(&v.to_le_bytes());
    }
    out
}

/// Writes `<dir>/<profile>/<feature>_{mean,std}.npy` and `<dir>/normalization.parquet` from the
/// clips of `split` (originals, mirrors and synthetic pairs alike, as training sees them).
pub fn write_normalization(
    dir: &Path,
    clips: &[LoadedClip],
    split: &str,
    profiles: &BTreeMap<String, Profile>,
    config: &FeatureConfig,
) -> Result<Vec<PathBuf>, NormalizationError> {
    let mut stats = NormalizationStats::default();
    for clip in clips.iter().filter(|c| c.clip.split == split) {
        stats.add(clip, profiles, config);
    }
    NormalizationStats::per_profile(vec![(split.to_string(), stats)]).write(dir)
}

/// Per-feature moments gathered one clip at a time, so the clips need not be in memory together.
#[derive(Default)]
pub struct NormalizationStats {
    stats: BTreeMap<(String, &'static str), Moments>,
    /// Per profile, the split its moments were gathered over (set by [`Self::per_profile`]).
    split_of: BTreeMap<String, String>,
}

/// A standard deviation below this (in the feature's unit: metres, or unitless for 6D
/// rotations) marks a constant dimension: a trainer dividing by it would blow up noise.
pub const CONSTANT_STD: f64 = 1e-6;

/// `normalization/normalization.json`: per profile, where its statistics come from and which
/// dimensions are constant.
pub const SUMMARY_FILE: &str = "normalization.json";

/// What `normalization.json` says of one skeleton profile.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ProfileSummary {
    /// The split the statistics are taken over: `train`, or the first split in order holding
    /// the profile's rows when `train` holds none.
    pub split: String,
    /// Frames the statistics are taken over.
    pub frames: u64,
    /// Per feature, its number of dimensions (joints x dims).
    pub dimensions: BTreeMap<String, usize>,
    /// Per feature, its constant dimensions as `joint <j> <axis>` (standard deviation below
    /// [`CONSTANT_STD`]; their `std` is floored at 1e-8 in the files).
    pub constant: BTreeMap<String, Vec<String>>,
}

/// The name of dimension `k` of a feature with `dims` numbers per joint.
fn dimension_name(k: usize, dims: usize) -> String {
    let axis = match (dims, k % dims) {
        (3, a) => ["x", "y", "z"][a].to_string(),
        (_, a) => a.to_string(),
    };
    format!("joint {} {axis}", k / dims)
}

impl NormalizationStats {
    /// Adds every frame of `clip` (skipped when its profile is not in `profiles`).
    pub fn add(
        &mut self,
        clip: &LoadedClip,
        profiles: &BTreeMap<String, Profile>,
        config: &FeatureConfig,
    ) {
        if let Ok(row) = Row::of_clip(clip, profiles, config) {
            self.add_row(&row);
        }
    }

    /// Adds every frame of a prepared row: the values its shard holds.
    pub fn add_row(&mut self, row: &Row<'_>) {
        let n = row.joints;
        let mut groups: Vec<(&'static str, usize, &[f32])> = vec![
            ("joint_positions", 3, &row.motion.positions),
            ("canonical_positions", 3, &row.canonical),
        ];
        if let Some(v) = &row.features.rotations_6d {
            groups.push(("rotations_6d", 6, v));
        }
        if let Some(v) = &row.features.velocities {
            groups.push(("joint_velocities", 3, v));
        }
        for (name, dims, values) in groups {
            let entry = self
                .stats
                .entry((row.clip.profile.clone(), name))
                .or_insert_with(|| Moments::new(n * dims, dims));
            if entry.sum.len() != n * dims {
                continue;
            }
            for frame in values.chunks_exact(n * dims) {
                entry.add(frame);
            }
        }
    }

    /// Adds the statistics gathered over other rows (a later shard's, so that shards can be
    /// gathered in parallel and merged in shard order, the same result on every run).
    pub fn merge(&mut self, other: NormalizationStats) {
        for (key, moments) in other.stats {
            match self.stats.get_mut(&key) {
                None => {
                    self.stats.insert(key, moments);
                }
                Some(mine) if mine.sum.len() == moments.sum.len() => {
                    mine.count += moments.count;
                    for (a, b) in mine.sum.iter_mut().zip(&moments.sum) {
                        *a += b;
                    }
                    for (a, b) in mine.sq.iter_mut().zip(&moments.sq) {
                        *a += b;
                    }
                }
                // Another joint count under the same profile: skipped, as `add_row` skips it.
                Some(_) => {}
            }
        }
    }

    /// Per profile, the statistics of the first split in `splits` (given in split order, train
    /// first) that holds rows of it, so every profile has statistics and says where they are from.
    pub fn per_profile(splits: Vec<(String, NormalizationStats)>) -> NormalizationStats {
        let mut out = NormalizationStats::default();
        for (split, stats) in splits {
            for ((profile, feature), moments) in stats.stats {
                let taken = out.split_of.get(&profile);
                if taken.is_some_and(|s| *s != split) {
                    continue;
                }
                out.split_of.insert(profile.clone(), split.clone());
                out.stats.insert((profile, feature), moments);
            }
        }
        out
    }

    /// Per profile: split, frames, dimensions and constant dimensions.
    pub fn summary(&self) -> BTreeMap<String, ProfileSummary> {
        let mut out: BTreeMap<String, ProfileSummary> = BTreeMap::new();
        for ((profile, feature), moments) in &self.stats {
            let entry = out
                .entry(profile.clone())
                .or_insert_with(|| ProfileSummary {
                    split: self.split_of.get(profile).cloned().unwrap_or_default(),
                    frames: moments.count,
                    dimensions: BTreeMap::new(),
                    constant: BTreeMap::new(),
                });
            entry
                .dimensions
                .insert(feature.to_string(), moments.sum.len());
            let (_, _, constant) = moments.finish();
            let names: Vec<String> = constant
                .iter()
                .enumerate()
                .filter(|(_, c)| **c)
                .map(|(k, _)| dimension_name(k, moments.dims))
                .collect();
            if !names.is_empty() {
                entry.constant.insert(feature.to_string(), names);
            }
        }
        out
    }

    /// Writes the statistics gathered (see [`write_normalization`]).
    pub fn write(self, dir: &Path) -> Result<Vec<PathBuf>, NormalizationError> {
        let summary = self.summary();
        let split_of = self.split_of;
        let stats = self.stats;
        let mut written = Vec::new();
        let (
            mut col_profile,
            mut col_feature,
            mut col_joint,
            mut col_dim,
            mut col_mean,
            mut col_std,
        ) = (
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
        );
        let (mut col_split, mut col_constant) = (Vec::new(), Vec::new());
        for ((profile, feature), moments) in &stats {
            let (mean, std, constant) = moments.finish();
            // The last guard of "nothing non-finite is written" (inputs are bounded at ingest).
            if mean.iter().chain(&std).any(|v| !v.is_finite()) {
                return Err(NormalizationError::NonFinite {
                    profile: profile.clone(),
                    feature: feature.to_string(),
                });
            }
            let shape = [mean.len() / moments.dims, moments.dims];
            for (suffix, values) in [("mean", &mean), ("std", &std)] {
                let path = dir.join(profile).join(format!("{feature}_{suffix}.npy"));
                write_atomic(&path, &npy_f32(values, &shape))?;
                written.push(path);
            }
            for k in 0..mean.len() {
                col_profile.push(profile.clone());
                col_feature.push(feature.to_string());
                col_joint.push((k / moments.dims) as i32);
                col_dim.push((k % moments.dims) as i32);
                col_mean.push(mean[k]);
                col_std.push(std[k]);
                col_split.push(split_of.get(profile).cloned().unwrap_or_default());
                col_constant.push(constant[k]);
            }
        }
        let schema = Arc::new(Schema::new(vec![
            Field::new("profile", DataType::Utf8, false),
            Field::new("feature", DataType::Utf8, false),
            Field::new("joint", DataType::Int32, false),
            Field::new("dim", DataType::Int32, false),
            Field::new("mean", DataType::Float32, false),
            Field::new("std", DataType::Float32, false),
            Field::new("split", DataType::Utf8, false),
            Field::new("constant", DataType::Boolean, false),
        ]));
        let columns: Vec<ArrayRef> = vec![
            Arc::new(StringArray::from(col_profile)),
            Arc::new(StringArray::from(col_feature)),
            Arc::new(Int32Array::from(col_joint)),
            Arc::new(Int32Array::from(col_dim)),
            Arc::new(Float32Array::from(col_mean)),
            Arc::new(Float32Array::from(col_std)),
            Arc::new(StringArray::from(col_split)),
            Arc::new(arrow_array::BooleanArray::from(col_constant)),
        ];
        // Folders of profiles no longer in the split would pass for current statistics.
        let current: std::collections::BTreeSet<&str> =
            stats.keys().map(|(profile, _)| profile.as_str()).collect();
        if let Ok(entries) = std::fs::read_dir(dir) {
            for entry in entries.flatten() {
                let name = entry.file_name().to_string_lossy().into_owned();
                if entry.file_type().is_ok_and(|t| t.is_dir()) && !current.contains(name.as_str()) {
                    let _ = std::fs::remove_dir_all(entry.path());
                }
            }
        }
        let path = dir.join("normalization.parquet");
        let table = |e: TableError| NormalizationError::Table {
            path: path.clone(),
            source: Box::new(e),
        };
        let batch =
            RecordBatch::try_new(Arc::clone(&schema), columns).map_err(|e| table(e.into()))?;
        let mut failure = None;
        write_atomic_with(&path, |file| {
            let handle = file.try_clone()?;
            let run = || -> Result<(), TableError> {
                let mut w = ArrowWriter::try_new(handle, Arc::clone(&schema), None)?;
                w.write(&batch)?;
                w.close()?;
                Ok(())
            };
            run().map_err(|e| {
                failure = Some(e);
                std::io::Error::other("normalization table encoding failed")
            })
        })
        .map_err(|e| match failure.take() {
            Some(source) => NormalizationError::Table {
                path: path.clone(),
                source: Box::new(source),
            },
            None => NormalizationError::Write(e),
        })?;
        written.push(path);
        let summary_path = dir.join(SUMMARY_FILE);
        let json = serde_json::to_vec_pretty(&serde_json::json!({ "profiles": summary }))
            .unwrap_or_default();
        write_atomic(&summary_path, &json)?;
        written.push(summary_path);
        Ok(written)
    }
}

/// The per-profile summary a build wrote into `<normalization dir>/normalization.json`; `None`
/// when there is none (no shard written yet) or it does not parse.
pub fn read_summary(dir: &Path) -> Option<BTreeMap<String, ProfileSummary>> {
    #[derive(serde::Deserialize)]
    struct File {
        profiles: BTreeMap<String, ProfileSummary>,
    }
    let bytes = std::fs::read(dir.join(SUMMARY_FILE)).ok()?;
    serde_json::from_slice::<File>(&bytes)
        .ok()
        .map(|f| f.profiles)
}
