//! Runs of many tasks: the task list, its shard, resuming, the pool of
//! guests, and the summary and report at the end.
//!
//! A run is: load the tasks (a folder, or an upstream index such as
//! `test_all.json`, kept in the index's order); keep this machine's
//! [`shard::Shard`] (chosen from the tasks sorted by domain and name, so every
//! machine agrees whatever the order); drop the tasks whose folder already
//! holds a `result.txt` (resuming is the default, so running the same command
//! again after a crash finishes the job); put the rest in the [`TaskOrder`]
//! asked for (upstream's: the index's) and hand them to the guests in that
//! order ([`pool`]); then write
//! `summary.json`, `summary.md` and `report.html` at the root of the output.
//!
//! It is not the episode (see [`crate::episode`]), nor `arena run`'s driver (the
//! plan, the guests, the preflight: `crate::driver`), and it does not parse the
//! command line or print (see `crate::cli`).
//!
//! # Layout
//!
//! - [`pool`]: [`pool::run_pool`], one task per guest, retries, dead guests set aside.
//! - [`shard`]: [`shard::Shard`], `--shard i/n`.
//! - [`merge`]: [`merge::merge`], shard folders into one.
//! - [`blame`]: whose failure a guest that stops answering is, by what the agent did in the step.
//! - [`watch`]: [`watch::RunWatch`], what a run tells whoever watches it as it goes.
//! - `fleet`: the run's VMs (`arena_vm::fleet::VmFleet`) as the pool's lifecycle, the blame's watch and the observation's stand-in screen.

pub mod blame;
mod fleet;
pub mod merge;
pub mod pool;
pub mod shard;
pub mod watch;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arena_client::client::GuestClient;
use arena_results::html::write_report;
use arena_results::summary::Summary;
use arena_results::{ResultsError, RunLayout};
use arena_task::{Difficulty, Task, TaskError};

use self::pool::{run_pool, PoolConfig, PoolEvent, PoolReport, TaskRunner};
use self::shard::Shard;

/// The task list could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LoadError {
    /// One or more task files are broken (all are listed).
    #[error("{} task file(s) could not be loaded:\n{}", .0.len(), list(.0))]
    Tasks(Vec<TaskError>),
    #[error("{path}: no task files found")]
    Empty { path: PathBuf },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

fn list(errors: &[TaskError]) -> String {
    errors.iter().map(|e| format!("  {e}")).collect::<Vec<_>>().join("\n")
}

/// Loads the tasks of a folder (every task file below it, by path) or an index
/// file (`test_all.json`: domain -> names, resolved into
/// `<index folder>/<examples or examples_noctxt>/<domain>/<name>.json`, in the
/// index's order, which is the order upstream runs them in).
///
/// # Errors
///
/// Any task that does not load (all of them, for a folder), or no tasks at all.
pub fn load_tasks(spec: &Path, difficulty: Difficulty) -> Result<Vec<Task>, LoadError> {
    let meta = std::fs::metadata(spec).map_err(|source| LoadError::Io { path: spec.to_owned(), source })?;
    let mut tasks = if meta.is_dir() {
        // A corpus root (holding `examples/`) is read in the chosen difficulty.
        let examples = spec.join(difficulty.folder());
        let dir = if examples.is_dir() { examples } else { spec.to_owned() };
        let (tasks, errors) = arena_task::load_dir(&dir);
        if !errors.is_empty() {
            return Err(LoadError::Tasks(errors));
        }
        tasks
    } else {
        let root = spec.parent().unwrap_or(Path::new("."));
        arena_task::load_index(root, spec, difficulty).map_err(|err| LoadError::Tasks(vec![err]))?
    };
    if tasks.is_empty() {
        return Err(LoadError::Empty { path: spec.to_owned() });
    }
    if meta.is_dir() {
        tasks.sort_by(|a, b| a.path.cmp(&b.path));
    }
    Ok(tasks)
}

/// The order a shard's tasks are handed to the guests in (`--order`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TaskOrder {
    /// As loaded: an index file's order, as upstream's `run.py` runs it.
    #[default]
    Index,
    /// By domain, then name.
    Sorted,
    /// A shuffle of the index order, the same for the same seed.
    Shuffle { seed: u64 },
}

impl std::fmt::Display for TaskOrder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TaskOrder::Index => f.write_str("index"),
            TaskOrder::Sorted => f.write_str("sorted"),
            TaskOrder::Shuffle { seed } => write!(f, "shuffle:{seed}"),
        }
    }
}

/// Sorts by domain, then name (then path, for duplicates).
pub fn sort_tasks(tasks: &mut [Task]) {
    tasks.sort_by(|a, b| a.order_key().cmp(&b.order_key()));
}

/// Which tasks a run will do.
#[derive(Debug)]
pub struct Plan {
    /// This shard's unfinished tasks, in order.
    pub todo: Vec<Task>,
    /// This shard's tasks that already have a `result.txt` (resuming).
    pub finished: Vec<Task>,
}

/// This shard's slice of `tasks`, split into to-do and already finished, each
/// in `order`. The shard is chosen from the tasks sorted by domain and name,
/// so shards agree across machines whatever the order. With `resume` off every
/// task of the shard is to do again.
pub fn plan(tasks: Vec<Task>, shard: Shard, layout: &RunLayout, resume: bool, order: TaskOrder) -> Plan {
    plan_trials(tasks, shard, layout, resume, order, 1)
}

/// [`plan`] for `trials` trials of each task: with more than one, every task is
/// queued once per trial, trial-major (every task of trial 0 in `order`, then of
/// trial 1, ...), so that what drifts over a run (a guest, a model endpoint) is
/// spread over the trials instead of lining up with one; each copy carries its
/// trial ([`arena_results::TRIAL_KEY`]), which puts it in trial folder 0..K-1
/// ([`RunLayout::task_dir`]), finished or not on its own.
pub fn plan_trials(
    tasks: Vec<Task>,
    shard: Shard,
    layout: &RunLayout,
    resume: bool,
    order: TaskOrder,
    trials: u32,
) -> Plan {
    let mut numbered: Vec<(usize, Task)> = tasks.into_iter().enumerate().collect();
    numbered.sort_by(|(_, a), (_, b)| a.order_key().cmp(&b.order_key()));
    let mut mine = shard.select(numbered);
    match order {
        TaskOrder::Sorted => {}
        TaskOrder::Index => mine.sort_by_key(|(pos, _)| *pos),
        TaskOrder::Shuffle { seed } => {
            use rand::seq::SliceRandom;
            use rand::SeedableRng;
            // ChaCha8 by name: its stream is fixed, so a seed means the same order in every build.
            mine.sort_by_key(|(pos, _)| *pos);
            mine.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
        }
    }
    let mine = mine.into_iter().map(|(_, mut task)| {
        task.extra.remove(arena_results::TRIAL_KEY);
        task
    });
    let queue: Vec<Task> = if trials > 1 {
        let mine: Vec<Task> = mine.collect();
        (0..trials)
            .flat_map(|trial| {
                mine.iter().map(move |task| {
                    let mut task = task.clone();
                    task.extra.insert(arena_results::TRIAL_KEY.to_owned(), trial.into());
                    task
                })
            })
            .collect()
    } else {
        mine.collect()
    };
    let (finished, todo) = queue.into_iter().partition(|task| resume && layout.task_dir(task).is_finished());
    Plan { todo, finished }
}

/// How a run behaves.
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub layout: RunLayout,
    pub shard: Shard,
    /// Skip tasks that have a `result.txt` (default on).
    pub resume: bool,
    pub pool: PoolConfig,
    /// Who is told of the run as it goes (the CLI's progress display).
    pub watch: Arc<dyn watch::RunWatch>,
    /// The report's title.
    pub title: String,
    /// The order tasks go to the guests in.
    pub order: TaskOrder,
    /// Trials of each task (`--trials`, 1 by default): trial folders 0..K-1, trial-major.
    pub trials: u32,
    /// Spend after which no new task starts (`--max-cost`, `--max-total-tokens`);
    /// the spend of the folder's earlier runs counts.
    pub budget: arena_results::ledger::Budget,
}

/// What a run did.
#[derive(Debug)]
pub struct RunOutcome {
    /// Tasks of this shard that were to do.
    pub todo: usize,
    /// Tasks of this shard skipped as already finished.
    pub skipped: usize,
    pub pool: PoolReport,
    /// Of the whole output folder.
    pub summary: Summary,
    pub report: PathBuf,
}

/// Runs this shard's unfinished `tasks` over `guests` with `runner`, then
/// writes the summary and report of the output folder.
///
/// # Errors
///
/// The output folder cannot be created, or the summary or report cannot be written.
pub async fn run_tasks(
    tasks: Vec<Task>,
    guests: Vec<GuestClient>,
    runner: Arc<dyn TaskRunner>,
    options: &RunOptions,
) -> Result<RunOutcome, ResultsError> {
    let root = &options.layout.root;
    std::fs::create_dir_all(root).map_err(|source| ResultsError::Io { path: root.clone(), reason: source })?;
    let plan = plan_trials(tasks, options.shard, &options.layout, options.resume, options.order, options.trials);
    let (todo, skipped) = (plan.todo.len(), plan.finished.len());
    // The whole list, so that a task that never starts still counts (the strict rate).
    let listed: Vec<&Task> = plan.todo.iter().chain(&plan.finished).collect();
    arena_results::task_list::record(&options.layout.base(), &listed)?;
    tracing::info!(shard = %options.shard, todo, skipped, guests = guests.len(), "starting the run");
    let watch = Arc::clone(&options.watch);
    let guest_urls: Vec<String> = guests.iter().map(|g| g.base_url().to_owned()).collect();
    watch.begin(todo, &guest_urls);
    let mut tally = watch::Tally { total: todo, ..watch::Tally::default() };
    let budget = options.budget;
    let mut spent = arena_results::ledger::Spent::default();
    if budget.is_set() {
        for task in Summary::from_dir(root)?.tasks {
            spent.add(task.tokens.as_ref(), task.cost_usd);
        }
    }
    let mut stopped = budget.reached(&spent);
    let no_new_tasks = options.pool.no_new_tasks.clone();
    if stopped.is_some() {
        no_new_tasks.cancel();
    }
    let mut on_event = |event: PoolEvent<'_>| match event {
        PoolEvent::Started { task, guest, attempt } => {
            tracing::info!(task = %task.name, domain = %task.domain, guest, attempt, "task started");
            watch.started(task, guest, attempt);
        }
        PoolEvent::Finished { task, result } => {
            tally.done += 1;
            tally.score_sum += result.score;
            if result.success() {
                tally.solved += 1;
            }
            spent.add(result.tokens.as_ref(), result.cost_usd);
            if stopped.is_none() {
                stopped = budget.reached(&spent);
                if let Some(why) = &stopped {
                    tracing::warn!(why, "the budget is spent: no new task starts");
                    watch.note(&format!("budget reached ({why}): no new task starts; running ones finish"));
                    no_new_tasks.cancel();
                }
            }
            tracing::info!(task = %task.name, domain = %task.domain, score = result.score, status = result.status.kind(), steps = result.steps, action_errors = result.action_errors, "task finished");
            if result.action_errors > 0 {
                tracing::warn!(task = %task.name, action_errors = result.action_errors, "actions failed; the episode went on");
            }
            watch.finished(task, &result.guest, result, &tally);
        }
        PoolEvent::Retrying { task, guest, attempt, error } => {
            tracing::warn!(task = %task.name, attempt, error, "infrastructure error: trying the task again");
            watch.note(&format!(
                "{}/{}: infrastructure error on {guest} ({error}); try {attempt} follows",
                task.domain, task.name
            ));
        }
        PoolEvent::GuestDown { guest, error } => {
            tracing::warn!(guest, error, "guest taken out of the pool until it answers again");
            watch.note(&format!("guest {guest} is down: {error}"));
        }
        PoolEvent::GuestBack { guest } => {
            tracing::info!(guest, "guest back in the pool");
            watch.note(&format!("guest {guest} is back"));
        }
        PoolEvent::GaveUp { task, reason } => {
            tracing::error!(task = %task.name, reason, "task given up");
            watch.note(&format!("gave up {}/{}: {reason}", task.domain, task.name));
        }
    };
    let report = run_pool(guests, plan.todo, runner, &options.pool, &mut on_event).await;
    watch.end(&tally);
    if budget.is_set() {
        let not_started = if stopped.is_some() { report.not_run.clone() } else { Vec::new() };
        arena_results::ledger::BudgetRecord { budget, spent, stopped, not_started }.write(root)?;
    }
    let (summary, path) = write_report(root, &options.title)?;
    Ok(RunOutcome { todo, skipped, pool: report, summary, report: path })
}

#[cfg(test)]
mod tests;
