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
//! scores 0 with the reason recorded in the outcome.
//!
//! Scoring, as upstream:
//! 1. `func: "infeasible"`: 1 when the agent's last word was FAIL, else 0.
//! 2. Otherwise a FAIL scores 0 without fetching anything.
//! 3. For each metric: the result getter (an error scores that metric 0), the
//!    expected getter if the task has one, then `metric(result, expected, **options)`.
//! 4. Several metrics: `and` stops at the first 0 and scores the mean of those
//!    run; `or` stops at the first 1 and scores the max.
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
    /// The metric itself: its options or inputs are not what it takes, or it crashed.
    Metric,
    /// The metric could not read or parse a file: scored 0, as most of upstream's
    /// metrics catch that and return 0 (docs/compatibility.md, "Unreadable files").
    Unreadable,
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
    /// Set when upstream's `evaluate` would raise here instead of returning a
    /// score: the task is then left unfinished (no `result.txt`) and played
    /// again by the next run. See [`evaluate`] for the rules.
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
        if let Some(at) = outcome.failed_at.filter(|at| *at != FailedAt::Unreadable) {
            let error = outcome.error.clone().unwrap_or_default();
            // Upstream's one-metric path returns 0 when the result getter raises;
            // everything else that raises (an expected getter, the metric, a result
            // getter in the list path) leaves the task without a score.
            if at == FailedAt::Result && !listed {
                stopped = Some(0.0);
                score_is_int = true;
            } else {
                unfinished = Some(format!("{}: {error}", outcome.metric));
            }
            outcomes.push(outcome);
            break;
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

/// Runs one metric with its getters; every failure becomes a 0 with the reason.
async fn run_metric(ctx: &EvalContext, call: &MetricCall, last: Option<LastAction>) -> MetricOutcome {
    let started = Instant::now();
    let mut outcome = MetricOutcome {
        metric: call.metric.clone(),
        score: 0.0,
        result: None,
        expected: None,
        error: None,
        failed_at: None,
        elapsed_ms: 0,
    };
    let finish = |mut outcome: MetricOutcome| {
        outcome.elapsed_ms = u64::try_from(started.elapsed().as_millis()).unwrap_or(u64::MAX);
        if let Some(error) = &outcome.error {
            tracing::warn!(metric = %outcome.metric, %error, "evaluation step failed; scoring 0");
        }
        outcome
    };
    let Some(metric) = metrics::lookup(&call.metric) else {
        outcome.error = Some(format!("metric {} is not implemented in this build", call.metric));
        outcome.failed_at = Some(FailedAt::Missing);
        return finish(outcome);
    };
    let result = match &call.result {
        None => Fetched::None,
        Some(spec) => match fetch(ctx, spec).await {
            Ok(value) => value,
            Err(err) => {
                outcome.failed_at = Some(getter_failure(&err, FailedAt::Result));
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
                outcome.failed_at = Some(getter_failure(&err, FailedAt::Expected));
                outcome.error = Some(err.to_string());
                return finish(outcome);
            }
        },
    };
    outcome.expected = expected.as_ref().map(Fetched::summary);
    let input = MetricInput { result, expected, options: call.options.clone(), last_action: last };
    // Metrics parse files (spreadsheets, images, video); keep them off the async
    // workers, and turn a panic in one into that metric's error.
    match tokio::task::spawn_blocking(move || metric(&input)).await {
        // Upstream writes what the metric returns, unclamped.
        Ok(Ok(score)) if score.is_finite() => outcome.score = score,
        Ok(Ok(score)) => outcome.error = Some(format!("metric {} returned {score}, not a score", call.metric)),
        Ok(Err(err @ (MetricError::Io { .. } | MetricError::Parse { .. }))) => {
            outcome.error = Some(err.to_string());
            outcome.failed_at = Some(FailedAt::Unreadable);
        }
        Ok(Err(err)) => outcome.error = Some(err.to_string()),
        Err(err) => outcome.error = Some(format!("metric {} crashed: {err}", call.metric)),
    }
    if outcome.error.is_some() && outcome.failed_at.is_none() {
        outcome.failed_at = Some(FailedAt::Metric);
    }
    finish(outcome)
}

/// A getter this build lacks is [`FailedAt::Missing`] (upstream has it, so the
/// failure is ours, never a score); any other failure is the getter's.
fn getter_failure(err: &GetterError, stage: FailedAt) -> FailedAt {
    match err {
        GetterError::NotImplemented(_) => FailedAt::Missing,
        _ => stage,
    }
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

/// The getters and metrics `task` names that this build does not implement,
/// getters first, each once.
pub fn unsupported_names(task: &Task) -> Vec<String> {
    let needs = task.needs();
    let getters = needs.getters.into_iter().filter(|g| !getter_supported(g));
    let metrics = needs.metrics.into_iter().filter(|m| !metric_supported(m));
    getters.chain(metrics).collect()
}
