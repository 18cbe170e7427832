//! What a run tells whoever watches it while it goes: tasks starting and
//! finishing, each episode's step, and notes worth a line of their own (a guest
//! down, a task given up, action errors, MCP sessions). The `arena` CLI draws
//! these as a progress display or prints them one line per task
//! (`crate::cli::progress`); a library caller gets nothing unless it asks.
//!
//! The run calls a [`RunWatch`] from its dispatcher loop and the episodes call
//! [`RunWatch::step`] from their own tasks, so an implementation must be cheap
//! and must not block.

use arena_task::Task;

use arena_results::EpisodeResult;

/// Where a run stands, after a task finished.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Tally {
    /// Tasks finished in this run (given-up ones are not: they have no result).
    pub done: usize,
    /// Tasks this run has to do (those already finished before it are not counted).
    pub total: usize,
    /// Of `done`, those that passed.
    pub solved: usize,
    /// Of `done`, the sum of the scores.
    pub score_sum: f64,
}

impl Tally {
    /// The share of finished tasks that passed, in percent (0 before any finished).
    pub fn solved_percent(&self) -> f64 {
        if self.done == 0 {
            0.0
        } else {
            100.0 * self.solved as f64 / self.done as f64
        }
    }
}

/// What a run reports as it goes. Every method has an empty default.
pub trait RunWatch: Send + Sync + std::fmt::Debug {
    /// The run begins: `total` tasks to do over `guests` (their base URLs).
    fn begin(&self, _total: usize, _guests: &[String]) {}
    /// `task` started on `guest` (try number `attempt`).
    fn started(&self, _task: &Task, _guest: &str, _attempt: u32) {}
    /// The episode of `task` on `guest` begins step `step` (from 1).
    fn step(&self, _guest: &str, _task: &Task, _step: u32) {}
    /// `task` finished on `guest` with `result`; `tally` counts it in.
    fn finished(&self, _task: &Task, _guest: &str, _result: &EpisodeResult, _tally: &Tally) {}
    /// A line worth showing on its own.
    fn note(&self, _line: &str) {}
    /// The run is over (its summary follows).
    fn end(&self, _tally: &Tally) {}
}

/// The watch of a run nobody watches.
#[derive(Debug, Clone, Copy, Default)]
pub struct Unwatched;

impl RunWatch for Unwatched {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_solved_share_is_of_finished_tasks() {
        assert_eq!(Tally::default().solved_percent(), 0.0);
        let tally = Tally { done: 4, total: 10, solved: 1, score_sum: 1.5 };
        assert!((tally.solved_percent() - 25.0).abs() < 1e-9);
    }
}
