//! How a scene's problems are reported: [`SceneError`] and its messages, the problems collected
//! while resolving (at most [`MAX_PROBLEMS`] listed), and each problem's dotted key and line in
//! the file.

use std::cell::OnceCell;
use std::path::{Path, PathBuf};

use motionforge_core::base::toml_path::{self, SpannedToml};

/// The most problems a rejected scene lists (a file with a million bad names gets the first
/// ones, not a million lines).
const MAX_PROBLEMS: usize = 100;

/// The most names a message lists (`objects: cup, phone`); a longer list is cut with its count.
const MAX_NAMES_SHOWN: usize = 20;

/// Why a scene file cannot be used. Every variant names the file; problems name their key.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file cannot be read.
    #[error("scene {path}: cannot read: {source}")]
    Read {
        /// The scene file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is larger than a scene file may be
    /// ([`MAX_SCENE_BYTES`](super::MAX_SCENE_BYTES)).
    #[error(
        "scene {}: more than {limit} bytes, the most a scene file may have; split it into \
         smaller scenes",
        path.display()
    )]
    TooBig {
        /// The scene file.
        path: PathBuf,
        /// The limit, in bytes.
        limit: usize,
    },
    /// The file is not TOML.
    #[error("scene {}{}: {}", path.display(), at_line(*line), error.message().trim_end())]
    Syntax {
        /// The scene file.
        path: PathBuf,
        /// 1-based line, where known.
        line: Option<usize>,
        /// The parser's error. Not a `#[source]`: the message quotes its short form, and its
        /// full form (the file's lines) would be appended by whatever prints the causes. Boxed:
        /// it is large, and errors are rare.
        error: Box<toml::de::Error>,
    },
    /// The file is TOML but not of the scene's shape.
    #[error("scene {}{}: {}{}", path.display(), at_line(*line), key.as_deref().map(|k| format!("{k}: ")).unwrap_or_default(), error.message().trim_end())]
    Shape {
        /// The scene file.
        path: PathBuf,
        /// 1-based line, where known.
        line: Option<usize>,
        /// The dotted key of the value, `None` for the whole file.
        key: Option<String>,
        /// What the reader expected there (not a `#[source]`, and boxed, as for
        /// [`SceneError::Syntax`]).
        error: Box<toml::de::Error>,
    },
    /// Values parse but are not acceptable: every problem found.
    #[error("{}", invalid_message(path, problems, *unlisted))]
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// What is wrong, in file order where lines are known (at most the first 100 found).
        problems: Vec<SceneProblem>,
        /// Problems found beyond those listed.
        unlisted: usize,
    },
    /// The bundled motion-type taxonomy did not load (a build defect, not the scene's).
    #[error(transparent)]
    Taxonomy(#[from] motionforge_sources::annotate::taxonomy::TaxonomyError),
}

/// One problem of a scene: its dotted key, its line and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SceneProblem {
    /// Dotted key with array positions: `interactions[2].type`.
    pub key: String,
    /// 1-based line of the key (or of its table), where known.
    pub line: Option<usize>,
    /// What is wrong and what is expected.
    pub message: String,
}

/// `:line`, or nothing when the line is not known.
fn at_line(line: Option<usize>) -> String {
    line.map(|l| format!(":{l}")).unwrap_or_default()
}

fn invalid_message(path: &Path, problems: &[SceneProblem], unlisted: usize) -> String {
    let at = |p: &SceneProblem| match p.line {
        Some(line) => format!("{}:{line}: {}: {}", path.display(), p.key, p.message),
        None => format!("{}: {}: {}", path.display(), p.key, p.message),
    };
    match problems {
        [one] if unlisted == 0 => format!("scene {}", at(one)),
        many => {
            let mut text = format!(
                "scene {} has {} problems:",
                path.display(),
                many.len() + unlisted
            );
            for p in many {
                text.push_str("\n  ");
                text.push_str(&at(p));
            }
            if unlisted > 0 {
                text.push_str(&format!("\n  ... and {unlisted} more"));
            }
            text
        }
    }
}

/// `names` joined with `, `, the first [`MAX_NAMES_SHOWN`] of a longer list with its count.
pub(super) fn listing(names: &[String]) -> String {
    if names.len() <= MAX_NAMES_SHOWN {
        return names.join(", ");
    }
    format!(
        "{}, ... ({} in all)",
        names[..MAX_NAMES_SHOWN].join(", "),
        names.len()
    )
}

#[derive(Debug, Clone)]
pub(super) enum Seg {
    K(String),
    I(usize),
}

pub(super) fn segments(path: &serde_path_to_error::Path) -> Vec<Seg> {
    use serde_path_to_error::Segment;
    path.iter()
        .filter_map(|s| match s {
            Segment::Seq { index } => Some(Seg::I(*index)),
            Segment::Map { key } => Some(Seg::K(key.clone())),
            _ => None,
        })
        .collect()
}

/// `path` as the borrowed steps `base::toml_path` reads.
pub(super) fn steps(path: &[Seg]) -> Vec<toml_path::Seg<'_>> {
    path.iter()
        .map(|seg| match seg {
            Seg::K(k) => toml_path::Seg::K(k),
            Seg::I(i) => toml_path::Seg::I(*i),
        })
        .collect()
}

/// The lines of a scene's text: a byte offset's line by binary search (not by counting), and a
/// key's line from a spanned tree parsed only when a problem asks for one.
pub(super) struct Lines<'i> {
    text: &'i str,
    starts: Vec<usize>,
    tree: OnceCell<Option<SpannedToml<'i>>>,
}

impl<'i> Lines<'i> {
    pub(super) fn new(text: &'i str) -> Lines<'i> {
        let starts = std::iter::once(0)
            .chain(memchr::memchr_iter(b'\n', text.as_bytes()).map(|i| i + 1))
            .collect();
        Lines {
            text,
            starts,
            tree: OnceCell::new(),
        }
    }

    /// 1-based line of a byte offset.
    pub(super) fn at(&self, offset: usize) -> usize {
        self.starts.partition_point(|&s| s <= offset).max(1)
    }

    /// The line of the deepest part of `path` the file spells out.
    pub(super) fn line(&self, path: &[toml_path::Seg<'_>]) -> Option<usize> {
        let tree = self.tree.get_or_init(|| {
            toml::de::DeTable::parse(self.text)
                .ok()
                .map(|t| SpannedToml::new(self.text, t.into_inner()))
        });
        tree.as_ref()?.find(path).1.map(|s| self.at(s.start))
    }
}

pub(super) struct Problems<'a, 'i> {
    pub(super) lines: &'a Lines<'i>,
    pub(super) found: Vec<SceneProblem>,
    /// Problems found after the first [`MAX_PROBLEMS`], counted, not listed.
    pub(super) unlisted: usize,
}

impl Problems<'_, '_> {
    /// Problems found so far, listed or not.
    pub(super) fn count(&self) -> usize {
        self.found.len() + self.unlisted
    }

    pub(super) fn push(&mut self, path: &[Seg], message: String) {
        if self.found.len() >= MAX_PROBLEMS {
            self.unlisted += 1;
            return;
        }
        let path = steps(path);
        self.found.push(SceneProblem {
            key: toml_path::key_name(&path),
            line: self.lines.line(&path),
            message,
        });
    }
}

pub(super) fn k(s: &str) -> Seg {
    Seg::K(s.to_string())
}
