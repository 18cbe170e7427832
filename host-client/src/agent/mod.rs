//! Agents: what decides the next action from an observation, and how an
//! agent's actions are carried out on a guest.
//!
//! Every agent implements [`Agent`]: it gets an [`Observation`] and answers a
//! [`Prediction`] holding [`AgentAction`]s. [`execute`] carries out one action:
//! typed actions go straight to `POST /v1/actions`; Navi `computer.*` code and
//! pyautogui code run here on the host, in the `arena_script`
//! interpreter, whose effects become typed `/v1` calls (see [`exec`]). The
//! guest therefore never runs agent code.
//!
//! It is not the episode loop (observe, predict, execute, evaluate: that is
//! `crate::episode`), and it does not decide when a step counts or when to stop.
//!
//! # Layout
//!
//! - [`exec`]: [`execute`] and the [`script::ScriptHost`](arena_script::ScriptHost) over a [`GuestClient`].
//! - [`parse`]: code blocks, `DONE`/`FAIL`/`WAIT` and the memory block in model output.
//! - [`navi`]: [`navi::NaviAgent`], Navi-style prompting of any OpenAI-compatible chat endpoint.
//! - [`scripted`]: [`scripted::ScriptedAgent`], which follows a plan file (oracle solutions, tests).
//! - [`replay`]: [`replay::ReplayAgent`], which repeats a recorded trajectory.
//! - [`cu`]: the computer-use agents (Anthropic's `computer` tool, OpenAI's Responses API, UI-TARS).
//! - [`external`]: [`external::ExternalAgent`], an agent in another program over the step protocol.

pub mod cu;
pub mod exec;
pub mod external;
pub mod llm;
pub mod navi;
pub mod observe;
pub mod parse;
pub mod replay;
pub mod scripted;
pub mod waa_prompts;

use serde::{Deserialize, Serialize};

use arena_shared::action::Action;
use arena_shared::observation::{A11yTree, ScreenInfo};

use crate::client::GuestClient;
use crate::error::ClientError;
use crate::som::Marks;
use crate::task::Task;

pub use exec::{execute, execute_with, ActionOutcome, ExecOptions};
pub use observe::{Frame, ObserveConfig, ObserveError, ObserveTimings};

/// What an agent sees at one step; built only by [`observe::observe`], the
/// harness's own builder (tests use it through [`Observation::capture`]).
#[derive(Debug, Clone)]
pub struct Observation {
    /// 1-based step number.
    pub step: u32,
    /// The task's instruction.
    pub instruction: String,
    /// The full-screen screenshot, decoded once ([`Frame`]: the pixels and the bytes as sent).
    pub screenshot: Frame,
    /// Where the screenshot came from when not from the guest (`vm-display: why`).
    pub screenshot_source: Option<String>,
    pub screen: ScreenInfo,
    /// The accessibility tree, when it could be read (its `truncated` flag says whether the budget cut it).
    pub a11y: Option<A11yTree>,
    /// The window names upstream lists ([`arena_shared::window_list::window_names`]).
    pub window_titles: Vec<String>,
    /// The foreground window's title, `Desktop` for Program Manager or an untitled
    /// window ([`arena_shared::window_list::foreground_title`]).
    pub foreground_title: String,
    /// The foreground window's id, when there is one.
    pub foreground_id: Option<u64>,
    /// The clipboard text the agent's `computer` object tracks (what its
    /// `copy_text` put there), which upstream's Navi is shown as
    /// `computer_clipboard`; `None` until its code copies something.
    pub tracked_clipboard: Option<String>,
    /// The clipboard's text, when it holds text.
    pub clipboard: Option<String>,
    /// The browser's front-page DOM elements in screen pixels (upstream Navi's
    /// `webparse` proposals), read only for an agent whose [`Agent::wants_dom`]
    /// is true; `None` otherwise or when no browser answers.
    pub dom: Option<Vec<crate::browser::DomElement>>,
    /// How long each part took.
    pub timings: ObserveTimings,
}

impl Observation {
    /// The screen's size in physical pixels, which the tree's rectangles use.
    pub fn screen_size(&self) -> (u32, u32) {
        (self.screen.physical_width, self.screen.physical_height)
    }

    /// The Set-of-Marks boxes of this observation, when it has a tree.
    pub fn marks(&self) -> Option<Marks> {
        self.a11y.as_ref().map(|tree| crate::som::marks_from_tree(tree, self.screen_size()))
    }

    /// The harness's observation ([`observe::observe`] with the default
    /// [`ObserveConfig`]: tree read, no DOM), after reading the screen.
    ///
    /// # Errors
    ///
    /// [`ObserveError`] when the screen, the screenshot or the window list cannot be read.
    pub async fn capture(client: &GuestClient, step: u32, instruction: &str) -> Result<Observation, ObserveError> {
        let screen = client
            .screen()
            .await
            .map_err(|err| ObserveError { what: "reading the screen", reason: err.to_string() })?;
        observe::observe(client, &ObserveConfig::default(), &screen, step, instruction).await
    }
}

/// One thing an agent wants done.
///
/// In trajectories it is written as JSON with a `kind` tag:
/// `{"kind": "computer", "code": "..."}`, `{"kind": "pyautogui", "code": "..."}`,
/// `{"kind": "typed", "actions": [...]}`, `{"kind": "wait"}`, `{"kind": "done"}`, `{"kind": "fail"}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(into = "ActionRecord", from = "ActionRecord")]
pub enum AgentAction {
    /// Navi `computer.*` code, run with `computer` bound (upstream's `/execute_windows`).
    Computer(String),
    /// pyautogui code, run with `pyautogui` and `time` imported (upstream's `python -c`).
    Pyautogui(String),
    /// Typed input actions, sent as one batch.
    Typed(Vec<Action>),
    /// The agent waits a step.
    Wait,
    /// The agent says the task is done.
    Done,
    /// The agent says the task cannot be done.
    Fail,
}

impl AgentAction {
    /// Whether this action ends the episode (`DONE` or `FAIL`).
    pub fn is_terminal(&self) -> bool {
        matches!(self, AgentAction::Done | AgentAction::Fail)
    }

    /// A one-line description for logs and prompts' action history.
    pub fn summary(&self) -> String {
        match self {
            AgentAction::Computer(code) | AgentAction::Pyautogui(code) => code.trim().replace('\n', "; "),
            AgentAction::Typed(actions) => serde_json::to_string(actions).unwrap_or_else(|_| format!("{actions:?}")),
            AgentAction::Wait => "WAIT".to_owned(),
            AgentAction::Done => "DONE".to_owned(),
            AgentAction::Fail => "FAIL".to_owned(),
        }
    }
}

/// The JSON shape of [`AgentAction`].
#[derive(Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum ActionRecord {
    Computer { code: String },
    Pyautogui { code: String },
    Typed { actions: Vec<Action> },
    Wait,
    Done,
    Fail,
}

impl From<AgentAction> for ActionRecord {
    fn from(a: AgentAction) -> ActionRecord {
        match a {
            AgentAction::Computer(code) => ActionRecord::Computer { code },
            AgentAction::Pyautogui(code) => ActionRecord::Pyautogui { code },
            AgentAction::Typed(actions) => ActionRecord::Typed { actions },
            AgentAction::Wait => ActionRecord::Wait,
            AgentAction::Done => ActionRecord::Done,
            AgentAction::Fail => ActionRecord::Fail,
        }
    }
}

impl From<ActionRecord> for AgentAction {
    fn from(r: ActionRecord) -> AgentAction {
        match r {
            ActionRecord::Computer { code } => AgentAction::Computer(code),
            ActionRecord::Pyautogui { code } => AgentAction::Pyautogui(code),
            ActionRecord::Typed { actions } => AgentAction::Typed(actions),
            ActionRecord::Wait => AgentAction::Wait,
            ActionRecord::Done => AgentAction::Done,
            ActionRecord::Fail => AgentAction::Fail,
        }
    }
}

/// An agent's answer for one step.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Prediction {
    /// The model's full reply (or a description of the plan step).
    pub response: String,
    /// What to do, in order. Empty when the output was malformed.
    pub actions: Vec<AgentAction>,
    /// The element boxes `move_id` resolves against, when the agent used Set-of-Marks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub marks: Option<Marks>,
    /// Why the output could not be used (no code block, a parse error). The
    /// step is spent and the agent is asked again; the agent keeps the error
    /// to tell the model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raw_error: Option<String>,
    /// What the agent wants kept about this step (the request it sent, the
    /// annotated image, the element list), written beside the trajectory as
    /// upstream's recorder writes an agent's `logs`.
    #[serde(skip)]
    pub logs: Vec<StepLog>,
    /// How long the agent's own parts took (Set-of-Marks, the model), for `traj.jsonl`.
    #[serde(skip)]
    pub timings: PredictTimings,
    /// What this prediction's pyautogui code measures coordinates in, when the agent
    /// said (an outside agent's `hello`); `None` is the run's `--coords`.
    #[serde(skip)]
    pub coords: Option<crate::actionspace::Coords>,
}

/// The parts of one prediction an agent times, in milliseconds; `None`: the agent has no such part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct PredictTimings {
    /// Making the Set-of-Marks (its sources and the annotated image).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub som_ms: Option<u64>,
    /// The model call, its own retries included.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_ms: Option<u64>,
    /// Tries the model client made (1 when the first answered; 0 without a model).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub model_tries: u32,
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}

/// One entry of an agent's per-step logs.
#[derive(Debug, Clone, PartialEq)]
pub struct StepLog {
    /// The key, which names the file (`<key>-step_<i>_<time>.<ext>`) and the trajectory field.
    pub key: String,
    pub value: LogValue,
}

/// A log entry's value: how it is kept.
#[derive(Debug, Clone, PartialEq)]
pub enum LogValue {
    /// A `.txt` file.
    Text(String),
    /// A `.png` file.
    Png(Vec<u8>),
    /// A `.png` file, encoded from these pixels when it is written.
    Image(std::sync::Arc<image::RgbaImage>),
    /// A `.json` file.
    Json(serde_json::Value),
    /// Inline in the trajectory line.
    Inline(serde_json::Value),
}

/// Why an agent could not answer, or an action could not be carried out.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AgentError {
    /// The model endpoint failed (unreachable, HTTP error, an answer that is not a chat completion).
    #[error("model endpoint {endpoint}: {reason}")]
    Model { endpoint: String, reason: String },
    /// A plan or trajectory file is missing or malformed.
    #[error("{path}: {reason}")]
    Plan { path: String, reason: String },
    /// A scripted or replayed agent has no steps left.
    #[error("{0}: no steps left")]
    Exhausted(String),
    /// The guest could not be reached while carrying out an action (an infrastructure error,
    /// not the agent's fault).
    #[error(transparent)]
    Guest(#[from] ClientError),
    /// The model refused to answer (`message.refusal` without content). Upstream's
    /// Navi cannot read such an answer, and the task is left unfinished, as for
    /// [`AgentError::Model`] but without asking again.
    #[error("model endpoint {endpoint} refused: {text}")]
    Refused { endpoint: String, text: String },
    /// The agent's configuration is unusable.
    #[error("agent configuration: {0}")]
    Config(String),
    /// The worker thread that ran a script died.
    #[error("the script worker failed: {0}")]
    Worker(String),
    /// An outside agent broke the step protocol, did not answer in time, gave
    /// up, or its process died (`--agent exec`, `--agent http`, `--agent mcp`).
    #[error("agent {agent}: {reason}")]
    External { agent: String, reason: String },
}

/// Something that picks actions from observations.
#[async_trait::async_trait]
pub trait Agent: Send {
    /// A short name for results and logs (`navi`, `scripted`, `replay`).
    fn name(&self) -> &str;

    /// Forgets the previous episode and prepares for `task`.
    async fn reset(&mut self, task: &Task);

    /// The next actions for `obs`.
    ///
    /// # Errors
    ///
    /// [`AgentError`] when no answer can be had at all (model endpoint down,
    /// plan missing or used up). Malformed model output is not an error: it is a
    /// [`Prediction`] with no actions and [`Prediction::raw_error`] set.
    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError>;

    /// Whether each observation should carry the browser's DOM elements
    /// ([`Observation::dom`]); reading them costs a DevTools round trip per step.
    fn wants_dom(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_shared::action::MouseButton;

    #[test]
    fn actions_round_trip_through_json_with_a_kind_tag() {
        let check = |action: AgentAction, json: &str| {
            assert_eq!(serde_json::to_string(&action).expect("serialize"), json);
            assert_eq!(serde_json::from_str::<AgentAction>(json).expect("deserialize"), action);
        };
        check(
            AgentAction::Computer("computer.mouse.move_id(id=3)".into()),
            r#"{"kind":"computer","code":"computer.mouse.move_id(id=3)"}"#,
        );
        check(AgentAction::Pyautogui("pyautogui.click()".into()), r#"{"kind":"pyautogui","code":"pyautogui.click()"}"#);
        check(
            AgentAction::Typed(vec![Action::Click { x: Some(1), y: Some(2), button: MouseButton::Left, count: 1 }]),
            r#"{"kind":"typed","actions":[{"type":"click","x":1,"y":2,"button":"left"}]}"#,
        );
        check(AgentAction::Wait, r#"{"kind":"wait"}"#);
        check(AgentAction::Done, r#"{"kind":"done"}"#);
        check(AgentAction::Fail, r#"{"kind":"fail"}"#);
    }

    #[test]
    fn an_unknown_kind_is_an_error() {
        assert!(serde_json::from_str::<AgentAction>(r#"{"kind":"teleport"}"#).is_err());
    }
}
