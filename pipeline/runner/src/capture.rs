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
    let mut item = Item {
        key: file.display.clone(),
        ..Item::default()
    };
    let mut read = match CaptureRead::open(shared, file) {
        Ok(read) => read,
        Err(reject) => {
            item.rejects.push(reject);
            return Ok(item);
        }
    };
    let mut parsed: Option<ingest::IngestOutput> = None;
    if let Ingested::Read(header, ingest_fp) =
        ingest_capture(shared, &mut read, &mut parsed, &mut item)?
    {
        segment_ingested(shared, &mut read, parsed, &ingest_fp, &header, &mut item)?;
    }
    Ok(item)
}

/// One capture file as its ingest and segment stages read it: its source, its content digest,
/// and its bytes once read (at most once per build).
struct CaptureRead<'s> {
    file: &'s CaptureFile,
    source: &'s crate::config::SourceConfig,
    spec: &'s ProfileSpec,
    fps_override: Option<f64>,
    sha256: String,
    /// Read only when the digest is not known or a stage must run.
    bytes: Option<Vec<u8>>,
}

impl<'s> CaptureRead<'s> {
    /// The capture's digest, remembered from its stat data or read from its bytes; a reject when
    /// the file cannot be read.
    fn open(shared: &'s Shared<'_>, file: &'s CaptureFile) -> Result<CaptureRead<'s>, Reject> {
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
        let meta = std::fs::metadata(&file.path).map_err(cannot_read)?;
        let path_key = file.path.to_string_lossy();
        let mut bytes: Option<Vec<u8>> = None;
        let sha256 = match shared.digests.known(&path_key, &meta) {
            Some(sha) => sha,
            None => {
                let b = std::fs::read(&file.path).map_err(cannot_read)?;
                let sha = sha256_hex(&b);
                bytes = Some(b);
                sha
            }
        };
        shared.digests.record(&path_key, &meta, &sha256);
        let source = &shared.config.sources[file.source];
        Ok(CaptureRead {
            file,
            source,
            spec: &shared.specs[file.source],
            fps_override: source::fps_override(source, &shared.fps_tables[file.source], file),
            sha256,
            bytes,
        })
    }

    /// What the ingest stage reads, with the capture's `bytes`.
    fn input<'i>(&'i self, bytes: &'i [u8]) -> ingest::CaptureInput<'i> {
        ingest::CaptureInput {
            file: self.file,
            bytes,
            sha256: &self.sha256,
            source: &self.source.name,
            profile: self.spec,
            fps_override: self.fps_override,
            format: ingest::format_of(self.source),
        }
    }

    /// Reads (when not read yet) and parses the capture: at most once per build, on an ingest
    /// miss or in the segment stage on a capture whose ingest record is cached.
    fn parse(&mut self) -> Result<ingest::IngestOutput, BuildError> {
        if self.bytes.is_none() {
            let file = self.file;
            let read = std::fs::read(&file.path).map_err(super::workspace::io_err(&file.path))?;
            if sha256_hex(&read) != self.sha256 {
                return Err(BuildError::CaptureChanged {
                    file: file.display.to_string(),
                });
            }
            self.bytes = Some(read);
        }
        Ok(ingest::run(
            &self.input(self.bytes.as_deref().unwrap_or_default()),
        ))
    }
}

/// What the ingest stage of one capture leaves for its segment stage.
enum Ingested {
    /// Probe mode: the ingest output is not cached (the item says so).
    Pending,
    /// The capture was refused (its rejects are on the item).
    Refused,
    /// The capture without its frames, and the ingest fingerprint.
    Read(ingest::CaptureHeader, String),
}

/// The ingest stage of one capture, cached by its content. A capture parsed here is left in
/// `parsed` for the segment stage.
fn ingest_capture(
    shared: &Shared<'_>,
    read: &mut CaptureRead<'_>,
    parsed: &mut Option<ingest::IngestOutput>,
    item: &mut Item,
) -> Result<Ingested, BuildError> {
    let stamp = ingest::fingerprint(&read.input(&[]));
    let ingest_fp = stamp.fingerprint.clone();
    let ingested = item.run_stage::<ingest::Ingest, BuildError>(
        &shared.workspace,
        stamp,
        |_| true,
        || {
            let out = read.parse()?;
            let record = out.record();
            *parsed = Some(out);
            Ok(record)
        },
    )?;
    let Some(ingested) = ingested else {
        return Ok(Ingested::Pending);
    };
    Ok(match ingested.capture {
        Some(header) => Ingested::Read(header, ingest_fp),
        None => Ingested::Refused,
    })
}

/// The segment stage of one ingested capture: its annotation and bound profile, then its clips,
/// cached without their frames (those go to frame chunks as they are made).
fn segment_ingested(
    shared: &Shared<'_>,
    read: &mut CaptureRead<'_>,
    mut parsed: Option<ingest::IngestOutput>,
    ingest_fp: &str,
    header: &ingest::CaptureHeader,
    item: &mut Item,
) -> Result<(), BuildError> {
    let config = shared.config;
    let (file, source) = (read.file, read.source);
    let Some((annotation, profile)) = annotation_and_profile(shared, read, header, item) else {
        return Ok(());
    };
    let seg_fp = segment::fingerprint(
        ingest_fp,
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
    let segmented = item.run_stage::<segment::Segment, BuildError>(
        &shared.workspace,
        seg_fp,
        chunks_present,
        || {
            let capture = match parsed.take() {
                Some(out) => out.capture,
                None => read.parse()?.capture,
            };
            let Some(capture) = capture else {
                return Err(BuildError::CaptureUnreadable {
                    file: file.display.to_string(),
                });
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
            Ok((out, spill.finish()?))
        },
    )?;
    let Some((mut segmented, refs)) = segmented else {
        return Ok(());
    };
    item.clips = std::mem::take(&mut segmented.clips);
    for clip in &mut item.clips {
        shared.skeletons.share(&mut clip.skeleton);
    }
    item.refs = refs;
    item.segment = segmented;
    Ok(())
}

/// The capture's annotation and its skeleton's bound profile; a reject on the item when either
/// is missing.
fn annotation_and_profile(
    shared: &Shared<'_>,
    read: &CaptureRead<'_>,
    header: &ingest::CaptureHeader,
    item: &mut Item,
) -> Option<(
    motionforge_sources::annotate::span::CaptureAnnotation,
    motionforge_core::motion::Profile,
)> {
    let (file, source) = (read.file, read.source);
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
            return None;
        }
    };
    match shared.bound.bind(read.spec, &header.skeleton) {
        Ok(profile) => Some((annotation, profile)),
        Err(e) => {
            item.rejects.push(ingest::reject(
                segment::NAME,
                file,
                RejectReason::Profile,
                e.to_string(),
                None,
                None,
            ));
            None
        }
    }
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
    // Taken for the stage's run, which records itself on the item, and put back after.
    let (clips, clip_refs) = (
        std::mem::take(&mut item.clips),
        std::mem::take(&mut item.refs),
    );
    let mirrored = item.run_stage::<mirror::Mirror, BuildError>(
        &shared.workspace,
        fp,
        |_| true,
        || {
            let mut out = mirror::MirrorOutput::default();
            let mut refs = Vec::new();
            for (clip, at) in clips.iter().zip(&clip_refs) {
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
            Ok((out, refs))
        },
    );
    item.clips = clips;
    item.refs = clip_refs;
    let Some((mirrored, refs)) = mirrored? else {
        return Ok(());
    };
    item.mirrored = mirrored.clips;
    for clip in &mut item.mirrored {
        shared.skeletons.share(&mut clip.skeleton);
    }
    item.mirrored_refs = refs;
    Ok(())
}
