//! Starting `motionforge serve` in-process on a free loopback port, and reading its JSON.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use motionforge::config::Config;
use motionforge::serve::schedule::SystemClock;
use motionforge::serve::{Service, ServiceSetup, Token};
use serde_json::Value;

/// A service over `configs` with state in `state`, builds run by `builder`, accepting `token`;
/// and its base URL.
pub async fn start_service(
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
pub async fn get(client: &reqwest::Client, url: &str) -> (u16, Value) {
    let response = client.get(url).send().await.unwrap();
    let status = response.status().as_u16();
    (status, response.json().await.unwrap())
}
