//! The episode's two ports to the guest: what an agent sees ([`observe`], which
//! builds the [`Observation`]) and how what it wants done is carried out ([`exec`],
//! which executes an [`AgentAction`]).
//!
//! Every agent family meets the guest only here: it is handed an [`Observation`]
//! and answers [`AgentAction`]s; the episode loop (`crate::episode`) calls both
//! ports, and `arena act` the action port.
//!
//! It is not an agent (`crate::agent`) and does not decide when a step counts.
//!
//! # Layout
//!
//! - [`observe`]: [`observe::observe`], the one observation builder, its timings and
//!   the VM display that stands in for a failed screenshot ([`observe::ScreenSource`]).
//! - [`exec`]: [`exec::execute_with`], the [`arena_script::ScriptHost`] over a guest
//!   ([`exec::GuestHost`]) for `computer` code, and the runner of an action space's steps.

pub mod exec;
pub mod observe;

use serde::{Deserialize, Serialize};

use arena_actionspace::{Decision, Step};
use arena_client::browser::DomElement;
use arena_client::client::GuestClient;
use arena_client::frame::Frame;
use arena_shared::action::Action;
use arena_shared::observation::{A11yTree, ScreenInfo};

use crate::som::Marks;

pub use observe::{ObserveConfig, ObserveError, ObserveTimings};

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
    pub dom: Option<Vec<DomElement>>,
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
/// `{"kind": "typed", "actions": [...]}`, `{"kind": "clipboard", "text": "..."}`,
/// `{"kind": "wait"}`, `{"kind": "done"}`, `{"kind": "fail"}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(into = "ActionRecord", from = "ActionRecord")]
pub enum AgentAction {
    /// Navi `computer.*` code, run with `computer` bound (upstream's `/execute_windows`).
    Computer(String),
    /// pyautogui code, translated by the `pyautogui` action space (with `pyautogui`
    /// and `time` imported, as upstream's `python -c`) and carried out as its steps.
    Pyautogui(String),
    /// Typed input actions, sent as one batch.
    Typed(Vec<Action>),
    /// Text put on the clipboard (`PUT /v1/clipboard`): an action space's clipboard
    /// step (UI-TARS typing by paste, an OpenAI or Anthropic translation).
    Clipboard(String),
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
            AgentAction::Clipboard(text) => {
                format!("clipboard {}", serde_json::to_string(text).unwrap_or_else(|_| format!("{text:?}")))
            }
            AgentAction::Wait | AgentAction::Done | AgentAction::Fail => {
                self.decision().map(|d| d.word().to_owned()).unwrap_or_default()
            }
        }
    }

    /// The decision this action is, if it is one.
    pub fn decision(&self) -> Option<Decision> {
        match self {
            AgentAction::Wait => Some(Decision::Wait),
            AgentAction::Done => Some(Decision::Done),
            AgentAction::Fail => Some(Decision::Fail),
            _ => None,
        }
    }

    /// What an action space's steps ask the episode to do: runs of input actions
    /// become one typed batch, a clipboard write stays a typed clipboard action,
    /// and the decisions keep their meaning. Requests only the agent answers
    /// (screenshot, cursor position, zoom) do nothing here.
    pub fn from_steps(steps: &[Step]) -> Vec<AgentAction> {
        let mut out: Vec<AgentAction> = Vec::new();
        for step in steps {
            match step {
                Step::Act(action) => match out.last_mut() {
                    Some(AgentAction::Typed(batch)) => batch.push(action.clone()),
                    _ => out.push(AgentAction::Typed(vec![action.clone()])),
                },
                Step::SetClipboard(text) => out.push(AgentAction::Clipboard(text.clone())),
                Step::Wait => out.push(AgentAction::Wait),
                Step::Done => out.push(AgentAction::Done),
                Step::Fail => out.push(AgentAction::Fail),
                Step::Screenshot | Step::CursorPosition | Step::Zoom(_) => {}
            }
        }
        out
    }
}

impl From<Decision> for AgentAction {
    fn from(decision: Decision) -> AgentAction {
        match decision {
            Decision::Wait => AgentAction::Wait,
            Decision::Done => AgentAction::Done,
            Decision::Fail => AgentAction::Fail,
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
    Clipboard { text: String },
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
            AgentAction::Clipboard(text) => ActionRecord::Clipboard { text },
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
            ActionRecord::Clipboard { text } => AgentAction::Clipboard(text),
            ActionRecord::Wait => AgentAction::Wait,
            ActionRecord::Done => AgentAction::Done,
            ActionRecord::Fail => AgentAction::Fail,
        }
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
        check(AgentAction::Clipboard("it's".into()), r#"{"kind":"clipboard","text":"it's"}"#);
        check(AgentAction::Wait, r#"{"kind":"wait"}"#);
        check(AgentAction::Done, r#"{"kind":"done"}"#);
        check(AgentAction::Fail, r#"{"kind":"fail"}"#);
    }

    #[test]
    fn an_unknown_kind_is_an_error() {
        assert!(serde_json::from_str::<AgentAction>(r#"{"kind":"teleport"}"#).is_err());
    }

    #[test]
    fn steps_become_batches_a_typed_clipboard_write_and_decisions() {
        let click = Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 };
        let steps = [
            Step::Act(Action::MoveTo { x: 1, y: 2 }),
            Step::Act(click.clone()),
            Step::SetClipboard("it's".into()),
            Step::Screenshot,
            Step::Act(Action::Hotkey { keys: vec!["ctrl".into(), "v".into()] }),
            Step::Done,
        ];
        assert_eq!(
            AgentAction::from_steps(&steps),
            vec![
                AgentAction::Typed(vec![Action::MoveTo { x: 1, y: 2 }, click]),
                AgentAction::Clipboard("it's".into()),
                AgentAction::Typed(vec![Action::Hotkey { keys: vec!["ctrl".into(), "v".into()] }]),
                AgentAction::Done,
            ]
        );
        for decision in Decision::ALL {
            assert_eq!(AgentAction::from(decision).decision(), Some(decision));
            assert_eq!(AgentAction::from(decision).summary(), decision.word());
        }
    }
}
