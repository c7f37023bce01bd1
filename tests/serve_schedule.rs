//! Cron schedules of `motionforge serve`, on a manual clock: which datasets come due and when,
//! the loop that queues them, config errors, and a scheduled rebuild of the demo with nothing
//! changed (a no-op), all without waiting for real time to pass.
use crate::common;

use std::sync::Arc;
use std::time::{Duration, Instant};

use chrono::{DateTime, Utc};
use motionforge::config::Config;
use motionforge::serve::schedule::{Clock, ManualClock, Timetable, parse_schedule, run_timetable};
use motionforge::serve::{Service, ServiceSetup, Token, load_configs};
use serde_json::Value;
use tokio::sync::{mpsc, watch};

use common::project::ConfigSpec;
use common::repo;

fn at(text: &str) -> DateTime<Utc> {
    DateTime::parse_from_rfc3339(text).unwrap().to_utc()
}

fn timetable(schedules: &[(&str, &str)], now: DateTime<Utc>) -> Timetable {
    Timetable::new(
        schedules
            .iter()
            .map(|(d, s)| (d.to_string(), parse_schedule(s).unwrap()))
            .collect(),
        now,
    )
}

/// Steps `clock` a minute at a time for `minutes`, collecting (time, dataset) of each due build.
fn step(table: &mut Timetable, clock: &ManualClock, minutes: u32) -> Vec<(DateTime<Utc>, String)> {
    let mut fired = Vec::new();
    for _ in 0..minutes {
        clock.advance(Duration::from_secs(60));
        for dataset in table.due(clock.now()) {
            fired.push((clock.now(), dataset));
        }
    }
    fired
}

#[test]
fn a_daily_schedule_fires_once_a_day_at_its_time() {
    let clock = ManualClock::new(at("2026-05-01T00:00:00Z"));
    let mut table = timetable(&[("demo", "0 3 * * *")], clock.now());
    assert_eq!(table.next_wake(), Some(at("2026-05-01T03:00:00Z")));
    let fired = step(&mut table, &clock, 3 * 24 * 60);
    assert_eq!(
        fired,
        vec![
            (at("2026-05-01T03:00:00Z"), "demo".to_string()),
            (at("2026-05-02T03:00:00Z"), "demo".to_string()),
            (at("2026-05-03T03:00:00Z"), "demo".to_string()),
        ]
    );
}

#[test]
fn datasets_fire_on_their_own_schedules() {
    let clock = ManualClock::new(at("2026-05-01T10:00:00Z"));
    let mut table = timetable(
        &[("small", "*/10 * * * *"), ("large", "30 * * * *")],
        clock.now(),
    );
    let fired = step(&mut table, &clock, 60);
    let small: Vec<_> = fired.iter().filter(|(_, d)| d == "small").collect();
    let large: Vec<_> = fired.iter().filter(|(_, d)| d == "large").collect();
    assert_eq!(small.len(), 6, "{fired:?}");
    assert_eq!(
        large,
        vec![&(at("2026-05-01T10:30:00Z"), "large".to_string())]
    );
    assert_eq!(table.next_of("large"), Some(at("2026-05-01T11:30:00Z")));
}

#[test]
fn times_missed_while_late_fire_once_not_once_each() {
    let clock = ManualClock::new(at("2026-05-01T00:00:00Z"));
    let mut table = timetable(&[("demo", "*/15 * * * *")], clock.now());
    clock.advance(Duration::from_secs(5 * 3600 + 7 * 60));
    assert_eq!(table.due(clock.now()), vec!["demo".to_string()]);
    assert!(table.due(clock.now()).is_empty());
    assert_eq!(table.next_wake(), Some(at("2026-05-01T05:15:00Z")));
}

#[tokio::test]
async fn the_loop_queues_a_dataset_when_the_manual_clock_reaches_its_time() {
    let clock = Arc::new(ManualClock::new(at("2026-05-01T02:58:00Z")));
    let table = timetable(&[("demo", "0 3 * * *")], clock.now());
    let (due_tx, mut due_rx) = mpsc::unbounded_channel();
    let (stop_tx, stop_rx) = watch::channel(false);
    let task = tokio::spawn(run_timetable(
        table,
        clock.clone(),
        move |d| {
            let _ = due_tx.send(d.to_string());
        },
        stop_rx,
    ));
    let settle = || async {
        for _ in 0..20 {
            tokio::task::yield_now().await;
        }
    };
    settle().await;
    clock.advance(Duration::from_secs(119));
    settle().await;
    assert!(due_rx.try_recv().is_err(), "fired before 03:00");
    clock.advance(Duration::from_secs(1));
    let fired = tokio::time::timeout(Duration::from_secs(10), due_rx.recv())
        .await
        .expect("the loop wakes when the clock reaches 03:00");
    assert_eq!(fired.as_deref(), Some("demo"));
    settle().await;
    assert!(due_rx.try_recv().is_err(), "fired twice for one time");
    clock.set(at("2026-05-02T03:00:00Z"));
    let fired = tokio::time::timeout(Duration::from_secs(10), due_rx.recv())
        .await
        .expect("and again the next day");
    assert_eq!(fired.as_deref(), Some("demo"));
    stop_tx.send(true).unwrap();
    tokio::time::timeout(Duration::from_secs(10), task)
        .await
        .expect("the loop stops when told")
        .unwrap();
}

#[test]
fn a_bad_schedule_is_refused_naming_the_key_value_and_form() {
    let dir = tempfile::tempdir().unwrap();
    let path = ConfigSpec::demo()
        .schedule("every night")
        .write(dir.path().join("nightly.toml"));
    let err = load_configs(&[path]).unwrap_err().to_string();
    assert!(err.contains("nightly.toml"), "{err}");
    assert!(err.contains("dataset.schedule"), "{err}");
    assert!(err.contains("\"every night\""), "{err}");
    assert!(err.contains("five fields"), "{err}");

    let good = ConfigSpec::demo()
        .schedule("0 3 * * *")
        .write(dir.path().join("good.toml"));
    let configs = load_configs(std::slice::from_ref(&good)).unwrap();
    assert_eq!(configs[0].dataset.schedule.as_deref(), Some("0 3 * * *"));
    // When to build is not what to build: the config fingerprint must not see it.
    let mut without = configs[0].clone();
    without.dataset.schedule = None;
    assert_eq!(
        serde_json::to_string(&configs[0]).unwrap(),
        serde_json::to_string(&without).unwrap()
    );
    let twice = load_configs(&[good.clone(), good]).unwrap_err().to_string();
    assert!(twice.contains("both build dataset `demo`"), "{twice}");
}

async fn get(client: &reqwest::Client, url: &str) -> Value {
    client.get(url).send().await.unwrap().json().await.unwrap()
}

/// Polls (every 100 ms, up to ten minutes) until `pick` finds a final build in `GET /builds`.
async fn wait_for(client: &reqwest::Client, base: &str, pick: impl Fn(&Value) -> bool) -> Value {
    let start = Instant::now();
    loop {
        let builds = get(client, &format!("{base}/builds")).await;
        if let Some(b) = builds["builds"].as_array().unwrap().iter().find(|b| {
            pick(b)
                && ["succeeded", "failed", "interrupted"].contains(&b["state"].as_str().unwrap())
        }) {
            return get(client, &format!("{base}/builds/{}", b["id"])).await;
        }
        assert!(start.elapsed() < Duration::from_secs(600), "{builds}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scheduled_rebuild_with_nothing_changed_is_a_no_op() {
    let out = tempfile::tempdir().unwrap();
    let state = tempfile::tempdir().unwrap();
    let mut config = Config::load(&repo().join("fixtures/demo.toml")).unwrap();
    config.dataset.output = out.path().to_path_buf();
    config.dataset.schedule = Some("0 3 * * *".into());
    let clock = Arc::new(ManualClock::new(at("2026-05-01T02:59:00Z")));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let service = Service::start(
        ServiceSetup {
            datasets: vec![config],
            state_dir: state.path().to_path_buf(),
            token: Token::new("t").unwrap(),
            clock: clock.clone(),
            builder: env!("CARGO_BIN_EXE_motionforge").into(),
        },
        listener,
    )
    .await
    .unwrap();
    let base = format!("http://{}", service.local_addr());
    let client = reqwest::Client::new();

    let datasets = get(&client, &format!("{base}/datasets")).await;
    assert_eq!(datasets["datasets"][0]["schedule"], "0 3 * * *");
    assert_eq!(
        datasets["datasets"][0]["next_scheduled"],
        "2026-05-01T03:00:00Z"
    );

    // A first build, so the scheduled one finds everything done.
    let first: Value = client
        .post(format!("{base}/builds"))
        .bearer_auth("t")
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let first_id = first["id"].clone();
    let built = wait_for(&client, &base, |b| b["id"] == first_id).await;
    assert_eq!(built["state"], "succeeded", "{built}");

    clock.advance(Duration::from_secs(60));
    let scheduled = wait_for(&client, &base, |b| b["trigger"] == "schedule").await;
    assert_eq!(scheduled["state"], "succeeded", "{scheduled}");
    assert_eq!(scheduled["requested_at"], "2026-05-01T03:00:00.000Z");
    assert_eq!(scheduled["counts"]["nothing_ran"], true, "{scheduled}");
    assert_eq!(scheduled["counts"]["clips"], 24);
    println!(
        "scheduled rebuild with nothing changed: {} s (debug build)",
        scheduled["seconds"]
    );
    let builds = get(&client, &format!("{base}/builds")).await;
    assert_eq!(builds["builds"].as_array().unwrap().len(), 2, "{builds}");
    service.stop().await.unwrap();
}
