//! The yardsticks `bench --build` measures a build against, each on one thread: a bare scan of
//! the BVH bytes into f64, arrow-rs re-encoding the finished shards with the shard writer's own
//! properties (the encode reference), the SHA-256 checksums the dataset records, and `bvhio`
//! reading the same files (issue 34).

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};

use super::bench::peak_rss_kb;
use super::bench_build::Input;
use super::bench_machine::{reset_peak_rss, thread_cpu_seconds};

/// `scripts/bvhio_reference.py`, carried in the binary so the bench runs from anywhere.
const BVHIO_REFERENCE: &str = include_str!("../../../../scripts/bvhio_reference.py");

// ---- the bare scan ---------------------------------------------------------------------------

/// The bare scan's best and range, and what it parsed.
pub(super) struct Scan {
    pub(super) seconds: Vec<f64>,
    /// This thread's CPU seconds of each pass.
    pub(super) cpu_seconds: Vec<f64>,
    /// This thread's CPU seconds hashing the same bytes (SHA-256, `copies` times over): the
    /// `source_sha256` every row carries, fastest pass.
    pub(super) digest_cpu_seconds: f64,
    pub(super) numbers: u64,
    pub(super) bytes: u64,
    pub(super) peak_rss_kb: Option<u64>,
}

/// Every file's text in memory (not timed), then on this thread: split on ASCII whitespace and
/// parse every token that parses as f64, `copies` times over, `repeat` times.
pub(super) fn scan(input: &Input, copies: usize, repeat: usize) -> Result<Scan> {
    reset_peak_rss();
    let texts: Vec<String> = input
        .files
        .iter()
        .map(|f| std::fs::read_to_string(f).with_context(|| format!("cannot read {}", f.display())))
        .collect::<Result<_>>()?;
    let mut seconds = Vec::new();
    let mut cpu_seconds = Vec::new();
    let mut numbers = 0u64;
    for _ in 0..repeat {
        let cpu0 = thread_cpu_seconds();
        let t0 = Instant::now();
        let (mut sum, mut count) = (0.0f64, 0u64);
        for _ in 0..copies {
            for text in &texts {
                for token in text.split_ascii_whitespace() {
                    if let Ok(v) = token.parse::<f64>() {
                        sum += v;
                        count += 1;
                    }
                }
            }
        }
        // The sum is used, so the parsing cannot be optimised away.
        std::hint::black_box(sum);
        seconds.push(t0.elapsed().as_secs_f64());
        cpu_seconds.push(thread_cpu_seconds() - cpu0);
        numbers = count;
    }
    let mut digest_cpu_seconds = f64::INFINITY;
    for _ in 0..repeat {
        let cpu0 = thread_cpu_seconds();
        for _ in 0..copies {
            for text in &texts {
                std::hint::black_box(motionforge::base::sha256_hex(text.as_bytes()));
            }
        }
        digest_cpu_seconds = digest_cpu_seconds.min(thread_cpu_seconds() - cpu0);
    }
    Ok(Scan {
        seconds,
        cpu_seconds,
        digest_cpu_seconds,
        numbers,
        bytes: texts.iter().map(|t| t.len() as u64).sum::<u64>() * copies as u64,
        peak_rss_kb: peak_rss_kb(),
    })
}

// ---- the encode reference ------------------------------------------------------------------

/// The encode reference: what arrow-rs's own writer spends encoding the table the build wrote.
pub(super) struct EncodeReference {
    /// Wall seconds of each pass (all shards).
    pub(super) seconds: Vec<f64>,
    /// This thread's CPU seconds of each pass.
    pub(super) cpu_seconds: Vec<f64>,
    pub(super) shards: usize,
    pub(super) rows: usize,
    /// Bytes one pass wrote.
    pub(super) bytes: u64,
    /// Whether every shard the reference wrote is byte for byte the build's.
    pub(super) identical: bool,
    /// This thread's CPU seconds hashing the shards (SHA-256, the manifest's checksums), fastest
    /// pass.
    pub(super) digest_cpu_seconds: f64,
}

/// Every finished shard read back into memory (not timed), then written again to memory by
/// arrow-rs's `ArrowWriter` in one thread, with the shard writer's own properties
/// ([`shard_properties`](motionforge::io::parquet::shard_properties): zstd at the dataset's
/// level, BYTE_STREAM_SPLIT floats without dictionary, no statistics on frame lists, 8 MB pages,
/// 64-row groups, the same key-value metadata); only the writes are timed, `repeat` times. One
/// shard is in memory at a time.
pub(super) fn encode_reference(
    data: &Path,
    zstd_level: i32,
    repeat: usize,
) -> Result<EncodeReference> {
    use parquet::arrow::ArrowWriter;
    let shards = motionforge::dataset::open_clip_tables(data)
        .with_context(|| format!("cannot list {}", data.display()))?;
    let mut reference = EncodeReference {
        seconds: vec![0.0; repeat],
        cpu_seconds: vec![0.0; repeat],
        shards: shards.len(),
        rows: 0,
        bytes: 0,
        identical: true,
        digest_cpu_seconds: 0.0,
    };
    for open in &shards {
        let file = open.path();
        let shard =
            std::fs::read(file).with_context(|| format!("cannot read {}", file.display()))?;
        let skeletons = open.key_value("motionforge.skeletons")?.unwrap_or_default();
        // The reader copies the file's key-value metadata into the Arrow schema; the writer
        // adds it back from the properties, so the schema the build wrote has none.
        let fields = open.schema()?.fields().clone();
        let schema = Arc::new(arrow_schema::Schema::new(fields.clone()));
        let batches = open
            .read_named(fields.iter().map(|f| f.name()))
            .batch_rows(motionforge::io::parquet::ROWS_PER_GROUP)
            .batches()?
            .map(|b| b.map(|b| b.record_batch().clone()))
            .collect::<Result<Vec<_>, _>>()
            .with_context(|| format!("cannot read {}", file.display()))?;
        reference.rows += batches.iter().map(|b| b.num_rows()).sum::<usize>();
        let props = motionforge::io::parquet::shard_properties(&skeletons, zstd_level)?;
        for pass in 0..repeat {
            // Room for the whole file up front, as a file's pages would not be copied again.
            let mut out = Vec::with_capacity(shard.len());
            let cpu0 = thread_cpu_seconds();
            let t0 = Instant::now();
            let mut writer =
                ArrowWriter::try_new(&mut out, Arc::clone(&schema), Some(props.clone()))?;
            for batch in &batches {
                writer.write(batch)?;
            }
            writer.close()?;
            reference.seconds[pass] += t0.elapsed().as_secs_f64();
            reference.cpu_seconds[pass] += thread_cpu_seconds() - cpu0;
            if pass == 0 {
                reference.bytes += out.len() as u64;
                reference.identical &= out[..] == shard[..];
            }
        }
        let mut digest = f64::INFINITY;
        for _ in 0..repeat {
            let cpu0 = thread_cpu_seconds();
            std::hint::black_box(motionforge::base::sha256_hex(&shard));
            digest = digest.min(thread_cpu_seconds() - cpu0);
        }
        reference.digest_cpu_seconds += digest;
    }
    Ok(reference)
}

// ---- the bvhio reference --------------------------------------------------------------------

/// What bvhio spent reading the folder and computing every joint's world position per frame.
pub(super) struct BvhioReference {
    pub(super) version: String,
    pub(super) files: u64,
    pub(super) frames: u64,
    pub(super) positions: u64,
    pub(super) wall_s: f64,
    pub(super) cpu_s: f64,
}

/// Runs `scripts/bvhio_reference.py` (embedded) over `dir` on one thread, from `work`.
pub(super) fn bvhio_reference(
    dir: &Path,
    python: Option<&Path>,
    work: &Path,
) -> Result<BvhioReference> {
    let python = super::bench_export::reference_python(python)?;
    let printed = super::bench_export::run_python_script(
        &python,
        work,
        "bvhio_reference.py",
        BVHIO_REFERENCE,
        &[dir.as_os_str()],
    )?;
    let value: serde_json::Value = serde_json::from_str(printed.trim())
        .with_context(|| format!("the bvhio reference printed {printed:?}"))?;
    let number = |key: &str| {
        value[key]
            .as_f64()
            .with_context(|| format!("no number `{key}` in the bvhio reference's {value}"))
    };
    Ok(BvhioReference {
        version: value["bvhio"].as_str().unwrap_or("?").to_string(),
        files: number("files")? as u64,
        frames: number("frames")? as u64,
        positions: number("positions")? as u64,
        wall_s: number("wall_s")?,
        cpu_s: number("cpu_s")?,
    })
}
