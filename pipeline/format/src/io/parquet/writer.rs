//! The shard file: the writer's properties, row groups encoded column by column and group by
//! group on the build's threads, and the small tables written beside the shards (task plans).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::sync::Arc;

use arrow_array::{Int32Array, RecordBatch, StringArray};
use arrow_schema::{DataType, Field, SchemaRef};
use parquet::arrow::ArrowWriter;
use parquet::arrow::arrow_writer::{
    ArrowColumnChunk, ArrowLeafColumn, ArrowRowGroupWriterFactory, compute_leaves,
};
use parquet::basic::{Compression, ZstdLevel};
use parquet::errors::ParquetError;
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;

use super::{Row, TableError, rows_to_batch};
use crate::io::schema::{SCHEMA_VERSION, clip_schema};
use motionforge_core::features::FeatureConfig;
use motionforge_core::motion::Profile;
use motionforge_sources::clip::LoadedClip;

/// Every float leaf column of `schema` encoded BYTE_STREAM_SPLIT, without a dictionary, and
/// without statistics when it is a list (per-frame values). Motion
/// floats are nearly unique, so dictionaries only cost time; splitting each value's bytes into
/// separate streams puts the slowly varying exponent and high mantissa bytes together, where zstd
/// finds the redundancy that plain encoding hides (`docs/decisions.md`, "Float encoding").
fn float_encoding(
    schema: &arrow_schema::Schema,
    mut props: parquet::file::properties::WriterPropertiesBuilder,
) -> Result<parquet::file::properties::WriterPropertiesBuilder, ParquetError> {
    let descriptor = parquet::arrow::ArrowSchemaConverter::new().convert(schema)?;
    for column in descriptor.columns() {
        if matches!(
            column.physical_type(),
            parquet::basic::Type::FLOAT | parquet::basic::Type::DOUBLE
        ) {
            let path = column.path().clone();
            // Min and max of a list of frames select nothing (no reader filters on them) and
            // cost a pass over every value; scalar floats (metrics) keep theirs.
            if column.max_rep_level() > 0 {
                props = props.set_column_statistics_enabled(
                    path.clone(),
                    parquet::file::properties::EnabledStatistics::None,
                );
            }
            props = props
                .set_column_dictionary_enabled(path.clone(), false)
                .set_column_encoding(path, parquet::basic::Encoding::BYTE_STREAM_SPLIT);
        }
    }
    Ok(props)
}

/// The zstd level of the shards unless `dataset.zstd_level` says otherwise: level 1 writes the
/// motion columns 30% faster than level 3 for 5-7% more bytes (`docs/decisions.md`).
pub const DEFAULT_ZSTD_LEVEL: i32 = 1;

/// Largest data page before compression. A row group's per-frame column is a few MB, which
/// parquet's default (1 MB) cut into several pages, each compressed on its own: one page per
/// column chunk writes faster and compresses a little better (`docs/decisions.md`, "Shard
/// writer: no statistics on frame lists, 8 MB pages").
pub const PAGE_BYTES: usize = 8 * 1024 * 1024;

/// Clips per row group: large enough for efficient scans, small enough that one group's buffers
/// stay a few tens of MB for long captures.
pub const ROWS_PER_GROUP: usize = 64;

/// The writer properties of a shard, compressed with zstd at `zstd_level` (1 to 22): float
/// columns BYTE_STREAM_SPLIT without a dictionary (and without statistics when per-frame),
/// [`PAGE_BYTES`] pages, [`ROWS_PER_GROUP`] rows per group, and the schema version and the
/// skeletons in the file's `key_value_metadata`, so the file describes itself. Public so that a
/// reference encoder (`bench --build`) writes with the same settings.
pub fn shard_properties(
    skeletons_json: &str,
    zstd_level: i32,
) -> Result<WriterProperties, TableError> {
    Ok(float_encoding(&clip_schema(), WriterProperties::builder())?
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(zstd_level)?))
        .set_max_row_group_row_count(Some(ROWS_PER_GROUP))
        .set_data_page_size_limit(PAGE_BYTES)
        .set_key_value_metadata(Some(vec![
            KeyValue::new(
                "motionforge.schema_version".to_string(),
                SCHEMA_VERSION.to_string(),
            ),
            KeyValue::new(
                "motionforge.skeletons".to_string(),
                skeletons_json.to_string(),
            ),
        ]))
        .build())
}

/// A shard of the clip table being written: one row group per [`ShardWriter::write`], with the
/// properties of [`shard_properties`]. Streams: only the row group being encoded is in memory.
///
/// A row group's leaf columns are encoded in parallel on the current rayon pool (arrow-rs's
/// `ArrowColumnWriter`s, one per leaf), then appended in schema order: the bytes are those
/// `ArrowWriter` writes encoding them one after the other, whatever the number of threads.
pub struct ShardWriter<W: Write + Send> {
    file: SerializedFileWriter<W>,
    columns: ArrowRowGroupWriterFactory,
    schema: SchemaRef,
}

impl<W: Write + Send> ShardWriter<W> {
    /// Starts a shard on `out`, compressed with zstd at `zstd_level` (1 to 22).
    pub fn new(
        out: W,
        skeletons_json: &str,
        zstd_level: i32,
    ) -> Result<ShardWriter<W>, TableError> {
        let props = shard_properties(skeletons_json, zstd_level)?;
        let schema = Arc::new(clip_schema());
        // ArrowWriter sets the file up (the Parquet schema, the embedded Arrow schema in the
        // key-value metadata) exactly as it would for itself; the row groups are then ours.
        let (file, columns) = ArrowWriter::try_new(out, Arc::clone(&schema), Some(props))?
            .into_serialized_writer()?;
        Ok(ShardWriter {
            file,
            columns,
            schema,
        })
    }

    /// Encodes `rows` (at most [`ROWS_PER_GROUP`]) as one row group.
    pub fn write(&mut self, rows: &[Row<'_>]) -> Result<(), TableError> {
        self.write_batch(&rows_to_batch(rows)?)
    }

    /// Encodes `batch` (from [`rows_to_batch`]) as row groups of at most [`ROWS_PER_GROUP`]
    /// rows, as `ArrowWriter` cuts it: the caller can let the rows go before the encoder's
    /// buffers grow.
    pub fn write_batch(&mut self, batch: &RecordBatch) -> Result<(), TableError> {
        self.write_batches(std::slice::from_ref(batch))
    }

    /// Encodes the batches as [`write_batch`](Self::write_batch) would one after the other, but
    /// every row group of them at once on the pool's threads (each group's leaves too); the
    /// groups are then appended in order, so the file is the same bytes.
    pub fn write_batches(&mut self, batches: &[RecordBatch]) -> Result<(), TableError> {
        use rayon::prelude::*;
        let groups: Vec<RecordBatch> = batches
            .iter()
            .flat_map(|batch| {
                (0..batch.num_rows())
                    .step_by(ROWS_PER_GROUP)
                    .map(|start| batch.slice(start, ROWS_PER_GROUP.min(batch.num_rows() - start)))
            })
            .collect();
        let first = self.file.flushed_row_groups().len();
        let (columns, schema) = (&self.columns, &self.schema);
        let encoded = groups
            .par_iter()
            .enumerate()
            .map(|(i, group)| encode_group(columns, schema, group, first + i))
            .collect::<Result<Vec<_>, TableError>>()?;
        drop(groups);
        for chunks in encoded {
            let mut group = self.file.next_row_group()?;
            for chunk in chunks {
                chunk.append_to_row_group(&mut group)?;
            }
            group.close()?;
        }
        Ok(())
    }

    /// Writes the footer and gives the output back.
    pub fn finish(self) -> Result<W, TableError> {
        Ok(self.file.into_inner()?)
    }
}

/// One row group's column chunks: the leaves' levels and the leaves' encoding (zstd included)
/// on all the pool's threads. `index` is the group's place in the file.
fn encode_group(
    columns: &ArrowRowGroupWriterFactory,
    schema: &SchemaRef,
    batch: &RecordBatch,
    index: usize,
) -> Result<Vec<ArrowColumnChunk>, TableError> {
    use rayon::prelude::*;
    let fields = schema.fields();
    if batch.num_columns() != fields.len() {
        return Err(ParquetError::General(format!(
            "a batch of {} columns for a table of {}",
            batch.num_columns(),
            fields.len()
        ))
        .into());
    }
    let writers = columns.create_column_writers(index)?;
    let leaves = fields
        .as_ref()
        .par_iter()
        .zip(batch.columns().par_iter())
        .map(|(field, column)| compute_leaves(field, column))
        .collect::<Result<Vec<Vec<ArrowLeafColumn>>, ParquetError>>()?;
    let leaves: Vec<ArrowLeafColumn> = leaves.into_iter().flatten().collect();
    if leaves.len() != writers.len() {
        return Err(ParquetError::General(format!(
            "{} leaf columns for {} column writers",
            leaves.len(),
            writers.len()
        ))
        .into());
    }
    Ok(writers
        .into_par_iter()
        .zip(leaves.par_iter())
        .map(|(mut writer, leaf)| {
            writer.write(leaf)?;
            writer.close()
        })
        .collect::<Result<Vec<ArrowColumnChunk>, ParquetError>>()?)
}

/// Streams clips with their frames into a Parquet file, one row group at a time, at the default
/// zstd level (see [`ShardWriter`]).
pub fn write_clips(
    file: File,
    clips: &[LoadedClip],
    profiles: &BTreeMap<String, Profile>,
    skeletons_json: &str,
    features: &FeatureConfig,
) -> Result<File, TableError> {
    let mut writer = ShardWriter::new(file, skeletons_json, DEFAULT_ZSTD_LEVEL)?;
    for chunk in clips.chunks(ROWS_PER_GROUP) {
        let rows = chunk
            .iter()
            .map(|c| Row::of_clip(c, profiles, features))
            .collect::<Result<Vec<_>, _>>()?;
        writer.write(&rows)?;
    }
    writer.finish()
}

/// Writes task plans, one row per step: `text`, `step_id`, `step`, `category`.
pub fn write_plans(
    file: File,
    plans: &BTreeMap<String, Vec<motionforge_llm::plans::PlanStep>>,
) -> Result<File, TableError> {
    let schema = Arc::new(arrow_schema::Schema::new(vec![
        Field::new("text", DataType::Utf8, false),
        Field::new("step_id", DataType::Int32, false),
        Field::new("step", DataType::Utf8, false),
        Field::new("category", DataType::Utf8, false),
    ]));
    let rows: Vec<(&String, &motionforge_llm::plans::PlanStep)> = plans
        .iter()
        .flat_map(|(t, steps)| steps.iter().map(move |s| (t, s)))
        .collect();
    let category = |s: &motionforge_llm::plans::PlanStep| match s.category {
        motionforge_llm::plans::StepCategory::Locomotion => "locomotion",
        motionforge_llm::plans::StepCategory::Grasp => "grasp",
        motionforge_llm::plans::StepCategory::Interaction => "interaction",
    };
    let batch = RecordBatch::try_new(
        Arc::clone(&schema),
        vec![
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|(t, _)| t.as_str()),
            )),
            Arc::new(Int32Array::from_iter_values(
                rows.iter().map(|(_, s)| s.step_id as i32),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|(_, s)| s.step.as_str()),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|(_, s)| category(s)),
            )),
        ],
    )?;
    let props = WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(3)?))
        .build();
    let mut writer = ArrowWriter::try_new(file, schema, Some(props))?;
    writer.write(&batch)?;
    Ok(writer.into_inner()?)
}
