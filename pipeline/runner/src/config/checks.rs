//! Config checks: every value against what it may be, and every file the config names, each
//! problem with its key, value, expectation and line, all reported at once.

use super::*;
use motionforge_core::motion::bvh::FPS_RANGE;

/// Longest dataset name: a folder name, within the 255-byte file-name limit of common file
/// systems with room for the prefixes and suffixes of temporary files.
const MAX_NAME_BYTES: usize = 200;
/// Longest `<output>/<name>`: the files under it (`.motionforge/cache/<stage>/<pack name>`, up to
/// about 120 bytes more) must stay within Linux's 4096-byte path limit.
const MAX_DATASET_PATH_BYTES: usize = 3800;

impl Config {
    pub(super) fn validate(&self, c: &mut Checks<'_>) {
        use Seg::{I, K};
        let d = &self.dataset;
        if d.name.is_empty()
            || d.name == "."
            || d.name == ".."
            || !d
                .name
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || "-_.".contains(ch))
        {
            c.push(
                &[K("dataset"), K("name")],
                format!("{:?}", d.name),
                "a non-empty name of letters, digits, `-`, `_`, `.` (not `.` or `..`): it names the dataset folder",
            );
        }
        if d.name.len() > MAX_NAME_BYTES {
            c.push(
                &[K("dataset"), K("name")],
                format!("{} characters", d.name.len()),
                &format!(
                    "at most {MAX_NAME_BYTES} characters: it names the dataset folder, and file systems refuse names over 255 bytes (the rest is room for temporary-file prefixes and suffixes)"
                ),
            );
        }
        if d.output.as_os_str().len() + d.name.len() > MAX_DATASET_PATH_BYTES {
            c.push(
                &[K("dataset"), K("output")],
                format!("{} bytes with the name", d.output.as_os_str().len() + d.name.len()),
                &format!(
                    "a dataset folder path of at most {MAX_DATASET_PATH_BYTES} bytes: files inside it must stay within the system's 4096-byte path limit"
                ),
            );
        }
        if d.output.as_os_str().is_empty() {
            c.push(
                &[K("dataset"), K("output")],
                "\"\"".into(),
                "a folder path (relative to the config file)",
            );
        }
        if !(d.fps.is_finite() && d.fps > 0.0 && d.fps <= 1000.0) {
            c.push(
                &[K("dataset"), K("fps")],
                d.fps.to_string(),
                "a frame rate above 0 and at most 1000",
            );
        }
        if d.shard_bytes < 1024 {
            c.push(
                &[K("dataset"), K("shard_bytes")],
                d.shard_bytes.to_string(),
                "at least 1024 bytes",
            );
        }
        if !(-7..=22).contains(&d.zstd_level) || d.zstd_level == 0 {
            c.push(
                &[K("dataset"), K("zstd_level")],
                d.zstd_level.to_string(),
                "a zstd level from 1 to 22 (smallest), or -1 to -7 (zstd's fast levels: faster, larger)",
            );
        }
        if self.paraphrases.n == 0 || self.paraphrases.n > 50 {
            c.push(
                &[K("paraphrases"), K("n")],
                self.paraphrases.n.to_string(),
                "between 1 and 50 alternatives",
            );
        }
        if self.paraphrases.on_invalid == OnInvalid::Embedded {
            c.push(
                &[K("paraphrases"), K("on_invalid")],
                "\"embedded\"".into(),
                "\"drop\" or \"keep\": there is no embedded paraphraser to fall back to",
            );
        }
        self.validate_splits(c);
        let p = self.synthetic.probability;
        if !(0.0..=1.0).contains(&p) {
            c.push(
                &[K("synthetic"), K("probability")],
                p.to_string(),
                "a probability between 0 and 1",
            );
        }
        let kept = self.synthetic.min_action_kept;
        if !(0.0..=1.0).contains(&kept) {
            c.push(
                &[K("synthetic"), K("min_action_kept")],
                kept.to_string(),
                "a share between 0 and 1",
            );
        }
        let t = &self.synthetic.thresholds;
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
                    &[K("synthetic"), K("thresholds"), K(key)],
                    value.to_string(),
                    expected,
                );
            }
        }
        let speed = self.features.contact_speed;
        if !(speed.is_finite() && speed > 0.0) {
            c.push(
                &[K("features"), K("contact_speed")],
                speed.to_string(),
                "a speed above 0 m/s",
            );
        }
        if let Some(llm) = &self.llm {
            validate_llm(llm, c);
        }
        for (key, value) in [
            ("llm_cache", &self.llm_cache),
            ("prompts_dir", &self.prompts_dir),
        ] {
            if value.as_ref().is_some_and(|p| p.as_os_str().is_empty()) {
                c.push(
                    &[K(key)],
                    "\"\"".into(),
                    "a path (relative to the config file)",
                );
            }
        }
        if self.sources.is_empty() {
            c.push(
                &[K("sources")],
                "[]".into(),
                "at least one [[sources]] table",
            );
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, s) in self.sources.iter().enumerate() {
            let at = |rest: &[Seg<'static>]| -> Vec<Seg<'static>> {
                let mut path = vec![K("sources"), I(i)];
                path.extend_from_slice(rest);
                path
            };
            if s.name.trim().is_empty() {
                c.push(
                    &at(&[K("name")]),
                    format!("{:?}", s.name),
                    "a non-empty name",
                );
            } else if !names.insert(&s.name) {
                c.push(
                    &at(&[K("name")]),
                    format!("{:?}", s.name),
                    "a name no other source uses",
                );
            }
            if s.captures.is_empty() {
                c.push(
                    &at(&[K("captures")]),
                    "[]".into(),
                    "at least one glob pattern",
                );
            }
            for (j, pattern) in s.captures.iter().enumerate() {
                if let Err(e) = glob::Pattern::new(pattern) {
                    c.push(
                        &[K("sources"), I(i), K("captures"), I(j)],
                        format!("{pattern:?}"),
                        &format!("a valid glob pattern ({e})"),
                    );
                } else if pattern.trim().is_empty() {
                    c.push(
                        &[K("sources"), I(i), K("captures"), I(j)],
                        format!("{pattern:?}"),
                        "a glob pattern of capture files",
                    );
                }
            }
            if s.profile.trim().is_empty() {
                c.push(
                    &at(&[K("profile")]),
                    "\"\"".into(),
                    "a bundled profile name (bandai-namco, cmu, smpl-22, smplh-52, smplx-55) or a .toml file",
                );
            }
            for (file, fps) in &s.fps_override {
                if !FPS_RANGE.contains(fps) {
                    c.push(
                        &[K("sources"), I(i), K("fps_override"), K(file)],
                        fps.to_string(),
                        &format!(
                            "a capture frame rate from {} to {} fps",
                            FPS_RANGE.start(),
                            FPS_RANGE.end()
                        ),
                    );
                }
            }
            match &s.labels {
                LabelConfig::Filename { pattern, .. } => {
                    if let Err(e) =
                        motionforge_sources::annotate::filename::FilenamePattern::new(pattern)
                    {
                        c.push(
                            &at(&[K("labels"), K("pattern")]),
                            format!("{pattern:?}"),
                            &e.to_string(),
                        );
                    }
                }
                LabelConfig::Babel { path, key_pattern }
                | LabelConfig::FrameIndex {
                    path, key_pattern, ..
                } => {
                    if path.trim().is_empty() {
                        c.push(
                            &at(&[K("labels"), K("path")]),
                            "\"\"".into(),
                            "the annotation file (relative to the config file)",
                        );
                    }
                    if let Some(p) = key_pattern
                        && !regex::Regex::new(p)
                            .is_ok_and(|r| r.capture_names().flatten().any(|n| n == "key"))
                    {
                        c.push(
                            &at(&[K("labels"), K("key_pattern")]),
                            format!("{p:?}"),
                            "a regex with a named group `key`",
                        );
                    }
                }
                LabelConfig::EventLog { path, .. } => {
                    if path.trim().is_empty() {
                        c.push(
                            &at(&[K("labels"), K("path")]),
                            "\"\"".into(),
                            "the event log file(s) (relative to the config file)",
                        );
                    }
                }
            }
            if let LabelConfig::EventLog { fps, .. } | LabelConfig::FrameIndex { fps, .. } =
                &s.labels
                && !FPS_RANGE.contains(fps)
            {
                c.push(
                    &at(&[K("labels"), K("fps")]),
                    fps.to_string(),
                    &format!(
                        "a frame rate from {} to {} fps",
                        FPS_RANGE.start(),
                        FPS_RANGE.end()
                    ),
                );
            }
            let seg = &s.segment;
            if !(seg.min_seconds.is_finite() && seg.min_seconds >= 0.0) {
                c.push(
                    &at(&[K("segment"), K("min_seconds")]),
                    seg.min_seconds.to_string(),
                    "zero or more seconds",
                );
            } else if !(seg.max_seconds.is_finite() && seg.max_seconds > seg.min_seconds) {
                c.push(
                    &at(&[K("segment"), K("max_seconds")]),
                    seg.max_seconds.to_string(),
                    &format!("a length above min_seconds ({})", seg.min_seconds),
                );
            }
            if !(seg.trim_start_seconds >= 0.0 && seg.trim_start_seconds.is_finite()) {
                c.push(
                    &at(&[K("segment"), K("trim_start_seconds")]),
                    seg.trim_start_seconds.to_string(),
                    "zero or more seconds",
                );
            }
            if seg.max_simultaneous < 2 {
                c.push(
                    &at(&[K("segment"), K("max_simultaneous")]),
                    seg.max_simultaneous.to_string(),
                    "2 or more",
                );
            }
            if let Some(p) = &s.positions {
                if s.profile.trim() != "smpl-22" {
                    c.push(
                        &at(&[K("profile")]),
                        format!("{:?}", s.profile),
                        "`smpl-22`: joint-position captures (`positions`) become motions on the SMPL body skeleton",
                    );
                }
                if !FPS_RANGE.contains(&p.fps) {
                    c.push(
                        &at(&[K("positions"), K("fps")]),
                        p.fps.to_string(),
                        &format!(
                            "a frame rate from {} to {} fps (HumanML3D: 20)",
                            FPS_RANGE.start(),
                            FPS_RANGE.end()
                        ),
                    );
                }
                if !crate::config::UNITS_RANGE.contains(&p.units) {
                    c.push(
                        &at(&[K("positions"), K("units")]),
                        // `1e160` as written, not 161 digits.
                        if p.units.abs() >= 1e15 || (p.units != 0.0 && p.units.abs() < 1e-4) {
                            format!("{:e}", p.units)
                        } else {
                            p.units.to_string()
                        },
                        &format!(
                            "metres per unit of the arrays, from {:e} to {:e} (HumanML3D: 1; millimetres: 0.001)",
                            crate::config::UNITS_RANGE.start(),
                            crate::config::UNITS_RANGE.end()
                        ),
                    );
                }
                if !(p.bone_tolerance.is_finite()
                    && p.bone_tolerance > 0.0
                    && p.bone_tolerance < 1.0)
                {
                    c.push(
                        &at(&[K("positions"), K("bone_tolerance")]),
                        p.bone_tolerance.to_string(),
                        "a fraction above 0 and below 1 (default 0.05)",
                    );
                }
                if p.up.axis == p.forward.axis {
                    c.push(
                        &at(&[K("positions"), K("forward")]),
                        p.forward.to_string(),
                        &format!("an axis other than the up axis {}", p.up),
                    );
                }
            }
            if let Some(a) = &s.amass {
                if s.positions.is_some() {
                    c.push(
                        &at(&[K("amass")]),
                        "(with `positions`)".into(),
                        "either `amass` or `positions`: a source's captures are one kind of file",
                    );
                }
                let profile = s.profile.trim();
                if !(["smplh-52", "smplx-55"].contains(&profile) || profile.ends_with(".toml")) {
                    c.push(
                        &at(&[K("profile")]),
                        format!("{:?}", s.profile),
                        "`smplh-52` (SMPL-H files) or `smplx-55` (SMPL-X files): AMASS captures become motions on the body model's skeleton",
                    );
                }
                if a.body_model.trim().is_empty() {
                    c.push(
                        &at(&[K("amass"), K("body_model")]),
                        "\"\"".into(),
                        "the body model folder (smplh/{male,female,neutral}/model.npz), relative to the config file",
                    );
                }
                if a.num_betas > motionforge_sources::amass::model::MAX_BETAS {
                    c.push(
                        &at(&[K("amass"), K("num_betas")]),
                        a.num_betas.to_string(),
                        &format!(
                            "0 to {} shape coefficients (HumanML3D: 10)",
                            motionforge_sources::amass::model::MAX_BETAS
                        ),
                    );
                }
                if a.frame_rate == motionforge_sources::amass::FrameRateMode::Humanml3d
                    && (self.dataset.fps - 20.0).abs() > 1e-9
                {
                    c.push(
                        &at(&[K("amass"), K("frame_rate")]),
                        "\"humanml3d\"".into(),
                        &format!(
                            "`resample` with dataset.fps = {}: the `humanml3d` stride gives HumanML3D's 20 fps frames (set dataset.fps = 20)",
                            self.dataset.fps
                        ),
                    );
                }
            }
        }
    }

    pub(super) fn validate_splits(&self, c: &mut Checks<'_>) {
        use Seg::K;
        let splits = &self.splits;
        let shown = || {
            let parts: Vec<String> = splits
                .ratios
                .iter()
                .map(|(k, v)| format!("{k} = {v}"))
                .collect();
            format!("{{ {} }}", parts.join(", "))
        };
        if splits.ratios.is_empty() {
            c.push(
                &[K("splits"), K("ratios")],
                "{}".into(),
                "split names with shares, e.g. { train = 0.8, validation = 0.1, test = 0.1 }",
            );
        }
        for (name, share) in &splits.ratios {
            // Split names become shard file names (`<split>-00000-of-00001.parquet`).
            if name.is_empty()
                || name.starts_with('.')
                || !name
                    .chars()
                    .all(|ch| ch.is_ascii_alphanumeric() || "-_.".contains(ch))
            {
                c.push(
                    &[K("splits"), K("ratios"), K(name)],
                    format!("{name:?}"),
                    "a split name of letters, digits, `-`, `_`, `.` (it names shard files)",
                );
            }
            if !(share.is_finite() && (0.0..=1.0).contains(share)) {
                c.push(
                    &[K("splits"), K("ratios"), K(name)],
                    share.to_string(),
                    "a share between 0 and 1",
                );
            }
        }
        let sum: f64 = splits.ratios.values().sum();
        if !splits.ratios.is_empty()
            && splits.ratios.values().all(|r| r.is_finite())
            && (sum - 1.0).abs() > 1e-6
        {
            c.push(
                &[K("splits"), K("ratios")],
                shown(),
                &format!("shares that sum to 1 (they sum to {})", round6(sum)),
            );
        }
        if let Some(p) = &splits.subject_pattern
            && !regex::Regex::new(p)
                .is_ok_and(|r| r.capture_names().flatten().any(|n| n == "subject"))
        {
            c.push(
                &[K("splits"), K("subject_pattern")],
                format!("{p:?}"),
                "a regex with a named group `subject`",
            );
        }
        if splits.file.as_ref().is_some_and(|f| f.trim().is_empty()) {
            c.push(
                &[K("splits"), K("file")],
                "\"\"".into(),
                "a CSV file of capture,split rows (relative to the config file)",
            );
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

    pub(super) fn check_inputs_into(&self, c: &mut Checks<'_>) -> InputSummary {
        use Seg::{I, K};
        let mut summary = InputSummary::default();
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
        if let Some(llm) = &self.llm
            && let Some(var) = &llm.api_key_env
            && std::env::var(var).map_or(true, |v| v.trim().is_empty())
        {
            summary.warnings.push(format!(
                "llm.api_key_env: environment variable {var} is not set: requests will fail (export it, or build with --offline)"
            ));
        }
        for (i, s) in self.sources.iter().enumerate() {
            let mut files = std::collections::BTreeSet::new();
            for (j, pattern) in s.captures.iter().enumerate() {
                if pattern.trim().is_empty() || glob::Pattern::new(pattern).is_err() {
                    continue;
                }
                let found = self.glob_files(pattern);
                if found.is_empty() {
                    c.push(
                        &[K("sources"), I(i), K("captures"), I(j)],
                        format!("{pattern:?}"),
                        &self.no_match(pattern, "capture files"),
                    );
                }
                files.extend(found);
            }
            summary.captures.push(files.len());
            if let Err(e) = super::resolve_profile(self, s)
                && !s.profile.trim().is_empty()
            {
                c.push(
                    &[K("sources"), I(i), K("profile")],
                    format!("{:?}", s.profile),
                    &format!(
                        "a bundled profile ({}) or a readable profile .toml file: {e}",
                        motionforge_core::motion::ProfileSpec::bundled_names()
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                );
            }
            if let Some(table) = &s.fps_table
                && !self.resolve(Path::new(table)).is_file()
            {
                c.push(
                    &[K("sources"), I(i), K("fps_table")],
                    format!("{table:?}"),
                    &format!(
                        "an existing JSON file (resolved as {})",
                        self.resolve(Path::new(table)).display()
                    ),
                );
            }
            if let Some(a) = &s.amass
                && !a.body_model.trim().is_empty()
            {
                check_body_model(a, &[K("sources"), I(i), K("amass"), K("body_model")], c);
            }
            match &s.labels {
                LabelConfig::Filename { .. } => {}
                LabelConfig::Babel { path, .. } | LabelConfig::EventLog { path, .. } => {
                    if !path.trim().is_empty() && self.glob_files(path).is_empty() {
                        c.push(
                            &[K("sources"), I(i), K("labels"), K("path")],
                            format!("{path:?}"),
                            &self.no_match(path, "annotation files"),
                        );
                    }
                }
                LabelConfig::FrameIndex { path, texts, .. } => {
                    let resolved = self.resolve(Path::new(path));
                    if !path.trim().is_empty() && !resolved.is_file() {
                        c.push(
                            &[K("sources"), I(i), K("labels"), K("path")],
                            format!("{path:?}"),
                            &format!("an existing index CSV (resolved as {})", resolved.display()),
                        );
                    }
                    if let Some(dir) = texts
                        && !self.resolve(Path::new(dir)).is_dir()
                    {
                        c.push(
                            &[K("sources"), I(i), K("labels"), K("texts")],
                            format!("{dir:?}"),
                            &format!(
                                "an existing folder of caption files (resolved as {})",
                                self.resolve(Path::new(dir)).display()
                            ),
                        );
                    }
                }
            }
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

/// The body model folder of an AMASS source: there, with model files for the genders the
/// source asks for, each holding the keys joints need (read once; the build reuses them).
fn check_body_model(a: &AmassConfig, key: &[Seg<'_>], c: &mut Checks<'_>) {
    use motionforge_sources::amass::{Family, GenderChoice, model_path};
    let dir = &a.body_model_dir;
    let shown = format!("{:?}", a.body_model);
    if !dir.is_dir() {
        c.push(
            key,
            shown,
            &format!(
                "an existing body model folder (resolved as {}); get SMPL-H from https://mano.is.tue.mpg.de or SMPL-X from https://smpl-x.is.tue.mpg.de (docs/amass.md)",
                dir.display()
            ),
        );
        return;
    }
    let files = motionforge_sources::amass::model_files(dir);
    if files.is_empty() {
        c.push(
            key,
            shown,
            &format!(
                "a folder holding smplh/{{male,female,neutral}}/model.npz or smplx/... (resolved as {}; none there)",
                dir.display()
            ),
        );
        return;
    }
    let forced = match a.gender {
        GenderChoice::File => None,
        GenderChoice::Male => Some("male"),
        GenderChoice::Female => Some("female"),
        GenderChoice::Neutral => Some("neutral"),
    };
    if let Some(gender) = forced
        && ![Family::SmplH, Family::SmplX]
            .iter()
            .any(|f| model_path(dir, *f, gender).is_file())
    {
        c.push(
            key,
            shown.clone(),
            &format!(
                "a folder with a {gender} model (gender = \"{gender}\"): no {} nor {}",
                model_path(dir, Family::SmplH, gender).display(),
                model_path(dir, Family::SmplX, gender).display()
            ),
        );
    }
    for path in files {
        if let Err(e) = motionforge_sources::amass::load_model(&path, a.num_betas) {
            c.push(key, shown.clone(), &format!("a usable body model: {e}"));
        }
    }
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
