//! Conformance tables for every action space: each grammar's actions and keys
//! against the typed actions they must become, and the errors they must give.
//! The example texts are our own, written in each grammar's published form.

use serde_json::{json, Value};

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;

use super::*;

const SCREEN: (u32, u32) = (1440, 900);

fn ctx(coords: Coords) -> Context {
    Context { screen: SCREEN, cursor: (10, 20), coords }
}

fn click(x: i32, y: i32, button: MouseButton, count: u32) -> Step {
    Step::Act(Action::Click { x: Some(x), y: Some(y), button, count })
}

fn act(a: Action) -> Step {
    Step::Act(a)
}

fn key(k: &str) -> Step {
    act(Action::KeyPress { key: k.into(), presses: 1 })
}

fn hotkey(keys: &[&str]) -> Step {
    act(Action::Hotkey { keys: keys.iter().map(|k| (*k).to_owned()).collect() })
}

fn check(space: ActionSpace, coords: Coords, input: Value, expected: &[Step]) {
    match parse(space, &input, &ctx(coords)) {
        Ok(steps) => assert_eq!(steps, expected, "{space} {input}"),
        Err(err) => panic!("{space} {input}: {err}"),
    }
}

fn check_err(space: ActionSpace, input: Value, needles: &[&str]) {
    match parse(space, &input, &ctx(Coords::Pixels)) {
        Ok(steps) => panic!("{space} {input} should fail, got {steps:?}"),
        Err(err) => {
            let text = err.to_string();
            assert!(text.starts_with(&format!("{space} action: ")), "{text}");
            for needle in needles {
                assert!(text.contains(needle), "{space} {input}: {text:?} lacks {needle:?}");
            }
        }
    }
}

#[test]
fn pyautogui_as_osworld_agents_write_it() {
    let p = ActionSpace::Pyautogui;
    let px = Coords::Pixels;
    check(p, px, json!("pyautogui.click(100, 200)"), &[click(100, 200, MouseButton::Left, 1)]);
    check(p, px, json!("WAIT"), &[Step::Wait]);
    check(p, px, json!(" DONE\n"), &[Step::Done]);
    check(p, px, json!("FAIL"), &[Step::Fail]);
    // UI-TARS's adapter in the forked WAA: paste through the clipboard, sleep, drag with a duration.
    check(
        p,
        px,
        json!("import pyautogui\nimport pyperclip\nimport time\npyperclip.copy('héllo')\npyautogui.hotkey('ctrl', 'v')\ntime.sleep(0.5)\npyautogui.moveTo(10, 10)\npyautogui.dragTo(300, 400, duration=1.0)"),
        &[
            Step::SetClipboard("héllo".into()),
            hotkey(&["ctrl", "v"]),
            act(Action::Wait { ms: 500 }),
            act(Action::MoveTo { x: 10, y: 10 }),
            act(Action::Drag { from: None, to: Point { x: 300, y: 400 }, button: MouseButton::Left, duration_ms: Some(1000) }),
        ],
    );
    check(
        p,
        px,
        json!("pyautogui.typewrite('ab', interval=0.05)\npyautogui.write('c')"),
        &[
            act(Action::TypeText { text: "ab".into(), interval_ms: Some(50) }),
            act(Action::TypeText { text: "c".into(), interval_ms: None }),
        ],
    );
    check(
        p,
        px,
        json!("pyautogui.keyDown('shift'); pyautogui.press('down'); pyautogui.keyUp('shift')"),
        &[act(Action::KeyDown { key: "shift".into() }), key("down"), act(Action::KeyUp { key: "shift".into() })],
    );
    check(
        p,
        px,
        json!("pyautogui.scroll(-3, x=50, y=60)\npyautogui.hscroll(4)"),
        &[
            act(Action::Scroll { x: Some(50), y: Some(60), dx: 0, dy: -3 }),
            act(Action::Scroll { x: None, y: None, dx: 4, dy: 0 }),
        ],
    );
    check(
        p,
        px,
        json!("import pyperclip\npyperclip.copy('x')\npyautogui.write(pyperclip.paste())"),
        &[Step::SetClipboard("x".into()), act(Action::TypeText { text: "x".into(), interval_ms: None })],
    );
}

#[test]
fn pyautogui_coordinates_in_each_convention() {
    let p = ActionSpace::Pyautogui;
    let centre = [click(720, 450, MouseButton::Left, 1)];
    check(p, Coords::Fraction, json!("pyautogui.click(0.5, 0.5)"), &centre);
    check(p, Coords::Fraction, json!("pyautogui.click(x=0.5, y=0.5)"), &centre);
    check(p, Coords::Fraction, json!("pyautogui.click((0.5, 0.5))"), &centre);
    check(p, Coords::Grid1000, json!("pyautogui.click(500, 500)"), &centre);
    check(
        p,
        Coords::Grid1000,
        json!("for i in range(2):\n    pyautogui.moveTo(x=100 * (i + 1), y=1000)"),
        &[act(Action::MoveTo { x: 144, y: 900 }), act(Action::MoveTo { x: 288, y: 900 })],
    );
    check(
        p,
        Coords::Fraction,
        json!("pyautogui.scroll(-5, 0.5, 0.5)\npyautogui.moveRel(0.1, 0)\npyautogui.click()"),
        &[
            act(Action::Scroll { x: Some(720), y: Some(450), dx: 0, dy: -5 }),
            act(Action::MoveRel { dx: 144, dy: 0 }),
            act(Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 }),
        ],
    );
    // Amounts and key names are never scaled.
    check(
        p,
        Coords::Grid1000,
        json!("pyautogui.press('a', presses=2)"),
        &[act(Action::KeyPress { key: "a".into(), presses: 2 })],
    );
}

#[test]
fn pyautogui_errors_name_the_code_and_the_problem() {
    let p = ActionSpace::Pyautogui;
    check_err(p, json!("pyautogui.press('entr')"), &["cannot translate", "entr"]);
    check_err(p, json!("with open('x') as f: pass"), &["cannot parse", "`with`"]);
    check_err(p, json!("pyautogui.screenshot('a.png')"), &["saving a screenshot"]);
    check_err(p, json!("import subprocess\nsubprocess.Popen(['notepad'])"), &["starting a process"]);
    check_err(p, json!("import pyperclip\npyautogui.write(pyperclip.paste())"), &["clipboard this code did not write"]);
    check_err(p, json!("pyperclip.copy('x')"), &["NameError", "pyperclip"]);
    check_err(p, json!({"code": "x"}), &["expected a string, got an object"]);
    check_err(p, json!("open('C:/x.txt', 'w')"), &["cannot translate", "open"]);
    check_err(p, json!("import os\nos.system('del C:\\\\x.txt')"), &["running a command"]);
    let at = Context { screen: SCREEN, cursor: (10, 20), coords: Coords::Pixels };
    assert_eq!(pyautogui::parse("pyautogui.moveRel(5, 5)", &at).unwrap(), [act(Action::MoveRel { dx: 5, dy: 5 })]);
}

#[test]
fn pyautogui_answers_that_never_end_are_refused_in_time() {
    let started = std::time::Instant::now();
    // Far more work than the loop budget allows would take longer than the deadline,
    // were the budget not there; either bound ends it with an error naming the code.
    let err = pyautogui::parse("while True:\n    x = 1", &ctx(Coords::Pixels)).unwrap_err();
    assert!(err.message.contains("cannot translate"), "{err}");
    assert!(started.elapsed() <= pyautogui::TRANSLATE_TIME + std::time::Duration::from_secs(5));
}

#[test]
fn computer_13_templates_translate_to_actions() {
    // The pyautogui lines upstream's host sends for computer_13 actions (waa-api.md §b.6).
    let at = Context { screen: (1440, 900), cursor: (10, 20), coords: Coords::Pixels };
    let check = |code: &str, expected: &[Action]| {
        let steps = pyautogui::parse(code, &at).unwrap_or_else(|e| panic!("{code}: {e}"));
        let expected: Vec<Step> = expected.iter().cloned().map(Step::Act).collect();
        assert_eq!(steps, expected, "{code}");
    };
    let key = |k: &str| Action::KeyPress { key: k.into(), presses: 1 };
    let text = |t: &str| Action::TypeText { text: t.into(), interval_ms: None };
    let wait = |ms: u64| Action::Wait { ms };
    let click_at = |x: i32, y: i32| Action::Click { x: Some(x), y: Some(y), button: MouseButton::Left, count: 1 };
    let keys = |k: &[&str]| Action::Hotkey { keys: k.iter().map(|s| (*s).to_owned()).collect() };
    check("pyautogui.moveTo(100, 200, 0.6, pyautogui.easeInQuad)", &[Action::MoveTo { x: 100, y: 200 }]);
    check("pyautogui.moveTo(100.9, 200.2, 0.5, pyautogui.easeOutBounce)", &[Action::MoveTo { x: 100, y: 200 }]);
    check(
        "pyautogui.click(button='right', x=5, y=6, clicks=2)",
        &[Action::Click { x: Some(5), y: Some(6), button: MouseButton::Right, count: 2 }],
    );
    check("pyautogui.click()", &[Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 }]);
    check("pyautogui.mouseDown(button='left')", &[Action::MouseDown { button: MouseButton::Left, x: None, y: None }]);
    check("pyautogui.mouseUp(button='middle')", &[Action::MouseUp { button: MouseButton::Middle, x: None, y: None }]);
    check("pyautogui.rightClick(x=7, y=8)", &[Action::RightClick { x: Some(7), y: Some(8) }]);
    check("pyautogui.doubleClick(x=7, y=8)", &[Action::DoubleClick { x: Some(7), y: Some(8) }]);
    check(
        "pyautogui.dragTo(500, 400, duration=1.0, button='left', mouseDownUp=True)",
        &[Action::Drag { from: None, to: Point::new(500, 400), button: MouseButton::Left, duration_ms: Some(1000) }],
    );
    check("pyautogui.hscroll(-3)", &[Action::Scroll { x: None, y: None, dx: -3, dy: 0 }]);
    check("pyautogui.vscroll(120)", &[Action::Scroll { x: None, y: None, dx: 0, dy: 120 }]);
    check("pyautogui.scroll(-5, x=1, y=2)", &[Action::Scroll { x: Some(1), y: Some(2), dx: 0, dy: -5 }]);
    check("pyautogui.typewrite('hello world')", &[text("hello world")]);
    check("pyautogui.typewrite(\"it's\")", &[text("it's")]);
    check("pyautogui.typewrite('a\\nb\\tc')", &[text("a"), key("enter"), text("b"), key("tab"), text("c")]);
    check("pyautogui.write(['a', 'Enter', 'pgdn'])", &[key("a"), key("enter"), key("pagedown")]);
    check("pyautogui.press('enter')", &[key("enter")]);
    check("pyautogui.press('ESC', presses=3)", &[Action::KeyPress { key: "esc".into(), presses: 3 }]);
    check("pyautogui.press(['a', 'b'], interval=0.1)", &[key("a"), key("b"), wait(100)]);
    check("pyautogui.keyDown('shift')", &[Action::KeyDown { key: "shift".into() }]);
    check("pyautogui.keyUp('shift')", &[Action::KeyUp { key: "shift".into() }]);
    check("pyautogui.hotkey('ctrl', 'c')", &[keys(&["ctrl", "c"])]);
    check("pyautogui.hotkey(['ctrl', 'shift', 't'])", &[keys(&["ctrl", "shift", "t"])]);
    check(
        "pyautogui.hotkey('ctrl', 'c', interval=0.1)",
        &[
            Action::KeyDown { key: "ctrl".into() },
            wait(100),
            Action::KeyDown { key: "c".into() },
            wait(100),
            Action::KeyUp { key: "c".into() },
            wait(100),
            Action::KeyUp { key: "ctrl".into() },
            wait(100),
        ],
    );
    check("pyautogui.moveRel(5, -5)", &[Action::MoveRel { dx: 5, dy: -5 }]);
    check("pyautogui.move(None, 3)", &[Action::MoveRel { dx: 0, dy: 3 }]);
    check(
        "pyautogui.drag(30, 40, button='right')",
        &[Action::Drag { from: None, to: Point::new(40, 60), button: MouseButton::Right, duration_ms: None }],
    );
    check("pyautogui.click((300, 400))", &[click_at(300, 400)]);
    check("pyautogui.click(x=300)", &[click_at(300, 20)]);
    check("pyautogui.click([100, 200, 50, 31])", &[click_at(125, 215)]);
    check(
        "pyautogui.click(1, 2, clicks=2, interval=0.25)",
        &[
            click_at(1, 2),
            wait(250),
            Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 },
            wait(250),
        ],
    );
    check("pyautogui.tripleClick()", &[Action::Click { x: None, y: None, button: MouseButton::Left, count: 3 }]);
    check("pyautogui.sleep(0.3)", &[wait(300)]);
    check("x = 1, 2", &[]);
}

#[test]
fn computer_13_every_type() {
    let c = ActionSpace::Computer13;
    let px = Coords::Pixels;
    let table: Vec<(Value, Vec<Step>)> = vec![
        (json!({"action_type": "MOVE_TO", "x": 5, "y": 6}), vec![act(Action::MoveTo { x: 5, y: 6 })]),
        (json!({"action_type": "MOVE_TO"}), vec![]),
        (
            json!({"action_type": "CLICK", "parameters": {"button": "right", "x": 1, "y": 2, "num_clicks": 2}}),
            vec![click(1, 2, MouseButton::Right, 2)],
        ),
        (
            json!({"action_type": "CLICK"}),
            vec![act(Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 })],
        ),
        (
            json!({"action_type": "MOUSE_DOWN", "button": "middle"}),
            vec![act(Action::MouseDown { button: MouseButton::Middle, x: None, y: None })],
        ),
        (
            json!({"action_type": "MOUSE_UP"}),
            vec![act(Action::MouseUp { button: MouseButton::Left, x: None, y: None })],
        ),
        (
            json!({"action_type": "RIGHT_CLICK", "x": 3, "y": 4}),
            vec![act(Action::RightClick { x: Some(3), y: Some(4) })],
        ),
        (json!({"action_type": "DOUBLE_CLICK"}), vec![act(Action::DoubleClick { x: None, y: None })]),
        (
            json!({"action_type": "DRAG_TO", "x": 7, "y": 8}),
            vec![act(Action::Drag {
                from: None,
                to: Point { x: 7, y: 8 },
                button: MouseButton::Left,
                duration_ms: Some(1000),
            })],
        ),
        (
            json!({"action_type": "SCROLL", "dx": 2, "dy": -3}),
            vec![
                act(Action::Scroll { x: None, y: None, dx: 2, dy: 0 }),
                act(Action::Scroll { x: None, y: None, dx: 0, dy: -3 }),
            ],
        ),
        (
            json!({"action_type": "TYPING", "text": "hi\n"}),
            vec![act(Action::TypeText { text: "hi\n".into(), interval_ms: None })],
        ),
        (json!({"action_type": "PRESS", "key": "Enter"}), vec![key("enter")]),
        (json!({"action_type": "KEY_DOWN", "key": "ctrl"}), vec![act(Action::KeyDown { key: "ctrl".into() })]),
        (json!({"action_type": "KEY_UP", "key": "ctrl"}), vec![act(Action::KeyUp { key: "ctrl".into() })]),
        (json!({"action_type": "HOTKEY", "keys": ["ctrl", "shift", "esc"]}), vec![hotkey(&["ctrl", "shift", "esc"])]),
        (json!({"action_type": "WAIT"}), vec![Step::Wait]),
        (json!("DONE"), vec![Step::Done]),
        (json!({"action_type": "FAIL"}), vec![Step::Fail]),
    ];
    for (input, expected) in table {
        check(c, px, input, &expected);
    }
    assert_eq!(computer13::ACTION_TYPES.len(), 13);
    check(
        c,
        Coords::Fraction,
        json!({"action_type": "CLICK", "x": 0.25, "y": 0.5}),
        &[click(360, 450, MouseButton::Left, 1)],
    );
    check(c, px, json!([{"action_type": "PRESS", "key": "a"}, "DONE"]), &[key("a"), Step::Done]);
    check_err(c, json!({"action_type": "TELEPORT"}), &["unknown action_type \"TELEPORT\"", "MOVE_TO"]);
    check_err(c, json!({"action_type": "PRESS", "key": "entr"}), &["unknown key \"entr\""]);
    check_err(c, json!({"action_type": "CLICK", "x": 1}), &["needs both `x` and `y`"]);
    check_err(c, json!({"action_type": "CLICK", "num_clicks": 4}), &["num_clicks"]);
    check_err(c, json!({"action_type": "HOTKEY", "keys": "ctrl+c"}), &["a list of key names"]);
    check_err(c, json!({"action_type": "TYPING"}), &["`text` is missing"]);
    check_err(c, json!(3), &["expected an action object"]);
}

#[test]
fn anthropic_every_action_of_both_versions() {
    for space in [ActionSpace::Anthropic20250124, ActionSpace::Anthropic20251124] {
        let px = Coords::Pixels;
        let table: Vec<(Value, Vec<Step>)> = vec![
            (json!({"action": "key", "text": "Return"}), vec![key("enter")]),
            (json!({"action": "key", "text": "ctrl+a BackSpace"}), vec![hotkey(&["ctrl", "a"]), key("backspace")]),
            (json!({"action": "key", "text": "super+Page_Down"}), vec![hotkey(&["win", "pagedown"])]),
            (json!({"action": "key", "text": "KP_0"}), vec![key("num0")]),
            (json!({"action": "key", "text": "XF86AudioMute"}), vec![key("volumemute")]),
            (json!({"action": "key", "text": "Escape"}), vec![key("esc")]),
            (
                json!({"action": "hold_key", "text": "shift", "duration": 0.5}),
                vec![
                    act(Action::KeyDown { key: "shift".into() }),
                    act(Action::Wait { ms: 500 }),
                    act(Action::KeyUp { key: "shift".into() }),
                ],
            ),
            (
                json!({"action": "type", "text": "x y"}),
                vec![act(Action::TypeText { text: "x y".into(), interval_ms: None })],
            ),
            (json!({"action": "cursor_position"}), vec![Step::CursorPosition]),
            (json!({"action": "mouse_move", "coordinate": [3, 4]}), vec![act(Action::MoveTo { x: 3, y: 4 })]),
            (
                json!({"action": "left_mouse_down"}),
                vec![act(Action::MouseDown { button: MouseButton::Left, x: None, y: None })],
            ),
            (
                json!({"action": "left_mouse_up"}),
                vec![act(Action::MouseUp { button: MouseButton::Left, x: None, y: None })],
            ),
            (json!({"action": "left_click", "coordinate": [1, 2]}), vec![click(1, 2, MouseButton::Left, 1)]),
            (
                json!({"action": "left_click", "coordinate": [1, 2], "text": "ctrl+shift"}),
                vec![
                    act(Action::KeyDown { key: "ctrl".into() }),
                    act(Action::KeyDown { key: "shift".into() }),
                    click(1, 2, MouseButton::Left, 1),
                    act(Action::KeyUp { key: "shift".into() }),
                    act(Action::KeyUp { key: "ctrl".into() }),
                ],
            ),
            (json!({"action": "right_click", "coordinate": [1, 2]}), vec![click(1, 2, MouseButton::Right, 1)]),
            (json!({"action": "middle_click", "coordinate": [1, 2]}), vec![click(1, 2, MouseButton::Middle, 1)]),
            (json!({"action": "double_click", "coordinate": [1, 2]}), vec![click(1, 2, MouseButton::Left, 2)]),
            (json!({"action": "triple_click", "coordinate": [1, 2]}), vec![click(1, 2, MouseButton::Left, 3)]),
            (
                json!({"action": "left_click"}),
                vec![act(Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 })],
            ),
            (
                json!({"action": "left_click_drag", "start_coordinate": [1, 2], "coordinate": [30, 40]}),
                vec![act(Action::Drag {
                    from: Some(Point { x: 1, y: 2 }),
                    to: Point { x: 30, y: 40 },
                    button: MouseButton::Left,
                    duration_ms: None,
                })],
            ),
            (
                json!({"action": "scroll", "coordinate": [5, 6], "scroll_direction": "down", "scroll_amount": 3}),
                vec![act(Action::Scroll { x: Some(5), y: Some(6), dx: 0, dy: -360 })],
            ),
            (
                json!({"action": "scroll", "scroll_direction": "left", "scroll_amount": 1}),
                vec![act(Action::Scroll { x: None, y: None, dx: -120, dy: 0 })],
            ),
            (json!({"action": "wait", "duration": 2}), vec![act(Action::Wait { ms: 2000 })]),
            (json!({"action": "screenshot"}), vec![Step::Screenshot]),
        ];
        for (input, expected) in table {
            check(space, px, input, &expected);
        }
        check_err(space, json!({"action": "teleport"}), &["unknown action \"teleport\"", "triple_click"]);
        check_err(space, json!({"action": "key", "text": "Hyper_Q"}), &["unknown key \"Hyper_Q\""]);
        check_err(space, json!({"action": "mouse_move"}), &["mouse_move needs `coordinate`"]);
        check_err(space, json!({"action": "scroll", "scroll_direction": "sideways"}), &["sideways"]);
        check_err(space, json!({"action": "left_click", "coordinate": [1]}), &["must be [x, y]"]);
        check_err(space, json!({"action": "wait", "duration": -1}), &["duration"]);
    }
    // The scaled screenshot's pixels are mapped back to the screen's.
    check(
        ActionSpace::Anthropic20250124,
        Coords::Image { width: 1280, height: 800 },
        json!({"action": "left_click", "coordinate": [640, 400]}),
        &[click(720, 450, MouseButton::Left, 1)],
    );
    check(
        ActionSpace::Anthropic20251124,
        Coords::Pixels,
        json!({"action": "zoom", "region": [0, 0, 100, 50]}),
        &[Step::Zoom([0, 0, 100, 50])],
    );
    check_err(
        ActionSpace::Anthropic20250124,
        json!({"action": "zoom", "region": [0, 0, 10, 10]}),
        &["unknown action \"zoom\""],
    );
    check_err(ActionSpace::Anthropic20251124, json!({"action": "zoom", "region": [10, 0, 0, 10]}), &["x2 > x1"]);
}

#[test]
fn anthropic_toolset_members_are_the_tool_actions_named_by_the_block() {
    let t = ActionSpace::AnthropicToolset20260801;
    let px = Coords::Pixels;
    let table: Vec<(Value, Vec<Step>)> = vec![
        (json!({"name": "key", "input": {"text": "ctrl+s"}}), vec![hotkey(&["ctrl", "s"])]),
        (json!({"name": "key", "input": {"text": "Down", "repeat": 3}}), vec![key("down"), key("down"), key("down")]),
        (
            json!({"name": "hold_key", "input": {"text": "shift", "duration": 1}}),
            vec![
                act(Action::KeyDown { key: "shift".into() }),
                act(Action::Wait { ms: 1000 }),
                act(Action::KeyUp { key: "shift".into() }),
            ],
        ),
        (
            json!({"name": "type", "input": {"text": "hi"}}),
            vec![act(Action::TypeText { text: "hi".into(), interval_ms: None })],
        ),
        (json!({"name": "cursor_position", "input": {}}), vec![Step::CursorPosition]),
        (json!({"name": "mouse_move", "input": {"coordinate": [5, 6]}}), vec![act(Action::MoveTo { x: 5, y: 6 })]),
        (
            json!({"name": "left_mouse_down"}),
            vec![act(Action::MouseDown { button: MouseButton::Left, x: None, y: None })],
        ),
        (
            json!({"name": "left_mouse_up", "input": null}),
            vec![act(Action::MouseUp { button: MouseButton::Left, x: None, y: None })],
        ),
        (
            json!({"type": "tool_use", "id": "t1", "toolset_name": "computer", "name": "left_click", "input": {"coordinate": [7, 8]}}),
            vec![click(7, 8, MouseButton::Left, 1)],
        ),
        (
            json!({"name": "left_click", "input": {"coordinate": [7, 8], "text": "ctrl"}}),
            vec![
                act(Action::KeyDown { key: "ctrl".into() }),
                click(7, 8, MouseButton::Left, 1),
                act(Action::KeyUp { key: "ctrl".into() }),
            ],
        ),
        (
            json!({"name": "left_click_drag", "input": {"start_coordinate": [1, 2], "coordinate": [3, 4]}}),
            vec![act(Action::Drag {
                from: Some(Point { x: 1, y: 2 }),
                to: Point { x: 3, y: 4 },
                button: MouseButton::Left,
                duration_ms: None,
            })],
        ),
        (json!({"name": "right_click", "input": {"coordinate": [1, 1]}}), vec![click(1, 1, MouseButton::Right, 1)]),
        (json!({"name": "middle_click", "input": {"coordinate": [1, 1]}}), vec![click(1, 1, MouseButton::Middle, 1)]),
        (json!({"name": "double_click", "input": {"coordinate": [1, 1]}}), vec![click(1, 1, MouseButton::Left, 2)]),
        (json!({"name": "triple_click", "input": {"coordinate": [1, 1]}}), vec![click(1, 1, MouseButton::Left, 3)]),
        (
            json!({"name": "scroll", "input": {"scroll_direction": "down", "scroll_amount": 2}}),
            vec![act(Action::Scroll { x: None, y: None, dx: 0, dy: -240 })],
        ),
        (json!({"name": "wait", "input": {"duration": 2}}), vec![act(Action::Wait { ms: 2000 })]),
        (json!({"name": "screenshot", "input": {}}), vec![Step::Screenshot]),
        (json!({"name": "zoom", "input": {"region": [0, 0, 100, 50]}}), vec![Step::Zoom([0, 0, 100, 50])]),
    ];
    let named: std::collections::BTreeSet<&str> = table.iter().filter_map(|(v, _)| v["name"].as_str()).collect();
    assert_eq!(named.len(), anthropic::TOOLSET_MEMBERS.len(), "a row per member");
    for (input, expected) in table {
        check(t, px, input, &expected);
    }
    // Several blocks of one turn, in order.
    check(
        t,
        px,
        json!([{"name": "left_click", "input": {"coordinate": [1, 1]}}, {"name": "type", "input": {"text": "x"}}]),
        &[click(1, 1, MouseButton::Left, 1), act(Action::TypeText { text: "x".into(), interval_ms: None })],
    );
    check_err(
        t,
        json!({"name": "computer", "input": {"action": "left_click"}}),
        &["unknown member \"computer\"", "zoom"],
    );
    check_err(
        t,
        json!({"name": "left_click", "input": {"action": "left_click"}}),
        &["left_click:", "carries no `action`"],
    );
    check_err(t, json!({"name": "left_click", "input": [1, 2]}), &["left_click:", "must be an object"]);
    check_err(t, json!({"name": "key", "input": {"text": "a", "repeat": 0}}), &["key:", "1 to 100"]);
    check_err(t, json!({"name": "key", "input": {"text": "a", "repeat": 101}}), &["1 to 100"]);
    check_err(t, json!({"name": "type", "input": {"text": "a", "repeat": 2}}), &["only `key` takes `repeat`"]);
    check_err(t, json!({"name": "mouse_move", "input": {}}), &["mouse_move:", "needs `coordinate`"]);
    check_err(t, json!({"name": "key", "input": {"text": "Hyper_L"}}), &["key:", "Hyper_L"]);
    check_err(t, json!({"input": {}}), &["name"]);
}

#[test]
fn openai_keys_held_during_a_mouse_action() {
    let o = ActionSpace::OpenAi;
    let px = Coords::Pixels;
    let down = |k: &str| act(Action::KeyDown { key: k.into() });
    let up = |k: &str| act(Action::KeyUp { key: k.into() });
    check(
        o,
        px,
        json!({"type": "click", "button": "left", "x": 5, "y": 6, "keys": ["SHIFT", "CTRL"]}),
        &[down("shift"), down("ctrl"), click(5, 6, MouseButton::Left, 1), up("ctrl"), up("shift")],
    );
    check(o, px, json!({"type": "move", "x": 1, "y": 2, "keys": []}), &[act(Action::MoveTo { x: 1, y: 2 })]);
    check(
        o,
        px,
        json!({"type": "double_click", "x": 1, "y": 2, "keys": null}),
        &[act(Action::DoubleClick { x: Some(1), y: Some(2) })],
    );
    // A GA `computer_call.actions` batch is a list, done in order.
    check(
        o,
        px,
        json!([{"type": "click", "button": "left", "x": 5, "y": 6}, {"type": "type", "text": "hi"}, {"type": "keypress", "keys": ["CTRL", "s"]}]),
        &[
            click(5, 6, MouseButton::Left, 1),
            act(Action::TypeText { text: "hi".into(), interval_ms: None }),
            hotkey(&["ctrl", "s"]),
        ],
    );
    check_err(o, json!({"type": "click", "button": "left", "x": 5, "y": 6, "keys": ["HYPER"]}), &["HYPER"]);
}

#[test]
fn openai_every_action() {
    let o = ActionSpace::OpenAi;
    let px = Coords::Pixels;
    let table: Vec<(Value, Vec<Step>)> = vec![
        (json!({"type": "click", "x": 1, "y": 2, "button": "left"}), vec![click(1, 2, MouseButton::Left, 1)]),
        (json!({"type": "click", "x": 1, "y": 2, "button": "right"}), vec![click(1, 2, MouseButton::Right, 1)]),
        (json!({"type": "click", "x": 1, "y": 2, "button": "wheel"}), vec![click(1, 2, MouseButton::Middle, 1)]),
        (
            json!({"type": "click", "x": 1, "y": 2, "button": "back"}),
            vec![act(Action::MoveTo { x: 1, y: 2 }), key("browserback")],
        ),
        (
            json!({"type": "click", "x": 1, "y": 2, "button": "forward"}),
            vec![act(Action::MoveTo { x: 1, y: 2 }), key("browserforward")],
        ),
        (json!({"type": "double_click", "x": 1, "y": 2}), vec![act(Action::DoubleClick { x: Some(1), y: Some(2) })]),
        (
            json!({"type": "drag", "path": [{"x": 1, "y": 2}, {"x": 3, "y": 4}]}),
            vec![act(Action::Drag {
                from: Some(Point { x: 1, y: 2 }),
                to: Point { x: 3, y: 4 },
                button: MouseButton::Left,
                duration_ms: None,
            })],
        ),
        (
            json!({"type": "drag", "path": [{"x": 1, "y": 2}, {"x": 3, "y": 4}, {"x": 5, "y": 6}]}),
            vec![
                act(Action::MouseDown { button: MouseButton::Left, x: Some(1), y: Some(2) }),
                act(Action::MoveTo { x: 3, y: 4 }),
                act(Action::MouseUp { button: MouseButton::Left, x: Some(5), y: Some(6) }),
            ],
        ),
        (json!({"type": "keypress", "keys": ["CTRL", "S"]}), vec![hotkey(&["ctrl", "s"])]),
        (json!({"type": "keypress", "keys": ["ENTER"]}), vec![key("enter")]),
        (json!({"type": "keypress", "keys": ["ARROWLEFT"]}), vec![key("left")]),
        (json!({"type": "keypress", "keys": ["CMD", "SPACE"]}), vec![hotkey(&["win", "space"])]),
        (json!({"type": "move", "x": 9, "y": 8}), vec![act(Action::MoveTo { x: 9, y: 8 })]),
        (json!({"type": "screenshot"}), vec![Step::Screenshot]),
        (
            json!({"type": "scroll", "x": 5, "y": 6, "scroll_x": 0, "scroll_y": 300}),
            vec![act(Action::Scroll { x: Some(5), y: Some(6), dx: 0, dy: -360 })],
        ),
        (
            json!({"type": "type", "text": "hello"}),
            vec![act(Action::TypeText { text: "hello".into(), interval_ms: None })],
        ),
        (json!({"type": "wait"}), vec![act(Action::Wait { ms: 1000 })]),
    ];
    for (input, expected) in table {
        check(o, px, input, &expected);
    }
    // openai-cu declares a 1024x640 display for a 1440x900 screen: points and scroll
    // distances are the display's, scaled to the screen's (300 * 1.40625 px, 120 per 100 px).
    let display = Coords::Image { width: 1024, height: 640 };
    check(
        o,
        display,
        json!({"type": "scroll", "x": 512, "y": 320, "scroll_x": 0, "scroll_y": 300}),
        &[act(Action::Scroll { x: Some(720), y: Some(450), dx: 0, dy: -505 })],
    );
    check_err(o, json!({"type": "teleport"}), &["unknown action type \"teleport\"", "keypress"]);
    check_err(o, json!({"type": "click", "x": 1, "y": 2, "button": "thumb"}), &["unknown button \"thumb\""]);
    check_err(o, json!({"type": "keypress", "keys": ["HYPER"]}), &["unknown key \"HYPER\""]);
    check_err(o, json!({"type": "drag", "path": [{"x": 1, "y": 2}]}), &["at least two points"]);
    check_err(o, json!({"type": "move", "x": 1}), &["`y` is missing"]);
}

#[test]
fn uitars_grammar_and_notations() {
    let u = ActionSpace::UiTars;
    let grid = Coords::Grid1000;
    let centre = click(720, 450, MouseButton::Left, 1);
    check(
        u,
        grid,
        json!("Thought: Click the button\nAction: click(start_box='(500,500)')"),
        std::slice::from_ref(&centre),
    );
    check(
        u,
        grid,
        json!("Action: click(start_box='<|box_start|>(500,500)<|box_end|>')"),
        std::slice::from_ref(&centre),
    );
    check(u, grid, json!("Action: click(start_box='(400,400,600,600)')"), std::slice::from_ref(&centre));
    check(u, grid, json!("Action: click(point='<point>500 500</point>')"), std::slice::from_ref(&centre));
    check(u, grid, json!("Action: left_single(start_box='<bbox>400 400 600 600</bbox>')"), &[centre]);
    check(
        u,
        grid,
        json!("Action: left_double(start_box='(0,0)')"),
        &[act(Action::DoubleClick { x: Some(0), y: Some(0) })],
    );
    check(u, grid, json!("Action: right_single(start_box='(1000,1000)')"), &[click(1440, 900, MouseButton::Right, 1)]);
    check(
        u,
        grid,
        json!("Action: drag(start_point='<point>0 0</point>', end_point='<point>500 500</point>')"),
        &[
            act(Action::MoveTo { x: 0, y: 0 }),
            act(Action::Drag {
                from: None,
                to: Point { x: 720, y: 450 },
                button: MouseButton::Left,
                duration_ms: Some(1000),
            }),
        ],
    );
    check(u, grid, json!("Action: hotkey(key='ctrl c')"), &[hotkey(&["ctrl", "c"])]);
    check(u, grid, json!("Action: hotkey(key='arrowdown')"), &[hotkey(&["down"])]);
    // Positions: fractions of the screen, round(..., 3), then pyautogui's int().
    check(u, grid, json!("Action: click(start_box='(333,667)')"), &[click(479, 600, MouseButton::Left, 1)]);
    check(
        u,
        grid,
        json!("Action: type(content='it\\'s done\\n')"),
        &[Step::SetClipboard("it's done".into()), hotkey(&["ctrl", "v"]), act(Action::Wait { ms: 500 }), key("enter")],
    );
    check(
        u,
        grid,
        json!("Action: scroll(start_box='(500,500)', direction='down')"),
        &[act(Action::Scroll { x: Some(720), y: Some(450), dx: 0, dy: -5 })],
    );
    check(
        u,
        grid,
        json!("Action: scroll(direction='left')"),
        &[act(Action::Scroll { x: None, y: None, dx: -5, dy: 0 })],
    );
    check(u, grid, json!("Thought: loading\nAction: wait()"), &[Step::Wait]);
    check(u, grid, json!("Action: finished(content='all set')"), &[Step::Done]);
    check(u, grid, json!("Action: call_user()"), &[Step::Fail]);
    check(
        u,
        grid,
        json!("Action: hotkey(key='ctrl a')\n\nhotkey(key='delete')"),
        &[hotkey(&["ctrl", "a"]), act(Action::Wait { ms: 1000 }), hotkey(&["delete"])],
    );
    check_err(u, json!("Thought: nothing to do"), &["no `Action:`"]);
    check_err(u, json!("Action: teleport(start_box='(1,1)')"), &["unknown call \"teleport\""]);
    check_err(u, json!("Action: click()"), &["needs `start_box`"]);
    check_err(u, json!("Action: click(start_box='(1,2,3)')"), &["(x,y) or (x1,y1,x2,y2)"]);
    check_err(u, json!("Action: hotkey(key='ctrl hyper')"), &["unknown key \"hyper\""]);
    check_err(u, json!("Action: scroll(direction='sideways')"), &["sideways"]);

    let reply = uitars::parse("Thought: Open the menu\nAction: click(start_box='(1,1)')", &ctx(grid)).unwrap();
    assert_eq!(reply.thought.as_deref(), Some("Open the menu"));
    assert_eq!(reply.action_text, "click(start_box='(1,1)')");
}

#[test]
fn uitars_versions_and_smart_resize() {
    // smart_resize keeps sides that are multiples of 28 and within the pixel budget.
    assert_eq!(uitars::smart_resize(1080, 1920), (1092, 1932));
    assert_eq!(uitars::smart_resize(900, 1440), (896, 1428));
    assert_eq!(uitars::smart_resize(10, 10), (280, 280));
    let (h, w) = uitars::smart_resize(8000, 8000);
    assert!(h * w <= 16384 * 28 * 28 && h % 28 == 0 && w % 28 == 0, "{h}x{w}");
    assert_eq!(uitars::UiTarsVersion::V1.coords(SCREEN), Coords::Grid1000);
    let coords = uitars::UiTarsVersion::V1_5.coords(SCREEN);
    assert_eq!(coords, Coords::Image { width: 1428, height: 896 });
    // UI-TARS-1.5's pixels of the resized image land on the screen's.
    check(
        ActionSpace::UiTars,
        coords,
        json!("Action: click(start_box='(714,448)')"),
        &[click(720, 450, MouseButton::Left, 1)],
    );
}

#[test]
fn typed_actions_and_coordinate_conventions() {
    check(
        ActionSpace::Typed,
        Coords::Pixels,
        json!([{"type": "move_to", "x": 1, "y": 2}]),
        &[act(Action::MoveTo { x: 1, y: 2 })],
    );
    check_err(ActionSpace::Typed, json!({"type": "teleport"}), &["unknown typed action", "teleport"]);
    check_err(ActionSpace::Typed, json!({"x": 1}), &["not a typed action"]);
    for space in ActionSpace::ALL {
        assert_eq!(space.name().parse::<ActionSpace>(), Ok(space));
    }
    assert!("morse".parse::<ActionSpace>().unwrap_err().contains("computer_13"));
    assert_eq!(Coords::Fraction.from_screen(720, 450, SCREEN), (0.5, 0.5));
    assert_eq!("grid1000".parse::<Coords>(), Ok(Coords::Grid1000));
    assert!("inches".parse::<Coords>().unwrap_err().contains("inches"));
}

#[test]
fn every_key_table_entry_names_a_guest_key() {
    for (space, table) in [
        (ActionSpace::Anthropic20250124, anthropic::KEYS),
        (ActionSpace::OpenAi, openai::KEYS),
        (ActionSpace::UiTars, uitars::KEYS),
    ] {
        for (from, to) in table {
            assert_eq!(*from, from.to_lowercase(), "{space}: table names are matched lowercased");
            assert!(arena_shared::keys::Key::parse(to).is_ok(), "{space}: {from} -> {to} is not a guest key");
            assert!(key_name(space, table, from).is_ok(), "{space}: {from}");
        }
    }
}

#[test]
fn openai_letters_are_keys_not_shifted_characters() {
    // Found by the input catalogue (`ctrl_c` in openai_computer): `C` became Shift+C.
    let ctx = Context::new((1440, 900), Coords::Pixels);
    let steps = parse(ActionSpace::OpenAi, &json!({"type": "keypress", "keys": ["CTRL", "C"]}), &ctx).unwrap();
    assert_eq!(steps, vec![Step::Act(Action::Hotkey { keys: vec!["ctrl".into(), "c".into()] })]);
    let steps = parse(ActionSpace::OpenAi, &json!({"type": "keypress", "keys": ["A"]}), &ctx).unwrap();
    assert_eq!(steps, vec![Step::Act(Action::KeyPress { key: "a".into(), presses: 1 })]);
}
