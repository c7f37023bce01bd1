//! Config checks: every value against what it may be, and every file the config names, each
//! problem with its key, value, expectation and line, all reported at once.

use super::section_checks::check_features;
use super::*;

/// Longest dataset name: a folder name, within the 255-byte file-name limit of common file
/// systems with room for the prefixes and suffixes of temporary files.
pub(super) const MAX_NAME_BYTES: usize = 200;
/// Longest `<output>/<name>`: the files under it (`.motionforge/cache/<stage>/<pack name>`, up to
/// about 120 bytes more) must stay within Linux's 4096-byte path limit.
pub(super) const MAX_DATASET_PATH_BYTES: usize = 3800;

impl Config {
    /// The value checks, section by section in the order they are reported.
    pub(super) fn validate(&self, c: &mut Checks<'_>) {
        use Seg::K;
        self.dataset.check(&[K("dataset")], c);
        self.paraphrases.check(&[K("paraphrases")], c);
        self.splits.check(&[K("splits")], c);
        self.synthetic.check(&[K("synthetic")], c);
        check_features(&self.features, &[K("features")], c);
        if let Some(llm) = &self.llm {
            validate_llm(llm, c);
        }
        self.check_top_level_paths(c);
        if self.sources.is_empty() {
            c.push(
                &[K("sources")],
                "[]".into(),
                "at least one [[sources]] table",
            );
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, source) in self.sources.iter().enumerate() {
            source.check(&[K("sources"), Seg::I(i)], self.dataset.fps, &mut names, c);
        }
    }

    /// Checks what the config names on disk, reporting every problem at once: each capture
    /// pattern matches a file (and says when its folder is missing), profiles are known or
    /// readable, annotation files, fps tables, the split file, the taxonomy and the prompt folder
    /// exist and load, and the output folder is not a file. [`Config::load`] checks values only.
    pub fn check_inputs(&self, path: &Path) -> Result<InputSummary, ConfigError> {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        let tree = toml::de::DeTable::parse(&text)
            .map(|t| t.into_inner())
            .unwrap_or_default();
        let mut checks = Checks::new(&text, tree);
        let summary = self.check_inputs_into(&mut checks);
        checks.finish(path)?;
        Ok(summary)
    }

    /// The file checks, section by section in the order they are reported; capture counts and
    /// warnings go to the summary.
    pub(super) fn check_inputs_into(&self, c: &mut Checks<'_>) -> InputSummary {
        let mut summary = InputSummary::default();
        self.check_output_cache_and_prompts(c);
        self.check_motion_type_files(c);
        self.check_split_file(c);
        self.warn_of_unset_api_key(&mut summary);
        for (i, source) in self.sources.iter().enumerate() {
            source.check_files(self, &[Seg::K("sources"), Seg::I(i)], &mut summary, c);
        }
        summary
    }

    /// Files a pattern relative to the config matches (none for a malformed pattern).
    pub(super) fn glob_files(&self, pattern: &str) -> Vec<PathBuf> {
        let resolved = self.resolve(Path::new(pattern));
        glob::glob(&resolved.to_string_lossy())
            .map(|paths| paths.flatten().filter(|p| p.is_file()).collect())
            .unwrap_or_default()
    }

    /// What a pattern that matched nothing was expected to match, and why it may not have.
    pub(super) fn no_match(&self, pattern: &str, what: &str) -> String {
        let resolved = self.resolve(Path::new(pattern));
        // The folder part before the first wildcard: missing folders are the usual mistake.
        let fixed: PathBuf = resolved
            .components()
            .take_while(|c| !c.as_os_str().to_string_lossy().contains(['*', '?', '[']))
            .collect();
        let folder = if fixed == resolved {
            fixed.parent().map(Path::to_path_buf).unwrap_or_default()
        } else {
            fixed
        };
        let why = if folder.as_os_str().is_empty() || folder.is_dir() {
            String::new()
        } else {
            format!("; folder {} does not exist", folder.display())
        };
        let nearby = extension_of(&resolved)
            .map(|ext| found_nearby(&folder, &ext))
            .unwrap_or_default();
        format!(
            "a pattern that matches {what} (resolved as {}{why}; paths are relative to the config file){nearby}",
            resolved.display()
        )
    }
}

/// The extension a pattern's file name asks for (`bvh` of `data/*.bvh`), when it is literal.
fn extension_of(pattern: &Path) -> Option<String> {
    let name = pattern.file_name()?.to_string_lossy().into_owned();
    let (_, ext) = name.rsplit_once('.')?;
    (!ext.is_empty() && !ext.contains(['*', '?', '[', ']'])).then(|| ext.to_string())
}

/// Where files with extension `ext` (any case) are, near `folder`: folders within three levels
/// of its nearest existing ancestor (of its parent when `folder` exists), with their counts, as a hint after a pattern that
/// matched nothing. The walk stops after 20,000 entries so a pattern under `/` stays quick.
fn found_nearby(folder: &Path, ext: &str) -> String {
    const MAX_ENTRIES: usize = 20_000;
    const MAX_DEPTH: usize = 3;
    // An existing folder without such files: look at its siblings too.
    let start = if folder.is_dir() {
        folder.parent().filter(|p| p.is_dir()).or(Some(folder))
    } else {
        // A relative pattern's ancestors end in "", which is the working folder.
        folder
            .ancestors()
            .find(|a| a.is_dir())
            .or(Some(Path::new(".")))
    };
    let Some(start) = start else {
        return String::new();
    };
    let mut counts: std::collections::BTreeMap<PathBuf, usize> = Default::default();
    let mut queue = std::collections::VecDeque::from([(start.to_path_buf(), 0)]);
    let mut seen = 0;
    while let Some((dir, depth)) = queue.pop_front() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut entries: Vec<_> = entries.flatten().map(|e| e.path()).collect();
        // Sorted so the hint is the same on every run.
        entries.sort();
        for path in entries {
            seen += 1;
            if seen > MAX_ENTRIES {
                break;
            }
            let is_link = path.symlink_metadata().is_ok_and(|m| m.is_symlink());
            if path.is_dir() && !is_link {
                if depth < MAX_DEPTH {
                    queue.push_back((path, depth + 1));
                }
            } else if path
                .extension()
                .is_some_and(|e| e.to_string_lossy().eq_ignore_ascii_case(ext))
            {
                *counts.entry(dir.clone()).or_insert(0) += 1;
            }
        }
    }
    if counts.is_empty() {
        return format!(
            "; no .{ext} file within {MAX_DEPTH} levels of {}",
            start.display()
        );
    }
    let mut folders: Vec<(PathBuf, usize)> = counts.into_iter().collect();
    folders.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    let listed: Vec<String> = folders
        .iter()
        .take(3)
        .map(|(dir, n)| format!("{} ({n})", dir.display()))
        .collect();
    let more = folders.len().saturating_sub(3);
    let more = if more > 0 {
        format!(" and {more} more folders")
    } else {
        String::new()
    };
    format!("; .{ext} files are in {}{more}", listed.join(", "))
}

pub(super) fn round6(x: f64) -> f64 {
    (x * 1e6).round() / 1e6
}

pub(super) use motionforge_core::base::toml_path::{Seg, line_of};
use motionforge_core::base::toml_path::{SpannedToml, key_name};

/// Problems found while checking a config, with the lines of their keys.
pub(super) struct Checks<'i> {
    doc: SpannedToml<'i>,
    problems: Vec<Problem>,
}

impl<'i> Checks<'i> {
    pub(super) fn new(text: &'i str, root: toml::de::DeTable<'i>) -> Checks<'i> {
        Checks {
            doc: SpannedToml::new(text, root),
            problems: Vec::new(),
        }
    }

    pub(super) fn push(&mut self, path: &[Seg<'_>], value: String, expected: &str) {
        self.problems.push(Problem {
            key: key_name(path),
            value,
            expected: expected.to_string(),
            line: self.line(path),
        });
    }

    /// The line of the deepest part of `path` the file spells out (a key left at its default
    /// points at its table).
    pub(super) fn line(&self, path: &[Seg<'_>]) -> Option<usize> {
        self.doc.line(path)
    }

    /// The line of `path` itself, if the file spells all of it out.
    pub(super) fn exact_line(&self, path: &[Seg<'_>]) -> Option<usize> {
        self.doc.exact_line(path)
    }

    pub(super) fn finish(mut self, path: &Path) -> Result<(), ConfigError> {
        if self.problems.is_empty() {
            return Ok(());
        }
        self.problems.sort_by_key(|p| p.line.unwrap_or(usize::MAX));
        Err(ConfigError::Invalid {
            path: path.to_path_buf(),
            problems: self.problems,
        })
    }
}

pub(super) fn validate_llm(llm: &motionforge_llm::client::LlmConfig, c: &mut Checks<'_>) {
    use Seg::K;
    let key = |k: &'static str| [K("llm"), K(k)];
    let root = llm.base_url.trim_end_matches('/');
    if !reqwest::Url::parse(root).is_ok_and(|u| matches!(u.scheme(), "http" | "https")) {
        c.push(
            &key("base_url"),
            format!("{:?}", llm.base_url),
            "an http(s) URL of the API root, e.g. \"http://127.0.0.1:8080/v1\"",
        );
    }
    if llm.model.trim().is_empty() {
        c.push(&key("model"), format!("{:?}", llm.model), "a model name");
    }
    if llm
        .api_key_env
        .as_ref()
        .is_some_and(|v| v.trim().is_empty())
    {
        c.push(
            &key("api_key_env"),
            "\"\"".into(),
            "the name of the environment variable that holds the API key",
        );
    }
    if !(llm.temperature.is_finite() && llm.temperature >= 0.0) {
        c.push(
            &key("temperature"),
            llm.temperature.to_string(),
            "0 or more",
        );
    }
    if llm.max_tokens == 0 {
        c.push(&key("max_tokens"), "0".into(), "at least 1 token");
    }
    if let Some(bigger) = llm.retry_max_tokens
        && bigger <= llm.max_tokens
    {
        c.push(
            &key("retry_max_tokens"),
            bigger.to_string(),
            &format!(
                "more than max_tokens ({}): the retry of a cut-off answer asks for more",
                llm.max_tokens
            ),
        );
    }
    if llm.circuit_breaker_failures == 0 {
        c.push(
            &key("circuit_breaker_failures"),
            "0".into(),
            "at least 1 connection failure",
        );
    }
    if llm.concurrency == 0 {
        c.push(&key("concurrency"), "0".into(), "at least 1 request");
    }
    if llm.requests_per_minute == 0 {
        c.push(
            &key("requests_per_minute"),
            "0".into(),
            "at least 1 request per minute",
        );
    }
    if !(llm.timeout_seconds.is_finite() && llm.timeout_seconds > 0.0) {
        c.push(
            &key("timeout_seconds"),
            llm.timeout_seconds.to_string(),
            "more than 0 seconds",
        );
    }
    for (k, v) in [
        ("backoff_seconds", llm.backoff_seconds),
        ("max_retry_after_seconds", llm.max_retry_after_seconds),
    ] {
        if !(v.is_finite() && (0.0..=86_400.0).contains(&v)) {
            c.push(&key(k), v.to_string(), "between 0 and 86400 seconds");
        }
    }
}

#[cfg(test)]
mod nearby_tests {
    use super::*;

    #[test]
    fn a_pattern_that_matches_nothing_points_to_files_with_its_extension() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("captures/bandai")).unwrap();
        for name in ["a.BVH", "b.bvh", "notes.txt"] {
            std::fs::write(dir.path().join("captures/bandai").join(name), "x").unwrap();
        }
        // The user wrote `capture/*.bvh` (missing `s`, wrong depth).
        let hint = found_nearby(&dir.path().join("capture"), "bvh");
        let expected = format!(
            "; .bvh files are in {} (2)",
            dir.path().join("captures/bandai").display()
        );
        assert_eq!(hint, expected);
        assert_eq!(extension_of(Path::new("x/*.bvh")).as_deref(), Some("bvh"));
        assert_eq!(extension_of(Path::new("x/*")), None);
        let none = found_nearby(&dir.path().join("capture"), "npz");
        assert!(
            none.starts_with("; no .npz file within 3 levels of"),
            "{none}"
        );
    }
}
