//! pyautogui code from agents (the OSWorld-style `pyautogui` action space) turned
//! into typed [`Action`]s for the guest's native `/v1/actions` route.
//!
//! It is a thin wrapper over `arena_shared::script::actions_from_pyautogui`, the
//! same parser and interpreter the guest runs for `/execute`, with errors that
//! quote the code. It performs nothing and runs no Python: code that does more
//! than input (screenshots, files, processes, windows) is refused, naming what.

use arena_shared::action::Action;
use arena_shared::script::{actions_from_pyautogui, ErrorKind};

/// How much of the code an error quotes.
const QUOTE_CHARS: usize = 200;

/// Translates pyautogui code into the input actions it performs, for a screen of
/// `screen` pixels with the cursor at `cursor` (relative moves and `position()` use
/// them). `pyautogui` and `time` are imported first, as the upstream host's prefix does;
/// `time.sleep` becomes [`Action::Wait`].
///
/// # Errors
///
/// The code does not parse, uses something outside the interpreter's subset, does
/// something other than input, or raises; the message names the line and quotes the code.
pub fn actions_from_code(code: &str, screen: (u32, u32), cursor: (i32, i32)) -> anyhow::Result<Vec<Action>> {
    actions_from_pyautogui(code, screen, cursor).map_err(|err| {
        let quoted: String = code.chars().take(QUOTE_CHARS).collect();
        let ellipsis = if code.chars().count() > QUOTE_CHARS { "..." } else { "" };
        let what = if err.kind == ErrorKind::Syntax { "cannot parse" } else { "cannot translate" };
        anyhow::anyhow!("{what} the pyautogui code {quoted:?}{ellipsis}: {err}")
    })
}

#[cfg(test)]
mod tests {
    use arena_shared::action::MouseButton;

    use super::*;

    fn check(code: &str, expected: &[Action]) {
        match actions_from_code(code, (1440, 900), (10, 20)) {
            Ok(actions) => assert_eq!(actions, expected, "{code}"),
            Err(err) => panic!("{code}: {err:#}"),
        }
    }

    fn check_err(code: &str, needles: &[&str]) {
        match actions_from_code(code, (1440, 900), (10, 20)) {
            Ok(actions) => panic!("{code} should fail, got {actions:?}"),
            Err(err) => {
                let text = format!("{err:#}");
                for needle in needles {
                    assert!(text.contains(needle), "{code}: {text:?} lacks {needle:?}");
                }
            }
        }
    }

    #[test]
    fn agent_code_becomes_actions() {
        check(
            "pyautogui.click(10, 20)",
            &[Action::Click { x: Some(10), y: Some(20), button: MouseButton::Left, count: 1 }],
        );
        check(
            "import pyautogui; pyautogui.FAILSAFE = False; pyautogui.moveRel(5, 5); time.sleep(0.5); pyautogui.hotkey('ctrl', 'v')",
            &[
                Action::MoveRel { dx: 5, dy: 5 },
                Action::Wait { ms: 500 },
                Action::Hotkey { keys: vec!["ctrl".into(), "v".into()] },
            ],
        );
        check(
            "p = pyautogui.position()\npyautogui.click(p[0] + 1, p.y)",
            &[Action::Click { x: Some(11), y: Some(20), button: MouseButton::Left, count: 1 }],
        );
        check("", &[]);
    }

    #[test]
    fn errors_name_the_code_and_the_problem() {
        check_err(
            "with open('x') as f: pyautogui.click()",
            &["cannot parse", "with open", "`with` statements are not supported"],
        );
        check_err("pyautogui.screenshot('a.png')", &["cannot translate", "saving a screenshot"]);
        check_err("pyautogui.press('entr')", &["cannot translate", "entr"]);
        let long = format!("pyautogui.typewrite('{}'); foo()", "a".repeat(300));
        check_err(&long, &["...", "foo"]);
    }
}
