//! The one reader of clip tables: finding a dataset's shards, reading the columns a caller names
//! (by name, never by position) from an [`OpenShard`], a batch of rows at a time, and decoding
//! them into typed values. Every reader of a built dataset (`clips`, `preview`, `export-bvh`,
//! the report and its gallery, the planner, the exports, the service, the build's read-back of
//! its own shards, `bench-build`) goes through it.
//!
//! The decoders take each column in the Arrow types a clip table may come in (the writer's, and
//! what pandas or polars make of it: large and view strings, dictionary-encoded strings, 64-bit
//! integers, 64-bit floats), and an absent column as all nulls; which columns must be there is
//! the caller's to say ([`ShardRead::require`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Float64Type, Int32Type, Int64Type};
use arrow_array::{Array, ArrayRef, RecordBatch};
use arrow_schema::SchemaRef;
use parquet::arrow::ProjectionMask;
use parquet::arrow::arrow_reader::{ParquetRecordBatchReaderBuilder, RowSelection, RowSelector};

use super::{DatasetError, OpenShard};
use crate::io::schema::Column;

/// Rows decoded at once unless a read says otherwise.
const BATCH_ROWS: usize = 256;

/// Every `.parquet` file under `dir` (recursively) whose schema has a `clip_id` column, sorted by
/// path: the clip tables of a build whatever its layout (`clips.parquet`, or shards such as
/// `data/train-00000-of-00002.parquet`), other tables (`plans.parquet`) left out. Hidden files and
/// folders (the `.motionforge` cache, a shard being written) are not searched.
pub fn find_clip_tables(dir: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    Ok(open_clip_tables(dir)?
        .into_iter()
        .map(|shard| shard.path().to_path_buf())
        .collect())
}

/// [`find_clip_tables`], each table opened (once: the schema was read from what stays open).
pub fn open_clip_tables(dir: &Path) -> Result<Vec<OpenShard>, DatasetError> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        let io = |source| DatasetError::Io {
            path: folder.clone(),
            source,
        };
        for entry in std::fs::read_dir(&folder).map_err(io)? {
            let entry = entry.map_err(io)?;
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') {
                continue;
            }
            if entry.file_type().map_err(io)?.is_dir() {
                stack.push(path);
            } else if name.ends_with(".parquet") {
                let shard = OpenShard::open(&path)?;
                if shard.has(Column::ClipId)? {
                    found.push(shard);
                }
            }
        }
    }
    found.sort_by(|a, b| a.path().cmp(b.path()));
    Ok(found)
}

impl OpenShard {
    fn builder(&self) -> Result<ParquetRecordBatchReaderBuilder<OpenShard>, DatasetError> {
        ParquetRecordBatchReaderBuilder::try_new(self.clone()).map_err(|source| {
            DatasetError::Parquet {
                path: self.path().to_path_buf(),
                source,
            }
        })
    }

    /// The shard's Arrow schema (its key-value metadata included).
    pub fn schema(&self) -> Result<SchemaRef, DatasetError> {
        Ok(self.builder()?.schema().clone())
    }

    /// Whether the shard has `column`.
    pub fn has(&self, column: Column) -> Result<bool, DatasetError> {
        Ok(self.schema()?.column_with_name(column.name()).is_some())
    }

    /// The value of the file's key-value metadata entry `key` (`motionforge.skeletons`, ...).
    pub fn key_value(&self, key: &str) -> Result<Option<String>, DatasetError> {
        let builder = self.builder()?;
        Ok(builder
            .metadata()
            .file_metadata()
            .key_value_metadata()
            .and_then(|kv| kv.iter().find(|kv| kv.key == key))
            .and_then(|kv| kv.value.clone()))
    }

    /// A read of `columns` (those of them the shard has) of every row.
    pub fn read(&self, columns: &[Column]) -> ShardRead<'_> {
        self.read_named(columns.iter().map(|c| c.name()))
    }

    /// A read of the columns called `names` (those of them the shard has), for a reader of
    /// columns it does not know in advance (the service's column view).
    pub fn read_named<S: AsRef<str>>(&self, names: impl IntoIterator<Item = S>) -> ShardRead<'_> {
        ShardRead {
            shard: self,
            names: names.into_iter().map(|n| n.as_ref().to_string()).collect(),
            required: Vec::new(),
            selection: None,
            first_row: 0,
            batch_rows: BATCH_ROWS,
        }
    }
}

/// What to read of one shard: built by [`OpenShard::read`], run by [`ShardRead::batches`].
#[derive(Debug)]
#[must_use = "a read does nothing until its batches are taken"]
pub struct ShardRead<'a> {
    shard: &'a OpenShard,
    names: Vec<String>,
    required: Vec<Column>,
    selection: Option<RowSelection>,
    first_row: usize,
    batch_rows: usize,
}

impl ShardRead<'_> {
    /// Fails the read ([`DatasetError::MissingColumn`]) when the shard lacks any of `columns`.
    pub fn require(mut self, columns: &[Column]) -> Self {
        self.required.extend_from_slice(columns);
        self
    }

    /// Only the rows `first..first + count`.
    pub fn rows(mut self, first: usize, count: usize) -> Self {
        self.selection = Some(RowSelection::from(vec![
            RowSelector::skip(first),
            RowSelector::select(count),
        ]));
        self.first_row = first;
        self
    }

    /// At most `rows` rows per batch (at least one).
    pub fn batch_rows(mut self, rows: usize) -> Self {
        self.batch_rows = rows.max(1);
        self
    }

    /// The batches, in row order. Only the named columns are decoded: projecting by the Arrow
    /// schema's root fields decodes whole columns (lists included) and nothing else.
    pub fn batches(
        self,
    ) -> Result<impl Iterator<Item = Result<ShardBatch, DatasetError>> + use<>, DatasetError> {
        let path: Arc<Path> = Arc::from(self.shard.path());
        let builder = self.shard.builder()?;
        let schema = builder.schema().clone();
        for c in &self.required {
            if schema.column_with_name(c.name()).is_none() {
                return Err(DatasetError::MissingColumn {
                    path: path.to_path_buf(),
                    column: c.name(),
                });
            }
        }
        let indices: Vec<usize> = self
            .names
            .iter()
            .filter_map(|n| schema.index_of(n).ok())
            .collect();
        let mask = ProjectionMask::roots(builder.parquet_schema(), indices);
        let mut builder = builder
            .with_projection(mask)
            .with_batch_size(self.batch_rows);
        if let Some(s) = self.selection {
            builder = builder.with_row_selection(s);
        }
        let reader = builder.build().map_err(|source| DatasetError::Parquet {
            path: path.to_path_buf(),
            source,
        })?;
        let mut first_row = self.first_row;
        Ok(reader.map(move |batch| {
            let batch = batch.map_err(|source| DatasetError::Arrow {
                path: path.to_path_buf(),
                source,
            })?;
            let at = first_row;
            first_row += batch.num_rows();
            Ok(ShardBatch {
                path: path.clone(),
                batch,
                first_row: at,
            })
        }))
    }
}

/// One batch of a shard's rows, with typed access to its columns; errors name the shard and
/// the column.
#[derive(Debug, Clone)]
pub struct ShardBatch {
    path: Arc<Path>,
    batch: RecordBatch,
    first_row: usize,
}

impl ShardBatch {
    /// The shard.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The decoded columns as Arrow holds them.
    pub fn record_batch(&self) -> &RecordBatch {
        &self.batch
    }

    /// Rows in the batch.
    pub fn num_rows(&self) -> usize {
        self.batch.num_rows()
    }

    /// The shard's row number of the batch's first row.
    pub fn first_row(&self) -> usize {
        self.first_row
    }

    /// Whether the batch has `column` (the shard has it and the read named it).
    pub fn has(&self, column: Column) -> bool {
        self.batch.column_by_name(column.name()).is_some()
    }

    /// The column as Arrow holds it, or [`DatasetError::MissingColumn`].
    pub fn column(&self, column: Column) -> Result<&ArrayRef, DatasetError> {
        self.batch
            .column_by_name(column.name())
            .ok_or_else(|| DatasetError::MissingColumn {
                path: self.path.to_path_buf(),
                column: column.name(),
            })
    }

    fn wrong(&self, column: Column, found: &ArrayRef, expected: &'static str) -> DatasetError {
        DatasetError::ColumnType {
            path: self.path.to_path_buf(),
            column: column.name(),
            found: found.data_type().to_string(),
            expected,
        }
    }

    /// `None` per row when the column is absent, else `decode` of it or a type error.
    fn decoded<T: Clone>(
        &self,
        column: Column,
        absent: T,
        expected: &'static str,
        decode: impl FnOnce(&ArrayRef) -> Option<Vec<T>>,
    ) -> Result<Vec<T>, DatasetError> {
        match self.batch.column_by_name(column.name()) {
            None => Ok(vec![absent; self.batch.num_rows()]),
            Some(c) => decode(c).ok_or_else(|| self.wrong(column, c, expected)),
        }
    }

    /// A string column's values (`None` per null row).
    pub fn strings(&self, column: Column) -> Result<Vec<Option<String>>, DatasetError> {
        self.decoded(column, None, "Utf8", string_values)
    }

    /// A list-of-strings column's values (empty for a null row).
    pub fn string_lists(&self, column: Column) -> Result<Vec<Vec<String>>, DatasetError> {
        let expected = "List<Utf8>";
        let Some(c) = self.batch.column_by_name(column.name()) else {
            return Ok(vec![Vec::new(); self.batch.num_rows()]);
        };
        let rows =
            crate::io::parquet::list_rows(c).ok_or_else(|| self.wrong(column, c, expected))?;
        rows.into_iter()
            .map(|row| match row {
                None => Ok(Vec::new()),
                Some(items) => string_values(&items)
                    .map(|v| v.into_iter().flatten().collect())
                    .ok_or_else(|| self.wrong(column, c, expected)),
            })
            .collect()
    }

    /// A Float32 or Float64 column's values, as f64.
    pub fn floats(&self, column: Column) -> Result<Vec<Option<f64>>, DatasetError> {
        self.decoded(column, None, "Float32 or Float64", float_values)
    }

    /// A Float32 column's values (a Float64 one narrowed).
    pub fn f32s(&self, column: Column) -> Result<Vec<Option<f32>>, DatasetError> {
        self.decoded(column, None, "Float32", |c| {
            if let Some(a) = c.as_primitive_opt::<Float32Type>() {
                return Some(a.iter().collect());
            }
            float_values(c).map(|v| v.into_iter().map(|x| x.map(|x| x as f32)).collect())
        })
    }

    /// An Int32 or Int64 column's values, as i64.
    pub fn ints(&self, column: Column) -> Result<Vec<Option<i64>>, DatasetError> {
        self.decoded(column, None, "Int32 or Int64", |c| {
            if let Some(a) = c.as_primitive_opt::<Int32Type>() {
                return Some(a.iter().map(|v| v.map(i64::from)).collect());
            }
            c.as_primitive_opt::<Int64Type>()
                .map(|a| a.iter().collect())
        })
    }

    /// A Boolean column's values.
    pub fn bools(&self, column: Column) -> Result<Vec<Option<bool>>, DatasetError> {
        self.decoded(column, None, "Boolean", |c| {
            c.as_boolean_opt().map(|a| a.iter().collect())
        })
    }

    /// A small vector per row (a goal), as a list or a fixed-size list of floats.
    pub fn f32_lists(&self, column: Column) -> Result<Vec<Option<Vec<f32>>>, DatasetError> {
        self.lists(column, "a list of Float32", |v| {
            if let Some(f) = v.as_primitive_opt::<Float32Type>() {
                Some(f.iter().map(|x| x.unwrap_or(f32::NAN)).collect())
            } else {
                float_values(v)
                    .map(|f| f.into_iter().map(|x| x.map_or(f32::NAN, |x| x as f32)))
                    .map(Iterator::collect)
            }
        })
    }

    /// A list of flags per row (`parts`).
    pub fn bool_lists(&self, column: Column) -> Result<Vec<Option<Vec<bool>>>, DatasetError> {
        self.lists(column, "a list of Boolean", |v| {
            v.as_boolean_opt()
                .map(|b| b.iter().map(|x| x.unwrap_or(false)).collect())
        })
    }

    /// A list column's rows, each decoded by `decode` (`None`: not the `expected` type); every
    /// row null when the shard has no such column.
    fn lists<T>(
        &self,
        column: Column,
        expected: &'static str,
        decode: impl Fn(&ArrayRef) -> Option<Vec<T>>,
    ) -> Result<Vec<Option<Vec<T>>>, DatasetError> {
        let Some(c) = self.batch.column_by_name(column.name()) else {
            return Ok((0..self.batch.num_rows()).map(|_| None).collect());
        };
        let rows =
            crate::io::parquet::list_rows(c).ok_or_else(|| self.wrong(column, c, expected))?;
        rows.into_iter()
            .map(|row| {
                row.map(|v| decode(&v).ok_or_else(|| self.wrong(column, c, expected)))
                    .transpose()
            })
            .collect()
    }

    /// A list of flag lists per row (`composed_parts`).
    pub fn bool_list_lists(&self, column: Column) -> Result<Vec<Vec<Vec<bool>>>, DatasetError> {
        let expected = "a list of lists of Boolean";
        let Some(c) = self.batch.column_by_name(column.name()) else {
            return Ok(vec![Vec::new(); self.batch.num_rows()]);
        };
        let rows =
            crate::io::parquet::list_rows(c).ok_or_else(|| self.wrong(column, c, expected))?;
        rows.into_iter()
            .map(|row| {
                let Some(inner) = row else {
                    return Ok(Vec::new());
                };
                let inner = crate::io::parquet::list_rows(&inner)
                    .ok_or_else(|| self.wrong(column, c, expected))?;
                inner
                    .into_iter()
                    .map(|v| {
                        v.as_ref()
                            .and_then(|v| v.as_boolean_opt())
                            .map(|b| b.iter().map(|x| x.unwrap_or(false)).collect())
                            .ok_or_else(|| self.wrong(column, c, expected))
                    })
                    .collect()
            })
            .collect()
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

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_array::{DictionaryArray, Float32Array, Int64Array, LargeStringArray, StringArray};

    #[test]
    fn columns_written_by_other_tools_decode_and_a_missing_one_is_named() {
        let split: DictionaryArray<Int32Type> = vec![Some("train"), None].into_iter().collect();
        let batch = RecordBatch::try_from_iter([
            (
                "clip_id",
                Arc::new(LargeStringArray::from(vec!["a", "b"])) as ArrayRef,
            ),
            ("split", Arc::new(split) as ArrayRef),
            (
                "fps",
                Arc::new(Float32Array::from(vec![30.0, 20.0])) as ArrayRef,
            ),
            (
                "num_frames",
                Arc::new(Int64Array::from(vec![Some(5), None])) as ArrayRef,
            ),
        ])
        .unwrap();
        let dir = std::env::temp_dir().join(format!("mf-table-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.parquet");
        let mut writer = parquet::arrow::ArrowWriter::try_new(
            std::fs::File::create(&path).unwrap(),
            batch.schema(),
            None,
        )
        .unwrap();
        writer.write(&batch).unwrap();
        writer.close().unwrap();
        let shard = OpenShard::open(&path).unwrap();
        let columns = [
            Column::ClipId,
            Column::Split,
            Column::Fps,
            Column::NumFrames,
        ];
        let batches: Vec<ShardBatch> = shard
            .read(&columns)
            .require(&columns)
            .batches()
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let b = &batches[0];
        assert_eq!(
            b.strings(Column::ClipId).unwrap(),
            [Some("a".into()), Some("b".into())]
        );
        assert_eq!(
            b.strings(Column::Split).unwrap(),
            [Some("train".into()), None]
        );
        assert_eq!(b.floats(Column::Fps).unwrap(), [Some(30.0), Some(20.0)]);
        assert_eq!(b.ints(Column::NumFrames).unwrap(), [Some(5), None]);
        // Absent columns read as nulls unless required.
        assert_eq!(b.strings(Column::MotionType).unwrap(), [None, None]);
        assert!(matches!(
            b.bools(Column::ClipId),
            Err(DatasetError::ColumnType {
                column: "clip_id",
                ..
            })
        ));
        let missing = shard
            .read(&[Column::ClipId])
            .require(&[Column::Mirrored])
            .batches();
        let e = missing.err().unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(
            matches!(
                &e,
                DatasetError::MissingColumn {
                    column: "mirrored",
                    ..
                }
            ),
            "{e}"
        );
    }

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
