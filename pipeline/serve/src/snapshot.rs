//! What the browser reads of a served dataset: its clip index (every row's metadata, where each
//! row is, the skeletons), read once per version of the dataset and shared by every request; and
//! the bound on the heavy reads (an index, a motion, a page of clips) that run at once.
//!
//! A version is what the dataset folder's `manifest.json` and `data/` folder are on disk (device,
//! inode, size, modification time). A build replaces a dataset by renames only, the manifest
//! removed first and the new one put in last (`build::output`), so:
//!
//! - an index is read between two looks at the version that agree, both with a manifest: no
//!   switch ran in between, and its shards are one build's;
//! - its shards stay open in the index, so a request that took it reads that build to the end,
//!   even after a rebuild has replaced or removed its files;
//! - while the manifest is missing and `data/` is there, a switch is under way: requests keep the
//!   index they have, and a first read waits for the switch to end (at most [`SWITCH_WAIT`]; a
//!   folder that never gets a manifest is then read as it is).

use std::collections::HashMap;
use std::os::unix::fs::MetadataExt;
use std::path::Path;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use super::api::ApiError;
use super::wire::Written;
use motionforge_core::base::layout::{DATA_DIR, MANIFEST_FILE};
use motionforge_format::dataset::{self, ClipFrames, ClipInfo, DatasetError, OpenShard, Skeletons};

/// Heavy reads (an index, a motion, a page of clips) running at once, over all datasets. Each
/// holds at most one index being read, or one answer being built and then sent, so this bounds
/// the memory that readers add, however many there are; the others wait their turn.
pub(crate) const HEAVY_READS: usize = 4;
/// Longest time an answer being sent holds its heavy-read turn: a client that does not read its
/// answer does not hold up the others for longer.
pub(crate) const SEND_TURN: Duration = Duration::from_secs(10);
/// Bytes of an answer handed to the connection at a time (copied out, so the answer is freed as
/// soon as its last piece is handed over); the next piece waits until all but one piece of what
/// was handed over has been written.
const PIECE: usize = 16 * 1024;
/// Longest wait for a rebuild's switch to end before an index is read.
pub(crate) const SWITCH_WAIT: Duration = Duration::from_secs(2);
/// How often a waiting read looks again.
const POLL: Duration = Duration::from_millis(10);

/// What a file is on disk: a file replaced by a rename, or modified, is another.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stamp {
    dev: u64,
    ino: u64,
    len: u64,
    mtime: (i64, i64),
}

impl Stamp {
    fn of(path: &Path) -> Option<Stamp> {
        let m = std::fs::metadata(path).ok()?;
        Some(Stamp {
            dev: m.dev(),
            ino: m.ino(),
            len: m.len(),
            mtime: (m.mtime(), m.mtime_nsec()),
        })
    }
}

/// A version of a dataset folder: its manifest and its `data/` folder (whose time changes with
/// every file added, removed or renamed in it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Version {
    manifest: Option<Stamp>,
    data: Option<Stamp>,
}

impl Version {
    fn of(dataset: &Path) -> Version {
        Version {
            manifest: Stamp::of(&dataset.join(MANIFEST_FILE)),
            data: Stamp::of(&dataset.join(DATA_DIR)),
        }
    }

    /// A build is moving its files in: the manifest is gone, the shards are there.
    fn switching(&self) -> bool {
        self.manifest.is_none() && self.data.is_some()
    }
}

/// One version of a dataset as the browser reads it.
#[derive(Debug)]
pub(crate) struct Snapshot {
    version: Version,
    /// Every row's metadata, in shard order and then row order.
    pub(crate) clips: Vec<ClipInfo>,
    /// Each clip's shard (an index into `shards`) and row in it.
    places: Vec<(usize, usize)>,
    /// Clip id to its index in `clips` (the first row with it).
    by_id: HashMap<String, usize>,
    /// The shards, open.
    shards: Vec<OpenShard>,
    /// `skeletons.json`, or why it cannot be read.
    skeletons: Result<Skeletons, String>,
    /// The choices of each filter over the whole dataset: motion types, splits, kinds.
    pub(crate) choices: [Vec<String>; 3],
    /// The column view's statistics (JSON), counted at the first request for them.
    column_statistics: OnceLock<Result<Vec<u8>, String>>,
}

impl Snapshot {
    /// Reads the version of `dataset` on disk now, consistently (see the module).
    fn read(dataset: &Path) -> Result<Snapshot, DatasetError> {
        let mut waited = Duration::ZERO;
        loop {
            let before = Version::of(dataset);
            if before.switching() && waited < SWITCH_WAIT {
                std::thread::sleep(POLL);
                waited += POLL;
                continue;
            }
            let opened = dataset::open_shards(dataset);
            let skeletons = dataset::read_skeletons(dataset).map_err(|e| e.to_string());
            let settled = Version::of(dataset) == before && !before.switching();
            let retry = waited < SWITCH_WAIT && (!settled || opened.as_ref().is_err_and(vanished));
            if retry {
                std::thread::sleep(POLL);
                waited += POLL;
                continue;
            }
            return Snapshot::decode(dataset, before, opened?, skeletons);
        }
    }

    fn decode(
        dataset: &Path,
        version: Version,
        shards: Vec<OpenShard>,
        skeletons: Result<Skeletons, String>,
    ) -> Result<Snapshot, DatasetError> {
        let mut clips = Vec::new();
        let mut places = Vec::new();
        for (k, shard) in shards.iter().enumerate() {
            let start = clips.len();
            shard.read_infos(dataset, &mut clips)?;
            places.extend((0..clips.len() - start).map(|row| (k, row)));
        }
        let mut by_id = HashMap::with_capacity(clips.len());
        for (i, c) in clips.iter().enumerate() {
            by_id.entry(c.clip_id.clone()).or_insert(i);
        }
        let choice = |of: &dyn Fn(&ClipInfo) -> Option<&str>| {
            let mut v: Vec<String> = clips.iter().filter_map(of).map(str::to_string).collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        let types = choice(&|c| c.motion_type.as_deref());
        let splits = choice(&|c| Some(c.split.as_str()));
        let mut kinds = choice(&|c| Some(c.source_kind.as_str()));
        kinds.extend(["mirrored".to_string(), "original".to_string()]);
        Ok(Snapshot {
            version,
            clips,
            places,
            by_id,
            shards,
            skeletons,
            choices: [types, splits, kinds],
            column_statistics: OnceLock::new(),
        })
    }

    /// The clip with this id.
    pub(crate) fn clip(&self, clip_id: &str) -> Option<&ClipInfo> {
        self.by_id.get(clip_id).map(|&i| &self.clips[i])
    }

    /// A clip's frames, read from the shard this version opened.
    pub(crate) fn frames(&self, dataset: &Path, clip_id: &str) -> Result<ClipFrames, DatasetError> {
        let found = self.by_id.get(clip_id).and_then(|&i| {
            let (shard, row) = self.places[i];
            Some((self.clips[i].clone(), self.shards.get(shard)?, row))
        });
        let Some((info, shard, row)) = found else {
            return Err(DatasetError::NoClip {
                path: dataset.to_path_buf(),
                clip_id: clip_id.to_string(),
                count: self.clips.len(),
                hint: String::new(),
            });
        };
        shard.read_frames(info, row)
    }

    /// Every column's statistics over the whole table ([`super::columns::statistics`]), counted
    /// once per version.
    pub(crate) fn column_statistics(&self) -> Result<&[u8], &str> {
        self.column_statistics
            .get_or_init(|| super::columns::statistics(&self.shards, self.clips.len()))
            .as_deref()
            .map_err(String::as_str)
    }

    /// Rows `offset..offset + limit` of the whole table ([`super::columns::page`]).
    pub(crate) fn rows(&self, offset: usize, limit: usize) -> Result<serde_json::Value, String> {
        super::columns::page(&self.shards, &self.places, &self.clips, offset, limit)
    }

    /// The skeletons, or why they cannot be read.
    pub(crate) fn skeletons(&self) -> Result<&Skeletons, &str> {
        self.skeletons.as_ref().map_err(String::as_str)
    }
}

/// A file the listing named was gone when opened: a switch ran in between.
fn vanished(e: &DatasetError) -> bool {
    matches!(e, DatasetError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound)
}

/// The snapshot of one dataset and the lock that lets one request read a new version while the
/// others wait for it.
#[derive(Debug, Default)]
struct Slot {
    current: Mutex<Option<Arc<Snapshot>>>,
    reading: tokio::sync::Mutex<()>,
}

impl Slot {
    /// The snapshot held, if it may answer for the folder as it is now: the same version, or a
    /// version that had a manifest while a switch replaces it.
    fn usable(&self, now: &Version) -> Option<Arc<Snapshot>> {
        let held = self.current.lock().unwrap_or_else(|e| e.into_inner());
        held.as_ref()
            .filter(|s| s.version == *now || (now.switching() && s.version.manifest.is_some()))
            .cloned()
    }
}

/// The readers of every served dataset.
pub(crate) struct Readers {
    slots: HashMap<String, Slot>,
    heavy: Arc<Semaphore>,
    /// The threads heavy reads run on: always the same few, so what the allocator keeps of
    /// their reads for reuse is bounded too (the runtime's blocking pool grows a thread whenever
    /// none is idle at the moment one is asked for).
    threads: rayon::ThreadPool,
}

impl std::fmt::Debug for Readers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Readers")
            .field("slots", &self.slots)
            .finish_non_exhaustive()
    }
}

impl Readers {
    /// Readers for the datasets named.
    pub(crate) fn new<'a>(
        names: impl IntoIterator<Item = &'a String>,
    ) -> Result<Readers, std::io::Error> {
        let threads = rayon::ThreadPoolBuilder::new()
            .num_threads(HEAVY_READS)
            .thread_name(|i| format!("motionforge-read-{i}"))
            // A read that panics answers 500 (its answer channel closes); the service stays up.
            .panic_handler(|_| super::say("a dataset read panicked; it answers 500"))
            .build()
            .map_err(std::io::Error::other)?;
        Ok(Readers {
            slots: names
                .into_iter()
                .map(|n| (n.clone(), Slot::default()))
                .collect(),
            heavy: Arc::new(Semaphore::new(HEAVY_READS)),
            threads,
        })
    }

    /// The snapshot of dataset `name` (folder `dataset`) as it is now, read when it changed.
    pub(crate) async fn snapshot(
        &self,
        name: &str,
        dataset: &Path,
    ) -> Result<Result<Arc<Snapshot>, DatasetError>, ApiError> {
        let Some(slot) = self.slots.get(name) else {
            return Err(ApiError::internal(format!("no reader for `{name}`")));
        };
        if let Some(s) = slot.usable(&Version::of(dataset)) {
            return Ok(Ok(s));
        }
        let _reading = slot.reading.lock().await;
        // Another request may have read it while this one waited.
        if let Some(s) = slot.usable(&Version::of(dataset)) {
            return Ok(Ok(s));
        }
        let dir = dataset.to_path_buf();
        let read = self.heavy(move || Snapshot::read(&dir)).await?;
        Ok(read.map(|s| {
            let s = Arc::new(s);
            *slot.current.lock().unwrap_or_else(|e| e.into_inner()) = Some(s.clone());
            s
        }))
    }

    /// Lets go of dataset `name`'s index, and so of its open shards: once a build has replaced
    /// them, their disk space is freed when the requests still reading them end, not at the next
    /// read of the dataset.
    pub(crate) fn forget(&self, name: &str) {
        if let Some(slot) = self.slots.get(name) {
            slot.current
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .take();
        }
    }

    /// Runs `f` on a read thread once fewer than [`HEAVY_READS`] heavy reads run.
    pub(crate) async fn heavy<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, ApiError> {
        let (value, _turn) = self.heavy_turn(f).await?;
        Ok(value)
    }

    /// Builds an answer with `f` as [`Readers::heavy`] runs it, and keeps the turn while the
    /// answer is sent on the connection `writes` counts: until it has been written, or for
    /// [`SEND_TURN`] at most.
    pub(crate) async fn answer(
        &self,
        writes: Option<Arc<Written>>,
        f: impl FnOnce() -> Result<Vec<u8>, ApiError> + Send + 'static,
    ) -> Result<HeldAnswer, ApiError> {
        let (bytes, turn) = self.heavy_turn(f).await?;
        let bytes = bytes?;
        let turn = Arc::new(Mutex::new(Some(turn)));
        let expiry = Arc::downgrade(&turn);
        tokio::spawn(async move {
            tokio::time::sleep(SEND_TURN).await;
            if let Some(turn) = expiry.upgrade() {
                turn.lock().unwrap_or_else(|e| e.into_inner()).take();
            }
        });
        Ok(HeldAnswer {
            len: bytes.len(),
            bytes,
            sent: 0,
            turn: Some(GiveBack(turn)),
            writes: writes.map(|w| {
                let start = w.bytes();
                (w, start)
            }),
        })
    }

    async fn heavy_turn<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> Result<(T, OwnedSemaphorePermit), ApiError> {
        let turn = self
            .heavy
            .clone()
            .acquire_owned()
            .await
            .map_err(ApiError::internal)?;
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.threads.spawn(move || {
            let _ = tx.send(f());
        });
        let value = rx
            .await
            .map_err(|_| ApiError::internal("a dataset read ended without an answer"))?;
        Ok((value, turn))
    }
}

/// A heavy-read turn, given back when dropped.
struct GiveBack(Arc<Mutex<Option<OwnedSemaphorePermit>>>);

impl Drop for GiveBack {
    fn drop(&mut self) {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).take();
    }
}

/// An answer's body, handed to the connection [`PIECE`] bytes at a time, that holds its
/// heavy-read turn until the connection has written all of it (or it is dropped, or
/// [`SEND_TURN`] has passed).
pub(crate) struct HeldAnswer {
    bytes: Vec<u8>,
    len: usize,
    sent: usize,
    turn: Option<GiveBack>,
    /// The connection's count of written bytes, and its value when the answer was made.
    writes: Option<(Arc<Written>, u64)>,
}

impl HeldAnswer {
    /// All handed over: the turn waits for the connection to write it.
    fn handed_over(&mut self) {
        self.bytes = Vec::new();
        let Some(turn) = self.turn.take() else {
            return;
        };
        if let Some((writes, start)) = &self.writes {
            writes.keep_until(start + self.len as u64, Box::new(turn));
        }
    }
}

impl http_body::Body for HeldAnswer {
    type Data = bytes::Bytes;
    type Error = std::convert::Infallible;

    fn poll_frame(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<Option<Result<http_body::Frame<bytes::Bytes>, Self::Error>>> {
        // One piece at a time: the next once the connection has written all but a piece of what
        // it was given, so the HTTP server's buffer for the connection stays a piece or two.
        if let Some((writes, start)) = &self.writes
            && self.sent > PIECE
            && !writes.reached(start + (self.sent - PIECE) as u64, cx)
        {
            return std::task::Poll::Pending;
        }
        let rest = self.bytes.get(self.sent..).unwrap_or_default();
        if rest.is_empty() {
            self.handed_over();
            return std::task::Poll::Ready(None);
        }
        let piece = bytes::Bytes::copy_from_slice(&rest[..rest.len().min(PIECE)]);
        self.sent += piece.len();
        if self.sent >= self.len {
            self.handed_over();
        }
        std::task::Poll::Ready(Some(Ok(http_body::Frame::data(piece))))
    }

    fn is_end_stream(&self) -> bool {
        self.sent >= self.len
    }

    fn size_hint(&self) -> http_body::SizeHint {
        http_body::SizeHint::with_exact(self.len.saturating_sub(self.sent) as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use http_body::Body;
    use std::task::{Context, Poll, Waker};

    fn poll(answer: &mut HeldAnswer) -> Poll<Option<usize>> {
        let mut cx = Context::from_waker(Waker::noop());
        std::pin::Pin::new(answer)
            .poll_frame(&mut cx)
            .map(|f| f.map(|f| f.unwrap().into_data().unwrap().len()))
    }

    #[tokio::test]
    async fn an_answer_is_handed_over_as_the_connection_writes_and_keeps_its_turn_until_written() {
        let readers = Readers::new(&[]).unwrap();
        let writes = Arc::new(Written::default());
        let mut answer = readers
            .answer(Some(writes.clone()), || Ok(vec![7u8; 3 * PIECE + 10]))
            .await
            .unwrap();
        assert_eq!(readers.heavy.available_permits(), HEAVY_READS - 1);
        assert_eq!(answer.size_hint().exact(), Some(3 * PIECE as u64 + 10));
        // Two pieces go at once; the third waits until the first has been written.
        assert_eq!(poll(&mut answer), Poll::Ready(Some(PIECE)));
        assert_eq!(poll(&mut answer), Poll::Ready(Some(PIECE)));
        assert_eq!(poll(&mut answer), Poll::Pending);
        writes.advance_for_test(PIECE);
        assert_eq!(poll(&mut answer), Poll::Ready(Some(PIECE)));
        writes.advance_for_test(2 * PIECE);
        assert_eq!(poll(&mut answer), Poll::Ready(Some(10)));
        assert!(answer.is_end_stream());
        // All handed over, not all written: the turn is still taken.
        assert_eq!(readers.heavy.available_permits(), HEAVY_READS - 1);
        writes.advance_for_test(10);
        assert_eq!(readers.heavy.available_permits(), HEAVY_READS);
        assert_eq!(poll(&mut answer), Poll::Ready(None));
    }

    #[tokio::test]
    async fn a_dropped_or_failed_answer_gives_its_turn_back() {
        let readers = Readers::new(&[]).unwrap();
        let answer = readers
            .answer(Some(Arc::default()), || Ok(vec![1u8; 10]))
            .await
            .unwrap();
        assert_eq!(readers.heavy.available_permits(), HEAVY_READS - 1);
        drop(answer);
        assert_eq!(readers.heavy.available_permits(), HEAVY_READS);
        let failed = readers
            .answer(None, || Err(ApiError::internal("no such shard")))
            .await;
        assert!(failed.is_err());
        assert_eq!(readers.heavy.available_permits(), HEAVY_READS);
    }
}
