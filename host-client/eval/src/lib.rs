//! Task evaluation (`arena-eval`): run a task's getters, call its metrics,
//! combine the scores as upstream's `DesktopEnv.evaluate` does. [`evaluate`] is
//! the boundary: the episode hands it the task's evaluator, the agent's last
//! word and an [`EvalContext`], and gets an [`EvalOutcome`].
//!
//! What it is: the framework ([`evaluate`], the outcome types, the getter and
//! metric registries), the getters and metrics with the file formats they read
//! (PDF, SQLite, 7z, audio, video, Office packages); the download cache it reads
//! cloud files through is `arena_client::cache`, which the setup steps share. What it is not: it does not
//! run `postconfig` (the episode runner runs those steps with `arena-setup`
//! first) and it never fails: a getter or metric that cannot produce a value
//! scores 0 with the reason recorded in the outcome when the failure is the
//! agent's, and marks the outcome unfinished, naming the cause, when it is not.
//!
//! Scoring, as upstream:
//! 1. `func: "infeasible"`: 1 when the agent's last word was FAIL, else 0.
//! 2. Otherwise a FAIL scores 0 without fetching anything.
//! 3. For each metric: the result getter, the expected getter if the task has
//!    one, then `metric(result, expected, **options)`.
//! 4. Several metrics: `and` stops at the first 0 and scores the mean of those
//!    run; `or` stops at the first 1 and scores the max.
//!
//! Who a failure belongs to ([`Fault`]) decides what it does, here and not as
//! upstream (where any exception leaves the task unscored): a failure caused by
//! what the agent left (a result file that does not parse, an empty document, a
//! settings file of the wrong shape, a result the guest answered it does not
//! have) scores that metric 0, the agent's; a failure in the task's own parts
//! (its getters' parameters, its options, its expected side, a metric or getter
//! this build lacks) or in reaching what the harness provides (the guest, the
//! browser's debugging port) leaves the task unfinished, `evaluator_error` with
//! its cause (docs/compatibility.md, "Evaluator failures").
//!
//! # Layout
//!
//! - [`value`]: [`Fetched`], what getters return, and Python's `==` over JSON.
//! - [`getters`]: the getter registry ([`getters::lookup`]), one file per family.
//! - [`metrics`]: the metric registry ([`metrics::lookup`]), one file per family.

#![forbid(unsafe_code)]

pub mod getters;
pub mod metrics;
pub mod value;

#[cfg(test)]
mod tests;

use std::path::PathBuf;
use std::time::Instant;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use arena_client::cache::DownloadCache;
use arena_client::client::GuestClient;
use arena_task::{Conj, Evaluator, GetterSpec, MetricCall, Scoring, Task};

pub use getters::{Getter, GetterError};
pub use metrics::{MetricError, MetricFn, MetricInput};
pub use value::Fetched;

/// What getters need: the guest, the host's download cache, and a folder of
/// their own for the files they save (`dest`).
#[derive(Debug, Clone)]
pub struct EvalContext {
    pub client: GuestClient,
    pub cache: DownloadCache,
    /// Per-task folder where getters put `dest` files; created when needed.
    pub work_dir: PathBuf,
    /// The folder of the task file, where `host_file` reads (None: no such getter works).
    pub task_dir: Option<PathBuf>,
}

/// The agent's final control word.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum LastAction {
    Done,
    Fail,
    Wait,
    /// Anything else (the episode ended on the step cap after a normal action).
    Other,
}

/// Where a metric's evaluation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FailedAt {
    /// This build lacks the metric or one of its getters.
    Missing,
    /// The result getter.
    Result,
    /// The expected getter.
    Expected,
    /// The metric itself.
    Metric,
}

/// Whose failure a metric's error is: it decides whether the metric scores 0
/// or the task is left unfinished.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Fault {
    /// What the agent left is not what the metric reads (a file that does not
    /// parse, an empty document, a value of the wrong shape, a result the guest
    /// says it does not have): the metric scores 0, the agent's.
    Agent,
    /// The task's own parts: a getter's parameters, the metric's options or
    /// rules, the expected side. The task is left unfinished (`evaluator_error`).
    Task,
    /// The harness: a getter or metric this build lacks, a guest or browser the
    /// getter could not reach, a host file it could not write, a metric that
    /// crashed. The task is left unfinished (`evaluator_error`).
    Harness,
}

impl Fault {
    /// Whether the failure leaves the task unfinished instead of scoring 0.
    pub fn is_evaluator(self) -> bool {
        self != Fault::Agent
    }

    /// The cause in words, for the unfinished task's reason.
    pub fn words(self) -> &'static str {
        match self {
            Fault::Agent => "the agent's fault",
            Fault::Task => "a fault of the task's evaluator",
            Fault::Harness => "a fault of the harness",
        }
    }
}

/// The score of one metric and what it was computed from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MetricOutcome {
    pub metric: String,
    /// In `[0, 1]`; 0 when `error` is set.
    pub score: f64,
    /// A summary of the result getter's value (long text cut), when it produced one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub result: Option<Value>,
    /// A summary of the expected getter's value, when there is one and it produced one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub expected: Option<Value>,
    /// Why the metric scored 0 without comparing (a getter or metric failure).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Where it failed, when `error` is set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failed_at: Option<FailedAt>,
    /// Whose failure it is, when `error` is set: [`Fault::Agent`] scored 0, the
    /// others left the task unfinished.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fault: Option<Fault>,
    /// Time spent in the getters and the metric.
    pub elapsed_ms: u64,
}

/// A task's score.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalOutcome {
    /// In `[0, 1]`.
    pub score: f64,
    /// The metrics that ran, in order (the rest are skipped after an early stop).
    pub metrics: Vec<MetricOutcome>,
    /// The first getter or metric failure, if any: the score may reflect the
    /// evaluation's failure rather than the agent's work.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Why nothing was measured, when the rules decided alone (a FAIL on a feasible task).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// Set when the evaluation failed for a reason that is not the agent's (the
    /// task's parts, the harness; see [`Fault`]): the task is then left
    /// unfinished (no `result.txt`, `evaluator_error`) and played again by the
    /// next run. The reason names the metric and the cause.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unfinished: Option<String>,
    /// Whether upstream's value is a Python `int` (`1`/`0` in `result.txt`).
    #[serde(default)]
    pub score_is_int: bool,
}

impl EvalOutcome {
    fn decided(score: f64, metrics: Vec<MetricOutcome>, note: Option<String>) -> EvalOutcome {
        EvalOutcome { score, metrics, error: None, note, unfinished: None, score_is_int: true }
    }
}

/// Scores a task's evaluator after the episode (and after its `postconfig`).
/// Never fails: see the module documentation.
pub async fn evaluate(ctx: &EvalContext, evaluator: &Evaluator, last_action: Option<&LastAction>) -> EvalOutcome {
    let last = last_action.copied();
    let (conj, calls, listed) = match &evaluator.scoring {
        Scoring::Infeasible => {
            let score = if last == Some(LastAction::Fail) { 1.0 } else { 0.0 };
            let outcome = MetricOutcome {
                metric: "infeasible".into(),
                score,
                result: Some(serde_json::to_value(last).unwrap_or(Value::Null)),
                expected: Some(Value::String("FAIL".into())),
                error: None,
                failed_at: None,
                fault: None,
                elapsed_ms: 0,
            };
            return EvalOutcome::decided(score, vec![outcome], None);
        }
        Scoring::Metrics { conj, calls, listed } => (*conj, calls, *listed),
    };
    if last == Some(LastAction::Fail) {
        return EvalOutcome::decided(0.0, Vec::new(), Some("the agent answered FAIL on a feasible task".into()));
    }
    if calls.is_empty() {
        return EvalOutcome {
            score: 0.0,
            metrics: Vec::new(),
            error: Some("the evaluator names no metric".into()),
            note: None,
            unfinished: Some("the evaluator names no metric".into()),
            score_is_int: false,
        };
    }
    let mut outcomes = Vec::with_capacity(calls.len());
    let mut stopped = None;
    let mut unfinished = None;
    let mut score_is_int = false;
    for call in calls {
        let outcome = run_metric(ctx, call, last).await;
        let score = outcome.score;
        if let (Some(at), Some(fault)) = (outcome.failed_at, outcome.fault) {
            if fault.is_evaluator() {
                let error = outcome.error.clone().unwrap_or_default();
                unfinished = Some(format!("{} ({}, {}): {error}", outcome.metric, at.words(), fault.words()));
                outcomes.push(outcome);
                break;
            }
            // Upstream's one-metric path returns 0 when the result getter raises.
            if at == FailedAt::Result && !listed {
                stopped = Some(0.0);
                score_is_int = true;
                outcomes.push(outcome);
                break;
            }
        }
        outcomes.push(outcome);
        if listed {
            match conj {
                Conj::And if score == 0.0 => stopped = Some(0.0),
                Conj::Or if score == 1.0 => stopped = Some(1.0),
                _ => {}
            }
            if stopped.is_some() {
                score_is_int = true;
                break;
            }
        }
    }
    let score = if unfinished.is_some() {
        0.0
    } else {
        stopped.unwrap_or_else(|| combine(conj, outcomes.iter().map(|o| o.score)))
    };
    let error = outcomes.iter().find_map(|o| o.error.as_ref().map(|e| format!("{}: {e}", o.metric)));
    EvalOutcome { score, metrics: outcomes, error, note: None, unfinished, score_is_int }
}

/// The mean (`and`) or the max (`or`) of the scores; 0 for none.
fn combine(conj: Conj, scores: impl Iterator<Item = f64>) -> f64 {
    let scores: Vec<f64> = scores.collect();
    if scores.is_empty() {
        return 0.0;
    }
    match conj {
        Conj::And => scores.iter().sum::<f64>() / scores.len() as f64,
        Conj::Or => scores.iter().copied().fold(0.0, f64::max),
    }
}

/// Runs one metric with its getters; every failure becomes a 0 with the reason
/// and its [`Fault`].
async fn run_metric(ctx: &EvalContext, call: &MetricCall, last: Option<LastAction>) -> MetricOutcome {
    let started = Instant::now();
    let mut outcome = MetricOutcome {
        metric: call.metric.clone(),
        score: 0.0,
        result: None,
        expected: None,
        error: None,
        failed_at: None,
        fault: None,
        elapsed_ms: 0,
    };
    let finish = |mut outcome: MetricOutcome| {
        outcome.elapsed_ms = u64::try_from(started.elapsed().as_millis()).unwrap_or(u64::MAX);
        if let Some(error) = &outcome.error {
            tracing::warn!(metric = %outcome.metric, %error, fault = ?outcome.fault, "evaluation step failed");
        }
        outcome
    };
    if metrics::lookup(&call.metric).is_none() {
        outcome.error = Some(format!("metric {} is not implemented in this build", call.metric));
        outcome.failed_at = Some(FailedAt::Missing);
        outcome.fault = Some(Fault::Harness);
        return finish(outcome);
    }
    let result = match &call.result {
        None => Fetched::None,
        Some(spec) => match fetch(ctx, spec).await {
            Ok(value) => value,
            Err(err) => {
                let (at, fault) = getter_failure(&err, FailedAt::Result);
                outcome.failed_at = Some(at);
                outcome.fault = Some(fault);
                outcome.error = Some(err.to_string());
                return finish(outcome);
            }
        },
    };
    outcome.result = Some(result.summary());
    let expected = match &call.expected {
        None => None,
        Some(spec) => match fetch(ctx, spec).await {
            Ok(value) => Some(value),
            Err(err) => {
                let (at, fault) = getter_failure(&err, FailedAt::Expected);
                outcome.failed_at = Some(at);
                outcome.fault = Some(fault);
                outcome.error = Some(err.to_string());
                return finish(outcome);
            }
        },
    };
    outcome.expected = expected.as_ref().map(Fetched::summary);
    let input = MetricInput { result, expected, options: call.options.clone(), last_action: last };
    let name = call.metric.clone();
    // Metrics parse files (spreadsheets, images, video); keep them off the async
    // workers, and turn a panic in one into that metric's error.
    let judged = match tokio::task::spawn_blocking(move || judge(&name, &input)).await {
        Ok(judged) => judged,
        Err(err) => Judged {
            score: 0.0,
            error: Some(format!("metric {} crashed: {err}", call.metric)),
            fault: Some(Fault::Harness),
        },
    };
    outcome.score = judged.score;
    outcome.error = judged.error;
    outcome.fault = judged.fault;
    if outcome.error.is_some() {
        outcome.failed_at = Some(FailedAt::Metric);
    }
    finish(outcome)
}

impl FailedAt {
    /// The stage in words, for the unfinished task's reason.
    pub fn words(self) -> &'static str {
        match self {
            FailedAt::Missing => "not implemented",
            FailedAt::Result => "the result getter",
            FailedAt::Expected => "the expected getter",
            FailedAt::Metric => "the metric",
        }
    }
}

/// What one metric made of its input: a score, or the error and whose it is.
#[derive(Debug, Clone, PartialEq)]
pub struct Judged {
    /// The metric's score; 0 when `error` is set.
    pub score: f64,
    pub error: Option<String>,
    /// Whose failure `error` is.
    pub fault: Option<Fault>,
}

/// Runs the registered metric `name` on `input` (synchronously) and decides
/// whose failure an error is: a [`MetricError::Malformed`] result, or a file of
/// the result that cannot be read or parsed, is the agent's (score 0); an error
/// in the options, the rules or the expected side is the task's; a metric this
/// build lacks, or a score that is not a number, is the harness's.
pub fn judge(name: &str, input: &MetricInput) -> Judged {
    let Some(metric) = metrics::lookup(name) else {
        return Judged {
            score: 0.0,
            error: Some(format!("metric {name} is not implemented in this build")),
            fault: Some(Fault::Harness),
        };
    };
    let failed = |error: String, fault| Judged { score: 0.0, error: Some(error), fault: Some(fault) };
    match metric(input) {
        // Upstream writes what the metric returns, unclamped.
        Ok(score) if score.is_finite() => Judged { score, error: None, fault: None },
        Ok(score) => failed(format!("metric {name} returned {score}, not a score"), Fault::Harness),
        Err(err) => {
            let fault = if metric_error_is_the_results(&err, &input.result) { Fault::Agent } else { Fault::Task };
            failed(err.to_string(), fault)
        }
    }
}

/// Whether a metric's error was caused by the result value: it says so
/// ([`MetricError::Malformed`]), or it is a file of the result that could not be
/// read or parsed. Anything else (options, rules, the expected file) is the task's.
fn metric_error_is_the_results(err: &MetricError, result: &Fetched) -> bool {
    let mut paths = Vec::new();
    result_paths(result, &mut paths);
    match err {
        MetricError::Malformed(_) => true,
        MetricError::Io { path, .. } => paths.iter().any(|p| p == path),
        MetricError::Parse { what, .. } => {
            what.starts_with("the result") || paths.iter().any(|p| what.starts_with(&p.display().to_string()))
        }
        _ => false,
    }
}

fn result_paths<'a>(value: &'a Fetched, out: &mut Vec<&'a std::path::Path>) {
    match value {
        Fetched::File(path) => out.push(path),
        Fetched::List(items) => items.iter().for_each(|item| result_paths(item, out)),
        _ => {}
    }
}

/// Where a getter's failure stands and whose it is: a getter this build lacks
/// is [`FailedAt::Missing`] (the harness's); bad parameters are the task's; a
/// guest out of reach or failing (a 5xx answer, a browser not listening on its
/// debugging port being the guest's 502), a failed download or a host file that
/// could not be written are the harness's; anything else (the guest answered
/// that it has no such file, key or window, or refused it; what it answered is
/// not what the getter reads) is the agent's, except on the expected side,
/// which is the task's whatever failed.
fn getter_failure(err: &GetterError, stage: FailedAt) -> (FailedAt, Fault) {
    let (at, fault) = match err {
        GetterError::NotImplemented(_) => (FailedAt::Missing, Fault::Harness),
        GetterError::BadParams { .. } => (stage, Fault::Task),
        GetterError::Guest { source, .. } if source.out_of_reach() || source.status().is_some_and(|s| s >= 500) => {
            (stage, Fault::Harness)
        }
        GetterError::Io { .. } | GetterError::Download { .. } => (stage, Fault::Harness),
        _ => (stage, Fault::Agent),
    };
    if stage == FailedAt::Expected && fault == Fault::Agent {
        return (at, Fault::Task);
    }
    (at, fault)
}

/// Runs one getter by name.
///
/// # Errors
///
/// [`GetterError::NotImplemented`] for a name this build lacks; the getter's own error otherwise.
pub async fn fetch(ctx: &EvalContext, spec: &GetterSpec) -> Result<Fetched, GetterError> {
    let getter = getters::lookup(&spec.kind).ok_or_else(|| GetterError::NotImplemented(spec.kind.clone()))?;
    getter.fetch(ctx, &spec.params).await
}

/// Whether this build implements the getter `name`.
pub fn getter_supported(name: &str) -> bool {
    getters::lookup(name).is_some()
}

/// Whether this build implements the metric `name`.
pub fn metric_supported(name: &str) -> bool {
    metrics::lookup(name).is_some()
}

/// The `host_file` gold of `evaluator` that cannot be read from `task_dir` (the
/// task file's folder; `None` for a task that has no file, as a task object sent
/// to `arena env serve`): one line per getter, naming the metric, the side and why.
/// Empty when every such file is there.
pub fn unresolved_host_files(evaluator: &Evaluator, task_dir: Option<&std::path::Path>) -> Vec<String> {
    let Scoring::Metrics { calls, .. } = &evaluator.scoring else { return Vec::new() };
    let mut problems = Vec::new();
    for call in calls {
        for (side, spec) in [("result", &call.result), ("expected", &call.expected)] {
            let Some(spec) = spec.as_ref().filter(|s| s.kind == "host_file") else { continue };
            if let Some(why) = getters::host_file_problem(task_dir, &spec.params) {
                problems.push(format!("{} ({side}): {why}", call.metric));
            }
        }
    }
    problems
}

/// The getters and metrics `task` names that this build does not implement,
/// getters first, each once.
pub fn unsupported_names(task: &Task) -> Vec<String> {
    let needs = task.needs();
    let getters = needs.getters.into_iter().filter(|g| !getter_supported(g));
    let metrics = needs.metrics.into_iter().filter(|m| !metric_supported(m));
    getters.chain(metrics).collect()
}
