//! A persistent LLM response cache: an append-only JSON Lines file that survives a crash mid-write.
//!
//! Every answer is one line, appended with a single `write_all` and made durable with `sync_data`
//! before it counts as cached. A crash can therefore leave at most one incomplete last line; `open`
//! drops (and counts) it and truncates the file back to its last complete line, so appends never
//! glue a new record onto a torn one.

use std::collections::HashMap;
use std::fs::{self, File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::client::{RequestKind, SamplingParams};
use motionforge_core::base::hex;
use motionforge_core::base::sha256_hex;

/// Characters of the prompt kept in each record, so a human can tell entries apart.
const PREVIEW_CHARS: usize = 120;

/// Bumped when the key derivation changes, so old entries stop matching instead of being misread.
const KEY_VERSION: &str = "motionforge-llm-cache-v1";

/// Errors of the response cache: always name the file.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// An I/O error on the cache file.
    #[error("{path}: {source}")]
    Io {
        /// The cache file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A record could not be encoded as JSON.
    #[error("{path}: cannot encode cache record: {source}")]
    Encode {
        /// The cache file.
        path: PathBuf,
        /// The encoder's error.
        source: serde_json::Error,
    },
}

/// The cache key of one request: hex SHA-256 over the model, the endpoint kind, the rendered
/// prompt and the sampling parameters, each length-prefixed so concatenations cannot collide.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct CacheKey(String);

impl CacheKey {
    /// The key of a request. The server address is deliberately not part of it: the same model
    /// served elsewhere (a local vLLM instead of a remote one) reuses the answers.
    pub fn new(model: &str, kind: RequestKind, prompt: &str, params: &SamplingParams) -> CacheKey {
        let mut h = Sha256::new();
        let mut field = |s: &str| {
            h.update((s.len() as u64).to_le_bytes());
            h.update(s.as_bytes());
        };
        field(KEY_VERSION);
        field(model);
        field(kind.as_str());
        field(prompt);
        // -0.0 and 0.0 sample identically; Display is the shortest text that reads back exactly.
        let temperature = if params.temperature == 0.0 {
            0.0
        } else {
            params.temperature
        };
        field(&temperature.to_string());
        field(&params.max_tokens.to_string());
        // "-" cannot be a decimal seed, so "no seed" never collides with a seed.
        field(
            &params
                .seed
                .map_or_else(|| "-".to_string(), |s| s.to_string()),
        );
        CacheKey(hex(&h.finalize()))
    }

    /// The hex digest.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Display for CacheKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// One cached answer with what produced it. The prompt itself is not stored, only its digest and
/// a short preview.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CacheEntry {
    /// The model name as sent to the server.
    pub model: String,
    /// Chat or completion endpoint.
    pub kind: RequestKind,
    /// The sampling parameters of the request.
    pub params: SamplingParams,
    /// Hex SHA-256 of the rendered prompt.
    pub prompt_sha256: String,
    /// The first characters of the prompt, for people reading the file.
    #[serde(default)]
    pub prompt_preview: String,
    /// The answer text.
    pub response: String,
    /// Where the answer came from: `llm`, or `import:<file>` for answers imported from elsewhere.
    pub source: String,
    /// Why the server stopped (`stop`, or `unreported` when it did not say). Absent in entries of
    /// versions that did not record it; such `llm` entries may be cut-off answers and are asked
    /// again when a server is available (see [`CacheEntry::is_settled`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub finish_reason: Option<String>,
}

impl CacheEntry {
    /// An entry for `response` to `prompt`, filling in the digest and preview.
    pub fn new(
        model: &str,
        kind: RequestKind,
        prompt: &str,
        params: &SamplingParams,
        response: String,
        source: &str,
    ) -> CacheEntry {
        CacheEntry {
            model: model.to_string(),
            kind,
            params: *params,
            prompt_sha256: sha256_hex(prompt.as_bytes()),
            prompt_preview: prompt.chars().take(PREVIEW_CHARS).collect(),
            response,
            source: source.to_string(),
            finish_reason: None,
        }
    }

    /// True when the answer was cut off by the token limit (`finish_reason` `length`).
    pub fn is_truncated(&self) -> bool {
        matches!(self.finish_reason.as_deref(), Some("length" | "max_tokens"))
    }

    /// True when the entry is a final answer a build may use without asking again: fetched with
    /// its finish reason recorded and not cut off, or imported. An `llm` entry without a finish
    /// reason comes from a version that cached cut-off answers as good; online builds ask it again.
    pub fn is_settled(&self) -> bool {
        if self.is_truncated() {
            return false;
        }
        self.finish_reason.is_some() || self.source != "llm"
    }
}

/// A record as written: the key first, so `grep` on a key finds its line.
#[derive(Serialize)]
struct RecordOut<'a> {
    key: &'a str,
    #[serde(flatten)]
    entry: &'a CacheEntry,
}

#[derive(Deserialize)]
struct RecordIn {
    key: String,
    #[serde(flatten)]
    entry: CacheEntry,
}

/// The response cache: all entries in memory, backed by the JSON Lines file. Later records for a
/// key win. One writer at a time: two processes appending to the same file are not coordinated.
#[derive(Debug)]
pub struct ResponseCache {
    path: PathBuf,
    file: File,
    /// Bytes of complete records in the file; a failed append is truncated back to this.
    len_bytes: u64,
    entries: HashMap<String, CacheEntry>,
    recovered_partial_lines: usize,
    corrupt_lines: usize,
}

impl ResponseCache {
    /// Opens (or creates, with its parent folders) the cache file and loads every complete record.
    /// An incomplete last line, the trace of a crash mid-append, is dropped and truncated away; if
    /// it turns out to be a whole record missing only its newline, it is kept and the newline added.
    pub fn open(path: &Path) -> Result<ResponseCache, CacheError> {
        let io = |source| CacheError::Io {
            path: path.to_path_buf(),
            source,
        };
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
        if let Some(dir) = dir {
            fs::create_dir_all(dir).map_err(|source| CacheError::Io {
                path: dir.to_path_buf(),
                source,
            })?;
        }
        let existed = path.exists();
        let mut file = OpenOptions::new()
            .read(true)
            .append(true)
            .create(true)
            .open(path)
            .map_err(io)?;
        if !existed {
            // Make the new file's directory entry durable too; best effort, as in `write_atomic`.
            if let Ok(d) = File::open(dir.unwrap_or(Path::new("."))) {
                let _ = d.sync_all();
            }
        }
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io)?;

        let complete = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        let mut entries = HashMap::new();
        let mut corrupt_lines = 0;
        for line in bytes[..complete].split(|&b| b == b'\n') {
            if line.iter().all(u8::is_ascii_whitespace) {
                continue;
            }
            match serde_json::from_slice::<RecordIn>(line) {
                Ok(r) => {
                    entries.insert(r.key, r.entry);
                }
                // A complete but unreadable line cannot come from a crash of this writer; it is
                // skipped, counted and left in place rather than destroyed.
                Err(_) => corrupt_lines += 1,
            }
        }

        let mut len_bytes = bytes.len() as u64;
        let mut recovered_partial_lines = 0;
        let tail = &bytes[complete..];
        if !tail.is_empty() {
            match serde_json::from_slice::<RecordIn>(tail) {
                Ok(r) => {
                    entries.insert(r.key, r.entry);
                    file.write_all(b"\n").map_err(io)?;
                    file.sync_data().map_err(io)?;
                    len_bytes += 1;
                }
                Err(_) => {
                    recovered_partial_lines = 1;
                    file.set_len(complete as u64).map_err(io)?;
                    file.sync_all().map_err(io)?;
                    len_bytes = complete as u64;
                }
            }
        }

        Ok(ResponseCache {
            path: path.to_path_buf(),
            file,
            len_bytes,
            entries,
            recovered_partial_lines,
            corrupt_lines,
        })
    }

    /// The cached answer for a key, unless it was cut off by the token limit (offline builds use
    /// it; online ones also ask again answers that are not [settled](CacheEntry::is_settled)).
    pub fn get(&self, key: &CacheKey) -> Option<&str> {
        self.get_entry(key).map(|e| e.response.as_str())
    }

    /// The whole cached entry for a key, unless it was cut off by the token limit.
    pub fn get_entry(&self, key: &CacheKey) -> Option<&CacheEntry> {
        self.entries.get(&key.0).filter(|e| !e.is_truncated())
    }

    /// Appends an entry and syncs it to disk before it becomes visible; it replaces any earlier
    /// entry for the key. On failure nothing changes, in memory or (as far as the OS allows) on disk.
    pub fn insert(&mut self, key: CacheKey, entry: CacheEntry) -> Result<(), CacheError> {
        self.insert_many(vec![(key, entry)])
    }

    /// Appends many entries with one write and one sync (imports of thousands of answers would
    /// otherwise spend seconds in fsync). All or nothing, like [`ResponseCache::insert`].
    pub fn insert_many(&mut self, entries: Vec<(CacheKey, CacheEntry)>) -> Result<(), CacheError> {
        let mut buffer = Vec::new();
        for (key, entry) in &entries {
            serde_json::to_writer(&mut buffer, &RecordOut { key: &key.0, entry }).map_err(
                |source| CacheError::Encode {
                    path: self.path.clone(),
                    source,
                },
            )?;
            buffer.push(b'\n');
        }
        let written = self
            .file
            .write_all(&buffer)
            .and_then(|()| self.file.sync_data());
        if let Err(source) = written {
            let _ = self.file.set_len(self.len_bytes);
            return Err(CacheError::Io {
                path: self.path.clone(),
                source,
            });
        }
        self.len_bytes += buffer.len() as u64;
        for (key, entry) in entries {
            self.entries.insert(key.0, entry);
        }
        Ok(())
    }

    /// Number of distinct keys cached.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether nothing is cached.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Incomplete last lines dropped by `open` (0 or 1): an append interrupted by a crash.
    pub fn recovered_partial_lines(&self) -> usize {
        self.recovered_partial_lines
    }

    /// Complete lines that `open` could not read and skipped (left in the file untouched).
    pub fn corrupt_lines(&self) -> usize {
        self.corrupt_lines
    }

    /// The cache file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}
