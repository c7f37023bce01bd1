//! Starting `motionforge serve` in-process on a free loopback port, and reading its JSON.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use motionforge::config::Config;
use motionforge::serve::schedule::SystemClock;
use motionforge::serve::{Service, ServiceSetup, Token};
use serde_json::Value;

/// A service over `configs` with state in `state`, builds run by `builder`, accepting `token`;
/// and its base URL.
pub(crate) async fn start_service(
    state: &Path,
    configs: Vec<Config>,
    builder: PathBuf,
    token: &str,
) -> (Service, String) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let service = Service::start(
        ServiceSetup {
            datasets: configs,
            state_dir: state.to_path_buf(),
            token: Token::new(token).unwrap(),
            clock: Arc::new(SystemClock),
            builder,
        },
        listener,
    )
    .await
    .unwrap();
    let base = format!("http://{}", service.local_addr());
    (service, base)
}

/// Status and JSON body of `GET url`.
pub(crate) async fn get(client: &reqwest::Client, url: &str) -> (u16, Value) {
    let response = client.get(url).send().await.unwrap();
    let status = response.status().as_u16();
    (status, response.json().await.unwrap())
}

/// Writes a copy of the demo config into `dir` that builds into `output` (its sources still the
/// repository's fixtures), for commands such as `serve` that take no `--output`; returns its path.
pub(crate) fn demo_config_file(dir: &Path, output: &Path) -> PathBuf {
    super::project::ConfigSpec::demo()
        .output(output)
        .write(dir.join("demo.toml"))
}

/// A `motionforge serve` process on a free loopback port; killed (SIGKILL) when dropped.
pub(crate) struct ServeProcess {
    /// The process.
    pub child: std::process::Child,
    /// Its base URL.
    pub base: String,
    /// Its standard error so far, line by line (read on a thread of its own).
    pub log: Arc<std::sync::Mutex<Vec<String>>>,
}

impl ServeProcess {
    /// Starts `motionforge serve --config <config> --state <state>` with `token`, and waits until
    /// it says where it serves.
    pub(crate) fn start(config: &Path, state: &Path, token: &str) -> ServeProcess {
        ServeProcess::start_limited(config, state, token, None)
    }

    /// [`ServeProcess::start`], under an address-space limit of `mib` MiB (`prlimit --as`) when
    /// given, so that a memory regression fails instead of taking the machine's memory. The
    /// build processes it starts inherit the limit.
    pub(crate) fn start_limited(
        config: &Path,
        state: &Path,
        token: &str,
        mib: Option<u64>,
    ) -> ServeProcess {
        use std::io::BufRead;
        let mut command = match mib {
            Some(mib) => {
                let mut c = std::process::Command::new("prlimit");
                c.arg(format!("--as={}", mib << 20))
                    .arg(env!("CARGO_BIN_EXE_motionforge"));
                c
            }
            None => std::process::Command::new(env!("CARGO_BIN_EXE_motionforge")),
        };
        let mut child = command
            .args(["serve", "--bind", "127.0.0.1:0", "--config"])
            .arg(config)
            .arg("--state")
            .arg(state)
            .env("MOTIONFORGE_TOKEN", token)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let stderr = child.stderr.take().unwrap();
        let log = Arc::new(std::sync::Mutex::new(Vec::new()));
        let (tx, rx) = std::sync::mpsc::channel();
        let lines = log.clone();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                if let Some(addr) = line.split("on http://").nth(1) {
                    let _ = tx.send(addr.trim().to_string());
                }
                lines.lock().unwrap().push(line);
            }
        });
        let addr = rx
            .recv_timeout(std::time::Duration::from_secs(60))
            .unwrap_or_else(|_| panic!("serve never said where it serves: {:?}", log.lock()));
        ServeProcess {
            child,
            base: format!("http://{addr}"),
            log,
        }
    }

    /// Its process id (`prlimit` runs it in its own process).
    pub(crate) fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Its peak resident memory so far (`VmHWM`), in KiB.
    pub(crate) fn peak_rss_kib(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.pid())).unwrap();
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .expect("VmHWM in /proc/<pid>/status")
    }

    /// Stops it with SIGTERM, as systemd does, and waits for it.
    pub(crate) fn stop(mut self) {
        let _ = std::process::Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        let _ = self.child.wait();
    }
}

impl Drop for ServeProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}
