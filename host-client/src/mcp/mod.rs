//! The MCP endpoint of `arena run --agent mcp`: the agent drives. An MCP client
//! connects to `http://ADDR/mcp` (streamable HTTP, bearer token), calls
//! `get_task` to be given an episode, and then acts with the desktop tools
//! until `done`/`fail`, a closed session, or the step budget ends it; the
//! episode is evaluated as usual and the session is told the result.
//!
//! The pieces: the [`Hub`] the run shares (episodes offered to sessions, and
//! their results); [`McpAgent`], the [`Agent`] of each episode, whose every
//! `predict` waits for the session's next action tool call (that call is the
//! step, recorded in `traj.jsonl` as any agent's); [`McpRunner`], which runs
//! the episodes and hands each result to the hub; [`server`], the rmcp
//! handler and the HTTP server. The tools' names and arguments are
//! `arena_shared::mcp_tools`, which the guest's own MCP server shares.
//!
//! Reading tools (`screenshot`, `accessibility_tree`, `list_windows`) answer
//! from the step's observation, which the episode records, and spend no step;
//! every other tool is one step, so `--max-steps` counts actions as for any agent.
//!
//! A session that goes away (closed by its client, idle past the limit, or its
//! stream lost and not back within `arena_mcp::STREAM_GRACE`) lets its episode go
//! at once: one it had not acted in yet goes back to the hub for the next session
//! (nothing happened in it, so no agent gains a second try at anything), one it
//! had acted in ends as the agent's error. `--agent-timeout` bounds the wait for
//! a session to take an episode and for each tool call after it.

pub mod server;

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::{json, Value};
use tokio::sync::{mpsc, oneshot, Notify};

use crate::run::pool::TaskRunner;
use arena_agents::observation::Observation;
use arena_agents::{Agent, AgentError, LogValue, Prediction, StepLog};
use arena_client::client::GuestClient;
use arena_exec::AgentAction;
use arena_results::EpisodeResult;
use arena_task::Task;

/// What the session is told when its action tool call has been carried out.
#[derive(Debug, Clone)]
pub enum Reply {
    /// The action ran and the next observation is in; `steps_left` remain.
    Stepped { step: u32, steps_left: u32 },
    /// The episode is over (a decision, the budget, the deadline).
    Ended,
}

/// One action tool call on its way to the episode.
#[derive(Debug)]
pub struct Pending {
    pub tool: String,
    pub arguments: Value,
    pub action: AgentAction,
    pub reply: oneshot::Sender<Reply>,
}

/// What the reading tools answer from: the latest observation of an episode.
#[derive(Debug, Clone, Default)]
pub struct Snapshot {
    pub step: u32,
    pub png: Vec<u8>,
    pub xml: Option<String>,
    pub windows: Vec<String>,
    pub foreground: String,
    pub screen: (u32, u32),
}

/// An episode as a session sees it.
#[derive(Debug)]
pub struct EpisodeLink {
    /// `get_task`'s answer.
    pub task: Value,
    /// The task's name, which its result is filed under.
    pub task_name: String,
    pub max_steps: u32,
    pub calls: mpsc::Sender<Pending>,
    pub latest: Mutex<Snapshot>,
    pub ended: std::sync::atomic::AtomicBool,
    /// Cancelled when the session that took the episode goes away.
    pub abandoned: tokio_util::sync::CancellationToken,
}

impl EpisodeLink {
    /// `get_task`'s answer with the steps left now.
    pub fn task_info(&self) -> Value {
        let step = self.latest.lock().map(|s| s.step).unwrap_or(1);
        let mut task = self.task.clone();
        task["steps_left"] = json!(self.max_steps.saturating_sub(step.saturating_sub(1)));
        task
    }
}

/// What the run's sessions and episodes share.
#[derive(Debug, Default)]
pub struct Hub {
    offers: Mutex<VecDeque<Arc<EpisodeLink>>>,
    offered: Notify,
    results: Mutex<HashMap<String, Value>>,
    published: Notify,
    closed: std::sync::atomic::AtomicBool,
    watch: Mutex<Watching>,
}

/// Where the hub's notes go: the run's watch once it has one; until then they wait
/// (sessions may open before the run's first task).
#[derive(Debug, Default)]
struct Watching {
    watch: Option<Arc<dyn crate::run::watch::RunWatch>>,
    early: Vec<String>,
}

impl Hub {
    /// A hub for one run.
    pub fn new() -> Arc<Hub> {
        Arc::new(Hub::default())
    }

    /// Where the hub's notes go (the run's progress display).
    pub fn set_watch(&self, watch: Arc<dyn crate::run::watch::RunWatch>) {
        let early = match self.watch.lock() {
            Ok(mut slot) => {
                slot.watch = Some(Arc::clone(&watch));
                std::mem::take(&mut slot.early)
            }
            Err(_) => Vec::new(),
        };
        for line in early {
            watch.note(&line);
        }
    }

    /// A line for the console (and the log).
    pub fn note(&self, line: &str) {
        tracing::info!("{line}");
        let watch = match self.watch.lock() {
            Ok(mut slot) => match &slot.watch {
                Some(watch) => Some(Arc::clone(watch)),
                None => {
                    // Bounded: a flood of sessions before the run starts keeps its last notes.
                    if slot.early.len() >= 256 {
                        slot.early.remove(0);
                    }
                    slot.early.push(line.to_owned());
                    None
                }
            },
            Err(_) => None,
        };
        if let Some(watch) = watch {
            watch.note(line);
        }
    }

    /// What the session manager tells of sessions, as console notes.
    pub fn session_event(&self, event: arena_mcp::SessionEvent) {
        use arena_mcp::SessionEvent;
        let short = |id: &str| id.chars().take(8).collect::<String>();
        let line = match &event {
            SessionEvent::Opened(id) => format!("MCP session {} opened", short(id)),
            SessionEvent::StreamLost(id) => format!(
                "MCP session {} lost its stream; it closes in {} s unless its client comes back",
                short(id),
                arena_mcp::STREAM_GRACE.as_secs()
            ),
            SessionEvent::Closed { id, why } => format!("MCP session {} closed ({why})", short(id)),
        };
        self.note(&line);
    }

    fn offer(&self, link: Arc<EpisodeLink>) {
        if let Ok(mut offers) = self.offers.lock() {
            offers.push_back(link);
        }
        self.offered.notify_waiters();
    }

    /// The next episode no session has taken, waiting for one; `None` once the run is over.
    pub async fn take(&self) -> Option<Arc<EpisodeLink>> {
        loop {
            let notified = self.offered.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            {
                let mut offers = self.offers.lock().ok()?;
                while let Some(link) = offers.pop_front() {
                    if !link.ended.load(std::sync::atomic::Ordering::SeqCst) {
                        return Some(link);
                    }
                }
            }
            if self.closed.load(std::sync::atomic::Ordering::SeqCst) {
                return None;
            }
            notified.await;
        }
    }

    /// Files an episode's result for the session that played it.
    pub fn publish(&self, task_name: &str, result: &EpisodeResult) {
        let summary = json!({
            "task_id": result.task_id,
            "task_name": result.task_name,
            "score": result.score,
            "status": result.status.kind(),
            "error": result.status.message(),
            "steps": result.steps,
        });
        if let Ok(mut results) = self.results.lock() {
            results.insert(task_name.to_owned(), summary);
        }
        self.published.notify_waiters();
    }

    /// The result of `task_name`, waiting at most `within` for the evaluation.
    pub async fn result(&self, task_name: &str, within: Duration) -> Option<Value> {
        let wait = async {
            loop {
                let notified = self.published.notified();
                tokio::pin!(notified);
                notified.as_mut().enable();
                if let Some(result) = self.results.lock().ok().and_then(|mut r| r.remove(task_name)) {
                    return result;
                }
                notified.await;
            }
        };
        tokio::time::timeout(within, wait).await.ok()
    }

    /// The run is over: sessions waiting in `get_task` are told there is no task left.
    pub fn close(&self) {
        self.closed.store(true, std::sync::atomic::Ordering::SeqCst);
        self.offered.notify_waiters();
    }
}

/// The agent of one episode played over MCP.
#[derive(Debug)]
pub struct McpAgent {
    hub: Arc<Hub>,
    task: Option<Task>,
    link: Option<Arc<EpisodeLink>>,
    calls: Option<mpsc::Receiver<Pending>>,
    pending: Option<oneshot::Sender<Reply>>,
    max_steps: u32,
    /// Longest wait for a session, and for each tool call.
    timeout: Duration,
}

impl McpAgent {
    /// An agent for one episode of a run served by `hub`.
    pub fn new(hub: Arc<Hub>, max_steps: u32, timeout: Duration) -> McpAgent {
        McpAgent { hub, task: None, link: None, calls: None, pending: None, max_steps, timeout }
    }

    fn error(reason: impl Into<String>) -> AgentError {
        AgentError::External { agent: "mcp".into(), reason: reason.into() }
    }

    /// Offers this episode to the sessions, on a fresh link (a link is one session's).
    fn offer(&mut self, obs: &Observation) -> Result<(), AgentError> {
        let Some(task) = &self.task else { return Err(Self::error("no task")) };
        let (width, height) = obs.screen_size();
        let (tx, rx) = mpsc::channel(1);
        let link = Arc::new(EpisodeLink {
            task: json!({
                "instruction": task.instruction,
                "task_id": task.id,
                "domain": task.domain,
                "screen_width": width,
                "screen_height": height,
            }),
            task_name: task.name.clone(),
            max_steps: self.max_steps,
            calls: tx,
            latest: Mutex::new(snapshot(obs)),
            ended: Default::default(),
            abandoned: Default::default(),
        });
        self.hub.offer(Arc::clone(&link));
        self.link = Some(link);
        self.calls = Some(rx);
        Ok(())
    }
}

/// The reading tools' view of an observation: the one place MCP uses it.
fn snapshot(obs: &Observation) -> Snapshot {
    Snapshot {
        step: obs.step,
        png: obs.screenshot.encoded.to_vec(),
        xml: obs.a11y.as_ref().map(|tree| arena_shared::a11y_xml::to_xml(tree, obs.foreground_id)),
        windows: obs.window_titles.clone(),
        foreground: obs.foreground_title.clone(),
        screen: obs.screen_size(),
    }
}

impl Drop for McpAgent {
    fn drop(&mut self) {
        if let Some(link) = &self.link {
            link.ended.store(true, std::sync::atomic::Ordering::SeqCst);
        }
        if let Some(reply) = self.pending.take() {
            let _ = reply.send(Reply::Ended);
        }
    }
}

#[async_trait::async_trait]
impl Agent for McpAgent {
    fn name(&self) -> &str {
        "mcp"
    }

    async fn reset(&mut self, task: &Task) {
        self.task = Some(task.clone());
    }

    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError> {
        if self.link.is_none() {
            self.offer(obs)?;
        } else if let Some(link) = &self.link {
            if let Ok(mut latest) = link.latest.lock() {
                *latest = snapshot(obs);
            }
        }
        if let Some(reply) = self.pending.take() {
            let steps_left = self.max_steps.saturating_sub(obs.step.saturating_sub(1));
            let _ = reply.send(Reply::Stepped { step: obs.step.saturating_sub(1), steps_left });
        }
        let call = loop {
            let Some(link) = self.link.clone() else { return Err(Self::error("no episode link")) };
            let Some(calls) = self.calls.as_mut() else { return Err(Self::error("no session channel")) };
            let waited = tokio::select! {
                call = tokio::time::timeout(self.timeout, calls.recv()) => Some(call),
                () = link.abandoned.cancelled() => None,
            };
            match waited {
                Some(Ok(Some(call))) => break call,
                Some(Ok(None)) => return Err(Self::error("the MCP session closed")),
                Some(Err(_)) => {
                    return Err(Self::error(format!("no tool call within {} s", self.timeout.as_secs_f64())));
                }
                None => {
                    let task = format!("{}/{}", link.task["domain"].as_str().unwrap_or(""), link.task_name);
                    // Every tool call is one step: past step 1, a session has acted.
                    if obs.step > 1 {
                        self.hub.note(&format!(
                            "{task}: its MCP session went away after acting; the episode ends as the agent's error"
                        ));
                        return Err(Self::error("the MCP session that was playing this episode went away"));
                    }
                    self.hub.note(&format!(
                        "{task}: its MCP session went away before acting; the task goes back to the queue"
                    ));
                    link.ended.store(true, std::sync::atomic::Ordering::SeqCst);
                    self.offer(obs)?;
                }
            }
        };
        self.pending = Some(call.reply);
        let logs = vec![
            StepLog { key: "tool".into(), value: LogValue::Inline(Value::String(call.tool.clone())) },
            StepLog { key: "arguments".into(), value: LogValue::Inline(call.arguments.clone()) },
        ];
        Ok(Prediction {
            response: format!("{} {}", call.tool, call.arguments),
            actions: vec![call.action],
            marks: None,
            raw_error: None,
            logs,
            timings: Default::default(),
            coords: None,
            usage: None,
        })
    }
}

/// Runs episodes with an inner runner and files each result in the hub.
#[derive(Debug)]
pub struct McpRunner<R> {
    pub inner: R,
    pub hub: Arc<Hub>,
}

#[async_trait::async_trait]
impl<R: TaskRunner> TaskRunner for McpRunner<R> {
    async fn run(
        &self,
        guest: &GuestClient,
        task: &Task,
        attempt: u32,
        vm: Option<arena_results::VmStart>,
    ) -> EpisodeResult {
        let result = self.inner.run(guest, task, attempt, vm).await;
        self.hub.publish(&task.name, &result);
        result
    }
}

/// What an action tool call does in an episode: input as a typed action, code
/// as Navi's `computer` code when it uses the `computer` object, else as pyautogui
/// code (the one rule, `arena_script::dialect_of`, which Navi's replies and the
/// guest's MCP server follow too).
pub fn agent_action(call: arena_shared::mcp_tools::ToolCall) -> Option<AgentAction> {
    use arena_script::{dialect_of, Dialect};
    use arena_shared::mcp_tools::ToolCall;
    match call {
        ToolCall::Input(action) => Some(AgentAction::Typed(vec![action])),
        ToolCall::RunPython(code) => Some(match dialect_of(&code) {
            Dialect::Computer => AgentAction::Computer(code.into()),
            Dialect::Pyautogui => AgentAction::Pyautogui(code.into()),
        }),
        ToolCall::Done => Some(AgentAction::Done),
        ToolCall::Fail => Some(AgentAction::Fail),
        _ => None,
    }
}

/// A fresh random token for `--agent mcp` without `--mcp-token`.
pub fn generate_token() -> String {
    format!("{:032x}", rand::random::<u128>())
}

/// What [`Reply::Ended`] tells the session: the result once evaluated.
pub(crate) fn ended_text(result: Option<Value>) -> String {
    let mut answer = json!({
        "episode_ended": true,
        "next": "call get_task for the next task; it answers {\"task_id\": null} when the run has none left for this session",
    });
    match result {
        Some(result) => answer["result"] = result,
        None => answer["result"] = Value::Null,
    }
    answer.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_closed_hub_answers_no_task() {
        let hub = Hub::new();
        let waiting = tokio::spawn({
            let hub = Arc::clone(&hub);
            async move { hub.take().await.is_none() }
        });
        tokio::task::yield_now().await;
        hub.close();
        assert!(waiting.await.expect("join"));
    }
}
