//! The names of a dataset folder's files, shared by the writer and every reader.

/// Folder of the Parquet shards inside the dataset folder (`<split>-NNNNN-of-NNNNN.parquet`).
pub const DATA_DIR: &str = "data";
/// Normalisation statistics (mean/std per feature over the training split).
pub const NORMALIZATION_DIR: &str = "normalization";
/// Shard list, checksums, counts and provenance.
pub const MANIFEST_FILE: &str = "manifest.json";
/// Dataset card (Hugging Face style, YAML front matter).
pub const CARD_FILE: &str = "README.md";
/// Skeleton descriptions beside the table.
pub const SKELETONS_FILE: &str = "skeletons.json";
/// One JSON object per rejected input.
pub const REJECTS_FILE: &str = "rejects.jsonl";
/// What the last build did.
pub const REPORT_FILE: &str = "build-report.json";
/// Task plans, one row per step.
pub const PLANS_FILE: &str = "plans.parquet";
/// The report's statistics, inside the dataset folder.
pub const REPORT_STATS: &str = "report/stats.json";
/// The LLM response cache's default place inside the dataset folder (`[llm] cache`).
pub const LLM_CACHE_FILE: &str = "llm-cache.jsonl";
