//! Labels from file names (one action per file, as in Bandai Namco's datasets), plus an optional
//! sidecar JSON beside each capture.

use std::collections::BTreeMap;

use regex::Regex;

use motionforge_core::base::RejectReason;
use motionforge_language::caption::{MAX_CAPTION_CHARS, over_length};

use super::span::{CaptureAnnotation, Span, Time};

/// Why a file-name pattern or template cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PatternError {
    /// The pattern is not a valid regex once placeholders are expanded.
    #[error("not a valid pattern: {0}")]
    Regex(#[source] regex::Error),
    /// An unclosed `{` in a pattern or template.
    #[error("unclosed `{{` in `{0}`")]
    Unclosed(String),
    /// A template names a field the pattern does not capture.
    #[error("`{{{field}}}` is not captured by the file-name pattern or the sidecar")]
    UnknownField {
        /// The field name.
        field: String,
    },
}

/// A compiled file-stem pattern.
#[derive(Debug, Clone)]
pub struct FilenamePattern {
    source: String,
    regex: Regex,
}

impl FilenamePattern {
    /// Compiles `dataset-1_{content}_{style}_{take}`-style patterns (each `{name}` matches one or
    /// more characters other than `_`), or a raw regex with named groups when it starts with `^`.
    pub fn new(pattern: &str) -> Result<FilenamePattern, PatternError> {
        let regex_text = if pattern.starts_with('^') {
            pattern.to_string()
        } else {
            let mut out = String::from("^");
            let mut rest = pattern;
            while let Some(open) = rest.find('{') {
                out.push_str(&regex::escape(&rest[..open]));
                let close = rest[open..]
                    .find('}')
                    .ok_or_else(|| PatternError::Unclosed(pattern.to_string()))?
                    + open;
                let name = &rest[open + 1..close];
                out.push_str(&format!("(?P<{name}>[^_]+)"));
                rest = &rest[close + 1..];
            }
            out.push_str(&regex::escape(rest));
            out.push('$');
            out
        };
        let regex = Regex::new(&regex_text).map_err(PatternError::Regex)?;
        Ok(FilenamePattern {
            source: pattern.to_string(),
            regex,
        })
    }

    /// The pattern as configured.
    pub fn as_str(&self) -> &str {
        &self.source
    }

    /// The named groups of a file stem, or `None` when it does not match.
    pub fn captures(&self, stem: &str) -> Option<BTreeMap<String, String>> {
        let caps = self.regex.captures(stem)?;
        Some(
            self.regex
                .capture_names()
                .flatten()
                .filter_map(|name| {
                    caps.name(name)
                        .map(|m| (name.to_string(), m.as_str().to_string()))
                })
                .collect(),
        )
    }
}

/// Fills `{field}` placeholders from `fields`. With `words`, `-` and `_` in values become spaces
/// (captions read as text; labels keep their spelling).
pub fn fill_template(
    template: &str,
    fields: &BTreeMap<String, String>,
    words: bool,
) -> Result<String, PatternError> {
    let mut out = String::new();
    let mut rest = template;
    while let Some(open) = rest.find('{') {
        out.push_str(&rest[..open]);
        let close = rest[open..]
            .find('}')
            .ok_or_else(|| PatternError::Unclosed(template.to_string()))?
            + open;
        let field = &rest[open + 1..close];
        let value = fields
            .get(field)
            .ok_or_else(|| PatternError::UnknownField {
                field: field.to_string(),
            })?;
        if words {
            out.push_str(&value.replace(['-', '_'], " "));
        } else {
            out.push_str(value);
        }
        rest = &rest[close + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

/// Flattens a sidecar JSON object into string attributes (numbers and booleans as written).
pub fn sidecar_fields(json: &serde_json::Value) -> Option<BTreeMap<String, String>> {
    let object = json.as_object()?;
    Some(
        object
            .iter()
            .filter_map(|(k, v)| {
                let s = match v {
                    serde_json::Value::String(s) => s.clone(),
                    serde_json::Value::Number(n) => n.to_string(),
                    serde_json::Value::Bool(b) => b.to_string(),
                    _ => return None,
                };
                Some((k.clone(), s))
            })
            .collect(),
    )
}

/// Why a capture's file name gives no label: a short reason and a message for people.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelRefusal {
    /// `label_pattern`, `sidecar` or `label_template`.
    pub reason: RejectReason,
    /// What was expected and found: the `Reject`'s message (kept as text: the kind is `reason`,
    /// and the runner builds refusals of its own from other readers' texts).
    pub message: String,
}

/// The annotation a file name (and its sidecar JSON) gives a capture: one span over the whole
/// capture, with the pattern's fields (and the sidecar's, as `sidecar.<key>`) as attributes.
pub fn filename_annotation(
    pattern: &str,
    action: &str,
    text: &str,
    stem: &str,
    sidecar: Option<&[u8]>,
) -> Result<CaptureAnnotation, LabelRefusal> {
    let compiled = FilenamePattern::new(pattern).map_err(|e| LabelRefusal {
        reason: RejectReason::LabelPattern,
        message: e.to_string(),
    })?;
    compiled_filename_annotation(&compiled, action, text, stem, sidecar)
}

/// [`filename_annotation`] with the pattern compiled once for every capture of a source.
pub fn compiled_filename_annotation(
    compiled: &FilenamePattern,
    action: &str,
    text: &str,
    stem: &str,
    sidecar: Option<&[u8]>,
) -> Result<CaptureAnnotation, LabelRefusal> {
    let refuse = |reason, message| LabelRefusal { reason, message };
    let pattern = compiled.as_str();
    let mut fields = compiled.captures(stem).ok_or_else(|| {
        refuse(
            RejectReason::LabelPattern,
            format!("file name `{stem}` does not match the label pattern `{pattern}`"),
        )
    })?;
    let mut overrides: BTreeMap<String, String> = BTreeMap::new();
    if let Some(bytes) = sidecar {
        // serde_json names the line and column of what it cannot read, a byte that is not UTF-8
        // included.
        let json = serde_json::from_slice::<serde_json::Value>(bytes).map_err(|e| {
            refuse(
                RejectReason::Sidecar,
                format!("sidecar `{stem}.json` is not a JSON object: {e}"),
            )
        })?;
        let side = sidecar_fields(&json).ok_or_else(|| {
            refuse(
                RejectReason::Sidecar,
                format!("sidecar `{stem}.json` is not a JSON object"),
            )
        })?;
        for (k, v) in side {
            if k == "action" || k == "text" {
                overrides.insert(k, v);
            } else {
                fields.entry(format!("sidecar.{k}")).or_insert(v);
            }
        }
    }
    let fill = |template: &str, words: bool, key: &str| match overrides.get(key) {
        Some(v) => Ok(v.clone()),
        None => fill_template(template, &fields, words)
            .map_err(|e| refuse(RejectReason::LabelTemplate, e.to_string())),
    };
    let label = fill(action, false, "action")?;
    let caption = fill(text, true, "text")?;
    // A sidecar can make any text a caption; the tagger and the readers take captions up to a
    // bound (docs/formats.md, "Caption files").
    for (what, value) in [("action", &label), ("text", &caption)] {
        if let Some(chars) = over_length(value) {
            let reason = if sidecar.is_some() {
                RejectReason::Sidecar
            } else {
                RejectReason::LabelTemplate
            };
            return Err(refuse(
                reason,
                format!(
                    "the {what} of `{stem}` has {chars} characters; a caption has at most \
                     {MAX_CAPTION_CHARS}"
                ),
            ));
        }
    }
    Ok(CaptureAnnotation {
        spans: vec![Span {
            start: Time::Seconds(0.0),
            end: Time::End,
            raw_text: caption,
            label,
            categories: Vec::new(),
            motion_type: None,
            hand: None,
            object: None,
            grasp: None,
            id: stem.to_string(),
            alternatives: Vec::new(),
        }],
        simultaneous: false,
        duration: None,
        origin: format!("file name {stem}"),
        notes: Vec::new(),
        attributes: fields,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bandai_names_split_on_underscores_and_keep_hyphens() {
        let p = FilenamePattern::new("dataset-1_{content}_{style}_{take}").unwrap();
        let f = p.captures("dataset-1_walk-left_not-confident_001").unwrap();
        assert_eq!(f["content"], "walk-left");
        assert_eq!(f["style"], "not-confident");
        assert_eq!(f["take"], "001");
        assert!(p.captures("dataset-2_walk_normal_001").is_none());
        assert_eq!(
            fill_template("{content}, {style} style", &f, true).unwrap(),
            "walk left, not confident style"
        );
        assert_eq!(fill_template("{content}", &f, false).unwrap(), "walk-left");
        assert!(matches!(
            fill_template("{mood}", &f, true),
            Err(PatternError::UnknownField { .. })
        ));
    }
}
