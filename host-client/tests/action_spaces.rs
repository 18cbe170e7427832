//! The conformance run of every action space: every stub task, each driven by
//! oracle answers written in one grammar (keys by that grammar's own names,
//! through its key table), translated by `actionspace::parse` and carried out on
//! an in-process stub guest, must score 1. The two File Explorer tasks start a
//! program as a person does on Windows: `win+r`, the command, Enter (or the Run
//! dialog's OK button, clicked in the grammar's coordinates).

use std::collections::VecDeque;
use std::path::Path;
use std::time::Duration;

use serde_json::{json, Value};

use arena_actionspace::{ActionSpace, Context, Coords};
use arena_agents::observation::Observation;
use arena_agents::{Agent, AgentError, Prediction};
use arena_client::cache::DownloadCache;
use arena_client::client::{ClientConfig, GuestClient};
use arena_exec::AgentAction;
use arena_host::episode::{run_episode, EpisodeConfig};
use arena_host::run::load_tasks;
use arena_results::{EpisodeStatus, RunLayout};
use arena_task::{Difficulty, Task};
use arena_test_support::StubGuest;

/// One oracle answer: in the grammar, or a decision for grammars that have none
/// of their own (the computer-use tools end by answering without a call).
#[derive(Clone)]
enum Answer {
    In(Value),
    Done,
    Fail,
}

/// Answers a fixed list, translated through the action space like any agent's.
struct Oracle {
    space: ActionSpace,
    coords: Coords,
    answers: VecDeque<Answer>,
}

#[async_trait::async_trait]
impl Agent for Oracle {
    fn name(&self) -> &str {
        "oracle"
    }

    async fn reset(&mut self, _task: &Task) {}

    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError> {
        let answer = self.answers.pop_front().ok_or_else(|| AgentError::Exhausted("oracle".into()))?;
        let (response, actions) = match answer {
            Answer::Done => ("DONE".to_owned(), vec![AgentAction::Done]),
            Answer::Fail => ("FAIL".to_owned(), vec![AgentAction::Fail]),
            Answer::In(value) => {
                let ctx = Context::new(obs.screen_size(), self.coords);
                let steps = arena_actionspace::parse(self.space, &value, &ctx)
                    .map_err(|e| AgentError::Plan { path: "oracle".into(), reason: e.to_string() })?;
                (value.to_string(), AgentAction::from_steps(&steps))
            }
        };
        Ok(Prediction { response, actions, ..Prediction::default() })
    }
}

fn stub_tasks() -> Vec<Task> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tasks/stub");
    load_tasks(&dir, Difficulty::Normal).expect("the stub tasks load")
}

/// Runs every (task, answers) pair of `space` on fresh stub guests and checks each scores 1.
async fn conform(space: ActionSpace, coords: Coords, oracles: Vec<(&str, Vec<Answer>)>) {
    let tasks = stub_tasks();
    let tmp = tempfile::tempdir().unwrap();
    for (name, answers) in oracles {
        let task = tasks.iter().find(|t| t.name == name).unwrap_or_else(|| panic!("no stub task {name}"));
        let guest = StubGuest::start().await;
        let client =
            GuestClient::new(guest.url(), ClientConfig { token: None, timeout: Duration::from_secs(20), retries: 1 })
                .expect("client");
        let mut config = EpisodeConfig::instant(DownloadCache::new(tmp.path().join("cache")).expect("cache"));
        config.max_steps = 10;
        let layout = RunLayout {
            root: tmp.path().to_owned(),
            agent: space.name().into(),
            observation: "screenshot".into(),
            model: "oracle".into(),
            trial: coords.name(),
        };
        let mut agent = Oracle { space, coords, answers: answers.into() };
        let result = run_episode(&client, task, &mut agent, &config, &layout.task_dir(task)).await;
        assert_eq!(
            (result.score, &result.status),
            (1.0, &EpisodeStatus::Completed),
            "{space} ({}) {name}: {}",
            coords.name(),
            serde_json::to_string_pretty(&result.eval).unwrap()
        );
    }
}

fn code(text: &str) -> Answer {
    Answer::In(json!(text))
}

#[tokio::test]
async fn pyautogui_in_every_coordinate_convention_scores_the_stub_tasks() {
    // `ok` is the Run dialog's OK button on the 1440x900 stub screen: the dialog sits at
    // the bottom left of the work area, its OK button's centre near (191, 821).
    for (coords, centre, ok) in [
        (Coords::Pixels, "720, 450", "191, 821"),
        (Coords::Fraction, "0.5, 0.5", "0.1326, 0.9122"),
        (Coords::Grid1000, "500, 500", "133, 912"),
    ] {
        let oracles = vec![
            (
                "stub-notepad-draft",
                vec![
                    code(&format!("pyautogui.moveTo({centre})\npyautogui.write('This is a draft.')")),
                    code("pyautogui.hotkey('ctrl', 's')"),
                    code("DONE"),
                ],
            ),
            (
                "stub-notepad-count",
                vec![
                    code("import pyperclip\nimport time\npyperclip.copy('3')\npyautogui.hotkey('ctrl', 'v')\ntime.sleep(0.1)"),
                    code("WAIT"),
                    code("pyautogui.keyDown('ctrl'); pyautogui.press('s'); pyautogui.keyUp('ctrl')"),
                    code("DONE"),
                ],
            ),
            (
                "stub-notepad-append",
                vec![
                    code("pyautogui.hotkey('ctrl', 'end')\npyautogui.typewrite('buy eggs\\n', interval=0.01)"),
                    code("pyautogui.hotkey('ctrl', 's')"),
                    code("DONE"),
                ],
            ),
            ("stub-settings-infeasible", vec![code("FAIL")]),
            (
                "stub-explorer-open-folder",
                vec![
                    code("pyautogui.hotkey('win', 'r')"),
                    code(r"pyautogui.write(r'C:\Users\Docker\Documents\Reports')"),
                    code(&format!("pyautogui.click({ok})")),
                    code("DONE"),
                ],
            ),
            (
                "stub-explorer-fill-file",
                vec![
                    code("pyautogui.keyDown('winleft'); pyautogui.press('r'); pyautogui.keyUp('winleft')"),
                    code(r"pyautogui.write('notepad C:\\Users\\Docker\\Documents\\Projects\\notes.txt\n')"),
                    code("pyautogui.write('kickoff on monday')\npyautogui.hotkey('ctrl', 's')"),
                    code("DONE"),
                ],
            ),
        ];
        conform(ActionSpace::Pyautogui, coords, oracles).await;
    }
}

#[tokio::test]
async fn computer_13_scores_the_stub_tasks() {
    let a = |v: Value| Answer::In(v);
    let oracles = vec![
        (
            "stub-notepad-draft",
            vec![
                a(json!({"action_type": "MOVE_TO", "x": 0.5, "y": 0.5})),
                a(json!({"action_type": "TYPING", "text": "This is a draft."})),
                a(json!({"action_type": "HOTKEY", "keys": ["ctrl", "s"]})),
                a(json!({"action_type": "DONE"})),
            ],
        ),
        (
            "stub-notepad-count",
            vec![
                a(json!({"action_type": "TYPING", "parameters": {"text": "3"}})),
                a(json!([
                    {"action_type": "KEY_DOWN", "key": "ctrl"},
                    {"action_type": "PRESS", "key": "s"},
                    {"action_type": "KEY_UP", "key": "ctrl"},
                ])),
                a(json!("DONE")),
            ],
        ),
        (
            "stub-notepad-append",
            vec![
                a(json!({"action_type": "HOTKEY", "keys": ["ctrl", "end"]})),
                a(json!({"action_type": "TYPING", "text": "buy eggs\n"})),
                a(json!({"action_type": "HOTKEY", "keys": ["ctrl", "s"]})),
                a(json!({"action_type": "DONE"})),
            ],
        ),
        ("stub-settings-infeasible", vec![a(json!({"action_type": "FAIL"}))]),
        (
            "stub-explorer-open-folder",
            vec![
                a(json!({"action_type": "HOTKEY", "keys": ["win", "r"]})),
                a(json!({"action_type": "TYPING", "text": r"C:\Users\Docker\Documents\Reports"})),
                a(json!({"action_type": "CLICK", "x": 0.1326, "y": 0.9122})),
                a(json!({"action_type": "DONE"})),
            ],
        ),
        (
            "stub-explorer-fill-file",
            vec![
                a(json!({"action_type": "HOTKEY", "keys": ["win", "r"]})),
                a(json!({"action_type": "TYPING", "text": r"notepad C:\Users\Docker\Documents\Projects\notes.txt"})),
                a(json!({"action_type": "PRESS", "key": "enter"})),
                a(json!({"action_type": "TYPING", "text": "kickoff on monday"})),
                a(json!({"action_type": "HOTKEY", "keys": ["ctrl", "s"]})),
                a(json!({"action_type": "DONE"})),
            ],
        ),
    ];
    conform(ActionSpace::Computer13, Coords::Fraction, oracles).await;
}

#[tokio::test]
async fn anthropic_tool_inputs_of_both_versions_score_the_stub_tasks() {
    for space in [ActionSpace::Anthropic20250124, ActionSpace::Anthropic20251124] {
        let a = |v: Value| Answer::In(v);
        let oracles = vec![
            (
                "stub-notepad-draft",
                vec![
                    a(json!({"action": "mouse_move", "coordinate": [640, 400]})),
                    a(json!({"action": "type", "text": "This is a draft."})),
                    a(json!({"action": "key", "text": "ctrl+s"})),
                    Answer::Done,
                ],
            ),
            (
                "stub-notepad-count",
                vec![
                    a(json!({"action": "type", "text": "3"})),
                    a(json!({"action": "hold_key", "text": "ctrl", "duration": 0})),
                    a(json!({"action": "key", "text": "ctrl+s"})),
                    Answer::Done,
                ],
            ),
            (
                "stub-notepad-append",
                vec![
                    a(json!({"action": "key", "text": "ctrl+End"})),
                    a(json!({"action": "type", "text": "buy eggs"})),
                    a(json!({"action": "key", "text": "Return ctrl+s"})),
                    Answer::Done,
                ],
            ),
            ("stub-settings-infeasible", vec![a(json!({"action": "screenshot"})), Answer::Fail]),
            (
                "stub-explorer-open-folder",
                vec![
                    a(json!({"action": "key", "text": "super+r"})),
                    a(json!({"action": "type", "text": r"C:\Users\Docker\Documents\Reports"})),
                    // The OK button, in the 1280x800 image the tool declares.
                    a(json!({"action": "left_click", "coordinate": [170, 730]})),
                    Answer::Done,
                ],
            ),
            (
                "stub-explorer-fill-file",
                vec![
                    a(json!({"action": "key", "text": "Super_L+r"})),
                    a(json!({"action": "type", "text": r"notepad C:\Users\Docker\Documents\Projects\notes.txt"})),
                    a(json!({"action": "key", "text": "Return"})),
                    a(json!({"action": "type", "text": "kickoff on monday"})),
                    a(json!({"action": "key", "text": "ctrl+s"})),
                    Answer::Done,
                ],
            ),
        ];
        conform(space, Coords::Image { width: 1280, height: 800 }, oracles).await;
    }
}

#[tokio::test]
async fn openai_actions_score_the_stub_tasks() {
    let a = |v: Value| Answer::In(v);
    let oracles = vec![
        (
            "stub-notepad-draft",
            vec![
                a(json!({"type": "move", "x": 720, "y": 450})),
                a(json!({"type": "type", "text": "This is a draft."})),
                a(json!({"type": "keypress", "keys": ["CTRL", "S"]})),
                Answer::Done,
            ],
        ),
        (
            "stub-notepad-count",
            vec![
                a(json!({"type": "type", "text": "3"})),
                a(json!({"type": "keypress", "keys": ["ctrl", "s"]})),
                Answer::Done,
            ],
        ),
        (
            "stub-notepad-append",
            vec![
                a(json!({"type": "keypress", "keys": ["CTRL", "END"]})),
                a(json!({"type": "type", "text": "buy eggs"})),
                a(json!({"type": "keypress", "keys": ["ENTER"]})),
                a(json!({"type": "wait"})),
                a(json!({"type": "keypress", "keys": ["CTRL", "S"]})),
                Answer::Done,
            ],
        ),
        ("stub-settings-infeasible", vec![Answer::Fail]),
        (
            "stub-explorer-open-folder",
            vec![
                a(json!({"type": "keypress", "keys": ["META", "R"]})),
                a(json!({"type": "type", "text": r"C:\Users\Docker\Documents\Reports"})),
                a(json!({"type": "click", "button": "left", "x": 191, "y": 821})),
                Answer::Done,
            ],
        ),
        (
            "stub-explorer-fill-file",
            vec![
                a(json!({"type": "keypress", "keys": ["SUPER", "R"]})),
                a(json!({"type": "type", "text": r"notepad C:\Users\Docker\Documents\Projects\notes.txt"})),
                a(json!({"type": "keypress", "keys": ["ENTER"]})),
                a(json!({"type": "type", "text": "kickoff on monday"})),
                a(json!({"type": "keypress", "keys": ["CTRL", "S"]})),
                Answer::Done,
            ],
        ),
    ];
    conform(ActionSpace::OpenAi, Coords::Pixels, oracles).await;
}

#[tokio::test]
async fn uitars_replies_score_the_stub_tasks() {
    let oracles = vec![
        (
            "stub-notepad-draft",
            vec![
                code("Thought: Type it.\nAction: type(content='This is a draft.')"),
                code("Thought: Save.\nAction: hotkey(key='ctrl s')"),
                code("Action: finished(content='saved')"),
            ],
        ),
        (
            "stub-notepad-count",
            vec![code("Action: type(content='3')"), code("Action: hotkey(key='ctrl s')"), code("Action: finished()")],
        ),
        (
            "stub-notepad-append",
            vec![
                code("Action: hotkey(key='ctrl end')"),
                code("Action: type(content='buy eggs\\n')"),
                code("Action: wait()"),
                code("Action: hotkey(key='ctrl s')\n\nfinished(content='done')"),
            ],
        ),
        ("stub-settings-infeasible", vec![code("Thought: No such setting.\nAction: call_user()")]),
        (
            "stub-explorer-open-folder",
            vec![
                code("Thought: Open the Run dialog.\nAction: hotkey(key='win r')"),
                // UI-TARS escapes a backslash in its quoted arguments.
                code(r"Action: type(content='C:\\Users\\Docker\\Documents\\Reports')"),
                // The OK button on the 0..1000 grid of UI-TARS 1.0.
                code("Action: click(start_box='(133,912)')"),
                code("Action: finished()"),
            ],
        ),
        (
            "stub-explorer-fill-file",
            vec![
                code("Action: hotkey(key='win r')"),
                code(r"Action: type(content='notepad C:\\Users\\Docker\\Documents\\Projects\\notes.txt\n')"),
                code("Action: type(content='kickoff on monday')"),
                code("Action: hotkey(key='ctrl s')"),
                code("Action: finished()"),
            ],
        ),
    ];
    conform(ActionSpace::UiTars, Coords::Grid1000, oracles).await;
}
