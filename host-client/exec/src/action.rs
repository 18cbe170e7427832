//! [`AgentAction`]: one thing an agent wants done, the unit the executor carries
//! out and trajectories record, and how an action space's steps become actions.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use arena_actionspace::{Decision, Step};
use arena_script::ast::Program;
use arena_script::ParseError;
use arena_shared::action::Action;

/// Code an agent sent (Navi `computer.*` or pyautogui), with the program it parses
/// to once something has parsed it: an agent that checks its model's reply parses
/// the code there ([`Code::parse`]), and the executor then runs that program
/// ([`Code::program`]) instead of reading the text again. Two codes are equal when
/// their text is; the JSON of an action carries the text only.
#[derive(Clone)]
pub struct Code {
    source: String,
    parsed: Option<Arc<Program>>,
}

impl Code {
    /// Code not parsed yet.
    pub fn new(source: impl Into<String>) -> Code {
        Code { source: source.into(), parsed: None }
    }

    /// Code parsed now, its program kept.
    ///
    /// # Errors
    ///
    /// The interpreter's parser refused it.
    pub fn parse(source: impl Into<String>) -> Result<Code, ParseError> {
        let source = source.into();
        let program = arena_script::parse(&source)?;
        Ok(Code { source, parsed: Some(Arc::new(program)) })
    }

    /// The text.
    pub fn as_str(&self) -> &str {
        &self.source
    }

    /// The text, owned.
    pub fn into_string(self) -> String {
        self.source
    }

    /// Whether the program is kept (the code was parsed once already).
    pub fn is_parsed(&self) -> bool {
        self.parsed.is_some()
    }

    /// The program: a copy of the kept one, else the text parsed now.
    ///
    /// # Errors
    ///
    /// The interpreter's parser refused the text.
    pub fn program(&self) -> Result<Program, ParseError> {
        match &self.parsed {
            Some(program) => Ok(Program::clone(program)),
            None => arena_script::parse(&self.source),
        }
    }
}

impl std::ops::Deref for Code {
    type Target = str;
    fn deref(&self) -> &str {
        &self.source
    }
}

impl std::fmt::Debug for Code {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Debug::fmt(&self.source, f)
    }
}

impl PartialEq for Code {
    fn eq(&self, other: &Code) -> bool {
        self.source == other.source
    }
}

impl PartialEq<str> for Code {
    fn eq(&self, other: &str) -> bool {
        self.source == other
    }
}

impl PartialEq<&str> for Code {
    fn eq(&self, other: &&str) -> bool {
        self.source == *other
    }
}

impl From<String> for Code {
    fn from(source: String) -> Code {
        Code::new(source)
    }
}

impl From<&str> for Code {
    fn from(source: &str) -> Code {
        Code::new(source)
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
    Computer(Code),
    /// pyautogui code (with `pyautogui` and `time` imported, as upstream's `python -c`),
    /// carried out as the executor's [`PyautoguiPolicy`](crate::PyautoguiPolicy) says:
    /// with its effects by default, or translated by the `pyautogui` action space.
    Pyautogui(Code),
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
            AgentAction::Computer(code) => ActionRecord::Computer { code: code.into_string() },
            AgentAction::Pyautogui(code) => ActionRecord::Pyautogui { code: code.into_string() },
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
            ActionRecord::Computer { code } => AgentAction::Computer(code.into()),
            ActionRecord::Pyautogui { code } => AgentAction::Pyautogui(code.into()),
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
    fn parsed_code_keeps_its_program_and_compares_and_serializes_by_its_text() {
        let parsed = Code::parse("pyautogui.click(1, 2)").expect("parses");
        assert!(parsed.is_parsed());
        let text = Code::new("pyautogui.click(1, 2)");
        assert!(!text.is_parsed());
        assert_eq!(parsed, text);
        assert_eq!(parsed.program().expect("kept"), text.program().expect("parsed now"));
        let action = AgentAction::Pyautogui(parsed);
        let back: AgentAction = serde_json::from_str(&serde_json::to_string(&action).unwrap()).unwrap();
        assert_eq!(back, action, "the JSON carries the text");
        assert!(Code::parse("pyautogui.click(").is_err());
        assert!(Code::new("pyautogui.click(").program().is_err());
    }

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
