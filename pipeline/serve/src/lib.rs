//! `motionforge serve`: an HTTP service that builds datasets on request and on cron schedules,
//! one build at a time per dataset, with its run history in SQLite.
//!
//! The routes are in [`api`], the history in [`history`], schedules and the clock in
//! [`schedule`]. Each build runs in a process of its own ([`worker`]), so no build can take the
//! service down. `docs/service.md` explains running it and `docs/openapi.json` describes the API.
//!
//! Step 8 of a clip's way: the service runs the runner on demand or on a schedule, and its
//! browser plays the clip beside its mirror from the shards.

pub mod api;
mod browse;
mod child;
mod columns;
pub mod history;
pub mod log;
mod public;
mod queue;
mod report;
pub mod schedule;
mod snapshot;
mod wire;
pub mod worker;

use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use chrono::{DateTime, SecondsFormat, Utc};
use croner::Cron;
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;

use history::{BuildId, BuildState, History, HistoryError, Left, Trigger};
use log::BuildLog;
use motionforge_runner::config::{Config, ConfigError};
use public::PathShield;
use schedule::{Clock, SystemClock, Timetable};

/// Default address: loopback only, so nothing outside the machine reaches it unless asked.
pub const DEFAULT_BIND: &str = "127.0.0.1:7878";
/// Default environment variable holding the bearer token.
pub const DEFAULT_TOKEN_ENV: &str = "MOTIONFORGE_TOKEN";
/// Default state folder (run history), relative to the working folder.
pub const DEFAULT_STATE_DIR: &str = ".motionforge-serve";
/// Folder inside the state folder where build jobs and reports pass between the service and its
/// build processes.
pub const JOBS_DIR: &str = "jobs";

/// Errors that keep the service from starting or stopping cleanly.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// A config does not load, or its schedule is not a cron expression.
    #[error("{0}")]
    Config(#[source] ConfigError),
    /// No config was given.
    #[error("no dataset to serve: give at least one --config")]
    NoDataset,
    /// Two configs name the same dataset.
    #[error("configs {first} and {second} both build dataset `{name}`; dataset names must differ")]
    DuplicateDataset {
        /// The dataset name.
        name: String,
        /// The first config.
        first: PathBuf,
        /// The second config.
        second: PathBuf,
    },
    /// The token variable is unset or empty.
    #[error(
        "environment variable {var} is not set or is empty: the service needs a bearer token for calls that change state (set {var}, or name another variable with --token-env)"
    )]
    NoToken {
        /// The variable's name.
        var: String,
    },
    /// The run history failed.
    #[error(transparent)]
    History(#[from] HistoryError),
    /// The address cannot be bound or served.
    #[error("cannot serve on {addr}: {source}")]
    Bind {
        /// The address.
        addr: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The async runtime cannot start.
    #[error("cannot start the async runtime: {0}")]
    Runtime(#[source] std::io::Error),
    /// The executable that runs builds is missing.
    #[error(
        "cannot run builds with {path}: it is not a file (it should be the motionforge binary)"
    )]
    NoBuilder {
        /// The path given.
        path: PathBuf,
    },
    /// The folder for build jobs cannot be prepared.
    #[error("cannot prepare the build job folder {path}: {source}")]
    Jobs {
        /// The folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// The bearer token that state-changing calls must present. Only its digest is kept, and
/// presented tokens are compared in constant time (digests first, so length leaks nothing).
#[derive(Clone)]
pub struct Token {
    digest: Vec<u8>,
}

impl Token {
    /// A token from its secret text; `None` when it is empty.
    pub fn new(secret: &str) -> Option<Token> {
        let secret = secret.trim();
        (!secret.is_empty()).then(|| Token {
            digest: Sha256::digest(secret.as_bytes()).to_vec(),
        })
    }

    /// The token in environment variable `var`.
    pub fn from_env(var: &str) -> Result<Token, ServeError> {
        std::env::var(var)
            .ok()
            .and_then(|s| Token::new(&s))
            .ok_or_else(|| ServeError::NoToken {
                var: var.to_string(),
            })
    }

    /// True when `presented` is the token.
    pub fn accepts(&self, presented: &str) -> bool {
        let digest = Sha256::digest(presented.trim().as_bytes());
        digest.as_slice().ct_eq(&self.digest).into()
    }
}

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(..)")
    }
}

/// What a service serves and where it keeps its history.
pub struct ServiceSetup {
    /// One loaded config per dataset.
    pub datasets: Vec<Config>,
    /// Folder of the run history database.
    pub state_dir: PathBuf,
    /// Token for state-changing calls.
    pub token: Token,
    /// The clock that schedules and timestamps follow.
    pub clock: Arc<dyn Clock>,
    /// The executable each build runs in, as `<builder> serve-build --job <file>`: the
    /// motionforge binary (`std::env::current_exe()` in the binary itself).
    pub builder: PathBuf,
}

/// A served dataset.
#[derive(Debug)]
pub(crate) struct Dataset {
    config: Config,
    schedule: Option<(String, Cron)>,
}

/// What the routes, workers and scheduler share.
pub(crate) struct Shared {
    datasets: BTreeMap<String, Dataset>,
    history: History,
    token: Token,
    clock: Arc<dyn Clock>,
    /// Builds running now, with their live progress.
    live: Mutex<HashMap<BuildId, Arc<BuildLog>>>,
    queues: BTreeMap<String, mpsc::UnboundedSender<BuildId>>,
    shutdown: watch::Receiver<bool>,
    /// The executable builds run in.
    builder: PathBuf,
    /// Where build jobs and reports are written.
    jobs_dir: PathBuf,
    /// How paths are shown to callers.
    shield: PathShield,
    /// What the browser reads of each dataset.
    readers: snapshot::Readers,
}

impl Shared {
    /// The served dataset names, quoted, for messages.
    fn served_names(&self) -> String {
        self.datasets
            .keys()
            .map(|n| format!("`{n}`"))
            .collect::<Vec<_>>()
            .join(", ")
    }

    fn now_ms(&self) -> i64 {
        self.clock.now().timestamp_millis()
    }

    fn live(&self, id: BuildId) -> Option<Arc<BuildLog>> {
        self.live
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&id)
            .cloned()
    }

    fn set_live(&self, id: BuildId, log: Option<Arc<BuildLog>>) {
        let mut live = self.live.lock().unwrap_or_else(|e| e.into_inner());
        match log {
            Some(log) => live.insert(id, log),
            None => live.remove(&id),
        };
    }

    /// Records a queued build and hands it to its dataset's queue.
    fn request_build(
        &self,
        dataset: &str,
        trigger: Trigger,
        force: bool,
        offline: bool,
    ) -> Result<BuildId, HistoryError> {
        let id = self
            .history
            .enqueue(dataset, trigger, force, offline, None, self.now_ms())?;
        self.hand_to_queue(dataset, id);
        Ok(id)
    }

    fn hand_to_queue(&self, dataset: &str, id: BuildId) {
        // A closed queue means the service is stopping: the row stays queued for the next start.
        let sent = self.queues.get(dataset).is_some_and(|q| q.send(id).is_ok());
        if !sent {
            say(&format!(
                "build {id} of `{dataset}` stays queued until the next start"
            ));
        }
    }

    /// The scheduler's request: skipped when one is already waiting, since that one will see the
    /// same inputs.
    fn schedule_build(&self, dataset: &str) {
        let waiting = self.history.list(&history::ListFilter {
            dataset: Some(dataset.to_string()),
            state: Some(history::BuildState::Queued),
            limit: 1,
        });
        match waiting {
            Ok(w) if !w.is_empty() => say(&format!(
                "schedule: `{dataset}` already has build {} queued; not adding another",
                w[0].id
            )),
            Ok(_) => match self.request_build(dataset, Trigger::Schedule, false, false) {
                Ok(id) => say(&format!("schedule: queued build {id} of `{dataset}`")),
                Err(e) => say(&format!("schedule: cannot queue `{dataset}`: {e}")),
            },
            Err(e) => say(&format!("schedule: cannot queue `{dataset}`: {e}")),
        }
    }
}

/// A line of the service's own log (standard error, which systemd's journal keeps). A closed
/// standard error loses the line; it does not panic the task that logs it, as `eprintln!` would.
fn say(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "motionforge serve: {line}");
}

/// Unix milliseconds as RFC 3339 UTC (`2026-05-01T03:00:00.000Z`).
pub fn rfc3339(ms: i64) -> Option<String> {
    DateTime::<Utc>::from_timestamp_millis(ms)
        .map(|t| t.to_rfc3339_opts(SecondsFormat::Millis, true))
}

/// Checks configs for a service: names differ, schedules parse.
fn datasets(configs: Vec<Config>) -> Result<BTreeMap<String, Dataset>, ServeError> {
    if configs.is_empty() {
        return Err(ServeError::NoDataset);
    }
    let mut out: BTreeMap<String, Dataset> = BTreeMap::new();
    for config in configs {
        // A loaded config keeps its folder, not its file name; `load_configs` names the file.
        let config_path = config.base_dir.clone();
        let schedule = match &config.dataset.schedule {
            Some(text) => {
                let cron = schedule::parse_schedule(text).map_err(|why| {
                    ServeError::Config(schedule_problem(&config_path, text, &why))
                })?;
                Some((text.clone(), cron))
            }
            None => None,
        };
        let name = config.dataset.name.clone();
        if let Some(first) = out.get(&name) {
            return Err(ServeError::DuplicateDataset {
                name,
                first: first.config.base_dir.clone(),
                second: config_path,
            });
        }
        out.insert(name, Dataset { config, schedule });
    }
    Ok(out)
}

/// The config error for an unusable `dataset.schedule`.
fn schedule_problem(path: &std::path::Path, text: &str, why: &str) -> ConfigError {
    ConfigError::Invalid {
        path: path.to_path_buf(),
        problems: vec![motionforge_runner::config::Problem {
            key: "dataset.schedule".into(),
            value: format!("{text:?}"),
            expected: format!("{} ({why})", schedule::SCHEDULE_FORM),
            line: None,
        }],
    }
}

/// Creates the job folder, emptied of what an earlier run left.
fn clear_jobs(dir: &std::path::Path) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.is_file() {
            std::fs::remove_file(&path)?;
        }
    }
    Ok(())
}

/// Loads config files for a service. A schedule error names the file.
pub fn load_configs(paths: &[PathBuf]) -> Result<Vec<Config>, ServeError> {
    let mut configs = Vec::new();
    let mut seen: BTreeMap<String, PathBuf> = BTreeMap::new();
    for path in paths {
        let config = Config::load(path).map_err(ServeError::Config)?;
        if let Some(first) = seen.insert(config.dataset.name.clone(), path.clone()) {
            return Err(ServeError::DuplicateDataset {
                name: config.dataset.name.clone(),
                first,
                second: path.clone(),
            });
        }
        if let Some(text) = &config.dataset.schedule
            && let Err(why) = schedule::parse_schedule(text)
        {
            return Err(ServeError::Config(schedule_problem(path, text, &why)));
        }
        configs.push(config);
    }
    Ok(configs)
}

/// A running service.
pub struct Service {
    addr: SocketAddr,
    shared: Arc<Shared>,
    stop: watch::Sender<bool>,
    server: JoinHandle<std::io::Result<()>>,
    tasks: Vec<JoinHandle<()>>,
}

impl Service {
    /// Recovers the history (running builds become interrupted and are queued again, queued ones
    /// are queued again), then serves on `listener` and runs the queues and schedules.
    pub async fn start(
        setup: ServiceSetup,
        listener: tokio::net::TcpListener,
    ) -> Result<Service, ServeError> {
        let datasets = datasets(setup.datasets)?;
        let addr = listener.local_addr().map_err(|source| ServeError::Bind {
            addr: "listener".into(),
            source,
        })?;
        if !setup.builder.is_file() {
            return Err(ServeError::NoBuilder {
                path: setup.builder,
            });
        }
        let history = History::open(&setup.state_dir)?;
        // The history's lock is held: no other service uses these jobs, so any left are stale.
        let jobs_dir = setup.state_dir.join(JOBS_DIR);
        clear_jobs(&jobs_dir).map_err(|source| ServeError::Jobs {
            path: jobs_dir.clone(),
            source,
        })?;
        let now = setup.clock.now().timestamp_millis();
        let ended = history.interrupt_running(
            "the service stopped while this build ran",
            Left::Died,
            now,
        )?;
        for (id, state) in &ended {
            say(&match state {
                BuildState::Failed => format!(
                    "build {id} was running when the service died, and it resumed an earlier interrupted build: failed, not resumed again"
                ),
                _ => format!("build {id} was running when the service stopped: interrupted"),
            });
        }
        let names: Vec<&str> = datasets.keys().map(String::as_str).collect();
        for id in history.resume_interrupted(&names, now)? {
            say(&format!("build {id} queued to resume an interrupted build"));
        }

        let (stop, shutdown) = watch::channel(false);
        let mut receivers = Vec::new();
        let mut queues = BTreeMap::new();
        for name in datasets.keys() {
            let (tx, rx) = mpsc::unbounded_channel();
            queues.insert(name.clone(), tx);
            receivers.push((name.clone(), rx));
        }
        let timetable = Timetable::new(
            datasets
                .iter()
                .filter_map(|(n, d)| d.schedule.as_ref().map(|(_, c)| (n.clone(), c.clone())))
                .collect(),
            setup.clock.now(),
        );
        let readers = snapshot::Readers::new(datasets.keys()).map_err(ServeError::Runtime)?;
        let shared = Arc::new(Shared {
            datasets,
            history,
            token: setup.token,
            clock: setup.clock,
            live: Mutex::new(HashMap::new()),
            queues,
            shutdown: shutdown.clone(),
            builder: setup.builder,
            jobs_dir,
            shield: PathShield::new(std::env::current_dir().ok()),
            readers,
        });
        for build in shared.history.queued()? {
            if shared.datasets.contains_key(&build.dataset) {
                shared.hand_to_queue(&build.dataset, build.id);
            } else {
                say(&format!(
                    "build {} of `{}` stays queued: this service does not serve that dataset",
                    build.id, build.dataset
                ));
            }
        }

        let mut tasks = Vec::new();
        for (name, rx) in receivers {
            tasks.push(tokio::spawn(queue::work(shared.clone(), name, rx)));
        }
        if !timetable.is_empty() {
            let for_schedule = shared.clone();
            tasks.push(tokio::spawn(schedule::run_timetable(
                timetable,
                shared.clock.clone(),
                move |dataset| for_schedule.schedule_build(dataset),
                shutdown.clone(),
            )));
        }
        let router = api::router(shared.clone());
        let mut server_stop = shutdown;
        let server = tokio::spawn(async move {
            axum::serve(
                wire::JsonErrors::new(listener),
                router.into_make_service_with_connect_info::<wire::ConnectionWrites>(),
            )
            .with_graceful_shutdown(async move {
                let _ = server_stop.wait_for(|s| *s).await;
            })
            .await
        });
        say(&format!(
            "serving {} on http://{addr}",
            shared.served_names()
        ));
        Ok(Service {
            addr,
            shared,
            stop,
            server,
            tasks,
        })
    }

    /// The address it serves on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops serving: finishes open requests, stops the queues and schedules, kills the build
    /// processes still running and marks their builds interrupted (the next start resumes them).
    /// A build's outputs are written atomically, so killing it is as safe as a crash.
    pub async fn stop(self) -> Result<(), ServeError> {
        let _ = self.stop.send(true);
        let served = self.server.await;
        for task in self.tasks {
            let _ = task.await;
        }
        let now = self.shared.now_ms();
        for (id, _) in self.shared.history.interrupt_running(
            "the service stopped during this build; it resumes on the next start",
            Left::Stopped,
            now,
        )? {
            say(&format!("build {id} interrupted by the shutdown"));
        }
        match served {
            Ok(Ok(())) => Ok(()),
            Ok(Err(source)) => Err(ServeError::Bind {
                addr: self.addr.to_string(),
                source,
            }),
            // The server task only ends by returning; a panic inside it is a bug worth showing.
            Err(e) => Err(ServeError::Bind {
                addr: self.addr.to_string(),
                source: std::io::Error::other(e.to_string()),
            }),
        }
    }
}

/// What `motionforge serve` was asked.
#[derive(Debug, Clone)]
pub struct ServeCommand {
    /// Config files, one per dataset.
    pub configs: Vec<PathBuf>,
    /// Address to listen on.
    pub bind: String,
    /// Folder of the run history.
    pub state_dir: PathBuf,
    /// Environment variable holding the token.
    pub token_env: String,
    /// The executable builds run in (see [`ServiceSetup::builder`]).
    pub builder: PathBuf,
}

/// Runs the service until Ctrl-C or SIGTERM, then stops it cleanly.
pub fn run(command: &ServeCommand) -> Result<(), ServeError> {
    let token = Token::from_env(&command.token_env)?;
    let configs = load_configs(&command.configs)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(ServeError::Runtime)?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind(&command.bind)
            .await
            .map_err(|source| ServeError::Bind {
                addr: command.bind.clone(),
                source,
            })?;
        let service = Service::start(
            ServiceSetup {
                datasets: configs,
                state_dir: command.state_dir.clone(),
                token,
                clock: Arc::new(SystemClock),
                builder: command.builder.clone(),
            },
            listener,
        )
        .await?;
        stop_signal().await;
        say("stopping");
        service.stop().await
    })?;
    // Build processes were killed when their builds were dropped, as the history already says.
    runtime.shutdown_background();
    Ok(())
}

/// Ctrl-C, or SIGTERM (what systemd sends) on Unix.
async fn stop_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        if let Ok(mut term) = signal(SignalKind::terminate()) {
            tokio::select! {
                _ = tokio::signal::ctrl_c() => {}
                _ = term.recv() => {}
            }
            return;
        }
    }
    let _ = tokio::signal::ctrl_c().await;
}
