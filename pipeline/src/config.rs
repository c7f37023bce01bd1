//! Build configuration (TOML), one typed section per stage, validated on load.
//!
//! Relative paths in a config resolve against the folder of the config file, so a build gives the
//! same result whatever the working folder.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// A configuration error that names the file, the key and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file does not exist.
    #[error("{}", not_found_message(path))]
    NotFound {
        /// The config path.
        path: PathBuf,
    },
    /// The file cannot be read.
    #[error("cannot read config {path}: {source}")]
    Read {
        /// The config path.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TOML does not parse or does not fit the schema.
    #[error("config {}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Parse {
        /// The config path.
        path: PathBuf,
        /// 1-based line, when known and not already in the message.
        line: Option<usize>,
        /// What the parser reported, with the key.
        message: String,
    },
    /// Values parse but are not acceptable: every problem found, not only the first.
    #[error("{}", invalid_message(path, problems))]
    Invalid {
        /// The config path.
        path: PathBuf,
        /// What is wrong, in file order where lines are known.
        problems: Vec<Problem>,
    },
}

/// The config file commands read when `--config` is not given, in the working folder.
pub const DEFAULT_CONFIG: &str = "motionforge.toml";

/// One unacceptable value: its dotted key, the value found, what is expected and its line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// Dotted key, with array positions: `sources[1].segment.max_seconds`.
    pub key: String,
    /// The value found, as TOML-ish text.
    pub value: String,
    /// What is expected instead.
    pub expected: String,
    /// 1-based line of the key (or of its table when the key was left at its default).
    pub line: Option<usize>,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {}: expected {}",
            self.key, self.value, self.expected
        )
    }
}

fn not_found_message(path: &Path) -> String {
    let cwd = std::env::current_dir()
        .map(|d| d.display().to_string())
        .unwrap_or_else(|_| "the working folder".into());
    if path.as_os_str() == DEFAULT_CONFIG {
        format!(
            "no {DEFAULT_CONFIG} in the working folder ({cwd}), the default config; pass one with --config FILE"
        )
    } else {
        format!(
            "config {} not found (relative paths start from the working folder, {cwd}); check the --config path",
            path.display()
        )
    }
}

fn invalid_message(path: &Path, problems: &[Problem]) -> String {
    let at = |p: &Problem| match p.line {
        Some(line) => format!("{}:{line}: {p}", path.display()),
        None => format!("{}: {p}", path.display()),
    };
    match problems {
        [one] => format!("config {}", at(one)),
        many => {
            let mut text = format!("config {} has {} problems:", path.display(), many.len());
            for p in many {
                text.push_str("\n  ");
                text.push_str(&at(p));
            }
            text
        }
    }
}

/// What a config's inputs add up to once [`Config::check_inputs`] found them all.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct InputSummary {
    /// Capture files per source, in config order.
    pub captures: Vec<usize>,
    /// Things that do not stop a build but may surprise (an unset API key variable).
    pub warnings: Vec<String>,
}

/// The whole build configuration.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Dataset-wide settings.
    pub dataset: DatasetConfig,
    /// Mirroring.
    #[serde(default)]
    pub mirror: MirrorConfig,
    /// Motion types: taxonomy and how dataset labels map to it.
    #[serde(default)]
    pub motion_types: crate::annotate::taxonomy::TypeMapConfig,
    /// Derived feature columns (6D rotations, velocities, foot contacts, future root).
    #[serde(default)]
    pub features: crate::features::FeatureConfig,
    /// Train/validation/test splits.
    #[serde(default)]
    pub splits: crate::stages::split::SplitConfig,
    /// Synthetic simultaneous pairs and their plausibility checks.
    #[serde(default)]
    pub synthetic: crate::stages::compose::SyntheticConfig,
    /// Body-part labelling.
    #[serde(default)]
    pub part_labels: PartLabelConfig,
    /// LINGO task plans for action texts.
    #[serde(default)]
    pub task_plans: TaskPlanConfig,
    /// Alternative descriptions of action texts.
    #[serde(default)]
    pub paraphrases: ParaphraseConfig,
    /// The LLM server; without it no request is ever sent (cached answers are still used).
    #[serde(default)]
    pub llm: Option<crate::llm::client::LlmConfig>,
    /// Response cache shared by the LLM stages; default `<output>/llm-cache.jsonl`.
    #[serde(default)]
    pub llm_cache: Option<PathBuf>,
    /// A folder of edited prompt templates and data (`part_labels.j2`, ...); bundled ones otherwise.
    #[serde(default)]
    pub prompts_dir: Option<PathBuf>,
    /// Capture sources.
    #[serde(rename = "sources")]
    pub sources: Vec<SourceConfig>,
    /// Folder of the config file; relative paths resolve against it.
    #[serde(skip)]
    pub base_dir: PathBuf,
}

/// Dataset-wide settings.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DatasetConfig {
    /// Dataset name (file names, manifest).
    pub name: String,
    /// Output folder.
    pub output: PathBuf,
    /// Frame rate every clip is resampled to.
    #[serde(default = "default_fps")]
    pub fps: f64,
    /// Seed for every random choice.
    #[serde(default)]
    pub seed: u64,
    /// Target size of a Parquet shard in bytes (uncompressed estimate; default 256 MiB).
    #[serde(default = "default_shard_bytes")]
    pub shard_bytes: u64,
    /// When `motionforge serve` rebuilds the dataset: a five-field cron expression in UTC
    /// (`"0 3 * * *"`), checked when the service loads the config.
    // Not serialised: it says when to build, not what, so it must not change the config fingerprint.
    #[serde(default, skip_serializing)]
    pub schedule: Option<String>,
}

fn default_shard_bytes() -> u64 {
    256 * 1024 * 1024
}

fn default_fps() -> f64 {
    30.0
}

/// Who labels body parts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Labeller {
    /// The embedded labeller: lexicon, then motion velocity; offline and deterministic.
    #[default]
    Embedded,
    /// The LLM (through the response cache), with SINC's prompt.
    Llm,
}

/// What to do with a text whose LLM answer is not in the cache and cannot be asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum OnMiss {
    /// Label it with the embedded labeller (and say so in `label_source`).
    #[default]
    Embedded,
    /// Fail the build, listing the missing texts.
    Fail,
}

/// Body-part labelling settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct PartLabelConfig {
    /// `embedded` (default) or `llm`.
    #[serde(default)]
    pub labeller: Labeller,
    /// SINC Table 1 prompt variant for the LLM.
    #[serde(default)]
    pub variant: crate::llm::prompt::PartPromptVariant,
    /// Never send requests; answers come from the cache only.
    #[serde(default)]
    pub offline: bool,
    /// Cache misses that cannot be asked: `embedded` (default) or `fail`.
    #[serde(default)]
    pub on_miss: OnMiss,
}

/// Task-plan settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskPlanConfig {
    /// Plan every unique action text (with an LLM or cached answers; skipped and reported
    /// otherwise).
    #[serde(default = "yes")]
    pub enabled: bool,
}

impl Default for TaskPlanConfig {
    fn default() -> Self {
        TaskPlanConfig { enabled: true }
    }
}

/// Paraphrase settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParaphraseConfig {
    /// Ask for alternatives of every unique action text (LLM or cache; skipped and reported
    /// otherwise).
    #[serde(default = "yes")]
    pub enabled: bool,
    /// Alternatives asked for per text.
    #[serde(default = "default_paraphrases")]
    pub n: usize,
}

fn default_paraphrases() -> usize {
    3
}

impl Default for ParaphraseConfig {
    fn default() -> Self {
        ParaphraseConfig {
            enabled: true,
            n: default_paraphrases(),
        }
    }
}

/// Mirroring settings.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MirrorConfig {
    /// Add a mirrored copy of every clip.
    #[serde(default = "yes")]
    pub enabled: bool,
}

fn yes() -> bool {
    true
}

impl Default for MirrorConfig {
    fn default() -> Self {
        MirrorConfig { enabled: true }
    }
}

/// One set of captures sharing a skeleton profile and an annotation source.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    /// Source name (provenance, reports).
    pub name: String,
    /// Glob patterns of capture files, relative to the config file.
    pub captures: Vec<String>,
    /// Skeleton profile: a bundled name (`bandai-namco`, `cmu`, `smpl-22`) or a path to a TOML file.
    pub profile: String,
    /// Per-file frame-rate overrides (file name or glob -> fps), for headers that state the wrong
    /// rate.
    #[serde(default)]
    pub fps_override: BTreeMap<String, f64>,
    /// A JSON object of true frame rates by annotation path (BABEL's `featp_2_fps.json`), matched
    /// to captures by the same key as annotations; `fps_override` wins over it.
    #[serde(default)]
    pub fps_table: Option<String>,
    /// Licence of the captures, carried to the dataset card.
    #[serde(default)]
    pub licence: String,
    /// Left/right pairs that override the profile's (joint name -> partner).
    #[serde(default)]
    pub pairs: BTreeMap<String, String>,
    /// Mirror reflections that override the profile's (joint name -> `x`, `y`, `z` or `xyz`).
    #[serde(default)]
    pub reflections: BTreeMap<String, crate::motion::Reflection>,
    /// Where action labels come from.
    pub labels: LabelConfig,
    /// How annotations become clips.
    #[serde(default)]
    pub segment: SegmentConfig,
}

/// How a source's captures get their labels.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum LabelConfig {
    /// One action per file, taken from the file name (and an optional sidecar JSON).
    Filename {
        /// File-stem pattern with `{name}` placeholders (each matches up to the next `_`), e.g.
        /// `dataset-1_{content}_{style}_{take}`; or a full regex with named groups when it starts
        /// with `^`.
        pattern: String,
        /// Action label template, e.g. `{content}`.
        action: String,
        /// Caption template, e.g. `{content}, {style} style`; `-` and `_` in values become spaces.
        text: String,
        /// Read `<stem>.json` beside each capture when present; its keys join the attributes and
        /// `action`/`text` keys override the templates.
        #[serde(default)]
        sidecar: bool,
    },
    /// BABEL JSON: frame labels in seconds, overlapping labels are simultaneous actions.
    Babel {
        /// The BABEL JSON file(s), a path or glob relative to the config.
        path: String,
        /// Regex with a named group `key` that turns a record's `feat_p` into the capture's file
        /// stem; default: the file name without `_poses` and extension.
        #[serde(default)]
        key_pattern: Option<String>,
    },
    /// LINGO-style event logs (CSV or JSON): each instruction lasts until the next one.
    EventLog {
        /// The log file(s), a path or glob relative to the config; one per capture unless rows
        /// name their `capture`.
        path: String,
        /// Rate of `frame` columns.
        #[serde(default = "default_fps")]
        fps: f64,
    },
    /// A frame-range index such as HumanML3D's `index.csv`: independent crops.
    FrameIndex {
        /// The index CSV, relative to the config.
        path: String,
        /// Rate the index counts frames at (HumanML3D: 20).
        fps: f64,
        /// Folder of caption files `<new_name>.txt` (HumanML3D `texts/`), relative to the config.
        #[serde(default)]
        texts: Option<String>,
        /// Caption for rows without a caption file.
        #[serde(default)]
        default_text: String,
        /// Regex with a named group `key` that turns `source_path` into the capture's file stem.
        #[serde(default)]
        key_pattern: Option<String>,
    },
}

impl LabelConfig {
    /// The format name recorded in clips.
    pub fn kind(&self) -> &'static str {
        match self {
            LabelConfig::Filename { .. } => "filename",
            LabelConfig::Babel { .. } => "babel",
            LabelConfig::EventLog { .. } => "event_log",
            LabelConfig::FrameIndex { .. } => "frame_index",
        }
    }
}

/// How a source's annotations become clips.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SegmentConfig {
    /// Shortest clip kept, seconds after resampling (SINC: 15 frames at 30 fps).
    #[serde(default = "default_min_seconds")]
    pub min_seconds: f64,
    /// Longest clip kept, seconds (SINC: 600 frames at 30 fps).
    #[serde(default = "default_max_seconds")]
    pub max_seconds: f64,
    /// Labels dropped before segmentation (compared lowercase, `-` and `_` as spaces).
    #[serde(default = "default_drop_labels")]
    pub drop_labels: Vec<String>,
    /// Real pairs involving a label that contains one of these words are dropped (SINC drops
    /// pairs with `stand` from validation).
    #[serde(default)]
    pub pair_exclude: Vec<String>,
    /// Seconds cut from the start of every capture (HumanML3D trims T-pose starts per dataset).
    #[serde(default)]
    pub trim_start_seconds: f64,
    /// Frames of the capture before the annotations' time zero (CMU BVH conversions add a
    /// T-pose frame 0 that AMASS-based annotations do not count).
    #[serde(default)]
    pub timeline_offset_frames: u64,
    /// Most actions one real simultaneous clip may combine.
    #[serde(default = "default_max_simultaneous")]
    pub max_simultaneous: usize,
}

fn default_min_seconds() -> f64 {
    0.5
}

fn default_max_seconds() -> f64 {
    20.0
}

fn default_max_simultaneous() -> usize {
    2
}

fn default_drop_labels() -> Vec<String> {
    ["transition", "t pose", "tpose", "a pose", "apose"]
        .map(String::from)
        .to_vec()
}

impl Default for SegmentConfig {
    fn default() -> Self {
        SegmentConfig {
            min_seconds: default_min_seconds(),
            max_seconds: default_max_seconds(),
            drop_labels: default_drop_labels(),
            pair_exclude: Vec::new(),
            trim_start_seconds: 0.0,
            timeline_offset_frames: 0,
            max_simultaneous: default_max_simultaneous(),
        }
    }
}

impl Config {
    /// Reads and validates a config file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        Config::parse(&read_config(path)?, path)
    }

    /// Parses and validates config text; `path` names the file in errors and sets the base folder.
    pub fn parse(text: &str, path: &Path) -> Result<Config, ConfigError> {
        let (config, checks) = Config::parse_unchecked(text, path)?;
        checks.finish(path)?;
        Ok(config)
    }

    /// Reads a config and checks its values and the files it names, reporting every problem of
    /// both kinds at once (`motionforge config check`, and before a build). `output` replaces
    /// `dataset.output`, as `build --output` does.
    pub fn load_checked(
        path: &Path,
        output: Option<PathBuf>,
    ) -> Result<(Config, InputSummary), ConfigError> {
        let text = read_config(path)?;
        let (mut config, mut checks) = Config::parse_unchecked(&text, path)?;
        if let Some(output) = output {
            config.dataset.output = std::path::absolute(&output).unwrap_or(output);
        }
        let summary = config.check_inputs_into(&mut checks);
        checks.finish(path)?;
        Ok((config, summary))
    }

    /// Deserialises the config and runs the value checks, leaving their problems to report.
    fn parse_unchecked<'i>(
        text: &'i str,
        path: &Path,
    ) -> Result<(Config, Checks<'i>), ConfigError> {
        // Parsed once into a spanned tree: it deserialises the config and tells problems' lines.
        let tree = toml::de::DeTable::parse(text).map_err(|e| ConfigError::Parse {
            path: path.to_path_buf(),
            line: None,
            message: e.to_string().trim_end().to_string(),
        })?;
        let parsed: Result<Config, _> =
            serde_path_to_error::deserialize(toml::Deserializer::from(tree.clone()));
        let mut checks = Checks::new(text, tree.into_inner());
        let mut config = parsed.map_err(|e| {
            use serde_path_to_error::Segment;
            let mut keys: Vec<Seg<'_>> = e
                .path()
                .iter()
                .filter_map(|s| match s {
                    Segment::Seq { index } => Some(Seg::I(*index)),
                    Segment::Map { key } => Some(Seg::K(key.as_str())),
                    _ => None,
                })
                .collect();
            let inner = e.inner();
            // Inside tagged tables (`[sources.labels]`) serde loses the span: find the key in
            // the file instead, the unknown one itself when that is the complaint.
            let unknown = inner
                .message()
                .strip_prefix("unknown field `")
                .and_then(|rest| rest.split('`').next());
            if let Some(field) = unknown
                && !matches!(keys.last(), Some(Seg::K(k)) if *k == field)
            {
                keys.push(Seg::K(field));
            }
            let exact = unknown.and_then(|_| checks.exact_line(&keys));
            let line = exact
                .or_else(|| inner.span().map(|s| line_of(text, s.start)))
                .or_else(|| checks.line(&keys));
            let key = e.path().to_string();
            let key = if key == "." {
                String::new()
            } else {
                format!("{key}: ")
            };
            ConfigError::Parse {
                path: path.to_path_buf(),
                line,
                message: format!("{key}{}", inner.message().trim_end()),
            }
        })?;
        // Lexically normalised, so `a/../fixtures/x.toml` and `fixtures/x.toml` show the same
        // capture paths (which splits are hashed from).
        config.base_dir = path.parent().map(normalize).unwrap_or_default();
        config.validate(&mut checks);
        Ok((config, checks))
    }

    fn validate(&self, c: &mut Checks<'_>) {
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
        if self.paraphrases.n == 0 || self.paraphrases.n > 50 {
            c.push(
                &[K("paraphrases"), K("n")],
                self.paraphrases.n.to_string(),
                "between 1 and 50 alternatives",
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
                    "a bundled profile name (bandai-namco, cmu, smpl-22) or a .toml file",
                );
            }
            for (file, fps) in &s.fps_override {
                if !(fps.is_finite() && *fps > 0.0) {
                    c.push(
                        &[K("sources"), I(i), K("fps_override"), K(file)],
                        fps.to_string(),
                        "a frame rate above 0",
                    );
                }
            }
            match &s.labels {
                LabelConfig::Filename { pattern, .. } => {
                    if let Err(e) = crate::annotate::filename::FilenamePattern::new(pattern) {
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
                && !(fps.is_finite() && *fps > 0.0)
            {
                c.push(
                    &at(&[K("labels"), K("fps")]),
                    fps.to_string(),
                    "a frame rate above 0",
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
        }
    }

    fn validate_splits(&self, c: &mut Checks<'_>) {
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
                "split names with shares, e.g. { train = 0.8, val = 0.1, test = 0.1 }",
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

    fn check_inputs_into(&self, c: &mut Checks<'_>) -> InputSummary {
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
                .and_then(|t| crate::annotate::taxonomy::TypeMap::new(t, &self.motion_types));
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
            if let Err(e) = crate::source::resolve_profile(self, s)
                && !s.profile.trim().is_empty()
            {
                c.push(
                    &[K("sources"), I(i), K("profile")],
                    format!("{:?}", s.profile),
                    &format!(
                        "a bundled profile ({}) or a readable profile .toml file: {e}",
                        crate::motion::ProfileSpec::bundled_names()
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
    fn glob_files(&self, pattern: &str) -> Vec<PathBuf> {
        let resolved = self.resolve(Path::new(pattern));
        glob::glob(&resolved.to_string_lossy())
            .map(|paths| paths.flatten().filter(|p| p.is_file()).collect())
            .unwrap_or_default()
    }

    /// What a pattern that matched nothing was expected to match, and why it may not have.
    fn no_match(&self, pattern: &str, what: &str) -> String {
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
        format!(
            "a pattern that matches {what} (resolved as {}{why}; paths are relative to the config file)",
            resolved.display()
        )
    }

    /// A path from the config, resolved against the config's folder.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            normalize(&self.base_dir.join(p))
        }
    }

    /// The output folder.
    pub fn output_dir(&self) -> PathBuf {
        self.resolve(&self.dataset.output)
    }

    /// The dataset's folder, `<output>/<name>`: shards under `data/`, card, manifest, reports and
    /// the build workspace.
    pub fn dataset_dir(&self) -> PathBuf {
        self.output_dir().join(&self.dataset.name)
    }

    /// The prompt templates: bundled, with any file in `prompts_dir` in its place.
    pub fn prompts(&self) -> Result<crate::llm::prompt::Prompts, crate::llm::prompt::PromptError> {
        match &self.prompts_dir {
            Some(dir) => crate::llm::prompt::Prompts::with_overrides(&self.resolve(dir)),
            None => crate::llm::prompt::Prompts::bundled(),
        }
    }

    /// The LLM response cache file.
    pub fn llm_cache_path(&self) -> PathBuf {
        match &self.llm_cache {
            Some(p) => self.resolve(p),
            None => self.dataset_dir().join("llm-cache.jsonl"),
        }
    }
}

/// Removes `.` and folds `dir/..` lexically, so paths print the way people wrote them.
fn normalize(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out: Vec<Component<'_>> = Vec::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir if matches!(out.last(), Some(Component::Normal(_))) => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    if out.is_empty() {
        PathBuf::from(".")
    } else {
        out.iter().collect()
    }
}

fn read_config(path: &Path) -> Result<String, ConfigError> {
    std::fs::read_to_string(path).map_err(|source| {
        if source.kind() == std::io::ErrorKind::NotFound {
            ConfigError::NotFound {
                path: path.to_path_buf(),
            }
        } else {
            ConfigError::Read {
                path: path.to_path_buf(),
                source,
            }
        }
    })
}

fn round6(x: f64) -> f64 {
    (x * 1e6).round() / 1e6
}

/// 1-based line of a byte offset.
fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|b| **b == b'\n')
        .count()
        + 1
}

/// One step of a key path: a table key or an array position.
#[derive(Debug, Clone, Copy)]
enum Seg<'a> {
    K(&'a str),
    I(usize),
}

/// Problems found while checking a config, with the lines of their keys.
struct Checks<'i> {
    text: &'i str,
    root: toml::de::DeValue<'i>,
    problems: Vec<Problem>,
}

impl<'i> Checks<'i> {
    fn new(text: &'i str, root: toml::de::DeTable<'i>) -> Checks<'i> {
        Checks {
            text,
            root: toml::de::DeValue::Table(root),
            problems: Vec::new(),
        }
    }

    fn push(&mut self, path: &[Seg<'_>], value: String, expected: &str) {
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
        self.problems.push(Problem {
            key,
            value,
            expected: expected.to_string(),
            line: self.line(path),
        });
    }

    /// The line of the deepest part of `path` the file spells out (a key left at its default
    /// points at its table).
    fn line(&self, path: &[Seg<'_>]) -> Option<usize> {
        self.find(path).1.map(|s| line_of(self.text, s.start))
    }

    /// The line of `path` itself, if the file spells all of it out.
    fn exact_line(&self, path: &[Seg<'_>]) -> Option<usize> {
        match self.find(path) {
            (found, Some(span)) if found == path.len() => Some(line_of(self.text, span.start)),
            _ => None,
        }
    }

    /// How many steps of `path` the file has, and the span of the last one found.
    fn find(&self, path: &[Seg<'_>]) -> (usize, Option<std::ops::Range<usize>>) {
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

    fn finish(mut self, path: &Path) -> Result<(), ConfigError> {
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

fn validate_llm(llm: &crate::llm::client::LlmConfig, c: &mut Checks<'_>) {
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
