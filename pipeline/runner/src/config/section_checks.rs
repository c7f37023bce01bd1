//! The value checks of the dataset-wide sections (`[dataset]`, `[paraphrases]`, `[splits]`,
//! `[synthetic]`, `[features]`, the top-level paths), each beside the others and called in file
//! order by [`Config::validate`]; and the checks of the files and folders those sections name.

use super::checks::{MAX_DATASET_PATH_BYTES, MAX_NAME_BYTES, round6};
use super::*;

/// `at` followed by `rest`: the key path of a value inside the section at `at`.
pub(super) fn key_at<'a>(at: &[Seg<'a>], rest: &[Seg<'a>]) -> Vec<Seg<'a>> {
    let mut path = at.to_vec();
    path.extend_from_slice(rest);
    path
}

impl DatasetConfig {
    /// The dataset's name (a folder name), output folder, frame rate and shard settings.
    pub(super) fn check(&self, at: &[Seg<'_>], c: &mut Checks<'_>) {
        use Seg::K;
        let d = self;
        if d.name.is_empty()
            || d.name == "."
            || d.name == ".."
            || !d
                .name
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || "-_.".contains(ch))
        {
            c.push(
                &key_at(at, &[K("name")]),
                format!("{:?}", d.name),
                "a non-empty name of letters, digits, `-`, `_`, `.` (not `.` or `..`): it names the dataset folder",
            );
        }
        if d.name.len() > MAX_NAME_BYTES {
            c.push(
                &key_at(at, &[K("name")]),
                format!("{} characters", d.name.len()),
                &format!(
                    "at most {MAX_NAME_BYTES} characters: it names the dataset folder, and file systems refuse names over 255 bytes (the rest is room for temporary-file prefixes and suffixes)"
                ),
            );
        }
        if d.output.as_os_str().len() + d.name.len() > MAX_DATASET_PATH_BYTES {
            c.push(
                &key_at(at, &[K("output")]),
                format!("{} bytes with the name", d.output.as_os_str().len() + d.name.len()),
                &format!(
                    "a dataset folder path of at most {MAX_DATASET_PATH_BYTES} bytes: files inside it must stay within the system's 4096-byte path limit"
                ),
            );
        }
        if d.output.as_os_str().is_empty() {
            c.push(
                &key_at(at, &[K("output")]),
                "\"\"".into(),
                "a folder path (relative to the config file)",
            );
        }
        if !(d.fps.is_finite() && d.fps > 0.0 && d.fps <= 1000.0) {
            c.push(
                &key_at(at, &[K("fps")]),
                d.fps.to_string(),
                "a frame rate above 0 and at most 1000",
            );
        }
        if d.shard_bytes < 1024 {
            c.push(
                &key_at(at, &[K("shard_bytes")]),
                d.shard_bytes.to_string(),
                "at least 1024 bytes",
            );
        }
        if !(-7..=22).contains(&d.zstd_level) || d.zstd_level == 0 {
            c.push(
                &key_at(at, &[K("zstd_level")]),
                d.zstd_level.to_string(),
                "a zstd level from 1 to 22 (smallest), or -1 to -7 (zstd's fast levels: faster, larger)",
            );
        }
    }
}

impl ParaphraseConfig {
    /// How many alternatives are asked for, and what becomes of invalid ones.
    pub(super) fn check(&self, at: &[Seg<'_>], c: &mut Checks<'_>) {
        use Seg::K;
        if self.n == 0 || self.n > 50 {
            c.push(
                &key_at(at, &[K("n")]),
                self.n.to_string(),
                "between 1 and 50 alternatives",
            );
        }
        if self.on_invalid == OnInvalid::Embedded {
            c.push(
                &key_at(at, &[K("on_invalid")]),
                "\"embedded\"".into(),
                "\"drop\" or \"keep\": there is no embedded paraphraser to fall back to",
            );
        }
    }
}

impl SplitConfig {
    /// Split names (they name shard files) and shares, the subject pattern and the split file.
    pub(super) fn check(&self, at: &[Seg<'_>], c: &mut Checks<'_>) {
        use Seg::K;
        let ratios = key_at(at, &[K("ratios")]);
        if self.ratios.is_empty() {
            c.push(
                &ratios,
                "{}".into(),
                "split names with shares, e.g. { train = 0.8, validation = 0.1, test = 0.1 }",
            );
        }
        for (name, share) in &self.ratios {
            let ratio = key_at(&ratios, &[K(name)]);
            // Split names become shard file names (`<split>-00000-of-00001.parquet`).
            if name.is_empty()
                || name.starts_with('.')
                || !name
                    .chars()
                    .all(|ch| ch.is_ascii_alphanumeric() || "-_.".contains(ch))
            {
                c.push(
                    &ratio,
                    format!("{name:?}"),
                    "a split name of letters, digits, `-`, `_`, `.` (it names shard files)",
                );
            }
            if !(share.is_finite() && (0.0..=1.0).contains(share)) {
                c.push(&ratio, share.to_string(), "a share between 0 and 1");
            }
        }
        let sum: f64 = self.ratios.values().sum();
        if !self.ratios.is_empty()
            && self.ratios.values().all(|r| r.is_finite())
            && (sum - 1.0).abs() > 1e-6
        {
            c.push(
                &ratios,
                self.shown_ratios(),
                &format!("shares that sum to 1 (they sum to {})", round6(sum)),
            );
        }
        if let Some(p) = &self.subject_pattern
            && !regex::Regex::new(p)
                .is_ok_and(|r| r.capture_names().flatten().any(|n| n == "subject"))
        {
            c.push(
                &key_at(at, &[K("subject_pattern")]),
                format!("{p:?}"),
                "a regex with a named group `subject`",
            );
        }
        if self.file.as_ref().is_some_and(|f| f.trim().is_empty()) {
            c.push(
                &key_at(at, &[K("file")]),
                "\"\"".into(),
                "a CSV file of capture,split rows (relative to the config file)",
            );
        }
    }

    /// The ratios as a TOML inline table, as a problem shows them.
    fn shown_ratios(&self) -> String {
        let parts: Vec<String> = self
            .ratios
            .iter()
            .map(|(k, v)| format!("{k} = {v}"))
            .collect();
        format!("{{ {} }}", parts.join(", "))
    }
}

impl SyntheticConfig {
    /// The pairing probability, the share of action a crop must keep, and the plausibility
    /// thresholds.
    pub(super) fn check(&self, at: &[Seg<'_>], c: &mut Checks<'_>) {
        use Seg::K;
        let p = self.probability;
        if !(0.0..=1.0).contains(&p) {
            c.push(
                &key_at(at, &[K("probability")]),
                p.to_string(),
                "a probability between 0 and 1",
            );
        }
        let kept = self.min_action_kept;
        if !(0.0..=1.0).contains(&kept) {
            c.push(
                &key_at(at, &[K("min_action_kept")]),
                kept.to_string(),
                "a share between 0 and 1",
            );
        }
        let t = &self.thresholds;
        for (key, value, expected) in [
            (
                "max_foot_skate",
                t.max_foot_skate,
                "a speed of 0 or more m/s",
            ),
            (
                "max_ground_penetration",
                t.max_ground_penetration,
                "a depth of 0 or more metres",
            ),
            (
                "min_self_distance",
                t.min_self_distance,
                "a distance of 0 or more metres",
            ),
            ("max_lean", t.max_lean, "an angle between 0 and 180 degrees"),
        ] {
            let limit = if key == "max_lean" { 180.0 } else { f64::MAX };
            if !(value.is_finite() && (0.0..=limit).contains(&value)) {
                c.push(
                    &key_at(at, &[K("thresholds"), K(key)]),
                    value.to_string(),
                    expected,
                );
            }
        }
    }
}

/// The `[features]` section: the foot-contact speed.
pub(super) fn check_features(
    features: &motionforge_core::features::FeatureConfig,
    at: &[Seg<'_>],
    c: &mut Checks<'_>,
) {
    let speed = features.contact_speed;
    if !(speed.is_finite() && speed > 0.0) {
        c.push(
            &key_at(at, &[Seg::K("contact_speed")]),
            speed.to_string(),
            "a speed above 0 m/s",
        );
    }
}

impl Config {
    /// The top-level paths (`llm_cache`, `prompts_dir`): not empty when given.
    pub(super) fn check_top_level_paths(&self, c: &mut Checks<'_>) {
        for (key, value) in [
            ("llm_cache", &self.llm_cache),
            ("prompts_dir", &self.prompts_dir),
        ] {
            if value.as_ref().is_some_and(|p| p.as_os_str().is_empty()) {
                c.push(
                    &[Seg::K(key)],
                    "\"\"".into(),
                    "a path (relative to the config file)",
                );
            }
        }
    }

    /// The output and dataset folders are folders (or not there yet), the LLM cache is not a
    /// folder, the prompt folder exists and its templates load.
    pub(super) fn check_output_cache_and_prompts(&self, c: &mut Checks<'_>) {
        use Seg::K;
        for (key, dir) in [("output", self.output_dir()), ("name", self.dataset_dir())] {
            if dir.exists() && !dir.is_dir() {
                c.push(
                    &[K("dataset"), K(key)],
                    dir.display().to_string(),
                    "a folder, but this is a file",
                );
            }
        }
        if let Some(cache) = &self.llm_cache
            && self.resolve(cache).is_dir()
        {
            c.push(
                &[K("llm_cache")],
                self.resolve(cache).display().to_string(),
                "a file, but this is a folder",
            );
        }
        if let Some(dir) = &self.prompts_dir {
            let resolved = self.resolve(dir);
            if !resolved.is_dir() {
                c.push(
                    &[K("prompts_dir")],
                    resolved.display().to_string(),
                    "an existing folder of prompt templates",
                );
            } else if let Err(e) = self.prompts() {
                c.push(
                    &[K("prompts_dir")],
                    resolved.display().to_string(),
                    &format!("templates that load ({e})"),
                );
            }
        }
    }

    /// The taxonomy file exists, and with the extra types and aliases makes a valid type map.
    pub(super) fn check_motion_type_files(&self, c: &mut Checks<'_>) {
        use Seg::K;
        if let Some(taxonomy) = &self.motion_types.taxonomy
            && !self.resolve(taxonomy).is_file()
        {
            c.push(
                &[K("motion_types"), K("taxonomy")],
                self.resolve(taxonomy).display().to_string(),
                "an existing taxonomy TOML file",
            );
        } else {
            let types = self
                .motion_types
                .load_taxonomy(Some(&self.base_dir))
                .and_then(|t| t.with_extra(self.motion_types.extra.clone()))
                .and_then(|t| {
                    motionforge_sources::annotate::taxonomy::TypeMap::new(t, &self.motion_types)
                });
            if let Err(e) = types {
                c.push(
                    &[K("motion_types")],
                    "(the taxonomy and mapping)".into(),
                    &format!("a valid taxonomy and mapping: {e}"),
                );
            }
        }
    }

    /// The split file exists.
    pub(super) fn check_split_file(&self, c: &mut Checks<'_>) {
        use Seg::K;
        if let Some(file) = &self.splits.file {
            let resolved = self.resolve(Path::new(file));
            if !resolved.is_file() {
                c.push(
                    &[K("splits"), K("file")],
                    resolved.display().to_string(),
                    "an existing CSV file of capture,split rows",
                );
            }
        }
    }

    /// A warning, not a problem: the API key variable the LLM section names is not set.
    pub(super) fn warn_of_unset_api_key(&self, summary: &mut InputSummary) {
        if let Some(llm) = &self.llm
            && let Some(var) = &llm.api_key_env
            && std::env::var(var).map_or(true, |v| v.trim().is_empty())
        {
            summary.warnings.push(format!(
                "llm.api_key_env: environment variable {var} is not set: requests will fail (export it, or build with --offline)"
            ));
        }
    }
}
