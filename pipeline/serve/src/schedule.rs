//! Cron schedules: when each dataset is due, over a [`Clock`] that tests can move by hand.
//!
//! Schedules are five-field cron expressions (`minute hour day-of-month month day-of-week`, or
//! `@daily`-style nicknames) evaluated in UTC. A schedule fires at its times while the service
//! runs; times passed while it was down, or while the loop was late, fire once, not once each.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use chrono::{DateTime, Utc};
use croner::Cron;
use croner::parser::{CronParser, Seconds, Year};
use tokio::sync::watch;

/// What a schedule must look like, for error messages.
pub const SCHEDULE_FORM: &str = "a cron expression of five fields, `minute hour day-of-month month day-of-week` in UTC (e.g. \"0 3 * * *\" for 03:00 every day), or @hourly, @daily, @weekly, @monthly";

/// Longest single sleep of the real clock: a wall clock that jumps (suspend, NTP) is noticed
/// within this.
const MAX_SLEEP: Duration = Duration::from_secs(60);

/// A future the clock resolves when a time has come.
pub type Sleep = Pin<Box<dyn Future<Output = ()> + Send>>;

/// The time as the service sees it.
pub trait Clock: Send + Sync {
    /// The current time.
    fn now(&self) -> DateTime<Utc>;
    /// Resolves at `deadline` or earlier (callers look at [`Clock::now`] again on waking).
    fn sleep_until(&self, deadline: DateTime<Utc>) -> Sleep;
}

/// The system's wall clock and tokio timers.
#[derive(Debug, Clone, Copy, Default)]
pub struct SystemClock;

impl Clock for SystemClock {
    fn now(&self) -> DateTime<Utc> {
        Utc::now()
    }

    fn sleep_until(&self, deadline: DateTime<Utc>) -> Sleep {
        let wait = (deadline - Utc::now()).to_std().unwrap_or(Duration::ZERO);
        Box::pin(tokio::time::sleep(wait.min(MAX_SLEEP)))
    }
}

/// A clock that moves only when told: for tests and simulations.
#[derive(Debug)]
pub struct ManualClock {
    now: watch::Sender<DateTime<Utc>>,
}

impl ManualClock {
    /// A clock standing at `start`.
    pub fn new(start: DateTime<Utc>) -> ManualClock {
        ManualClock {
            now: watch::Sender::new(start),
        }
    }

    /// Moves the clock forward by `by`, waking sleepers whose time has come.
    pub fn advance(&self, by: Duration) {
        let by = chrono::Duration::from_std(by).unwrap_or(chrono::Duration::MAX);
        self.now
            .send_modify(|t| *t = t.checked_add_signed(by).unwrap_or(*t));
    }

    /// Sets the clock to `t`.
    pub fn set(&self, t: DateTime<Utc>) {
        self.now.send_replace(t);
    }
}

impl Clock for ManualClock {
    fn now(&self) -> DateTime<Utc> {
        *self.now.borrow()
    }

    fn sleep_until(&self, deadline: DateTime<Utc>) -> Sleep {
        let mut rx = self.now.subscribe();
        Box::pin(async move {
            // An error means the clock is gone: nothing will ever be due, so sleep forever.
            if rx.wait_for(|now| *now >= deadline).await.is_err() {
                std::future::pending::<()>().await;
            }
        })
    }
}

/// Parses a schedule; the error says what is wrong with it.
pub fn parse_schedule(text: &str) -> Result<Cron, String> {
    let cron = CronParser::builder()
        .seconds(Seconds::Disallowed)
        .year(Year::Disallowed)
        .build()
        .parse(text)
        .map_err(|e| e.to_string())?;
    // Without a year field a pattern that matches once matches within any eight years (29
    // February), so one search from a fixed date tells whether it ever comes.
    let reference = DateTime::<Utc>::from_timestamp(946_684_800, 0).unwrap_or_default();
    if next_after(&cron, reference).is_none() {
        return Err("it names no date that exists".into());
    }
    Ok(cron)
}

/// The first time after `after` (exclusive) that `cron` names, if any.
pub fn next_after(cron: &Cron, after: DateTime<Utc>) -> Option<DateTime<Utc>> {
    cron.find_next_occurrence(&after, false).ok()
}

/// One dataset's schedule and its next time.
#[derive(Debug, Clone)]
struct Entry {
    dataset: String,
    cron: Cron,
    next: Option<DateTime<Utc>>,
}

/// Every dataset's schedule: which are due at a time, and when the next one is.
#[derive(Debug, Clone, Default)]
pub struct Timetable {
    entries: Vec<Entry>,
}

impl Timetable {
    /// Schedules `(dataset, cron)` whose first times are after `now`.
    pub fn new(schedules: Vec<(String, Cron)>, now: DateTime<Utc>) -> Timetable {
        Timetable {
            entries: schedules
                .into_iter()
                .map(|(dataset, cron)| {
                    let next = next_after(&cron, now);
                    Entry {
                        dataset,
                        cron,
                        next,
                    }
                })
                .collect(),
        }
    }

    /// Datasets whose time has come at `now`, each once however many of its times passed;
    /// their next times move past `now`.
    pub fn due(&mut self, now: DateTime<Utc>) -> Vec<String> {
        let mut due = Vec::new();
        for e in &mut self.entries {
            if e.next.is_some_and(|t| t <= now) {
                due.push(e.dataset.clone());
                e.next = next_after(&e.cron, now);
            }
        }
        due
    }

    /// The earliest next time of any schedule.
    pub fn next_wake(&self) -> Option<DateTime<Utc>> {
        self.entries.iter().filter_map(|e| e.next).min()
    }

    /// The next time of `dataset`'s schedule.
    pub fn next_of(&self, dataset: &str) -> Option<DateTime<Utc>> {
        self.entries
            .iter()
            .find(|e| e.dataset == dataset)
            .and_then(|e| e.next)
    }

    /// True when no dataset has a schedule.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

/// Runs the timetable until `shutdown` turns true: sleeps until the next time on `clock`, then
/// calls `on_due` for each due dataset.
pub async fn run_timetable(
    mut timetable: Timetable,
    clock: Arc<dyn Clock>,
    mut on_due: impl FnMut(&str) + Send,
    mut shutdown: watch::Receiver<bool>,
) {
    loop {
        if *shutdown.borrow() {
            return;
        }
        for dataset in timetable.due(clock.now()) {
            on_due(&dataset);
        }
        let sleep = match timetable.next_wake() {
            Some(t) => clock.sleep_until(t),
            None => Box::pin(std::future::pending()),
        };
        tokio::select! {
            () = sleep => {}
            changed = shutdown.changed() => {
                if changed.is_err() {
                    return;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(text: &str) -> DateTime<Utc> {
        DateTime::parse_from_rfc3339(text).unwrap().to_utc()
    }

    #[test]
    fn parse_accepts_five_fields_and_nicknames_only() {
        assert!(parse_schedule("0 3 * * *").is_ok());
        assert!(parse_schedule("@daily").is_ok());
        assert!(parse_schedule("*/15 * * * MON-FRI").is_ok());
        assert!(
            parse_schedule("0 0 3 * * *").is_err(),
            "seconds are not allowed"
        );
        assert!(parse_schedule("every night").is_err());
        assert!(parse_schedule("61 3 * * *").is_err());
        assert!(parse_schedule("").is_err());
        assert!(
            parse_schedule("0 0 31 2 *").is_err(),
            "31 February never comes"
        );
        assert!(parse_schedule("0 0 29 2 *").is_ok());
    }

    #[test]
    fn next_after_is_exclusive_and_in_utc() {
        let cron = parse_schedule("0 3 * * *").unwrap();
        assert_eq!(
            next_after(&cron, at("2026-05-01T02:59:59Z")),
            Some(at("2026-05-01T03:00:00Z"))
        );
        assert_eq!(
            next_after(&cron, at("2026-05-01T03:00:00Z")),
            Some(at("2026-05-02T03:00:00Z"))
        );
    }

    #[tokio::test]
    async fn manual_sleep_wakes_only_when_the_clock_reaches_the_deadline() {
        let clock = ManualClock::new(at("2026-05-01T00:00:00Z"));
        let mut sleep = clock.sleep_until(at("2026-05-01T00:10:00Z"));
        assert!(futures_poll_once(&mut sleep).await.is_none());
        clock.advance(Duration::from_secs(9 * 60));
        assert!(futures_poll_once(&mut sleep).await.is_none());
        clock.advance(Duration::from_secs(60));
        assert!(futures_poll_once(&mut sleep).await.is_some());
    }

    /// Polls a future once without waiting.
    async fn futures_poll_once(f: &mut Sleep) -> Option<()> {
        std::future::poll_fn(|cx| std::task::Poll::Ready(f.as_mut().poll(cx).is_ready()))
            .await
            .then_some(())
    }
}
