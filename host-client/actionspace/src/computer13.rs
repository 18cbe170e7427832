//! OSWorld's `computer_13` action space: JSON actions with an `action_type`.
//!
//! The thirteen types and their parameters are OSWorld's
//! (`desktop_env/actions.py`, `ACTION_SPACE`), executed as its
//! `desktop_env/controllers/python.py` does with pyautogui:
//!
//! | type | parameters | becomes |
//! |---|---|---|
//! | `MOVE_TO` | `x`, `y` (optional) | `moveTo` |
//! | `CLICK` | `button` (`left`/`right`/`middle`), `x`, `y`, `num_clicks` (1 to 3), all optional | `click` |
//! | `MOUSE_DOWN`, `MOUSE_UP` | `button` (optional) | `mouseDown`, `mouseUp` |
//! | `RIGHT_CLICK`, `DOUBLE_CLICK` | `x`, `y` (optional) | `rightClick`, `doubleClick` |
//! | `DRAG_TO` | `x`, `y` | `dragTo(x, y, duration=1.0, button='left')` |
//! | `SCROLL` | `dx`, `dy` (optional) | `hscroll(dx)` then `vscroll(dy)` |
//! | `TYPING` | `text` | `typewrite` |
//! | `PRESS`, `KEY_DOWN`, `KEY_UP` | `key` | `press`, `keyDown`, `keyUp` |
//! | `HOTKEY` | `keys` (a list) | `hotkey` |
//!
//! `WAIT`, `FAIL` and `DONE` (as an `action_type` or as a bare string) are the
//! decisions. Parameters may sit in a `parameters` object or beside
//! `action_type`, as OSWorld's controller accepts both. Keys are pyautogui's
//! names (OSWorld's `KEYBOARD_KEYS` is pyautogui's list); an unknown key is an
//! error, as OSWorld raises one. Coordinates are pixels by default and follow
//! [`Context::coords`].

use serde_json::Value;

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;

use super::{
    chord, json_type, key_list, key_name, opt_number, string, ActionError, ActionSpace, Context, Decision, Step,
};

const SPACE: ActionSpace = ActionSpace::Computer13;

/// OSWorld's keys are pyautogui's: no renaming.
const KEYS: super::KeyTable = &[];

/// The thirteen action types.
pub const ACTION_TYPES: [&str; 13] = [
    "MOVE_TO",
    "CLICK",
    "MOUSE_DOWN",
    "MOUSE_UP",
    "RIGHT_CLICK",
    "DOUBLE_CLICK",
    "DRAG_TO",
    "SCROLL",
    "TYPING",
    "PRESS",
    "KEY_DOWN",
    "KEY_UP",
    "HOTKEY",
];

/// One `computer_13` action.
///
/// # Errors
///
/// [`ActionError`] for an unknown type, a missing or malformed parameter, or an unknown key.
pub fn parse(action: &Value, ctx: &Context) -> Result<Vec<Step>, ActionError> {
    let (kind, params) = match action {
        Value::String(s) => (s.as_str(), Value::Null),
        Value::Object(map) => {
            let kind = string(SPACE, action, "action_type")?;
            let params = match map.get("parameters") {
                Some(p @ Value::Object(_)) => p.clone(),
                Some(Value::Null) | None => {
                    let mut rest = map.clone();
                    rest.remove("action_type");
                    Value::Object(rest)
                }
                Some(other) => {
                    return Err(ActionError::new(SPACE, format!("`parameters` must be an object, got {other}")))
                }
            };
            (kind, params)
        }
        other => return Err(ActionError::new(SPACE, format!("expected an action object, got {}", json_type(other)))),
    };
    let point = |required: bool| -> Result<Option<(i32, i32)>, ActionError> {
        match (opt_number(SPACE, &params, "x")?, opt_number(SPACE, &params, "y")?) {
            (Some(x), Some(y)) => Ok(Some(ctx.point(x, y))),
            (None, None) if !required => Ok(None),
            _ => Err(ActionError::new(SPACE, format!("{kind} needs both `x` and `y`"))),
        }
    };
    let button = || -> Result<MouseButton, ActionError> {
        match params.get("button") {
            None | Some(Value::Null) => Ok(MouseButton::Left),
            Some(Value::String(b)) => {
                MouseButton::from_name(b).ok_or_else(|| ActionError::new(SPACE, format!("unknown button {b:?}")))
            }
            Some(other) => Err(ActionError::new(SPACE, format!("`button` must be a string, got {other}"))),
        }
    };
    let key = || key_name(SPACE, KEYS, string(SPACE, &params, "key")?);
    let act = |a: Action| Ok(vec![Step::Act(a)]);
    if let Some(decision) = Decision::parse(kind) {
        return Ok(vec![decision.into()]);
    }
    match kind {
        "MOVE_TO" => match point(false)? {
            Some((x, y)) => act(Action::MoveTo { x, y }),
            None => Ok(Vec::new()),
        },
        "CLICK" => {
            let at = point(false)?;
            let count = match opt_number(SPACE, &params, "num_clicks")? {
                None => 1,
                Some(n) if [1.0, 2.0, 3.0].contains(&n) => n as u32,
                Some(n) => return Err(ActionError::new(SPACE, format!("`num_clicks` must be 1, 2 or 3, got {n}"))),
            };
            act(Action::Click { x: at.map(|p| p.0), y: at.map(|p| p.1), button: button()?, count })
        }
        "MOUSE_DOWN" => act(Action::MouseDown { button: button()?, x: None, y: None }),
        "MOUSE_UP" => act(Action::MouseUp { button: button()?, x: None, y: None }),
        "RIGHT_CLICK" => {
            let at = point(false)?;
            act(Action::RightClick { x: at.map(|p| p.0), y: at.map(|p| p.1) })
        }
        "DOUBLE_CLICK" => {
            let at = point(false)?;
            act(Action::DoubleClick { x: at.map(|p| p.0), y: at.map(|p| p.1) })
        }
        "DRAG_TO" => {
            let (x, y) = point(true)?.unwrap_or_default();
            act(Action::Drag { from: None, to: Point { x, y }, button: MouseButton::Left, duration_ms: Some(1000) })
        }
        "SCROLL" => {
            let amount = |k: &str| -> Result<i32, ActionError> {
                Ok(opt_number(SPACE, &params, k)?.map_or(0, |v| v.trunc().clamp(-1e6, 1e6) as i32))
            };
            let (dx, dy) = (amount("dx")?, amount("dy")?);
            let mut steps = Vec::new();
            if dx != 0 {
                steps.push(Step::Act(Action::Scroll { x: None, y: None, dx, dy: 0 }));
            }
            if dy != 0 {
                steps.push(Step::Act(Action::Scroll { x: None, y: None, dx: 0, dy }));
            }
            Ok(steps)
        }
        "TYPING" => act(Action::TypeText { text: string(SPACE, &params, "text")?.to_owned(), interval_ms: None }),
        "PRESS" => act(Action::KeyPress { key: key()?, presses: 1 }),
        "KEY_DOWN" => act(Action::KeyDown { key: key()? }),
        "KEY_UP" => act(Action::KeyUp { key: key()? }),
        "HOTKEY" => {
            let keys = key_list(SPACE, KEYS, params.get("keys"), "HOTKEY")?;
            act(chord(keys))
        }
        other => Err(ActionError::new(
            SPACE,
            format!("unknown action_type {other:?} (expected one of {}, WAIT, DONE, FAIL)", ACTION_TYPES.join(", ")),
        )),
    }
}
