//! The circuit breaker: after `circuit_breaker_failures` connection failures in a row, over all
//! prompts, the client stops sending for the rest of its life.

use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// Counts connection failures in a row; any HTTP answer resets the count.
pub(super) struct CircuitBreaker {
    limit: u32,
    /// Connection failures in a row, over all prompts; any HTTP answer resets it.
    connect_failures: AtomicU32,
    /// Set when `connect_failures` reached `limit`: nothing more is sent.
    open: AtomicBool,
}

impl CircuitBreaker {
    pub(super) fn new(limit: u32) -> CircuitBreaker {
        CircuitBreaker {
            limit,
            connect_failures: AtomicU32::new(0),
            open: AtomicBool::new(false),
        }
    }

    /// Failures in a row that open the breaker.
    pub(super) fn limit(&self) -> u32 {
        self.limit
    }

    /// True once the breaker opened: nothing more may be sent.
    pub(super) fn is_open(&self) -> bool {
        self.open.load(Ordering::SeqCst)
    }

    /// The server answered (with any status): the failures so far were not in a row.
    pub(super) fn answered(&self) {
        self.connect_failures.store(0, Ordering::SeqCst);
    }

    /// Counts one connection failure; true when it opened the breaker.
    pub(super) fn connect_failed(&self) -> bool {
        let failures = self.connect_failures.fetch_add(1, Ordering::SeqCst) + 1;
        if failures >= self.limit {
            self.open.store(true, Ordering::SeqCst);
            return true;
        }
        false
    }
}
