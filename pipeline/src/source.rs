//! Sources: finding capture files from the config's globs and resolving skeleton profiles.

use std::path::{Path, PathBuf};

use crate::config::{Config, SourceConfig};
use crate::motion::ProfileSpec;

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
    /// File stem (name without extension).
    pub fn stem(&self) -> String {
        self.path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
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

/// The profile a source names (bundled, or a TOML file relative to the config), with the source's
/// `pairs` and `reflections` overrides applied.
pub fn resolve_profile(config: &Config, source: &SourceConfig) -> Result<ProfileSpec, SourceError> {
    let mut spec = load_profile(config, source)?;
    spec.pairs.extend(source.pairs.clone());
    spec.reflections.extend(source.reflections.clone());
    Ok(spec)
}

fn load_profile(config: &Config, source: &SourceConfig) -> Result<ProfileSpec, SourceError> {
    let err = |message: String| SourceError::Profile {
        source_name: source.name.clone(),
        message,
    };
    if source.profile.ends_with(".toml") {
        let path = config.resolve(Path::new(&source.profile));
        let text = std::fs::read_to_string(&path)
            .map_err(|e| err(format!("profile {}: {e}", path.display())))?;
        ProfileSpec::from_toml(&source.profile, &text).map_err(|e| err(e.to_string()))
    } else {
        ProfileSpec::bundled(&source.profile).map_err(|e| err(e.to_string()))
    }
}

/// The frame-rate override for a file, if any (matched by file name or glob on the name).
pub fn fps_override(source: &SourceConfig, file: &CaptureFile) -> Option<f64> {
    let name = file.file_name();
    source.fps_override.iter().find_map(|(pattern, fps)| {
        let matches =
            pattern == &name || glob::Pattern::new(pattern).is_ok_and(|p| p.matches(&name));
        matches.then_some(*fps)
    })
}
