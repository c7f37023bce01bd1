//! Stage-cache entries packed into a few large files per stage instead of one file each.
//!
//! A build of a few thousand captures stores four entries per capture; as single files that is
//! over ten thousand creations and renames, and creating inodes was up to half of the time of
//! the first stage (`docs/performance.md`). Entries are appended to the stage's current pack
//! instead, and found again by scanning the packs' record headers when the stage is first used.
//!
//! A record is `MAGIC, fingerprint length (u32), body length (u64), fingerprint, body, body
//! length (u64), ENTRY_MARK`. Packs are written without fsync (entries can be made again): a
//! record cut short by a crash fails its footer check, and the scan of that pack stops there, so
//! a damaged entry reads as absent and is recomputed. Records are never changed in place: a
//! newer record of the same fingerprint supersedes an older one, and pruning rewrites a pack
//! with only its live records (new file, then the old one removed).

use std::collections::{BTreeSet, HashMap};
use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};

use motionforge_core::base::{WorkspaceError, io_err};

/// Starts every record.
const MAGIC: &[u8; 8] = b"mfpack1\n";
/// Ends every record, after the body's length.
const ENTRY_MARK: &[u8; 8] = b"mfentry1";
/// Bytes of a record's header before the fingerprint.
const HEADER: u64 = 8 + 4 + 8;
/// Bytes of a record's footer.
const FOOTER: u64 = 8 + 8;
/// Fingerprints are hex digests; anything longer is not a record.
const MAX_FINGERPRINT: u32 = 256;
/// A pack is closed and a new one started past this size, so pruning rewrites little.
const PACK_LIMIT: u64 = 64 << 20;
/// File name ending of packs; anything else in a stage folder is left over and pruned.
const PACK_EXT: &str = "pack";

/// Where an entry's body is.
#[derive(Debug, Clone, Copy)]
struct Location {
    /// Index into [`StagePacks::packs`].
    pack: usize,
    /// Offset of the body in the pack.
    offset: u64,
    /// Length of the body.
    len: u64,
}

/// A whole record of a pack: fingerprint, record start, body offset, body length. The
/// fingerprint is shared with the stage's index of entries, since a build holds both until it
/// ends (about 108,000 records over seven stages for ten times Bandai Namco 2).
type Record = (Arc<str>, u64, u64, u64);

/// One pack file and what it holds.
#[derive(Debug)]
struct Pack {
    path: PathBuf,
    /// Open for reading once read from (`None` after the pack was removed).
    file: Option<Arc<File>>,
    /// Every whole record.
    records: Vec<Record>,
}

/// The pack being appended to.
#[derive(Debug)]
struct Writer {
    pack: usize,
    file: File,
    len: u64,
}

/// One stage's packs, found by scanning its folder once.
#[derive(Debug, Default)]
struct StagePacks {
    packs: Vec<Pack>,
    /// The newest record of each fingerprint.
    entries: HashMap<Arc<str>, Location>,
    writer: Option<Writer>,
}

/// Every stage's packs under a cache folder, shared by all clones of a workspace.
#[derive(Debug, Default)]
pub(super) struct Packs {
    stages: Mutex<HashMap<String, StagePacks>>,
    /// Distinguishes the packs this process starts.
    sequence: std::sync::atomic::AtomicU64,
}

impl Packs {
    fn lock(&self) -> MutexGuard<'_, HashMap<String, StagePacks>> {
        // A panic while holding the lock leaves the index as it was before the record being
        // written, which is still true of the files.
        self.stages.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// True when `stage` has an entry under `fingerprint`.
    pub(super) fn has(&self, cache: &Path, stage: &str, fingerprint: &str) -> bool {
        let mut stages = self.lock();
        scanned(&mut stages, cache, stage)
            .entries
            .contains_key(fingerprint)
    }

    /// The body of `stage`'s entry under `fingerprint`; `None` when absent or unreadable.
    pub(super) fn read(&self, cache: &Path, stage: &str, fingerprint: &str) -> Option<Vec<u8>> {
        let (file, at) = {
            let mut stages = self.lock();
            let packs = scanned(&mut stages, cache, stage);
            let at = *packs.entries.get(fingerprint)?;
            let pack = packs.packs.get_mut(at.pack)?;
            if pack.file.is_none() {
                pack.file = File::open(&pack.path).ok().map(Arc::new);
            }
            (Arc::clone(pack.file.as_ref()?), at)
        };
        // The length was checked against the file's size when the pack was scanned or written.
        let mut body = vec![0u8; usize::try_from(at.len).ok()?];
        file.read_exact_at(&mut body, at.offset).ok()?;
        Some(body)
    }

    /// Appends an entry to `stage`'s current pack; it supersedes any older one of `fingerprint`.
    pub(super) fn write(
        &self,
        cache: &Path,
        stage: &str,
        fingerprint: &str,
        body: &[u8],
    ) -> Result<(), WorkspaceError> {
        self.write_with(cache, stage, fingerprint, body.len() as u64, |out| {
            out.write_all(body)
        })
    }

    /// Like [`Packs::write`], for a body of `len` bytes that `fill` writes straight into the
    /// pack, so a large entry is never held whole in memory. A body of another length is an
    /// error and leaves a record the scan stops at, as a torn one.
    pub(super) fn write_with(
        &self,
        cache: &Path,
        stage: &str,
        fingerprint: &str,
        len: u64,
        fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
    ) -> Result<(), WorkspaceError> {
        let mut stages = self.lock();
        let packs = scanned(&mut stages, cache, stage);
        // The writer is taken out while appending: after a failed append it is not put back
        // (what was appended may be a torn record, and later records would sit behind it,
        // unreachable by the scan), so the next entry starts a new pack.
        let mut writer = match packs.writer.take().filter(|w| w.len < PACK_LIMIT) {
            Some(w) => w,
            None => {
                let dir = cache.join(stage);
                fs::create_dir_all(&dir).map_err(io_err(&dir))?;
                let n = self
                    .sequence
                    .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let path = dir.join(pack_name(n));
                let file = OpenOptions::new()
                    .create_new(true)
                    .append(true)
                    .open(&path)
                    .map_err(io_err(&path))?;
                packs.packs.push(Pack {
                    path,
                    file: None,
                    records: Vec::new(),
                });
                Writer {
                    pack: packs.packs.len() - 1,
                    file,
                    len: 0,
                }
            }
        };
        let (start, pack) = (writer.len, writer.pack);
        append_record(&mut writer.file, fingerprint, len, fill).map_err(|source| {
            WorkspaceError::Io {
                path: packs.packs[pack].path.clone(),
                source,
            }
        })?;
        let offset = start + HEADER + fingerprint.len() as u64;
        writer.len = offset + len + FOOTER;
        packs.writer = Some(writer);
        let name: Arc<str> = fingerprint.into();
        packs.packs[pack]
            .records
            .push((Arc::clone(&name), start, offset, len));
        packs.entries.insert(name, Location { pack, offset, len });
        Ok(())
    }

    /// Keeps the entries of `stage` in `keep`: packs with nothing live are removed, packs with a
    /// quarter or more of their bytes dead are rewritten with the live records, and files that are
    /// not packs (an earlier version's entries, a rewrite cut short) are removed.
    pub(super) fn prune(&self, cache: &Path, stage: &str, keep: &BTreeSet<String>) {
        let mut stages = self.lock();
        let packs = scanned(&mut stages, cache, stage);
        packs.writer = None;
        let dir = cache.join(stage);
        let mut next = 0u64;
        for p in 0..packs.packs.len() {
            let live: Vec<Record> = packs.packs[p]
                .records
                .iter()
                .filter(|(fp, _, offset, _)| {
                    keep.contains(&**fp)
                        && packs
                            .entries
                            .get(fp)
                            .is_some_and(|at| at.pack == p && at.offset == *offset)
                })
                .cloned()
                .collect();
            let size = |records: &[Record]| -> u64 {
                records
                    .iter()
                    .map(|(fp, _, _, len)| HEADER + fp.len() as u64 + len + FOOTER)
                    .sum()
            };
            let (all, kept) = (size(&packs.packs[p].records), size(&live));
            // A pack mostly alive is left as it is: rewriting 64 MB to drop one changed capture's
            // old record would cost more than the space. Its dead records stay findable, which is
            // harmless: an entry is named by what it was computed from.
            if live.len() == packs.packs[p].records.len() || (kept > 0 && (all - kept) * 4 < all) {
                continue;
            }
            let old = packs.packs[p].path.clone();
            let mut rewritten = Vec::new();
            if !live.is_empty() {
                // The rewrite gets a new name: a crash before the old pack is removed leaves
                // both, with the same records, which the scan takes as one.
                let path = loop {
                    let candidate = dir.join(format!("{}-r{next}.{PACK_EXT}", stamp_now()));
                    next += 1;
                    if !candidate.exists() {
                        break candidate;
                    }
                };
                match rewrite(&old, &path, &live) {
                    Ok(records) => {
                        rewritten = records;
                        packs.packs[p].path = path;
                    }
                    // Pruning only saves space: a pack that cannot be rewritten stays.
                    Err(_) => continue,
                }
            }
            let _ = fs::remove_file(&old);
            for (fp, _, offset, _) in &packs.packs[p].records {
                if packs
                    .entries
                    .get(fp)
                    .is_some_and(|at| at.pack == p && at.offset == *offset)
                {
                    packs.entries.remove(fp);
                }
            }
            for (fp, _, offset, len) in &rewritten {
                packs.entries.insert(
                    fp.clone(),
                    Location {
                        pack: p,
                        offset: *offset,
                        len: *len,
                    },
                );
            }
            packs.packs[p].records = rewritten;
            packs.packs[p].file = None;
        }
        if let Ok(listing) = fs::read_dir(&dir) {
            let known: BTreeSet<&PathBuf> = packs.packs.iter().map(|p| &p.path).collect();
            for entry in listing.flatten() {
                let path = entry.path();
                if !known.contains(&path) || path.extension().is_none_or(|e| e != PACK_EXT) {
                    let _ = fs::remove_file(&path);
                }
            }
        }
        if keep.is_empty() {
            // A stage with nothing to keep leaves no folder (only removed when empty).
            let _ = fs::remove_dir(&dir);
        }
    }
}

/// The stage's packs, scanning its folder the first time.
fn scanned<'a>(
    stages: &'a mut HashMap<String, StagePacks>,
    cache: &Path,
    stage: &str,
) -> &'a mut StagePacks {
    stages
        .entry(stage.to_string())
        .or_insert_with(|| scan_stage(&cache.join(stage)))
}

/// Packs of a stage folder in the order they were written (names start with the time).
fn scan_stage(dir: &Path) -> StagePacks {
    let mut out = StagePacks::default();
    let Ok(listing) = fs::read_dir(dir) else {
        return out;
    };
    let mut paths: Vec<PathBuf> = listing
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == PACK_EXT))
        .collect();
    paths.sort();
    for path in paths {
        let records = File::open(&path).map(|f| scan_pack(&f)).unwrap_or_default();
        let pack = out.packs.len();
        for (fp, _, offset, len) in &records {
            out.entries.insert(
                fp.clone(),
                Location {
                    pack,
                    offset: *offset,
                    len: *len,
                },
            );
        }
        out.packs.push(Pack {
            path,
            file: None,
            records,
        });
    }
    out
}

/// Every whole record of a pack, up to the first that is not.
fn scan_pack(file: &File) -> Vec<Record> {
    let mut records = Vec::new();
    let Ok(size) = file.metadata().map(|m| m.len()) else {
        return records;
    };
    let mut pos = 0u64;
    while pos + HEADER + FOOTER <= size {
        let mut header = [0u8; HEADER as usize];
        if file.read_exact_at(&mut header, pos).is_err() || &header[..8] != MAGIC {
            break;
        }
        let fp_len = u32::from_le_bytes([header[8], header[9], header[10], header[11]]);
        let mut len_bytes = [0u8; 8];
        len_bytes.copy_from_slice(&header[12..20]);
        let len = u64::from_le_bytes(len_bytes);
        if fp_len > MAX_FINGERPRINT {
            break;
        }
        let offset = pos + HEADER + u64::from(fp_len);
        // Checked before anything is read or allocated: the length comes from the file.
        let Some(end) = offset
            .checked_add(len)
            .and_then(|e| e.checked_add(FOOTER))
            .filter(|e| *e <= size)
        else {
            break;
        };
        let mut fp = vec![0u8; fp_len as usize];
        let mut footer = [0u8; FOOTER as usize];
        if file.read_exact_at(&mut fp, pos + HEADER).is_err()
            || file.read_exact_at(&mut footer, offset + len).is_err()
            || footer[..8] != len.to_le_bytes()
            || &footer[8..] != ENTRY_MARK
        {
            break;
        }
        let Ok(fp) = String::from_utf8(fp) else {
            break;
        };
        records.push((fp.into(), pos, offset, len));
        pos = end;
    }
    records
}

fn append_record(
    file: &mut File,
    fingerprint: &str,
    len: u64,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let mut header = Vec::with_capacity(HEADER as usize + fingerprint.len());
    header.extend_from_slice(MAGIC);
    header.extend_from_slice(&(fingerprint.len() as u32).to_le_bytes());
    header.extend_from_slice(&len.to_le_bytes());
    header.extend_from_slice(fingerprint.as_bytes());
    file.write_all(&header)?;
    let mut body = Counted {
        inner: std::io::BufWriter::with_capacity(BODY_BUFFER, &mut *file),
        written: 0,
    };
    fill(&mut body)?;
    body.inner.flush()?;
    if body.written != len {
        return Err(std::io::Error::other(format!(
            "a cache entry of {} bytes where {len} were announced",
            body.written
        )));
    }
    drop(body);
    let mut footer = [0u8; FOOTER as usize];
    footer[..8].copy_from_slice(&len.to_le_bytes());
    footer[8..].copy_from_slice(ENTRY_MARK);
    file.write_all(&footer)
}

/// Write buffer of a record's body: a large entry reaches the file in pieces of this size.
const BODY_BUFFER: usize = 256 * 1024;

/// A writer that counts what passes through it.
struct Counted<W: Write> {
    inner: W,
    written: u64,
}

impl<W: Write> Write for Counted<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.written += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Copies the `live` records of `from` into a new pack at `to`; their places there.
fn rewrite(from: &Path, to: &Path, live: &[Record]) -> std::io::Result<Vec<Record>> {
    let source = File::open(from)?;
    let tmp = to.with_extension("tmp");
    let result = (|| {
        let mut out = File::create(&tmp)?;
        let mut records = Vec::with_capacity(live.len());
        let mut pos = 0u64;
        for (fp, _, offset, len) in live {
            let mut body = vec![0u8; usize::try_from(*len).map_err(std::io::Error::other)?];
            source.read_exact_at(&mut body, *offset)?;
            append_record(&mut out, fp, body.len() as u64, |w| w.write_all(&body))?;
            let body_at = pos + HEADER + fp.len() as u64;
            records.push((fp.clone(), pos, body_at, *len));
            pos = body_at + len + FOOTER;
        }
        fs::rename(&tmp, to)?;
        Ok(records)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// A pack name that sorts after every earlier one: the time in nanoseconds (fixed width), the
/// process and a counter.
fn pack_name(n: u64) -> String {
    format!("{}-{}-{n}.{PACK_EXT}", stamp_now(), std::process::id())
}

fn stamp_now() -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    format!("{nanos:020}")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body(n: u8, len: usize) -> Vec<u8> {
        (0..len).map(|i| n.wrapping_add(i as u8)).collect()
    }

    #[test]
    fn records_cut_short_read_as_absent_and_earlier_ones_stay() {
        let dir = tempfile::tempdir().unwrap();
        let cache = dir.path();
        let packs = Packs::default();
        packs.write(cache, "s", "a", &body(1, 100)).unwrap();
        packs.write(cache, "s", "b", &body(2, 50)).unwrap();
        let path = packs.lock()["s"].packs[0].path.clone();
        let whole = fs::read(&path).unwrap();
        let first_end = (HEADER + 1 + 100 + FOOTER) as usize;
        for cut in [first_end, first_end + 1, whole.len() - 1] {
            fs::write(&path, &whole[..cut]).unwrap();
            let fresh = Packs::default();
            assert_eq!(fresh.read(cache, "s", "a"), Some(body(1, 100)), "cut {cut}");
            assert_eq!(fresh.read(cache, "s", "b"), None, "cut {cut}");
        }
        for cut in [0, 1, first_end - 1] {
            fs::write(&path, &whole[..cut]).unwrap();
            assert_eq!(Packs::default().read(cache, "s", "a"), None, "cut {cut}");
        }
        // A footer that disagrees (zeroed by a crash) ends the scan too.
        let mut zeroed = whole.clone();
        zeroed[first_end - 8..first_end].fill(0);
        fs::write(&path, &zeroed).unwrap();
        assert_eq!(Packs::default().read(cache, "s", "a"), None);
    }

    #[test]
    fn a_streamed_body_reads_back_and_one_of_the_wrong_length_is_refused_not_kept() {
        let dir = tempfile::tempdir().unwrap();
        let cache = dir.path();
        let packs = Packs::default();
        // Larger than the write buffer, written in uneven pieces.
        let big = body(3, 3 * BODY_BUFFER + 17);
        packs
            .write_with(cache, "s", "big", big.len() as u64, |out| {
                for piece in big.chunks(100_003) {
                    out.write_all(piece)?;
                }
                Ok(())
            })
            .unwrap();
        // One byte short of what was announced: an error, and the record is not found.
        let short = packs.write_with(cache, "s", "short", 10, |out| out.write_all(&[7u8; 9]));
        assert!(short.is_err());
        packs.write(cache, "s", "after", &body(4, 20)).unwrap();
        for fresh in [&packs, &Packs::default()] {
            assert_eq!(fresh.read(cache, "s", "big"), Some(big.clone()));
            assert_eq!(fresh.read(cache, "s", "short"), None);
            assert_eq!(fresh.read(cache, "s", "after"), Some(body(4, 20)));
        }
    }

    #[test]
    fn a_body_length_past_the_file_is_not_allocated_or_trusted() {
        let dir = tempfile::tempdir().unwrap();
        let stage = dir.path().join("s");
        fs::create_dir_all(&stage).unwrap();
        let mut record = Vec::new();
        record.extend_from_slice(MAGIC);
        record.extend_from_slice(&1u32.to_le_bytes());
        record.extend_from_slice(&u64::MAX.to_le_bytes());
        record.extend_from_slice(b"a");
        record.extend_from_slice(&[0u8; 32]);
        fs::write(stage.join(format!("0.{PACK_EXT}")), &record).unwrap();
        assert!(!Packs::default().has(dir.path(), "s", "a"));
    }

    #[test]
    fn a_pack_mostly_alive_is_not_rewritten_for_one_dead_record() {
        let dir = tempfile::tempdir().unwrap();
        let cache = dir.path();
        let packs = Packs::default();
        for fp in ["a", "b", "c", "d", "e"] {
            packs.write(cache, "s", fp, &body(1, 100)).unwrap();
        }
        let path = packs.lock()["s"].packs[0].path.clone();
        let keep: BTreeSet<String> = ["a", "b", "c", "d"].map(String::from).into();
        packs.prune(cache, "s", &keep);
        assert!(path.is_file(), "one dead record in five: the pack stays");
        for fp in ["a", "b", "c", "d"] {
            assert_eq!(packs.read(cache, "s", fp), Some(body(1, 100)));
        }
        let keep: BTreeSet<String> = ["a", "b"].map(String::from).into();
        packs.prune(cache, "s", &keep);
        assert!(
            !path.is_file(),
            "three dead in five: rewritten under a new name"
        );
        for p in [&packs, &Packs::default()] {
            assert_eq!(p.read(cache, "s", "a"), Some(body(1, 100)));
            assert_eq!(p.read(cache, "s", "c"), None);
        }
    }

    #[test]
    fn newer_records_supersede_and_pruning_keeps_only_live_ones() {
        let dir = tempfile::tempdir().unwrap();
        let cache = dir.path();
        let packs = Packs::default();
        for (fp, n) in [("a", 1), ("b", 2), ("c", 3), ("a", 4)] {
            packs.write(cache, "s", fp, &body(n, 10)).unwrap();
        }
        assert_eq!(packs.read(cache, "s", "a"), Some(body(4, 10)));
        fs::write(
            cache.join("s").join("old.bin"),
            b"an earlier version's entry",
        )
        .unwrap();
        packs.prune(
            cache,
            "s",
            &BTreeSet::from(["a".to_string(), "c".to_string()]),
        );
        for p in [&packs, &Packs::default()] {
            assert_eq!(p.read(cache, "s", "a"), Some(body(4, 10)));
            assert_eq!(p.read(cache, "s", "b"), None);
            assert_eq!(p.read(cache, "s", "c"), Some(body(3, 10)));
        }
        let files: Vec<_> = fs::read_dir(cache.join("s")).unwrap().flatten().collect();
        assert_eq!(files.len(), 1, "one pack, nothing else: {files:?}");
        let size = files[0].metadata().unwrap().len();
        assert_eq!(size, 2 * (HEADER + 1 + 10 + FOOTER));
        // Writing after a prune starts a new pack; pruning everything removes the folder.
        packs.write(cache, "s", "d", &body(5, 10)).unwrap();
        assert_eq!(packs.read(cache, "s", "d"), Some(body(5, 10)));
        packs.prune(cache, "s", &BTreeSet::new());
        assert!(!cache.join("s").exists());
        assert!(!Packs::default().has(cache, "s", "a"));
    }
}
