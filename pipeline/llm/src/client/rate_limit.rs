//! The request-rate limit: request starts spaced evenly over each minute.

use std::sync::Mutex;
use std::time::Duration;

use tokio::time::Instant;

/// Spaces request starts at least 60 s / `requests_per_minute` apart, so no 60-second window
/// holds more than `requests_per_minute` starts. Each caller reserves the next free start time
/// under a lock and sleeps until it. No bursts: servers that enforce per-minute limits often
/// enforce them over shorter periods too.
pub(super) struct RateLimiter {
    interval: Duration,
    next_free: Mutex<Option<Instant>>,
}

impl RateLimiter {
    pub(super) fn new(requests_per_minute: u32) -> RateLimiter {
        RateLimiter {
            interval: Duration::from_secs(60) / requests_per_minute.max(1),
            next_free: Mutex::new(None),
        }
    }

    pub(super) async fn wait(&self) {
        let start = {
            // A poisoned lock only means another task panicked between two plain assignments.
            let mut next = self.next_free.lock().unwrap_or_else(|e| e.into_inner());
            let now = Instant::now();
            let start = next.filter(|&t| t > now).unwrap_or(now);
            *next = Some(start + self.interval);
            start
        };
        tokio::time::sleep_until(start).await;
    }
}
