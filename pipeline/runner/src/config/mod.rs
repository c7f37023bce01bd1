//! Build configuration (TOML), one typed section per stage, validated on load.
//!
//! Relative paths in a config resolve against the folder of the config file, so a build gives the
//! same result whatever the working folder.

mod checks;
mod section_checks;
mod source_checks;
use checks::{Checks, Seg, line_of};

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use motionforge_core::motion::ProfileSpec;
use motionforge_core::quality::Thresholds;

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
    pub motion_types: motionforge_sources::annotate::taxonomy::TypeMapConfig,
    /// Derived feature columns (6D rotations, velocities, foot contacts, future root).
    #[serde(default)]
    pub features: motionforge_core::features::FeatureConfig,
    /// Train/validation/test splits.
    #[serde(default)]
    pub splits: SplitConfig,
    /// Synthetic simultaneous pairs and their plausibility checks.
    #[serde(default)]
    pub synthetic: SyntheticConfig,
    /// The check of texts against motions (turn side, walking direction, hand).
    #[serde(default)]
    pub label_check: LabelCheckConfig,
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
    pub llm: Option<motionforge_llm::client::LlmConfig>,
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
    /// zstd level of the shards, 1 (fastest) to 22 (smallest); default 1.
    #[serde(default = "default_zstd_level")]
    pub zstd_level: i32,
    /// When `motionforge serve` rebuilds the dataset: a five-field cron expression in UTC
    /// (`"0 3 * * *"`), checked when the service loads the config.
    // Not serialised: it says when to build, not what, so it must not change the config fingerprint.
    #[serde(default, skip_serializing)]
    pub schedule: Option<String>,
}

pub use motionforge_format::io::parquet::DEFAULT_ZSTD_LEVEL;

fn default_zstd_level() -> i32 {
    DEFAULT_ZSTD_LEVEL
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

/// What a stage does with an LLM answer that fails its checks (a flagged part label, a paraphrase
/// line with a fault): `docs/llm-servers.md`, "What is checked".
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OnInvalid {
    /// Use the embedded labeller instead (part labels only; the label source says so).
    Embedded,
    /// Use nothing: no parts for the text, no paraphrase for the line.
    Drop,
    /// Use the answer anyway (counted as kept in the build report).
    Keep,
}

impl OnInvalid {
    /// The value as written in configs.
    pub fn as_str(self) -> &'static str {
        match self {
            OnInvalid::Embedded => "embedded",
            OnInvalid::Drop => "drop",
            OnInvalid::Keep => "keep",
        }
    }
}

fn embedded_on_invalid() -> OnInvalid {
    OnInvalid::Embedded
}
fn is_embedded(v: &OnInvalid) -> bool {
    *v == OnInvalid::Embedded
}
fn drop_on_invalid() -> OnInvalid {
    OnInvalid::Drop
}
fn is_drop(v: &OnInvalid) -> bool {
    *v == OnInvalid::Drop
}

/// Body-part labelling settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartLabelConfig {
    /// `embedded` (default) or `llm`.
    #[serde(default)]
    pub labeller: Labeller,
    /// SINC Table 1 prompt variant for the LLM.
    #[serde(default)]
    pub variant: motionforge_llm::prompt::PartPromptVariant,
    /// Never send requests; answers come from the cache only.
    #[serde(default)]
    pub offline: bool,
    /// Cache misses that cannot be asked: `embedded` (default) or `fail`.
    #[serde(default)]
    pub on_miss: OnMiss,
    /// Flagged answers (words outside the list, no part): `embedded` (default), `drop` or `keep`.
    // Skipped at its default so configs that leave it out keep their fingerprint.
    #[serde(default = "embedded_on_invalid", skip_serializing_if = "is_embedded")]
    pub on_invalid: OnInvalid,
}

impl Default for PartLabelConfig {
    fn default() -> Self {
        PartLabelConfig {
            labeller: Labeller::default(),
            variant: Default::default(),
            offline: false,
            on_miss: OnMiss::default(),
            on_invalid: OnInvalid::Embedded,
        }
    }
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
    /// Lines that fail the paraphrase checks: `drop` (default) or `keep`.
    // Skipped at its default so configs that leave it out keep their fingerprint.
    #[serde(default = "drop_on_invalid", skip_serializing_if = "is_drop")]
    pub on_invalid: OnInvalid,
}

fn default_paraphrases() -> usize {
    3
}

impl Default for ParaphraseConfig {
    fn default() -> Self {
        ParaphraseConfig {
            enabled: true,
            n: default_paraphrases(),
            on_invalid: OnInvalid::Drop,
        }
    }
}

/// The check of what a clip's text says (turn left or right, walk forward or back, left or right
/// hand) against what its motion does (`docs/plausibility.md`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct LabelCheckConfig {
    /// Leave out of the table the clips whose motion contradicts their text, and the synthetic
    /// pairs made from them. Off by default: they are only listed in the build report.
    #[serde(default)]
    pub drop: bool,
}

/// Mirroring settings.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MirrorConfig {
    /// Add a mirrored copy of every clip.
    #[serde(default = "yes")]
    pub enabled: bool,
    /// Bone offsets of the copy: `mirror` (default; the copy is the exact reflection, on the
    /// mirrored skeleton) or `keep` (the copy stays on the original skeleton, off by its
    /// left/right asymmetry). `docs/mirroring.md`.
    #[serde(default)]
    pub offsets: motionforge_core::motion::OffsetPolicy,
}

fn yes() -> bool {
    true
}

impl Default for MirrorConfig {
    fn default() -> Self {
        MirrorConfig {
            enabled: true,
            offsets: motionforge_core::motion::OffsetPolicy::default(),
        }
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
    pub reflections: BTreeMap<String, motionforge_core::motion::Reflection>,
    /// Where action labels come from.
    pub labels: LabelConfig,
    /// How annotations become clips.
    #[serde(default)]
    pub segment: SegmentConfig,
    /// For captures that are joint-position arrays (`.npy`): their joint layout, axes, units and
    /// rate. Without it every capture is read as BVH.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub positions: Option<PositionsConfig>,
    /// For AMASS captures (`.npz` of SMPL-H or SMPL-X pose parameters): the user's body model
    /// and how files are read (`docs/amass.md`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amass: Option<AmassConfig>,
}

/// How a source's AMASS files are read (`docs/amass.md`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AmassConfig {
    /// The body model folder, relative to the config: `smplh/{male,female,neutral}/model.npz`
    /// and `smplx/...`, as AMASS documents it.
    pub body_model: String,
    /// Shape coefficients used (HumanML3D: 10).
    #[serde(default = "default_num_betas")]
    pub num_betas: usize,
    /// The model each file gets: `file` (its `gender`), `male`, `female` or `neutral`.
    #[serde(default)]
    pub gender: motionforge_sources::amass::GenderChoice,
    /// `resample` (by time to the dataset rate) or `humanml3d` (HumanML3D's frame stride).
    #[serde(default)]
    pub frame_rate: motionforge_sources::amass::FrameRateMode,
    /// HumanML3D's gender quirk: only a str `male` gets the male model, every other file (a
    /// bytes `gender` among them) the female one.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub humanml3d_gender: bool,
    /// `body_model` resolved against the config's folder.
    #[serde(skip)]
    pub body_model_dir: PathBuf,
}

/// HumanML3D's shape coefficients: the first 10 betas.
pub const DEFAULT_NUM_BETAS: usize = 10;

fn default_num_betas() -> usize {
    DEFAULT_NUM_BETAS
}

/// Joint layout of a joint-position array.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
pub enum PositionLayoutName {
    /// The 22 SMPL body joints (HumanML3D `new_joints`).
    #[serde(rename = "smpl-22")]
    Smpl22,
    /// The 52 SMPL-H joints (HumanML3D `joints` and `pose_data`): the first 22 are the body, the
    /// 30 finger joints after them are not used.
    #[serde(rename = "smplh-52")]
    SmplH52,
}

impl PositionLayoutName {
    /// Joints per frame the layout stores.
    pub fn joints(self) -> usize {
        match self {
            PositionLayoutName::Smpl22 => 22,
            PositionLayoutName::SmplH52 => 52,
        }
    }

    /// The name as written in configs.
    pub fn as_str(self) -> &'static str {
        match self {
            PositionLayoutName::Smpl22 => "smpl-22",
            PositionLayoutName::SmplH52 => "smplh-52",
        }
    }
}

/// How a source's joint-position arrays are read (`docs/humanml3d.md`, "Joint-position captures").
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PositionsConfig {
    /// Joint layout of the arrays.
    pub layout: PositionLayoutName,
    /// The arrays' up axis (HumanML3D: `+y`; AMASS before HumanML3D's swap: `+z`).
    #[serde(default = "default_positions_up")]
    pub up: motionforge_core::motion::SignedAxis,
    /// The direction the body faces at rest in the arrays (HumanML3D: `+z`).
    #[serde(default = "default_positions_forward")]
    pub forward: motionforge_core::motion::SignedAxis,
    /// Metres per unit of the arrays (HumanML3D: 1).
    #[serde(default = "default_positions_units")]
    pub units: f64,
    /// Frame rate of the arrays (HumanML3D: 20).
    pub fps: f64,
    /// Negate x before anything else, as HumanML3D's `raw_pose_processing` does to its
    /// `pose_data` arrays when it cuts them (`data[..., 0] *= -1`); its `joints` and
    /// `new_joints` have it done already.
    #[serde(default)]
    pub negate_x: bool,
    /// Largest relative change of a bone's length from its mean over the capture; a capture
    /// whose bones wander further is refused (file, frame, bone).
    #[serde(default = "default_bone_tolerance")]
    pub bone_tolerance: f64,
}

fn default_positions_up() -> motionforge_core::motion::SignedAxis {
    motionforge_core::motion::SignedAxis {
        axis: 1,
        negative: false,
    }
}

fn default_positions_forward() -> motionforge_core::motion::SignedAxis {
    motionforge_core::motion::SignedAxis {
        axis: 2,
        negative: false,
    }
}

/// Metres per unit of a joint-position array accepted by `[sources.positions] units`: from
/// micrometres to thousands of kilometres. With values bounded by `motion::bvh::MAX_MAGNITUDE`
/// (as BVH values are), positions stay far from overflow in every feature.
pub const UNITS_RANGE: std::ops::RangeInclusive<f64> = 1e-6..=1e6;

fn default_positions_units() -> f64 {
    1.0
}

/// The default bone-length tolerance: 5%. HumanML3D's arrays come from SMPL meshes, whose bones
/// keep their length to float precision; 5% leaves room for other position sources (markers,
/// estimators) while refusing arrays that are not one body (swapped joints, a wrong layout).
pub const DEFAULT_BONE_TOLERANCE: f64 = 0.05;

fn default_bone_tolerance() -> f64 {
    DEFAULT_BONE_TOLERANCE
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
        /// Cut rows as HumanML3D's `raw_pose_processing` does: its dataset-specific head trims
        /// first (by `source_path`), then `[start_frame:end_frame]` as a Python slice, so `-1`
        /// stops one frame before the end (`docs/humanml3d.md`).
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        humanml3d_cuts: bool,
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
    /// What the manifest records of this config. Where the dataset is written is not part of what
    /// it is: the same config built into another folder gives the same fingerprint.
    pub fn built_from(&self) -> motionforge_format::io::manifest::BuiltFrom {
        let mut content = self.clone();
        content.dataset.output = PathBuf::new();
        motionforge_format::io::manifest::BuiltFrom {
            dataset: self.dataset.name.clone(),
            fps: self.dataset.fps,
            seed: self.dataset.seed,
            config_fingerprint: motionforge_core::base::Fingerprint::new("config", 1)
                .json("config", &content)
                .finish(),
        }
    }

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
            // Misspelt keys and variant names (`kind = "filname"`) get the closest valid one.
            let typo = unknown.or_else(|| {
                inner
                    .message()
                    .strip_prefix("unknown variant `")
                    .and_then(|rest| rest.split('`').next())
            });
            let hint = typo
                .and_then(|field| closest_expected(field, inner.message()))
                .map(|k| format!("; did you mean `{k}`?"))
                .unwrap_or_default();
            ConfigError::Parse {
                path: path.to_path_buf(),
                line,
                message: format!("{key}{}{hint}", inner.message().trim_end()),
            }
        })?;
        // Lexically normalised, so `a/../fixtures/x.toml` and `fixtures/x.toml` show the same
        // capture paths (which splits are hashed from).
        config.base_dir = path
            .parent()
            .map(motionforge_core::base::lexical_path)
            .unwrap_or_default();
        for source in &mut config.sources {
            if let Some(amass) = &mut source.amass {
                amass.body_model_dir = motionforge_core::base::lexical_path(
                    &config.base_dir.join(Path::new(&amass.body_model)),
                );
            }
        }
        config.validate(&mut checks);
        Ok((config, checks))
    }

    /// A path from the config, resolved against the config's folder.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            motionforge_core::base::lexical_path(&self.base_dir.join(p))
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
    pub fn prompts(
        &self,
    ) -> Result<motionforge_llm::prompt::Prompts, motionforge_llm::prompt::PromptError> {
        match &self.prompts_dir {
            Some(dir) => motionforge_llm::prompt::Prompts::with_overrides(&self.resolve(dir)),
            None => motionforge_llm::prompt::Prompts::bundled(),
        }
    }

    /// The LLM response cache file.
    pub fn llm_cache_path(&self) -> PathBuf {
        match &self.llm_cache {
            Some(p) => self.resolve(p),
            None => self
                .dataset_dir()
                .join(motionforge_core::base::layout::LLM_CACHE_FILE),
        }
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

/// Split settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SplitConfig {
    /// Split names and their share of captures (or subjects); normalised to sum to 1.
    #[serde(default = "default_ratios")]
    pub ratios: BTreeMap<String, f64>,
    /// Regex with a named group `subject` matched against each capture's path: captures of one
    /// subject share a split. Absent: each capture is its own unit.
    #[serde(default)]
    pub subject_pattern: Option<String>,
    /// A CSV of `capture,split` rows (capture = file stem or path as shown in the table), relative
    /// to the config; listed captures take that split, the rest are hashed.
    #[serde(default)]
    pub file: Option<String>,
}

fn default_ratios() -> BTreeMap<String, f64> {
    BTreeMap::from([
        ("train".to_string(), 0.8),
        ("validation".to_string(), 0.1),
        ("test".to_string(), 0.1),
    ])
}

impl Default for SplitConfig {
    fn default() -> Self {
        SplitConfig {
            ratios: default_ratios(),
            subject_pattern: None,
            file: None,
        }
    }
}

/// Synthetic-pair settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SyntheticConfig {
    /// Build synthetic pairs at all.
    #[serde(default = "yes")]
    pub enabled: bool,
    /// Chance that an eligible clip is paired with a random compatible partner (SINC: 0.5).
    #[serde(default = "half")]
    pub probability: f64,
    /// Most composites one clip may take part in (none when absent).
    #[serde(default)]
    pub max_per_clip: Option<usize>,
    /// Compose every compatible pair instead of sampling (small sets).
    #[serde(default)]
    pub exhaustive: bool,
    /// Crop the longer clip at a seeded random offset (overrides `keep_action`).
    #[serde(default)]
    pub random_offset: bool,
    /// Crop the longer clip to the window that keeps most of its action (locomotion: path and
    /// heading change; other parts: their motion energy). `false` crops from its start (SINC's
    /// protocol). `docs/synthetic-pairs.md`.
    #[serde(default = "yes")]
    pub keep_action: bool,
    /// Pairs whose crop keeps less than this share of the longer clip's action are dropped
    /// (`action_cut`); 0 keeps every pair.
    #[serde(default = "half")]
    pub min_action_kept: f64,
    /// Plausibility thresholds; composites that fail are dropped, counted by reason.
    #[serde(default)]
    pub thresholds: Thresholds,
    /// Ask the LLM (the `pair_compat` prompt, cached) whether a person can do both actions at
    /// once, and drop the pairs it says no to. Off by default; needs an `[llm]` section.
    #[serde(default)]
    pub llm_check: bool,
}

fn half() -> f64 {
    0.5
}

impl Default for SyntheticConfig {
    fn default() -> Self {
        SyntheticConfig {
            enabled: true,
            probability: half(),
            max_per_clip: None,
            exhaustive: false,
            random_offset: false,
            keep_action: true,
            min_action_kept: half(),
            thresholds: Thresholds::default(),
            llm_check: false,
        }
    }
}

/// The profile a source names (bundled, or a TOML file relative to the config), with the source's
/// `pairs` and `reflections` overrides applied.
pub fn resolve_profile(config: &Config, source: &SourceConfig) -> Result<ProfileSpec, String> {
    let mut spec = load_profile(config, source)?;
    spec.pairs.extend(source.pairs.clone());
    spec.reflections.extend(source.reflections.clone());
    Ok(spec)
}

fn load_profile(config: &Config, source: &SourceConfig) -> Result<ProfileSpec, String> {
    if source.profile.ends_with(".toml") {
        let path = config.resolve(Path::new(&source.profile));
        let text = std::fs::read_to_string(&path)
            .map_err(|e| format!("profile {}: {e}", path.display()))?;
        ProfileSpec::from_toml(&source.profile, &text).map_err(|e| e.to_string())
    } else {
        ProfileSpec::bundled(&source.profile).map_err(|e| e.to_string())
    }
}

/// The key serde's "unknown field `x`, expected one of `a`, `b`" message lists that is closest to
/// `field`, when one is close enough to be a typo (Jaro-Winkler 0.7 or more, clap's threshold for
/// subcommand suggestions).
fn closest_expected<'m>(field: &str, message: &'m str) -> Option<&'m str> {
    let (_, expected) = message.split_once("expected")?;
    expected
        .split('`')
        .skip(1)
        .step_by(2)
        .map(|k| (strsim::jaro_winkler(field, k), k))
        .filter(|(score, _)| *score >= 0.7)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, k)| k)
}

#[cfg(test)]
mod suggestion_tests {
    use super::*;

    #[test]
    fn an_unknown_key_gets_the_closest_known_one() {
        let text = "[dataset]\nnmae = \"demo\"\nfps = 30\n";
        let err = Config::parse(text, Path::new("typo.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("unknown field `nmae`"), "{err}");
        assert!(err.contains("did you mean `name`?"), "{err}");
        // Nothing close: no guess.
        let err = Config::parse("[dataset]\nzzzzzz = 1\n", Path::new("typo.toml"))
            .unwrap_err()
            .to_string();
        assert!(!err.contains("did you mean"), "{err}");
    }
}
