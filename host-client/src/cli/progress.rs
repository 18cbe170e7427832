//! What `arena run` shows on the console while it goes (`--progress`): on a
//! terminal a live display drawn with `indicatif` (tasks done of all, solved so
//! far, elapsed and ETA, and a line per guest naming its task and step); one
//! line per finished task when the console is not a terminal or with `plain`;
//! nothing with `none`. Notes (a guest down, a task given up, action errors, MCP
//! sessions) print above the display, or as lines of their own. Everything goes
//! to stderr: stdout keeps the summary alone.

use std::collections::HashMap;
use std::io::IsTerminal as _;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use arena_task::Task;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::run::watch::{RunWatch, Tally, Unwatched};
use arena_results::EpisodeResult;

/// `--progress`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ProgressArg {
    /// The live display on a terminal (and not under CI), plain lines otherwise.
    Auto,
    /// The live display (drawn only when stderr is a terminal).
    Bar,
    /// One line per finished task, and the notes.
    Plain,
    /// Nothing while the run goes.
    None,
}

/// The watch `--progress` asks for.
pub fn watch(arg: ProgressArg) -> Arc<dyn RunWatch> {
    let live = std::io::stderr().is_terminal() && std::env::var_os("CI").is_none();
    match arg {
        ProgressArg::Auto if live => Arc::new(Live::default()),
        ProgressArg::Bar => Arc::new(Live::default()),
        ProgressArg::Auto | ProgressArg::Plain => Arc::new(Plain),
        ProgressArg::None => Arc::new(Unwatched),
    }
}

/// `domain/name`, with the trial when there are several.
fn label(task: &Task) -> String {
    match task.extra.get(arena_results::TRIAL_KEY).and_then(serde_json::Value::as_u64) {
        Some(trial) => format!("{}/{} (trial {trial})", task.domain, task.name),
        None => format!("{}/{}", task.domain, task.name),
    }
}

/// What one finished task adds to the console: its outcome in a few words.
fn outcome(result: &EpisodeResult) -> String {
    let mut line = format!(
        "score {} ({}, {} step{}, {:.1} s",
        arena_results::python_float(result.score),
        result.status.kind(),
        result.steps,
        if result.steps == 1 { "" } else { "s" },
        result.elapsed_ms as f64 / 1000.0
    );
    if result.action_errors > 0 {
        line.push_str(&format!(", {} action error(s): the episode went on, see traj.jsonl", result.action_errors));
    }
    line.push(')');
    if let Some(why) = result.status.message() {
        // The first line, and not all of it: episode.json has the whole message.
        let first = why.lines().next().unwrap_or("");
        let mut short: String = first.chars().take(160).collect();
        if short.len() < why.len() {
            short.push('…');
        }
        line.push_str(&format!(": {short}"));
    }
    line
}

fn solved(tally: &Tally) -> String {
    format!("{} solved ({:.1} %)", tally.solved, tally.solved_percent())
}

/// One line per finished task, on stderr.
#[derive(Debug, Clone, Copy)]
struct Plain;

impl RunWatch for Plain {
    fn begin(&self, total: usize, guests: &[String]) {
        eprintln!("{total} task(s) to run on {} guest(s)", guests.len());
    }

    fn finished(&self, task: &Task, guest: &str, result: &EpisodeResult, tally: &Tally) {
        eprintln!(
            "[{}/{}] {}: {} on {guest} · {}",
            tally.done,
            tally.total,
            label(task),
            outcome(result),
            solved(tally)
        );
    }

    fn note(&self, line: &str) {
        eprintln!("{line}");
    }
}

/// The live display: a bar of the run and a line per guest.
#[derive(Debug, Default)]
struct Live {
    state: Mutex<Option<LiveState>>,
}

#[derive(Debug)]
struct LiveState {
    multi: MultiProgress,
    run: ProgressBar,
    guests: HashMap<String, ProgressBar>,
}

const RUN_TEMPLATE: &str = "{elapsed_precise} [{bar:30}] {pos}/{len} tasks · {msg} · ETA {eta}";
const GUEST_TEMPLATE: &str = "  {prefix}: {msg}";

impl Live {
    fn with(&self, f: impl FnOnce(&LiveState)) {
        if let Some(state) = self.state.lock().unwrap_or_else(PoisonError::into_inner).as_ref() {
            f(state);
        }
    }
}

impl RunWatch for Live {
    fn begin(&self, total: usize, guests: &[String]) {
        let multi = MultiProgress::with_draw_target(ProgressDrawTarget::stderr());
        let run = multi.add(ProgressBar::new(total as u64));
        if let Ok(style) = ProgressStyle::with_template(RUN_TEMPLATE) {
            run.set_style(style.progress_chars("=> "));
        }
        run.set_message("0 solved");
        run.enable_steady_tick(Duration::from_millis(250));
        let style = ProgressStyle::with_template(GUEST_TEMPLATE).ok();
        let guests = guests
            .iter()
            .enumerate()
            .map(|(i, url)| {
                let line = multi.add(ProgressBar::new_spinner());
                if let Some(style) = &style {
                    line.set_style(style.clone());
                }
                line.set_prefix(format!("guest {} ({url})", i + 1));
                line.set_message("idle");
                (url.clone(), line)
            })
            .collect();
        *self.state.lock().unwrap_or_else(PoisonError::into_inner) = Some(LiveState { multi, run, guests });
    }

    fn started(&self, task: &Task, guest: &str, attempt: u32) {
        self.with(|state| {
            if let Some(line) = state.guests.get(guest) {
                let again = if attempt > 1 { format!(" (try {attempt})") } else { String::new() };
                line.set_message(format!("{}{again} · setting up", label(task)));
            }
        });
    }

    fn step(&self, guest: &str, task: &Task, step: u32) {
        self.with(|state| {
            if let Some(line) = state.guests.get(guest) {
                line.set_message(format!("{} · step {step}", label(task)));
            }
        });
    }

    fn finished(&self, task: &Task, guest: &str, result: &EpisodeResult, tally: &Tally) {
        self.with(|state| {
            if let Some(line) = state.guests.get(guest) {
                line.set_message("idle");
            }
            if result.action_errors > 0 || !result.success() {
                let _ = state.multi.println(format!("{}: {}", label(task), outcome(result)));
            }
            state.run.inc(1);
            state.run.set_message(solved(tally));
        });
    }

    fn note(&self, line: &str) {
        self.with(|state| {
            let _ = state.multi.println(line);
        });
    }

    fn end(&self, tally: &Tally) {
        if let Some(state) = self.state.lock().unwrap_or_else(PoisonError::into_inner).take() {
            for line in state.guests.values() {
                line.finish_and_clear();
            }
            state.run.set_message(solved(tally));
            state.run.finish();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_results::EpisodeStatus;

    #[test]
    fn a_finished_task_says_its_score_status_steps_and_action_errors() {
        let text = r#"{"id": "x", "instruction": "i", "config": [], "evaluator": {"func": "infeasible"}}"#;
        let task = Task::parse(text, std::path::Path::new("/tasks/notepad/t1.json")).expect("a task");
        let mut result = EpisodeResult::start(&task, "http://g", 1, EpisodeStatus::Completed);
        result.score = 1.0;
        result.steps = 3;
        result.elapsed_ms = 2500;
        assert_eq!(outcome(&result), "score 1.0 (completed, 3 steps, 2.5 s)");
        result.action_errors = 2;
        assert!(outcome(&result).contains("2 action error(s)"), "{}", outcome(&result));
        result.status = EpisodeStatus::AgentError(format!("{}\nsecond line", "x".repeat(300)));
        let said = outcome(&result);
        assert!(said.ends_with(&format!(": {}…", "x".repeat(160))), "{said}");
        assert_eq!(label(&task), "notepad/t1");
    }
}
