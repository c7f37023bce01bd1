//! `split`: which split every capture belongs to. Clips, their mirrors and synthetic pairs always
//! land in the split of their source capture; the build checks that over the written shards.

use std::collections::BTreeMap;

use sha2::{Digest, Sha256};

use crate::config::Config;
pub use crate::config::SplitConfig;
use motionforge_sources::clip::{Clip, Split};

/// Why splits cannot be assigned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SplitError {
    /// The split file names a capture twice with different splits.
    #[error(
        "{file}:{line}: capture `{capture}` is assigned to `{second}`, but line {first_line} assigns it to `{first}`; a capture must be in one split"
    )]
    Conflict {
        /// The split file.
        file: String,
        /// Line of the second assignment.
        line: usize,
        /// Line of the first assignment.
        first_line: usize,
        /// The capture.
        capture: String,
        /// First split.
        first: String,
        /// Second split.
        second: String,
    },
    /// A row of the split file is malformed.
    #[error("{file}:{line}: expected `capture,split`, found `{found}`")]
    Row {
        /// The split file.
        file: String,
        /// 1-based line.
        line: usize,
        /// The row.
        found: String,
    },
    /// The split file cannot be read.
    #[error("{}: {message}", file.display())]
    Read {
        /// The split file.
        file: std::path::PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The split file names a split the ratios do not.
    #[error("{file}:{line}: split `{split}` is not one of the configured splits ({known})")]
    UnknownSplit {
        /// The split file.
        file: String,
        /// 1-based line.
        line: usize,
        /// The split.
        split: String,
        /// Configured split names.
        known: String,
    },
}

/// Assigns splits to captures.
#[derive(Debug, Clone)]
pub struct Splits {
    order: Vec<(String, f64)>,
    subject: Option<regex::Regex>,
    listed: BTreeMap<String, String>,
}

/// Split names in a stable order ([`Split`]'s: train, val(idation), test, then the rest
/// alphabetically), each once.
pub fn split_order(names: impl IntoIterator<Item = Split>) -> Vec<Split> {
    let mut v: Vec<Split> = names.into_iter().collect();
    v.sort();
    v.dedup();
    v
}

impl Splits {
    /// The assignment a build uses: `[splits]` of `config`, with its split file read from disk
    /// (relative to the config's folder).
    pub fn from_config(config: &Config) -> Result<Splits, SplitError> {
        let text = match &config.splits.file {
            Some(name) => {
                let path = config.resolve(std::path::Path::new(name));
                let text = std::fs::read_to_string(&path).map_err(|e| SplitError::Read {
                    file: path,
                    message: e.to_string(),
                })?;
                Some((name.as_str(), text))
            }
            None => None,
        };
        Splits::new(&config.splits, text.as_ref().map(|(n, t)| (*n, t.as_str())))
    }

    /// Puts `clip` in the split of its capture (by the path shown in the table, or its stem).
    pub fn assign(&self, clip: &mut Clip) {
        let stem = std::path::Path::new(&clip.capture.path)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        clip.split = Split::new(self.split_of(&clip.capture.path, &stem));
    }

    /// Builds the assignment from the config and the split file's text (if any).
    pub fn new(config: &SplitConfig, file: Option<(&str, &str)>) -> Result<Splits, SplitError> {
        let total: f64 = config.ratios.values().filter(|r| **r > 0.0).sum();
        let order: Vec<(String, f64)> = split_order(config.ratios.keys().map(Split::new))
            .into_iter()
            .map(|n| {
                let n = n.as_str().to_string();
                let r = config.ratios.get(&n).copied().unwrap_or(0.0).max(0.0);
                (n, if total > 0.0 { r / total } else { 0.0 })
            })
            .collect();
        let subject = config
            .subject_pattern
            .as_deref()
            .and_then(|p| regex::Regex::new(p).ok());
        let mut listed: BTreeMap<String, (String, usize)> = BTreeMap::new();
        if let Some((name, text)) = file {
            let known = order
                .iter()
                .map(|(n, _)| n.as_str())
                .collect::<Vec<_>>()
                .join(", ");
            for (i, row) in text.lines().enumerate() {
                let line = i + 1;
                let row = row.trim();
                if row.is_empty()
                    || row.starts_with('#')
                    || (line == 1 && row.eq_ignore_ascii_case("capture,split"))
                {
                    continue;
                }
                let Some((capture, split)) = row.split_once(',').map(|(c, s)| (c.trim(), s.trim()))
                else {
                    return Err(SplitError::Row {
                        file: name.into(),
                        line,
                        found: row.into(),
                    });
                };
                if capture.is_empty() || split.is_empty() {
                    return Err(SplitError::Row {
                        file: name.into(),
                        line,
                        found: row.into(),
                    });
                }
                if !order.iter().any(|(n, _)| n == split) {
                    return Err(SplitError::UnknownSplit {
                        file: name.into(),
                        line,
                        split: split.into(),
                        known,
                    });
                }
                if let Some((first, first_line)) = listed.get(capture)
                    && first != split
                {
                    return Err(SplitError::Conflict {
                        file: name.into(),
                        line,
                        first_line: *first_line,
                        capture: capture.into(),
                        first: first.clone(),
                        second: split.into(),
                    });
                }
                listed.insert(capture.to_string(), (split.to_string(), line));
            }
        }
        Ok(Splits {
            order,
            subject,
            listed: listed.into_iter().map(|(k, (s, _))| (k, s)).collect(),
        })
    }

    /// The split of a capture, from its path as shown in the table and its file stem.
    pub fn split_of(&self, path: &str, stem: &str) -> String {
        if let Some(s) = self.listed.get(path).or_else(|| self.listed.get(stem)) {
            return s.clone();
        }
        let unit = self
            .subject
            .as_ref()
            .and_then(|re| {
                re.captures(path)
                    .and_then(|c| c.name("subject"))
                    .map(|m| m.as_str().to_string())
            })
            .unwrap_or_else(|| path.to_string());
        let digest = Sha256::digest(unit.as_bytes());
        let mut head = [0u8; 8];
        head.copy_from_slice(&digest[..8]);
        let u = u64::from_be_bytes(head) as f64 / 2f64.powi(64);
        let mut acc = 0.0;
        for (name, share) in &self.order {
            acc += share;
            if u < acc {
                return name.clone();
            }
        }
        self.order
            .last()
            .map(|(n, _)| n.clone())
            .unwrap_or_else(|| Split::TRAIN.into())
    }

    /// Configured split names, in order.
    pub fn names(&self) -> Vec<String> {
        self.order.iter().map(|(n, _)| n.clone()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hashing_follows_the_ratios_and_is_stable() {
        let s = Splits::new(&SplitConfig::default(), None).unwrap();
        let mut counts: BTreeMap<String, usize> = BTreeMap::new();
        for i in 0..10_000 {
            *counts
                .entry(s.split_of(&format!("captures/take_{i}.bvh"), "x"))
                .or_insert(0) += 1;
        }
        let share = |n: &str| counts[n] as f64 / 10_000.0;
        assert!(
            (share("train") - 0.8).abs() < 0.02 && (share("validation") - 0.1).abs() < 0.02,
            "{counts:?}"
        );
        assert_eq!(s.split_of("a/b.bvh", "b"), s.split_of("a/b.bvh", "b"));
    }

    #[test]
    fn a_capture_in_two_splits_is_refused_with_both_lines() {
        let err = Splits::new(
            &SplitConfig::default(),
            Some((
                "splits.csv",
                "capture,split\nwalk_001,train\nkick_001,validation\nwalk_001,test\n",
            )),
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("splits.csv:4") && err.contains("line 2") && err.contains("walk_001"),
            "{err}"
        );
    }

    #[test]
    fn subjects_share_a_split() {
        let cfg = SplitConfig {
            subject_pattern: Some(r"(?P<subject>\d+)_\d+\.bvh$".into()),
            ..SplitConfig::default()
        };
        let s = Splits::new(&cfg, None).unwrap();
        for subject in 0..50 {
            let a = s.split_of(&format!("cmu/{subject}_01.bvh"), "");
            let b = s.split_of(&format!("cmu/{subject}_02.bvh"), "");
            assert_eq!(a, b);
        }
    }
}
