//! `ingest`: one capture file in, its labelled clips out (parsed, labelled, resampled).

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

use crate::annotate::filename::{FilenamePattern, fill_template, sidecar_fields};
use crate::build::{Fingerprint, Reject, sha256_hex};
use crate::clip::{CaptureRef, Clip, SourceKind};
use crate::config::{LabelConfig, SourceConfig};
use crate::motion::{ProfileSpec, read_bvh};
use crate::source::CaptureFile;

/// Stage name.
pub const NAME: &str = "ingest";
/// Bump when the stage's output for the same input changes.
pub const VERSION: u32 = 1;

/// What the stage reads for one capture.
#[derive(Debug)]
pub struct CaptureInput<'a> {
    /// The file.
    pub file: &'a CaptureFile,
    /// Its bytes.
    pub bytes: &'a [u8],
    /// The sidecar JSON bytes, when the source uses sidecars and the file exists.
    pub sidecar: Option<&'a [u8]>,
    /// Its source's config.
    pub source: &'a SourceConfig,
    /// Its source's profile.
    pub profile: &'a ProfileSpec,
    /// Frame-rate override for this file.
    pub fps_override: Option<f64>,
    /// Dataset frame rate.
    pub fps: f64,
}

/// The stage's output for one capture: clips, or why the capture was refused.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct IngestOutput {
    /// Clips cut from the capture.
    pub clips: Vec<Clip>,
    /// Why (part of) the capture was refused.
    pub rejects: Vec<Reject>,
}

/// The fingerprint of one capture's ingest: everything the output depends on.
pub fn fingerprint(input: &CaptureInput<'_>) -> String {
    Fingerprint::new(NAME, VERSION)
        .text(&input.source.name)
        .text(&input.file.display)
        .text(&sha256_hex(input.bytes))
        .text(&input.sidecar.map(sha256_hex).unwrap_or_default())
        .json(&input.source.labels)
        .json(input.profile)
        .json(&input.fps_override)
        .json(&input.fps)
        .finish()
}

fn reject(
    file: &CaptureFile,
    reason: &str,
    message: String,
    line: Option<u64>,
    frame: Option<u64>,
) -> IngestOutput {
    IngestOutput {
        clips: Vec::new(),
        rejects: vec![Reject {
            stage: NAME.to_string(),
            file: file.display.clone(),
            line,
            frame,
            reason: reason.to_string(),
            message,
        }],
    }
}

/// Runs the stage on one capture.
pub fn run(input: &CaptureInput<'_>) -> IngestOutput {
    let file = input.file;
    let text = match std::str::from_utf8(input.bytes) {
        Ok(t) => t,
        Err(e) => {
            let line = input.bytes[..e.valid_up_to()]
                .iter()
                .filter(|b| **b == b'\n')
                .count() as u64
                + 1;
            return reject(
                file,
                "encoding",
                format!("not UTF-8 text (byte {})", e.valid_up_to()),
                Some(line),
                None,
            );
        }
    };
    let bvh = match read_bvh(text) {
        Ok(b) => b,
        Err(e) => {
            return reject(
                file,
                "bvh",
                e.kind.to_string(),
                Some(e.line as u64),
                e.frame.map(|f| f as u64),
            );
        }
    };
    if let Err(e) = input.profile.bind(&bvh.skeleton) {
        return reject(file, "profile", e.to_string(), None, None);
    }
    let LabelConfig::Filename {
        pattern,
        action,
        text: text_template,
        sidecar,
    } = &input.source.labels;
    let mut fields = match FilenamePattern::new(pattern).map(|p| p.captures(&file.stem())) {
        Ok(Some(f)) => f,
        Ok(None) => {
            return reject(
                file,
                "label_pattern",
                format!(
                    "file name `{}` does not match the label pattern `{pattern}`",
                    file.stem()
                ),
                None,
                None,
            );
        }
        Err(e) => return reject(file, "label_pattern", e.to_string(), None, None),
    };
    let mut overrides: BTreeMap<String, String> = BTreeMap::new();
    if *sidecar && let Some(bytes) = input.sidecar {
        match serde_json::from_slice::<serde_json::Value>(bytes)
            .ok()
            .as_ref()
            .and_then(sidecar_fields)
        {
            Some(side) => {
                for (k, v) in side {
                    if k == "action" || k == "text" {
                        overrides.insert(k, v);
                    } else {
                        fields.entry(format!("sidecar.{k}")).or_insert(v);
                    }
                }
            }
            None => {
                return reject(
                    file,
                    "sidecar",
                    "sidecar is not a JSON object".to_string(),
                    None,
                    None,
                );
            }
        }
    }
    let label = |template: &str, words: bool, key: &str| match overrides.get(key) {
        Some(v) => Ok(v.clone()),
        None => fill_template(template, &fields, words),
    };
    let (action, caption) = match (
        label(action, false, "action"),
        label(text_template, true, "text"),
    ) {
        (Ok(a), Ok(t)) => (a, t),
        (Err(e), _) | (_, Err(e)) => {
            return reject(file, "label_template", e.to_string(), None, None);
        }
    };
    let source_fps = input.fps_override.unwrap_or(bvh.header_fps);
    let frames = bvh.motion.num_frames();
    let mut motion = bvh.motion;
    motion.fps = source_fps;
    let motion = motion.resample(input.fps);
    if motion.num_frames() == 0 {
        return reject(
            file,
            "empty",
            "capture has no frames".to_string(),
            None,
            None,
        );
    }
    let clip = Clip {
        clip_id: format!("{}:0-{frames}", file.stem()),
        kind: SourceKind::RealSingle,
        capture: CaptureRef {
            source: input.source.name.clone(),
            path: file.display.clone(),
            sha256: sha256_hex(input.bytes),
            fps: source_fps,
        },
        frame_range: (0, frames as u64),
        mirrored: false,
        action,
        text: caption,
        annotation: "filename".to_string(),
        attributes: fields,
        profile: input.profile.name.clone(),
        motion,
    };
    IngestOutput {
        clips: vec![clip],
        rejects: Vec::new(),
    }
}
