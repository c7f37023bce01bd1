//! Reading the columns the statistics need from clip tables, and the drop/reject counts from a
//! build report.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Float64Type, Int32Type, Int64Type};
use arrow_array::{Array, ArrayRef, RecordBatch};
use parquet::arrow::ProjectionMask;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;

use super::stats::{NO_SPLIT, NULL_SPLIT};
use super::{ClipRow, ReportError};
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

/// Reads every table's clip rows, in the order of `tables` and then of the rows in each file.
/// Only the needed columns are decoded. Tables without a `split` column give rows of split
/// [`NO_SPLIT`].
pub fn read_rows(tables: &[PathBuf]) -> Result<Vec<ClipRow>, ReportError> {
    let mut rows = Vec::new();
    for path in tables {
        read_table(path, &mut rows)?;
    }
    Ok(rows)
}

fn read_table(path: &Path, rows: &mut Vec<ClipRow>) -> Result<(), ReportError> {
    let pq = |source| ReportError::Parquet {
        path: path.to_path_buf(),
        source,
    };
    let file = fs::File::open(path).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(file).map_err(pq)?;
    let schema = builder.schema().clone();
    for column in REQUIRED {
        if schema.column_with_name(column.name()).is_none() {
            return Err(ReportError::MissingColumn {
                path: path.to_path_buf(),
                column: column.name().to_string(),
            });
        }
    }
    // Root indices of the Arrow schema are the Parquet schema's root fields, so projecting by
    // them decodes whole columns (lists included) and nothing else.
    let indices: Vec<usize> = REQUIRED
        .iter()
        .chain(OPTIONAL.iter())
        .filter_map(|column| schema.index_of(column.name()).ok())
        .collect();
    let mask = ProjectionMask::roots(builder.parquet_schema(), indices);
    let reader = builder.with_projection(mask).build().map_err(pq)?;
    let mut offset = 0;
    for batch in reader {
        let batch = batch.map_err(|source| ReportError::Arrow {
            path: path.to_path_buf(),
            source,
        })?;
        read_batch(path, &batch, offset, rows)?;
        offset += batch.num_rows();
    }
    Ok(())
}

/// Column accessors of one batch, checked for type once.
struct Columns<'a> {
    path: &'a Path,
    batch: &'a RecordBatch,
}

impl<'a> Columns<'a> {
    fn get(&self, column_name: Column) -> Option<&'a ArrayRef> {
        self.batch.column_by_name(column_name.name())
    }

    fn type_error(&self, column_name: Column, column: &ArrayRef, expected: &str) -> ReportError {
        ReportError::ColumnType {
            path: self.path.to_path_buf(),
            column: column_name.name().to_string(),
            found: column.data_type().to_string(),
            expected: expected.to_string(),
        }
    }

    fn strings(&self, column_name: Column) -> Result<Option<Vec<Option<String>>>, ReportError> {
        let Some(column) = self.get(column_name) else {
            return Ok(None);
        };
        string_values(column)
            .map(Some)
            .ok_or_else(|| self.type_error(column_name, column, "Utf8"))
    }

    fn floats(&self, column_name: Column) -> Result<Option<Vec<Option<f64>>>, ReportError> {
        let Some(column) = self.get(column_name) else {
            return Ok(None);
        };
        float_values(column)
            .map(Some)
            .ok_or_else(|| self.type_error(column_name, column, "Float32 or Float64"))
    }

    fn ints(&self, column_name: Column) -> Result<Option<Vec<Option<i64>>>, ReportError> {
        let Some(column) = self.get(column_name) else {
            return Ok(None);
        };
        let values = if let Some(a) = column.as_primitive_opt::<Int32Type>() {
            a.iter().map(|v| v.map(i64::from)).collect()
        } else if let Some(a) = column.as_primitive_opt::<Int64Type>() {
            a.iter().collect()
        } else {
            return Err(self.type_error(column_name, column, "Int32 or Int64"));
        };
        Ok(Some(values))
    }

    fn bools(&self, column_name: Column) -> Result<Option<Vec<Option<bool>>>, ReportError> {
        let Some(column) = self.get(column_name) else {
            return Ok(None);
        };
        column
            .as_boolean_opt()
            .map(|a| Some(a.iter().collect()))
            .ok_or_else(|| self.type_error(column_name, column, "Boolean"))
    }

    /// A list-of-floats column as one `Vec<f64>` per row.
    fn string_lists(&self, column_name: Column) -> Result<Option<Vec<Vec<String>>>, ReportError> {
        let Some(column) = self.get(column_name) else {
            return Ok(None);
        };
        let items = |item: ArrayRef| -> Option<Vec<String>> {
            string_values(&item).map(|v| v.into_iter().flatten().collect())
        };
        let lists: Vec<Option<ArrayRef>> = if let Some(list) = column.as_list_opt::<i32>() {
            (0..list.len())
                .map(|i| (!list.is_null(i)).then(|| list.value(i)))
                .collect()
        } else if let Some(list) = column.as_list_opt::<i64>() {
            (0..list.len())
                .map(|i| (!list.is_null(i)).then(|| list.value(i)))
                .collect()
        } else {
            return Err(self.type_error(column_name, column, "List<Utf8>"));
        };
        lists
            .into_iter()
            .map(|item| match item {
                None => Ok(Vec::new()),
                Some(item) => {
                    items(item).ok_or_else(|| self.type_error(column_name, column, "List<Utf8>"))
                }
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Some)
    }

    fn float_lists(
        &self,
        column_name: Column,
    ) -> Result<Option<Vec<Option<Vec<f64>>>>, ReportError> {
        let Some(column) = self.get(column_name) else {
            return Ok(None);
        };
        let items = |item: ArrayRef| -> Option<Vec<f64>> {
            float_values(&item).map(|v| v.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
        };
        // List, large list or fixed-size list (a goal is fixed-size from version 9 on).
        let rows = motionforge_format::io::parquet::list_rows(column)
            .ok_or_else(|| self.type_error(column_name, column, "a list of Float32"))?;
        rows.into_iter()
            .map(|row| {
                row.map(|item| {
                    items(item)
                        .ok_or_else(|| self.type_error(column_name, column, "a list of Float32"))
                })
                .transpose()
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Some)
    }
}

/// Strings of a Utf8, LargeUtf8, Utf8View or dictionary-of-strings column; `None` for other types.
fn string_values(column: &ArrayRef) -> Option<Vec<Option<String>>> {
    let own = |v: Option<&str>| v.map(str::to_string);
    if let Some(a) = column.as_string_opt::<i32>() {
        return Some(a.iter().map(own).collect());
    }
    if let Some(a) = column.as_string_opt::<i64>() {
        return Some(a.iter().map(own).collect());
    }
    if let Some(a) = column.as_string_view_opt() {
        return Some(a.iter().map(own).collect());
    }
    if let Some(dict) = column.as_any_dictionary_opt() {
        // Someone writing `split` with pandas or polars may dictionary-encode it.
        let values = string_values(dict.values())?;
        let keys = dict.normalized_keys();
        return Some(
            keys.iter()
                .enumerate()
                .map(|(i, &k)| {
                    if dict.keys().is_null(i) {
                        None
                    } else {
                        values.get(k).cloned().flatten()
                    }
                })
                .collect(),
        );
    }
    None
}

/// Values of a Float32 or Float64 column as f64; `None` for other types.
fn float_values(column: &ArrayRef) -> Option<Vec<Option<f64>>> {
    if let Some(a) = column.as_primitive_opt::<Float32Type>() {
        return Some(a.iter().map(|v| v.map(f64::from)).collect());
    }
    if let Some(a) = column.as_primitive_opt::<Float64Type>() {
        return Some(a.iter().collect());
    }
    None
}

fn read_batch(
    path: &Path,
    batch: &RecordBatch,
    offset: usize,
    rows: &mut Vec<ClipRow>,
) -> Result<(), ReportError> {
    let c = Columns { path, batch };
    let missing = |column: Column| ReportError::MissingColumn {
        path: path.to_path_buf(),
        column: column.name().to_string(),
    };
    let clip_ids = c
        .strings(Column::ClipId)?
        .ok_or_else(|| missing(Column::ClipId))?;
    let kinds = c
        .strings(Column::SourceKind)?
        .ok_or_else(|| missing(Column::SourceKind))?;
    let mirrored = c
        .bools(Column::Mirrored)?
        .ok_or_else(|| missing(Column::Mirrored))?;
    let fps = c.floats(Column::Fps)?.ok_or_else(|| missing(Column::Fps))?;
    let frames = c
        .ints(Column::NumFrames)?
        .ok_or_else(|| missing(Column::NumFrames))?;
    let splits = c.strings(Column::Split)?;
    let motion_types = c.strings(Column::MotionType)?;
    let goals = c.float_lists(Column::GoalPelvis)?;
    let label_sources = c.strings(Column::LabelSource)?;
    let texts = c.string_lists(Column::Texts)?;
    let metrics: Vec<Option<Vec<Option<f64>>>> = METRIC_COLUMNS
        .iter()
        .map(|column| c.floats(*column))
        .collect::<Result<_, _>>()?;

    for i in 0..batch.num_rows() {
        let clip_id = clip_ids[i].clone().unwrap_or_default();
        let invalid = |message: String| ReportError::InvalidValue {
            path: path.to_path_buf(),
            row: offset + i,
            clip_id: clip_id.clone(),
            message,
        };
        if clip_ids[i].is_none() {
            return Err(invalid("`clip_id` is null".into()));
        }
        let source_kind = kinds[i]
            .clone()
            .ok_or_else(|| invalid("`source_kind` is null".into()))?;
        let mirrored = mirrored[i].ok_or_else(|| invalid("`mirrored` is null".into()))?;
        let fps = fps[i].ok_or_else(|| invalid("`fps` is null".into()))?;
        if !(fps.is_finite() && fps > 0.0) {
            return Err(invalid(format!("`fps` is {fps}, not a positive rate")));
        }
        let num_frames = frames[i].ok_or_else(|| invalid("`num_frames` is null".into()))?;
        let frames = usize::try_from(num_frames)
            .map_err(|_| invalid(format!("`num_frames` is {num_frames}")))?;
        let split = match &splits {
            None => NO_SPLIT.to_string(),
            Some(s) => s[i].clone().unwrap_or_else(|| NULL_SPLIT.to_string()),
        };
        let goal_pelvis = match goals.as_ref().and_then(|g| g[i].as_ref()) {
            None => None,
            Some(g) if g.len() == 2 => Some([g[0] as f32, g[1] as f32]),
            Some(g) => {
                return Err(invalid(format!(
                    "`goal_pelvis` has {} values, expected [x, y]",
                    g.len()
                )));
            }
        };
        let values: Vec<Option<f64>> = metrics
            .iter()
            .map(|m| m.as_ref().and_then(|m| m[i]))
            .collect();
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
            motion_type: motion_types.as_ref().and_then(|m| m[i].clone()),
            seconds: frames as f64 / fps,
            frames,
            goal_pelvis,
            label_source: label_sources.as_ref().and_then(|l| l[i].clone()),
            texts: texts.as_ref().map(|t| t[i].clone()).unwrap_or_default(),
            plausibility,
        });
    }
    Ok(())
}

/// Every `.parquet` file under `dir` (recursively) whose schema has a `clip_id` column, sorted by
/// path: finds the clip tables of a build whatever its layout (`clips.parquet`, or shards such as
/// `data/train-00000-of-00002.parquet`) and skips other tables (`plans.parquet`). Hidden folders
/// (the `.motionforge` cache) are not searched.
pub fn find_clip_tables(dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        let io = |source| ReportError::Io {
            path: folder.clone(),
            source,
        };
        for entry in fs::read_dir(&folder).map_err(io)? {
            let entry = entry.map_err(io)?;
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') {
                continue;
            }
            let kind = entry.file_type().map_err(io)?;
            if kind.is_dir() {
                stack.push(path);
            } else if name.ends_with(".parquet") && has_clip_id(&path)? {
                found.push(path);
            }
        }
    }
    found.sort();
    Ok(found)
}

fn has_clip_id(path: &Path) -> Result<bool, ReportError> {
    let file = fs::File::open(path).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let builder =
        ParquetRecordBatchReaderBuilder::try_new(file).map_err(|source| ReportError::Parquet {
            path: path.to_path_buf(),
            source,
        })?;
    Ok(builder
        .schema()
        .column_with_name(Column::ClipId.name())
        .is_some())
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
    let json: serde_json::Value = serde_json::from_str(&text).map_err(|e| ReportError::Json {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let counts = |key: &str| -> Result<BTreeMap<String, usize>, ReportError> {
        match json.get(key) {
            None | Some(serde_json::Value::Null) => Ok(BTreeMap::new()),
            Some(v) => serde_json::from_value(v.clone()).map_err(|e| ReportError::Json {
                path: path.to_path_buf(),
                message: format!("`{key}`: {e}"),
            }),
        }
    };
    Ok((counts("drops_by_reason")?, counts("rejects_by_reason")?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_array::{DictionaryArray, StringArray};
    use std::sync::Arc;

    #[test]
    fn dictionary_strings_are_decoded() {
        let dict: DictionaryArray<Int32Type> =
            vec![Some("train"), None, Some("test"), Some("train")]
                .into_iter()
                .collect();
        let column: ArrayRef = Arc::new(dict);
        let values = string_values(&column).unwrap();
        assert_eq!(
            values,
            vec![
                Some("train".to_string()),
                None,
                Some("test".to_string()),
                Some("train".to_string())
            ]
        );
        let plain: ArrayRef = Arc::new(StringArray::from(vec!["a"]));
        assert_eq!(string_values(&plain).unwrap(), vec![Some("a".to_string())]);
    }
}
