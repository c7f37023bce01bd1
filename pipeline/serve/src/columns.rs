//! The browser's column view of a dataset's whole clip table, as the Hugging Face dataset viewer
//! shows one: every column of the shards with its statistics, and the rows a page at a time.
//!
//! Both read the shards a snapshot opened, never more than a batch of rows at once, and the
//! per-frame arrays (`joint_positions`, ...) not at all: those are described by their shape
//! (`frames × joints × 3`, from each row's `num_frames` and `num_joints`). Statistics are
//! counted once per version of the dataset, in accumulators of a fixed size: numbers keep their
//! minimum, maximum and sum; strings and booleans their values up to [`MAX_DISTINCT`] distinct
//! ones (then the distinct count is a lower bound and no top values are given); lists their
//! lengths.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};

use arrow_array::cast::AsArray;
use arrow_array::types::{
    Float32Type, Float64Type, Int8Type, Int16Type, Int32Type, Int64Type, UInt8Type, UInt16Type,
    UInt32Type, UInt64Type,
};
use arrow_array::{Array, RecordBatch};
use arrow_schema::{DataType, SchemaRef};
use serde_json::{Map, Value, json};

use motionforge_format::dataset::{ClipInfo, OpenShard};
use motionforge_format::io::schema::{FrameShape, frame_shape};

/// Distinct values of a string or boolean column counted before its count becomes a lower bound.
pub(crate) const MAX_DISTINCT: usize = 1000;
/// Top values given per column.
const TOP_VALUES: usize = 5;
/// Characters of a value a statistic or a cell shows.
const MAX_VALUE_CHARS: usize = 200;
/// Items of a list a cell shows.
const MAX_LIST_ITEMS: usize = 12;
/// Rows decoded at once.
const BATCH_ROWS: usize = 256;
/// Most rows one page of the column view holds.
pub(crate) const MAX_ROWS: usize = 100;

/// Why a shard's columns cannot be read.
pub(crate) type ReadError = String;

/// The columns of the table: the first shard's schema (the builds write one schema).
fn table_schema(shards: &[OpenShard]) -> Result<Option<SchemaRef>, ReadError> {
    let Some(first) = shards.first() else {
        return Ok(None);
    };
    first.schema().map(Some).map_err(|e| e.to_string())
}

/// Reads the columns of `shard` named in `names` that are not per-frame arrays, the rows
/// `first..first + count` of it (all without them), a batch at a time.
fn batches(
    shard: &OpenShard,
    names: &[String],
    rows: Option<(usize, usize)>,
) -> Result<impl Iterator<Item = Result<RecordBatch, ReadError>> + use<>, ReadError> {
    let mut read = shard
        .read_named(names.iter().filter(|n| frame_shape(n).is_none()))
        .batch_rows(BATCH_ROWS);
    if let Some((first, count)) = rows {
        read = read.rows(first, count);
    }
    let batches = read.batches().map_err(|e| e.to_string())?;
    Ok(batches.map(|b| {
        b.map(|b| b.record_batch().clone())
            .map_err(|e| e.to_string())
    }))
}

/// The range and mean of a number column's finite values, and how many are not finite.
struct Numbers {
    min: f64,
    max: f64,
    sum: f64,
    finite: u64,
    non_finite: u64,
}

impl Numbers {
    fn new() -> Self {
        Numbers {
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            sum: 0.0,
            finite: 0,
            non_finite: 0,
        }
    }

    /// Counts one non-null value (`None`: not readable as a number).
    fn add(&mut self, value: Option<f64>) {
        match value {
            Some(v) if v.is_finite() => {
                self.min = self.min.min(v);
                self.max = self.max.max(v);
                self.sum += v;
                self.finite += 1;
            }
            _ => self.non_finite += 1,
        }
    }

    fn json(&self) -> Value {
        let Numbers {
            min,
            max,
            sum,
            finite,
            non_finite,
        } = self;
        if *finite > 0 {
            json!({ "min": min, "max": max, "mean": sum / *finite as f64,
                    "non_finite": non_finite })
        } else {
            json!({ "min": null, "max": null, "mean": null, "non_finite": non_finite })
        }
    }
}

/// What is counted of one column.
enum Tally {
    /// Integers and floats: finite values only.
    Number(Numbers),
    /// Strings and booleans: each value's count (by a hash of it; the first spelling shown).
    Values {
        counts: HashMap<u64, (String, u64)>,
        capped: bool,
        lengths: Lengths,
    },
    /// Lists: their lengths.
    List(Lengths),
    /// Per-frame arrays: not read.
    Frames(FrameShape),
    /// Anything else (structs): counted and null-counted only.
    Other,
}

#[derive(Default)]
struct Lengths {
    min: Option<u64>,
    max: u64,
    sum: u64,
}

impl Lengths {
    fn add(&mut self, n: u64) {
        self.min = Some(self.min.map_or(n, |m| m.min(n)));
        self.max = self.max.max(n);
        self.sum += n;
    }

    fn json(&self, count: u64) -> Value {
        match self.min {
            Some(min) if count > 0 => {
                json!({ "min": min, "max": self.max, "mean": self.sum as f64 / count as f64 })
            }
            _ => Value::Null,
        }
    }
}

struct ColumnTally {
    name: String,
    data_type: String,
    count: u64,
    nulls: u64,
    tally: Tally,
}

fn tally_for(name: &str, data_type: &DataType) -> Tally {
    if let Some(shape) = frame_shape(name) {
        return Tally::Frames(shape);
    }
    match data_type {
        t if number_type(t) => Tally::Number(Numbers::new()),
        DataType::Utf8 | DataType::LargeUtf8 | DataType::Utf8View | DataType::Boolean => {
            Tally::Values {
                counts: HashMap::new(),
                capped: false,
                lengths: Lengths::default(),
            }
        }
        DataType::List(_) | DataType::LargeList(_) | DataType::FixedSizeList(..) => {
            Tally::List(Lengths::default())
        }
        _ => Tally::Other,
    }
}

fn number_type(t: &DataType) -> bool {
    matches!(
        t,
        DataType::Int8
            | DataType::Int16
            | DataType::Int32
            | DataType::Int64
            | DataType::UInt8
            | DataType::UInt16
            | DataType::UInt32
            | DataType::UInt64
            | DataType::Float32
            | DataType::Float64
    )
}

/// Row `i` of a number column as f64.
fn number(a: &dyn Array, i: usize) -> Option<f64> {
    macro_rules! of {
        ($t:ty) => {
            a.as_primitive_opt::<$t>().map(|p| p.value(i) as f64)
        };
    }
    match a.data_type() {
        DataType::Int8 => of!(Int8Type),
        DataType::Int16 => of!(Int16Type),
        DataType::Int32 => of!(Int32Type),
        DataType::Int64 => of!(Int64Type),
        DataType::UInt8 => of!(UInt8Type),
        DataType::UInt16 => of!(UInt16Type),
        DataType::UInt32 => of!(UInt32Type),
        DataType::UInt64 => of!(UInt64Type),
        DataType::Float32 => a
            .as_primitive_opt::<Float32Type>()
            .map(|p| f64::from(p.value(i))),
        DataType::Float64 => a.as_primitive_opt::<Float64Type>().map(|p| p.value(i)),
        _ => None,
    }
}

/// Row `i` of a string or boolean column as text.
fn text(a: &dyn Array, i: usize) -> Option<String> {
    match a.data_type() {
        DataType::Utf8 => a.as_string_opt::<i32>().map(|s| s.value(i).to_string()),
        DataType::LargeUtf8 => a.as_string_opt::<i64>().map(|s| s.value(i).to_string()),
        DataType::Utf8View => a.as_string_view_opt().map(|s| s.value(i).to_string()),
        DataType::Boolean => a.as_boolean_opt().map(|b| b.value(i).to_string()),
        _ => None,
    }
}

/// Row `i` of a list column's length.
fn list_len(a: &dyn Array, i: usize) -> Option<u64> {
    match a.data_type() {
        DataType::List(_) => a.as_list_opt::<i32>().map(|l| l.value_length(i) as u64),
        DataType::LargeList(_) => a.as_list_opt::<i64>().map(|l| l.value_length(i) as u64),
        DataType::FixedSizeList(..) => a.as_fixed_size_list_opt().map(|l| l.value_length() as u64),
        _ => None,
    }
}

fn cut(text: &str) -> String {
    super::public::excerpt_of(text, MAX_VALUE_CHARS).into_owned()
}

impl ColumnTally {
    fn add(&mut self, a: &dyn Array) {
        for i in 0..a.len() {
            if a.is_null(i) {
                self.nulls += 1;
                continue;
            }
            self.count += 1;
            match &mut self.tally {
                Tally::Number(numbers) => numbers.add(number(a, i)),
                Tally::Values {
                    counts,
                    capped,
                    lengths,
                } => {
                    let Some(value) = text(a, i) else { continue };
                    lengths.add(value.chars().count() as u64);
                    let mut hasher = std::collections::hash_map::DefaultHasher::new();
                    value.hash(&mut hasher);
                    let key = hasher.finish();
                    let full = counts.len() >= MAX_DISTINCT;
                    match counts.get_mut(&key) {
                        Some((_, n)) => *n += 1,
                        None if !full => {
                            counts.insert(key, (cut(&value), 1));
                        }
                        None => *capped = true,
                    }
                }
                Tally::List(lengths) => {
                    if let Some(n) = list_len(a, i) {
                        lengths.add(n);
                    }
                }
                Tally::Frames(_) | Tally::Other => {}
            }
        }
    }

    fn json(&self, rows: u64) -> Value {
        let mut out = json!({ "name": self.name, "type": self.data_type });
        let (kind, extra) = match &self.tally {
            Tally::Number(numbers) => ("number", numbers.json()),
            Tally::Values {
                counts,
                capped,
                lengths,
            } => {
                let mut top: Vec<&(String, u64)> = counts.values().collect();
                top.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
                let top: Vec<Value> = if *capped {
                    Vec::new()
                } else {
                    top.iter()
                        .take(TOP_VALUES)
                        .map(|(v, n)| json!({ "value": v, "count": n }))
                        .collect()
                };
                (
                    if self.data_type == "Boolean" {
                        "bool"
                    } else {
                        "string"
                    },
                    json!({ "distinct": counts.len(), "distinct_at_least": capped,
                            "top": top, "length": lengths.json(self.count) }),
                )
            }
            Tally::List(lengths) => ("list", json!({ "length": lengths.json(self.count) })),
            Tally::Frames(shape) => ("frames", json!({ "shape": shape_text(shape, None) })),
            Tally::Other => ("other", json!({})),
        };
        out["kind"] = json!(kind);
        if let Tally::Frames(_) = self.tally {
            // Not read: every row has its frames.
            out["count"] = json!(rows);
            out["nulls"] = Value::Null;
        } else {
            out["count"] = json!(self.count);
            out["nulls"] = json!(self.nulls);
        }
        if let (Some(o), Value::Object(e)) = (out.as_object_mut(), extra) {
            o.extend(e);
        }
        out
    }
}

/// A per-frame array's shape: `frames × joints × 3`, with the counts of a row when given.
fn shape_text(shape: &FrameShape, row: Option<&ClipInfo>) -> String {
    let mut dims = vec![row.map_or("frames".to_string(), |r| r.frames.to_string())];
    if shape.per_joint {
        dims.push(row.map_or("joints".to_string(), |r| r.joints.to_string()));
    }
    dims.extend(shape.inner.iter().map(i32::to_string));
    dims.join(" × ")
}

/// Every column's statistics over every row of `shards` (`rows` rows in all), as JSON.
pub(crate) fn statistics(shards: &[OpenShard], rows: usize) -> Result<Vec<u8>, ReadError> {
    let Some(schema) = table_schema(shards)? else {
        return Ok(b"{\"rows\":0,\"columns\":[]}".to_vec());
    };
    let mut tallies: Vec<ColumnTally> = schema
        .fields()
        .iter()
        .map(|f| ColumnTally {
            name: f.name().clone(),
            data_type: f.data_type().to_string(),
            count: 0,
            nulls: 0,
            tally: tally_for(f.name(), f.data_type()),
        })
        .collect();
    let names: Vec<String> = tallies.iter().map(|t| t.name.clone()).collect();
    for shard in shards {
        for batch in batches(shard, &names, None)? {
            let batch = batch?;
            for t in &mut tallies {
                if let Tally::Frames(_) = t.tally {
                    continue;
                }
                match batch.column_by_name(&t.name) {
                    Some(column) => t.add(column.as_ref()),
                    // A shard without the column: its rows are nulls there.
                    None => t.nulls += batch.num_rows() as u64,
                }
            }
        }
    }
    let columns: Vec<Value> = tallies.iter().map(|t| t.json(rows as u64)).collect();
    serde_json::to_vec(&json!({ "rows": rows, "columns": columns })).map_err(|e| e.to_string())
}

/// Row `i` of `a` as a JSON value: lists cut at [`MAX_LIST_ITEMS`], text at [`MAX_VALUE_CHARS`].
fn cell(a: &dyn Array, i: usize) -> Value {
    if a.is_null(i) {
        return Value::Null;
    }
    let list = |items: &dyn Array| {
        let mut out: Vec<Value> = (0..items.len().min(MAX_LIST_ITEMS))
            .map(|k| cell(items, k))
            .collect();
        if items.len() > MAX_LIST_ITEMS {
            out.push(json!(format!("… {} more", items.len() - MAX_LIST_ITEMS)));
        }
        Value::Array(out)
    };
    match a.data_type() {
        DataType::Boolean => a
            .as_boolean_opt()
            .map_or(Value::Null, |b| json!(b.value(i))),
        t if number_type(t) => match number(a, i) {
            Some(v) if v.is_finite() => match t {
                DataType::Float32 | DataType::Float64 => json!(v),
                _ => json!(v as i64),
            },
            _ => Value::Null,
        },
        DataType::Utf8 | DataType::LargeUtf8 | DataType::Utf8View => {
            text(a, i).map_or(Value::Null, |s| json!(cut(&s)))
        }
        DataType::List(_) => a
            .as_list_opt::<i32>()
            .map_or(Value::Null, |l| list(l.value(i).as_ref())),
        DataType::LargeList(_) => a
            .as_list_opt::<i64>()
            .map_or(Value::Null, |l| list(l.value(i).as_ref())),
        DataType::FixedSizeList(..) => a
            .as_fixed_size_list_opt()
            .map_or(Value::Null, |l| list(l.value(i).as_ref())),
        DataType::Struct(_) => a.as_struct_opt().map_or(Value::Null, |s| {
            let fields: Map<String, Value> = s
                .column_names()
                .iter()
                .zip(s.columns())
                .map(|(name, c)| (name.to_string(), cell(c.as_ref(), i)))
                .collect();
            Value::Object(fields)
        }),
        other => json!(format!("({other})")),
    }
}

/// The rows `offset..offset + limit` of the table: `places[r]` is row `r`'s shard and row in it,
/// `clips[r]` its metadata (for the shapes of its per-frame arrays).
pub(crate) fn page(
    shards: &[OpenShard],
    places: &[(usize, usize)],
    clips: &[ClipInfo],
    offset: usize,
    limit: usize,
) -> Result<Value, ReadError> {
    let Some(schema) = table_schema(shards)? else {
        return Ok(json!({ "total": 0, "columns": [], "rows": [] }));
    };
    let names: Vec<String> = schema.fields().iter().map(|f| f.name().clone()).collect();
    let end = offset.saturating_add(limit).min(places.len());
    let mut rows: Vec<Value> = Vec::new();
    let mut r = offset;
    while r < end {
        // The run of rows in one shard, consecutive in it.
        let (shard, first) = places[r];
        let mut n = 1;
        while r + n < end && places[r + n] == (shard, first + n) {
            n += 1;
        }
        let Some(open) = shards.get(shard) else {
            return Err(format!("row {r}: no shard {shard}"));
        };
        let mut k = r;
        for batch in batches(open, &names, Some((first, n)))? {
            let batch = batch?;
            for i in 0..batch.num_rows() {
                let info = clips.get(k);
                let cells: Vec<Value> = names
                    .iter()
                    .map(|name| match frame_shape(name) {
                        Some(shape) => json!(shape_text(&shape, info)),
                        None => batch
                            .column_by_name(name)
                            .map_or(Value::Null, |c| cell(c.as_ref(), i)),
                    })
                    .collect();
                rows.push(Value::Array(cells));
                k += 1;
            }
        }
        r += n;
    }
    Ok(json!({ "total": places.len(), "columns": names, "rows": rows }))
}
