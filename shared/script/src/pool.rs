//! The memory all runs of a process share: a total that the programs running at once
//! draw their bytes from, on top of each program's own [`crate::MAX_MEMORY`].
//!
//! A run takes bytes from its pool in chunks of [`CHUNK`] as what it holds grows
//! past what it has taken, and gives all of them back when it ends: its share is its
//! high-water mark while it runs. When the pool has no more, the run fails with
//! `MemoryError` naming the total, as it does at its own budget. So a server running
//! many programs at once (the guest's `/execute`, its MCP `run_python`) holds at most
//! the pool's total in program values, however many programs it was sent.

use std::sync::atomic::{AtomicUsize, Ordering};

/// The granularity in which runs draw from a pool, so that the shared counter is
/// touched once per mebibyte a program grows, not per value.
pub const CHUNK: usize = 1 << 20;

/// A budget in bytes shared by the runs that name it in their `Globals`.
#[derive(Debug)]
pub struct MemoryPool {
    total: usize,
    taken: AtomicUsize,
}

impl MemoryPool {
    /// A pool of `total` bytes, none taken.
    pub fn new(total: usize) -> MemoryPool {
        MemoryPool { total, taken: AtomicUsize::new(0) }
    }

    /// The pool's size in bytes.
    pub fn total(&self) -> usize {
        self.total
    }

    /// The bytes the runs hold from it now.
    pub fn in_use(&self) -> usize {
        self.taken.load(Ordering::Relaxed)
    }

    /// Takes `bytes` when that many are left; false (and nothing taken) when not.
    pub(crate) fn take(&self, bytes: usize) -> bool {
        self.taken
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |taken| {
                taken.checked_add(bytes).filter(|&after| after <= self.total)
            })
            .is_ok()
    }

    /// Gives back `bytes` taken with [`MemoryPool::take`].
    pub(crate) fn give(&self, bytes: usize) {
        // Never below zero, whatever a caller gives back.
        let _ = self.taken.fetch_update(Ordering::AcqRel, Ordering::Acquire, |taken| Some(taken.saturating_sub(bytes)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn takes_up_to_the_total_and_gives_back() {
        let pool = MemoryPool::new(3 * CHUNK);
        assert!(pool.take(2 * CHUNK));
        assert!(!pool.take(2 * CHUNK), "past the total");
        assert_eq!(pool.in_use(), 2 * CHUNK);
        assert!(pool.take(CHUNK));
        pool.give(3 * CHUNK);
        assert_eq!(pool.in_use(), 0);
        pool.give(CHUNK);
        assert_eq!(pool.in_use(), 0);
    }

    #[test]
    fn a_run_past_its_pool_fails_naming_the_total_and_gives_its_share_back() {
        let pool = std::sync::Arc::new(MemoryPool::new(4 * CHUNK));
        let run = |code: &str| {
            let program = crate::parse(code).expect("parses");
            let mut host = crate::RecordingHost::new((100, 100), (0, 0));
            crate::run(&program, &mut host, crate::Globals::python().with_memory(Some(pool.clone())))
        };
        let err = run("x = 'a' * 6000000").expect_err("6 MB is past a 4 MiB pool");
        assert_eq!(err.kind, crate::ErrorKind::Memory);
        assert!(err.message.contains("4 MiB together"), "{}", err.message);
        assert_eq!(pool.in_use(), 0, "the run gave its share back");
        assert!(run("x = 'a' * 2000000").is_ok(), "within the pool");
        assert_eq!(pool.in_use(), 0);
    }

    #[test]
    fn actions_a_recording_host_keeps_count_against_the_run() {
        // 200,000 recorded actions (a line of text, then Enter, 100,000 times) hold
        // several MiB though the program's own value (one 200 kB string) holds far
        // less; a 4 MiB pool refuses them.
        let pool = std::sync::Arc::new(MemoryPool::new(4 * CHUNK));
        let program = crate::parse("import pyautogui\npyautogui.write('a\\n' * 100000)").expect("parses");
        let mut host = crate::RecordingHost::new((100, 100), (0, 0));
        let err = crate::run(&program, &mut host, crate::Globals::python().with_memory(Some(pool.clone())))
            .expect_err("the recorded actions are past the pool");
        assert_eq!(err.kind, crate::ErrorKind::Memory, "{err}");
        assert!(host.actions.len() < 200_000, "stopped before recording them all: {}", host.actions.len());
        assert_eq!(pool.in_use(), 0);
        // The same program against a host that acts (it does not say it keeps its
        // actions) holds only the string.
        let mut acting = crate::tests::FakeHost::new();
        crate::run(&program, &mut acting, crate::Globals::python().with_memory(Some(pool.clone()))).expect("runs");
        assert_eq!(acting.actions.len(), 200_000);
    }
}
