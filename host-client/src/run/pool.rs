//! Spreading tasks over a pool of guests: one task per guest at a time, with
//! infrastructure failures retried elsewhere and dead guests set aside.
//!
//! One dispatcher loop owns the queue of pending tasks and the list of free
//! guests; every episode runs in its own tokio task and hands its guest back
//! when it ends. When an episode ends in an infrastructure error the guest is
//! asked for its health at once: a guest that answers goes back to the pool,
//! one that does not is taken out and probed in the background until it
//! answers again. The task is queued again (at the front, and preferably for
//! a guest it has not failed on) until it has had `max_attempts` tries.
//!
//! It is not the episode: what a task run does is a [`TaskRunner`]'s business,
//! which keeps this module testable without guests that run episodes.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::task::JoinSet;
use tokio_util::sync::CancellationToken;

use arena_client::client::GuestClient;
use arena_results::VmStart;
use arena_results::{EpisodeResult, EpisodeStatus};
use arena_task::Task;

/// Runs one task on one guest. Implemented by the episode runner; tests use fakes.
#[async_trait::async_trait]
pub trait TaskRunner: Send + Sync {
    /// Runs `task` on `guest` (try number `attempt`, from 1; in the VM `vm`
    /// describes when the run owns its VMs) and returns what happened. It never
    /// fails: an unreachable guest is an [`EpisodeStatus::InfraError`] result.
    async fn run(&self, guest: &GuestClient, task: &Task, attempt: u32, vm: Option<VmStart>) -> EpisodeResult;
}

/// What the pool does to its guests besides running tasks on them, when it owns
/// them (the VMs of `arena run --vm-image`).
#[async_trait::async_trait]
pub trait GuestLifecycle: Send + Sync {
    /// Before a task on `guest`: restore its snapshot when the reset policy says
    /// so. An error makes this try an infrastructure error and the guest is revived.
    async fn before_task(&self, guest: &GuestClient) -> Result<Option<VmStart>, String>;
    /// A guest that stopped answering: kill and rebuild it. `Ok` once it answers.
    async fn revive(&self, guest: &GuestClient) -> Result<(), String>;
}

impl std::fmt::Debug for dyn GuestLifecycle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("GuestLifecycle")
    }
}

/// How the pool behaves.
#[derive(Debug, Clone)]
pub struct PoolConfig {
    /// Tries per task, the first included (so 3 is two retries).
    pub max_attempts: u32,
    /// How often a guest taken out of the pool is asked for its health.
    pub probe_interval: Duration,
    /// Deadline of one health question.
    pub health_timeout: Duration,
    /// How long the run waits with tasks left and no guest in the pool before
    /// it gives the remaining tasks up.
    pub no_guest_timeout: Duration,
    /// Cancelled to stop the run (the first Ctrl-C): no new task starts, the
    /// running episodes end at their next step, the rest are listed as not run.
    pub stop: CancellationToken,
    /// Cancelled when the run's budget is spent (`--max-cost`, `--max-total-tokens`):
    /// no new task starts, the running ones finish, the rest are listed as not run.
    pub no_new_tasks: CancellationToken,
    /// Set when the pool owns its guests: snapshots restored before tasks, dead
    /// guests rebuilt instead of waited for.
    pub lifecycle: Option<Arc<dyn GuestLifecycle>>,
}

impl Default for PoolConfig {
    fn default() -> PoolConfig {
        PoolConfig {
            max_attempts: 3,
            probe_interval: Duration::from_secs(5),
            health_timeout: Duration::from_secs(5),
            no_guest_timeout: Duration::from_secs(600),
            stop: CancellationToken::new(),
            no_new_tasks: CancellationToken::new(),
            lifecycle: None,
        }
    }
}

/// What happened, as it happens: for progress bars, logs and tests.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub enum PoolEvent<'a> {
    Started {
        task: &'a Task,
        guest: &'a str,
        attempt: u32,
    },
    Finished {
        task: &'a Task,
        result: &'a EpisodeResult,
    },
    /// The task will be tried again after an infrastructure error.
    Retrying {
        task: &'a Task,
        /// The guest the failed try ran on.
        guest: &'a str,
        attempt: u32,
        error: &'a str,
    },
    GuestDown {
        guest: &'a str,
        error: &'a str,
    },
    GuestBack {
        guest: &'a str,
    },
    /// The task was given up: out of tries, or no guest left.
    GaveUp {
        task: &'a Task,
        reason: &'a str,
    },
}

/// What a pool run did.
#[derive(Debug, Default)]
pub struct PoolReport {
    /// Episodes started, retries included.
    pub episodes: u32,
    /// The last result of every task that ran, in completion order.
    pub results: Vec<EpisodeResult>,
    /// Tasks that never started (no guest left, or the run was stopped), by `domain/name`.
    pub not_run: Vec<String>,
    /// Guests that were down when the run ended.
    pub guests_down: Vec<String>,
    /// Why the run ended with tasks left, when no healthy guest was left to run them.
    pub ended_early: Option<String>,
}

#[derive(Debug)]
struct Pending {
    task: Task,
    attempt: u32,
    /// Guests this task failed on, to try another first.
    avoid: Vec<String>,
}

/// One episode's end, as the dispatcher receives it.
#[derive(Debug)]
struct Finished {
    guest: GuestClient,
    item: Pending,
    result: EpisodeResult,
    /// False when the episode was an infrastructure error, or the agent's action
    /// ended the guest, and the guest did not answer afterwards.
    healthy: bool,
}

/// Runs `tasks` over `guests`, at most one task per guest at a time.
/// `on_event` is called from the dispatcher (never concurrently).
pub async fn run_pool(
    guests: Vec<GuestClient>,
    tasks: Vec<Task>,
    runner: Arc<dyn TaskRunner>,
    config: &PoolConfig,
    on_event: &mut (dyn FnMut(PoolEvent<'_>) + Send),
) -> PoolReport {
    let mut report = PoolReport::default();
    let mut pending: VecDeque<Pending> =
        tasks.into_iter().map(|task| Pending { task, attempt: 1, avoid: Vec::new() }).collect();
    let mut free: VecDeque<GuestClient> = guests.into();
    let mut running: JoinSet<Finished> = JoinSet::new();
    // Guests out of the pool; each probe task returns its guest once it answers.
    let mut probes: JoinSet<GuestClient> = JoinSet::new();
    let mut down: Vec<String> = Vec::new();
    let mut idle_since: Option<Instant> = None;

    loop {
        if config.stop.is_cancelled() || config.no_new_tasks.is_cancelled() {
            for item in pending.drain(..) {
                report.not_run.push(format!("{}/{}", item.task.domain, item.task.name));
            }
        }
        // Give every free guest a task.
        while !free.is_empty() && !pending.is_empty() {
            let Some(item) = pending.pop_front() else { break };
            let pick = free.iter().position(|g| !item.avoid.iter().any(|a| a == g.base_url())).unwrap_or(0);
            let Some(guest) = free.remove(pick) else { break };
            on_event(PoolEvent::Started { task: &item.task, guest: guest.base_url(), attempt: item.attempt });
            report.episodes += 1;
            let runner = Arc::clone(&runner);
            let health_timeout = config.health_timeout;
            let lifecycle = config.lifecycle.clone();
            running.spawn(async move {
                let vm = match &lifecycle {
                    Some(lifecycle) => lifecycle.before_task(&guest).await,
                    None => Ok(None),
                };
                let vm = match vm {
                    Ok(vm) => vm,
                    Err(error) => {
                        let result = infra_error(
                            &item.task,
                            guest.base_url(),
                            item.attempt,
                            // Only a run that owns its VMs prepares guests.
                            &format!("preparing the VM: {error}"),
                        );
                        return Finished { guest, item, result, healthy: false };
                    }
                };
                // The episode runs in a task of its own so that a panic in it
                // costs this one try, not the guest or the task record.
                let inner = {
                    let runner = Arc::clone(&runner);
                    let guest = guest.clone();
                    let task = item.task.clone();
                    let attempt = item.attempt;
                    tokio::spawn(async move { runner.run(&guest, &task, attempt, vm).await })
                };
                let result = match inner.await {
                    Ok(result) => result,
                    Err(err) => infra_error(
                        &item.task,
                        guest.base_url(),
                        item.attempt,
                        &format!("the episode task failed: {err}"),
                    ),
                };
                // After an infrastructure error, find out here (not in the
                // dispatcher, which must not wait) whether the guest still answers.
                // So also after an agent whose action ended its guest (run::blame):
                // the task is finished, but the guest must not get the next one.
                let suspect = result.status.is_infra() || super::blame::guest_lost_by_agent(&result.status);
                let healthy = !suspect || guest.with_timeout(health_timeout).health().await.is_ok();
                Finished { guest, item, result, healthy }
            });
        }
        if pending.is_empty() && running.is_empty() {
            break;
        }
        let waiting_for_guests = running.is_empty() && free.is_empty();
        if !waiting_for_guests {
            idle_since = None;
        }
        let idle_deadline = match (waiting_for_guests, idle_since) {
            (true, Some(since)) => config.no_guest_timeout.saturating_sub(since.elapsed()),
            (true, None) => {
                idle_since = Some(Instant::now());
                config.no_guest_timeout
            }
            // Unused: the branch is disabled; a year keeps the timer arithmetic far from overflow.
            (false, _) => Duration::from_secs(365 * 86_400),
        };
        tokio::select! {
            Some(joined) = running.join_next(), if !running.is_empty() => {
                let Ok(Finished { guest, item, result, healthy }) = joined else {
                    // The wrapper task cannot panic (it catches the inner one);
                    // if it was cancelled, nothing is left to record.
                    continue;
                };
                match &result.status {
                    EpisodeStatus::InfraError(error) => {
                        let error = error.clone();
                        if healthy {
                            free.push_back(guest.clone());
                        } else {
                            on_event(PoolEvent::GuestDown { guest: guest.base_url(), error: &error });
                            down.push(guest.base_url().to_owned());
                            probes.spawn(probe(guest.clone(), config.probe_interval, config.health_timeout, config.lifecycle.clone()));
                        }
                        if item.attempt < config.max_attempts {
                            on_event(PoolEvent::Retrying {
                                task: &item.task,
                                guest: guest.base_url(),
                                attempt: item.attempt + 1,
                                error: &error,
                            });
                            let mut avoid = item.avoid;
                            avoid.push(guest.base_url().to_owned());
                            pending.push_front(Pending { task: item.task, attempt: item.attempt + 1, avoid });
                        } else {
                            on_event(PoolEvent::Finished { task: &item.task, result: &result });
                            on_event(PoolEvent::GaveUp { task: &item.task, reason: &error });
                            report.results.push(result);
                        }
                    }
                    _ => {
                        on_event(PoolEvent::Finished { task: &item.task, result: &result });
                        report.results.push(result);
                        if healthy {
                            free.push_back(guest);
                        } else {
                            let error = "it stopped answering after the agent's action";
                            on_event(PoolEvent::GuestDown { guest: guest.base_url(), error });
                            down.push(guest.base_url().to_owned());
                            probes.spawn(probe(guest.clone(), config.probe_interval, config.health_timeout, config.lifecycle.clone()));
                        }
                    }
                }
            }
            Some(back) = probes.join_next(), if !probes.is_empty() => {
                if let Ok(guest) = back {
                    down.retain(|url| url != guest.base_url());
                    on_event(PoolEvent::GuestBack { guest: guest.base_url() });
                    free.push_back(guest);
                }
            }
            () = config.stop.cancelled(), if !config.stop.is_cancelled() => {}
            () = tokio::time::sleep(idle_deadline), if waiting_for_guests => {
                let reason = format!("no healthy guest left: none answered for {} s", config.no_guest_timeout.as_secs());
                report.ended_early = Some(reason.clone());
                for item in pending.drain(..) {
                    on_event(PoolEvent::GaveUp { task: &item.task, reason: &reason });
                    report.not_run.push(format!("{}/{}", item.task.domain, item.task.name));
                }
            }
        }
    }
    // Dropping the probes stops them: the run is over.
    probes.abort_all();
    report.guests_down = down;
    report
}

/// Asks `guest` for its health every `interval` until it answers, then returns
/// it. A guest the pool owns is rebuilt first, and again after each failure.
async fn probe(
    guest: GuestClient,
    interval: Duration,
    timeout: Duration,
    lifecycle: Option<Arc<dyn GuestLifecycle>>,
) -> GuestClient {
    let quick = guest.with_timeout(timeout);
    loop {
        if let Some(lifecycle) = &lifecycle {
            match lifecycle.revive(&guest).await {
                Ok(()) => return guest,
                Err(err) => tracing::warn!(guest = guest.base_url(), error = %err, "rebuilding the guest failed"),
            }
        }
        tokio::time::sleep(interval).await;
        match quick.health().await {
            Ok(_) => {
                tracing::info!(guest = guest.base_url(), "guest answers again");
                return guest;
            }
            Err(err) => tracing::debug!(guest = guest.base_url(), error = %err, "guest still down"),
        }
    }
}

/// The record of a try that never reached the agent (the guest could not be
/// prepared) or whose task panicked (a bug in this program, not the agent's
/// doing): an infrastructure error, so it is tried again.
fn infra_error(task: &Task, guest: &str, attempt: u32, message: &str) -> EpisodeResult {
    EpisodeResult::start(task, guest, attempt, EpisodeStatus::InfraError(message.to_owned()))
}
