//! Where a key of a TOML file is: key paths as people read them (`sources[0].fps_override."*"`)
//! and the line a path points at, for errors that name both. Used by the build config's checks
//! and the planner's scene files.

use std::ops::Range;

/// One step of a key path: a table key or an array position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Seg<'a> {
    /// A table key.
    K(&'a str),
    /// An array position.
    I(usize),
}

/// The path as written in messages: bare keys joined by `.`, other keys quoted, positions in
/// brackets (`sources[0].fps_override."*"`).
pub fn key_name(path: &[Seg<'_>]) -> String {
    let mut key = String::new();
    for seg in path {
        match seg {
            Seg::K(k) => {
                if !key.is_empty() {
                    key.push('.');
                }
                if !k.is_empty()
                    && k.chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
                {
                    key.push_str(k);
                } else {
                    key.push_str(&format!("{k:?}"));
                }
            }
            Seg::I(i) => key.push_str(&format!("[{i}]")),
        }
    }
    key
}

/// 1-based line of a byte offset.
pub fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|b| **b == b'\n')
        .count()
        + 1
}

/// A TOML file's text with its spanned tree, to find the line of a key path.
pub struct SpannedToml<'i> {
    text: &'i str,
    root: toml::de::DeValue<'i>,
}

impl<'i> SpannedToml<'i> {
    /// The tree `root` parsed from `text`.
    pub fn new(text: &'i str, root: toml::de::DeTable<'i>) -> SpannedToml<'i> {
        SpannedToml {
            text,
            root: toml::de::DeValue::Table(root),
        }
    }

    /// The line of the deepest part of `path` the file spells out (a key left at its default
    /// points at its table).
    pub fn line(&self, path: &[Seg<'_>]) -> Option<usize> {
        self.find(path).1.map(|s| line_of(self.text, s.start))
    }

    /// The line of `path` itself, if the file spells all of it out.
    pub fn exact_line(&self, path: &[Seg<'_>]) -> Option<usize> {
        match self.find(path) {
            (found, Some(span)) if found == path.len() => Some(line_of(self.text, span.start)),
            _ => None,
        }
    }

    /// How many steps of `path` the file has, and the span of the last one found.
    pub fn find(&self, path: &[Seg<'_>]) -> (usize, Option<Range<usize>>) {
        let mut value = &self.root;
        let mut span = None;
        let mut found = 0;
        for seg in path {
            let next = match seg {
                Seg::K(k) => value.get(*k),
                Seg::I(i) => value.get(*i),
            };
            let Some(next) = next else { break };
            span = Some(next.span());
            value = next.get_ref();
            found += 1;
        }
        (found, span)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_read_as_written_and_point_at_their_lines() {
        let text = "[dataset]\nname = \"demo\"\n\n[[sources]]\nfps_override = { \"*\" = 0.001 }\n";
        let root = toml::de::DeTable::parse(text).unwrap().into_inner();
        let doc = SpannedToml::new(text, root);
        let path = [
            Seg::K("sources"),
            Seg::I(0),
            Seg::K("fps_override"),
            Seg::K("*"),
        ];
        assert_eq!(key_name(&path), "sources[0].fps_override.\"*\"");
        assert_eq!(doc.line(&path), Some(5));
        assert_eq!(
            doc.exact_line(&[Seg::K("dataset"), Seg::K("name")]),
            Some(2)
        );
        // A key the file leaves out points at its table, and has no exact line.
        assert_eq!(doc.line(&[Seg::K("dataset"), Seg::K("fps")]), Some(1));
        assert_eq!(doc.exact_line(&[Seg::K("dataset"), Seg::K("fps")]), None);
    }
}
