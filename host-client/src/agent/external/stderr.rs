//! An exec agent's stderr into the run's log, bounded: read in chunks (a line
//! never grows past [`PIECE`] bytes: a longer one, or output with no newline,
//! is logged in pieces), at most [`RATE`] bytes a second after a burst of
//! [`BURST`], and at most [`TASK_CAP`] bytes per task. What is not logged is
//! counted, and the count is noted in the log when the task ends (or the
//! process does). The stream is not kept elsewhere: an agent that wants its
//! full output kept writes its own file.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use tokio::io::AsyncReadExt;

/// The longest piece of stderr logged as one line.
pub const PIECE: usize = 4096;
/// The most of one task's stderr the run's log takes.
pub const TASK_CAP: u64 = 1 << 20;
/// The steady rate of stderr the run's log takes, in bytes a second.
pub const RATE: f64 = 64.0 * 1024.0;
/// What may be logged at once above the steady rate.
pub const BURST: f64 = 256.0 * 1024.0;

/// One process's stderr budget, renewed with each task it serves.
#[derive(Debug)]
pub struct StderrBudget {
    pid: u32,
    state: Mutex<Budget>,
}

#[derive(Debug)]
struct Budget {
    logged: u64,
    dropped_bytes: u64,
    dropped_pieces: u64,
    tokens: f64,
    refilled: Instant,
}

impl StderrBudget {
    /// A fresh budget for the process `pid`.
    pub fn new(pid: u32) -> Arc<StderrBudget> {
        Arc::new(StderrBudget {
            pid,
            state: Mutex::new(Budget {
                logged: 0,
                dropped_bytes: 0,
                dropped_pieces: 0,
                tokens: BURST,
                refilled: Instant::now(),
            }),
        })
    }

    /// Whether a piece of `len` bytes goes into the log; the first refusal of a task is noted.
    fn admit(&self, len: usize) -> bool {
        let Ok(mut budget) = self.state.lock() else { return false };
        let now = Instant::now();
        let refill = now.duration_since(budget.refilled).as_secs_f64() * RATE;
        budget.tokens = (budget.tokens + refill).min(BURST);
        budget.refilled = now;
        let len64 = len as u64;
        if budget.logged + len64 <= TASK_CAP && budget.tokens >= len as f64 {
            budget.tokens -= len as f64;
            budget.logged += len64;
            return true;
        }
        if budget.dropped_pieces == 0 {
            tracing::warn!(
                target: "arena::agent",
                pid = self.pid,
                "the agent's stderr is over its bound ({} KiB a task, {} KiB/s); what follows is counted, not logged",
                TASK_CAP >> 10,
                RATE as u64 >> 10
            );
        }
        budget.dropped_bytes += len64;
        budget.dropped_pieces += 1;
        false
    }

    /// Ends a task's budget: notes what was not logged, and starts afresh.
    /// Answers the bytes logged and not logged in that task.
    pub fn end_task(&self) -> (u64, u64) {
        let Ok(mut budget) = self.state.lock() else { return (0, 0) };
        let counts = (budget.logged, budget.dropped_bytes);
        if budget.dropped_bytes > 0 {
            tracing::warn!(
                target: "arena::agent",
                pid = self.pid,
                dropped_bytes = budget.dropped_bytes,
                "{} bytes of the agent's stderr ({} pieces) were not logged",
                budget.dropped_bytes,
                budget.dropped_pieces
            );
        }
        budget.logged = 0;
        budget.dropped_bytes = 0;
        budget.dropped_pieces = 0;
        counts
    }
}

/// Reads `stderr` to its end into the log under `budget`; answers the bytes
/// of the last task logged and not logged (newlines apart).
pub async fn pump(mut stderr: impl tokio::io::AsyncRead + Unpin, budget: Arc<StderrBudget>) -> (u64, u64) {
    let mut chunk = vec![0u8; 16 * 1024];
    let mut piece: Vec<u8> = Vec::with_capacity(PIECE);
    let emit = |piece: &mut Vec<u8>| {
        if budget.admit(piece.len()) {
            let text = String::from_utf8_lossy(piece);
            tracing::info!(target: "arena::agent", pid = budget.pid, "{}", text.trim_end_matches('\r'));
        }
        piece.clear();
    };
    loop {
        let n = match stderr.read(&mut chunk).await {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        for &byte in &chunk[..n] {
            if byte == b'\n' {
                emit(&mut piece);
                continue;
            }
            piece.push(byte);
            if piece.len() >= PIECE {
                emit(&mut piece);
            }
        }
    }
    if !piece.is_empty() {
        emit(&mut piece);
    }
    budget.end_task()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_flood_is_logged_up_to_the_cap_and_the_rest_counted() {
        let budget = StderrBudget::new(1);
        // 8 MiB with no newline, then lines.
        let mut flood = vec![b'y'; 8 << 20];
        flood.extend(std::iter::repeat_n(b"line\n".as_slice(), 100_000).flatten());
        let started = Instant::now();
        let (logged, dropped) = pump(flood.as_slice(), budget.clone()).await;
        let allowed = BURST + RATE * started.elapsed().as_secs_f64();
        assert_eq!(logged + dropped, (8 << 20) + 4 * 100_000, "every byte logged or counted");
        assert!(logged as f64 <= allowed && logged <= TASK_CAP, "{logged} bytes logged");
        // pump ends the task: the budget is fresh again.
        let state = budget.state.lock().expect("state");
        assert_eq!((state.logged, state.dropped_bytes), (0, 0));
    }

    #[test]
    fn the_budget_takes_a_burst_then_refuses_and_a_new_task_starts_afresh() {
        let started = Instant::now();
        let budget = StderrBudget::new(1);
        let mut taken = 0usize;
        while budget.admit(PIECE) {
            taken += PIECE;
            let allowed = BURST + RATE * started.elapsed().as_secs_f64();
            assert!(taken as f64 <= allowed, "{taken} bytes taken, {allowed} allowed");
        }
        assert!(taken as f64 >= BURST - PIECE as f64, "{taken}");
        let dropped = budget.state.lock().expect("state").dropped_bytes;
        assert_eq!(dropped, PIECE as u64);
        assert_eq!(budget.end_task(), (taken as u64, PIECE as u64));
        assert_eq!(budget.state.lock().expect("state").dropped_bytes, 0);
        // The cap: a task never logs more than TASK_CAP, however long it waits.
        let mut state = budget.state.lock().expect("state");
        state.logged = TASK_CAP - 10;
        state.tokens = BURST;
        drop(state);
        assert!(!budget.admit(11));
        assert!(budget.admit(10));
    }
}
