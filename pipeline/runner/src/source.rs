//! Sources: finding capture files from the config's globs and resolving skeleton profiles.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::config::{Config, LabelConfig, SourceConfig};
use motionforge_core::base::RejectReason;
use motionforge_core::motion::ProfileSpec;
use motionforge_sources::annotate::event_log::{self, EventLogFormat};
use motionforge_sources::annotate::filename::{
    FilenamePattern, LabelRefusal, PatternError, compiled_filename_annotation,
};
use motionforge_sources::annotate::span::{
    AnnotationError, CaptureAnnotation, Note, NoteKind, stem_of,
};
use motionforge_sources::annotate::{babel, frame_index};

/// A capture file found by a source's globs.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct CaptureFile {
    /// Index of the source in the config.
    pub source: usize,
    /// Path on disk.
    pub path: PathBuf,
    /// Path as shown in datasets and reports: relative to the config folder when under it.
    pub display: String,
}

impl CaptureFile {
    /// File stem (name without extension): the key annotations find the capture by. An AMASS
    /// `.npz` also loses its `_poses` suffix, as annotation paths do ([`capture_key`]): BABEL's
    /// `feat_p` and HumanML3D's `source_path` name `01_01_poses` files `01_01`.
    pub fn stem(&self) -> String {
        let stem = self
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let amass = self.path.extension().is_some_and(|e| e == "npz");
        match stem.strip_suffix("_poses") {
            Some(key) if amass && !key.is_empty() => key.to_string(),
            _ => stem,
        }
    }

    /// File name.
    pub fn file_name(&self) -> String {
        self.path
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    }
}

/// Errors resolving sources; these stop the build, as they are configuration mistakes.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// A glob pattern is malformed.
    #[error("source `{source_name}`: capture pattern `{pattern}` is not a valid glob: {message}")]
    Pattern {
        /// Source name.
        source_name: String,
        /// The pattern.
        pattern: String,
        /// The parser's message.
        message: String,
    },
    /// A pattern matched nothing: almost always a wrong path.
    #[error(
        "source `{source_name}`: capture pattern `{pattern}` matches no file (resolved as {resolved}); paths are relative to the config file"
    )]
    NoMatch {
        /// Source name.
        source_name: String,
        /// The pattern.
        pattern: String,
        /// The pattern after resolution.
        resolved: String,
    },
    /// An annotation file cannot be read or parsed at all.
    #[error("source `{source_name}`: {message}")]
    Annotation {
        /// Source name.
        source_name: String,
        /// What went wrong, naming the file and line.
        message: String,
    },
    /// A profile file cannot be read or parsed, or the name is unknown.
    #[error("source `{source_name}`: {message}")]
    Profile {
        /// Source name.
        source_name: String,
        /// What went wrong.
        message: String,
    },
}

/// All capture files of all sources, sorted by source then path, without duplicates.
pub fn discover(config: &Config) -> Result<Vec<CaptureFile>, SourceError> {
    let mut out = Vec::new();
    for (index, source) in config.sources.iter().enumerate() {
        let mut files = Vec::new();
        for pattern in &source.captures {
            let resolved = config.resolve(Path::new(pattern));
            let resolved_text = resolved.to_string_lossy().into_owned();
            let paths = glob::glob(&resolved_text).map_err(|e| SourceError::Pattern {
                source_name: source.name.clone(),
                pattern: pattern.clone(),
                message: e.to_string(),
            })?;
            let before = files.len();
            files.extend(paths.flatten().filter(|p| p.is_file()));
            if files.len() == before {
                return Err(SourceError::NoMatch {
                    source_name: source.name.clone(),
                    pattern: pattern.clone(),
                    resolved: resolved_text,
                });
            }
        }
        files.sort();
        files.dedup();
        out.extend(files.into_iter().map(|path| CaptureFile {
            source: index,
            display: display_path(&config.base_dir, &path),
            path,
        }));
    }
    Ok(out)
}

fn display_path(base: &Path, path: &Path) -> String {
    let shown = path.strip_prefix(base).unwrap_or(path);
    shown.to_string_lossy().replace('\\', "/")
}

/// The source's skeleton profile (bundled or from a file), with the source's `pairs` and
/// `reflections` overrides applied.
pub fn resolve_profile(config: &Config, source: &SourceConfig) -> Result<ProfileSpec, SourceError> {
    crate::config::resolve_profile(config, source).map_err(|message| SourceError::Profile {
        source_name: source.name.clone(),
        message,
    })
}

/// The frame-rate override for a file, if any: `fps_override` (file name or glob on the name),
/// then the source's fps table by capture key.
pub fn fps_override(
    source: &SourceConfig,
    table: &BTreeMap<String, f64>,
    file: &CaptureFile,
) -> Option<f64> {
    let name = file.file_name();
    source
        .fps_override
        .iter()
        .find_map(|(pattern, fps)| {
            let matches =
                pattern == &name || glob::Pattern::new(pattern).is_ok_and(|p| p.matches(&name));
            matches.then_some(*fps)
        })
        .or_else(|| table.get(&file.stem()).copied())
}

/// The source's fps table (path -> fps JSON) by capture key; empty without one.
pub fn load_fps_table(
    config: &Config,
    source: &SourceConfig,
) -> Result<BTreeMap<String, f64>, SourceError> {
    let Some(path) = &source.fps_table else {
        return Ok(BTreeMap::new());
    };
    let err = |message: String| SourceError::Annotation {
        source_name: source.name.clone(),
        message,
    };
    let file = config.resolve(Path::new(path));
    let text = std::fs::read_to_string(&file)
        .map_err(|e| err(format!("fps table {}: {e}", file.display())))?;
    let table: BTreeMap<String, f64> = serde_json::from_str(&text).map_err(|e| {
        err(format!(
            "fps table {}:{}: expected an object of path -> frame rate: {e}",
            file.display(),
            e.line()
        ))
    })?;
    let key_pattern = match &source.labels {
        LabelConfig::Babel { key_pattern, .. } | LabelConfig::FrameIndex { key_pattern, .. } => {
            key_pattern
                .as_deref()
                .and_then(|p| regex::Regex::new(p).ok())
        }
        _ => None,
    };
    Ok(table
        .into_iter()
        .filter(|(_, fps)| fps.is_finite() && *fps > 0.0)
        .map(|(path, fps)| (capture_key(&path, key_pattern.as_ref()), fps))
        .collect())
}

/// The quirks of the sources' annotation files: what their readers noted, an
/// `annotation_without_capture` note for every annotated capture key that no capture file of its
/// source has (`files`, as discovered), and an `amass_not_a_motion` note for every AMASS
/// `shape.npz` or `*_stagei.npz` the globs found (ingest skips them). `annotations` are the config's sources', in order.
pub fn annotation_notes(
    config: &Config,
    annotations: &[SourceAnnotations],
    files: &[CaptureFile],
) -> Vec<Note> {
    let matched: BTreeSet<(usize, String)> = files.iter().map(|f| (f.source, f.stem())).collect();
    let mut notes = Vec::new();
    for ((index, ann), source) in annotations.iter().enumerate().zip(&config.sources) {
        if let SourceAnnotations::Indexed {
            by_key,
            notes: file_notes,
        } = ann
        {
            notes.extend(file_notes.iter().cloned());
            for key in by_key
                .keys()
                .filter(|k| !matched.contains(&(index, (*k).clone())))
            {
                notes.push(Note::new(
                    NoteKind::AnnotationWithoutCapture,
                    format!(
                        "source `{}`: annotations for `{key}` match no capture file",
                        source.name
                    ),
                ));
            }
        }
    }
    // Files among the captures that hold no motion (AMASS's body shapes): skipped, and said so.
    notes.extend(files.iter().filter_map(|file| {
        let source = config.sources.get(file.source)?;
        crate::stages::ingest::format_of(source).skipped(file)
    }));
    notes
}

/// A source's annotations, loaded once before the per-capture stages.
#[derive(Debug, Clone)]
pub enum SourceAnnotations {
    /// Labels come from each capture's file name (and sidecar), made per capture.
    Filename {
        /// File-stem pattern, compiled (or why it does not compile, reported per capture).
        pattern: Result<FilenamePattern, PatternError>,
        /// Action template.
        action: String,
        /// Caption template.
        text: String,
        /// Whether sidecars are read.
        sidecar: bool,
    },
    /// Annotations read from files, by capture key (file stem).
    Indexed {
        /// Annotation per capture key.
        by_key: BTreeMap<String, CaptureAnnotation>,
        /// Quirks of the files that belong to no capture (unreadable records, ...).
        notes: Vec<Note>,
    },
}

impl SourceAnnotations {
    /// The annotation of the capture with file stem `stem` at `path`: made from its file name
    /// (and sidecar JSON beside it, when the source reads sidecars), or looked up by stem. A
    /// capture the source cannot label is refused with the reason; `kind` names the source's
    /// annotation format in the message.
    pub fn for_capture(
        &self,
        stem: &str,
        path: &Path,
        kind: &str,
    ) -> Result<CaptureAnnotation, LabelRefusal> {
        match self {
            SourceAnnotations::Filename {
                pattern,
                action,
                text,
                sidecar,
            } => {
                let side = if *sidecar {
                    let file = path.with_extension("json");
                    match std::fs::read(&file) {
                        Ok(bytes) => Some(bytes),
                        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
                        Err(e) => {
                            return Err(LabelRefusal {
                                reason: RejectReason::Sidecar,
                                message: format!("sidecar `{stem}.json`: {e}"),
                            });
                        }
                    }
                } else {
                    None
                };
                let pattern = pattern.as_ref().map_err(|e| LabelRefusal {
                    reason: RejectReason::LabelPattern,
                    message: e.to_string(),
                })?;
                compiled_filename_annotation(pattern, action, text, stem, side.as_deref())
            }
            SourceAnnotations::Indexed { by_key, .. } => {
                by_key.get(stem).cloned().ok_or_else(|| LabelRefusal {
                    reason: RejectReason::NoAnnotation,
                    message: format!(
                        "no annotation for capture `{stem}` in the source's {kind} files"
                    ),
                })
            }
        }
    }
}

fn annotation_files(
    config: &Config,
    source: &SourceConfig,
    pattern: &str,
) -> Result<Vec<PathBuf>, SourceError> {
    let resolved = config.resolve(Path::new(pattern));
    let text = resolved.to_string_lossy().into_owned();
    let mut files: Vec<PathBuf> = glob::glob(&text)
        .map_err(|e| SourceError::Pattern {
            source_name: source.name.clone(),
            pattern: pattern.to_string(),
            message: e.to_string(),
        })?
        .flatten()
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(SourceError::NoMatch {
            source_name: source.name.clone(),
            pattern: pattern.to_string(),
            resolved: text,
        });
    }
    Ok(files)
}

/// The capture key of an annotation path: the `key` group of `key_pattern`, or by default the
/// file stem without a `_poses` suffix (AMASS naming: `CMU/CMU/01/01_01_poses.npz` -> `01_01`).
pub fn capture_key(path: &str, key_pattern: Option<&regex::Regex>) -> String {
    if let Some(re) = key_pattern
        && let Some(m) = re.captures(path).and_then(|c| c.name("key"))
    {
        return m.as_str().to_string();
    }
    let stem = stem_of(path);
    stem.strip_suffix("_poses")
        .map(str::to_string)
        .unwrap_or(stem)
}

/// Loads a source's annotation files.
pub fn load_annotations(
    config: &Config,
    source: &SourceConfig,
) -> Result<SourceAnnotations, SourceError> {
    let failed = |e: AnnotationError| SourceError::Annotation {
        source_name: source.name.clone(),
        message: e.to_string(),
    };
    let read = |path: &Path| {
        std::fs::read_to_string(path).map_err(|e| SourceError::Annotation {
            source_name: source.name.clone(),
            message: format!("{}: {e}", path.display()),
        })
    };
    let key_regex = |p: &Option<String>| p.as_deref().and_then(|p| regex::Regex::new(p).ok());
    let mut by_key = BTreeMap::new();
    let mut notes = Vec::new();
    match &source.labels {
        LabelConfig::Filename {
            pattern,
            action,
            text,
            sidecar,
        } => {
            return Ok(SourceAnnotations::Filename {
                pattern: FilenamePattern::new(pattern),
                action: action.clone(),
                text: text.clone(),
                sidecar: *sidecar,
            });
        }
        LabelConfig::Babel { path, key_pattern } => {
            let re = key_regex(key_pattern);
            for file in annotation_files(config, source, path)? {
                let shown = display_path(&config.base_dir, &file);
                let records = babel::read_babel(&read(&file)?, &shown).map_err(failed)?;
                for r in records {
                    match &r.feat_p {
                        Some(p) => {
                            by_key.insert(capture_key(p, re.as_ref()), r.annotation);
                        }
                        None => notes.extend(r.annotation.notes),
                    }
                }
            }
        }
        LabelConfig::EventLog { path, fps } => {
            for file in annotation_files(config, source, path)? {
                let shown = display_path(&config.base_dir, &file);
                let format = if shown.to_ascii_lowercase().ends_with(".json") {
                    EventLogFormat::Json
                } else {
                    EventLogFormat::Csv
                };
                by_key.extend(
                    event_log::read_event_log(&read(&file)?, format, &shown, *fps)
                        .map_err(failed)?,
                );
            }
        }
        LabelConfig::FrameIndex {
            path,
            fps,
            texts,
            default_text,
            key_pattern,
            humanml3d_cuts,
        } => {
            let re = key_regex(key_pattern);
            let file = config.resolve(Path::new(path));
            let shown = display_path(&config.base_dir, &file);
            let (rows, read_notes) =
                frame_index::read_frame_index(&read(&file)?, &shown).map_err(failed)?;
            notes.extend(read_notes);
            let texts_dir = texts.as_ref().map(|t| config.resolve(Path::new(t)));
            // Quirks of caption files, gathered while the index asks for them.
            let caption_notes = std::cell::RefCell::new(Vec::new());
            // A missing file is no caption; one that cannot be opened or read is said so.
            let captions = |name: &str| {
                let dir = texts_dir.as_ref()?;
                let path = dir.join(format!("{}.txt", stem_of(name)));
                let shown = display_path(&config.base_dir, &path);
                match std::fs::File::open(&path) {
                    Ok(f) => {
                        let (lines, found) =
                            frame_index::read_caption_file(std::io::BufReader::new(f), &shown);
                        caption_notes.borrow_mut().extend(found);
                        Some(lines)
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
                    Err(e) => {
                        caption_notes.borrow_mut().push(Note::new(
                            NoteKind::CaptionUnreadable,
                            format!("{shown}: {e}"),
                        ));
                        Some(Vec::new())
                    }
                }
            };
            by_key = frame_index::index_annotations_with(
                &rows,
                &frame_index::IndexOptions {
                    fps: *fps,
                    humanml3d_cuts: *humanml3d_cuts,
                },
                &shown,
                |p| capture_key(p, re.as_ref()),
                captions,
                default_text,
            );
            notes.extend(caption_notes.into_inner());
        }
    }
    // Bounded per kind: one file's damage must not make the build's memory unbounded.
    let notes = motionforge_sources::annotate::span::cap_per_kind(
        notes,
        motionforge_sources::annotate::span::NOTES_PER_KIND,
    );
    Ok(SourceAnnotations::Indexed { by_key, notes })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn annotations_without_a_capture_are_noted_per_source_with_the_readers_notes() {
        let text = "[dataset]\nname = \"notes\"\noutput = \"out\"\n\n\
            [[sources]]\nname = \"first\"\ncaptures = [\"a/*.bvh\"]\nprofile = \"cmu\"\n\
            [sources.labels]\nkind = \"filename\"\npattern = \"^(?P<name>.+)$\"\naction = \"{name}\"\ntext = \"{name}\"\n\n\
            [[sources]]\nname = \"second\"\ncaptures = [\"b/*.bvh\"]\nprofile = \"cmu\"\n\
            [sources.labels]\nkind = \"filename\"\npattern = \"^(?P<name>.+)$\"\naction = \"{name}\"\ntext = \"{name}\"\n";
        let config = Config::parse(text, Path::new("notes.toml")).unwrap();
        let indexed = |keys: &[&str], notes: Vec<Note>| SourceAnnotations::Indexed {
            by_key: keys
                .iter()
                .map(|k| (k.to_string(), CaptureAnnotation::default()))
                .collect(),
            notes,
        };
        let annotations = [
            indexed(
                &["walk", "jump"],
                vec![Note::new(NoteKind::NullLabel, "record 3")],
            ),
            // `walk` is captured under the first source only: the second's key has no capture.
            indexed(&["walk"], Vec::new()),
        ];
        let file = |source: usize, path: &str| CaptureFile {
            source,
            path: PathBuf::from(path),
            display: path.to_string(),
        };
        let files = [file(0, "a/walk.bvh"), file(1, "b/run.bvh")];
        let notes = annotation_notes(&config, &annotations, &files);
        let kinds: Vec<(&str, &str)> = notes
            .iter()
            .map(|n| (n.kind.as_str(), n.message.as_str()))
            .collect();
        assert_eq!(
            kinds,
            [
                ("null_label", "record 3"),
                (
                    "annotation_without_capture",
                    "source `first`: annotations for `jump` match no capture file"
                ),
                (
                    "annotation_without_capture",
                    "source `second`: annotations for `walk` match no capture file"
                ),
            ]
        );
    }
}
