//! The checks of one `[[sources]]` table, each of its sections beside the others: its values
//! (name, capture patterns, profile, frame-rate overrides, labels, segmentation, joint-position
//! and AMASS settings), then the files it names.

use super::section_checks::key_at;
use super::*;
use motionforge_core::motion::bvh::FPS_RANGE;

/// "a frame rate from 1 to 10000 fps": the capture rates a source may state, as a problem says.
fn fps_range_text() -> String {
    format!("{} to {} fps", FPS_RANGE.start(), FPS_RANGE.end())
}

impl SourceConfig {
    /// The values of the source at `at`; `names` holds the names of the sources before it.
    /// `dataset_fps` is the rate clips are resampled to (AMASS's `humanml3d` stride needs 20).
    pub(super) fn check<'s>(
        &'s self,
        at: &[Seg<'_>],
        dataset_fps: f64,
        names: &mut std::collections::BTreeSet<&'s String>,
        c: &mut Checks<'_>,
    ) {
        self.check_name_captures_and_profile(at, names, c);
        self.labels.check(&key_at(at, &[Seg::K("labels")]), c);
        self.segment.check(&key_at(at, &[Seg::K("segment")]), c);
        if let Some(p) = &self.positions {
            p.check(at, &self.profile, c);
        }
        if let Some(a) = &self.amass {
            a.check(at, self, dataset_fps, c);
        }
    }

    /// A unique name, valid glob patterns, a profile, and frame-rate overrides in range.
    fn check_name_captures_and_profile<'s>(
        &'s self,
        at: &[Seg<'_>],
        names: &mut std::collections::BTreeSet<&'s String>,
        c: &mut Checks<'_>,
    ) {
        use Seg::{I, K};
        if self.name.trim().is_empty() {
            c.push(
                &key_at(at, &[K("name")]),
                format!("{:?}", self.name),
                "a non-empty name",
            );
        } else if !names.insert(&self.name) {
            c.push(
                &key_at(at, &[K("name")]),
                format!("{:?}", self.name),
                "a name no other source uses",
            );
        }
        if self.captures.is_empty() {
            c.push(
                &key_at(at, &[K("captures")]),
                "[]".into(),
                "at least one glob pattern",
            );
        }
        for (j, pattern) in self.captures.iter().enumerate() {
            if let Err(e) = glob::Pattern::new(pattern) {
                c.push(
                    &key_at(at, &[K("captures"), I(j)]),
                    format!("{pattern:?}"),
                    &format!("a valid glob pattern ({e})"),
                );
            } else if pattern.trim().is_empty() {
                c.push(
                    &key_at(at, &[K("captures"), I(j)]),
                    format!("{pattern:?}"),
                    "a glob pattern of capture files",
                );
            }
        }
        if self.profile.trim().is_empty() {
            c.push(
                &key_at(at, &[K("profile")]),
                "\"\"".into(),
                "a bundled profile name (bandai-namco, cmu, smpl-22, smplh-52, smplx-55) or a .toml file",
            );
        }
        for (file, fps) in &self.fps_override {
            if !FPS_RANGE.contains(fps) {
                c.push(
                    &key_at(at, &[K("fps_override"), K(file)]),
                    fps.to_string(),
                    &format!("a capture frame rate from {}", fps_range_text()),
                );
            }
        }
    }

    /// The files the source at `at` names: its capture patterns match files (counted into
    /// `summary`), its profile loads, its fps table, AMASS body model and annotations exist.
    pub(super) fn check_files(
        &self,
        config: &Config,
        at: &[Seg<'_>],
        summary: &mut InputSummary,
        c: &mut Checks<'_>,
    ) {
        use Seg::{I, K};
        let mut files = std::collections::BTreeSet::new();
        for (j, pattern) in self.captures.iter().enumerate() {
            if pattern.trim().is_empty() || glob::Pattern::new(pattern).is_err() {
                continue;
            }
            let found = config.glob_files(pattern);
            if found.is_empty() {
                c.push(
                    &key_at(at, &[K("captures"), I(j)]),
                    format!("{pattern:?}"),
                    &config.no_match(pattern, "capture files"),
                );
            }
            files.extend(found);
        }
        summary.captures.push(files.len());
        if let Err(e) = super::resolve_profile(config, self)
            && !self.profile.trim().is_empty()
        {
            c.push(
                &key_at(at, &[K("profile")]),
                format!("{:?}", self.profile),
                &format!(
                    "a bundled profile ({}) or a readable profile .toml file: {e}",
                    motionforge_core::motion::ProfileSpec::bundled_names()
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            );
        }
        if let Some(table) = &self.fps_table {
            let key = key_at(at, &[K("fps_table")]);
            expect_existing(config, &key, table, "JSON file", Path::is_file, c);
        }
        if let Some(a) = &self.amass
            && !a.body_model.trim().is_empty()
        {
            check_body_model(a, &key_at(at, &[K("amass"), K("body_model")]), c);
        }
        self.labels
            .check_files(config, &key_at(at, &[K("labels")]), c);
    }
}

impl LabelConfig {
    /// The values of the labels section at `at`: a file-name pattern that parses, an annotation
    /// path, a key pattern with a `key` group, an annotation frame rate in range.
    pub(super) fn check(&self, at: &[Seg<'_>], c: &mut Checks<'_>) {
        use Seg::K;
        match self {
            LabelConfig::Filename { pattern, .. } => {
                if let Err(e) =
                    motionforge_sources::annotate::filename::FilenamePattern::new(pattern)
                {
                    c.push(
                        &key_at(at, &[K("pattern")]),
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
                        &key_at(at, &[K("path")]),
                        "\"\"".into(),
                        "the annotation file (relative to the config file)",
                    );
                }
                if let Some(p) = key_pattern
                    && !regex::Regex::new(p)
                        .is_ok_and(|r| r.capture_names().flatten().any(|n| n == "key"))
                {
                    c.push(
                        &key_at(at, &[K("key_pattern")]),
                        format!("{p:?}"),
                        "a regex with a named group `key`",
                    );
                }
            }
            LabelConfig::EventLog { path, .. } => {
                if path.trim().is_empty() {
                    c.push(
                        &key_at(at, &[K("path")]),
                        "\"\"".into(),
                        "the event log file(s) (relative to the config file)",
                    );
                }
            }
        }
        if let LabelConfig::EventLog { fps, .. } | LabelConfig::FrameIndex { fps, .. } = self
            && !FPS_RANGE.contains(fps)
        {
            c.push(
                &key_at(at, &[K("fps")]),
                fps.to_string(),
                &format!("a frame rate from {}", fps_range_text()),
            );
        }
    }

    /// The annotation files of the labels section at `at` exist (a pattern matches files, an
    /// index file and its caption folder are there).
    fn check_files(&self, config: &Config, at: &[Seg<'_>], c: &mut Checks<'_>) {
        use Seg::K;
        match self {
            LabelConfig::Filename { .. } => {}
            LabelConfig::Babel { path, .. } | LabelConfig::EventLog { path, .. } => {
                if !path.trim().is_empty() && config.glob_files(path).is_empty() {
                    c.push(
                        &key_at(at, &[K("path")]),
                        format!("{path:?}"),
                        &config.no_match(path, "annotation files"),
                    );
                }
            }
            LabelConfig::FrameIndex { path, texts, .. } => {
                if !path.trim().is_empty() {
                    let key = key_at(at, &[K("path")]);
                    expect_existing(config, &key, path, "index CSV", Path::is_file, c);
                }
                if let Some(dir) = texts {
                    let key = key_at(at, &[K("texts")]);
                    expect_existing(
                        config,
                        &key,
                        dir,
                        "folder of caption files",
                        Path::is_dir,
                        c,
                    );
                }
            }
        }
    }
}

impl SegmentConfig {
    /// Clip lengths (a minimum, a longer maximum), the start trim and the most simultaneous
    /// actions, of the segment section at `at`.
    pub(super) fn check(&self, at: &[Seg<'_>], c: &mut Checks<'_>) {
        use Seg::K;
        if !(self.min_seconds.is_finite() && self.min_seconds >= 0.0) {
            c.push(
                &key_at(at, &[K("min_seconds")]),
                self.min_seconds.to_string(),
                "zero or more seconds",
            );
        } else if !(self.max_seconds.is_finite() && self.max_seconds > self.min_seconds) {
            c.push(
                &key_at(at, &[K("max_seconds")]),
                self.max_seconds.to_string(),
                &format!("a length above min_seconds ({})", self.min_seconds),
            );
        }
        if !(self.trim_start_seconds >= 0.0 && self.trim_start_seconds.is_finite()) {
            c.push(
                &key_at(at, &[K("trim_start_seconds")]),
                self.trim_start_seconds.to_string(),
                "zero or more seconds",
            );
        }
        if self.max_simultaneous < 2 {
            c.push(
                &key_at(at, &[K("max_simultaneous")]),
                self.max_simultaneous.to_string(),
                "2 or more",
            );
        }
    }
}

impl PositionsConfig {
    /// Joint-position captures of the source at `source` (whose profile is `profile`): the SMPL
    /// body profile, a frame rate, units and bone tolerance in range, distinct up and forward axes.
    pub(super) fn check(&self, source: &[Seg<'_>], profile: &str, c: &mut Checks<'_>) {
        use Seg::K;
        let at = key_at(source, &[K("positions")]);
        if profile.trim() != "smpl-22" {
            c.push(
                &key_at(source, &[K("profile")]),
                format!("{profile:?}"),
                "`smpl-22`: joint-position captures (`positions`) become motions on the SMPL body skeleton",
            );
        }
        if !FPS_RANGE.contains(&self.fps) {
            c.push(
                &key_at(&at, &[K("fps")]),
                self.fps.to_string(),
                &format!("a frame rate from {} (HumanML3D: 20)", fps_range_text()),
            );
        }
        if !crate::config::UNITS_RANGE.contains(&self.units) {
            c.push(
                &key_at(&at, &[K("units")]),
                // `1e160` as written, not 161 digits.
                if self.units.abs() >= 1e15 || (self.units != 0.0 && self.units.abs() < 1e-4) {
                    format!("{:e}", self.units)
                } else {
                    self.units.to_string()
                },
                &format!(
                    "metres per unit of the arrays, from {:e} to {:e} (HumanML3D: 1; millimetres: 0.001)",
                    crate::config::UNITS_RANGE.start(),
                    crate::config::UNITS_RANGE.end()
                ),
            );
        }
        if !(self.bone_tolerance.is_finite()
            && self.bone_tolerance > 0.0
            && self.bone_tolerance < 1.0)
        {
            c.push(
                &key_at(&at, &[K("bone_tolerance")]),
                self.bone_tolerance.to_string(),
                "a fraction above 0 and below 1 (default 0.05)",
            );
        }
        if self.up.axis == self.forward.axis {
            c.push(
                &key_at(&at, &[K("forward")]),
                self.forward.to_string(),
                &format!("an axis other than the up axis {}", self.up),
            );
        }
    }
}

impl AmassConfig {
    /// AMASS captures of `source` (at `at`): not mixed with joint positions, a body-model
    /// profile, a body model folder, the shape coefficients, and HumanML3D's stride only at
    /// 20 fps (`dataset_fps`).
    pub(super) fn check(
        &self,
        at: &[Seg<'_>],
        source: &SourceConfig,
        dataset_fps: f64,
        c: &mut Checks<'_>,
    ) {
        use Seg::K;
        if source.positions.is_some() {
            c.push(
                &key_at(at, &[K("amass")]),
                "(with `positions`)".into(),
                "either `amass` or `positions`: a source's captures are one kind of file",
            );
        }
        let profile = source.profile.trim();
        if !(["smplh-52", "smplx-55"].contains(&profile) || profile.ends_with(".toml")) {
            c.push(
                &key_at(at, &[K("profile")]),
                format!("{:?}", source.profile),
                "`smplh-52` (SMPL-H files) or `smplx-55` (SMPL-X files): AMASS captures become motions on the body model's skeleton",
            );
        }
        if self.body_model.trim().is_empty() {
            c.push(
                &key_at(at, &[K("amass"), K("body_model")]),
                "\"\"".into(),
                "the body model folder (smplh/{male,female,neutral}/model.npz), relative to the config file",
            );
        }
        if self.num_betas > motionforge_sources::amass::model::MAX_BETAS {
            c.push(
                &key_at(at, &[K("amass"), K("num_betas")]),
                self.num_betas.to_string(),
                &format!(
                    "0 to {} shape coefficients (HumanML3D: 10)",
                    motionforge_sources::amass::model::MAX_BETAS
                ),
            );
        }
        if self.frame_rate == motionforge_sources::amass::FrameRateMode::Humanml3d
            && (dataset_fps - 20.0).abs() > 1e-9
        {
            c.push(
                &key_at(at, &[K("amass"), K("frame_rate")]),
                "\"humanml3d\"".into(),
                &format!(
                    "`resample` with dataset.fps = {dataset_fps}: the `humanml3d` stride gives HumanML3D's 20 fps frames (set dataset.fps = 20)"
                ),
            );
        }
    }
}

/// A problem at `key` unless `path`, relative to the config file, is there as `there` asks (a
/// file, a folder): `an existing {what} (resolved as ...)`.
fn expect_existing(
    config: &Config,
    key: &[Seg<'_>],
    path: &str,
    what: &str,
    there: fn(&Path) -> bool,
    c: &mut Checks<'_>,
) {
    let resolved = config.resolve(Path::new(path));
    if !there(&resolved) {
        c.push(
            key,
            format!("{path:?}"),
            &format!("an existing {what} (resolved as {})", resolved.display()),
        );
    }
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
