//! When a supervisor (the service's, or the logon task's launcher) starts the server
//! again after it ended: the one backoff both follow.

use std::time::Duration;

/// How long the supervisor waits before starting a worker again after one ended.
///
/// A worker that keeps dying at once (a taken port, a bad option) is restarted after
/// 1, 2, 4, ... up to 30 seconds, so it does not spin; one that ran for a minute or
/// more is restarted after a second again.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Backoff {
    next: Duration,
}

impl Backoff {
    /// The first delay.
    pub const MIN: Duration = Duration::from_secs(1);
    /// The longest delay.
    pub const MAX: Duration = Duration::from_secs(30);
    /// A worker that ran this long counts as healthy: the delay starts over.
    pub const HEALTHY: Duration = Duration::from_secs(60);

    pub fn new() -> Backoff {
        Backoff { next: Backoff::MIN }
    }

    /// The delay before the next start, given how long the worker that ended ran.
    pub fn after_exit(&mut self, ran_for: Duration) -> Duration {
        if ran_for >= Backoff::HEALTHY {
            self.next = Backoff::MIN;
        }
        let delay = self.next;
        self.next = (self.next * 2).min(Backoff::MAX);
        delay
    }
}

impl Default for Backoff {
    fn default() -> Backoff {
        Backoff::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_grows_while_the_worker_keeps_dying_and_resets_after_a_good_run() {
        let mut backoff = Backoff::new();
        let quick = Duration::from_millis(200);
        let delays: Vec<u64> = (0..7).map(|_| backoff.after_exit(quick).as_secs()).collect();
        assert_eq!(delays, [1, 2, 4, 8, 16, 30, 30]);
        assert_eq!(backoff.after_exit(Backoff::HEALTHY), Backoff::MIN);
        assert_eq!(backoff.after_exit(quick), Duration::from_secs(2));
    }
}
