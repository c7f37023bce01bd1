//! The clips the write stage reads, held compressed.
//!
//! Between the last stage and the shards, a build holds every clip of the table (without frames:
//! texts, labels, provenance, where its frames are). As `Clip` values that is about 3 KB per
//! clip, the part of a build's memory that grew with the dataset (26 MB per 2,902 captures of
//! Bandai Namco dataset 2). The writer reads them a shard at a time, in row order, so they are
//! kept as zstd-compressed blocks of postcard-encoded clips: a few hundred bytes per clip, and a
//! block is decoded only when a shard reaches it.

use std::sync::Arc;

use super::BuildError;
use super::motions::MotionRef;
use motionforge_core::motion::Skeleton;
use motionforge_sources::clip::{Clip, SkeletonTable, Split};

/// Clips per compressed block: large enough for zstd to find the texts' repetitions, small
/// enough that decoding one for a single clip costs little.
const BLOCK: usize = 64;

/// zstd level of the blocks: the fastest full level (they live for one build, in memory).
const LEVEL: i32 = 1;

/// What planning shards reads of a clip, kept uncompressed.
#[derive(Debug, Clone, Copy)]
pub(super) struct Summary {
    /// Index into [`HeldClips::splits`].
    split: u16,
    /// Frames of the clip's motion.
    pub(super) frames: u32,
    /// Joints of its skeleton.
    pub(super) joints: u32,
}

/// The table's clips in row order, each with where its frames are, compressed in blocks. Each
/// clip's skeleton is kept once per distinct skeleton beside the blocks (the clips share them,
/// `motion::SkeletonPool`), so decoding gives back clips that share them too.
pub(super) struct HeldClips {
    /// Each block compressed, with its length decoded: a block's size is set by its clips'
    /// texts, not bounded by a guess (a 20 MB caption overflowed a fixed 64 MiB bound).
    blocks: Vec<(Box<[u8]>, usize)>,
    summaries: Vec<Summary>,
    splits: Vec<Split>,
    skeletons: SkeletonTable,
}

/// What a block stores per clip: the clip with an empty skeleton, and its frames' location.
type Entry = (Clip, MotionRef);

impl HeldClips {
    /// Takes `clips` (in row order) and the location of each one's frames, `at`.
    pub(super) fn new(
        clips: Vec<Clip>,
        mut at: impl FnMut(&Clip) -> Option<MotionRef>,
    ) -> Result<HeldClips, BuildError> {
        let empty = Arc::new(Skeleton { joints: Vec::new() });
        let mut held = HeldClips {
            blocks: Vec::with_capacity(clips.len().div_ceil(BLOCK)),
            summaries: Vec::with_capacity(clips.len()),
            splits: Vec::new(),
            skeletons: SkeletonTable::default(),
        };
        let mut pending: Vec<Entry> = Vec::with_capacity(BLOCK);
        for mut clip in clips {
            let motion = at(&clip).ok_or_else(|| BuildError::NoMotion {
                clip: clip.clip_id.clone(),
            })?;
            let split = match held.splits.iter().position(|s| *s == clip.split) {
                Some(i) => i,
                None => {
                    held.splits.push(clip.split.clone());
                    held.splits.len() - 1
                }
            };
            let joints = clip.skeleton.len() as u32;
            held.skeletons.take(&mut clip, &empty);
            held.summaries.push(Summary {
                split: split as u16,
                frames: motion.frames(),
                joints,
            });
            pending.push((clip, motion));
            if pending.len() == BLOCK {
                held.seal(&mut pending)?;
            }
        }
        held.seal(&mut pending)?;
        Ok(held)
    }

    fn seal(&mut self, pending: &mut Vec<Entry>) -> Result<(), BuildError> {
        if pending.is_empty() {
            return Ok(());
        }
        use motionforge_core::base::WorkspaceError;
        const WHAT: &str = "held clips";
        let bytes = postcard::to_stdvec(&*pending).map_err(|source| WorkspaceError::Encode {
            what: WHAT.into(),
            source,
        })?;
        let packed =
            zstd::bulk::compress(&bytes, LEVEL).map_err(|source| WorkspaceError::Compress {
                what: WHAT.into(),
                source,
            })?;
        self.blocks.push((packed.into_boxed_slice(), bytes.len()));
        pending.clear();
        Ok(())
    }

    /// Split, frames and joints of every clip, in row order, without decoding any.
    pub(super) fn summaries(&self) -> impl Iterator<Item = (&Split, Summary)> + '_ {
        self.summaries
            .iter()
            .map(|s| (&self.splits[usize::from(s.split)], *s))
    }

    /// The clips `rows` (indices in row order, ascending), each with its frames' location;
    /// decodes each block they touch once.
    pub(super) fn get(&self, rows: &[usize]) -> Result<Vec<Entry>, BuildError> {
        let mut out = Vec::with_capacity(rows.len());
        let mut decoded: Option<(usize, Vec<Option<Entry>>)> = None;
        for &row in rows {
            let block = row / BLOCK;
            if decoded.as_ref().is_none_or(|(b, _)| *b != block) {
                decoded = Some((block, self.block(block)?.into_iter().map(Some).collect()));
            }
            let entry = decoded
                .as_mut()
                .and_then(|(_, entries)| entries.get_mut(row % BLOCK))
                .and_then(Option::take)
                .ok_or_else(|| undecodable(block, "a row asked for twice or past the end"))?;
            out.push(entry);
        }
        Ok(out)
    }

    fn block(&self, block: usize) -> Result<Vec<Entry>, BuildError> {
        let (packed, len) = self
            .blocks
            .get(block)
            .ok_or_else(|| undecodable(block, "no such block"))?;
        // The length was measured when this process sealed the block.
        let bytes =
            zstd::bulk::decompress(packed, *len).map_err(|e| undecodable(block, &e.to_string()))?;
        let mut entries: Vec<Entry> =
            postcard::from_bytes(&bytes).map_err(|e| undecodable(block, &e.to_string()))?;
        for (i, (clip, _)) in entries.iter_mut().enumerate() {
            let skeleton = self
                .skeletons
                .skeleton_of(block * BLOCK + i)
                .ok_or_else(|| undecodable(block, "a clip without its skeleton"))?;
            clip.skeleton = Arc::clone(skeleton);
        }
        Ok(entries)
    }
}

fn undecodable(block: usize, why: &str) -> BuildError {
    BuildError::HeldClips {
        block,
        why: why.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The demo's clips (real Bandai Namco and CMU captures through the real stages, mirrors
    /// and synthetic pairs included), staged in a temporary folder.
    fn fixture_clips() -> Vec<Clip> {
        let out = tempfile::tempdir().expect("a temporary folder");
        let mut config = crate::config::Config::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../fixtures/demo.toml"
        )))
        .expect("the demo config loads");
        config.dataset.output = out.path().to_path_buf();
        crate::collect_clips(&config, &crate::BuildOptions::default())
            .expect("the demo's clips")
            .into_iter()
            .map(|loaded| loaded.clip)
            .collect()
    }

    #[test]
    fn clips_come_back_equal_sharing_their_skeletons() {
        let clips = fixture_clips();
        assert!(clips.len() > BLOCK / 4, "{} clips", clips.len());
        // Several blocks, a partial last one.
        let mut many = Vec::new();
        for copy in 0..(3 * BLOCK).div_ceil(clips.len()) + 1 {
            many.extend(clips.iter().cloned().map(|mut c| {
                c.clip_id = format!("{}#{copy}", c.clip_id);
                c
            }));
        }
        let refs: Vec<MotionRef> = (0..many.len())
            .map(|i| MotionRef::Stored {
                stage: "segment-motions".into(),
                fingerprint: format!("{i:064x}").into(),
                index: i as u32,
                frames: 10 + i as u32,
            })
            .collect();
        let mut next = refs.iter().cloned();
        let held = HeldClips::new(many.clone(), |_| next.next()).expect("held");
        assert_eq!(held.summaries().count(), many.len());
        let all: Vec<usize> = (0..many.len()).collect();
        let back = held.get(&all).expect("decoded");
        for ((clip, at), (want, want_at)) in back.iter().zip(many.iter().zip(&refs)) {
            assert_eq!(clip, want);
            assert_eq!(at, want_at);
        }
        let distinct: std::collections::BTreeSet<*const Skeleton> =
            back.iter().map(|(c, _)| Arc::as_ptr(&c.skeleton)).collect();
        assert_eq!(distinct.len(), held.skeletons.distinct());
        let mut values: Vec<&Skeleton> = Vec::new();
        for c in &many {
            if !values.contains(&&*c.skeleton) {
                values.push(&c.skeleton);
            }
        }
        assert_eq!(held.skeletons.distinct(), values.len());
        let frames: Vec<u32> = held.summaries().map(|(_, s)| s.frames).collect();
        assert_eq!(
            frames,
            refs.iter().map(MotionRef::frames).collect::<Vec<_>>()
        );
        // A subset across blocks, and a row asked for twice.
        let some = [1, BLOCK + 3, many.len() - 1];
        let subset = held.get(&some).expect("subset");
        assert_eq!(subset[1].0, many[BLOCK + 3]);
        assert_eq!(subset[2].0, many[many.len() - 1]);
        assert!(held.get(&[2, 2]).is_err());
        assert!(held.get(&[many.len()]).is_err());
    }

    #[test]
    fn a_skeleton_table_gives_back_what_it_took_and_refuses_a_count_mismatch() {
        let clips = fixture_clips();
        let mut taken = clips.clone();
        let table = SkeletonTable::take_all(&mut taken);
        assert!(taken.iter().all(|c| c.skeleton.is_empty()));
        let bytes = postcard::to_stdvec(&(&taken, &table)).expect("encoded");
        let whole = postcard::to_stdvec(&clips).expect("encoded");
        assert!(
            bytes.len() < whole.len(),
            "{} vs {}",
            bytes.len(),
            whole.len()
        );
        let (mut back, table): (Vec<Clip>, SkeletonTable) =
            postcard::from_bytes(&bytes).expect("decoded");
        let mut short = back[1..].to_vec();
        assert!(!table.give_all(&mut short));
        assert!(short.iter().all(|c| c.skeleton.is_empty()));
        assert!(table.give_all(&mut back));
        assert_eq!(back, clips);
    }
}
