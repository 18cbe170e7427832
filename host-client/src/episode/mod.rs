//! One episode: reset the guest, set the task up, let the agent act until it
//! says DONE or FAIL or the step cap is reached, run the post-config, and
//! evaluate; with every step's observation, response, actions and timings
//! written to the task's result folder as it happens.
//!
//! The sequence is upstream's `lib_run_single.run_single_example` (waa-api.md
//! §b.5), over the typed `/v1` API:
//!
//! 1. `agent.reset(task)`; [`arena_setup::reset`] (close windows, wait for the
//!    guest's staged health, clear Downloads); the task's `config` steps. A
//!    failed reset or an aborted setup (a download that cannot be had) ends
//!    the episode as an infrastructure error.
//! 2. Up to `max_steps` times: observe (screenshot, accessibility tree,
//!    windows, clipboard), `agent.predict`, then each action in order:
//!    `DONE`/`FAIL` stop, `WAIT` pauses, anything else is carried out by
//!    [`arena_exec::execute_with`] and followed by the pause upstream calls
//!    `--sleep_after_execution`.
//! 3. The evaluator's `postconfig` steps, then [`arena_eval::evaluate`] with the
//!    agent's last control word.
//!
//! Errors are sorted three ways ([`EpisodeStatus`]): an unreachable guest (or a
//! failed reset, setup download or result write) is an infrastructure error
//! that says nothing about the agent, so no `result.txt` is written and the
//! run tries again; an agent that cannot answer (model endpoint down after
//! the retries, plan used up) ends the loop as an agent error and the task is
//! still evaluated; malformed model output and actions the desktop refuses are
//! recorded in the step and the episode goes on, as upstream does.
//!
//! It is not the pool of guests ([`crate::run`]) and writes nothing outside its
//! [`TaskDir`].

use std::sync::Arc;
use std::time::{Duration, Instant};

use serde_json::Value;

use arena_script::ComputerState;
use arena_shared::action::{Action, ActionBatch};
use arena_shared::observation::A11yQuery;

use crate::run::blame::{self, Phase};
use crate::run::pool::TaskRunner;
use arena_agents::observation::observe::{self, ObserveConfig, ScreenSource};
use arena_agents::observation::Observation;
use arena_agents::{Agent, AgentError, AgentFactory, LogValue, Prediction, StepLog};
use arena_client::cache::DownloadCache;
use arena_client::client::GuestClient;
use arena_eval::{EvalContext, LastAction};
use arena_exec::AgentAction;
use arena_exec::{self as exec, ExecError, ExecOptions};
use arena_results::{
    timestamp_now, ActionRecord, ObservationKeys, ResetRecord, RunLayout, StepRecord, StepTimings, TaskDir,
};
use arena_setup::{Settle, SetupContext};
use arena_som::Marks;
use arena_task::Task;

use arena_results::{EpisodeResult, EpisodeStatus};

/// Upstream's `--max_steps`.
pub const DEFAULT_MAX_STEPS: u32 = 15;
/// Upstream's `--sleep_after_execution`.
pub const DEFAULT_SLEEP_AFTER_ACTION: Duration = Duration::from_secs(3);

/// How an episode runs.
#[derive(Debug, Clone)]
pub struct EpisodeConfig {
    /// Steps the agent gets (upstream: 15).
    pub max_steps: u32,
    /// Pause after each action, DONE and FAIL included (upstream's
    /// `--sleep_after_execution`, 3 s in its scripts; 0 against the stub). `WAIT`
    /// pauses twice this, as upstream's `env.step` sleeps for WAIT and then again.
    pub sleep_after_action: Duration,
    /// Pause after closing the windows in the reset (upstream: 5 s).
    pub pause_after_close_all: Duration,
    /// Pause after the task's setup, before the first observation (upstream: 5 s).
    pub pause_after_setup: Duration,
    /// Where the pauses above go (a test's fake clock records them).
    pub clock: Arc<dyn arena_setup::Clock>,
    /// Cancelled to stop the run (Ctrl-C, SIGTERM): the episode ends at once,
    /// mid-step if need be, as [`EpisodeStatus::Interrupted`], without evaluating.
    pub stop: tokio_util::sync::CancellationToken,
    /// The named options in force, recorded in `episode.json` and `summary.json`
    /// (`pauses`, `order`, ...), so two runs can be compared honestly.
    pub options: std::collections::BTreeMap<String, String>,
    /// Whether observations include the accessibility tree (upstream's `a11y_tree` observation).
    pub a11y: bool,
    /// Budget of one accessibility-tree walk.
    pub a11y_query: A11yQuery,
    /// How many times a failing model call is asked again within one step
    /// before the episode ends as an agent error.
    pub max_model_retries: u32,
    /// Longest one prediction may take, and all the actions of one step together
    /// (those not begun when it is up are not run).
    pub step_timeout: Duration,
    /// Pauses of setup steps.
    pub settle: Settle,
    /// How agent code runs (its sleeps and per-call delays).
    pub exec: ExecOptions,
    /// Where downloads are cached.
    pub cache: DownloadCache,
    /// The model's name, for the record.
    pub model: String,
    /// The VMs' own displays, when the run owns its VMs: the observation's
    /// screenshot when the guest's capture fails or is black.
    pub screen_source: Option<Arc<dyn ScreenSource>>,
    /// What the harness knows of the guests' surroundings, when the run owns its
    /// VMs: a guest whose QEMU died is the environment's failure (run::blame).
    pub guest_watch: Option<Arc<dyn blame::GuestWatch>>,
    /// The price of the run's model (`--prices`): each episode's tokens are priced into `cost_usd`.
    pub price: Option<arena_results::ledger::Price>,
    /// Told of each step as it begins (the run's progress display).
    pub watch: Option<Arc<dyn crate::run::watch::RunWatch>>,
}

impl EpisodeConfig {
    /// Upstream's timings, with downloads cached in `cache`.
    pub fn upstream(cache: DownloadCache) -> EpisodeConfig {
        EpisodeConfig {
            max_steps: DEFAULT_MAX_STEPS,
            sleep_after_action: DEFAULT_SLEEP_AFTER_ACTION,
            pause_after_close_all: arena_setup::AFTER_CLOSE_ALL,
            pause_after_setup: arena_setup::AFTER_SETUP,
            clock: Arc::new(arena_setup::RealClock),
            stop: tokio_util::sync::CancellationToken::new(),
            options: [("pauses".to_owned(), "upstream".to_owned())].into(),
            a11y: true,
            a11y_query: A11yQuery::default(),
            max_model_retries: 2,
            step_timeout: Duration::from_secs(600),
            settle: Settle::upstream(),
            exec: ExecOptions::default(),
            cache,
            model: String::new(),
            screen_source: None,
            guest_watch: None,
            price: None,
            watch: None,
        }
    }

    /// No pauses anywhere: for the stub guest, which needs none.
    pub fn instant(cache: DownloadCache) -> EpisodeConfig {
        EpisodeConfig {
            sleep_after_action: Duration::ZERO,
            pause_after_close_all: Duration::ZERO,
            pause_after_setup: Duration::ZERO,
            options: [("pauses".to_owned(), "fast".to_owned())].into(),
            settle: Settle::none(),
            exec: ExecOptions::instant(),
            ..EpisodeConfig::upstream(cache)
        }
    }
}

/// Runs one episode of `task` on the guest behind `client` and writes it into `out`.
/// Never fails: what went wrong is in the result's status.
pub async fn run_episode(
    client: &GuestClient,
    task: &Task,
    agent: &mut dyn Agent,
    config: &EpisodeConfig,
    out: &TaskDir,
) -> EpisodeResult {
    run_attempt(client, task, agent, config, out, 1, None).await
}

/// [`run_episode`] for try number `attempt` of the task, in the VM that `vm`
/// describes when the run owns its VMs (both recorded in `episode.json`).
pub async fn run_attempt(
    client: &GuestClient,
    task: &Task,
    agent: &mut dyn Agent,
    config: &EpisodeConfig,
    out: &TaskDir,
    attempt: u32,
    vm: Option<arena_results::VmStart>,
) -> EpisodeResult {
    let started = Instant::now();
    let mut ep = Episode {
        result: EpisodeResult {
            agent: agent.name().to_owned(),
            model: config.model.clone(),
            options: config.options.clone(),
            vm,
            ..EpisodeResult::start(task, client.base_url(), attempt, EpisodeStatus::Completed)
        },
        reset: None,
        steps: Vec::new(),
        observe: ObserveConfig {
            a11y: config.a11y,
            a11y_query: config.a11y_query.clone(),
            dom: agent.wants_dom(),
            screen_source: config.screen_source.clone(),
        },
        keys_down: Vec::new(),
        reached: None,
        boot_id: None,
    };
    if let Err(err) = out.prepare() {
        ep.result.status = EpisodeStatus::InfraError(format!("cannot prepare the result folder: {err}"));
        return ep.result;
    }
    if let Err(status) = ep.play(client, task, agent, config, out, started).await {
        ep.result.status = status;
    }
    ep.result.elapsed_ms = ms(started.elapsed());
    ep.result.timings = ep.steps.iter().map(|s| s.timings.clone()).collect();
    if let Some(price) = &config.price {
        ep.result.cost_usd = Some(ep.result.tokens.as_ref().map_or(0.0, |t| price.cost(t)));
    }
    if let Err(err) = out.finish(&ep.result, ep.reset.as_ref(), &ep.steps) {
        tracing::error!(task = %task.name, error = %err, "cannot write the episode's results");
        ep.result.status = EpisodeStatus::InfraError(format!("cannot write the results: {err}"));
        ep.result.score = 0.0;
    }
    tracing::info!(
        task = %task.name,
        score = ep.result.score,
        status = ep.result.status.kind(),
        steps = ep.result.steps,
        elapsed_ms = ep.result.elapsed_ms,
        "episode finished"
    );
    ep.result
}

/// The episode being played: its record and its trajectory so far.
struct Episode {
    result: EpisodeResult,
    reset: Option<ResetRecord>,
    steps: Vec<StepRecord>,
    /// What each observation reads (the DOM when the agent wants it).
    observe: ObserveConfig,
    /// Every key an action pressed with `keyDown`: let go when the episode ends.
    keys_down: Vec<String>,
    /// The step in which an action of the agent first reached the guest: from then
    /// on a guest that stops answering or restarts is the agent's doing (run::blame).
    reached: Option<u32>,
    /// The guest's boot id after the setup, to tell a restart from a guest that answers.
    boot_id: Option<String>,
}

/// An observation and the file its screenshot was written to.
struct Seen {
    obs: Observation,
    file: String,
    /// `accessibility_tree-step_<i>_<time>.txt`: the tree in upstream's XML.
    tree_file: String,
}

/// What every part of one episode's play reads: the guest, the task, the run's
/// configuration, the task's result folder and the guest's screen.
struct Play<'a> {
    client: &'a GuestClient,
    task: &'a Task,
    config: &'a EpisodeConfig,
    out: &'a TaskDir,
    screen: &'a arena_shared::observation::ScreenInfo,
}

/// What the actions of one step did so far.
#[derive(Default)]
struct Acted {
    /// A decision ended the episode.
    stop: bool,
    /// The step's last control word.
    last: Option<LastAction>,
    /// Time spent in upstream's pauses.
    pause: Duration,
    /// Time spent observing after each action.
    observing: Duration,
    /// When the step's time is up (`step_timeout` after its actions began).
    deadline: Option<tokio::time::Instant>,
    /// An action that reaches the guest ran in this step (run::blame).
    ran: bool,
}

/// Writes one of an agent's step logs as upstream's recorder names its files
/// (`<key>-step_<step - 1>_<time>.<ext>`); answers what the trajectory line holds.
///
/// Text and JSON (a model's answer, a prompt) are written within
/// [`arena_results::MAX_LOG_FILE`]: past it a text is cut with a note, and a JSON
/// value is kept as `{"not_recorded": note, "kept": <its strings cut and its items
/// counted as the step's record is>}`.
fn write_log(out: &TaskDir, step: u32, timestamp: &str, log: &StepLog) -> Result<Value, arena_results::ResultsError> {
    let name = |ext: &str| format!("{}-step_{}_{timestamp}.{ext}", arena_results::safe_component(&log.key), step - 1);
    let (file, bytes) = match &log.value {
        LogValue::Inline(value) => return Ok(value.clone()),
        LogValue::Text(text) => (name("txt"), arena_results::RecordBudget::log_file().text(text).into_bytes()),
        LogValue::Png(png) => (name("png"), png.clone()),
        LogValue::Image(pixels) => (name("png"), arena_client::frame::encode_png(pixels)),
        LogValue::Json(value) => {
            let mut bytes = serde_json::to_vec_pretty(value).unwrap_or_default();
            if bytes.len() > arena_results::MAX_LOG_FILE {
                let mut budget = arena_results::RecordBudget::log_file();
                let kept = budget.value(value).unwrap_or(Value::Null);
                let note = budget.note().unwrap_or_default();
                // Compact: indenting a deeply nested value could outgrow the budget.
                bytes =
                    serde_json::to_vec(&serde_json::json!({ NOT_RECORDED: note, "kept": kept })).unwrap_or_default();
            }
            (name("json"), bytes)
        }
    };
    out.write_file(&file, &bytes)?;
    Ok(Value::String(file))
}

/// The key of a step's note of what its record left out ([`arena_results::RecordBudget`]).
const NOT_RECORDED: &str = "not_recorded";

/// `actions` as the step's record keeps them: their strings within `budget`, and the
/// actions that no longer fit left out (counted in the budget's note).
fn recorded_actions(actions: &[AgentAction], budget: &mut arena_results::RecordBudget) -> Vec<AgentAction> {
    let mut kept = Vec::new();
    for (i, action) in actions.iter().enumerate() {
        if budget.exhausted() {
            budget.drop_items(actions.len() - i);
            break;
        }
        kept.push(match action {
            AgentAction::Computer(code) => AgentAction::Computer(budget.text(code).into()),
            AgentAction::Pyautogui(code) => AgentAction::Pyautogui(budget.text(code).into()),
            AgentAction::Clipboard(text) => AgentAction::Clipboard(budget.text(text)),
            AgentAction::Typed(typed) => {
                let mut kept_typed = Vec::new();
                for (j, one) in typed.iter().enumerate() {
                    // An action that came back whole (its strings cut, none of its fields left out).
                    let bounded = serde_json::to_value(one)
                        .ok()
                        .and_then(|value| budget.value(&value))
                        .and_then(|value| serde_json::from_value(value).ok());
                    match bounded {
                        Some(one) => kept_typed.push(one),
                        None => {
                            budget.drop_items(typed.len() - j);
                            break;
                        }
                    }
                }
                AgentAction::Typed(kept_typed)
            }
            AgentAction::Wait | AgentAction::Done | AgentAction::Fail => action.clone(),
        });
    }
    kept
}

/// The action as upstream's trajectory logs it: the code, or the control word.
fn upstream_action(action: &AgentAction) -> String {
    match action {
        AgentAction::Computer(code) | AgentAction::Pyautogui(code) => code.as_str().to_owned(),
        AgentAction::Wait
        | AgentAction::Done
        | AgentAction::Fail
        | AgentAction::Typed(_)
        | AgentAction::Clipboard(_) => action.summary(),
    }
}

/// The observation keys of an upstream trajectory line.
fn observed(seen: &Seen) -> ObservationKeys {
    ObservationKeys {
        screenshot: seen.file.clone(),
        accessibility_tree: seen.tree_file.clone(),
        instruction: seen.obs.instruction.clone(),
        window_title: seen.obs.foreground_title.clone(),
        window_names_str: seen.obs.window_titles.join("\n"),
        computer_clipboard: seen.obs.tracked_clipboard.clone().unwrap_or_default(),
    }
}

fn ms(d: Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

/// Ends the episode as [`EpisodeStatus::Interrupted`] when the run is stopping.
fn interrupted(config: &EpisodeConfig, at: &str) -> Result<(), EpisodeStatus> {
    if config.stop.is_cancelled() {
        return Err(EpisodeStatus::Interrupted(format!("the run was stopped {at}; nothing was evaluated")));
    }
    Ok(())
}

fn infra(what: &str, err: impl std::fmt::Display) -> EpisodeStatus {
    EpisodeStatus::InfraError(format!("{what}: {err}"))
}

fn phase(report: &arena_setup::StepReport, phase: &str) -> Value {
    let mut value = serde_json::to_value(report).unwrap_or(Value::Null);
    if let Value::Object(map) = &mut value {
        map.insert("phase".into(), Value::String(phase.to_owned()));
    }
    value
}

impl Episode {
    /// Lets go of every key an action pressed with `keyDown`, after the evaluation
    /// (so the score is the one upstream gives) and before the next task, which
    /// upstream would start with the key still down. Reported as a `teardown` entry
    /// of the episode's setup reports; a failure is logged, never fatal.
    async fn release_keys(&mut self, client: &GuestClient) {
        if self.keys_down.is_empty() {
            return;
        }
        let started = Instant::now();
        let actions: Vec<Action> = self.keys_down.iter().rev().map(|key| Action::KeyUp { key: key.clone() }).collect();
        let names = self.keys_down.join(", ");
        let (ok, detail) = match client.act(&ActionBatch { actions }).await {
            Ok(_) => (true, format!("released {names}")),
            Err(err) => {
                tracing::warn!(error = %err, keys = %names, "releasing the keys the agent pressed failed");
                (false, format!("releasing {names} failed: {err}"))
            }
        };
        let report =
            arena_setup::StepReport { kind: "release_held_keys", ok, detail, elapsed_ms: ms(started.elapsed()) };
        self.result.setup.push(phase(&report, "teardown"));
    }

    /// Why the guest is not the one the episode started on, if it is not: it does
    /// not answer (one question within [`blame::DECIDING_CHECK`]), or its boot id
    /// changed since the setup (it restarted).
    async fn guest_gone(&self, client: &GuestClient) -> Option<String> {
        match client.health_once(blame::DECIDING_CHECK).await {
            Err(err) => Some(err.to_string()),
            Ok(report) => blame::restarted(self.boot_id.as_deref(), report.boot_id.as_deref()),
        }
    }

    /// The status of a guest found gone (`why`) at `when` (run::blame): the agent's
    /// failure once an action of its reached the guest, unless the harness knows an
    /// outside cause; before that, the environment's.
    async fn gone(&self, play: &Play<'_>, when: &str, why: String) -> EpisodeStatus {
        match self.reached {
            Some(first) => {
                let watch = play.config.guest_watch.as_deref();
                blame::after_action_unless_outside(watch, play.client.base_url(), first, when, why).await
            }
            None => EpisodeStatus::InfraError(format!("the guest stopped answering {when}: {why}")),
        }
    }

    /// Steps 1 to 3 of the module documentation. `Err` is an infrastructure
    /// error that ends the episode where it happened.
    async fn play(
        &mut self,
        client: &GuestClient,
        task: &Task,
        agent: &mut dyn Agent,
        config: &EpisodeConfig,
        out: &TaskDir,
        started: Instant,
    ) -> Result<(), EpisodeStatus> {
        agent.keep_files_in(out.path());
        agent.reset(task).await;
        arena_setup::reset(client, config.pause_after_close_all, config.clock.as_ref())
            .await
            .map_err(|err| infra("reset", err))?;
        let ctx = SetupContext {
            client: client.clone(),
            cache: config.cache.clone(),
            host_dir: out.setup_dir(),
            settle: config.settle,
            activate_non_strict: config.options.get("activate_non_strict").is_some_and(|v| v == "on"),
        };
        let reports = arena_setup::run_steps(&ctx, &task.config).await;
        self.result.setup.extend(reports.iter().map(|r| phase(r, "config")));
        if arena_setup::aborted(&reports) {
            let detail = reports.last().map(|r| r.detail.clone()).unwrap_or_default();
            return Err(EpisodeStatus::InfraError(format!("setup {detail}")));
        }
        config.clock.sleep(config.pause_after_setup, "after the setup").await;
        self.result.setup_ms = ms(started.elapsed());
        interrupted(config, "after the setup")?;

        // The guest's boot id now, so that a restart later in the episode shows.
        self.boot_id = client.health_once(blame::DECIDING_CHECK).await.ok().and_then(|h| h.boot_id);
        let screen = client.screen().await.map_err(|err| infra("reading the screen", err))?;
        let play = Play { client, task, config, out, screen: &screen };
        let mut computer = ComputerState::for_screen(
            i32::try_from(screen.physical_width).unwrap_or(i32::MAX),
            i32::try_from(screen.physical_height).unwrap_or(i32::MAX),
        );
        // The observation after the reset: upstream's step-0 line.
        let timestamp = timestamp_now();
        let mut seen = self.observe_into(&play, 1, None, &timestamp, computer.clipboard_content.clone()).await?;
        self.reset =
            Some(ResetRecord { step_num: 0, action_timestamp: timestamp, action: None, observation: observed(&seen) });
        let mut last: Option<LastAction> = None;
        for step in 1..=config.max_steps {
            interrupted(config, "between steps")?;
            if let Some(watch) = &config.watch {
                watch.step(client.base_url(), task, step);
            }
            // A stop does not wait for the step: whatever the agent answered,
            // its prediction and actions end here (the task runs again next time).
            let (stop, step_last, next) = tokio::select! {
                biased;
                () = config.stop.cancelled() => return Err(EpisodeStatus::Interrupted(format!(
                    "the run was stopped during step {step}; nothing was evaluated"
                ))),
                stepped = self.step(&play, agent, &mut computer, step, seen) => stepped?,
            };
            seen = next;
            if step_last.is_some() {
                last = step_last;
            }
            if stop {
                break;
            }
        }
        interrupted(config, "before the evaluation")?;
        self.result.last_action = match last {
            None => "none",
            Some(LastAction::Done) => "done",
            Some(LastAction::Fail) => "fail",
            Some(LastAction::Wait) => "wait",
            Some(LastAction::Other) => "other",
        }
        .to_owned();

        let eval_started = Instant::now();
        let post = arena_setup::run_steps(&ctx, &task.evaluator.postconfig).await;
        self.result.setup.extend(post.iter().map(|r| phase(r, "postconfig")));
        if arena_setup::aborted(&post) {
            let detail = post.last().map(|r| r.detail.clone()).unwrap_or_default();
            if let Some(why) = self.guest_gone(client).await {
                return Err(self.gone(&play, "in the postconfig", why).await);
            }
            return Err(EpisodeStatus::InfraError(format!("postconfig {detail}")));
        }
        let ectx = EvalContext {
            client: client.clone(),
            cache: config.cache.clone(),
            work_dir: out.eval_dir(),
            task_dir: task.path.parent().map(std::path::Path::to_path_buf),
        };
        let outcome = arena_eval::evaluate(&ectx, &task.evaluator, last.as_ref()).await;
        self.result.eval_ms = ms(eval_started.elapsed());
        self.release_keys(client).await;
        self.result.eval = serde_json::to_value(&outcome).unwrap_or(Value::Null);
        // A getter that failed because the guest went away scored 0 for the
        // wrong reason: find out before trusting the score.
        if outcome.error.is_some() {
            if let Some(why) = self.guest_gone(client).await {
                return Err(self.gone(&play, "during the evaluation", why).await);
            }
        }
        if let Some(reason) = outcome.unfinished {
            return Err(EpisodeStatus::EvaluatorError(reason));
        }
        self.result.score = outcome.score;
        self.result.score_is_int = outcome.score_is_int;
        Ok(())
    }

    /// Observes with the one builder ([`observe::observe`]), writes the
    /// screenshot (the guest's bytes, not re-encoded) and the tree under
    /// upstream's names and answers all three.
    async fn observe_into(
        &mut self,
        play: &Play<'_>,
        for_step: u32,
        index: Option<u32>,
        timestamp: &str,
        tracked_clipboard: Option<String>,
    ) -> Result<Seen, EpisodeStatus> {
        let mut obs = observe::observe(play.client, &self.observe, play.screen, for_step, &play.task.instruction)
            .await
            .map_err(|err| EpisodeStatus::InfraError(err.to_string()))?;
        obs.tracked_clipboard = tracked_clipboard;
        let out = play.out;
        let file = out
            .write_screenshot(index, timestamp, &obs.screenshot.encoded)
            .map_err(|err| infra("writing the screenshot", err))?;
        // Upstream's recorder keeps each observation's tree as text, its XML, or
        // "No data available" when there was none.
        let step = index.map_or_else(|| "reset".to_owned(), |i| i.to_string());
        let tree_file = format!("accessibility_tree-step_{step}_{timestamp}.txt");
        let tree = obs.a11y.as_ref().map_or_else(
            || "No data available".to_owned(),
            |tree| arena_shared::a11y_xml::to_xml(tree, obs.foreground_id),
        );
        out.write_file(&tree_file, tree.as_bytes()).map_err(|err| infra("writing the accessibility tree", err))?;
        Ok(Seen { obs, file, tree_file })
    }

    /// One step as upstream's loop makes it: predict from the latest observation,
    /// then each action in turn ([`Episode::act`]), each followed by its pause and a
    /// fresh observation (upstream's `env.step`). Answers whether the episode stops
    /// here, the step's last control word and the latest observation.
    async fn step(
        &mut self,
        play: &Play<'_>,
        agent: &mut dyn Agent,
        computer: &mut ComputerState,
        step: u32,
        seen: Seen,
    ) -> Result<(bool, Option<LastAction>, Seen), EpisodeStatus> {
        let (config, out) = (play.config, play.out);
        let mut record = StepRecord {
            first: ActionRecord {
                step_num: step,
                action_timestamp: timestamp_now(),
                info: serde_json::json!({}),
                ..ActionRecord::default()
            },
            step,
            response: String::new(),
            actions: Vec::new(),
            ended: false,
            screenshot_file: seen.file.clone(),
            screenshot_source: seen.obs.screenshot_source.clone(),
            screen: Some(<[u32; 2]>::from(seen.obs.screen_size())),
            timings: StepTimings {
                observe_ms: seen.obs.timings.total_ms,
                observe: seen.obs.timings,
                ..StepTimings::default()
            },
            error: None,
            outcomes: Vec::new(),
            usage: None,
            more: Vec::new(),
            logs: std::collections::BTreeMap::new(),
        };
        self.result.steps = step;

        let Some(prediction) = self.predict_step(play, agent, &seen.obs, &mut record).await? else {
            return Ok((true, None, seen));
        };

        // The guest answered at the step's start; ask again before anything of the
        // agent's runs, so a failure from here on is decided by what it did.
        if blame::before_actions(&prediction.actions) {
            if let Some(why) = self.guest_gone(play.client).await {
                let status = match self.reached {
                    // An earlier step's action reached it: the agent's doing (a
                    // reboot it scheduled, a kill that landed late).
                    Some(_) => self.gone(play, &format!("while the agent decided step {step}"), why).await,
                    None => blame::guest_failure(Phase::Deciding, step, "asked before the actions", why),
                };
                record.error = status.message().map(str::to_owned);
                record.ended = true;
                self.push(out, record)?;
                return Err(status);
            }
        }
        let t_act = Instant::now();
        // The step's actions share one deadline, not one each.
        let deadline = tokio::time::Instant::now() + config.step_timeout;
        let mut acted = Acted { deadline: Some(deadline), ..Acted::default() };
        let mut latest = seen;
        for (k, action) in prediction.actions.iter().enumerate() {
            if tokio::time::Instant::now() >= deadline {
                let message = format!(
                    "actions {} to {} not run: the step's {} s were up",
                    k + 1,
                    prediction.actions.len(),
                    config.step_timeout.as_secs_f64()
                );
                record.timings.timeouts.push(message);
                break;
            }
            let mut line = if k == 0 {
                record.first.clone()
            } else {
                ActionRecord { step_num: step, action_timestamp: timestamp_now(), ..ActionRecord::default() }
            };
            // From the record's copy, bounded as the rest of the record is.
            line.action = record.actions.get(k).map_or_else(|| "[not recorded]".to_owned(), upstream_action);
            line.info = match action {
                AgentAction::Done => serde_json::json!({"done": true}),
                AgentAction::Fail => serde_json::json!({"fail": true}),
                _ => serde_json::json!({}),
            };
            line.done = matches!(action, AgentAction::Done | AgentAction::Fail);
            if let Err(status) = self.act(play, &prediction, k, computer, &mut record, &mut acted).await {
                record.timings.act_ms = ms(t_act.elapsed());
                if !status.is_unfinished() {
                    record.error = status.message().map(str::to_owned);
                    record.ended = true;
                }
                self.push(out, record)?;
                return Err(status);
            }
            // Upstream observes after every action, DONE and FAIL included.
            let t_observe = Instant::now();
            let tracked = computer.clipboard_content.clone();
            let observed_after =
                self.observe_into(play, step + 1, Some(step - 1), &line.action_timestamp, tracked).await;
            latest = match observed_after {
                Ok(seen) => seen,
                // The guest went away after the step's actions ran: the agent's doing.
                Err(EpisodeStatus::InfraError(err)) if acted.ran => {
                    let watch = play.config.guest_watch.as_deref();
                    let status = blame::after_action_unless_outside(
                        watch,
                        play.client.base_url(),
                        step,
                        "observing after the action",
                        err,
                    )
                    .await;
                    record.error = status.message().map(str::to_owned);
                    record.ended = true;
                    record.timings.act_ms = ms(t_act.elapsed());
                    self.push(out, record)?;
                    return Err(status);
                }
                Err(status) => return Err(status),
            };
            acted.observing += t_observe.elapsed();
            line.observation = observed(&latest);
            if k == 0 {
                record.first = line;
            } else {
                record.more.push(line);
            }
            if acted.stop {
                break;
            }
        }
        if acted.ran && self.reached.is_none() {
            self.reached = Some(step);
        }
        record.timings.act_ms = ms(t_act.elapsed().saturating_sub(acted.pause).saturating_sub(acted.observing));
        record.timings.pause_ms = ms(acted.pause);
        record.ended = acted.stop || step == config.max_steps;
        self.push(out, record)?;
        Ok((acted.stop, acted.last, latest))
    }

    /// Asks the agent for the step's prediction and records it (response, actions,
    /// logs, a malformed-output error). `Ok(None)`: the agent could not answer, the
    /// step is recorded and the episode ends as an agent error; `Err`: the guest
    /// went away or the model stayed down (the task is left unfinished).
    async fn predict_step(
        &mut self,
        play: &Play<'_>,
        agent: &mut dyn Agent,
        obs: &Observation,
        record: &mut StepRecord,
    ) -> Result<Option<Prediction>, EpisodeStatus> {
        let (config, out) = (play.config, play.out);
        let t_predict = Instant::now();
        let prediction = predict(agent, obs, config, &mut record.timings).await;
        record.timings.predict_ms = ms(t_predict.elapsed());
        // The cost ledger: what the agent reported in its answer, else what its model client counted.
        record.usage = prediction.as_ref().ok().and_then(|p| p.usage).or_else(|| agent.take_usage());
        if let Some(usage) = &record.usage {
            self.result.tokens.get_or_insert_with(Default::default).add(usage);
        }
        let prediction = match prediction {
            Ok(p) => p,
            Err(AgentError::Guest(err)) => {
                self.push(out, record.clone())?;
                return Err(infra("the guest stopped answering", err));
            }
            Err(err @ (AgentError::Model { .. } | AgentError::Refused { .. })) => {
                // Upstream's `predict` raises when the model cannot be had: the
                // task is left unfinished, not scored.
                record.error = Some(err.to_string());
                record.ended = true;
                self.push(out, record.clone())?;
                return Err(EpisodeStatus::ModelError(err.to_string()));
            }
            Err(err) => {
                let message = err.to_string();
                record.error = Some(message.clone());
                record.ended = true;
                self.result.status = EpisodeStatus::AgentError(message);
                self.push(out, record.clone())?;
                return Ok(None);
            }
        };
        record.timings.predict = prediction.timings;
        // The record keeps a bounded share of what the agent sent (the actions run whole).
        let mut budget = arena_results::RecordBudget::default();
        record.response = budget.text(&prediction.response);
        record.actions = recorded_actions(&prediction.actions, &mut budget);
        let timestamp = record.first.action_timestamp.clone();
        for log in &prediction.logs {
            let value = match &log.value {
                LogValue::Inline(value) => match budget.value(value) {
                    Some(value) => value,
                    None => continue,
                },
                _ => {
                    write_log(out, record.step, &timestamp, log).map_err(|err| infra("writing the step's logs", err))?
                }
            };
            record.logs.insert(budget.text(&log.key), value);
        }
        if let Some(raw) = &prediction.raw_error {
            // The step is spent; the agent keeps the error to tell the model next time.
            record.error = Some(budget.text(raw));
            self.result.action_errors += 1;
        }
        if let Some(note) = budget.note() {
            record.logs.insert(NOT_RECORDED.into(), Value::String(note));
        }
        Ok(Some(prediction))
    }

    /// Action `k` of `prediction`: a decision stops or pauses, anything else is
    /// carried out through the action port, then upstream's pause. `Err`: the guest
    /// went away (an infrastructure error).
    async fn act(
        &mut self,
        play: &Play<'_>,
        prediction: &Prediction,
        k: usize,
        computer: &mut ComputerState,
        record: &mut StepRecord,
        acted: &mut Acted,
    ) -> Result<(), EpisodeStatus> {
        let config = play.config;
        let action = &prediction.actions[k];
        match action {
            AgentAction::Done | AgentAction::Fail => {
                let fail = *action == AgentAction::Fail;
                acted.last = Some(if fail { LastAction::Fail } else { LastAction::Done });
                acted.stop = true;
                acted.pause += config.sleep_after_action;
                config.clock.sleep(config.sleep_after_action, "after DONE or FAIL").await;
            }
            AgentAction::Wait => {
                // Upstream's env.step sleeps for WAIT, then again as after any action.
                acted.last = Some(LastAction::Wait);
                acted.pause += config.sleep_after_action * 2;
                config.clock.sleep(config.sleep_after_action * 2, "for WAIT").await;
            }
            _ => {
                acted.last = Some(LastAction::Other);
                // An agent that named its coordinate convention has its code translated in it.
                let options = match prediction.coords {
                    Some(coords) if coords != config.exec.coords => {
                        std::borrow::Cow::Owned(ExecOptions { coords, ..config.exec.clone() })
                    }
                    _ => std::borrow::Cow::Borrowed(&config.exec),
                };
                acted.ran = true;
                let run = exec::execute_with(
                    play.client,
                    action,
                    prediction.marks.as_ref().map(Marks::boxes),
                    computer,
                    &options,
                );
                let deadline = acted.deadline.unwrap_or_else(|| tokio::time::Instant::now() + config.step_timeout);
                match tokio::time::timeout_at(deadline, run).await {
                    Ok(Ok(outcome)) => {
                        if let Some(error) = &outcome.error {
                            tracing::debug!(task = %play.task.name, step = record.step, error, "an action failed");
                            self.result.action_errors += 1;
                        }
                        for key in &outcome.keys_down {
                            if !self.keys_down.contains(key) {
                                self.keys_down.push(key.clone());
                            }
                        }
                        record.outcomes.push(serde_json::to_value(&outcome).unwrap_or(Value::Null));
                    }
                    // The guest answered right before this step's actions: whatever
                    // became of it in one of them is the agent's (run::blame).
                    Ok(Err(ExecError::Guest(err))) => {
                        let what = format!("action {}", k + 1);
                        let watch = config.guest_watch.as_deref();
                        let url = play.client.base_url();
                        return Err(blame::after_action_unless_outside(watch, url, record.step, &what, err).await);
                    }
                    Ok(Err(err)) => {
                        self.result.action_errors += 1;
                        record.outcomes.push(serde_json::json!({ "error": err.to_string() }));
                    }
                    Err(_) => {
                        self.result.action_errors += 1;
                        let message =
                            format!("the action outlasted the step's {} s", config.step_timeout.as_secs_f64());
                        record.timings.timeouts.push(format!("action {}: {message}", k + 1));
                        record.outcomes.push(serde_json::json!({ "error": message }));
                    }
                }
                acted.pause += config.sleep_after_action;
                config.clock.sleep(config.sleep_after_action, "after an action").await;
            }
        }
        Ok(())
    }

    /// Records a step and rewrites the trajectory, so a crash keeps every finished step.
    fn push(&mut self, out: &TaskDir, record: StepRecord) -> Result<(), EpisodeStatus> {
        self.steps.push(record);
        out.write_trajectory(self.reset.as_ref(), &self.steps).map_err(|err| infra("writing the trajectory", err))
    }
}

/// Asks the agent, retrying model failures within the step as configured;
/// the retries and timeouts go into the step's `timings`.
async fn predict(
    agent: &mut dyn Agent,
    obs: &Observation,
    config: &EpisodeConfig,
    timings: &mut StepTimings,
) -> Result<Prediction, AgentError> {
    let mut tries = 0;
    loop {
        tries += 1;
        let answer = match tokio::time::timeout(config.step_timeout, agent.predict(obs)).await {
            Ok(answer) => answer,
            Err(_) => {
                let reason = format!("no answer within {} s", config.step_timeout.as_secs());
                timings.timeouts.push(format!("predict: {reason}"));
                Err(AgentError::Model { endpoint: agent.name().to_owned(), reason })
            }
        };
        match answer {
            Err(AgentError::Model { endpoint, reason }) if tries <= config.max_model_retries => {
                tracing::warn!(%endpoint, %reason, tries, "the model failed; asking again");
                timings.predict_retries += 1;
                tokio::time::sleep(Duration::from_millis(500 * u64::from(tries))).await;
            }
            other => return other,
        }
    }
}

/// The [`TaskRunner`] of real runs: a fresh agent per episode, results in the run's layout.
#[derive(Clone)]
pub struct EpisodeRunner {
    pub layout: RunLayout,
    pub config: EpisodeConfig,
    pub agents: AgentFactory,
}

impl std::fmt::Debug for EpisodeRunner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EpisodeRunner")
            .field("layout", &self.layout)
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

#[async_trait::async_trait]
impl TaskRunner for EpisodeRunner {
    async fn run(
        &self,
        guest: &GuestClient,
        task: &Task,
        attempt: u32,
        vm: Option<arena_results::VmStart>,
    ) -> EpisodeResult {
        let out = self.layout.task_dir(task);
        match (self.agents)() {
            Ok(mut agent) => run_attempt(guest, task, agent.as_mut(), &self.config, &out, attempt, vm).await,
            Err(err) => {
                // Without an agent nothing can run anywhere: record it as the
                // agent's failure so the run does not retry it on every guest.
                let status = EpisodeStatus::ModelError(format!("cannot create the agent: {err}"));
                let result = EpisodeResult {
                    model: self.config.model.clone(),
                    options: self.config.options.clone(),
                    vm: vm.clone(),
                    ..EpisodeResult::start(task, guest.base_url(), attempt, status)
                };
                if let Err(err) = out.prepare().and_then(|()| out.finish(&result, None, &[])) {
                    tracing::error!(task = %task.name, error = %err, "cannot write the episode's results");
                }
                result
            }
        }
    }
}

#[cfg(test)]
mod tests;
