//! Result folders of a run (`arena-results`): where each task's trajectory,
//! screenshots, score and record go, and how they are read back.
//!
//! The layout is upstream's (`lib_run_single.py` under `run.py`'s result
//! directory), so upstream's `show_result.py` reads it:
//!
//! ```text
//! <out>/<action space>/<observation>/<model>/<trial>/<domain>/<task name>/
//!     result.txt     the score as text ("1.0"), written LAST
//!     traj.jsonl     upstream's trajectory: a reset line, then a line per action
//!                    ([`ResetRecord`], [`StepRecord`], [`ActionRecord`])
//!     screenshot-step_reset_<time>.png, screenshot-step_<i>_<time>.png
//!                    the observations, named as upstream's recorder names them
//!     episode.json   our full record ([`EpisodeResult`])
//!     traj.html      the task's own page
//!     setup/, eval/  files setup steps and getters wrote
//! ```
//!
//! Every file is written to a temporary name beside it and renamed into
//! place, and `result.txt` is written after everything else, so a run that
//! crashes loses nothing already written, and a folder holding `result.txt`
//! is a finished task (what resuming relies on). An episode that ends in an
//! infrastructure error gets an `episode.json` but no `result.txt`, so the
//! next run of the same folder tries it again.
//!
//! This crate does no guest I/O and knows nothing of agents; [`summary`]
//! aggregates folders into the paper's table and [`html`] renders the report.
//!
//! # Layout
//!
//! - this file: [`RunLayout`], [`TaskDir`], the records, atomic writes, scanning.
//! - [`summary`]: [`summary::Summary`], `summary.json` and `summary.md`.
//! - [`compare`]: [`compare::Comparison`], `arena compare` of two folders.
//! - [`certificate`]: task certificates (`arena certify`) and a folder's record of the tasks they call broken.
//! - [`ledger`]: prices, the budget and its record (the cost ledger).
//! - [`stats`]: pass@k, pass^k and the bootstrap intervals of repeated trials.
//! - [`html`]: the HTML report, `report.html`, and each task's `traj.html`.
//! - [`viewer`]: the trajectory viewer's parts of a step: the model's reply read from the records, the markers of its actions.
//! - [`task_list`]: the run's task list in each trial folder (`task_list.json`).
//! - [`timings`]: the timed parts of a step's observation and prediction.
//! - `fixtures` (feature `fixtures`, for tests): an episode record, a layout, a finished task written.

#![forbid(unsafe_code)]

mod budget;
pub mod certificate;
pub mod compare;
pub mod html;
pub mod ledger;
pub mod stats;
pub mod summary;
pub mod task_list;
pub mod timings;
pub mod viewer;

pub use budget::{RecordBudget, MAX_LOG_FILE, MAX_RECORDED_TEXT, STEP_BUDGET};

use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use arena_shared::calendar::civil_from_days;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use arena_exec::AgentAction;
use arena_task::Task;

/// The score file upstream writes and reads.
pub const RESULT_FILE: &str = "result.txt";
/// The trajectory, one JSON object per step.
pub const TRAJ_FILE: &str = "traj.jsonl";
/// The task's own page, beside its trajectory.
pub const TRAJ_HTML: &str = "traj.html";
/// Our full record of the episode.
pub const EPISODE_FILE: &str = "episode.json";
/// Machine-readable run summary, at the root of a result folder.
pub const SUMMARY_JSON: &str = "summary.json";
/// The summary as a Markdown table.
pub const SUMMARY_MD: &str = "summary.md";
/// The HTML report.
pub const REPORT_HTML: &str = "report.html";

/// A result file could not be written or read. Always names the path.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ResultsError {
    /// The I/O error is in the message and not chained as a source, so that a chain
    /// (`{:#}`) says it once.
    #[error("{path}: {reason}")]
    Io { path: PathBuf, reason: std::io::Error },
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
}

impl ResultsError {
    fn io(path: &Path, source: std::io::Error) -> ResultsError {
        ResultsError::Io { path: path.to_owned(), reason: source }
    }

    /// The one format error: `path` holds (or would hold) something that is not
    /// what it should be, and why.
    pub fn format(path: &Path, why: impl std::fmt::Display) -> ResultsError {
        ResultsError::Format { path: path.to_owned(), message: why.to_string() }
    }
}

/// How an episode ended.
///
/// Two kinds of ending leave the task **unfinished** as upstream leaves it when
/// `run_single_example` raises: no `result.txt`, the reason in `episode.json`,
/// and the next `arena run` of the folder plays the task again. The others are
/// scored.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", content = "message", rename_all = "snake_case")]
pub enum EpisodeStatus {
    /// The loop ran to DONE, FAIL or the step cap, and the task was evaluated.
    Completed,
    /// The agent could not go on for a reason of its own (a scripted plan used
    /// up, output it cannot turn into actions); the task was still evaluated
    /// and the score counts.
    AgentError(String),
    /// Unfinished: the guest or the host's setup failed (unreachable guest,
    /// failed download, reset that did not work). The pool tries it again on
    /// another guest within the run.
    InfraError(String),
    /// Unfinished: the model endpoint kept failing after the retries (upstream's
    /// `predict` raises and the task is left without a result).
    ModelError(String),
    /// Unfinished: the evaluation failed for a reason that is not the agent's:
    /// the task's own parts (its getters' parameters, its options, its expected
    /// side, a metric or getter this build lacks) or what the harness provides
    /// (the guest, the browser's debugging port, a gold file's download). The
    /// message names the metric and the cause. Written as `evaluator_error`;
    /// `eval_error`, its name before, is still read.
    #[serde(alias = "eval_error")]
    EvaluatorError(String),
    /// Unfinished: the run was interrupted (Ctrl-C) before the episode ended;
    /// nothing half-done was evaluated.
    Interrupted(String),
}

/// Whose failure a task's outcome is, so a reader tells "the environment
/// failed" from "the agent failed" at a glance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Blame {
    /// Scored 1: no failure.
    Passed,
    /// The agent's: it finished without solving the task (a wrong answer, a
    /// give-up, the step cap) or could not go on for a reason of its own.
    Agent,
    /// The environment's: the guest stopped answering, its reset or setup failed.
    Guest,
    /// The environment's: the VM the run owns failed.
    Vm,
    /// The environment's: the evaluation could not finish.
    Evaluator,
    /// The environment's: the model endpoint (or a Set-of-Marks service) stayed
    /// down, refused, or the agent could not be made.
    Model,
    /// Nobody's: the run was stopped.
    Interrupted,
}

impl Blame {
    /// `passed`, `agent`, `guest`, `vm`, `evaluator`, `model` or `interrupted`.
    pub fn name(self) -> &'static str {
        match self {
            Blame::Passed => "passed",
            Blame::Agent => "agent",
            Blame::Guest => "guest",
            Blame::Vm => "vm",
            Blame::Evaluator => "evaluator",
            Blame::Model => "model",
            Blame::Interrupted => "interrupted",
        }
    }

    /// Whether the environment (guest, VM, evaluator, model endpoint) failed, not the agent.
    pub fn is_environment(self) -> bool {
        matches!(self, Blame::Guest | Blame::Vm | Blame::Evaluator | Blame::Model)
    }

    /// `passed`, `agent`, `environment` or `interrupted`.
    pub fn side(self) -> &'static str {
        if self.is_environment() {
            "environment"
        } else {
            self.name()
        }
    }

    /// The blame of an outcome: its status and score.
    pub fn of(status: &EpisodeStatus, score: f64) -> Blame {
        match status {
            EpisodeStatus::Completed if score >= 1.0 => Blame::Passed,
            EpisodeStatus::Completed | EpisodeStatus::AgentError(_) => Blame::Agent,
            // The fleet's failures name the VM (`preparing the VM: VM vm-0: QEMU exited`).
            EpisodeStatus::InfraError(m) if m.contains("VM") => Blame::Vm,
            EpisodeStatus::InfraError(_) => Blame::Guest,
            EpisodeStatus::ModelError(_) => Blame::Model,
            EpisodeStatus::EvaluatorError(_) => Blame::Evaluator,
            EpisodeStatus::Interrupted(_) => Blame::Interrupted,
        }
    }
}

impl EpisodeStatus {
    /// `completed`, `agent_error`, `infra_error`, `model_error`, `evaluator_error` or `interrupted`.
    pub fn kind(&self) -> &'static str {
        match self {
            EpisodeStatus::Completed => "completed",
            EpisodeStatus::AgentError(_) => "agent_error",
            EpisodeStatus::InfraError(_) => "infra_error",
            EpisodeStatus::ModelError(_) => "model_error",
            EpisodeStatus::EvaluatorError(_) => "evaluator_error",
            EpisodeStatus::Interrupted(_) => "interrupted",
        }
    }

    /// The error message, if any.
    pub fn message(&self) -> Option<&str> {
        match self {
            EpisodeStatus::Completed => None,
            EpisodeStatus::AgentError(m)
            | EpisodeStatus::InfraError(m)
            | EpisodeStatus::ModelError(m)
            | EpisodeStatus::EvaluatorError(m)
            | EpisodeStatus::Interrupted(m) => Some(m),
        }
    }

    /// An infrastructure error: the pool tries the task again on a healthy guest.
    pub fn is_infra(&self) -> bool {
        matches!(self, EpisodeStatus::InfraError(_))
    }

    /// No score: no `result.txt` is written and the next run plays the task again.
    pub fn is_unfinished(&self) -> bool {
        matches!(
            self,
            EpisodeStatus::InfraError(_)
                | EpisodeStatus::ModelError(_)
                | EpisodeStatus::EvaluatorError(_)
                | EpisodeStatus::Interrupted(_)
        )
    }
}

/// Host-side timings of one step, in milliseconds, with the timeouts and retries it met.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct StepTimings {
    /// Screenshot, accessibility tree, windows and clipboard (the observation the agent was given).
    pub observe_ms: u64,
    /// The agent's `predict` (Set-of-Marks and the model call, when it has them), retries included.
    pub predict_ms: u64,
    /// Executing every action of the step.
    pub act_ms: u64,
    /// The pause after the actions (`sleep_after_action`, upstream's `--sleep_after_execution`).
    #[serde(default)]
    pub pause_ms: u64,
    /// Each part of the observation the agent was given: screenshot, decode, tree, windows, clipboard, DOM.
    #[serde(default)]
    pub observe: crate::timings::ObserveTimings,
    /// The agent's own parts: Set-of-Marks, the model call and its tries.
    #[serde(default)]
    pub predict: crate::timings::PredictTimings,
    /// Times the harness asked the agent again after a model failure within the step.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub predict_retries: u32,
    /// Every timeout of the step, in words (`predict: no answer within 600 s`, `action 1: ...`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub timeouts: Vec<String>,
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}

/// The observation keys of a `traj.jsonl` line, as upstream's recorder saves
/// an observation: files for the screenshot and the tree, the rest inline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct ObservationKeys {
    /// `screenshot-step_<i>_<timestamp>.png` (`reset` for the first), in the task folder.
    #[serde(default)]
    pub screenshot: String,
    /// `accessibility_tree-step_<i>_<timestamp>.txt`: the tree in upstream's XML.
    #[serde(default)]
    pub accessibility_tree: String,
    #[serde(default)]
    pub instruction: String,
    #[serde(default)]
    pub window_title: String,
    /// The visible windows' titles, one per line (upstream's `window_names_str`).
    #[serde(default)]
    pub window_names_str: String,
    /// The clipboard text the agent's `computer` tracks (`computer_clipboard`), empty when none.
    #[serde(default)]
    pub computer_clipboard: String,
}

/// The first line of `traj.jsonl`: the observation after the reset, as
/// upstream's `record_init` writes it (`step_num` 0, `action` null).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResetRecord {
    pub step_num: u32,
    pub action_timestamp: String,
    pub action: Option<String>,
    #[serde(flatten)]
    pub observation: ObservationKeys,
}

/// The upstream part of a `traj.jsonl` line for one action, as upstream's
/// `record_step` writes it: the action, `reward` (always 0 upstream), `done`
/// (the action was DONE or FAIL), `info` (`{"done": true}`, `{"fail": true}`
/// or `{}`) and the observation taken after the action.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct ActionRecord {
    /// 1-based step number.
    pub step_num: u32,
    /// `YYYYMMDD@HHMMSS` (UTC) when the action started, as upstream writes it.
    pub action_timestamp: String,
    /// The action as upstream logs it: the code, or `DONE`, `FAIL`, `WAIT`.
    pub action: String,
    #[serde(default)]
    pub reward: f64,
    /// Whether this action was DONE or FAIL.
    pub done: bool,
    #[serde(default)]
    pub info: Value,
    /// The observation taken after the action.
    #[serde(flatten)]
    pub observation: ObservationKeys,
}

/// One step: the first `traj.jsonl` line of the step (upstream's line for its
/// first action, [`ActionRecord`], with our keys beside them), followed by one
/// upstream line per further action ([`StepRecord::more`]). A step whose model
/// output held no action still gets its line (upstream writes none), with an
/// empty `action`.
///
/// Our keys: `step` (what tells our lines from upstream-only lines), `response`,
/// `actions` (what the replay agent reads back), `ended`, `screenshot_file`
/// (what the agent saw), `timings`, `error`, `outcomes`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepRecord {
    #[serde(flatten)]
    pub first: ActionRecord,
    /// The step number again, under the name the replay agent reads (the host's replay agent).
    pub step: u32,
    /// The agent's raw response (the model's text).
    pub response: String,
    /// The actions, tagged by kind (`{"kind": "computer", "code": "..."}`), as the replay agent reads them.
    #[serde(default)]
    pub actions: Vec<AgentAction>,
    /// Whether the episode ended with this step (DONE, FAIL, the step cap or an error).
    #[serde(default)]
    pub ended: bool,
    /// The screenshot the agent saw when it chose this step's actions, in the task folder.
    pub screenshot_file: String,
    /// Where the step's screenshot came from when not from the guest: QEMU's
    /// display of its VM (`vm-display: ...`), when the guest's capture failed or was black.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub screenshot_source: Option<String>,
    #[serde(default)]
    pub timings: StepTimings,
    /// What went wrong in this step: unparsable model output, a failed action.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Per-action outcomes the agent's executor reported (free-form).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outcomes: Vec<Value>,
    /// The guest's screen in physical pixels when the step was observed (width,
    /// height): the space of the step's typed actions, which the viewer maps onto
    /// the screenshot's pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub screen: Option<[u32; 2]>,
    /// The tokens and model time of the step's prediction (the cost ledger),
    /// when the agent reports them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub usage: Option<crate::ledger::Usage>,
    /// Upstream's lines for the step's second and further actions.
    #[serde(skip)]
    pub more: Vec<ActionRecord>,
    /// The agent's logs of the step, as upstream's recorder adds them to the
    /// line: a file name for text, images and JSON, the value itself otherwise.
    /// Written by [`StepRecord::line`] (a log named as a field the line already has
    /// goes in as `log_<name>`), not read back.
    #[serde(skip)]
    pub logs: std::collections::BTreeMap<String, Value>,
}

/// The prefix of a log whose name the `traj.jsonl` line already has ([`StepRecord::line`]).
pub const LOG_PREFIX: &str = "log_";

impl StepRecord {
    /// The step's first `traj.jsonl` line: its fields, then the agent's logs beside
    /// them as upstream's recorder adds them. A log named as a field the line already
    /// has (`step`, `reward`, `screenshot_file`, the computer-use agents' `response`
    /// record, or any field an agent's `record` names) goes in as `log_<name>`
    /// (`log_log_<name>` if that is taken too), so the line never holds a key twice and
    /// no agent can overwrite what the harness recorded: every JSON reader takes the
    /// last of two equal keys, which would be the agent's.
    ///
    /// # Errors
    ///
    /// A field that does not serialise (none of the harness's do).
    pub fn line(&self) -> Result<String, serde_json::Error> {
        // The fields in the struct's order, then the logs in theirs.
        let mut line = serde_json::to_string(self)?;
        let mut taken: std::collections::HashSet<String> =
            serde_json::from_str::<serde_json::Map<String, Value>>(&line)?.into_iter().map(|(key, _)| key).collect();
        line.pop(); // the closing brace
        for (name, value) in &self.logs {
            let mut key = name.clone();
            while taken.contains(&key) {
                key.insert_str(0, LOG_PREFIX);
            }
            if line.len() > 1 {
                line.push(',');
            }
            line.push_str(&serde_json::to_string(&key)?);
            line.push(':');
            line.push_str(&serde_json::to_string(value)?);
            taken.insert(key);
        }
        line.push('}');
        Ok(line)
    }
}

/// Everything about one episode; `episode.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeResult {
    pub task_id: String,
    /// The file stem: upstream's name for the task and its folder.
    pub task_name: String,
    pub domain: String,
    pub instruction: String,
    pub agent: String,
    #[serde(default)]
    pub model: String,
    /// The guest the episode ran on.
    #[serde(default)]
    pub guest: String,
    /// 1 for the first try; higher when an infrastructure error made the run try again.
    #[serde(default = "one")]
    pub attempt: u32,
    /// 0.0 to 1.0; 0.0 for an unfinished task.
    pub score: f64,
    /// Whether upstream's `evaluate` gives the score as a Python `int` (or a
    /// `bool`) rather than a `float`: the rules decided alone (infeasible, FAIL on
    /// a feasible task, an `and` stopped at a 0, a result getter that failed).
    /// `result.txt` then holds `1` or `0` instead of `1.0` or `0.0`.
    #[serde(default)]
    pub score_is_int: bool,
    pub status: EpisodeStatus,
    /// Steps the agent took.
    pub steps: u32,
    /// The agent's last control word: `done`, `fail`, `wait` or `none`.
    #[serde(default)]
    pub last_action: String,
    /// Wall time of the whole episode, reset to evaluation.
    pub elapsed_ms: u64,
    /// Wall time of reset and setup.
    #[serde(default)]
    pub setup_ms: u64,
    /// Wall time of post-config and evaluation.
    #[serde(default)]
    pub eval_ms: u64,
    /// Seconds since the Unix epoch when the episode started.
    #[serde(default)]
    pub started_unix: u64,
    /// Reports of the setup steps (config and postconfig), as [`arena_setup`] gives them.
    #[serde(default)]
    pub setup: Vec<Value>,
    /// The evaluation outcome, as [`arena_eval`] gives it (`null` when it did not run).
    #[serde(default)]
    pub eval: Value,
    /// The per-step timings, in step order (a copy of what `traj.jsonl` holds).
    #[serde(default)]
    pub timings: Vec<StepTimings>,
    /// The named options in force (`pauses`, `order`, ...; docs/compatibility.md).
    #[serde(default)]
    pub options: std::collections::BTreeMap<String, String>,
    /// The VM the task ran in and the snapshot it started from, when the run
    /// owns its VMs (`arena run --vm-image`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vm: Option<VmStart>,
    /// The steps' tokens and model time together, when the agent reported any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tokens: Option<crate::ledger::Usage>,
    /// What [`EpisodeResult::tokens`] cost in US dollars, by the run's `--prices` file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost_usd: Option<f64>,
    /// Actions of the agent that failed and the episode went on, as upstream goes
    /// on: an answer that did not translate (an unknown key, an unsupported call,
    /// refused code), an action the guest refused, an action past the step's deadline.
    #[serde(default)]
    pub action_errors: u32,
}

/// Where a task's VM started from, recorded in `episode.json`. A plain record
/// of the results: the VM code (`arena-host`'s `vm`) fills it, and neither the results
/// nor the runner depend on the VM code.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VmStart {
    /// The VM's name.
    pub vm: String,
    /// The snapshot restored before the task, or `None` when the task found the
    /// VM as the previous one left it (`--reset never`, or between resets).
    pub snapshot: Option<String>,
    /// Restoring the snapshot and waiting for the guest's health, in milliseconds.
    pub restore_ms: u64,
    /// Whether the VM was rebuilt (QEMU started again) before this task.
    #[serde(default)]
    pub rebuilt: bool,
    /// QEMU's display against the guest's screenshot after the restore.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub screen: Option<ScreenCheck>,
    /// The guest's clock set to the host's after the restore (a restored VM
    /// wakes with the time it was saved at), and how far off it was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clock: Option<ClockSync>,
}

/// The guest's clock set after a restore or rebuild.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClockSync {
    /// How far the guest's clock was behind the host's, in milliseconds
    /// (negative: ahead); `None` when it could not be set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corrected_ms: Option<i64>,
    /// Why the clock was not set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// How QEMU's own view of the screen compares with the guest's screenshot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScreenCheck {
    pub dump_width: u32,
    pub dump_height: u32,
    pub dump_black: bool,
    pub guest_width: u32,
    pub guest_height: u32,
    pub guest_black: bool,
    /// What disagrees, when something does: a black guest capture over a lit
    /// display is a lock screen, UAC's secure desktop or a capture failure.
    pub problem: Option<String>,
}

fn one() -> u32 {
    1
}

impl EpisodeResult {
    /// The one way a record starts: `task` on `guest`, try `attempt`, with
    /// `status`, no score, no steps and nothing run yet. The episode fills in the rest.
    pub fn start(task: &arena_task::Task, guest: &str, attempt: u32, status: EpisodeStatus) -> EpisodeResult {
        EpisodeResult {
            task_id: task.id.clone(),
            task_name: task.name.clone(),
            domain: task.domain.clone(),
            instruction: task.instruction.clone(),
            agent: String::new(),
            model: String::new(),
            guest: guest.to_owned(),
            attempt,
            score: 0.0,
            score_is_int: false,
            status,
            steps: 0,
            last_action: "none".into(),
            elapsed_ms: 0,
            setup_ms: 0,
            eval_ms: 0,
            started_unix: unix_now(),
            setup: Vec::new(),
            eval: Value::Null,
            timings: Vec::new(),
            options: std::collections::BTreeMap::new(),
            vm: None,
            tokens: None,
            cost_usd: None,
            action_errors: 0,
        }
    }

    /// Whose failure this outcome is ([`Blame`]).
    pub fn blame(&self) -> Blame {
        Blame::of(&self.status, self.score)
    }

    /// What `result.txt` holds: Python's `str()` of upstream's value, `1`/`0`
    /// for an int, else the float's repr (`1.0`, `0.5`, `0.3333333333333333`).
    ///
    /// Upstream writes a metric's `bool` as `True`/`False`, which its own
    /// readers disagree on (`show_result.py` counts `False` as 1.0, `run.py`
    /// counts `True` as 0.0); those are written as `1`/`0` here
    /// (docs/compatibility.md, "result.txt").
    pub fn score_text(&self) -> String {
        if self.score_is_int && self.score.fract() == 0.0 {
            format!("{}", self.score as i64)
        } else {
            python_float(self.score)
        }
    }

    /// Whether the task counts as solved: a score of 1 (within rounding).
    pub fn success(&self) -> bool {
        !self.status.is_unfinished() && self.score >= 1.0 - 1e-9
    }
}

/// Folder names are kept to a safe alphabet: path separators and other
/// characters a model name may hold (`meta/llama-3:70b`) become `_`.
pub fn safe_component(text: &str) -> String {
    let cleaned: String = text
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.' | '@' | '+') { c } else { '_' })
        .collect();
    match cleaned.as_str() {
        "" | "." | ".." => "_".to_owned(),
        _ => cleaned,
    }
}

/// Where a run writes: `<root>/<action space>/<observation>/<model>/<trial>/`,
/// upstream's `<result_dir>/<action_space>/<observation_type>/<model>/<trial_id>/`,
/// with a task in `<domain>/<task name>/` below it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunLayout {
    pub root: PathBuf,
    /// Upstream's `--action_space` as the folder name (default `pyautogui`, the
    /// argument's default in `run.py`, whatever the agent).
    pub agent: String,
    /// Upstream's `--observation_type` (`a11y_tree`, `screenshot`, ...).
    pub observation: String,
    pub model: String,
    /// Upstream's `--trial_id` (default `0`).
    pub trial: String,
}

/// Upstream's default `--trial_id`.
pub const DEFAULT_TRIAL_ID: &str = "0";

/// The key of a task's `extra` map that carries its trial number (0..K-1) in a
/// run of several trials: the run sets it on each copy of a task it queues
/// (the host's `run::plan`) and removes it in a run of one, so a task file cannot choose it.
pub const TRIAL_KEY: &str = "_arena_trial";

/// The trial a run marked `task` with ([`TRIAL_KEY`]).
pub fn trial_of(task: &Task) -> Option<u64> {
    task.extra.get(TRIAL_KEY).and_then(Value::as_u64)
}

impl RunLayout {
    /// The trial folder the domains go in (`show_result.py`'s target folder).
    pub fn base(&self) -> PathBuf {
        self.trial_base(&self.trial)
    }

    /// The folder of trial `trial` (`<action space>/<observation>/<model>/<trial>`).
    pub fn trial_base(&self, trial: &str) -> PathBuf {
        self.root
            .join(safe_component(&self.agent))
            .join(safe_component(&self.observation))
            .join(safe_component(&self.model))
            .join(safe_component(trial))
    }

    /// The folder of one task (not created): in the trial the run marked it
    /// with ([`TRIAL_KEY`], `arena run --trials K`), else in [`RunLayout::trial`].
    pub fn task_dir(&self, task: &Task) -> TaskDir {
        let base = match trial_of(task) {
            Some(trial) => self.trial_base(&trial.to_string()),
            None => self.base(),
        };
        TaskDir::new(base.join(safe_component(&task.domain)).join(safe_component(&task.name)))
    }
}

/// One task's result folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TaskDir {
    path: PathBuf,
}

impl TaskDir {
    pub fn new(path: PathBuf) -> TaskDir {
        TaskDir { path }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Where setup steps put the stdout/stderr files `execute` names.
    pub fn setup_dir(&self) -> PathBuf {
        self.path.join("setup")
    }

    /// Where getters put their `dest` files.
    pub fn eval_dir(&self) -> PathBuf {
        self.path.join("eval")
    }

    /// Whether the task is finished: its `result.txt` holds a score.
    pub fn is_finished(&self) -> bool {
        read_score(&self.path.join(RESULT_FILE)).is_ok()
    }

    /// Empties the folder (the leftovers of an unfinished try) and creates it with
    /// its `setup/` and `eval/` subfolders.
    ///
    /// # Errors
    ///
    /// The folder cannot be removed or created.
    pub fn prepare(&self) -> Result<(), ResultsError> {
        match std::fs::remove_dir_all(&self.path) {
            Ok(()) => {}
            Err(err) if err.kind() == std::io::ErrorKind::NotFound => {}
            Err(err) => return Err(ResultsError::io(&self.path, err)),
        }
        for dir in [self.path.clone(), self.setup_dir(), self.eval_dir()] {
            std::fs::create_dir_all(&dir).map_err(|err| ResultsError::io(&dir, err))?;
        }
        Ok(())
    }

    /// The screenshot file name upstream's recorder gives the observation after
    /// the action of step index `index` (0-based; `None` for the reset) taken at
    /// `timestamp`: `screenshot-step_<index>_<timestamp>.png`.
    pub fn screenshot_name(index: Option<u32>, timestamp: &str) -> String {
        match index {
            Some(i) => format!("screenshot-step_{i}_{timestamp}.png"),
            None => format!("screenshot-step_reset_{timestamp}.png"),
        }
    }

    /// Writes a file of the task folder (atomically).
    ///
    /// # Errors
    ///
    /// The file cannot be written.
    pub fn write_file(&self, name: &str, bytes: &[u8]) -> Result<(), ResultsError> {
        write_atomic(&self.path.join(name), bytes)
    }

    /// Writes a screenshot under [`TaskDir::screenshot_name`] and returns its file name.
    ///
    /// # Errors
    ///
    /// The file cannot be written.
    pub fn write_screenshot(&self, index: Option<u32>, timestamp: &str, png: &[u8]) -> Result<String, ResultsError> {
        let name = TaskDir::screenshot_name(index, timestamp);
        write_atomic(&self.path.join(&name), png)?;
        Ok(name)
    }

    /// Rewrites `traj.jsonl`: the reset line, then each step's lines
    /// (atomically, so a crash leaves the previous complete version, never a torn line).
    ///
    /// # Errors
    ///
    /// The file cannot be written.
    pub fn write_trajectory(&self, reset: Option<&ResetRecord>, steps: &[StepRecord]) -> Result<(), ResultsError> {
        let path = self.path.join(TRAJ_FILE);
        let format = |err: serde_json::Error| ResultsError::format(&path, err);
        let mut text = String::new();
        if let Some(reset) = reset {
            text.push_str(&serde_json::to_string(reset).map_err(format)?);
            text.push('\n');
        }
        for step in steps {
            text.push_str(&step.line().map_err(format)?);
            text.push('\n');
            for more in &step.more {
                text.push_str(&serde_json::to_string(more).map_err(format)?);
                text.push('\n');
            }
        }
        write_atomic(&path, text.as_bytes())
    }

    /// Writes `episode.json`.
    ///
    /// # Errors
    ///
    /// The file cannot be written.
    pub fn write_episode(&self, episode: &EpisodeResult) -> Result<(), ResultsError> {
        write_json(&self.path.join(EPISODE_FILE), episode)
    }

    /// Writes `result.txt` as upstream does, `f"{result}\n"` (see
    /// [`EpisodeResult::score_text`]). Call it last: it marks the task finished.
    ///
    /// # Errors
    ///
    /// The file cannot be written.
    pub fn write_result(&self, text: &str) -> Result<(), ResultsError> {
        write_atomic(&self.path.join(RESULT_FILE), format!("{text}\n").as_bytes())
    }

    /// Writes a whole episode's files in the order that keeps a crash harmless:
    /// trajectory, record, and `result.txt` last (only when the episode was not
    /// an infrastructure error).
    ///
    /// # Errors
    ///
    /// The first file that cannot be written.
    pub fn finish(
        &self,
        episode: &EpisodeResult,
        reset: Option<&ResetRecord>,
        steps: &[StepRecord],
    ) -> Result<(), ResultsError> {
        self.write_trajectory(reset, steps)?;
        self.write_episode(episode)?;
        html::write_task_page(self, episode)?;
        if !episode.status.is_unfinished() {
            self.write_result(&episode.score_text())?;
        }
        Ok(())
    }

    /// Reads `episode.json`.
    ///
    /// # Errors
    ///
    /// The file is missing or malformed.
    pub fn read_episode(&self) -> Result<EpisodeResult, ResultsError> {
        read_episode(&self.path.join(EPISODE_FILE))
    }

    /// Reads `traj.jsonl` (an absent file is an empty trajectory).
    ///
    /// # Errors
    ///
    /// A line that is not a [`StepRecord`].
    pub fn read_trajectory(&self) -> Result<Vec<StepRecord>, ResultsError> {
        read_trajectory(&self.path.join(TRAJ_FILE))
    }
}

/// Formats a score as Python's `str(float)` does for the values scores take
/// (`1.0`, `0.0`, `0.5`, `0.3333333333333333`).
pub fn python_float(value: f64) -> String {
    if !value.is_finite() {
        return if value.is_nan() {
            "nan".into()
        } else if value > 0.0 {
            "inf".into()
        } else {
            "-inf".into()
        };
    }
    if value.fract() == 0.0 && value.abs() < 1e16 {
        format!("{value:.1}")
    } else {
        format!("{value}")
    }
}

/// Reads a `result.txt`: one number, as upstream writes it (Python's float
/// repr, possibly `True`/`False` from a metric that returned a bool).
///
/// # Errors
///
/// The file is missing or holds no number.
pub fn read_score(path: &Path) -> Result<f64, ResultsError> {
    let text = std::fs::read_to_string(path).map_err(|err| ResultsError::io(path, err))?;
    let word = text.trim();
    match word {
        "True" => return Ok(1.0),
        "False" => return Ok(0.0),
        _ => {}
    }
    word.parse::<f64>().ok().filter(|s| s.is_finite()).ok_or_else(|| ResultsError::Format {
        path: path.to_owned(),
        message: format!("not a score: {:?}", truncate(word, 40)),
    })
}

/// Reads an `episode.json`.
///
/// # Errors
///
/// The file is missing or malformed.
pub fn read_episode(path: &Path) -> Result<EpisodeResult, ResultsError> {
    let bytes = std::fs::read(path).map_err(|err| ResultsError::io(path, err))?;
    serde_json::from_slice(&bytes).map_err(|err| ResultsError::format(path, err))
}

/// Reads the steps of a `traj.jsonl` (an absent file is an empty trajectory):
/// the lines that carry our `step` key; upstream-only lines (the reset line, a
/// step's further actions, `run.py`'s error lines) and blank lines are skipped.
///
/// # Errors
///
/// A line that is not JSON, or a step line that is not a [`StepRecord`], naming its number.
pub fn read_trajectory(path: &Path) -> Result<Vec<StepRecord>, ResultsError> {
    Ok(read_trajectory_lines(path)?.into_iter().map(|(step, _)| step).collect())
}

/// [`read_trajectory`], each step with its line as JSON (which holds the
/// agent's logs, [`StepRecord::logs`], that a [`StepRecord`] does not read back).
///
/// # Errors
///
/// As [`read_trajectory`].
pub fn read_trajectory_lines(path: &Path) -> Result<Vec<(StepRecord, Value)>, ResultsError> {
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(err) => return Err(ResultsError::io(path, err)),
    };
    let bad = |idx: usize, err: serde_json::Error| ResultsError::Format {
        path: path.to_owned(),
        message: format!("line {}: {err}", idx + 1),
    };
    let mut steps = Vec::new();
    for (idx, line) in text.lines().enumerate().filter(|(_, line)| !line.trim().is_empty()) {
        let value: Value = serde_json::from_str(line).map_err(|err| bad(idx, err))?;
        if value.get("step").is_some() {
            steps.push((serde_json::from_value(value.clone()).map_err(|err| bad(idx, err))?, value));
        }
    }
    Ok(steps)
}

fn truncate(text: &str, max: usize) -> &str {
    let mut end = text.len().min(max);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a
/// rename, so readers (and a crash) see the old file or the new one, never half.
///
/// # Errors
///
/// The folder is missing or not writable, or the disk is full.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ResultsError> {
    arena_shared::atomic::write_atomic(path, bytes).map_err(|err| ResultsError::io(path, err))
}

/// `value` as pretty JSON into `path`, atomically ([`write_atomic`]): the one way
/// the results write a JSON file.
///
/// # Errors
///
/// [`ResultsError::Format`] when the value does not encode; else as [`write_atomic`].
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<(), ResultsError> {
    let bytes = serde_json::to_vec_pretty(value).map_err(|err| ResultsError::format(path, err))?;
    write_atomic(path, &bytes)
}

/// A task folder found under a result root.
#[derive(Debug, Clone, PartialEq)]
pub struct FoundTask {
    pub dir: TaskDir,
    /// The folder relative to the root it was found under.
    pub relative: PathBuf,
    /// `result.txt`'s score, when the task is finished.
    pub score: Option<f64>,
    /// `episode.json`, when present and readable.
    pub episode: Option<EpisodeResult>,
}

impl FoundTask {
    /// The task's domain: from its record, else its parent folder's name.
    pub fn domain(&self) -> String {
        match &self.episode {
            Some(ep) => ep.domain.clone(),
            None => self
                .relative
                .parent()
                .and_then(|p| p.file_name())
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
        }
    }

    /// The task's name: from its record, else its folder's name.
    pub fn name(&self) -> String {
        match &self.episode {
            Some(ep) => ep.task_name.clone(),
            None => self.relative.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
        }
    }
}

/// Every task folder below `root` (a folder holding `result.txt` or
/// `episode.json`), sorted by relative path.
///
/// # Errors
///
/// `root` cannot be read.
pub fn scan(root: &Path) -> Result<Vec<FoundTask>, ResultsError> {
    std::fs::read_dir(root).map_err(|err| ResultsError::io(root, err))?;
    let mut dirs = Vec::new();
    collect_task_dirs(root, 0, &mut dirs);
    dirs.sort();
    let mut found = Vec::with_capacity(dirs.len());
    for dir in dirs {
        let relative = dir.strip_prefix(root).map(Path::to_path_buf).unwrap_or_else(|_| dir.clone());
        let score = read_score(&dir.join(RESULT_FILE)).ok();
        let episode = match read_episode(&dir.join(EPISODE_FILE)) {
            Ok(ep) => Some(ep),
            Err(ResultsError::Io { .. }) => None,
            Err(err) => {
                tracing::warn!(error = %err, "ignoring an unreadable episode record");
                None
            }
        };
        found.push(FoundTask { dir: TaskDir::new(dir), relative, score, episode });
    }
    Ok(found)
}

/// Upstream's layout is six levels deep; a little slack covers a root given one level up.
const MAX_SCAN_DEPTH: usize = 9;

fn collect_task_dirs(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) {
    if dir.join(RESULT_FILE).is_file() || dir.join(EPISODE_FILE).is_file() {
        out.push(dir.to_owned());
        return;
    }
    if depth >= MAX_SCAN_DEPTH {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        // Symbolic links are not followed: a link loop must not hang a report.
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            collect_task_dirs(&entry.path(), depth + 1, out);
        }
    }
}

/// `YYYYMMDD@HHMMSS` in UTC, upstream's `action_timestamp` format.
pub fn timestamp_now() -> String {
    let secs = SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    format_timestamp(secs)
}

/// Seconds since the Unix epoch now.
pub fn unix_now() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0)
}

/// Formats Unix seconds as `YYYYMMDD@HHMMSS` (UTC).
pub fn format_timestamp(secs: u64) -> String {
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    let rem = secs % 86_400;
    format!("{y:04}{m:02}{d:02}@{:02}{:02}{:02}", rem / 3600, rem % 3600 / 60, rem % 60)
}

#[cfg(any(test, feature = "fixtures"))]
pub mod fixtures;
#[cfg(test)]
mod tests;
