//! Cancellation of the backend call in progress.
//!
//! A backend call runs on a blocking thread under a deadline ([`crate::call::blocking`]).
//! When the deadline passes, the request is answered at once, and this module tells the
//! call still running on its thread to stop: long work (typing with pauses, drags)
//! asks [`checkpoint`] between units and sleeps with [`sleep`], so a timed-out call
//! stops within one unit instead of carrying on (keys arriving in a window long after
//! the client was told the call failed, and interleaving with its next call).
//! Code outside a call (tests, tools) is never cancelled.

use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::{DesktopError, DesktopResult};

thread_local! {
    static CURRENT: RefCell<Option<(&'static str, u64, Arc<AtomicBool>)>> = const { RefCell::new(None) };
}

/// The cancel flag of one call; dropping the scope ends it on this thread.
#[derive(Debug)]
pub struct Scope(());

impl Scope {
    /// Marks the current thread as running call `op` with deadline `ms`, cancelled when
    /// `flag` is set.
    pub fn enter(op: &'static str, ms: u64, flag: Arc<AtomicBool>) -> Scope {
        CURRENT.with(|c| *c.borrow_mut() = Some((op, ms, flag)));
        Scope(())
    }
}

impl Drop for Scope {
    fn drop(&mut self) {
        CURRENT.with(|c| *c.borrow_mut() = None);
    }
}

/// The cancel flag of the call running on this thread, for work that checks it
/// itself (the script interpreter); `None` outside a call.
pub fn flag() -> Option<Arc<AtomicBool>> {
    CURRENT.with(|c| c.borrow().as_ref().map(|(_, _, flag)| Arc::clone(flag)))
}

/// Whether the call running on this thread has been cancelled.
pub fn cancelled() -> bool {
    CURRENT.with(|c| c.borrow().as_ref().is_some_and(|(_, _, flag)| flag.load(Ordering::Relaxed)))
}

/// Stops the work when its call was cancelled.
///
/// # Errors
///
/// [`DesktopError::Timeout`] naming the call and its deadline.
pub fn checkpoint() -> DesktopResult<()> {
    CURRENT.with(|c| match c.borrow().as_ref() {
        Some((op, ms, flag)) if flag.load(Ordering::Relaxed) => Err(DesktopError::Timeout { op, ms: *ms }),
        _ => Ok(()),
    })
}

/// Sleeps `pause`, waking early to stop when the call is cancelled.
///
/// # Errors
///
/// As [`checkpoint`].
pub fn sleep(pause: Duration) -> DesktopResult<()> {
    const SLICE: Duration = Duration::from_millis(10);
    let until = Instant::now() + pause;
    loop {
        checkpoint()?;
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Ok(());
        }
        std::thread::sleep(left.min(SLICE));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn work_stops_once_its_call_is_cancelled() {
        assert!(checkpoint().is_ok(), "outside a call nothing is cancelled");
        let flag = Arc::new(AtomicBool::new(false));
        let scope = Scope::enter("perform", 25, flag.clone());
        assert!(sleep(Duration::from_millis(1)).is_ok());
        flag.store(true, Ordering::Relaxed);
        assert!(cancelled());
        assert!(matches!(checkpoint(), Err(DesktopError::Timeout { op: "perform", ms: 25 })));
        let started = Instant::now();
        assert!(sleep(Duration::from_secs(3600)).is_err(), "a cancelled sleep returns");
        assert!(started.elapsed() < Duration::from_secs(3600));
        drop(scope);
        assert!(checkpoint().is_ok(), "the scope ended with its call");
    }
}
