//! OpenAI's `computer_call` actions: the `action` of a `computer_use_preview`
//! call, and each action of a GA `computer` call's `actions` batch (a list, which
//! this space takes as it takes any list, in order).
//!
//! The action objects are those of OpenAI's computer-use guide and API reference
//! (and of the `openai` SDK's `types/responses/computer_action.py`, release 3.57.0):
//!
//! | `type` | fields | becomes |
//! |---|---|---|
//! | `click` | `x`, `y`, `button`: `left`, `right`, `wheel`, `back`, `forward` | a click (`wheel` is the middle button; `back`/`forward` press the browser back/forward keys, which is what Windows makes of the side buttons) |
//! | `double_click` | `x`, `y` | a double click |
//! | `drag` | `path`: a list of `{x, y}` | a press at the first point, moves through the others, a release at the last |
//! | `keypress` | `keys`: a list, pressed as one chord | a press or hotkey |
//! | `move` | `x`, `y` | a move |
//! | `screenshot` | | [`Step::Screenshot`] |
//! | `scroll` | `x`, `y`, `scroll_x`, `scroll_y` (pixels; positive `scroll_y` scrolls down) | wheel turns at the point, 120 per 100 pixels |
//! | `type` | `text` | typed text |
//! | `wait` | | a 1 s wait (the duration of OpenAI's sample environments) |
//!
//! `click`, `double_click`, `drag`, `move` and `scroll` may carry `keys`, held
//! while the action runs (pressed in order before it, released in reverse after).
//!
//! Keys come in the model's spelling (`CTRL`, `ENTER`, `ARROWLEFT`, `CMD`, `SPACE`), mapped by [`KEYS`];
//! a letter names its key in either case (`["CTRL", "C"]` is Ctrl+C, not Ctrl+Shift+C).

use serde_json::Value;

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;

use super::{chord, json_type, key_list, number, string, ActionError, ActionSpace, Context, Step};

const SPACE: ActionSpace = ActionSpace::OpenAi;

/// Wheel delta per pixel of `scroll_x`/`scroll_y`: one notch (120) for 100 pixels,
/// about what a browser scrolls for a notch.
const WHEEL_PER_100_PX: i64 = 120;

/// The wait of a `wait` action, in milliseconds.
pub const WAIT_MS: u64 = 1000;

/// The model's key names (lowercased) to pyautogui names; others are pyautogui's own.
pub const KEYS: super::KeyTable = &[
    ("arrowup", "up"),
    ("arrowdown", "down"),
    ("arrowleft", "left"),
    ("arrowright", "right"),
    ("control", "ctrl"),
    ("cmd", "win"),
    ("command", "win"),
    ("meta", "win"),
    ("super", "win"),
    ("option", "alt"),
    ("escape", "esc"),
    ("return", "enter"),
    ("spacebar", "space"),
    ("/", "/"),
    ("\\", "\\"),
    // A letter is its key, whatever its case: the models write `CTRL` and `C` for Ctrl+C,
    // which an upper-case character would turn into Ctrl+Shift+C (Save As for Ctrl+S).
    ("a", "a"),
    ("b", "b"),
    ("c", "c"),
    ("d", "d"),
    ("e", "e"),
    ("f", "f"),
    ("g", "g"),
    ("h", "h"),
    ("i", "i"),
    ("j", "j"),
    ("k", "k"),
    ("l", "l"),
    ("m", "m"),
    ("n", "n"),
    ("o", "o"),
    ("p", "p"),
    ("q", "q"),
    ("r", "r"),
    ("s", "s"),
    ("t", "t"),
    ("u", "u"),
    ("v", "v"),
    ("w", "w"),
    ("x", "x"),
    ("y", "y"),
    ("z", "z"),
];

/// The action types.
pub const ACTIONS: [&str; 9] =
    ["click", "double_click", "drag", "keypress", "move", "screenshot", "scroll", "type", "wait"];

/// One `computer_call.action` object.
///
/// # Errors
///
/// [`ActionError`] for an unknown type or button, a missing or malformed field, or an unknown key.
pub fn parse(action: &Value, ctx: &Context) -> Result<Vec<Step>, ActionError> {
    if !action.is_object() {
        return Err(ActionError::new(SPACE, format!("expected an action object, got {}", json_type(action))));
    }
    let kind = string(SPACE, action, "type")?;
    let held = match action.get("keys") {
        Some(Value::Array(keys)) if keys.is_empty() => Vec::new(),
        Some(keys) if kind != "keypress" && !keys.is_null() => key_list(SPACE, KEYS, Some(keys), kind)?,
        _ => Vec::new(),
    };
    let steps = one(kind, action, ctx)?;
    if held.is_empty() {
        return Ok(steps);
    }
    let downs = held.iter().map(|k| Step::Act(Action::KeyDown { key: k.clone() }));
    let ups = held.iter().rev().map(|k| Step::Act(Action::KeyUp { key: k.clone() }));
    Ok(downs.chain(steps).chain(ups).collect())
}

/// The steps of one action of type `kind`, without its held `keys`.
fn one(kind: &str, action: &Value, ctx: &Context) -> Result<Vec<Step>, ActionError> {
    let point = |v: &Value| -> Result<(i32, i32), ActionError> {
        Ok(ctx.point(number(SPACE, v, "x")?, number(SPACE, v, "y")?))
    };
    let act = |a: Action| Ok(vec![Step::Act(a)]);
    match kind {
        "click" => {
            let (x, y) = point(action)?;
            let button = match action.get("button").and_then(Value::as_str).unwrap_or("left") {
                "left" => MouseButton::Left,
                "right" => MouseButton::Right,
                "wheel" | "middle" => MouseButton::Middle,
                side @ ("back" | "forward") => {
                    let key = if side == "back" { "browserback" } else { "browserforward" };
                    return Ok(vec![
                        Step::Act(Action::MoveTo { x, y }),
                        Step::Act(Action::KeyPress { key: key.into(), presses: 1 }),
                    ]);
                }
                other => {
                    return Err(ActionError::new(
                        SPACE,
                        format!("unknown button {other:?} (expected left, right, wheel, back or forward)"),
                    ))
                }
            };
            act(Action::Click { x: Some(x), y: Some(y), button, count: 1 })
        }
        "double_click" => {
            let (x, y) = point(action)?;
            act(Action::DoubleClick { x: Some(x), y: Some(y) })
        }
        "drag" => {
            let Some(Value::Array(path)) = action.get("path") else {
                return Err(ActionError::new(SPACE, "drag needs `path`, a list of {x, y} points"));
            };
            let points = path.iter().map(&point).collect::<Result<Vec<_>, _>>()?;
            match points.as_slice() {
                [] | [_] => Err(ActionError::new(SPACE, "drag needs at least two points in `path`")),
                [(fx, fy), (tx, ty)] => act(Action::Drag {
                    from: Some(Point { x: *fx, y: *fy }),
                    to: Point { x: *tx, y: *ty },
                    button: MouseButton::Left,
                    duration_ms: None,
                }),
                [(fx, fy), middle @ .., (tx, ty)] => {
                    let mut steps =
                        vec![Step::Act(Action::MouseDown { button: MouseButton::Left, x: Some(*fx), y: Some(*fy) })];
                    steps.extend(middle.iter().map(|&(x, y)| Step::Act(Action::MoveTo { x, y })));
                    steps.push(Step::Act(Action::MouseUp { button: MouseButton::Left, x: Some(*tx), y: Some(*ty) }));
                    Ok(steps)
                }
            }
        }
        "keypress" => {
            let keys = key_list(SPACE, KEYS, action.get("keys"), "keypress")?;
            act(chord(keys))
        }
        "move" => {
            let (x, y) = point(action)?;
            act(Action::MoveTo { x, y })
        }
        "screenshot" => Ok(vec![Step::Screenshot]),
        "scroll" => {
            let (x, y) = point(action)?;
            // The distances are in the model's pixels, as its coordinates: screen pixels after scaling.
            let (fx, fy) = ctx.coords.factors(ctx.screen);
            let wheel = |key: &str, factor: f64| -> Result<i32, ActionError> {
                let px = (number(SPACE, action, key)? * factor).clamp(-1e6, 1e6) as i64;
                Ok((px * WHEEL_PER_100_PX / 100) as i32)
            };
            // Positive scroll_y scrolls down, which is a negative wheel delta.
            act(Action::Scroll { x: Some(x), y: Some(y), dx: wheel("scroll_x", fx)?, dy: -wheel("scroll_y", fy)? })
        }
        "type" => act(Action::TypeText { text: string(SPACE, action, "text")?.to_owned(), interval_ms: None }),
        "wait" => act(Action::Wait { ms: WAIT_MS }),
        other => Err(ActionError::new(
            SPACE,
            format!("unknown action type {other:?} (expected one of {})", ACTIONS.join(", ")),
        )),
    }
}
