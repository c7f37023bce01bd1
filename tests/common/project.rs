//! A test project, built as cargo's `project().file().build()`: a temporary folder with captures,
//! fixtures, files and a config, and the binary run inside it.
//!
//! ```ignore
//! let p = Project::new()
//!     .captures("bandai-namco-1", &WALK_KICK_BYE)
//!     .config(ConfigSpec::new("llm").source(Source::bandai1("bandai")))
//!     .build();
//! let out = p.motionforge(&["build", "--config", "build.toml"]).output().unwrap();
//! ```

use std::path::{Path, PathBuf};
use std::process::Command;

use toml::{Table, Value};

/// The file name every project's config is written to.
pub(crate) const CONFIG_FILE: &str = "build.toml";

/// What [`ProjectBuilder::build`] puts at a path of the project.
enum Content {
    Text(String),
    /// A file or a folder (copied recursively).
    Copy(PathBuf),
}

/// The files of a project to be; [`Project::new`] starts one.
#[must_use]
pub(crate) struct ProjectBuilder {
    entries: Vec<(PathBuf, Content)>,
}

/// A built project: its folder (removed when dropped) and its config, `build.toml`.
pub(crate) struct Project {
    dir: tempfile::TempDir,
}

impl Project {
    /// An empty project to fill.
    #[allow(clippy::new_ret_no_self)]
    pub(crate) fn new() -> ProjectBuilder {
        ProjectBuilder {
            entries: Vec::new(),
        }
    }

    /// The project folder.
    pub(crate) fn path(&self) -> &Path {
        self.dir.path()
    }

    /// A path inside the project folder.
    pub(crate) fn join(&self, path: impl AsRef<Path>) -> PathBuf {
        self.dir.path().join(path)
    }

    /// The config file, `build.toml` in the project folder.
    pub(crate) fn config_path(&self) -> PathBuf {
        self.join(CONFIG_FILE)
    }

    /// The config, loaded as a build loads it.
    pub(crate) fn load(&self) -> motionforge::config::Config {
        let path = self.config_path();
        motionforge::config::Config::load(&path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    }

    /// The dataset folder the config builds, `<output>/<name>`.
    pub(crate) fn dataset(&self) -> PathBuf {
        self.load().dataset_dir()
    }

    /// The tested binary with `args`, run in the project folder.
    pub(crate) fn motionforge<S: AsRef<std::ffi::OsStr>>(&self, args: &[S]) -> Command {
        let mut command = Command::new(env!("CARGO_BIN_EXE_motionforge"));
        command.args(args).current_dir(self.path());
        command
    }

    /// Writes `text` to a file of the project (its folders made as needed).
    pub(crate) fn write(&self, path: impl AsRef<Path>, text: impl AsRef<[u8]>) {
        let path = self.join(path);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).unwrap();
        }
        std::fs::write(&path, text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
}

impl ProjectBuilder {
    /// A file with this text.
    pub(crate) fn file(mut self, path: impl AsRef<Path>, text: impl Into<String>) -> Self {
        self.entries
            .push((path.as_ref().to_path_buf(), Content::Text(text.into())));
        self
    }

    /// A copy of a file or folder (recursively) at `to`.
    pub(crate) fn copy(mut self, from: impl AsRef<Path>, to: impl AsRef<Path>) -> Self {
        self.entries.push((
            to.as_ref().to_path_buf(),
            Content::Copy(from.as_ref().to_path_buf()),
        ));
        self
    }

    /// A copy of the repository's `fixtures/<name>` (file or folder) under the same name.
    pub(crate) fn fixture(self, name: &str) -> Self {
        self.copy(super::repo().join("fixtures").join(name), name)
    }

    /// Real captures (`<stem>.bvh` of `../shared/data/<set>/data`) copied into `captures/`.
    pub(crate) fn captures(self, set: &str, stems: &[&str]) -> Self {
        self.captures_with(set, stems, &["bvh"])
    }

    /// [`ProjectBuilder::captures`], with each stem's files of these extensions (sidecars).
    pub(crate) fn captures_with(mut self, set: &str, stems: &[&str], extensions: &[&str]) -> Self {
        let data = super::shared_data().join(set).join("data");
        for stem in stems {
            for ext in extensions {
                let name = format!("{stem}.{ext}");
                self = self.copy(data.join(&name), Path::new("captures").join(name));
            }
        }
        self
    }

    /// The config, rendered from its spec into `build.toml`.
    pub(crate) fn config(self, spec: ConfigSpec) -> Self {
        let text = spec.render();
        self.config_toml(text)
    }

    /// The config, rendered from its spec into `path` (a config inside a copied fixture folder,
    /// whose relative paths are the fixture's).
    pub(crate) fn config_at(self, path: impl AsRef<Path>, spec: ConfigSpec) -> Self {
        let text = spec.render();
        self.file(path, text)
    }

    /// The config as TOML text, written as it is into `build.toml`.
    pub(crate) fn config_toml(self, text: impl Into<String>) -> Self {
        self.file(CONFIG_FILE, text)
    }

    /// Makes the folder and writes every file, in the order given.
    pub(crate) fn build(self) -> Project {
        let project = Project {
            dir: tempfile::tempdir().unwrap(),
        };
        for (path, content) in self.entries {
            let target = project.join(&path);
            if let Some(parent) = target.parent() {
                std::fs::create_dir_all(parent).unwrap();
            }
            match content {
                Content::Text(text) => project.write(&path, text),
                Content::Copy(from) if from.is_dir() => super::copy_dir(&from, &target),
                Content::Copy(from) => {
                    std::fs::copy(&from, &target)
                        .unwrap_or_else(|e| panic!("{}: {e}", from.display()));
                }
            }
        }
        project
    }
}

/// A config as values, rendered with the `toml` crate: the common shapes have their own methods,
/// anything else goes through [`ConfigSpec::set`] or [`ConfigSpec::toml`].
#[derive(Clone, Debug)]
#[must_use]
pub(crate) struct ConfigSpec {
    table: Table,
}

impl ConfigSpec {
    /// `[dataset]` with this name, built into `out`.
    pub(crate) fn new(name: &str) -> ConfigSpec {
        ConfigSpec {
            table: Table::new(),
        }
        .set("dataset.name", name)
        .set("dataset.output", "out")
    }

    /// The bundled demo (`fixtures/demo.toml`) with its inputs' paths made absolute, so that it
    /// builds from any folder, into `out` beside the config.
    pub(crate) fn demo() -> ConfigSpec {
        let fixtures = std::fs::canonicalize(super::repo().join("fixtures")).unwrap();
        let mut spec = ConfigSpec::from_file(&fixtures.join("demo.toml")).output("out");
        let absolute = |value: &mut Value| {
            if let Value::String(path) = value {
                *path = fixtures.join(&*path).to_string_lossy().into_owned();
            }
        };
        let Some(Value::Array(sources)) = spec.table.get_mut("sources") else {
            panic!("the demo config has no sources");
        };
        for source in sources {
            if let Some(Value::Array(captures)) = source.get_mut("captures") {
                captures.iter_mut().for_each(absolute);
            }
            if let Some(path) = source.get_mut("labels").and_then(|l| l.get_mut("path")) {
                absolute(path);
            }
        }
        spec
    }

    /// A config file as it is (a bundled fixture's), to change and write elsewhere.
    pub(crate) fn from_file(path: &Path) -> ConfigSpec {
        let text =
            std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        ConfigSpec {
            table: text
                .parse()
                .unwrap_or_else(|e| panic!("{}: {e}", path.display())),
        }
    }

    /// `dataset.name`.
    pub(crate) fn name(self, name: &str) -> Self {
        self.set("dataset.name", name)
    }

    /// `dataset.output`.
    pub(crate) fn output(self, output: impl AsRef<Path>) -> Self {
        let output = output.as_ref().to_string_lossy().into_owned();
        self.set("dataset.output", output)
    }

    /// `dataset.fps`.
    pub(crate) fn fps(self, fps: i64) -> Self {
        self.set("dataset.fps", fps)
    }

    /// `dataset.seed`.
    pub(crate) fn seed(self, seed: i64) -> Self {
        self.set("dataset.seed", seed)
    }

    /// `dataset.schedule`, when `serve` rebuilds the dataset (a cron expression).
    pub(crate) fn schedule(self, cron: &str) -> Self {
        self.set("dataset.schedule", cron)
    }

    /// `dataset.shard_bytes`, the size a shard is cut at.
    pub(crate) fn shard_bytes(self, bytes: i64) -> Self {
        self.set("dataset.shard_bytes", bytes)
    }

    /// Only the `[[sources]]` entries with these names, in their order.
    pub(crate) fn only_sources(mut self, names: &[&str]) -> Self {
        if let Some(Value::Array(sources)) = self.table.get_mut("sources") {
            sources.retain(|s| {
                s.get("name")
                    .and_then(Value::as_str)
                    .is_some_and(|n| names.contains(&n))
            });
        }
        self
    }

    /// Sets the value at a dotted key of the `[[sources]]` entry named `source`.
    pub(crate) fn set_in_source(
        mut self,
        source: &str,
        key: &str,
        value: impl Into<Value>,
    ) -> Self {
        let Some(Value::Array(sources)) = self.table.get_mut("sources") else {
            panic!("no sources to set {key} in");
        };
        let Some(Value::Table(entry)) = sources
            .iter_mut()
            .find(|s| s.get("name").and_then(Value::as_str) == Some(source))
        else {
            panic!("no source named {source}");
        };
        set_dotted(entry, key, value.into());
        self
    }

    /// One more `[[sources]]` entry.
    pub(crate) fn source(mut self, source: Source) -> Self {
        let sources = self
            .table
            .entry("sources")
            .or_insert_with(|| Value::Array(Vec::new()));
        match sources {
            Value::Array(list) => list.push(Value::Table(source.table)),
            other => panic!("sources is not a list: {other}"),
        }
        self
    }

    /// `mirror.enabled`.
    pub(crate) fn mirror(self, enabled: bool) -> Self {
        self.set("mirror.enabled", enabled)
    }

    /// `synthetic.enabled`.
    pub(crate) fn synthetic(self, enabled: bool) -> Self {
        self.set("synthetic.enabled", enabled)
    }

    /// `[llm]` at `base_url` (see [`super::llm::LlmServer::base_url`]) for model `test-model`,
    /// with a rate limit and backoff that keep tests fast.
    pub(crate) fn llm(self, base_url: &str) -> Self {
        self.set("llm.base_url", base_url)
            .set("llm.model", "test-model")
            .set("llm.requests_per_minute", 6000)
            .set("llm.backoff_seconds", 0.01)
    }

    /// Sets the value at a dotted key (`"synthetic.exhaustive"`), making its tables as needed.
    pub(crate) fn set(mut self, key: &str, value: impl Into<Value>) -> Self {
        set_dotted(&mut self.table, key, value.into());
        self
    }

    /// Merges TOML text into the config (its tables into these, its values over these): the escape
    /// hatch for what has no method.
    pub(crate) fn toml(mut self, text: &str) -> Self {
        let extra: Table = text
            .parse()
            .unwrap_or_else(|e| panic!("bad TOML in a test config: {e}\n{text}"));
        merge(&mut self.table, extra);
        self
    }

    /// The config's TOML text.
    pub(crate) fn render(&self) -> String {
        toml::to_string(&self.table).unwrap()
    }

    /// Writes the config to `path` (for tests whose folder is not a [`Project`]); returns `path`.
    pub(crate) fn write(&self, path: impl AsRef<Path>) -> PathBuf {
        let path = path.as_ref();
        std::fs::write(path, self.render()).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        path.to_path_buf()
    }
}

/// One `[[sources]]` entry.
#[derive(Clone, Debug)]
#[must_use]
pub(crate) struct Source {
    table: Table,
}

impl Source {
    /// A source of this name reading `captures` with the bundled `profile`.
    pub(crate) fn new(name: &str, profile: &str, captures: &[&str]) -> Source {
        Source {
            table: Table::new(),
        }
        .set("name", name)
        .set("captures", captures.to_vec())
        .set("profile", profile)
    }

    /// Bandai Namco dataset-1 captures in `captures/` labelled from their file names: the
    /// content is the action and the text.
    pub(crate) fn bandai1(name: &str) -> Source {
        Source::new(name, "bandai-namco", &["captures/*.bvh"]).filename_labels(
            "dataset-1_{content}_{style}_{take}",
            "{content}",
            "{content}",
        )
    }

    /// `licence`, the terms the source's captures are under.
    pub(crate) fn licence(self, licence: &str) -> Self {
        self.set("licence", licence)
    }

    /// `[sources.labels]` of kind `frame_index`: cuts and texts from the index CSV at `path`,
    /// whose frames are counted at `fps`.
    pub(crate) fn frame_index_labels(self, path: &str, fps: i64) -> Self {
        self.set("labels.kind", "frame_index")
            .set("labels.path", path)
            .set("labels.fps", fps)
    }

    /// `[sources.labels]` of kind `babel`: BABEL records at `path`.
    pub(crate) fn babel_labels(self, path: &str) -> Self {
        self.set("labels.kind", "babel").set("labels.path", path)
    }

    /// `[sources.labels]` of kind `event_log`: instruction logs at `path`.
    pub(crate) fn event_log_labels(self, path: &str) -> Self {
        self.set("labels.kind", "event_log")
            .set("labels.path", path)
    }

    /// `[sources.amass]` with the body models in `body_model`.
    pub(crate) fn amass(self, body_model: &str) -> Self {
        self.set("amass.body_model", body_model)
    }

    /// `[sources.labels]` of kind `filename`.
    pub(crate) fn filename_labels(self, pattern: &str, action: &str, text: &str) -> Self {
        self.set("labels.kind", "filename")
            .set("labels.pattern", pattern)
            .set("labels.action", action)
            .set("labels.text", text)
    }

    /// Sets the value at a dotted key of the source (`"labels.sidecar"`).
    pub(crate) fn set(mut self, key: &str, value: impl Into<Value>) -> Self {
        set_dotted(&mut self.table, key, value.into());
        self
    }
}

fn set_dotted(table: &mut Table, key: &str, value: Value) {
    let (parents, last) = match key.rsplit_once('.') {
        Some((parents, last)) => (Some(parents), last),
        None => (None, key),
    };
    let mut at = table;
    for part in parents.into_iter().flat_map(|p| p.split('.')) {
        at = match at.entry(part).or_insert_with(|| Value::Table(Table::new())) {
            Value::Table(t) => t,
            other => panic!("`{part}` of `{key}` is not a table: {other}"),
        };
    }
    at.insert(last.to_string(), value);
}

fn merge(into: &mut Table, from: Table) {
    for (key, value) in from {
        match (into.get_mut(&key), value) {
            (Some(Value::Table(a)), Value::Table(b)) => merge(a, b),
            (_, value) => {
                into.insert(key, value);
            }
        }
    }
}
