//! Waiting for a condition a test polls: the one place the poll interval and the
//! message of a missed wait are decided.

use std::time::{Duration, Instant};

/// How often [`eventually`] asks again.
const POLL: Duration = Duration::from_millis(100);

/// Calls `check` every 100 ms until it gives a value, and returns that value.
///
/// # Panics
///
/// When `within` passes first, naming `what` was waited for.
pub async fn eventually<T, F, Fut>(what: &str, within: Duration, mut check: F) -> T
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Option<T>>,
{
    let deadline = Instant::now() + within;
    loop {
        if let Some(value) = check().await {
            return value;
        }
        assert!(Instant::now() < deadline, "timed out after {within:?} waiting for: {what}");
        tokio::time::sleep(POLL).await;
    }
}
