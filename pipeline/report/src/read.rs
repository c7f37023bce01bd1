//! The report's view of clip tables ([`ClipRow`], the columns the statistics need, read through
//! the dataset reader of `motionforge_format::dataset`), and the drop/reject counts from a build
//! report.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use super::stats::{NO_SPLIT, NULL_SPLIT};
use super::{ClipRow, ReportError, ValueProblem};
use motionforge_format::dataset::{OpenShard, ShardBatch};
use motionforge_format::io::schema::Column;

/// Columns without which a table is not a clip table.
const REQUIRED: [Column; 5] = [
    Column::ClipId,
    Column::SourceKind,
    Column::Mirrored,
    Column::Fps,
    Column::NumFrames,
];
/// Columns read when present: older layouts lack some, and `split` comes with sharded outputs.
const OPTIONAL: [Column; 9] = [
    Column::Split,
    Column::Texts,
    Column::MotionType,
    Column::GoalPelvis,
    Column::LabelSource,
    Column::FootSkate,
    Column::GroundPenetration,
    Column::SelfDistance,
    Column::Lean,
];
/// The plausibility columns, in the order of [`ClipRow::plausibility`].
const METRIC_COLUMNS: [Column; 4] = [
    Column::FootSkate,
    Column::GroundPenetration,
    Column::SelfDistance,
    Column::Lean,
];

/// Reads every table's clip rows, in the order of `tables` and then of the rows in each file,
/// through the dataset reader ([`motionforge_format::dataset::OpenShard::read`]). Only the needed
/// columns are decoded. Tables without a `split` column give rows of split [`NO_SPLIT`].
pub fn read_rows(tables: &[PathBuf]) -> Result<Vec<ClipRow>, ReportError> {
    let mut rows = Vec::new();
    for path in tables {
        let columns: Vec<Column> = REQUIRED.iter().chain(OPTIONAL.iter()).copied().collect();
        let shard = OpenShard::open(path)?;
        for batch in shard.read(&columns).require(&REQUIRED).batches()? {
            read_batch(&batch?, &mut rows)?;
        }
    }
    Ok(rows)
}

fn read_batch(b: &ShardBatch, rows: &mut Vec<ClipRow>) -> Result<(), ReportError> {
    let clip_ids = b.strings(Column::ClipId)?;
    let kinds = b.strings(Column::SourceKind)?;
    let mirrored = b.bools(Column::Mirrored)?;
    let fps = b.floats(Column::Fps)?;
    let frames = b.ints(Column::NumFrames)?;
    let splits = b
        .has(Column::Split)
        .then(|| b.strings(Column::Split))
        .transpose()?;
    let motion_types = b.strings(Column::MotionType)?;
    let goals = b.f32_lists(Column::GoalPelvis)?;
    let label_sources = b.strings(Column::LabelSource)?;
    let texts = b.string_lists(Column::Texts)?;
    let metrics: Vec<Vec<Option<f64>>> = METRIC_COLUMNS
        .iter()
        .map(|column| b.floats(*column))
        .collect::<Result<_, _>>()?;

    for i in 0..b.num_rows() {
        let clip_id = clip_ids[i].clone().unwrap_or_default();
        let invalid = |problem: ValueProblem| ReportError::InvalidValue {
            path: b.path().to_path_buf(),
            row: b.first_row() + i,
            clip_id: clip_id.clone(),
            problem,
        };
        let null = |column: &'static str| invalid(ValueProblem::Null(column));
        if clip_ids[i].is_none() {
            return Err(null("clip_id"));
        }
        let source_kind = kinds[i].clone().ok_or_else(|| null("source_kind"))?;
        let mirrored = mirrored[i].ok_or_else(|| null("mirrored"))?;
        let fps = fps[i].ok_or_else(|| null("fps"))?;
        if !(fps.is_finite() && fps > 0.0) {
            return Err(invalid(ValueProblem::Fps(fps)));
        }
        let num_frames = frames[i].ok_or_else(|| null("num_frames"))?;
        let frames =
            usize::try_from(num_frames).map_err(|_| invalid(ValueProblem::Frames(num_frames)))?;
        let split = match &splits {
            None => NO_SPLIT.to_string(),
            Some(s) => s[i].clone().unwrap_or_else(|| NULL_SPLIT.to_string()),
        };
        let goal_pelvis = match &goals[i] {
            None => None,
            Some(g) if g.len() == 2 => Some([g[0], g[1]]),
            Some(g) => {
                return Err(invalid(ValueProblem::Goal(g.len())));
            }
        };
        let values: Vec<Option<f64>> = metrics.iter().map(|m| m[i]).collect();
        let plausibility = if values.iter().all(Option::is_none) {
            None
        } else {
            let v = |k: usize| values[k].map_or(f32::NAN, |x| x as f32);
            Some([v(0), v(1), v(2), v(3)])
        };
        rows.push(ClipRow {
            clip_id,
            split,
            source_kind,
            mirrored,
            motion_type: motion_types[i].clone(),
            seconds: frames as f64 / fps,
            frames,
            goal_pelvis,
            label_source: label_sources[i].clone(),
            texts: texts[i].clone(),
            plausibility,
        });
    }
    Ok(())
}

/// Every `.parquet` file under `dir` (recursively) whose schema has a `clip_id` column, sorted by
/// path: [`motionforge_format::dataset::find_clip_tables`], kept here for the report's callers.
pub fn find_clip_tables(dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
    Ok(motionforge_format::dataset::find_clip_tables(dir)?)
}

/// Drop and reject counts by reason from a build's `build-report.json` (`drops_by_reason`,
/// `rejects_by_reason`); a missing key gives an empty map.
#[allow(clippy::type_complexity)]
pub fn read_build_counts(
    path: &Path,
) -> Result<(BTreeMap<String, usize>, BTreeMap<String, usize>), ReportError> {
    let text = fs::read_to_string(path).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let json: serde_json::Value =
        serde_json::from_str(&text).map_err(|source| ReportError::Json {
            path: path.to_path_buf(),
            source,
        })?;
    let counts = |key: &'static str| -> Result<BTreeMap<String, usize>, ReportError> {
        match json.get(key) {
            None | Some(serde_json::Value::Null) => Ok(BTreeMap::new()),
            Some(v) => serde_json::from_value(v.clone()).map_err(|source| ReportError::Counts {
                path: path.to_path_buf(),
                key,
                source,
            }),
        }
    };
    Ok((counts("drops_by_reason")?, counts("rejects_by_reason")?))
}
