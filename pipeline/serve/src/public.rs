//! What the API may show anyone who asks: reading needs no token, so answers carry no absolute
//! filesystem path and echo no more than an excerpt of what the client sent.

use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::sync::LazyLock;

use regex::Regex;

/// Characters of client input an error message quotes.
pub(crate) const EXCERPT_CHARS: usize = 80;

/// At most `max` characters of `text`, with `…` when it was cut.
pub(crate) fn excerpt_of(text: &str, max: usize) -> Cow<'_, str> {
    match text.char_indices().nth(max) {
        None => Cow::Borrowed(text),
        Some((cut, _)) => Cow::Owned(format!("{}…", &text[..cut])),
    }
}

/// Client input as an error message quotes it: at most [`EXCERPT_CHARS`] characters.
pub(crate) fn excerpt(text: &str) -> Cow<'_, str> {
    excerpt_of(text, EXCERPT_CHARS)
}

/// An absolute path inside text: a `/` that starts the text or follows a space, quote, bracket,
/// `=` or `,`, up to a space, quote, closing bracket, `,`, `;` or `:` (the usual end of a path
/// in a message, as in `/data/a.bvh: cannot read`).
static ABSOLUTE: LazyLock<Option<Regex>> =
    LazyLock::new(|| Regex::new(r#"(^|[\s'"`(\[{<=,])(/[^\s'"`)\]}>,;:]*)"#).ok());

/// Shows filesystem paths relative to the service's working folder, and only the last part of
/// those outside it (`…/stats.json`).
#[derive(Debug, Clone)]
pub(crate) struct PathShield {
    root: Option<PathBuf>,
}

impl PathShield {
    /// Paths relative to `root` (the service's working folder); `None` shows every absolute path
    /// as its last part only.
    pub(crate) fn new(root: Option<PathBuf>) -> PathShield {
        PathShield { root }
    }

    /// A path as the API shows it.
    pub(crate) fn path(&self, path: &Path) -> String {
        if !path.is_absolute() {
            return path.display().to_string();
        }
        let path = motionforge_core::base::lexical_path(path);
        if let Some(root) = &self.root
            && let Ok(inside) = path.strip_prefix(root)
        {
            return if inside.as_os_str().is_empty() {
                ".".to_string()
            } else {
                inside.display().to_string()
            };
        }
        match path.file_name() {
            Some(name) => format!("…/{}", name.to_string_lossy()),
            None => "…".to_string(),
        }
    }

    /// `text` with every absolute path in it shown as [`PathShield::path`] shows it.
    pub(crate) fn text<'t>(&self, text: &'t str) -> Cow<'t, str> {
        let Some(absolute) = ABSOLUTE.as_ref() else {
            return Cow::Borrowed(text);
        };
        if !text.contains('/') {
            return Cow::Borrowed(text);
        }
        absolute.replace_all(text, |caps: &regex::Captures<'_>| {
            let lead = caps.get(1).map_or("", |m| m.as_str());
            let path = caps.get(2).map_or("", |m| m.as_str());
            format!("{lead}{}", self.path(Path::new(path)))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn excerpts_cut_on_characters() {
        assert_eq!(excerpt("demo"), "demo");
        let long = "é".repeat(200);
        let cut = excerpt(&long);
        assert_eq!(cut.chars().count(), EXCERPT_CHARS + 1);
        assert!(cut.ends_with('…'));
    }

    #[test]
    fn paths_show_relative_to_the_root_or_by_their_last_part() {
        let shield = PathShield::new(Some("/srv/mf".into()));
        assert_eq!(shield.path(Path::new("/srv/mf/out/demo")), "out/demo");
        assert_eq!(shield.path(Path::new("/srv/mf")), ".");
        assert_eq!(shield.path(Path::new("/srv/mf/../data/x.bvh")), "…/x.bvh");
        assert_eq!(shield.path(Path::new("/tmp/.tmpAb12/demo")), "…/demo");
        assert_eq!(shield.path(Path::new("/")), "…");
        assert_eq!(shield.path(Path::new("out/demo")), "out/demo");
        assert_eq!(
            PathShield::new(None).path(Path::new("/srv/mf/out")),
            "…/out"
        );
    }

    #[test]
    fn absolute_paths_in_text_are_shielded_and_urls_left_alone() {
        let shield = PathShield::new(Some("/srv/mf".into()));
        assert_eq!(
            shield.text("cannot read /data/bandai/a.bvh: no such file (os error 2)"),
            "cannot read …/a.bvh: no such file (os error 2)"
        );
        assert_eq!(
            shield.text("config `/srv/mf/demo.toml`, output=/srv/mf/out/demo"),
            "config `demo.toml`, output=out/demo"
        );
        assert_eq!(
            shield.text("/tmp/x/y.json is missing"),
            "…/y.json is missing"
        );
        let url = "POST http://127.0.0.1:8080/v1/chat/completions failed";
        assert_eq!(shield.text(url), url);
        assert_eq!(
            shield.text("ingest: finished, 9 ran"),
            "ingest: finished, 9 ran"
        );
    }
}
