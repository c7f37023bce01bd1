//! The build workspace: the per-item stage cache and the ledger of what each stage last saw.

use std::fs;
use std::path::{Path, PathBuf};

use std::collections::BTreeMap;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

pub(crate) use motionforge_core::base::io_err;
use motionforge_core::base::{Stamp, WorkspaceError};

/// The file recording, per stage and item, the fingerprint of the last run.
pub const LEDGER_FILE: &str = "ledger.json";

/// The file recording which config file the dataset folder was last built from, so commands
/// given only the folder (`status <dataset>`) can find it.
pub const CONFIG_RECORD_FILE: &str = "config.json";

/// Which config file a dataset folder was last built from (`.motionforge/config.json`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ConfigRecord {
    /// The config file, absolute when the build could make it so.
    pub config: PathBuf,
}

impl ConfigRecord {
    /// The config the dataset in `dataset_dir` was last built from; `None` when no build
    /// recorded one (a folder built before builds recorded it, or not a dataset folder).
    pub fn load(dataset_dir: &Path) -> Option<PathBuf> {
        let bytes = fs::read(dataset_dir.join(".motionforge").join(CONFIG_RECORD_FILE)).ok()?;
        serde_json::from_slice::<ConfigRecord>(&bytes)
            .ok()
            .map(|r| r.config)
    }

    /// Records `config` as the file the dataset of `workspace` was built from (atomically).
    pub(crate) fn save(workspace: &Workspace, config: &Path) -> Result<(), WorkspaceError> {
        let record = ConfigRecord {
            config: std::path::absolute(config).unwrap_or_else(|_| config.to_path_buf()),
        };
        let json = serde_json::to_vec_pretty(&record).unwrap_or_default();
        motionforge_core::base::write_atomic(&workspace.root().join(CONFIG_RECORD_FILE), &json)
    }
}

/// What the last runs of each stage saw: per item, its [`Stamp`]; per stage, when and how much.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Ledger {
    /// By stage name.
    pub stages: BTreeMap<String, StageLedger>,
}

/// One stage's record in the [`Ledger`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StageLedger {
    /// When the stage last ran or was checked fresh (seconds since the Unix epoch).
    pub last_run: u64,
    /// Items covered then.
    pub items: usize,
    /// Items computed then.
    pub ran: usize,
    /// Items reused then.
    pub reused: usize,
    /// The stamp of each item (capture path, or `*` for stages over the whole set).
    pub entries: BTreeMap<String, Stamp>,
}

impl Ledger {
    /// The ledger of a workspace; empty when missing or unreadable (nothing is known, so every
    /// item counts as new).
    pub fn load(workspace: &Workspace) -> Ledger {
        fs::read(workspace.root().join(LEDGER_FILE))
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())
            .unwrap_or_default()
    }

    /// Why an item whose stamp is `now` is not in the cache, compared with the last run.
    pub fn why(&self, stage: &str, key: &str, now: &Stamp) -> crate::plan::StaleReason {
        use crate::plan::StaleReason;
        let Some(before) = self.stages.get(stage).and_then(|s| s.entries.get(key)) else {
            return StaleReason::New;
        };
        let changed: Vec<String> = now
            .parts
            .iter()
            .filter(|(name, digest)| before.parts.get(*name) != Some(*digest))
            .map(|(name, _)| name.clone())
            .chain(
                before
                    .parts
                    .keys()
                    .filter(|name| !now.parts.contains_key(*name))
                    .cloned(),
            )
            .collect();
        if changed.is_empty() {
            StaleReason::CacheEntryMissing
        } else {
            StaleReason::Changed(changed)
        }
    }
}

/// A stage item the probe found missing from the cache.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Miss {
    /// Stage name.
    pub stage: String,
    /// Item key.
    pub key: String,
    /// Its stamp now.
    pub stamp: Stamp,
}

/// Stamps per compressed block of [`SeenStamps`].
const SEEN_BLOCK: usize = 512;

/// Entries larger than this are encoded straight into their pack rather than into a buffer
/// first; smaller ones are encoded outside the packs' lock, so the cores do not wait on it.
const STREAMED_ENTRY: usize = 1 << 20;

/// The item stamps a run has seen, for the ledger and `plan`: encoded with postcard and
/// compressed with zstd in blocks, which go to a temporary file in the stage cache's folder
/// (removed from the folder as soon as it is opened) as they are sealed.
/// One stamp per capture and stage (a path, a digest and each named part's digest: about 1.4 KB
/// in the heap, about 250 bytes compressed) grew a build's memory with the dataset, and the
/// compressed blocks still did (11 MB at four times Bandai Namco 2) until the end of the build.
/// A block the file cannot take stays in memory: nothing is dropped.
#[derive(Debug, Default)]
pub struct SeenStamps {
    /// Sealed blocks, in order.
    blocks: Vec<SeenBlock>,
    pending: Vec<Miss>,
    /// The folder of the spill file; `None` keeps every block in memory (probe mode, which
    /// writes nothing).
    dir: Option<PathBuf>,
    /// Where sealed blocks go, opened with the first one (`None` also when it could not be).
    spill: Option<std::fs::File>,
    /// Bytes written to `spill`.
    spilled: u64,
}

/// A sealed block of stamps: its encoded length, and the compressed bytes or where they are.
#[derive(Debug)]
enum SeenBlock {
    Held { len: usize, packed: Vec<u8> },
    Spilled { len: usize, at: u64, packed: usize },
}

impl SeenStamps {
    /// Stamps whose sealed blocks go to a file in `dir` (created when missing).
    pub fn spilling_in(dir: &Path) -> SeenStamps {
        SeenStamps {
            dir: Some(dir.to_path_buf()),
            ..SeenStamps::default()
        }
    }

    /// Adds a stamp.
    pub fn push(&mut self, miss: Miss) {
        self.pending.push(miss);
        if self.pending.len() >= SEEN_BLOCK {
            // A block that cannot be encoded stays pending: nothing is dropped.
            if let Ok(encoded) = postcard::to_stdvec(&self.pending)
                && let Ok(packed) = zstd::bulk::compress(&encoded, 1)
            {
                let block = self.seal(encoded.len(), packed);
                self.blocks.push(block);
                self.pending.clear();
            }
        }
    }

    /// A sealed block, written to the spill file when there is one.
    fn seal(&mut self, len: usize, packed: Vec<u8>) -> SeenBlock {
        use std::os::unix::fs::FileExt;
        if self.blocks.is_empty()
            && let Some(dir) = &self.dir
        {
            self.spill = open_unlinked(dir);
        }
        if let Some(file) = &self.spill
            && file.write_all_at(&packed, self.spilled).is_ok()
        {
            let at = self.spilled;
            self.spilled += packed.len() as u64;
            return SeenBlock::Spilled {
                len,
                at,
                packed: packed.len(),
            };
        }
        SeenBlock::Held { len, packed }
    }

    /// Every stamp, in the order added.
    pub fn into_vec(self) -> Result<Vec<Miss>, WorkspaceError> {
        use motionforge_core::base::ReadBackProblem;
        use std::os::unix::fs::FileExt;
        let damaged = |problem: ReadBackProblem| WorkspaceError::ReadBack {
            what: "the stamps seen in this build, read back".to_string(),
            problem,
        };
        let mut all = Vec::with_capacity(self.blocks.len() * SEEN_BLOCK + self.pending.len());
        for block in &self.blocks {
            let (len, packed) = match block {
                SeenBlock::Held { len, packed } => (*len, std::borrow::Cow::Borrowed(packed)),
                SeenBlock::Spilled { len, at, packed } => {
                    let file = self
                        .spill
                        .as_ref()
                        .ok_or_else(|| damaged(ReadBackProblem::SpillGone))?;
                    let mut bytes = vec![0u8; *packed];
                    file.read_exact_at(&mut bytes, *at)
                        .map_err(|e| damaged(ReadBackProblem::Io(e)))?;
                    (*len, std::borrow::Cow::Owned(bytes))
                }
            };
            let encoded = zstd::bulk::decompress(&packed, len)
                .map_err(|e| damaged(ReadBackProblem::Io(e)))?;
            let block: Vec<Miss> =
                postcard::from_bytes(&encoded).map_err(|e| damaged(ReadBackProblem::Decode(e)))?;
            all.extend(block);
        }
        all.extend(self.pending);
        Ok(all)
    }
}

/// A new file in `dir`, open for reading and writing and already removed from the folder, so
/// the system deletes it when it is closed, however the build ends.
fn open_unlinked(dir: &Path) -> Option<std::fs::File> {
    std::fs::create_dir_all(dir).ok()?;
    let path = dir.join(format!(
        "seen-{}-{}.tmp",
        std::process::id(),
        SPILLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    ));
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create_new(true)
        .open(&path)
        .ok()?;
    std::fs::remove_file(&path).ok()?;
    Some(file)
}

/// Spill files opened by this process, for unique names.
static SPILLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// The per-item stage cache under `<output>/.motionforge/cache/<stage>/`, entries named by
/// fingerprint and packed into a few files per stage (`pack.rs`). In probe mode (for
/// `plan`) nothing is computed or stored: misses are collected instead.
#[derive(Debug, Clone)]
pub struct Workspace {
    root: PathBuf,
    probe: bool,
    seen: std::sync::Arc<std::sync::Mutex<SeenStamps>>,
    packs: std::sync::Arc<super::pack::Packs>,
}

impl Workspace {
    /// The workspace of an output folder.
    pub fn new(output: &Path) -> Workspace {
        let root = output.join(".motionforge");
        Workspace {
            // In the cache folder: `clean` and `--force` remove it with the cache, so even a
            // file left by a build killed between creating and unlinking it does not stay.
            seen: std::sync::Arc::new(std::sync::Mutex::new(SeenStamps::spilling_in(
                &root.join("cache"),
            ))),
            root,
            probe: false,
            packs: Default::default(),
        }
    }

    /// The same workspace in probe mode: a stage computes nothing on a miss.
    pub fn probing(output: &Path) -> Workspace {
        Workspace {
            probe: true,
            seen: Default::default(),
            ..Workspace::new(output)
        }
    }

    /// True in probe mode.
    pub fn is_probe(&self) -> bool {
        self.probe
    }

    /// Every item stamp seen in this run so far (hits and misses), for the ledger, handed over
    /// rather than copied; a later call returns only what was seen since.
    pub fn take_seen(&self) -> SeenStamps {
        self.seen
            .lock()
            .map(|mut v| std::mem::take(&mut *v))
            .unwrap_or_default()
    }

    /// The cached output of `stage` for item `key`, used only when `usable` accepts it (an
    /// output that names entries of another stage, a segment's frame chunks, is recomputed when
    /// one of them is gone, instead of failing the build when it is read), or `compute`'s,
    /// stored; the flag says whether it ran. In probe mode a miss returns `None` and computes
    /// nothing. Stages reach it through [`crate::stage::CachedStage`].
    pub(crate) fn try_item_where<T: Serialize + DeserializeOwned, E: From<WorkspaceError>>(
        &self,
        stage: &str,
        key: &str,
        stamp: &Stamp,
        usable: impl FnOnce(&T) -> bool,
        compute: impl FnOnce() -> Result<T, E>,
    ) -> Result<Option<(T, bool)>, E> {
        if let Ok(mut seen) = self.seen.lock() {
            seen.push(Miss {
                stage: stage.to_string(),
                key: key.to_string(),
                stamp: stamp.clone(),
            });
        }
        if let Some(v) = self.load(stage, &stamp.fingerprint).filter(|v| usable(v)) {
            return Ok(Some((v, false)));
        }
        if self.probe {
            return Ok(None);
        }
        let v = compute()?;
        self.store(stage, &stamp.fingerprint, &v)?;
        Ok(Some((v, true)))
    }

    /// True when `stage` has a cached output under `fingerprint`.
    pub fn has(&self, stage: &str, fingerprint: &str) -> bool {
        self.packs.has(&self.cache(), stage, fingerprint)
    }

    /// The workspace folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    fn cache(&self) -> PathBuf {
        self.root.join("cache")
    }

    /// A cached stage output, if present and readable. A damaged entry counts as absent, so the
    /// item is recomputed rather than trusted.
    pub fn load<T: DeserializeOwned>(&self, stage: &str, fingerprint: &str) -> Option<T> {
        let bytes = self.packs.read(&self.cache(), stage, fingerprint)?;
        postcard::from_bytes(&bytes).ok()
    }

    /// Stores a stage output; it replaces any entry under the same fingerprint.
    pub fn store<T: Serialize>(
        &self,
        stage: &str,
        fingerprint: &str,
        value: &T,
    ) -> Result<(), WorkspaceError> {
        let encode = |source: postcard::Error| WorkspaceError::Encode {
            what: format!("{stage} output"),
            source,
        };
        // Sized first: grown by doubling, the buffer of a large entry (the compose stage's, 21 MB
        // at four times Bandai Namco 2) held up to twice its size at the build's peak.
        let size = postcard::experimental::serialized_size(value).map_err(encode)?;
        if size > STREAMED_ENTRY {
            // Encoded straight into the pack: held whole, the compose stage's entry was the
            // largest single allocation at the build's peak.
            return self
                .packs
                .write_with(&self.cache(), stage, fingerprint, size as u64, |out| {
                    postcard::to_io(value, out)
                        .map(drop)
                        .map_err(std::io::Error::other)
                });
        }
        let mut bytes = vec![0u8; size];
        let used = postcard::to_slice(value, &mut bytes).map_err(encode)?.len();
        bytes.truncate(used);
        self.packs.write(&self.cache(), stage, fingerprint, &bytes)
    }

    /// Stores already-encoded bytes under `fingerprint`, unless an entry is there.
    pub fn store_bytes(
        &self,
        stage: &str,
        fingerprint: &str,
        bytes: &[u8],
    ) -> Result<(), WorkspaceError> {
        let cache = self.cache();
        if self.packs.has(&cache, stage, fingerprint) {
            return Ok(());
        }
        self.packs.write(&cache, stage, fingerprint, bytes)
    }

    /// Removes cache entries of `stage` not in `keep` (old fingerprints).
    pub fn prune(&self, stage: &str, keep: &std::collections::BTreeSet<String>) {
        if self.probe {
            return;
        }
        self.packs.prune(&self.cache(), stage, keep);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seen_stamps_come_back_whole_and_in_order_across_blocks() {
        // Two sealed blocks and a pending part, with the parts a real stamp has.
        let stamps: Vec<Miss> = (0..SEEN_BLOCK * 2 + 7)
            .map(|i| Miss {
                stage: ["ingest", "segment", "mirror"][i % 3].to_string(),
                key: format!("data/dataset-2_walk_normal_{i:03}.bvh"),
                stamp: motionforge_core::base::Fingerprint::new("ingest", 4)
                    .text("file content", &i.to_string())
                    .text("file path", "data")
                    .stamp(),
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let mut seen = SeenStamps::spilling_in(dir.path());
        for m in stamps.clone() {
            seen.push(m);
        }
        assert_eq!(seen.blocks.len(), 2);
        assert!(
            seen.blocks
                .iter()
                .all(|b| matches!(b, SeenBlock::Spilled { .. })),
            "sealed blocks leave memory"
        );
        assert_eq!(seen.pending.len(), 7);
        assert_eq!(seen.into_vec().unwrap(), stamps);
        // A damaged block is an error, not a silently shorter ledger: held in memory, or cut
        // short in the spill file.
        let mut seen = SeenStamps::spilling_in(dir.path());
        for m in stamps.clone() {
            seen.push(m);
        }
        let SeenBlock::Spilled { len, at, packed } = seen.blocks[1] else {
            panic!("a spilled block");
        };
        seen.blocks[1] = SeenBlock::Held {
            len,
            packed: vec![0u8; 10],
        };
        let err = seen.into_vec().unwrap_err().to_string();
        assert!(err.contains("stamps seen in this build"), "{err}");
        let mut seen = SeenStamps::spilling_in(dir.path());
        for m in stamps.clone() {
            seen.push(m);
        }
        if let Some(file) = &seen.spill {
            file.set_len(at + packed as u64 / 2).unwrap();
        }
        let err = seen.into_vec().unwrap_err().to_string();
        assert!(err.contains("stamps seen in this build"), "{err}");
        // The spill files are gone from the folder while open; without a folder, blocks stay
        // in memory and come back the same.
        assert_eq!(fs_entries(dir.path()), 0);
        let mut held = SeenStamps::default();
        for m in stamps.clone() {
            held.push(m);
        }
        assert!(
            held.blocks
                .iter()
                .all(|b| matches!(b, SeenBlock::Held { .. }))
        );
        assert_eq!(held.into_vec().unwrap(), stamps);
    }

    fn fs_entries(dir: &Path) -> usize {
        std::fs::read_dir(dir).unwrap().count()
    }

    #[test]
    fn entries_are_found_again_by_a_new_workspace() {
        let dir = tempfile::tempdir().unwrap();
        let workspace = Workspace::new(dir.path());
        workspace.store("stage", "fp", &vec![1u32, 2, 3]).unwrap();
        assert_eq!(
            workspace.load::<Vec<u32>>("stage", "fp"),
            Some(vec![1, 2, 3])
        );
        let again = Workspace::new(dir.path());
        assert!(again.has("stage", "fp"));
        assert_eq!(again.load::<Vec<u32>>("stage", "fp"), Some(vec![1, 2, 3]));
    }
}
