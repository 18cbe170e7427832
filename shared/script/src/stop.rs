//! When a run must stop: its deadline and its cancel flag, checked at a bounded
//! interval of work.
//!
//! The interpreter checks at every loop iteration and call ([`check`]); built-ins
//! that do a lot of work in one call (sorting, repeating, joining, building a list
//! from a range) count their units of work ([`work`]) and check every
//! [`WORK_SLICE`] units. So a program stops within one slice of work after its
//! deadline passes or its flag is set, with one `TimeoutError` that no `except`
//! catches. Like the memory meter, the state is thread-local: a run never leaves
//! its thread, and the built-ins that count work have no interpreter at hand.

use std::cell::{Cell, RefCell};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::error::{ErrorKind, ScriptError};

/// What stops a run early: a deadline, a flag another thread sets (a dropped
/// request, a server shutting down), or both.
#[derive(Debug, Clone, Default)]
pub struct Stop {
    /// The run fails with `TimeoutError` once this instant has passed.
    pub deadline: Option<Instant>,
    /// The run fails with `TimeoutError` once this flag is set.
    pub cancel: Option<Arc<AtomicBool>>,
}

impl Stop {
    /// Never stops early (the step and memory limits still end every run).
    pub fn never() -> Stop {
        Stop::default()
    }

    /// Stops at `deadline` or when `cancel` is set.
    pub fn new(deadline: Option<Instant>, cancel: Option<Arc<AtomicBool>>) -> Stop {
        Stop { deadline, cancel }
    }

    fn reason(&self) -> Option<&'static str> {
        if self.cancel.as_ref().is_some_and(|flag| flag.load(Ordering::Relaxed)) {
            return Some("the program was cancelled (its request timed out, went away or the server is stopping)");
        }
        if self.deadline.is_some_and(|deadline| Instant::now() >= deadline) {
            return Some("the program ran past its deadline");
        }
        None
    }
}

/// How many units of work a built-in does between two checks.
pub(crate) const WORK_SLICE: u64 = 1 << 14;

thread_local! {
    static CURRENT: RefCell<Stop> = RefCell::new(Stop::default());
    static WORK: Cell<u64> = const { Cell::new(0) };
    static CHECKS: Cell<u64> = const { Cell::new(0) };
}

/// The stop conditions of one run on this thread; gives the previous ones back when dropped.
#[derive(Debug)]
pub(crate) struct StopScope {
    saved: Stop,
    saved_work: u64,
    saved_checks: u64,
}

impl StopScope {
    pub(crate) fn enter(stop: Stop) -> StopScope {
        let saved = CURRENT.with(|c| c.replace(stop));
        StopScope { saved, saved_work: WORK.with(|w| w.replace(0)), saved_checks: CHECKS.with(|c| c.replace(0)) }
    }
}

impl Drop for StopScope {
    fn drop(&mut self) {
        CURRENT.with(|c| *c.borrow_mut() = std::mem::take(&mut self.saved));
        WORK.with(|w| w.set(self.saved_work));
        CHECKS.with(|c| c.set(self.saved_checks));
    }
}

/// The time left before the run's deadline, if it has one.
pub(crate) fn time_left() -> Option<Duration> {
    CURRENT.with(|c| c.borrow().deadline.map(|deadline| deadline.saturating_duration_since(Instant::now())))
}

/// Fails with `TimeoutError` when the run's deadline has passed or its flag is set.
///
/// # Errors
///
/// `TimeoutError` saying which.
pub(crate) fn check() -> Result<(), ScriptError> {
    CHECKS.with(|c| c.set(c.get() + 1));
    match CURRENT.with(|c| c.borrow().reason()) {
        Some(reason) => Err(ScriptError::new(ErrorKind::Timeout, reason)),
        None => Ok(()),
    }
}

/// Counts `units` of work in a built-in, checking ([`check`]) each time another
/// [`WORK_SLICE`] units have been done.
///
/// # Errors
///
/// As [`check`].
pub(crate) fn work(units: u64) -> Result<(), ScriptError> {
    let (before, after) = WORK.with(|w| {
        let before = w.get();
        let after = before.saturating_add(units);
        w.set(after);
        (before, after)
    });
    if before / WORK_SLICE != after / WORK_SLICE {
        check()?;
    }
    Ok(())
}

/// The units of work counted and the checks made so far in the run on this thread.
pub(crate) fn counters() -> (u64, u64) {
    (WORK.with(Cell::get), CHECKS.with(Cell::get))
}
