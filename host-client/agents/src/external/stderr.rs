//! An exec agent's stderr into the run's log, bounded: read in chunks (a line
//! never grows past [`PIECE`] bytes: a longer one, or output with no newline,
//! is logged in pieces), at most [`RATE`] bytes a second after a burst of
//! [`BURST`], and at most [`TASK_CAP`] bytes per task. What is not logged is
//! counted, and the count is noted in the log when the task ends (or the
//! process does).
//!
//! The stream itself, byte for byte, goes to the task's result folder
//! ([`FILE_NAME`], at most [`FILE_CAP`] bytes a task, then a note of how much
//! more there was), once the episode has named its folder ([`StderrBudget::keep_in`]).

use std::io::Write;
use std::path::{Path, PathBuf};
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
/// The file of a task's result folder that keeps the agent's stderr.
pub const FILE_NAME: &str = "agent-stderr.log";
/// The most of one task's stderr its file keeps.
pub const FILE_CAP: u64 = 16 << 20;

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
    /// The task's stderr file, while it has one.
    file: Option<Kept>,
}

/// A task's [`FILE_NAME`].
#[derive(Debug)]
struct Kept {
    path: PathBuf,
    file: std::fs::File,
    written: u64,
    dropped: u64,
}

impl Kept {
    /// Closes the file with a note of what it did not keep.
    fn close(mut self) {
        if self.dropped > 0 {
            let note = format!(
                "\n[arena: {} more bytes of stderr were not kept; this file keeps at most {} MiB a task]\n",
                self.dropped,
                FILE_CAP >> 20
            );
            let _ = self.file.write_all(note.as_bytes());
        }
    }
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
                file: None,
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
        let kept = budget.file.take();
        if budget.dropped_bytes > 0 {
            let whole = kept.as_ref().map(|k| format!("; the stream is in {}", k.path.display())).unwrap_or_default();
            tracing::warn!(
                target: "arena::agent",
                pid = self.pid,
                dropped_bytes = budget.dropped_bytes,
                "{} bytes of the agent's stderr ({} pieces) were not logged{whole}",
                budget.dropped_bytes,
                budget.dropped_pieces
            );
        }
        if let Some(kept) = kept {
            kept.close();
        }
        budget.logged = 0;
        budget.dropped_bytes = 0;
        budget.dropped_pieces = 0;
        counts
    }

    /// Keeps the stream from now on in `dir`'s [`FILE_NAME`] (a task's result
    /// folder), until [`StderrBudget::end_task`]. A file that cannot be created
    /// is said in the log; the stream is then only logged.
    pub fn keep_in(&self, dir: &Path) {
        let path = dir.join(FILE_NAME);
        let kept = match std::fs::File::create(&path) {
            Ok(file) => Some(Kept { path, file, written: 0, dropped: 0 }),
            Err(err) => {
                tracing::warn!(target: "arena::agent", pid = self.pid, error = %err, "cannot keep the agent's stderr in {}", path.display());
                None
            }
        };
        let Ok(mut budget) = self.state.lock() else { return };
        if let Some(old) = std::mem::replace(&mut budget.file, kept) {
            old.close();
        }
    }

    /// Writes `bytes` of the stream to the task's file, up to its cap.
    fn keep(&self, bytes: &[u8]) {
        let Ok(mut budget) = self.state.lock() else { return };
        let Some(kept) = budget.file.as_mut() else { return };
        let room = usize::try_from(FILE_CAP.saturating_sub(kept.written)).unwrap_or(usize::MAX);
        let (now, over) = bytes.split_at(bytes.len().min(room));
        if !now.is_empty() {
            if kept.file.write_all(now).is_err() {
                kept.dropped += now.len() as u64;
            } else {
                kept.written += now.len() as u64;
            }
        }
        kept.dropped += over.len() as u64;
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
        budget.keep(&chunk[..n]);
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

    #[tokio::test]
    async fn the_whole_stream_goes_to_the_tasks_file_up_to_its_cap_with_a_note_of_the_rest() {
        let tmp = tempfile::tempdir().expect("tmp");
        let (first, second) = (tmp.path().join("first"), tmp.path().join("second"));
        std::fs::create_dir_all(&first).expect("dir");
        std::fs::create_dir_all(&second).expect("dir");
        let budget = StderrBudget::new(1);
        let cap = usize::try_from(FILE_CAP).expect("cap");
        let stream: Vec<u8> = (0..cap + 1000).map(|i| b"ab\n"[i % 3]).collect();
        budget.keep_in(&first);
        pump(stream.as_slice(), budget.clone()).await;
        let kept = std::fs::read(first.join(FILE_NAME)).expect("the first task's file");
        assert!(kept[..cap] == stream[..cap], "the stream, byte for byte");
        let note = String::from_utf8_lossy(&kept[cap..]);
        assert!(note.contains("1000 more bytes of stderr were not kept") && note.contains("16 MiB"), "{note}");
        // The next task starts a file of its own; a stream under the cap is kept whole, with no note.
        budget.keep_in(&second);
        pump(b"one\ntwo".as_slice(), budget.clone()).await;
        assert_eq!(std::fs::read(second.join(FILE_NAME)).expect("the second task's file"), b"one\ntwo");
        assert_eq!(std::fs::read(first.join(FILE_NAME)).expect("unchanged").len(), kept.len());
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
