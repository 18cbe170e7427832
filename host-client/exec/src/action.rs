//! [`AgentAction`]: one thing an agent wants done, the unit the executor carries
//! out and trajectories record, and how an action space's steps become actions.

use serde::{Deserialize, Serialize};

use arena_actionspace::{Decision, Step};
use arena_shared::action::Action;

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
    /// pyautogui code (with `pyautogui` and `time` imported, as upstream's `python -c`),
    /// carried out as the executor's [`PyautoguiPolicy`](crate::PyautoguiPolicy) says:
    /// with its effects by default, or translated by the `pyautogui` action space.
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
