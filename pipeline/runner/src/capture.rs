//! Per-capture stages: ingest and segment, then (after the text stages) mirror.

use std::collections::BTreeMap;

use super::motions::{MotionRef, MotionSpill};
use super::{BuildError, Reject, Stage, Workspace, sha256_hex};
use crate::config::Config;
use crate::source::{self, CaptureFile, SourceAnnotations};
use crate::stages::segment::{self, SegmentOutput};
use crate::stages::{ingest, mirror};
use motionforge_core::base::RejectReason;
use motionforge_core::motion::{BoundProfiles, ProfileSpec, SkeletonPool};
use motionforge_sources::annotate::taxonomy::TypeMap;
use motionforge_sources::clip::Clip;

/// What the per-capture stages produced for one capture.
#[derive(Default)]
pub(super) struct Item {
    /// In probe mode: the first stage whose output is not cached (nothing after it is known).
    pub(super) pending: Option<Stage>,
    /// The item's key in the ledger: the capture path as found.
    pub(super) key: String,
    /// The per-capture stages that reached this capture, in order: each one's fingerprint and
    /// whether it ran (else it was reused).
    pub(super) done: Vec<(Stage, String, bool)>,
    /// The capture's original clips (labelled by the text stages before mirroring), without
    /// their frames.
    pub(super) clips: Vec<Clip>,
    /// Where the frames of `clips` are.
    pub(super) refs: Vec<MotionRef>,
    /// Mirrored copies, without their frames.
    pub(super) mirrored: Vec<Clip>,
    /// Where the frames of `mirrored` are.
    pub(super) mirrored_refs: Vec<MotionRef>,
    pub(super) rejects: Vec<Reject>,
    /// Segmentation counts and notes (its clips moved to `clips`).
    pub(super) segment: SegmentOutput,
}

impl Item {
    /// The fingerprint of `stage` for this capture, when the stage reached it.
    pub(super) fn fingerprint(&self, stage: Stage) -> Option<&str> {
        self.done
            .iter()
            .find(|(s, _, _)| *s == stage)
            .map(|(_, f, _)| f.as_str())
    }

    /// Whether `stage` reached this capture, and if so whether it ran.
    pub(super) fn ran(&self, stage: Stage) -> Option<bool> {
        self.done
            .iter()
            .find(|(s, _, _)| *s == stage)
            .map(|(_, _, ran)| *ran)
    }
}

/// Everything the per-capture stages share.
pub(super) struct Shared<'a> {
    pub(super) config: &'a Config,
    pub(super) workspace: Workspace,
    pub(super) specs: Vec<ProfileSpec>,
    /// Profiles bound to the skeletons seen so far.
    pub(super) bound: std::sync::Arc<BoundProfiles>,
    /// One copy of each skeleton for all the clips held.
    pub(super) skeletons: SkeletonPool,
    pub(super) annotations: Vec<SourceAnnotations>,
    pub(super) fps_tables: Vec<BTreeMap<String, f64>>,
    pub(super) types: TypeMap,
    /// Digest of the taxonomy's content and the mapping config: a taxonomy edit re-runs segments.
    pub(super) types_digest: String,
    /// Digests of capture files, known from their stat data.
    pub(super) digests: super::digests::FileDigests,
}

impl Shared<'_> {
    /// Where the held clips' frames are read from: this build's stage cache, on its profiles.
    pub(super) fn motions(&self) -> super::motions::MotionSource {
        super::motions::MotionSource::new(
            &self.workspace,
            &self.specs,
            &self.bound,
            self.config.mirror.offsets,
        )
    }

    /// The bound profile of a clip's skeleton.
    pub(super) fn profile_of(&self, clip: &Clip) -> Option<motionforge_core::motion::Profile> {
        let spec = self.specs.iter().find(|s| s.name == clip.profile)?;
        self.bound.bind(spec, &clip.skeleton).ok()
    }
}

/// Runs ingest and segment for one capture, reusing cached outputs.
pub(super) fn segment_capture(shared: &Shared<'_>, file: &CaptureFile) -> Result<Item, BuildError> {
    let config = shared.config;
    let source = &config.sources[file.source];
    let spec = &shared.specs[file.source];
    let mut item = Item {
        key: file.display.clone(),
        ..Item::default()
    };
    let cannot_read = |e: std::io::Error| {
        ingest::reject(
            ingest::NAME,
            file,
            RejectReason::Io,
            format!("cannot read: {e}"),
            None,
            None,
        )
    };
    let meta = match std::fs::metadata(&file.path) {
        Ok(m) => m,
        Err(e) => {
            item.rejects.push(cannot_read(e));
            return Ok(item);
        }
    };
    // The bytes are read only when the digest is not known or a stage must run.
    let path_key = file.path.to_string_lossy();
    let mut bytes: Option<Vec<u8>> = None;
    let sha256 = match shared.digests.known(&path_key, &meta) {
        Some(sha) => sha,
        None => match std::fs::read(&file.path) {
            Ok(b) => {
                let sha = sha256_hex(&b);
                bytes = Some(b);
                sha
            }
            Err(e) => {
                item.rejects.push(cannot_read(e));
                return Ok(item);
            }
        },
    };
    shared.digests.record(&path_key, &meta, &sha256);
    let fps_override = source::fps_override(source, &shared.fps_tables[file.source], file);
    // Reads (when not read yet) and parses the capture: at most once per build, here on an
    // ingest miss or in the segment stage on a capture whose ingest record is cached.
    let parse = |bytes: &mut Option<Vec<u8>>| -> Result<ingest::IngestOutput, BuildError> {
        if bytes.is_none() {
            let read = std::fs::read(&file.path).map_err(super::workspace::io_err(&file.path))?;
            if sha256_hex(&read) != sha256 {
                return Err(BuildError::Motion(format!(
                    "{}: the file changed during the build; run the build again",
                    file.display
                )));
            }
            *bytes = Some(read);
        }
        Ok(ingest::run(&ingest::CaptureInput {
            file,
            bytes: bytes.as_deref().unwrap_or_default(),
            sha256: &sha256,
            source: &source.name,
            profile: spec,
            fps_override,
            positions: source.positions.as_ref(),
            amass: source.amass.as_ref(),
        }))
    };
    let ingest_fp = ingest::fingerprint(&ingest::CaptureInput {
        file,
        bytes: &[],
        sha256: &sha256,
        source: &source.name,
        profile: spec,
        fps_override,
        positions: source.positions.as_ref(),
        amass: source.amass.as_ref(),
    });
    let mut parsed: Option<ingest::IngestOutput> = None;
    let Some((ingested, ran)) =
        shared
            .workspace
            .try_item(ingest::NAME, &item.key, &ingest_fp, || {
                let out = parse(&mut bytes)?;
                let record = out.record();
                parsed = Some(out);
                Ok::<_, BuildError>(record)
            })?
    else {
        item.pending = Some(Stage::Ingest);
        return Ok(item);
    };
    let ingest_fp = ingest_fp.fingerprint;
    item.done.push((Stage::Ingest, ingest_fp.clone(), ran));
    item.rejects.extend(ingested.rejects);
    let Some(header) = ingested.capture else {
        return Ok(item);
    };

    let annotation = match shared.annotations[file.source].for_capture(
        &header.stem,
        &file.path,
        source.labels.kind(),
    ) {
        Ok(a) => a,
        Err(refusal) => {
            item.rejects.push(ingest::reject(
                segment::NAME,
                file,
                refusal.reason,
                refusal.message,
                None,
                None,
            ));
            return Ok(item);
        }
    };
    let profile = match shared.bound.bind(spec, &header.skeleton) {
        Ok(p) => p,
        Err(e) => {
            item.rejects.push(ingest::reject(
                segment::NAME,
                file,
                RejectReason::Profile,
                e.to_string(),
                None,
                None,
            ));
            return Ok(item);
        }
    };
    let seg_fp = segment::fingerprint(
        &ingest_fp,
        &annotation,
        source.labels.kind(),
        &source.segment,
        config.dataset.fps,
        &shared.types_digest,
    );
    // The cached output is the clips without frames and where their frames went.
    // A cached segment output names its frame chunks; pruning may have removed a chunk an
    // older, still-findable output names (an annotation changed and changed back), so such an
    // output is made again rather than trusted.
    let chunks_present = |(_, refs): &(SegmentOutput, Vec<MotionRef>)| {
        refs.iter()
            .flat_map(MotionRef::chunks)
            .all(|(stage, fingerprint)| shared.workspace.has(stage, fingerprint))
    };
    let Some(((segmented, refs), ran)): Option<((SegmentOutput, Vec<MotionRef>), bool)> = shared
        .workspace
        .try_item_where(segment::NAME, &item.key, &seg_fp, chunks_present, || {
            let capture = match parsed.take() {
                Some(out) => out.capture,
                None => parse(&mut bytes)?.capture,
            };
            let Some(capture) = capture else {
                return Err(BuildError::Motion(format!(
                    "{}: the capture read before no longer reads; run the build again with --force",
                    file.display
                )));
            };
            let seg_input = segment::SegmentInput {
                capture: &capture,
                annotation: &annotation,
                kind: source.labels.kind(),
                config: &source.segment,
                types: &shared.types,
                profile: &profile,
                fps: config.dataset.fps,
            };
            let mut spill = MotionSpill::new(&shared.workspace);
            let out = segment::run_with(&seg_input, |_, motion| spill.push(motion))?;
            Ok::<_, BuildError>((out, spill.finish()?))
        })?
    else {
        item.pending = Some(Stage::Segment);
        return Ok(item);
    };

    let mut segmented = segmented;
    item.clips = std::mem::take(&mut segmented.clips);
    for clip in &mut item.clips {
        shared.skeletons.share(&mut clip.skeleton);
    }
    item.refs = refs;
    item.done.push((Stage::Segment, seg_fp.fingerprint, ran));
    item.segment = segmented;
    Ok(item)
}

/// Mirrors a capture's labelled clips, reusing the cached copies when the clips are unchanged.
pub(super) fn mirror_capture(shared: &Shared<'_>, item: &mut Item) -> Result<(), BuildError> {
    let Some(first) = item.clips.first() else {
        return Ok(());
    };
    let Some(spec) = shared.specs.iter().find(|s| s.name == first.profile) else {
        return Ok(());
    };
    // The stage's input is exactly the clips, labels included, and their frames (named by where
    // they are): that encoding is the fingerprint.
    let encoded =
        motionforge_core::base::encoded_sha256(&(&item.clips, &item.refs), "clips to mirror")?;
    let offsets = shared.config.mirror.offsets;
    let fp = mirror::fingerprint(&encoded, spec, &shared.types_digest, offsets);
    // The copies' texts and labels are made here; their frames are made from the originals'
    // when read (`MotionRef::Mirrored`), so the stage reads and stores no frames.
    let Some(((mirrored, refs), ran)): Option<((mirror::MirrorOutput, Vec<MotionRef>), bool)> =
        shared.workspace.item(mirror::NAME, &item.key, &fp, || {
            let mut out = mirror::MirrorOutput::default();
            let mut refs = Vec::new();
            for (clip, at) in item.clips.iter().zip(&item.refs) {
                let one = mirror::run_with(
                    std::slice::from_ref(clip),
                    spec,
                    &shared.bound,
                    shared.types.taxonomy(),
                    offsets,
                );
                for copy in one.clips {
                    refs.push(MotionRef::Mirrored(Box::new(at.clone())));
                    out.clips.push(copy);
                }
                out.rejects.extend(one.rejects);
            }
            (out, refs)
        })?
    else {
        item.pending = Some(Stage::Mirror);
        return Ok(());
    };

    item.mirrored = mirrored.clips;
    for clip in &mut item.mirrored {
        shared.skeletons.share(&mut clip.skeleton);
    }
    item.mirrored_refs = refs;
    item.done.push((Stage::Mirror, fp.fingerprint, ran));
    item.rejects.extend(mirrored.rejects);
    Ok(())
}
